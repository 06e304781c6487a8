//! A plant model of the user's own (an FMU, a Python class): what a declared system's plant
//! (`scenarios/declared`) integrates or steps. The model sees flat numbers in the order the
//! launch file declares them (`[system]`): the state, the input, the outputs. It never sees the
//! loop, the clock or IPC.

use std::path::PathBuf;

use crate::config::launch::LaunchConfig;
use crate::config::launch::declared::{PlantSection, SystemSection};

/// How LoopLab advances a model over one loop period.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Stepping {
    /// LoopLab integrates `derivative` with its own RK4, the input held, `substeps` per period
    /// (FMI Model Exchange, a Python class).
    Derivative,
    /// The model steps itself over each period (`do_step`; FMI Co-Simulation).
    OwnStep,
}

/// What a model is built from: the declared names, in order, and the launch file's settings.
#[derive(Debug, Clone)]
pub struct ModelSpec {
    /// The launch file, for error messages.
    pub file: String,
    /// The launch file's folder: a relative model path is relative to it.
    pub folder: PathBuf,
    /// `[system]` state components' names, in order.
    pub state: Vec<String>,
    /// `[system]` input components' names, in order.
    pub input: Vec<String>,
    /// `[system]` output components' names, in order (the plant publishes them after the state).
    pub outputs: Vec<String>,
    /// The initial value of each state component the launch file gives (None: the model's own).
    pub initial: Vec<Option<f64>>,
    /// `[plant.parameters]`: name → value, set before the model initialises.
    pub parameters: Vec<(String, f64)>,
    /// The loop period, s.
    pub dt: f64,
}

impl ModelSpec {
    /// A declared system's model, as its launch file's `[system]` and `[plant]` declare it.
    pub fn declared(c: &LaunchConfig, system: &SystemSection, plant: &PlantSection) -> Self {
        Self {
            file: c.origin_file(),
            folder: plant.folder.clone().unwrap_or_else(|| std::env::current_dir().unwrap_or_default()),
            state: system.state.iter().map(|s| s.name.clone()).collect(),
            input: system.input.iter().map(|s| s.name.clone()).collect(),
            outputs: system.outputs.iter().map(|s| s.name.clone()).collect(),
            initial: system.state.iter().map(|s| s.initial).collect(),
            parameters: plant.parameters.iter().map(|(name, value)| (name.clone(), *value)).collect(),
            dt: c.dt(),
        }
    }
}

/// A plant model. Errors are one line that says what failed ("pendulum.fmu: fmi2GetDerivatives
/// returned fmi2Error at t = 1.234 s"); during a run they end the plant's incarnation.
pub trait PlantModel: Send {
    /// One line for the report: what it is ("pendulum.fmu, FMI 2.0 Model Exchange").
    fn describe(&self) -> String;
    fn stepping(&self) -> Stepping;
    /// The state it starts from: its own start values with the spec's `initial` applied.
    fn initial_state(&mut self) -> anyhow::Result<Vec<f64>>;
    /// ẋ = f(t, x, u) into `dx` ([`Stepping::Derivative`]).
    fn derivative(&mut self, t: f64, x: &[f64], u: &[f64], dx: &mut [f64]) -> anyhow::Result<()>;
    /// Advances its own state from `t` by `dt` with `u` held, and writes the new state into `x`
    /// ([`Stepping::OwnStep`]).
    fn do_step(&mut self, t: f64, dt: f64, u: &[f64], x: &mut [f64]) -> anyhow::Result<()>;
    /// The declared outputs y = g(t, x, u) into `y` (nothing to do when none are declared).
    fn outputs(&mut self, t: f64, x: &[f64], u: &[f64], y: &mut [f64]) -> anyhow::Result<()>;
    /// Its whole internal state as bytes, where it can serialise it (an FMU with
    /// `canSerializeFMUstate`); None: it cannot, and a restart goes on from the state vector.
    fn freeze(&mut self) -> anyhow::Result<Option<Vec<u8>>> {
        Ok(None)
    }
    /// Goes on from what [`PlantModel::freeze`] returned.
    fn thaw(&mut self, _frozen: &[u8]) -> anyhow::Result<()> {
        Err(anyhow::anyhow!("this model cannot restore a saved state"))
    }
    /// Goes on from state vector `x` (a restart without saved bytes). Err: it cannot (a
    /// co-simulation FMU that does not serialise its state), and the report says so.
    fn set_state(&mut self, x: &[f64]) -> anyhow::Result<()>;
}
