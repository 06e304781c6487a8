//! The systems LoopLab runs, and resolution by name. Each scenario lives in one folder (plant,
//! sensors, estimator, controller side by side) and plugs into the loop through the traits of
//! [`crate::model::scenario`], so the five processes stay scenario-agnostic. [`ALL`] is the
//! registry; [`resolve`] turns a name or a launch file into a checked configuration and the
//! scenario it describes.

pub mod fip;
pub mod pendulum;
pub mod quadcopter;
pub mod tethered;
pub mod tiltrotor;

#[cfg(test)]
mod fault_tests;
#[cfg(test)]
mod launch_tests;

use std::path::Path;

use crate::config::launch::{self, LaunchConfig, LaunchError, Override};
use crate::config::schema::ScenarioSchema;

use crate::model::scenario::{Scenario, ScenarioEntry};

pub const ALL: &[ScenarioEntry] = &[pendulum::ENTRY, quadcopter::ENTRY, tiltrotor::ENTRY, fip::ENTRY, tethered::ENTRY];

/// The built-in scenario of this name, with its default launch file compiled in.
pub fn builtin(name: &str) -> Option<&'static ScenarioEntry> {
    ALL.iter().find(|s| s.name == name)
}

/// The built-in scenarios' names, for error messages.
pub fn scenario_names() -> String {
    ALL.iter().map(|s| s.name).collect::<Vec<_>>().join(", ")
}

/// What the configuration layer checks launch files against: every built-in scenario.
pub fn catalog() -> Vec<ScenarioSchema> {
    ALL.iter().map(ScenarioEntry::schema).collect()
}

/// Resolves what the user asked to run, a scenario name or a launch-file path, with overrides,
/// into a checked configuration and the scenario it describes.
pub fn resolve(target: &str, overrides: &[Override]) -> Result<(LaunchConfig, Box<dyn Scenario>), LaunchError> {
    build(launch::resolve_config(target, overrides, &catalog())?)
}

/// Reads a resolved launch file written by the launcher (what each loop process does).
pub fn load_resolved(path: &Path) -> Result<(LaunchConfig, Box<dyn Scenario>), LaunchError> {
    build(launch::load_resolved_config(path, &catalog())?)
}

fn build(config: LaunchConfig) -> Result<(LaunchConfig, Box<dyn Scenario>), LaunchError> {
    let entry = builtin(&config.scenario).expect("the configuration names a scenario of the catalog");
    let scenario = (entry.build)(&config)?;
    Ok((config, scenario))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::contract::msg::{MAX_ESTIMATE, MAX_INPUT, MAX_SENSOR_DIM, MAX_STATE};

    #[test]
    fn every_scenario_fits_the_messages() {
        for entry in ALL {
            entry.schema().check_fits().unwrap_or_else(|e| panic!("{e}"));
            let v = entry.vectors;
            assert!(v.state.len() <= MAX_STATE && v.input.len() <= MAX_INPUT && v.estimate.len() <= MAX_ESTIMATE);
            assert!(v.signals.iter().all(|s| s.components.len() <= MAX_SENSOR_DIM), "{}", entry.name);
        }
    }

    /// The built scenario reports its entry's vectors, and the names derive from them.
    #[test]
    fn a_built_scenario_has_its_entrys_vectors() {
        for entry in ALL {
            let (_, scenario) = resolve(entry.name, &[]).unwrap();
            assert!(std::ptr::eq(scenario.vectors(), entry.vectors), "{}", entry.name);
            assert_eq!(scenario.estimate_names().len(), entry.vectors.estimate.len());
        }
        let (_, pendulum) = resolve("pendulum", &[]).unwrap();
        assert_eq!(pendulum.state_names(), ["theta", "theta_dot", "wheel_speed"]);
        assert_eq!(pendulum.input_names(), ["current"]);
        assert_eq!(pendulum.estimate_names(), ["theta", "theta_dot", "wheel_speed", "bias"]);
    }

    #[test]
    fn the_sections_derive_from_the_defaults() {
        let sections = |name| builtin(name).unwrap().schema().sections();
        assert_eq!(sections("pendulum"), ["controller", "estimator", "limits", "model", "plant"]);
        assert_eq!(
            sections("quadcopter"),
            ["controller", "estimator", "limits", "metrics", "model", "plant", "reference"]
        );
    }
}
