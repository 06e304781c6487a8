//! A declared system: a launch file with no `scenario` and a `[system]` table names its own
//! vectors, and its sensors name what they read (`reads = ["state.theta"]`). What such a file is
//! checked against is made from the file itself ([`declared_schema`]); the names are leaked,
//! once per resolution, to be the `&'static` components every scenario has.

use std::collections::BTreeMap;
use std::path::PathBuf;

use serde::{Deserialize, Serialize};

use crate::config::error::LaunchError;
use crate::config::launch::types::{LaunchConfig, Origins, deserialize_at};
use crate::config::schema::{Component, ScenarioSchema, SignalLayout};
use crate::contract::msg::{MAX_ESTIMATE, MAX_INPUT, MAX_SENSOR_DIM, MAX_STATE};

/// The name a declared system's configuration carries (`LaunchConfig::scenario`).
pub const DECLARED: &str = "declared";

/// What a declared file is merged over: the run's common defaults and the sections a declared
/// system may have (empty; each is checked by the part that reads it).
pub const DECLARED_DEFAULTS: &str = r#"
mode = "realtime"
rate_hz = 100.0
duration_s = 10.0
seed = 1

[system]
[plant]
[parameters]
[controller]
[limits]
[reference]
"#;

/// `[system]`: the declared vectors, in order.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SystemSection {
    pub state: Vec<StateComponent>,
    pub input: Vec<InputComponent>,
    /// What the plant computes from its state and input (y = g(t, x, u)); published after the
    /// state in the state message.
    #[serde(default)]
    pub outputs: Vec<NamedComponent>,
    /// What the estimator writes; None: the state's components (the built-in pass-through).
    #[serde(default)]
    pub estimate: Option<Vec<NamedComponent>>,
}

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct StateComponent {
    pub name: String,
    pub unit: String,
    /// Where it starts; None: the model's own start value (0 for `[plant.linear]`).
    #[serde(default)]
    pub initial: Option<f64>,
}

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct InputComponent {
    pub name: String,
    pub unit: String,
    /// The closed range the actuator accepts; the plant rejects a command outside it.
    pub min: f64,
    pub max: f64,
}

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct NamedComponent {
    pub name: String,
    pub unit: String,
}

/// Which vector a sensor's read names.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Source {
    State,
    Output,
    Input,
}

impl SystemSection {
    /// The estimate's components: declared, or the state's.
    pub fn estimate(&self) -> Vec<NamedComponent> {
        self.estimate.clone().unwrap_or_else(|| {
            self.state.iter().map(|c| NamedComponent { name: c.name.clone(), unit: c.unit.clone() }).collect()
        })
    }

    /// `"state.theta"` → (State, index, unit); an error names what the vector has.
    pub fn find(&self, read: &str) -> Result<(Source, usize, &str), String> {
        let (vector, name) = read.split_once('.').unwrap_or(("", read));
        let named: Vec<(&str, &str)> = match vector {
            "state" => self.state.iter().map(|c| (c.name.as_str(), c.unit.as_str())).collect(),
            "output" => self.outputs.iter().map(|c| (c.name.as_str(), c.unit.as_str())).collect(),
            "input" => self.input.iter().map(|c| (c.name.as_str(), c.unit.as_str())).collect(),
            _ => {
                return Err(format!(
                    "\"{read}\" names no vector; write \"state.<name>\", \"output.<name>\" or \"input.<name>\""
                ));
            }
        };
        let source = match vector {
            "state" => Source::State,
            "output" => Source::Output,
            _ => Source::Input,
        };
        match named.iter().position(|(n, _)| *n == name) {
            Some(i) => Ok((source, i, named[i].1)),
            None => Err(format!(
                "\"{read}\": the {vector} has no component \"{name}\"; it has: {}",
                named.iter().map(|(n, _)| *n).collect::<Vec<_>>().join(", ")
            )),
        }
    }
}

