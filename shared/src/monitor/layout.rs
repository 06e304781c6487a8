//! The run's vectors as the recorder reads them: names and sizes of the state, each sensor's
//! reading, the estimate and the command, taken once from the launch file and the scenario.

use crate::config::launch::LaunchConfig;
use crate::config::schema::Component;
use crate::model::scenario::Scenario;

#[derive(Debug, Clone, Default, PartialEq)]
pub struct Layout {
    pub state: Vec<String>,
    /// Per sensor, in the launch file's order (the order of readings in `Measurements`): its
    /// name and its components' names.
    pub sensors: Vec<(String, Vec<String>)>,
    pub estimate: Vec<String>,
    pub input: Vec<String>,
}

impl Layout {
    /// A small made-up layout for the sinks' unit tests: two state components, two sensors
    /// (one scalar, one of two components), one estimate, one input.
    #[cfg(test)]
    pub fn example() -> Self {
        let names = |n: &[&str]| n.iter().map(|s| s.to_string()).collect::<Vec<_>>();
        Layout {
            state: names(&["theta", "omega"]),
            sensors: vec![("encoder".into(), names(&["angle"])), ("imu".into(), names(&["x", "y"]))],
            estimate: names(&["theta"]),
            input: names(&["u"]),
        }
    }

    pub fn new(config: &LaunchConfig, scenario: &dyn Scenario) -> Self {
        let names = |components: &[Component]| components.iter().map(|c| c.name.to_string()).collect::<Vec<_>>();
        let vectors = scenario.vectors();
        Self {
            state: names(vectors.state),
            sensors: config
                .sensors
                .iter()
                .map(|(name, spec)| (name.clone(), names(config.signal_of(spec).components)))
                .collect(),
            estimate: names(vectors.estimate),
            input: names(vectors.input),
        }
    }

    /// The number of components of each sensor's reading.
    pub fn sensor_dims(&self) -> Vec<usize> {
        self.sensors.iter().map(|(_, components)| components.len()).collect()
    }
}
