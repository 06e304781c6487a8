//! Launch files: load, merge over the scenario's defaults, apply `--set KEY=VALUE`, check.
//!
//! A launch file is TOML. Its keys override the scenario's built-in defaults
//! (`launch/<scenario>.toml`) key by key, and `--set` overrides both. Every problem is
//! reported as a [`LaunchError`] that names where the value came from (a file or a `--set`),
//! the dotted key, and what is allowed.

use std::collections::{BTreeMap, BTreeSet};
use std::fmt;
use std::path::Path;

use serde::de::DeserializeOwned;
use serde::{Deserialize, Serialize};

use crate::config::faults::{
    FaultKind, FaultSpec, MAX_BACKOFF_S, MAX_RESTARTS, MAX_STOP_S, MAX_TIMEOUT_S, Supervision,
};
use crate::config::hosts::Hosts;
use crate::config::schema::{ScenarioSchema, SignalLayout};
use crate::config::wait::MAX_WAIT_US;
use crate::config::wait::WaitSettings;
use crate::contract::msg::MAX_SENSORS;
use crate::contract::role::Role;

/// The longest run allowed, s (one week): it keeps every time and tick count of a run far
/// from the limits of `Duration` and `u64` arithmetic.
pub const MAX_DURATION_S: f64 = 604_800.0;
/// The fastest loop allowed, Hz.
pub const MAX_RATE_HZ: f64 = 100_000.0;
/// The most loops a run may have (a week at 1 kHz is 6.048e8); also keeps tick counts that are
/// derived from a run's loops within `u32` (delays in ticks).
pub const MAX_LOOPS: u64 = 1_000_000_000;

pub use crate::config::error::{COMMON_KEYS, LaunchError};

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
    /// Which of the scenario's signals it measures (for example `theta`).
    pub signal: String,
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

#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
struct CommonKeys {
    scenario: String,
    mode: Mode,
    rate_hz: f64,
    duration_s: f64,
    seed: u64,
    #[serde(default)]
    sensors: BTreeMap<String, SensorSpec>,
    #[serde(default)]
    faults: Vec<FaultSpec>,
    #[serde(default)]
    supervision: Supervision,
    #[serde(default)]
    wait: WaitSettings,
    /// Read by `Hosts::parse`, for errors that name the key.
    #[serde(default)]
    hosts: toml::Table,
}

/// A checked launch configuration: the keys every scenario shares, plus the scenario's own
/// sections, still as TOML, for the scenario to read with [`LaunchConfig::section`].
#[derive(Debug, Clone)]
pub struct LaunchConfig {
    pub scenario: String,
    pub mode: Mode,
    pub rate_hz: f64,
    pub duration_s: f64,
    pub seed: u64,
    /// Sorted by name: this order is the order of readings in every `Measurements` message.
    pub sensors: BTreeMap<String, SensorSpec>,
    /// Faults to inject, in the order given.
    pub faults: Vec<FaultSpec>,
    pub supervision: Supervision,
    /// How each loop process waits for its input.
    pub wait: WaitSettings,
    /// Stages placed on another host (none: the whole loop runs here).
    pub hosts: Hosts,
    /// The whole resolved document, as written to the run folder.
    pub document: toml::Table,
    /// The scenario it was checked against.
    pub schema: ScenarioSchema,
    /// Where the values came from, for error messages.
    origins: Origins,
}

/// Which `--set` overrides were applied, so that an error in one names it instead of the file.
#[derive(Debug, Clone, Default)]
struct Origins {
    file: String,
    set_keys: BTreeMap<String, String>,
}

impl Origins {
    fn of(&self, key: &str) -> String {
        for (set_key, set_text) in &self.set_keys {
            let within = |a: &str, b: &str| a == b || a.starts_with(&format!("{b}."));
            if within(key, set_key) || within(set_key, key) {
                return set_text.clone();
            }
        }
        self.file.clone()
    }

    fn error(&self, key: &str, message: impl Into<String>) -> LaunchError {
        LaunchError::new(self.of(key), Some(key), message)
    }
}