/// `[plant.linear]`: the matrices, row by row.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct LinearSection {
    /// n × n.
    pub a: Vec<Vec<f64>>,
    /// n × m (m inputs).
    pub b: Vec<Vec<f64>>,
    /// p × n (p outputs); leave out when no outputs are declared.
    #[serde(default)]
    pub c: Vec<Vec<f64>>,
    /// p × m; left out: zero.
    #[serde(default)]
    pub d: Vec<Vec<f64>>,
}

/// `[plant]` of a declared system.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PlantSection {
    #[serde(default)]
    pub linear: Option<LinearSection>,
    #[serde(default)]
    pub fmu: Option<String>,
    /// Which of the FMU's interfaces runs it: "model-exchange" or "co-simulation" (default: Model
    /// Exchange where the FMU offers it).
    #[serde(default)]
    pub fmu_interface: Option<String>,
    #[serde(default)]
    pub python: Option<String>,
    /// RK4 steps per loop period (a model LoopLab integrates).
    #[serde(default = "one")]
    pub substeps: u32,
    /// Set before the model initialises (an FMU's parameters by name).
    #[serde(default)]
    pub parameters: BTreeMap<String, f64>,
    /// The folder `fmu` and `python` are relative to: the launch file's (written at resolve).
    #[serde(default)]
    pub folder: Option<PathBuf>,
}

fn one() -> u32 {
    1
}

/// Whether `document` declares a system: no `scenario`, and a `[system]` table.
pub fn is_declared(document: &toml::Table) -> bool {
    !document.contains_key("scenario") && document.contains_key("system")
}

/// A component's name becomes a column of trajectory.csv and a field name in the MCAP file.
fn check_name(origins: &Origins, key: &str, name: &str) -> Result<(), LaunchError> {
    let ok = name.chars().next().is_some_and(|c| c.is_ascii_alphabetic() || c == '_')
        && name.chars().all(|c| c.is_ascii_alphanumeric() || c == '_');
    if ok {
        Ok(())
    } else {
        Err(origins.error(key, format!("\"{name}\" is not a name: use letters, digits and _, starting with a letter")))
    }
}

pub(super) fn leak_components(items: impl IntoIterator<Item = (String, String)>) -> &'static [Component] {
    let components: Vec<Component> =
        items.into_iter().map(|(name, unit)| Component::new(name.leak(), unit.leak())).collect();
    components.leak()
}

/// The `[system]` of `document`, checked: names, limits, sizes against the messages.
pub(super) fn system_section(document: &toml::Table, origins: &Origins) -> Result<SystemSection, LaunchError> {
    let value = document.get("system").cloned().unwrap_or(toml::Value::Table(toml::Table::new()));
    let system: SystemSection = deserialize_at(origins, "system", value)?;
    let estimate = system.estimate();
    let vectors: [(&str, Vec<&str>); 4] = [
        ("state", system.state.iter().map(|c| c.name.as_str()).collect()),
        ("input", system.input.iter().map(|c| c.name.as_str()).collect()),
        ("outputs", system.outputs.iter().map(|c| c.name.as_str()).collect()),
        ("estimate", estimate.iter().map(|c| c.name.as_str()).collect()),
    ];
    for (vector, names) in &vectors {
        for (i, name) in names.iter().enumerate() {
            check_name(origins, &format!("system.{vector}.{i}.name"), name)?;
            if names[..i].contains(name) {
                return Err(
                    origins.error(&format!("system.{vector}.{i}.name"), format!("\"{name}\" is declared twice"))
                );
            }
        }
    }
    if let Some(name) = vectors[2].1.iter().find(|n| vectors[0].1.contains(n)) {
        return Err(origins.error(
            "system.outputs",
            format!("\"{name}\" is both a state and an output component; the state message carries both, by name"),
        ));
    }
    for (vector, len) in [("state", system.state.len()), ("input", system.input.len())] {
        if len == 0 {
            return Err(origins.error(&format!("system.{vector}"), "declare at least one component"));
        }
    }
    let sizes = [
        (
            "system.state",
            "the state and the outputs have",
            system.state.len() + system.outputs.len(),
            MAX_STATE,
            "state",
        ),
        ("system.input", "the input has", system.input.len(), MAX_INPUT, "command"),
        ("system.estimate", "the estimate has", estimate.len(), MAX_ESTIMATE, "estimate"),
    ];
    for (key, what, len, max, message) in sizes {
        if len > max {
            return Err(
                origins.error(key, format!("{what} {len} components, more than the {max} a {message} message carries"))
            );
        }
    }
    for (i, c) in system.input.iter().enumerate() {
        if c.min > c.max {
            return Err(origins.error(
                &format!("system.input.{i}.min"),
                format!("must be at most max ({}), got {} for \"{}\"", c.max, c.min, c.name),
            ));
        }
    }
    Ok(system)
}

