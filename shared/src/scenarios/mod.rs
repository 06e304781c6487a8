//! The systems LoopLab runs. Each scenario lives in one folder (plant, sensors, estimator,
//! controller side by side) and plugs into the loop through the traits of
//! [`crate::model::scenario`], so the five processes stay scenario-agnostic. [`ALL`] is the list
//! of their entries; [`builtin`] is the catalog of them that LoopLab's own binaries run, and that
//! a crate outside this one extends with its own ([`Catalog::with`]).

pub mod declared;
pub mod fip;
pub mod pendulum;
pub mod quadcopter;
pub mod tethered;
pub mod tiltrotor;

#[cfg(test)]
mod fault_tests;
#[cfg(test)]
mod launch_tests;

use std::path::Path;

use crate::config::launch::{LaunchConfig, LaunchError, Override};
use crate::model::catalog::Catalog;
use crate::model::scenario::{Scenario, ScenarioEntry};

/// The built-in scenarios' entries.
pub const ALL: &[ScenarioEntry] = &[pendulum::ENTRY, quadcopter::ENTRY, tiltrotor::ENTRY, fip::ENTRY, tethered::ENTRY];

/// The catalog of the built-in scenarios, and of declared systems (`[system]`, no scenario).
pub fn builtin() -> Catalog {
    Catalog::new(ALL.iter().cloned()).with_declared(declared::build)
}

/// [`Catalog::resolve`] in the built-in catalog.
pub fn resolve(target: &str, overrides: &[Override]) -> Result<(LaunchConfig, Box<dyn Scenario>), LaunchError> {
    builtin().resolve(target, overrides)
}

/// [`Catalog::load_resolved`] in the built-in catalog.
pub fn load_resolved(path: &Path) -> Result<(LaunchConfig, Box<dyn Scenario>), LaunchError> {
    builtin().load_resolved(path)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::contract::msg::{MAX_ESTIMATE, MAX_INPUT, MAX_SENSOR_DIM, MAX_STATE};
    use crate::model::vectors::Vectors;

    #[test]
    fn every_scenario_fits_the_messages() {
        for entry in ALL {
            entry.schema().check_fits().unwrap_or_else(|e| panic!("{e}"));
            let v = entry.vectors;
            assert!(v.state.len() <= MAX_STATE && v.input.len() <= MAX_INPUT && v.estimate.len() <= MAX_ESTIMATE);
            assert!(v.signals.iter().all(|s| s.components.len() <= MAX_SENSOR_DIM), "{}", entry.name);
        }
    }

    /// The names derive from the entry's vectors.
    #[test]
    fn a_built_scenario_names_its_entrys_components() {
        let (_, pendulum) = resolve("pendulum", &[]).unwrap();
        assert_eq!(pendulum.state_names(), ["theta", "theta_dot", "wheel_speed"]);
        assert_eq!(pendulum.input_names(), ["current"]);
        assert_eq!(pendulum.estimate_names(), ["theta", "theta_dot", "wheel_speed", "bias"]);
    }

    /// An entry built under another name carries that entry's vectors, not the code's.
    #[test]
    fn a_built_scenario_carries_the_vectors_of_the_entry_that_built_it() {
        let v = &pendulum::VECTORS;
        let no_signals: &'static Vectors =
            Box::leak(Box::new(Vectors { state: v.state, input: v.input, estimate: v.estimate, signals: &[] }));
        let entry = ScenarioEntry { vectors: no_signals, ..pendulum::ENTRY };
        let (config, _) = resolve("pendulum", &[]).unwrap();
        let scenario = entry.build(&config).unwrap();
        assert!(std::ptr::eq(scenario.vectors(), no_signals));
    }

    #[test]
    fn the_builtin_catalog_holds_every_entry_once_in_order() {
        let catalog = builtin();
        assert_eq!(catalog.names(), "pendulum, quadcopter, tiltrotor, fip, tethered");
        assert_eq!(catalog.schemas().len(), ALL.len());
        assert!(catalog.find("tiltrotor").is_some_and(|e| std::ptr::eq(e.vectors, tiltrotor::ENTRY.vectors)));
        assert!(catalog.find("nope").is_none());
    }

    /// `with` replaces the entry of the same name in its place, and adds a new one at the end.
    #[test]
    fn with_replaces_by_name_or_adds() {
        let described = ScenarioEntry { description: "replaced", ..pendulum::ENTRY };
        let catalog = builtin().with(described);
        assert_eq!(catalog.names(), "pendulum, quadcopter, tiltrotor, fip, tethered");
        assert_eq!(catalog.find("pendulum").unwrap().description, "replaced");
        let text: &'static str =
            pendulum::ENTRY.text.replace(r#"scenario = "pendulum""#, r#"scenario = "swing""#).leak();
        let catalog = catalog.with(ScenarioEntry { name: "swing", text, ..pendulum::ENTRY });
        assert_eq!(catalog.names(), "pendulum, quadcopter, tiltrotor, fip, tethered, swing");
    }

    #[test]
    #[should_panic(expected = "must say scenario = \"swing\"")]
    fn an_entry_whose_defaults_name_another_scenario_is_refused() {
        let _ = builtin().with(ScenarioEntry { name: "swing", ..pendulum::ENTRY });
    }

    #[test]
    fn the_sections_derive_from_the_defaults() {
        let catalog = builtin();
        let sections = |name| crate::config::launch::sections(&catalog.find(name).unwrap().schema());
        assert_eq!(sections("pendulum"), ["controller", "estimator", "limits", "model", "plant"]);
        assert_eq!(
            sections("quadcopter"),
            ["controller", "estimator", "limits", "metrics", "model", "plant", "reference"]
        );
    }
}
