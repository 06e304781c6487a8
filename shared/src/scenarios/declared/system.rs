//! A declared system's description, read from its launch file: the `[system]` vectors (checked
//! by the configuration layer, `config::launch::declared`), the `[plant]` (which model, its
//! sub-steps, its parameters), the built-in `[controller]`, and what its stages may read.

use std::path::{Path, PathBuf};

use serde::Deserialize;

use crate::config::launch::declared::{LinearSection, PlantSection, SystemSection};
use crate::config::launch::{LaunchConfig, LaunchError};
use crate::contract::role::Role;
use crate::model::plant_model::ModelSpec;
use crate::model::reference::{NamedReference, Signal, declared_references};
use crate::model::scenario::check_substeps;
use crate::scenarios::declared::fmu::FmiKind;

/// Where the plant's model comes from (`[plant]`: exactly one of these keys).
#[derive(Debug, Clone, PartialEq)]
pub enum PlantSource {
    /// `[plant.linear]`: ẋ = A x + B u, y = C x + D u, built in.
    Linear(LinearSection),
    /// `[plant] fmu = "model.fmu"`: the FMU's path, absolute (`fmu::load`).
    Fmu(PathBuf),
    /// `[plant] python = "my_plant.py:Pendulum"`: the file (absolute) and the class. The plant
    /// role runs as a python3 process over it (`runtime::stage::user_plant`); no Rust process builds it.
    Python { file: PathBuf, class: String },
}

/// `[controller]`: the built-in state feedback u = −K (x̂ − r), clamped to the input's limits, for a
/// first run without a controller of the user's own (`[stages.controller]`).
#[derive(Debug, Clone, Default, Deserialize)]
#[serde(deny_unknown_fields)]
struct ControllerSection {
    /// K, one row per input, one column per estimate component.
    #[serde(default)]
    gains: Option<Vec<Vec<f64>>>,
}

/// Everything a declared system's parts are built from.
#[derive(Debug, Clone)]
pub struct System {
    pub vectors: SystemSection,
    pub source: PlantSource,
    /// What a plant model is built from (names in order, initial values, parameters, dt).
    pub spec: ModelSpec,
    pub substeps: u32,
    pub input_limits: Vec<(f64, f64)>,
    /// The built-in controller's K (rows: inputs); None: `[stages.controller]` runs instead.
    pub gains: Option<Vec<Vec<f64>>>,
    /// Per estimate component, the reference it should follow (None: zero).
    pub setpoints: Vec<Option<Signal>>,
    /// For the pass-through estimator: each estimate component's (sensor, component) reading;
    /// None where `[stages.estimator]` runs instead.
    pub pass_through: Option<Vec<(usize, usize)>>,
    /// The launch file's folder (a python or fmu path in the file is relative to it).
    pub folder: PathBuf,
    /// `[plant] fmu_interface`; None: Model Exchange where the FMU offers it.
    pub fmu_interface: Option<FmiKind>,
}

/// Checks that `rows` is a `rows × cols` matrix of finite numbers.
fn check_matrix(c: &LaunchConfig, key: &str, m: &[Vec<f64>], rows: usize, cols: usize) -> Result<(), LaunchError> {
    let shape =
        |m: &[Vec<f64>]| format!("{} rows of {:?} numbers", m.len(), m.iter().map(Vec::len).collect::<Vec<_>>());
    if m.len() != rows || m.iter().any(|r| r.len() != cols) {
        return Err(c.error(key, format!("must be {rows} × {cols} (rows × columns), got {}", shape(m))));
    }
    Ok(())
}

