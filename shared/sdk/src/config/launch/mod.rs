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
pub mod run_paths;
pub mod run_vectors;
mod types;

pub use crate::config::error::LaunchError;
pub use load::{check_python_plant, common_keys, load_resolved_config, load_run_config, resolve_config, sections};
pub use overrides::{Override, merge};
pub use types::{LaunchConfig, MAX_DURATION_S, MAX_LOOPS, MAX_RATE_HZ, Mode, PerComponent, SensorSpec};

/// The pendulum's launch file (`launch/pendulum.toml`) resolved with `overrides` against its two
/// signals, no scenario built: what the runtime's unit tests run on (the scenarios are a crate
/// above this one).
#[cfg(test)]
pub(crate) fn test_pendulum(overrides: &[Override]) -> Result<LaunchConfig, LaunchError> {
    use crate::config::schema::{Component, ScenarioSchema, SignalLayout};
    const THETA: &[Component] = &[Component::new("theta", "rad")];
    const WHEEL_SPEED: &[Component] = &[Component::new("wheel_speed", "rad/s")];
    let schema = ScenarioSchema {
        name: "pendulum",
        file: "launch/pendulum.toml",
        text: include_str!("../../../../../launch/pendulum.toml"),
        state: &[],
        input: &[],
        estimate: &[],
        signals: vec![
            SignalLayout { name: "theta", components: THETA },
            SignalLayout { name: "wheel_speed", components: WHEEL_SPEED },
        ],
    };
    resolve_config("pendulum", overrides, &[schema])
}