impl LaunchConfig {
    /// Loop period in seconds.
    pub fn dt(&self) -> f64 {
        1.0 / self.rate_hz
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

/// One `--set KEY=VALUE` from the command line.
#[derive(Debug, Clone, PartialEq)]
pub struct Override {
    pub key: String,
    pub value: toml::Value,
    /// As the user typed it, for error messages.
    pub text: String,
    /// Appends `value` to the array at `key` (a `--fault`) instead of setting it.
    pub append: bool,
}

impl Override {
    /// Parses `KEY=VALUE`. The value is read as TOML (`0.05`, `true`, `[1, 2]`, `"x"`);
    /// anything that is not valid TOML is taken as a plain string (`no-bias`).
    pub fn parse(text: &str) -> Result<Self, LaunchError> {
        let origin = format!("--set {text}");
        let Some((key, raw)) = text.split_once('=') else {
            return Err(LaunchError::new(origin, None, "expected KEY=VALUE, for example sensors.encoder.bias=0.05"));
        };
        let key = key.trim();
        if key.is_empty() || key.split('.').any(str::is_empty) {
            return Err(LaunchError::new(origin, None, "the key must be a dotted path such as estimator.kind"));
        }
        let raw = raw.trim();
        let value = toml::from_str::<toml::Table>(&format!("v = {raw}"))
            .ok()
            .and_then(|mut t| t.remove("v"))
            .unwrap_or_else(|| toml::Value::String(raw.to_owned()));
        Ok(Self { key: key.to_owned(), value, text: text.to_owned(), append: false })
    }

    /// Parses a `--fault` text (see [`crate::config::faults::FAULT_SYNTAX`]) into an entry appended to
    /// the launch file's `faults` list.
    pub fn fault(text: &str) -> Result<Self, LaunchError> {
        let origin = format!("--fault {text}");
        let spec = crate::config::faults::parse_fault(text).map_err(|e| LaunchError::new(&origin, None, e))?;
        let value = toml::Value::try_from(&spec).expect("a fault always converts to TOML");
        Ok(Self { key: "faults".into(), value, text: text.to_owned(), append: true })
    }

    /// Where the value came from, for error messages.
    fn origin(&self) -> String {
        if self.append { format!("--fault {}", self.text) } else { format!("--set {}", self.text) }
    }
}

/// The names of the scenarios of `catalog`, for error messages.
fn names(catalog: &[ScenarioSchema]) -> String {
    catalog.iter().map(|s| s.name).collect::<Vec<_>>().join(", ")
}

fn find<'a>(catalog: &'a [ScenarioSchema], name: &str) -> Option<&'a ScenarioSchema> {
    catalog.iter().find(|s| s.name == name)
}

/// Resolves what the user asked to run, a scenario name or a launch-file path, with overrides,
/// into a checked configuration for one of the scenarios of `catalog` (the scenarios layer
/// passes its registry, and builds the scenario the configuration describes).
pub fn resolve_config(
    target: &str,
    overrides: &[Override],
    catalog: &[ScenarioSchema],
) -> Result<LaunchConfig, LaunchError> {
    let scenario_names = || names(catalog);
    // A scenario's name wins over a file of that name; anything else that looks like a path is one.
    let looks_like_path = find(catalog, target).is_none()
        && !Path::new(target).is_dir()
        && (target.ends_with(".toml") || target.contains('/') || Path::new(target).is_file());
    let (origin, document) = if looks_like_path {
        let text = std::fs::read_to_string(target)
            .map_err(|e| LaunchError::new(target, None, format!("cannot read the launch file: {e}")))?;
        let user: toml::Table = toml::from_str(&text).map_err(|e| toml_error(target, &text, &e))?;
        let name = match user.get("scenario") {
            Some(toml::Value::String(name)) => name.clone(),
            Some(_) => {
                return Err(LaunchError::new(
                    target,
                    Some("scenario"),
                    format!("must be a string; allowed: {}", scenario_names()),
                ));
            }
            None => {
                return Err(LaunchError::new(
                    target,
                    Some("scenario"),
                    format!("missing; allowed: {}", scenario_names()),
                ));
            }
        };
        let schema = find(catalog, &name).ok_or_else(|| {
            LaunchError::new(
                target,
                Some("scenario"),
                format!("unknown scenario \"{name}\"; allowed: {}", scenario_names()),
            )
        })?;
        let mut document = schema.defaults();
        merge(&mut document, user);
        (target.to_owned(), document)
    } else if Path::new(target).is_dir() {
        return Err(LaunchError::new(
            target,
            None,
            format!("is a folder; give a launch file (.toml) or a scenario name: {}", scenario_names()),
        ));
    } else {
        let schema = find(catalog, target).ok_or_else(|| {
            LaunchError::new(
                "command line",
                None,
                format!(
                    "unknown scenario \"{target}\"; allowed: {} (or a path to a .toml launch file)",
                    scenario_names()
                ),
            )
        })?;
        (schema.file.to_owned(), schema.defaults())
    };
    from_document(document, &origin, overrides, catalog)
}