impl System {
    pub fn from_config(c: &LaunchConfig) -> Result<Self, LaunchError> {
        let vectors = c.system()?;
        let plant: PlantSection = c.section("plant")?;
        check_substeps(c, "plant.substeps", plant.substeps)?;
        let (n, m, p) = (vectors.state.len(), vectors.input.len(), vectors.outputs.len());
        let given: Vec<&str> =
            [("linear", plant.linear.is_some()), ("fmu", plant.fmu.is_some()), ("python", plant.python.is_some())]
                .iter()
                .filter(|(_, present)| *present)
                .map(|(key, _)| *key)
                .collect();
        if given.len() != 1 {
            return Err(c.error(
                "plant",
                format!(
                    "give exactly one plant model: [plant.linear] (a, b, c, d), fmu = \"model.fmu\" or python = \
                     \"file.py:Class\"; got {}",
                    if given.is_empty() { "none".to_owned() } else { given.join(" and ") }
                ),
            ));
        }
        let spec = ModelSpec::declared(c, &vectors, &plant);
        let folder = spec.folder.clone();
        let source = if let Some(linear) = plant.linear {
            check_matrix(c, "plant.linear.a", &linear.a, n, n)?;
            check_matrix(c, "plant.linear.b", &linear.b, n, m)?;
            check_matrix(c, "plant.linear.c", &linear.c, p, n)?;
            if !linear.d.is_empty() {
                check_matrix(c, "plant.linear.d", &linear.d, p, m)?;
            }
            PlantSource::Linear(linear)
        } else if let Some(fmu) = plant.fmu {
            PlantSource::Fmu(folder.join(fmu))
        } else {
            let text = plant.python.unwrap_or_default();
            let Some((file, class)) = text.rsplit_once(':').filter(|(f, c)| !f.is_empty() && !c.is_empty()) else {
                return Err(c.error("plant.python", format!("\"{text}\": write \"file.py:ClassName\"")));
            };
            PlantSource::Python { file: folder.join(file), class: class.to_owned() }
        };
        let fmu_interface = match plant.fmu_interface.as_deref() {
            None => None,
            Some(_) if !matches!(source, PlantSource::Fmu(_)) => {
                return Err(c.error("plant.fmu_interface", "is for an FMU plant (fmu = \"model.fmu\")"));
            }
            Some(text) => Some(
                FmiKind::parse(text)
                    .ok_or_else(|| c.error("plant.fmu_interface", format!("\"{text}\": one of {}", FmiKind::NAMES)))?,
            ),
        };
        if !plant.parameters.is_empty() && matches!(source, PlantSource::Linear(_)) {
            return Err(c.error("plant.parameters", "a linear plant has no parameters (its matrices are its model)"));
        }

        let controller: ControllerSection = c.section("controller")?;
        let estimate = vectors.estimate();
        let user_controller = c.stages.commands.contains_key(&Role::Controller);
        let gains = match (controller.gains, user_controller) {
            (Some(_), true) => {
                return Err(c.error(
                    "controller.gains",
                    "[stages.controller] runs a controller of your own; leave out the built-in one's gains",
                ));
            }
            (Some(k), false) => {
                check_matrix(c, "controller.gains", &k, m, estimate.len())?;
                Some(k)
            }
            (None, true) => None,
            (None, false) => {
                return Err(c.error(
                    "controller",
                    "a declared system needs a controller: [stages.controller] command = \"...\" (your own) or \
                     [controller] gains = [[...]] (the built-in u = −K x̂, one row per input)",
                ));
            }
        };
        // A replay that plays the estimator back needs none of its own.
        let played_back = c.replay.as_ref().is_some_and(|r| r.plays_back(Role::Estimator));
        let pass_through = if c.stages.commands.contains_key(&Role::Estimator) || played_back {
            None
        } else {
            // Each estimate component from the first sensor that reads a component of its name.
            let read_by: Vec<(usize, usize, &str)> = c
                .sensors
                .values()
                .enumerate()
                .flat_map(|(i, s)| s.reads.iter().enumerate().map(move |(j, r)| (i, j, r.as_str())))
                .collect();
            let mut picks = Vec::new();
            for (i, e) in estimate.iter().enumerate() {
                let found = read_by.iter().find(|(_, _, read)| read.split_once('.').is_some_and(|(_, n)| n == e.name));
                let Some(&(sensor, component, _)) = found else {
                    return Err(c.error(
                        &format!("system.estimate.{i}.name"),
                        format!(
                            "the built-in pass-through estimator takes each estimate component from a sensor that \
                             reads it, and no sensor reads \"{}\"; add it to a sensor's reads, or run \
                             [stages.estimator]",
                            e.name
                        ),
                    ));
                };
                picks.push((sensor, component));
            }
            Some(picks)
        };
        let input_limits = vectors.input.iter().map(|u| (u.min, u.max)).collect();
        // The built-in controller's setpoint: each estimate component's reference, where one
        // tracks the state or output component of its name.
        let references = declared_references(c)?;
        let setpoints = estimate
            .iter()
            .map(|e| {
                let tracks = |r: &&NamedReference| r.track.split_once('.').is_some_and(|(_, name)| name == e.name);
                references.iter().find(tracks).map(|r| r.signal.clone())
            })
            .collect();
        Ok(System {
            vectors,
            source,
            spec,
            substeps: plant.substeps,
            input_limits,
            gains,
            setpoints,
            pass_through,
            folder,
            fmu_interface,
        })
    }

    /// One line for reports: what the plant is.
    pub fn plant_title(&self) -> String {
        let name = |p: &Path| p.file_name().map(|f| f.to_string_lossy().into_owned()).unwrap_or_default();
        match &self.source {
            PlantSource::Linear(_) => "linear state-space plant".to_owned(),
            PlantSource::Fmu(path) => format!("FMU plant {}", name(path)),
            PlantSource::Python { file, class } => format!("Python plant {}:{class}", name(file)),
        }
    }
}