/// What a declared file is checked against, from its own `[system]` and sensors: the state is
/// the state message (the state, then the outputs), and each sensor is a signal of its own name
/// whose components are what it `reads`.
pub(super) fn declared_schema(document: &toml::Table, origins: &Origins) -> Result<ScenarioSchema, LaunchError> {
    let system = system_section(document, origins)?;
    let state = leak_components(
        system
            .state
            .iter()
            .map(|c| (c.name.clone(), c.unit.clone()))
            .chain(system.outputs.iter().map(|c| (c.name.clone(), c.unit.clone()))),
    );
    let input = leak_components(system.input.iter().map(|c| (c.name.clone(), c.unit.clone())));
    let estimate = leak_components(system.estimate().into_iter().map(|c| (c.name, c.unit)));
    let mut signals = Vec::new();
    if let Some(toml::Value::Table(sensors)) = document.get("sensors") {
        for (name, sensor) in sensors {
            let reads = sensor.get("reads").cloned().unwrap_or(toml::Value::Array(vec![]));
            let key = format!("sensors.{name}.reads");
            if sensor.get("signal").is_some() {
                return Err(origins.error(
                    &format!("sensors.{name}.signal"),
                    "a declared system's sensor names what it reads: reads = [\"state.<name>\", ...]",
                ));
            }
            let reads: Vec<String> = deserialize_at(origins, &key, reads)?;
            if reads.is_empty() {
                return Err(origins.error(
                    &key,
                    "missing; name what the sensor reads: \"state.<name>\", \"output.<name>\" or \"input.<name>\"",
                ));
            }
            if reads.len() > MAX_SENSOR_DIM {
                return Err(origins.error(
                    &key,
                    format!("{} components, more than the {MAX_SENSOR_DIM} a sensor's reading carries", reads.len()),
                ));
            }
            let mut components = Vec::new();
            for (i, read) in reads.iter().enumerate() {
                let (_, _, unit) = system.find(read).map_err(|m| origins.error(&format!("{key}.{i}"), m))?;
                let component = read.split_once('.').map_or(read.as_str(), |(_, n)| n);
                components.push((component.to_owned(), unit.to_owned()));
            }
            signals.push(SignalLayout { name: name.clone().leak(), components: leak_components(components) });
        }
    }
    let schema = ScenarioSchema {
        name: DECLARED,
        file: origins.file.clone().leak(),
        text: DECLARED_DEFAULTS,
        state,
        input,
        estimate,
        signals,
    };
    schema.check_fits()?;
    Ok(schema)
}

impl LaunchConfig {
    /// A declared system's `[system]`, checked (as it was at load).
    pub fn system(&self) -> Result<SystemSection, LaunchError> {
        system_section(&self.document, &self.origins)
    }

    /// The declared system's `[plant]`.
    pub fn plant_section(&self) -> Result<PlantSection, LaunchError> {
        self.section("plant")
    }

    /// The file (or command line) the configuration came from, for a model's error messages.
    pub fn origin_file(&self) -> String {
        self.origins.file.clone()
    }

    /// Whether this configuration declares its own system.
    pub fn is_declared(&self) -> bool {
        self.schema.name == DECLARED
    }
}
