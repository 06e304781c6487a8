//! A declared system's plant from an FMU (`[plant] fmu = "model.fmu"`): FMI 2.0 and 3.0, Model
//! Exchange (LoopLab integrates the derivatives) and Co-Simulation (the FMU's own doStep).
//!
//! Crates: `fmi-schema` reads modelDescription.xml, `zip` unpacks, `libloading` opens the binary,
//! and [`ffi`] is a small hand-written table of the FMI C functions called (the `fmi` crate
//! would generate them with bindgen, which needs libclang at build time).
//!
//! The declared names map to the FMU's variables by name: the state to its continuous states
//! (Model Exchange: all of them, in any order) or to any Real variables (Co-Simulation), the input
//! to its inputs, the outputs to any Real variables, `[plant.parameters]` to its parameters.

mod archive;
mod description;
mod ffi;
mod model;
#[cfg(test)]
mod tests;

use std::path::Path;

pub use archive::{build_fmu, pendulum_source, platform, remove_abandoned_unpack_folders};
pub use description::Version;

use crate::model::plant_model::{ModelSpec, PlantModel};
use description::{Causality, Description, Kind};

/// Which of the FMU's interfaces runs it.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum FmiKind {
    ModelExchange,
    CoSimulation,
}

impl FmiKind {
    /// The launch file's spelling.
    pub const NAMES: &str = "model-exchange, co-simulation";

    pub fn parse(text: &str) -> Option<FmiKind> {
        match text {
            "model-exchange" => Some(FmiKind::ModelExchange),
            "co-simulation" => Some(FmiKind::CoSimulation),
            _ => None,
        }
    }

    fn label(self) -> &'static str {
        match self {
            FmiKind::ModelExchange => "Model Exchange",
            FmiKind::CoSimulation => "Co-Simulation",
        }
    }
}

/// The FMU as a plant model: Model Exchange where it offers it, else Co-Simulation.
pub fn load(spec: &ModelSpec, fmu: &Path) -> Result<Box<dyn PlantModel>, String> {
    load_as(spec, fmu, None)
}

/// The FMU as a plant model through the interface `kind` (None: Model Exchange where offered).
/// A relative `fmu` is relative to the launch file's folder. Every error is one line that starts
/// with the FMU's file name (the caller names the launch file and its key).
pub fn load_as(spec: &ModelSpec, fmu: &Path, kind: Option<FmiKind>) -> Result<Box<dyn PlantModel>, String> {
    let Checked { archive, interface, kind, map, label } = check(spec, fmu, kind)?;
    let describe = format!("{label}, {} {}", archive.description.version.label(), kind.label());
    let unpacked = archive.unpack(&label)?;
    model::FmuModel::new(unpacked, interface, kind, map, spec, label.clone(), describe)
        .map(|m| Box::new(m) as Box<dyn PlantModel>)
        .map_err(|e| format!("{label}: {e:#}"))
}

/// Checks the FMU against the declared system without running any of its code: its description,
/// the interface, the names mapped, its binary. The launcher checks this way; the FMU's code runs
/// only in the plant process, which the launcher supervises (a crash, an exit or a hang while it
/// loads is that process's, and fails the run).
pub fn inspect(spec: &ModelSpec, fmu: &Path, kind: Option<FmiKind>) -> Result<(), String> {
    check(spec, fmu, kind).map(|_| ())
}

/// An FMU checked against the declared system, not unpacked yet.
struct Checked {
    archive: archive::Archive,
    interface: description::Interface,
    kind: FmiKind,
    map: Mapping,
    label: String,
}

fn check(spec: &ModelSpec, fmu: &Path, kind: Option<FmiKind>) -> Result<Checked, String> {
    let path = if fmu.is_relative() { spec.folder.join(fmu) } else { fmu.to_path_buf() };
    let label = fmu.file_name().map_or_else(|| fmu.display().to_string(), |n| n.to_string_lossy().into_owned());
    let archive = archive::open(&path, &label)?;
    let d = &archive.description;
    let kind = match kind {
        Some(k) => k,
        None if d.model_exchange.is_some() => FmiKind::ModelExchange,
        None => FmiKind::CoSimulation,
    };
    let interface = match kind {
        FmiKind::ModelExchange => d.model_exchange.as_ref(),
        FmiKind::CoSimulation => d.co_simulation.as_ref(),
    };
    let Some(interface) = interface.cloned() else {
        let offered = [(FmiKind::ModelExchange, &d.model_exchange), (FmiKind::CoSimulation, &d.co_simulation)]
            .iter()
            .filter(|(_, i)| i.is_some())
            .map(|(k, _)| k.label())
            .collect::<Vec<_>>()
            .join(" and ");
        return Err(format!("{label} offers no {} (it offers {offered})", kind.label()));
    };
    let map = Mapping::new(spec, d, kind, &label)?;
    if !archive.has_binary(&interface.identifier) {
        return Err(format!("{label}: no {} in binaries/{}", interface.identifier, platform(d.version)));
    }
    Ok(Checked { archive, interface, kind, map, label })
}

