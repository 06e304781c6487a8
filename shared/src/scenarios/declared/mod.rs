//! A system declared in its launch file, no Rust: a launch file with no `scenario` and a
//! `[system]` table (its vectors), a `[plant]` (a built-in linear model, an FMU or a Python
//! class), `[sensors.<name>] reads = [...]`, and its estimator and controller as stages of the
//! user's own or built in (the pass-through estimator, state feedback).
//!
//! - `system`: the description read from the file (plant source, model spec, checks);
//! - `plant`: [`plant::DeclaredPlant`], a `Plant` over a `PlantModel`;
//! - `linear`: the built-in `[plant.linear]` model;
//! - `fmu`: an FMU as a `PlantModel`;
//! - `sensors`: the vectors, each sensor a signal picking what it reads;
//! - `estimator`, `controller`: the built-in pass-through and state feedback;
//! - `metrics`: the generic metrics, tracking errors and the `[limits]` error measure;
//! - `reference`: `[[reference]]`, what a component tracks (a table or an expression of t).

pub mod controller;
pub mod estimator;
pub mod fmu;
pub mod linear;
pub mod margin;
pub mod metrics;
#[cfg(test)]
mod plant_tests;
pub mod reference;
pub mod sensors;
pub mod step_response;
pub mod system;

use self::controller::{NoController, StateFeedback};
use self::estimator::PassThrough;
use self::linear::LinearModel;
use self::system::{PlantSource, System};
use crate::config::launch::{LaunchConfig, LaunchError};
use crate::model::declared_plant::{DeclaredPlant, FailedPlant};
use crate::model::plant_model::PlantModel;
use crate::model::scenario::{
    Controller, ErrorMeasure, Estimator, Metrics, Plant, Scenario, ScenarioParts, TheoreticalMargin,
};
use crate::model::vectors::Vectors;

/// The scenario a declared system's configuration describes (`Catalog::with_declared`).
/// `check_model`: check the plant's model now, so that a bad model is an error at resolve time
/// (the launcher), not in the plant process: a linear model is built once; an FMU is checked
/// without running its code, which runs only in the plant process.
pub fn build(c: &LaunchConfig, check_model: bool) -> Result<Box<dyn Scenario>, LaunchError> {
    let system = System::from_config(c)?;
    let vectors = sensors::vectors(c, &system)?;
    // An open-loop replay plays the plant back: its model is neither checked nor loaded.
    let played_back = c.replay.as_ref().is_some_and(|r| r.plays_back(crate::contract::role::Role::Plant));
    if check_model && !played_back {
        match &system.source {
            PlantSource::Linear(_) => {
                declared_plant(&system).map_err(|message| c.error("plant.linear", message))?;
            }
            PlantSource::Fmu(path) => fmu::inspect(&system.spec, path, system.fmu_interface)
                .map_err(|message| c.error("plant.fmu", message))?,
            PlantSource::Python { .. } => {}
        }
    }
    let file = std::path::Path::new(&system.spec.file);
    let name = file.file_name().map_or_else(|| system.spec.file.clone(), |f| f.to_string_lossy().into_owned());
    let title = format!("declared system {name}, {}", system.plant_title());
    let measures = metrics::DeclaredMeasures::from_system(c, &system.vectors)?;
    Ok(Box::new(Declared { system, vectors, title, measures }))
}

/// The plant's model, built from its source.
pub fn model(system: &System) -> Result<Box<dyn PlantModel>, String> {
    match &system.source {
        PlantSource::Linear(linear) => Ok(Box::new(LinearModel::new(linear.clone(), &system.spec))),
        PlantSource::Fmu(path) => fmu::load_as(&system.spec, path, system.fmu_interface),
        PlantSource::Python { .. } => {
            Err("a Python plant runs as its own python3 process; it cannot be built in this one".to_owned())
        }
    }
}

/// The plant over its model, at its initial state.
pub fn declared_plant(system: &System) -> Result<DeclaredPlant, String> {
    let model = model(system)?;
    DeclaredPlant::new(model, system.vectors.outputs.len(), system.vectors.input.len(), system.substeps)
        .map_err(|e| format!("{e:#}"))
}

pub struct Declared {
    pub system: System,
    vectors: &'static Vectors,
    title: String,
    measures: metrics::DeclaredMeasures,
}

impl Scenario for Declared {
    fn vectors(&self) -> &'static Vectors {
        self.vectors
    }
}

impl ScenarioParts for Declared {
    fn title(&self) -> String {
        self.title.clone()
    }

    fn input_limits(&self) -> Vec<(f64, f64)> {
        self.system.input_limits.clone()
    }

    fn plant(&self) -> Box<dyn Plant> {
        match declared_plant(&self.system) {
            Ok(plant) => Box::new(plant),
            Err(error) => Box::new(FailedPlant { x: vec![0.0; self.vectors.state.len()], error }),
        }
    }

    fn estimator(&self) -> Box<dyn Estimator> {
        // With [stages.estimator] the user's runs and this one is never asked for an update.
        Box::new(PassThrough { picks: self.system.pass_through.clone().unwrap_or_default() })
    }

    fn controller(&self) -> Box<dyn Controller> {
        match &self.system.gains {
            Some(gains) => Box::new(StateFeedback {
                gains: gains.clone(),
                limits: self.system.input_limits.clone(),
                setpoints: self.system.setpoints.clone(),
            }),
            None => Box::new(NoController),
        }
    }

    fn metrics(&self) -> Box<dyn Metrics> {
        self.measures.metrics()
    }

    fn error_measure(&self) -> ErrorMeasure {
        self.measures.error_measure()
    }

    fn delay_margin(&self, config: &LaunchConfig) -> Option<TheoreticalMargin> {
        margin::delay_margin(&self.system, config)
    }
}
