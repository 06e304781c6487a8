//! LoopLab's shared crate, in layers that depend only downwards:
//! contract → config → model → scenarios → runtime → monitor → launcher → tools.
//! The binaries in `services/` are one call each into here. ARCHITECTURE.md has the picture.

pub mod cli;
pub mod config;
pub mod contract;
pub mod launcher;
pub mod model;
pub mod monitor;
pub mod runtime;
pub mod scenarios;
pub mod tools;

// The flat paths of before the layers, kept only while issue 11 moves code (removed at its end).
pub use config::{faults, launch};
pub use contract::{clock, msg, protocol};
pub use launcher::report;
pub use model::{integrate, sensors};
pub use runtime::child as stages;
pub use runtime::{ipc, plant, signals, snapshot, wait};
pub use tools::{bench, sweep};
