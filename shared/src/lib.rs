//! LoopLab's shared crate: the messages, the models, the loop stages, the monitor and the
//! launcher. The binaries in `services/` are one call each into here.

pub mod bench;
pub mod clock;
pub mod faults;
pub mod integrate;
pub mod ipc;
pub mod launch;
pub mod launcher;
pub mod monitor;
pub mod msg;
pub mod plant;
pub mod protocol;
pub mod report;
pub mod scenarios;
pub mod sensors;
pub mod signals;
pub mod snapshot;
pub mod stages;
pub mod sweep;
pub mod wait;
