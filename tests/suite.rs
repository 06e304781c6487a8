//! The integration tests, as one test binary: each module is one subject's tests, run against
//! the real `looplab` binary (which starts the real processes over real iceoryx2 shared memory).
//! One binary links LoopLab once instead of once per subject, which is most of the suite's build
//! time. Run one subject with `cargo test --release --test suite pendulum::`.
//! `user_stage_errors` and `outside_crate` stay binaries of their own: each has its own `main`.

mod common;
mod figure_check;

mod answers;
mod c_and_rust_stages;
mod catalog;
mod cli;
mod compare;
mod controller_restart;
mod dashboard;
mod declared;
mod declared_metrics;
mod delay_margin;
mod diff;
mod explain;
mod faults;
mod fip;
mod fmu_plant;
mod golden_ci;
mod layers;
mod loop_runtime;
mod mcap;
mod netns;
mod one_number;
mod pendulum;
mod perfetto;
mod plot;
mod probe;
mod python_plant;
mod python_stage;
mod quadcopter;
mod recorded;
mod remote;
mod replay;
mod security;
mod soak;
mod summary_schema;
mod tethered;
mod tiltrotor;
mod trajectory_hashes;

/// Every file of tests/ is a module of this binary: with `autotests = false` a test file left
/// out of the list above would never be built, and its tests would pass unseen.
#[test]
fn every_test_file_is_in_the_suite() {
    let suite = include_str!("suite.rs");
    let tests = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("tests");
    for entry in std::fs::read_dir(&tests).unwrap().flatten() {
        let name = entry.file_name().to_string_lossy().into_owned();
        let module = name.strip_suffix(".rs").unwrap_or(&name);
        if matches!(module, "suite" | "user_stage_errors" | "outside_crate") {
            continue;
        }
        assert!(suite.contains(&format!("\nmod {module};\n")), "tests/{name} is not a module of tests/suite.rs");
    }
}
