//! The launch configuration's types: the mode, the sensors as written, and the checked
//! [`LaunchConfig`] with the origins its errors name.

use std::collections::BTreeMap;

use serde::de::DeserializeOwned;
use serde::{Deserialize, Serialize};

use crate::config::error::LaunchError;
use crate::config::faults::{FaultSpec, Supervision};
use crate::config::hosts::Hosts;
use crate::config::realtime::RealtimeSettings;
use crate::config::replay::ReplaySpec;
use crate::config::schema::{ScenarioSchema, SignalLayout};
use crate::config::stages::Stages;
use crate::config::wait::WaitSettings;

/// The longest run allowed, s (one week): it keeps every time and tick count of a run far
/// from the limits of `Duration` and `u64` arithmetic.
pub const MAX_DURATION_S: f64 = 604_800.0;
/// The fastest loop allowed, Hz.
pub const MAX_RATE_HZ: f64 = 100_000.0;
/// The most loops a run may have (a week at 1 kHz is 6.048e8); also keeps tick counts that are
/// derived from a run's loops within `u32` (delays in ticks).
pub const MAX_LOOPS: u64 = 1_000_000_000;

#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, strum::IntoStaticStr, schemars::JsonSchema)]
#[serde(rename_all = "lowercase")]
#[strum(serialize_all = "lowercase")]
pub enum Mode {
    /// The plant ticks on an absolute-deadline timer and applies the newest command it has.
    Realtime,
    /// The plant waits for command k before integrating tick k→k+1: deterministic, as fast
    /// as the loop allows.
    Lockstep,
}

impl Mode {
    pub fn name(self) -> &'static str {
        self.into()
    }
}

/// A value given either as one number (for every component) or one number per component.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(untagged)]
pub enum PerComponent {
    All(f64),
    Each(Vec<f64>),
}

impl Default for PerComponent {
    fn default() -> Self {
        PerComponent::All(0.0)
    }
}

impl PerComponent {
    /// The value for each of `dim` components (the length was checked in [`LaunchConfig`]).
    pub fn expand(&self, dim: usize) -> Vec<f64> {
        match self {
            PerComponent::All(v) => vec![*v; dim],
            PerComponent::Each(v) => v.clone(),
        }
    }
}

/// One emulated sensor, as written in the launch file.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SensorSpec {
    /// Which of the scenario's signals it measures (for example `theta`); a declared system's
    /// sensor is a signal of its own name (set at load).
    #[serde(default, skip_serializing_if = "String::is_empty")]
    pub signal: String,
    /// A declared system's sensor: the components it reads (`"state.theta"`, `"output.y"`,
    /// `"input.current"`).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub reads: Vec<String>,
    /// Sample period in seconds: a whole multiple of the loop period.
    pub period_s: f64,
    /// Standard deviation of the Gaussian noise added at each sample.
    #[serde(default)]
    pub noise_std: PerComponent,
    /// Constant offset added to the true value.
    #[serde(default)]
    pub bias: PerComponent,
    /// Quantisation step (0: none). Values are rounded to the nearest multiple.
    #[serde(default)]
    pub quantum: f64,
    /// Transport delay, in loop ticks, between sampling and delivery.
    #[serde(default)]
    pub delay_ticks: u32,
    /// false removes a sensor the scenario's defaults have (the lab has no rate sensors).
    #[serde(default = "enabled")]
    pub enabled: bool,
}

fn enabled() -> bool {
    true
}

