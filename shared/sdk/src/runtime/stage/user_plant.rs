//! A plant model of the user's own in the plant's process: their model, LoopLab's plant. A
//! declared system's `[plant] python = "file.py:Class"` makes the launcher start the plant role as
//! `python3` running `looplab.run_plant` (`config::python_plant`); the module builds a
//! [`PlantModel`] over the user's object and hands it to [`run_plant`] here, which runs the same
//! plant process as a built-in plant's (`runtime::stage::plant`): the declared system's plant
//! integrates the model (RK4, the input held), with the same schedule, fail-safes, snapshots,
//! restarts and reports. The twin of `runtime::stage::user_stage` for the plant role.

use std::process::ExitCode;

use anyhow::{Context as _, Result};

use crate::config::launch::LaunchConfig;
use crate::contract::msg::layout_fingerprint;
use crate::contract::protocol::{ProcessArgs, stage_env};
use crate::contract::role::Role;
use crate::model::declared_plant::DeclaredPlant;
use crate::model::plant_model::{ModelSpec, PlantModel};
use crate::model::scenario::Plant;
use crate::runtime::stage::user_stage::{input_limits, run_stage};

/// What a user's plant model is told when it starts.
pub struct PlantInfo<'a> {
    /// The run's resolved launch file (`config.document` is all of it).
    pub config: &'a LaunchConfig,
    /// The declared names (state, input, outputs), the initial state, `[plant.parameters]` and
    /// the loop period.
    pub spec: &'a ModelSpec,
    /// 0 for the first start in the run, then one more per restart.
    pub incarnation: u32,
}

/// Runs each plant step: a model that must hold something while it is called (a Python model:
/// the GIL, once per step rather than once per derivative) takes it here.
pub type Hold = fn(&mut dyn FnMut() -> Result<()>) -> Result<()>;

/// Runs the plant the launcher started with `make`'s model.
pub fn run_plant(make: impl FnOnce(&PlantInfo) -> Result<Box<dyn PlantModel>>) -> ExitCode {
    run_plant_holding(make, |step| step())
}

/// `f`'s value, made inside `hold`.
fn hold_result<T>(hold: Hold, f: &mut dyn FnMut() -> Result<T>) -> Result<T> {
    let mut value = None;
    hold(&mut || {
        value = Some(f()?);
        Ok(())
    })?;
    Ok(value.expect("hold ran the call"))
}

/// [`run_plant`] with each plant step run inside `hold`.
pub fn run_plant_holding(make: impl FnOnce(&PlantInfo) -> Result<Box<dyn PlantModel>>, hold: Hold) -> ExitCode {
    // Said here for the plant; `run_stage` checks the same for the stages.
    if ProcessArgs::from_env().is_none_or(|(role, _)| role != Role::Plant.name()) {
        eprintln!(
            "error: this program is a LoopLab plant: the launcher starts it for a launch file's [plant] python \
             with `looplab run`, which sets {} and the run's other variables",
            stage_env::ROLE
        );
        return ExitCode::from(2);
    }
    run_stage(&[Role::Plant], layout_fingerprint(), |context, _| {
        let config = &context.config;
        let plant_section = config.plant_section()?;
        let spec = ModelSpec::declared(config, &config.system()?, &plant_section);
        let info = PlantInfo { config, spec: &spec, incarnation: context.incarnation };
        let model = make(&info).context("the plant's constructor failed")?;
        let (outputs, inputs) = (spec.outputs.len(), spec.input.len());
        // Its initial state and outputs come from the model: with the GIL, as every later call.
        let mut model = Some(model);
        let plant = hold_result(hold, &mut || {
            DeclaredPlant::new(model.take().expect("built once"), outputs, inputs, plant_section.substeps)
        })?;
        crate::runtime::stage::plant::run_with(context, Box::new(Held { plant, hold }), input_limits(config))
    })
}

/// A plant whose every step runs inside `hold`.
struct Held {
    plant: DeclaredPlant,
    hold: Hold,
}

impl Plant for Held {
    fn state(&self) -> &[f64] {
        self.plant.state()
    }
    fn step(&mut self, t: f64, u: &[f64], dt: f64) -> Result<()> {
        let plant = &mut self.plant;
        (self.hold)(&mut || plant.step(t, u, dt))
    }
    fn restore(&mut self, state: &[f64]) {
        let plant = &mut self.plant;
        // `restore` cannot fail: a model that refuses the state says so at the next step.
        let _ = (self.hold)(&mut || {
            plant.restore(state);
            Ok(())
        });
    }
    fn applied_input(&self) -> Option<&[f64]> {
        self.plant.applied_input()
    }
    fn initial_input(&self) -> Option<&[f64]> {
        self.plant.initial_input()
    }
}