/// Reads a resolved launch file written by the launcher (what each loop process does).
pub fn load_resolved_config(path: &Path, catalog: &[ScenarioSchema]) -> Result<LaunchConfig, LaunchError> {
    let origin = path.display().to_string();
    let text = std::fs::read_to_string(path)
        .map_err(|e| LaunchError::new(&origin, None, format!("cannot read the launch file: {e}")))?;
    let document: toml::Table = toml::from_str(&text).map_err(|e| toml_error(&origin, &text, &e))?;
    from_document(document, &origin, &[], catalog)
}

fn from_document(
    mut document: toml::Table,
    origin: &str,
    overrides: &[Override],
    catalog: &[ScenarioSchema],
) -> Result<LaunchConfig, LaunchError> {
    let mut origins = Origins { file: origin.to_owned(), set_keys: BTreeMap::new() };
    for o in overrides {
        let key =
            set_dotted(&mut document, o).map_err(|message| LaunchError::new(o.origin(), Some(&o.key), message))?;
        origins.set_keys.insert(key, o.origin());
    }
    // TOML allows nan and inf; no key of a launch file means either, and the checks below
    // (and the physics) can then assume finite numbers.
    document.iter().try_for_each(|(key, value)| check_finite(&origins, key, value))?;

    let scenario_name = match document.get("scenario") {
        Some(toml::Value::String(s)) => s.clone(),
        _ => return Err(origins.error("scenario", format!("missing or not a string; allowed: {}", names(catalog)))),
    };
    let schema = find(catalog, &scenario_name).ok_or_else(|| {
        origins.error("scenario", format!("unknown scenario \"{scenario_name}\"; allowed: {}", names(catalog)))
    })?;
    schema.check_fits()?;

    // Top-level keys: the shared ones, then the scenario's sections; anything else is a typo.
    let sections = schema.sections();
    let allowed: BTreeSet<&str> = COMMON_KEYS.iter().copied().chain(sections.iter().map(String::as_str)).collect();
    for key in document.keys() {
        if !allowed.contains(key.as_str()) {
            return Err(origins.error(
                key,
                format!(
                    "unknown key; allowed at the top level: {}",
                    allowed.iter().copied().collect::<Vec<_>>().join(", ")
                ),
            ));
        }
    }
    let mut common_table = toml::Table::new();
    for key in COMMON_KEYS {
        if let Some(v) = document.get(key) {
            common_table.insert(key.to_owned(), v.clone());
        }
    }
    let common: CommonKeys = deserialize_at(&origins, "", toml::Value::Table(common_table))?;
    let hosts = Hosts::parse(&common.hosts, |key, message| origins.error(key, message))?;

    let config = LaunchConfig {
        scenario: common.scenario,
        mode: common.mode,
        rate_hz: common.rate_hz,
        duration_s: common.duration_s,
        seed: common.seed,
        sensors: common.sensors.into_iter().filter(|(_, s)| s.enabled).collect(),
        faults: common.faults,
        supervision: common.supervision,
        wait: common.wait,
        hosts,
        document,
        schema: schema.clone(),
        origins,
    };
    check_common(&config)?;
    check_sensors(&config)?;
    check_supervision(&config.supervision, &config)?;
    check_wait(&config.wait, &config)?;
    for (i, fault) in config.faults.iter().enumerate() {
        check_fault(fault, &config, &format!("faults.{i}"))?;
    }
    Ok(config)
}

