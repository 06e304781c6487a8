//! The pendulum declared in a launch file with its plant from the project's own FMU
//! (services/fmu/pendulum, built here with `cc`) and the built-in estimator and controller ported
//! to Python: lockstep, five processes, the built-in pendulum's trajectory.csv byte for byte in
//! Model Exchange (the FMU's ẋ is the same arithmetic) and in Co-Simulation (its doStep is the same
//! RK4); a killed FMU plant goes on from the FMU's own serialised state; bad FMUs are one line.

use crate::common;

use std::path::PathBuf;
use std::sync::OnceLock;

use common::*;
use looplab_shared::scenarios::declared::fmu::{Version, build_fmu, pendulum_source};

const LAUNCH: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/services/examples/fmu-plant/pendulum_fmu.toml");

fn launcher() -> std::process::Command {
    python_launcher()
}

/// The pendulum FMU of `version`, built once per test process.
fn fmu(version: Version) -> PathBuf {
    static BUILT: OnceLock<PathBuf> = OnceLock::new();
    let dir = BUILT.get_or_init(|| {
        let dir = fresh_dir("fmu-plant-fmus");
        std::fs::create_dir_all(&dir).unwrap();
        build_fmu(&pendulum_source(), Version::Fmi2, &dir.join("pendulum2.fmu")).unwrap();
        build_fmu(&pendulum_source(), Version::Fmi3, &dir.join("pendulum3.fmu")).unwrap();
        dir
    });
    dir.join(if version == Version::Fmi2 { "pendulum2.fmu" } else { "pendulum3.fmu" })
}

fn trajectory_bytes(run: &Run) -> Vec<u8> {
    std::fs::read(run.dir.join("trajectory.csv")).expect("trajectory.csv")
}

fn declared(name: &str, version: Version, interface: &str, extra: &[&str]) -> Run {
    let fmu = format!("plant.fmu=\"{}\"", fmu(version).display());
    let interface = format!("plant.fmu_interface=\"{interface}\"");
    let mut args = vec![LAUNCH, "--duration", "3", "--set", &fmu, "--set", &interface];
    args.extend_from_slice(extra);
    run_from(launcher(), name, &args)
}

#[test]
fn the_fmu_pendulum_with_python_stages_is_the_builtin_pendulum_byte_for_byte() {
    let builtin = run_from(launcher(), "fmu-builtin", &["pendulum", "--mode", "lockstep", "--duration", "3"]);
    for version in [Version::Fmi2, Version::Fmi3] {
        for interface in ["model-exchange", "co-simulation"] {
            let run = declared(&format!("fmu-{version:?}-{interface}"), version, interface, &[]);
            let s = run.summary();
            assert!(s.completed, "{version:?} {interface}: {:?}", s.stopped_because);
            assert_eq!(s.loops, 3000);
            assert!(
                trajectory_bytes(&run) == trajectory_bytes(&builtin),
                "{version:?} {interface}: trajectory.csv differs from the built-in pendulum's"
            );
            assert_nothing_left(s);
        }
    }
}

/// A co-simulation FMU cannot be set from a state vector: the restarted plant goes on only
/// through the FMU's own serialised state, kept beside the plant's snapshot. In lockstep the
/// killed run is the nominal one, byte for byte.
#[test]
fn a_killed_fmu_plant_goes_on_from_the_fmus_serialised_state() {
    let nominal = declared("fmu-cs-nominal", Version::Fmi3, "co-simulation", &[]);
    let killed = declared("fmu-cs-killed", Version::Fmi3, "co-simulation", &["--fault", "kill plant at 1.5s"]);
    let s = killed.summary();
    assert!(s.completed, "{:?}", s.stopped_because);
    assert_eq!(s.restarts[&looplab_shared::contract::role::Role::Plant], 1);
    assert!(trajectory_bytes(&killed) == trajectory_bytes(&nominal), "the restarted FMU did not resume its state");
    assert!(!s.notes.iter().any(|n| n.contains("state vector")), "it went on from its own bytes: {:?}", s.notes);
    assert_nothing_left(s);
}

#[test]
fn a_bad_fmu_is_one_line_and_exit_2() {
    let dir = fresh_dir("fmu-bad");
    std::fs::create_dir_all(&dir).unwrap();
    let corrupt = dir.join("corrupt.fmu");
    std::fs::write(&corrupt, b"not a zip").unwrap();
    // The same FMU as if built for Windows only: its binary moved to binaries/win64.
    let windows = dir.join("windows.fmu");
    let moved = std::process::Command::new("python3")
        .args([
            "-c",
            "import sys, zipfile\nsrc, dst = zipfile.ZipFile(sys.argv[1]), zipfile.ZipFile(sys.argv[2], 'w')\n\
                      for i in src.infolist(): dst.writestr(i.filename.replace('linux64', 'win64'), src.read(i))\n\
                      dst.close()",
        ])
        .arg(fmu(Version::Fmi2))
        .arg(&windows)
        .status()
        .unwrap();
    assert!(moved.success());
    let cases: [(String, &str); 6] = [
        (format!("plant.fmu=\"{}\"", dir.join("missing.fmu").display()), "missing.fmu: cannot open the FMU"),
        (format!("plant.fmu=\"{}\"", corrupt.display()), "corrupt.fmu: not an FMU (a zip archive)"),
        (
            format!("plant.fmu=\"{}\"", windows.display()),
            "windows.fmu: no binary for this platform (linux64); the FMU has binaries for: win64",
        ),
        ("plant.parameters.mass=1.0".into(), "has no parameter \"mass\" ([plant.parameters]); its parameters: m_p"),
        (
            "system.outputs=[{ name = \"power\", unit = \"W\" }]".into(),
            "has no output \"power\" ([system] outputs); its outputs: energy",
        ),
        ("plant.fmu_interface=\"scheduled\"".into(), "\"scheduled\": one of model-exchange, co-simulation"),
    ];
    for (set, expected) in cases {
        let fmu = format!("plant.fmu=\"{}\"", fmu(Version::Fmi2).display());
        let output = launcher()
            .args(["run", LAUNCH, "--duration", "1", "--set", &fmu, "--set", &set, "-q", "--out"])
            .arg(dir.join("run"))
            .output()
            .unwrap();
        let stderr = String::from_utf8_lossy(&output.stderr);
        assert_eq!(output.status.code(), Some(2), "{set}: {stderr}");
        assert!(stderr.contains(expected), "{set}: {stderr}\n  should say: {expected}");
        assert_eq!(stderr.trim().lines().count(), 1, "{set}: {stderr}");
        assert!(!dir.join("run").exists(), "{set}: nothing starts, so no run folder and no shared memory");
    }
    let _ = std::fs::remove_dir_all(&dir);
}
