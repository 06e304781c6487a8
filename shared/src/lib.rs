//! LoopLab's shared crate, in layers that depend only downwards:
//! contract → config → model → scenarios → runtime → monitor → launcher → tools → cli.
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
