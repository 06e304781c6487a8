//! The systems LoopLab runs. Each scenario lives in one folder (plant, sensors, estimator,
//! controller side by side) and plugs into the loop through the traits below, so the five
//! processes stay scenario-agnostic.

pub mod pendulum;

use std::collections::BTreeMap;

use crate::launch::{LaunchConfig, LaunchError};
use crate::msg::SensorReading;

/// A scenario the launcher knows by name, with its default launch file compiled in.
pub struct ScenarioEntry {
    pub name: &'static str,
    pub description: &'static str,
    /// The launch file in the repository that holds the defaults.
    pub file: &'static str,
    pub text: &'static str,
    /// The scenario's own top-level sections of a launch file.
    pub sections: &'static [&'static str],
    /// What its sensors can measure.
    pub signals: &'static [Signal],
    pub build: fn(&LaunchConfig) -> Result<Box<dyn Scenario>, LaunchError>,
}

impl std::fmt::Debug for ScenarioEntry {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name)
    }
}

impl ScenarioEntry {
    pub fn defaults(&self) -> toml::Table {
        toml::from_str(self.text).unwrap_or_else(|e| panic!("built-in {} does not parse: {e}", self.file))
    }
}

pub const ALL: &[ScenarioEntry] = &[pendulum::ENTRY];

/// Something a sensor can measure: named components read from the true state.
pub struct Signal {
    pub name: &'static str,
    /// One name per component; a scalar signal has one.
    pub components: &'static [&'static str],
    pub read: fn(state: &[f64], out: &mut [f64]),
}

/// A configured scenario: the names of its vectors and factories for its loop stages.
pub trait Scenario: Send {
    /// One line for reports, for example "reaction-wheel pendulum, bias-observer".
    fn title(&self) -> String;
    fn state_names(&self) -> &'static [&'static str];
    fn input_names(&self) -> &'static [&'static str];
    fn estimate_names(&self) -> &'static [&'static str];
    /// The closed range of each input the actuator accepts; the plant rejects anything else.
    fn input_limits(&self) -> Vec<(f64, f64)>;
    fn plant(&self) -> Box<dyn Plant>;
    fn estimator(&self) -> Box<dyn Estimator>;
    fn controller(&self) -> Box<dyn Controller>;
    fn metrics(&self) -> Box<dyn Metrics>;
}

/// The physical model: the truth.
pub trait Plant {
    fn state(&self) -> &[f64];
    /// Advances one loop period with the input held constant (zero-order hold).
    fn step(&mut self, u: &[f64], dt: f64);
}

pub trait Estimator {
    /// Takes every sensor's held reading at simulation time `t` and the input the actuator
    /// applied over the last interval; writes the estimate.
    fn update(&mut self, t: f64, readings: &[SensorReading], u_applied: &[f64], estimate: &mut [f64]);
}

pub trait Controller {
    fn update(&mut self, t: f64, estimate: &[f64], command: &mut [f64]);
}

/// One loop as the monitor joined it, for the scenario's metrics.
pub struct Row<'a> {
    pub k: u64,
    pub t: f64,
    pub state: &'a [f64],
    pub readings: &'a [SensorReading],
    pub estimate: &'a [f64],
    pub command: &'a [f64],
}

/// The scenario's control metrics, fed every loop in order.
pub trait Metrics: Send {
    fn observe(&mut self, row: &Row);
    fn finish(&self) -> BTreeMap<String, f64>;
}