/// A checked launch configuration: the keys every scenario shares, plus the scenario's own
/// sections, still as TOML, for the scenario to read with [`LaunchConfig::section`].
#[derive(Debug, Clone)]
pub struct LaunchConfig {
    pub scenario: String,
    pub mode: Mode,
    pub rate_hz: f64,
    /// Real time: how long after its tick is due loop k's command may reach the plant before
    /// the loop counts as a deadline miss, µs. None: one loop period (the command is in before
    /// the next tick is due).
    pub deadline_us: Option<f64>,
    /// Every loop whose end-to-end latency is over this, µs, gets a cause too, as every deadline
    /// miss does (`looplab run --explain-over US`). None: the misses only.
    pub explain_over_us: Option<f64>,
    /// Real time: a probe beside the loop measures how late the OS wakes a bare timer at the
    /// plant's priority and the loop's rate (`looplab run --probe`; `launcher::probe`).
    pub probe: bool,
    /// Record the kernel's scheduler events for the run and name the task that ran while a loop
    /// process waited (`looplab run --trace-sched`; `launcher::sched_trace`).
    pub trace_sched: bool,
    pub duration_s: f64,
    pub seed: u64,
    /// Sorted by name: this order is the order of readings in every `Measurements` message.
    pub sensors: BTreeMap<String, SensorSpec>,
    /// Faults to inject, in the order given.
    pub faults: Vec<FaultSpec>,
    pub supervision: Supervision,
    /// How each loop process waits for its input.
    pub wait: WaitSettings,
    /// Real-time priority and memory locking of the loop's processes.
    pub realtime: RealtimeSettings,
    /// Stages placed on another host (none: the whole loop runs here).
    pub hosts: Hosts,
    /// Stages of the user's own, run in place of the built-in ones.
    pub stages: Stages,
    /// A replay of a recorded run into one stage (`looplab replay`).
    pub replay: Option<ReplaySpec>,
    /// `[gate] fail_on`: what fails the run (`config::gate`).
    pub gates: Vec<crate::config::gate::Gate>,
    /// The whole resolved document, as written to the run folder.
    pub document: toml::Table,
    /// The scenario it was checked against.
    pub schema: ScenarioSchema,
    /// The input's limits, as the launcher resolved them: a run's `launch.toml` read without a
    /// catalog has them (`load_run_config`); elsewhere the scenario says them.
    pub input_limits: Option<Vec<(f64, f64)>>,
    /// Where the values came from, for error messages.
    pub(super) origins: Origins,
}

/// Which `--set` overrides were applied, so that an error in one names it instead of the file.
#[derive(Debug, Clone, Default)]
pub(super) struct Origins {
    pub(super) file: String,
    pub(super) set_keys: BTreeMap<String, String>,
}

impl Origins {
    pub(super) fn of(&self, key: &str) -> String {
        for (set_key, set_text) in &self.set_keys {
            let within = |a: &str, b: &str| a == b || a.starts_with(&format!("{b}."));
            if within(key, set_key) || within(set_key, key) {
                return set_text.clone();
            }
        }
        self.file.clone()
    }

    pub(super) fn error(&self, key: &str, message: impl Into<String>) -> LaunchError {
        LaunchError::new(self.of(key), Some(key), message)
    }
}

impl LaunchConfig {
    /// Loop period in seconds.
    pub fn dt(&self) -> f64 {
        1.0 / self.rate_hz
    }

    /// The deadline in ns: `deadline_us`, or one loop period, the plant's own (so that the
    /// default is exactly "before tick k+1 is due").
    pub fn deadline_ns(&self) -> u64 {
        match self.deadline_us {
            // At most one period (checked at load), so well within u64 nanoseconds.
            Some(us) => (us * 1e3).round() as u64,
            None => self.period_ns(),
        }
    }

    /// `explain_over_us` in ns.
    pub fn explain_over_ns(&self) -> Option<u64> {
        // Positive and at most an hour (checked at load).
        self.explain_over_us.map(|us| (us * 1e3).round() as u64)
    }

    /// The loop period in ns, as the plant's schedule has it.
    pub fn period_ns(&self) -> u64 {
        crate::contract::clock::period_ns(self.rate_hz)
    }

    /// Number of loops the run has: duration × rate, rounded to the nearest tick.
    pub fn loops(&self) -> u64 {
        // duration_s ≤ a week and rate_hz ≤ 100 kHz (checked at load): below 1e11, no saturation.
        (self.duration_s * self.rate_hz).round() as u64
    }

    /// What a sensor measures (checked to exist when the launch file loads).
    pub fn signal_of(&self, sensor: &SensorSpec) -> &SignalLayout {
        self.schema.signal(&sensor.signal).expect("sensor signals are checked at load")
    }

    /// A sensor's period in loop ticks (checked to be a whole number at load).
    pub fn period_ticks(&self, sensor: &SensorSpec) -> u64 {
        // period_s ≤ duration_s (checked at load): at most the run's loops.
        (sensor.period_s * self.rate_hz).round() as u64
    }

