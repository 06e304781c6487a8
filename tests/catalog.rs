//! The catalog as a value, from outside the crate (as a crate with its own scenarios uses it):
//! the built-in catalog with one entry added, resolved by name, run in lockstep in this process.
//! The added entry is the pendulum's code under another name with other default gains
//! (`common::stiff_pendulum`).

use crate::common;

use std::path::{Path, PathBuf};

use common::{Table, fresh_dir, stiff_pendulum};
use looplab_shared::config::launch::Override;
use looplab_shared::launcher::{self, Outcome};
use looplab_shared::model::catalog::Catalog;
use looplab_shared::scenarios;
use sha2::{Digest, Sha256};

fn extended() -> Catalog {
    scenarios::builtin().with(stiff_pendulum())
}

/// Lockstep, 2 s, seed 7: the settings of `tests/trajectory_hashes.rs`.
fn lockstep() -> Vec<Override> {
    ["mode=lockstep", "duration_s=2.0", "seed=7"].iter().map(|s| Override::parse(s).unwrap()).collect()
}

/// Runs scenario `name` of `catalog` in this process; returns its run folder.
fn run_in_process(catalog: &Catalog, name: &str) -> PathBuf {
    let (config, scenario) = catalog.resolve(name, &lockstep()).unwrap_or_else(|e| panic!("{e}"));
    let dir = launcher::create_run_dir(Some(&fresh_dir(name)), &config.scenario).unwrap();
    let (summary, outcome) = launcher::in_process::run_in_process(&config, scenario.as_ref(), &dir).unwrap();
    assert_eq!(outcome, Outcome::Completed, "{name}");
    assert_eq!(summary.scenario, name);
    dir
}

fn sha256(path: &Path) -> String {
    Sha256::digest(std::fs::read(path).unwrap()).iter().map(|b| format!("{b:02x}")).collect()
}

/// The added scenario runs by its name with its own defaults: the same columns and start as the
/// pendulum's, other commands; the built-in pendulum of the extended catalog still gives the
/// bytes pinned in `tests/trajectory_hashes.rs`.
#[test]
fn an_added_scenario_runs_by_name_with_its_own_defaults() {
    let catalog = extended();
    let (config, _) = catalog.resolve("pendulum-stiff", &[]).unwrap();
    assert_eq!(config.document["controller"]["gains"], toml::Value::try_from([-420.0, -60.0, -1.0]).unwrap());

    let builtin_dir = run_in_process(&catalog, "pendulum");
    let stiff_dir = run_in_process(&catalog, "pendulum-stiff");
    assert_eq!(
        sha256(&builtin_dir.join("trajectory.csv")),
        "60c15b033268e52f261957d2292f96d1415a2855f0d452f8000bed24767e23a3",
        "the built-in pendulum's pinned trajectory"
    );
    let (builtin, stiff) =
        (Table::read(&builtin_dir.join("trajectory.csv")), Table::read(&stiff_dir.join("trajectory.csv")));
    assert_eq!(builtin.columns, stiff.columns, "the same code, the same vectors");
    assert_eq!(builtin.rows.len(), stiff.rows.len());
    assert_eq!(builtin.col("theta_rad")[0], stiff.col("theta_rad")[0], "the same initial state");
    let (a, b) = (builtin.col("cmd.current_A"), stiff.col("cmd.current_A"));
    assert!(a.iter().zip(&b).filter(|(a, b)| a != b).count() > a.len() / 2, "the commands differ throughout");

    // What each loop process does with the run's launch file: only the extended catalog has it.
    let launch = stiff_dir.join("launch.toml");
    let (loaded, scenario) = catalog.load_resolved(&launch).unwrap();
    assert_eq!(
        (loaded.scenario.as_str(), scenario.title()),
        ("pendulum-stiff", "reaction-wheel pendulum, bias-observer".into())
    );
    let refused = scenarios::builtin().load_resolved(&launch).map(|_| ()).unwrap_err().to_string();
    assert!(refused.contains(r#"unknown scenario "pendulum-stiff""#), "{refused}");
    for dir in [builtin_dir, stiff_dir] {
        let _ = std::fs::remove_dir_all(dir);
    }
}

/// The name resolves only in the catalog that has it, and an unknown name's error lists the
/// names of the catalog it was looked up in.
#[test]
fn a_name_resolves_only_in_the_catalog_that_has_it() {
    let builtin_names = "pendulum, quadcopter, tiltrotor, fip, tethered";
    let error = scenarios::builtin().resolve("pendulum-stiff", &[]).map(|_| ()).unwrap_err().to_string();
    assert!(error.contains(&format!(r#"unknown scenario "pendulum-stiff"; allowed: {builtin_names} "#)), "{error}");
    let error = extended().resolve("pendulum-limp", &[]).map(|_| ()).unwrap_err().to_string();
    assert!(error.contains(&format!("allowed: {builtin_names}, pendulum-stiff ")), "{error}");
    assert_eq!(extended().names(), format!("{builtin_names}, pendulum-stiff"));
}
