//! Layer 2, the model: pure maths with no IPC and no mode (the sensor emulator, the integrator).
//! Depends on the contract and the configuration.

pub mod integrate;
pub mod sensors;
