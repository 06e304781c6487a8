//! A crate of its own that adds a scenario (`Catalog::with`) builds LoopLab's six binaries with
//! its catalog (`runtime::stage::child::process_main_with`). This test binary is that crate: linked
//! under the six names it is the launcher and the five loop processes with the built-in catalog
//! plus `pendulum-stiff` (the pendulum's code under another name, other default gains). A
//! Python controller of the user's own (the example's) runs on the added scenario, five
//! processes in lockstep, and sends the very commands of the scenario's own controller: the
//! stage read the run's vectors from its launch.toml, not from a catalog (the Python module has
//! none).
//!
//! Its own `main` (Cargo.toml: `harness = false`), since it is six programs.

mod common;

use std::path::{Path, PathBuf};
use std::process::{Command, ExitCode};

use common::{STIFF_GAINS, fresh_dir, python_module_dir, stiff_pendulum};
use looplab_shared::contract::role::Role;
use looplab_shared::model::catalog::Catalog;
use looplab_shared::runtime::builtin;
use looplab_shared::runtime::stage::child::process_main_with;
use looplab_shared::scenarios;

fn catalog() -> Catalog {
    scenarios::builtin().with(stiff_pendulum())
}

fn main() -> ExitCode {
    let name: Option<String> =
        std::env::args().next().map(PathBuf::from).and_then(|p| Some(p.file_name()?.to_string_lossy().into()));
    match name.as_deref().unwrap_or_default() {
        "looplab" => looplab_shared::cli::main_with(&catalog()),
        "looplab-plant" => process_main_with(Role::Plant, builtin::plant, &catalog()),
        "looplab-sensors" => process_main_with(Role::Sensors, builtin::sensors, &catalog()),
        "looplab-estimator" => process_main_with(Role::Estimator, builtin::estimator, &catalog()),
        "looplab-controller" => process_main_with(Role::Controller, builtin::controller, &catalog()),
        "looplab-monitor" => process_main_with(Role::Monitor, looplab_shared::monitor::run, &catalog()),
        _ => test(),
    }
}

fn test() -> ExitCode {
    let name = "a_python_stage_runs_on_a_scenario_an_outside_crate_added";
    let passed = std::panic::catch_unwind(a_python_stage_runs_on_a_scenario_an_outside_crate_added).is_ok();
    println!("test {name} ... {}", if passed { "ok" } else { "FAILED" });
    println!(
        "\ntest result: {}. {} passed; {} failed",
        if passed { "ok" } else { "FAILED" },
        passed as u8,
        !passed as u8
    );
    if passed { ExitCode::SUCCESS } else { ExitCode::FAILURE }
}

/// This binary under the six names in `dir` (hard links: the launcher finds the loop processes
/// beside the executable it was started as).
fn link_binaries(dir: &Path) -> PathBuf {
    std::fs::create_dir_all(dir).unwrap();
    let exe = std::env::current_exe().unwrap();
    for name in
        ["looplab", "looplab-plant", "looplab-sensors", "looplab-estimator", "looplab-controller", "looplab-monitor"]
    {
        let link = dir.join(name);
        if std::fs::hard_link(&exe, &link).is_err() {
            std::fs::copy(&exe, &link).unwrap();
        }
    }
    dir.join("looplab")
}

/// Runs `target` in lockstep for 2 s with this crate's launcher; returns the run folder.
fn run(launcher: &Path, target: &str, out: &Path) -> PathBuf {
    let output = Command::new(launcher)
        .args(["run", target, "--mode", "lockstep", "--duration", "2", "-q", "--out"])
        .arg(out)
        .env("PYTHONPATH", python_module_dir())
        .env_remove("CARGO")
        .env_remove("CARGO_MANIFEST_DIR")
        .output()
        .unwrap();
    let said = format!("{}{}", String::from_utf8_lossy(&output.stdout), String::from_utf8_lossy(&output.stderr));
    assert!(output.status.success(), "{target}: {said}");
    out.to_path_buf()
}

fn a_python_stage_runs_on_a_scenario_an_outside_crate_added() {
    let dir = fresh_dir("outside-crate");
    let launcher = link_binaries(&dir.join("bin"));
    let examples = Path::new(env!("CARGO_MANIFEST_DIR")).join("services/examples/controller");
    let launch = dir.join("stiff_python.toml");
    let controller = examples.join("pendulum_controller.py");
    std::fs::write(
        &launch,
        format!(
            "scenario = \"pendulum-stiff\"\n[stages.controller]\ncommand = [\"python3\", {:?}]\n",
            controller.display().to_string()
        ),
    )
    .unwrap();

    let builtin = run(&launcher, "pendulum-stiff", &dir.join("builtin"));
    let python = run(&launcher, launch.to_str().unwrap(), &dir.join("python"));
    let bytes = |run: &Path| std::fs::read(run.join("trajectory.csv")).unwrap();
    assert!(bytes(&python) == bytes(&builtin), "the Python controller's trajectory differs from the scenario's own");
    // The stiff gains ran (not the pendulum's), and the stage that ran was the Python one.
    let resolved = std::fs::read_to_string(python.join("launch.toml")).unwrap();
    let vectors = resolved.parse::<toml::Table>().unwrap()["vectors"].clone();
    assert_eq!(vectors["scenario"].as_str(), Some("pendulum-stiff"), "{resolved}");
    assert!(resolved.contains(STIFF_GAINS) && resolved.contains("pendulum_controller.py"), "{resolved}");
    let summary: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(python.join("summary.json")).unwrap()).unwrap();
    let controller = summary["processes"].as_array().unwrap().iter().find(|p| p["name"] == "controller").unwrap();
    assert!(controller["command"].as_str().is_some_and(|p| p.contains("pendulum_controller.py")), "{controller}");
    let _ = std::fs::remove_dir_all(dir);
}