fn check_common(c: &LaunchConfig) -> Result<(), LaunchError> {
    if !(c.rate_hz.is_finite() && c.rate_hz > 0.0) {
        return Err(c.error("rate_hz", format!("must be a positive number of loops per second, got {}", c.rate_hz)));
    }
    if c.rate_hz > MAX_RATE_HZ {
        return Err(c.error("rate_hz", format!("must be at most {MAX_RATE_HZ} Hz, got {}", c.rate_hz)));
    }
    if !(c.duration_s.is_finite() && c.duration_s > 0.0 && c.duration_s <= MAX_DURATION_S) {
        return Err(c.error(
            "duration_s",
            format!("must be a positive number of seconds, at most {MAX_DURATION_S} (a week), got {}", c.duration_s),
        ));
    }
    if c.loops() == 0 {
        return Err(c.error("duration_s", format!("{} s at {} Hz is less than one loop", c.duration_s, c.rate_hz)));
    }
    if c.loops() > MAX_LOOPS {
        return Err(c.error(
            "duration_s",
            format!(
                "{} s at {} Hz is {} loops; at most {MAX_LOOPS} are allowed (shorten the run or lower rate_hz)",
                c.duration_s,
                c.rate_hz,
                c.loops()
            ),
        ));
    }
    if c.sensors.len() > MAX_SENSORS {
        return Err(c.error("sensors", format!("at most {MAX_SENSORS} sensors are supported, got {}", c.sensors.len())));
    }
    let dt = c.dt();
    for (name, s) in &c.sensors {
        let key = |field: &str| format!("sensors.{name}.{field}");
        let ticks = s.period_s * c.rate_hz;
        if !(s.period_s.is_finite() && s.period_s > 0.0) || ticks.round() < 1.0 || (ticks - ticks.round()).abs() > 1e-6
        {
            return Err(c.error(
                &key("period_s"),
                format!(
                    "{} s is not a whole multiple of the loop period {dt} s (rate_hz = {}); allowed: {dt}, {}, {}, ...",
                    s.period_s,
                    c.rate_hz,
                    2.0 * dt,
                    3.0 * dt
                ),
            ));
        }
        // A sensor slower than the run samples once, at loop 0; the bound keeps tick counts small.
        if s.period_s > MAX_DURATION_S {
            return Err(
                c.error(&key("period_s"), format!("must be at most {MAX_DURATION_S} s (a week), got {}", s.period_s))
            );
        }
        if u64::from(s.delay_ticks) > c.loops() {
            return Err(c.error(
                &key("delay_ticks"),
                format!("must be at most the run's {} loops, got {}", c.loops(), s.delay_ticks),
            ));
        }
        if !(s.quantum.is_finite() && s.quantum >= 0.0) {
            return Err(c.error(&key("quantum"), format!("must be 0 (none) or a positive step, got {}", s.quantum)));
        }
        for (field, value) in [("noise_std", &s.noise_std), ("bias", &s.bias)] {
            let values = match value {
                PerComponent::All(v) => vec![*v],
                PerComponent::Each(v) => v.clone(),
            };
            if values.iter().any(|v| !v.is_finite()) || (field == "noise_std" && values.iter().any(|v| *v < 0.0)) {
                return Err(c.error(&key(field), "must be finite (and not negative for noise_std)"));
            }
        }
    }
    Ok(())
}

fn check_sensors(c: &LaunchConfig) -> Result<(), LaunchError> {
    for (name, s) in &c.sensors {
        let Some(signal) = c.schema.signal(&s.signal) else {
            let names: Vec<_> = c.schema.signals.iter().map(|sig| sig.name).collect();
            return Err(c.error(
                &format!("sensors.{name}.signal"),
                format!("unknown signal \"{}\"; allowed: {}", s.signal, names.join(", ")),
            ));
        };
        let dim = signal.components.len();
        for (field, value) in [("noise_std", &s.noise_std), ("bias", &s.bias)] {
            if let PerComponent::Each(v) = value
                && v.len() != dim
            {
                return Err(c.error(
                    &format!("sensors.{name}.{field}"),
                    format!(
                        "signal \"{}\" has {dim} components, so give one number or {dim}; got {}",
                        s.signal,
                        v.len()
                    ),
                ));
            }
        }
    }
    Ok(())
}

/// Rejects NaN and ±inf anywhere in `value`, found at dotted `key` (list items by index).
fn check_finite(origins: &Origins, key: &str, value: &toml::Value) -> Result<(), LaunchError> {
    let child = |part: &dyn fmt::Display| format!("{key}.{part}");
    match value {
        toml::Value::Float(v) if !v.is_finite() => {
            Err(origins.error(key, format!("must be a finite number, got {v}; nan and inf are not allowed")))
        }
        toml::Value::Table(table) => table.iter().try_for_each(|(k, v)| check_finite(origins, &child(k), v)),
        toml::Value::Array(items) => {
            items.iter().enumerate().try_for_each(|(i, v)| check_finite(origins, &child(&i), v))
        }
        _ => Ok(()),
    }
}

