//! Launch files: load, merge over the scenario's defaults, apply `--set KEY=VALUE`, check.
//!
//! A launch file is TOML. Its keys override the scenario's built-in defaults
//! (`launch/<scenario>.toml`) key by key, and `--set` overrides both. Every problem is
//! reported as a [`LaunchError`] that names where the value came from (a file or a `--set`),
//! the dotted key, and what is allowed.
//!
//! The types are in `types`, the command line's overrides and the merge in `overrides`, loading
//! and resolution in `load`, and every check in `checks`; their public items are re-exported
//! here, so callers name `crate::config::launch::X`.

mod checks;
pub mod declared;
mod load;
mod overrides;
mod types;

pub use crate::config::error::{COMMON_KEYS, LaunchError};
pub use load::{check_python_plant, load_resolved_config, resolve_config};
pub use overrides::{Override, merge};
pub use types::{LaunchConfig, MAX_DURATION_S, MAX_LOOPS, MAX_RATE_HZ, Mode, PerComponent, SensorSpec};
