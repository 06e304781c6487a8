//! A plant from an FMU (`[plant] fmu = "model.fmu"`). Placeholder until the FMU loader lands
//! (helper B replaces this file): every FMU is refused at resolve time with one line.

use std::path::Path;

use crate::model::plant_model::{ModelSpec, PlantModel};

/// The FMU at `fmu` as a plant model for `spec`'s declared names.
pub fn load(_spec: &ModelSpec, fmu: &Path) -> Result<Box<dyn PlantModel>, String> {
    Err(format!("{}: FMU support is not built yet", fmu.display()))
}
