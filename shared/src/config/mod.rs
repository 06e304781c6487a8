//! Layer 1, configuration: launch files, fault and supervision settings, wait settings. Depends
//! only on the contract.

pub mod faults;
pub mod launch;
pub mod wait;
