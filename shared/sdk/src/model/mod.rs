//! Layer 2, the model: the scenario interface and pure maths with no IPC and no mode (the
//! sensor emulator, the integrator). Depends on the contract and the configuration.

pub mod autodiff;
pub mod catalog;
pub mod command_link;
pub mod declared_plant;
pub mod figure;
pub mod integrate;
pub mod layout;
pub mod mean;
pub mod plant_model;
pub mod poly;
pub mod reference;
pub mod scenario;
pub mod sensors;
pub mod so3;
pub mod taylor;
pub mod vectors;
