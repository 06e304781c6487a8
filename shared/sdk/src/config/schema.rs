//! A scenario as the configuration layer sees it: plain data to check a launch file against
//! (its defaults, its sections, the names, units and sizes of its vectors), with no model code.
//! The scenarios layer fills it in; the message limits are checked here, when a launch file is
//! resolved, so that no child process ever meets a vector larger than its messages.

use std::fmt;

use crate::config::error::LaunchError;
use crate::contract::msg::{MAX_ESTIMATE, MAX_INPUT, MAX_SENSOR_DIM, MAX_STATE};

/// One component of a vector: its name and its unit (together a column of `trajectory.csv`).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Component {
    pub name: &'static str,
    /// SI, as written in reports ("rad/s", "N·m"); "1" for a pure number.
    pub unit: &'static str,
}

impl Component {
    pub const fn new(name: &'static str, unit: &'static str) -> Self {
        Self { name, unit }
    }
}

/// A component reads as its name (as a field of the MCAP recording is named).
impl fmt::Display for Component {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name)
    }
}

/// The names of a vector's components, in order.
pub fn names(components: &[Component]) -> Vec<&'static str> {
    components.iter().map(|c| c.name).collect()
}

/// Something a scenario's sensors can measure, as a launch file names it.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct SignalLayout {
    pub name: &'static str,
    /// One per component; a scalar signal has one.
    pub components: &'static [Component],
}

/// What a launch file for one scenario is checked against.
#[derive(Clone)]
pub struct ScenarioSchema {
    pub name: &'static str,
    /// The launch file in the repository that holds the defaults.
    pub file: &'static str,
    /// Its text, compiled in.
    pub text: &'static str,
    pub state: &'static [Component],
    pub input: &'static [Component],
    pub estimate: &'static [Component],
    pub signals: Vec<SignalLayout>,
}

/// Its name: the rest is a whole launch file and tables of names.
impl fmt::Debug for ScenarioSchema {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name)
    }
}

impl ScenarioSchema {
    /// The default launch file, parsed.
    pub fn defaults(&self) -> toml::Table {
        toml::from_str(self.text).unwrap_or_else(|e| panic!("built-in {} does not parse: {e}", self.file))
    }

    pub fn signal(&self, name: &str) -> Option<&SignalLayout> {
        self.signals.iter().find(|s| s.name == name)
    }

    /// An error naming the scenario and the vector unless every vector fits the messages.
    pub fn check_fits(&self) -> Result<(), LaunchError> {
        let vectors = [("the state", self.state.len(), MAX_STATE), ("the input", self.input.len(), MAX_INPUT)];
        let signals =
            self.signals.iter().map(|s| (format!("signal \"{}\"", s.name), s.components.len(), MAX_SENSOR_DIM));
        let all = vectors
            .into_iter()
            .map(|(what, len, max)| (what.to_owned(), len, max))
            .chain([("the estimate".to_owned(), self.estimate.len(), MAX_ESTIMATE)])
            .chain(signals);
        for (what, len, max) in all {
            if len > max {
                return Err(LaunchError::new(
                    format!("scenario {}", self.name),
                    None,
                    format!("{what} has {len} components, more than the {max} a message carries"),
                ));
            }
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const ONE: &[Component] = &[Component::new("x", "m")];

    fn schema(estimate: &'static [Component], signal: &'static [Component]) -> ScenarioSchema {
        ScenarioSchema {
            name: "made-up",
            file: "launch/made-up.toml",
            text: "",
            state: ONE,
            input: ONE,
            estimate,
            signals: vec![SignalLayout { name: "wide", components: signal }],
        }
    }

    #[test]
    fn a_vector_larger_than_its_message_is_an_error_naming_the_scenario_and_the_vector() {
        const E60: &[Component] = &[Component::new("e", "1"); 60];
        const S17: &[Component] = &[Component::new("s", "1"); 17];
        const S16: &[Component] = &[Component::new("s", "1"); 16];
        const E48: &[Component] = &[Component::new("e", "1"); 48];
        assert_eq!(
            schema(E60, ONE).check_fits().unwrap_err().to_string(),
            "scenario made-up: the estimate has 60 components, more than the 48 a message carries"
        );
        assert_eq!(
            schema(ONE, S17).check_fits().unwrap_err().to_string(),
            "scenario made-up: signal \"wide\" has 17 components, more than the 16 a message carries"
        );
        schema(E48, S16).check_fits().unwrap();
    }
}
