//! Layer 1, configuration: launch files, fault and supervision settings, wait settings, and the
//! plain-data view of a scenario a launch file is checked against. Depends only on the contract.

pub mod error;
pub mod faults;
pub mod gate;
pub mod hosts;
pub mod launch;
pub mod python_plant;
pub mod realtime;
pub mod replay;
pub mod schema;
pub mod seed;
pub mod stage_build;
pub mod stages;
pub mod validate;
pub mod wait;