/// The declared names as the FMU's value references.
struct Mapping {
    /// The declared state's value references, in the declared order.
    state: Vec<u32>,
    /// Model Exchange: declared state i is the FMU's continuous state `order[i]`.
    order: Vec<usize>,
    input: Vec<u32>,
    outputs: Vec<u32>,
    real_parameters: (Vec<u32>, Vec<f64>),
    integer_parameters: (Vec<u32>, Vec<i32>),
}

impl Mapping {
    fn new(spec: &ModelSpec, d: &Description, kind: FmiKind, label: &str) -> Result<Mapping, String> {
        let is_state = |v: &description::Variable| d.states.contains(&v.vr) && v.kind == Kind::Real;
        let real = |v: &description::Variable| v.kind == Kind::Real && v.scalar;
        let missing = |name: &str, role: &str, listed: &str, has: String| {
            format!("{label} has no {listed} \"{name}\" ([system] {role}); its {listed}s: {has}")
        };
        let mut state = Vec::new();
        let mut order = Vec::new();
        for name in &spec.state {
            let found = match kind {
                FmiKind::ModelExchange => d.by_name(name).filter(|v| is_state(v)),
                FmiKind::CoSimulation => d.by_name(name).filter(|v| real(v)),
            };
            let Some(v) = found else {
                return Err(match kind {
                    FmiKind::ModelExchange => missing(name, "state", "continuous state", d.names(is_state)),
                    FmiKind::CoSimulation => missing(name, "state", "Real variable", d.names(real)),
                });
            };
            state.push(v.vr);
            order.push(d.states.iter().position(|s| *s == v.vr).unwrap_or(0));
        }
        if kind == FmiKind::ModelExchange && spec.state.len() != d.states.len() {
            return Err(format!(
                "{label} has {} continuous states ({}); [system] state declares {}: Model Exchange integrates them all",
                d.states.len(),
                d.names(is_state),
                spec.state.len()
            ));
        }
        let is_input = |v: &description::Variable| v.causality == Causality::Input && real(v);
        let input = spec
            .input
            .iter()
            .map(|n| {
                d.by_name(n)
                    .filter(|v| is_input(v))
                    .map(|v| v.vr)
                    .ok_or_else(|| missing(n, "input", "input", d.names(is_input)))
            })
            .collect::<Result<_, _>>()?;
        let is_output = |v: &description::Variable| v.causality == Causality::Output && real(v);
        let outputs = spec
            .outputs
            .iter()
            .map(|n| {
                d.by_name(n)
                    .filter(|v| real(v))
                    .map(|v| v.vr)
                    .ok_or_else(|| missing(n, "outputs", "output", d.names(is_output)))
            })
            .collect::<Result<_, _>>()?;
        let is_parameter =
            |v: &description::Variable| v.causality == Causality::Parameter && v.kind != Kind::Other && v.scalar;
        let (mut real_parameters, mut integer_parameters) = ((vec![], vec![]), (vec![], vec![]));
        for (name, value) in &spec.parameters {
            let Some(v) = d.by_name(name).filter(|v| is_parameter(v)) else {
                return Err(format!(
                    "{label} has no parameter \"{name}\" ([plant.parameters]); its parameters: {}",
                    d.names(is_parameter)
                ));
            };
            if v.kind == Kind::Integer {
                if value.fract() != 0.0 || value.abs() > f64::from(i32::MAX) {
                    return Err(format!("{label}: parameter {name} is an integer, [plant.parameters] gives {value}"));
                }
                integer_parameters.0.push(v.vr);
                integer_parameters.1.push(*value as i32);
            } else {
                real_parameters.0.push(v.vr);
                real_parameters.1.push(*value);
            }
        }
        Ok(Mapping { state, order, input, outputs, real_parameters, integer_parameters })
    }
}
