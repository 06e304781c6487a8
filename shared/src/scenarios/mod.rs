//! The systems LoopLab runs. Each scenario lives in one folder (plant, sensors, estimator,
//! controller side by side) and plugs into the loop through the traits below, so the five
//! processes stay scenario-agnostic.

pub mod pendulum;
pub mod quadcopter;

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

pub const ALL: &[ScenarioEntry] = &[pendulum::ENTRY, quadcopter::ENTRY];

/// The most integration steps per loop period: more would only make a loop slower than its
/// period (and a huge count hangs the plant).
pub const MAX_SUBSTEPS: u32 = 1000;

/// An error unless `substeps` (at dotted `key`) is 1 to [`MAX_SUBSTEPS`].
pub fn check_substeps(c: &LaunchConfig, key: &str, substeps: u32) -> Result<(), LaunchError> {
    if (1..=MAX_SUBSTEPS).contains(&substeps) {
        Ok(())
    } else {
        Err(c.error(key, format!("must be 1 to {MAX_SUBSTEPS} integration steps per loop, got {substeps}")))
    }
}

/// Something a sensor can measure: named components read from the true state.
pub struct Signal {
    pub name: &'static str,
    /// One name per component; a scalar signal has one.
    pub components: &'static [&'static str],
    pub read: fn(state: &[f64], out: &mut [f64]),
}

/// A configured scenario: the names of its vectors and factories for its loop stages.
pub trait Scenario: Send + Sync {
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
    /// How fault reports judge the physical system.
    fn error_measure(&self) -> ErrorMeasure;
    /// The loop's delay margin from the linearised model: the smallest extra controller delay,
    /// in ticks, at which the sampled loop is unstable. None if the scenario has no such model.
    fn delay_margin(&self, _config: &LaunchConfig) -> Option<TheoreticalMargin> {
        None
    }
}

/// A delay margin from theory, for `looplab sweep` to print next to the measured one.
#[derive(Debug, Clone, serde::Serialize, serde::Deserialize, PartialEq)]
pub struct TheoreticalMargin {
    /// Exact, from the spectral radius of the linearised sampled loop.
    pub ticks: u32,
    /// Continuous-time estimate: phase margin over crossover frequency, in ticks.
    pub continuous_ticks: f64,
    /// The same with the delays that sampling adds on each path (command hold, sensor holds).
    pub lagged_ticks: f64,
    pub crossover_rad_s: f64,
    pub phase_margin_deg: f64,
    /// Per-tick spectral radius one tick below the margin and at it.
    pub radius_before: f64,
    pub radius_at_margin: f64,
}

/// How far the physical system is from where it should be, for fault reports: the worst value
/// during and after a fault, the band it must come back within (recovery), and the limit it
/// must never pass (for the pendulum: the angle at which it has fallen).
/// The error at simulation time t in true state x.
pub type ErrorOfState = std::sync::Arc<dyn Fn(f64, &[f64]) -> f64 + Send + Sync>;

#[derive(Clone)]
pub struct ErrorMeasure {
    pub name: &'static str,
    pub of_state: ErrorOfState,
    pub recovery_band: f64,
    pub limit: f64,
}

impl ErrorMeasure {
    pub fn describe(&self) -> crate::report::ErrorMeasureInfo {
        crate::report::ErrorMeasureInfo { name: self.name.into(), recovery_band: self.recovery_band, limit: self.limit }
    }
}

/// The physical model: the truth.
pub trait Plant {
    fn state(&self) -> &[f64];
    /// Advances one loop period from simulation time `t` with the input held constant
    /// (zero-order hold).
    fn step(&mut self, t: f64, u: &[f64], dt: f64);
    /// Sets the state, for a restarted plant going on from its snapshot.
    fn restore(&mut self, state: &[f64]);
    /// What the actuator applied over the last step, where it differs from the command (a
    /// command link that samples the commands): the estimator predicts with it.
    fn applied_input(&self) -> Option<&[f64]> {
        None
    }
}

pub trait Estimator {
    /// Takes every sensor's held reading at simulation time `t` and the input the actuator
    /// applied over the last interval; writes the estimate.
    fn update(&mut self, t: f64, readings: &[SensorReading], u_applied: &[f64], estimate: &mut [f64]);
    /// Slow states worth keeping across a restart, such as a calibrated sensor bias; the fast
    /// ones start again from the current measurements. None: nothing to keep (yet).
    fn calibration(&self) -> Option<Calibration> {
        None
    }
    /// A restarted estimator gets its predecessor's calibration before its first update.
    fn resume(&mut self, _calibration: &Calibration) {}
}

/// Up to 32 numbers an estimator keeps across restarts.
pub type Calibration = [f64; 32];

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
    /// What the actuator applied over the period that ended at tick k.
    pub applied: &'a [f64],
}

/// The scenario's control metrics, fed every loop in order.
pub trait Metrics: Send {
    fn observe(&mut self, row: &Row);
    fn finish(&self) -> BTreeMap<String, f64>;
    /// Findings the numbers alone do not say.
    fn notes(&self) -> Vec<String> {
        Vec::new()
    }
}