    /// Reads one scenario section (`model`, `estimator`, ...) into its typed form; an unknown
    /// key or a bad value is an error naming the dotted key and what is allowed.
    pub fn section<T: DeserializeOwned>(&self, name: &str) -> Result<T, LaunchError> {
        let value = self.document.get(name).cloned().unwrap_or(toml::Value::Table(toml::Table::new()));
        deserialize_at(&self.origins, name, value)
    }

    /// An error about one key of this configuration, naming where that key's value came from.
    pub fn error(&self, key: &str, message: impl Into<String>) -> LaunchError {
        self.origins.error(key, message)
    }

    /// The index of the one sensor measuring `signal`, for estimators that need it.
    pub fn sensor_for(&self, signal: &str) -> Result<(usize, &str, &SensorSpec), LaunchError> {
        let found: Vec<_> = self
            .sensors
            .iter()
            .enumerate()
            .filter(|(_, (_, spec))| spec.signal == signal)
            .map(|(i, (name, spec))| (i, name.as_str(), spec))
            .collect();
        match found.as_slice() {
            [one] => Ok(*one),
            [] => Err(self.error(
                "sensors",
                format!("the {} scenario needs a sensor with signal = \"{signal}\", and none has it", self.scenario),
            )),
            many => Err(self.error(
                "sensors",
                format!(
                    "the {} scenario needs exactly one sensor with signal = \"{signal}\"; found {}",
                    self.scenario,
                    many.iter().map(|(_, name, _)| *name).collect::<Vec<_>>().join(", ")
                ),
            )),
        }
    }

    /// The configuration with `wait.lockstep = "auto"` decided for a machine with `cpus` CPUs
    /// (`WaitSettings::decided_for`), in the settings and in the document the run keeps.
    pub fn with_wait_decided(&self, cpus: usize) -> Self {
        let mut decided = self.clone();
        decided.wait = self.wait.decided_for(cpus);
        let lockstep: &str = decided.wait.lockstep.into();
        if let toml::Value::Table(wait) =
            decided.document.entry("wait").or_insert_with(|| toml::Value::Table(toml::Table::new()))
        {
            wait.insert("lockstep".into(), toml::Value::String(lockstep.into()));
        }
        decided
    }

    /// The resolved document as TOML text, for the run folder.
    pub fn to_toml(&self) -> String {
        toml::to_string(&self.document).expect("a TOML table always serialises")
    }
}

/// Deserialises `value` (found at dotted `key`) and turns a failure into an error that names
/// the full dotted path of the offending key.
pub(super) fn deserialize_at<T: DeserializeOwned>(
    origins: &Origins,
    key: &str,
    value: toml::Value,
) -> Result<T, LaunchError> {
    serde_path_to_error::deserialize(value).map_err(|e| {
        let inner = e.path().to_string();
        let path = match (key.is_empty(), inner.as_str()) {
            (true, _) => inner.clone(),
            (false, ".") => key.to_owned(),
            (false, _) => format!("{key}.{inner}"),
        };
        // The TOML deserialiser appends "in `key`" lines; the key is already named.
        let message = e.inner().to_string().lines().next().unwrap_or_default().to_owned();
        origins.error(&path, message)
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::config::faults::FaultKind;

    /// The text of each enum comes from its derives, the same in a launch file, summary.json
    /// and every message.
    #[test]
    fn enum_text_is_derived_and_the_same_everywhere() {
        use crate::config::wait::Strategy;
        fn same<T: Serialize>(value: T, name: &str) {
            assert_eq!(serde_json::to_value(value).unwrap().as_str(), Some(name));
        }
        for kind in crate::config::faults::FAULT_KINDS {
            same(kind, kind.name());
        }
        for mode in [Mode::Realtime, Mode::Lockstep] {
            same(mode, mode.name());
        }
        for strategy in [Strategy::Block, Strategy::Spin, Strategy::Adaptive] {
            same(strategy, strategy.name());
        }
        assert_eq!((FaultKind::Corrupt.name(), Mode::Lockstep.name()), ("corrupt", "lockstep"));
    }
}