/// A TOML syntax error on one line: where, and what.
fn toml_error(origin: &str, text: &str, e: &toml::de::Error) -> LaunchError {
    let message = e.message().lines().collect::<Vec<_>>().join(", ");
    let place = e.span().map(|span| {
        let before = &text[..span.start.min(text.len())];
        let line = before.matches('\n').count() + 1;
        let column = before.len() - before.rfind('\n').map_or(0, |i| i + 1) + 1;
        format!("line {line}, column {column}: ")
    });
    LaunchError::new(origin, None, format!("not valid TOML: {}{message}", place.unwrap_or_default()))
}

/// Deserialises `value` (found at dotted `key`) and turns a failure into an error that names
/// the full dotted path of the offending key.
fn deserialize_at<T: DeserializeOwned>(origins: &Origins, key: &str, value: toml::Value) -> Result<T, LaunchError> {
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

/// Deep-merges `over` into `base`: tables merge key by key, anything else replaces.
pub fn merge(base: &mut toml::Table, over: toml::Table) {
    for (key, value) in over {
        match (base.get_mut(&key), value) {
            (Some(toml::Value::Table(b)), toml::Value::Table(o)) => merge(b, o),
            (_, value) => {
                base.insert(key, value);
            }
        }
    }
}

/// Sets a dotted key, or appends to the array at it; returns the key that was set (for an
/// append, with the new element's index). A number in the path indexes an array
/// (`faults.0.delay_ticks`). An integer written where the defaults hold a float is taken as that
/// float, so `--set duration_s=30` works.
fn set_dotted(document: &mut toml::Table, o: &Override) -> Result<String, String> {
    let parts: Vec<&str> = o.key.split('.').collect();
    let (last, parents) = parts.split_last().expect("keys are checked to be non-empty");
    let mut root = toml::Value::Table(std::mem::take(document));
    let result = (|| {
        let mut value = &mut root;
        for (i, part) in parents.iter().enumerate() {
            let path = parts[..i].join(".");
            value = match value {
                toml::Value::Table(t) => {
                    t.entry(part.to_string()).or_insert_with(|| toml::Value::Table(toml::Table::new()))
                }
                toml::Value::Array(items) => {
                    let len = items.len();
                    let index = part.parse::<usize>().ok().filter(|i| *i < len);
                    index.and_then(|i| items.get_mut(i)).ok_or_else(|| {
                        format!("`{path}` is a list of {len}; index it with 0 to {}", len.saturating_sub(1))
                    })?
                }
                _ => return Err(format!("`{path}` is a value, not a table, so it has no key `{part}`")),
            };
        }
        // One item of a list (`model.inertia_kg_m2.1`).
        if let toml::Value::Array(items) = value
            && !o.append
        {
            let len = items.len();
            let item = last.parse::<usize>().ok().and_then(|i| items.get_mut(i)).ok_or_else(|| {
                format!("`{}` is a list of {len}; index it with 0 to {}", parents.join("."), len.saturating_sub(1))
            })?;
            *item = match (&*item, &o.value) {
                (toml::Value::Float(_), toml::Value::Integer(i)) => toml::Value::Float(*i as f64),
                (_, v) => v.clone(),
            };
            return Ok(o.key.clone());
        }
        let toml::Value::Table(table) = value else {
            return Err(format!("`{}` is not a table, so it has no key `{last}`", parents.join(".")));
        };
        if o.append {
            let items = table.entry(last.to_string()).or_insert_with(|| toml::Value::Array(vec![]));
            let toml::Value::Array(items) = items else { return Err(format!("`{}` is not a list", o.key)) };
            items.push(o.value.clone());
            return Ok(format!("{}.{}", o.key, items.len() - 1));
        }
        let value = match (table.get(*last), &o.value) {
            (Some(toml::Value::Float(_)), toml::Value::Integer(i)) => toml::Value::Float(*i as f64),
            (Some(toml::Value::Table(_)), v) if !v.is_table() => {
                return Err(format!("`{}` is a table; set one of its keys instead", o.key));
            }
            (_, v) => v.clone(),
        };
        table.insert(last.to_string(), value);
        Ok(o.key.clone())
    })();
    let toml::Value::Table(table) = root else { unreachable!("the root stays a table") };
    *document = table;
    result
}

/// Checks the fault against the run; `key` is its dotted key (`faults.2`).
fn check_fault(f: &FaultSpec, c: &LaunchConfig, key: &str) -> Result<(), LaunchError> {
    let field = |f: &str| format!("{key}.{f}");
    let targets = f.kind.targets();
    if !f.process.parse::<Role>().is_ok_and(|role| targets.contains(&role)) {
        let allowed: Vec<&str> = targets.iter().map(|r| r.name()).collect();
        return Err(c.error(
            &field("process"),
            format!("a {} fault cannot target \"{}\"; allowed: {}", f.kind.name(), f.process, allowed.join(", ")),
        ));
    }
    if Role::BRIDGES.iter().any(|r| r.name() == f.process) && c.hosts.remote().is_none() {
        return Err(c.error(
            &field("process"),
            format!("no {} runs: no stage is placed on another host (hosts.<stage> = \"<host>\")", f.process),
        ));
    }
    if !(f.at_s.is_finite() && f.at_s >= 0.0 && f.at_s < c.duration_s) {
        return Err(c.error(
            &field("at_s"),
            format!("must be a time within the run, 0 ≤ at_s < {} s, got {}", c.duration_s, f.at_s),
        ));
    }
    if let Some(d) = f.duration_s {
        // A stop lasts wall-clock seconds; the others simulation time, where anything past
        // the run's end means "to the end".
        let (most, what) = if f.kind == FaultKind::Stop {
            (MAX_STOP_S, "wall-clock seconds, at most 3600 (an hour)")
        } else {
            (MAX_DURATION_S, "seconds, at most 604800 (a week; leave it out for \"to the end of the run\")")
        };
        if !(d.is_finite() && d > 0.0 && d <= most) {
            return Err(c.error(&field("duration_s"), format!("must be a positive number of {what}, got {d}")));
        }
    }
    let only = |name: &str, present: bool, kind: FaultKind| -> Result<(), LaunchError> {
        if present && f.kind != kind {
            return Err(c.error(&field(name), format!("applies to {} faults only", kind.name())));
        }
        Ok(())
    };
    only("delay_s", f.delay_s.is_some(), FaultKind::Delay)?;
    only("delay_ticks", f.delay_ticks.is_some(), FaultKind::Delay)?;
    only("probability", f.probability.is_some(), FaultKind::Drop)?;
    only("value", f.value.is_some(), FaultKind::Corrupt)?;
    match f.kind {
        FaultKind::Kill if f.duration_s.is_some() => {
            Err(c.error(&field("duration_s"), "a kill has no duration (the process is restarted, or not)"))
        }
        FaultKind::Stop if f.duration_s.is_none() => {
            Err(c.error(&field("duration_s"), "a stop needs the seconds it lasts before SIGCONT"))
        }
        FaultKind::Delay => match (f.delay_s, f.delay_ticks) {
            (Some(_), Some(_)) | (None, None) => {
                Err(c.error(&field("delay_s"), "give exactly one of delay_s (seconds) and delay_ticks (loops)"))
            }
            (Some(d), None) if !(d.is_finite() && d >= 0.0 && d < c.duration_s) => Err(c.error(
                &field("delay_s"),
                format!("must be 0 or more seconds, less than the run's duration_s = {} s, got {d}", c.duration_s),
            )),
            (None, Some(t)) if u64::from(t) > c.loops() => {
                Err(c.error(&field("delay_ticks"), format!("must be at most the run's {} loops, got {t}", c.loops())))
            }
            _ => Ok(()),
        },
        FaultKind::Drop => match f.probability {
            Some(p) if (0.0..=1.0).contains(&p) => Ok(()),
            Some(p) => Err(c.error(&field("probability"), format!("must be between 0 and 1, got {p}"))),
            None => Err(c.error(&field("probability"), "a drop needs the chance, 0 to 1, that each output is lost")),
        },
        _ => Ok(()),
    }
}

fn check_supervision(s: &Supervision, c: &LaunchConfig) -> Result<(), LaunchError> {
    let timeout = |key: &str, v: f64| {
        if v.is_finite() && v > 0.0 && v <= MAX_TIMEOUT_S {
            Ok(())
        } else {
            Err(c.error(
                &format!("supervision.{key}"),
                format!("must be a positive number of seconds, at most {MAX_TIMEOUT_S} (an hour), got {v}"),
            ))
        }
    };
    timeout("stall_timeout_s", s.stall_timeout_s)?;
    timeout("command_timeout_s", s.command_timeout_s)?;
    timeout("lockstep_stall_s", s.lockstep_stall_s)?;
    timeout("backoff_reset_s", s.backoff_reset_s)?;
    for role in Role::ALL {
        // The key to blame: the process's own, or the default it took.
        let key = |field: &str| {
            let own = match field {
                "backoff_s" => s.policy_of(role).backoff_s.is_some(),
                _ => s.policy_of(role).max_restarts.is_some(),
            };
            if own { format!("supervision.{role}.{field}") } else { format!("supervision.{field}") }
        };
        let policy = s.policy(role);
        if !(policy.backoff_s.is_finite() && policy.backoff_s >= 0.0 && policy.backoff_s <= MAX_BACKOFF_S) {
            return Err(
                c.error(&key("backoff_s"), format!("must be 0 to {MAX_BACKOFF_S} seconds, got {}", policy.backoff_s))
            );
        }
        if policy.max_restarts > MAX_RESTARTS {
            return Err(c.error(
                &key("max_restarts"),
                format!("must be 0 to {MAX_RESTARTS} restarts per process and run, got {}", policy.max_restarts),
            ));
        }
    }
    Ok(())
}

fn check_wait(w: &WaitSettings, config: &LaunchConfig) -> Result<(), LaunchError> {
    for (key, value) in [("wait.lead_us", Some(w.lead_us)), ("wait.spin_cap_us", w.spin_cap_us)] {
        let Some(value) = value else { continue };
        if !(value.is_finite() && (0.0..=MAX_WAIT_US).contains(&value)) {
            return Err(config.error(key, format!("must be 0 to {MAX_WAIT_US} µs (a second), got {value}")));
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The text of each enum comes from its derives, the same in a launch file, summary.json
    /// and every message.
    #[test]
    fn enum_text_is_derived_and_the_same_everywhere() {
        use crate::config::wait::Strategy;
        fn same<T: Serialize>(value: T, name: &str) {
            assert_eq!(serde_json::to_value(value).unwrap().as_str(), Some(name));
        }
        for kind in [FaultKind::Kill, FaultKind::Stop, FaultKind::Delay, FaultKind::Drop, FaultKind::Corrupt] {
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

    /// A scenario whose estimate is larger than a message carries cannot be resolved: the error
    /// names the scenario and the vector (and no child process ever starts).
    #[test]
    fn a_scenario_whose_vectors_do_not_fit_the_messages_is_an_error_at_resolution() {
        use crate::config::schema::Component;
        const E60: &[Component] = &[Component::new("e", "1"); 60];
        let schema = ScenarioSchema {
            name: "made-up",
            file: "launch/made-up.toml",
            text: "scenario = \"made-up\"\nmode = \"lockstep\"\nrate_hz = 100.0\nduration_s = 1.0\nseed = 1\n",
            state: &[],
            input: &[],
            estimate: E60,
            signals: vec![],
        };
        let e = resolve_config("made-up", &[], std::slice::from_ref(&schema)).unwrap_err();
        assert_eq!(
            e.to_string(),
            "scenario made-up: the estimate has 60 components, more than the 48 a message carries"
        );
        let fits = ScenarioSchema { estimate: &E60[..48], ..schema };
        let c = resolve_config("made-up", &[], &[fits]).unwrap();
        assert_eq!((c.scenario.as_str(), c.loops()), ("made-up", 100));
    }

    #[test]
    fn override_parsing() {
        assert_eq!(Override::parse("a.b=1.5").unwrap().value, toml::Value::Float(1.5));
        assert_eq!(Override::parse("a=no-bias").unwrap().value, toml::Value::String("no-bias".into()));
        assert_eq!(Override::parse("a=[1, 2]").unwrap().value.as_array().unwrap().len(), 2);
        assert!(Override::parse("novalue").is_err());
        assert!(Override::parse("a..b=1").is_err());
    }
}
