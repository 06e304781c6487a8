//! The pendulum declared in a launch file with its plant from the project's own FMU
//! (services/fmu/pendulum, built here with `cc`) and the built-in estimator and controller ported
//! to Python: lockstep, five processes, the built-in pendulum's trajectory.csv byte for byte in
//! Model Exchange (the FMU's ẋ is the same arithmetic) and in Co-Simulation (its doStep is the same
//! RK4); a killed FMU plant goes on from the FMU's own serialised state; bad FMUs are one line.

use crate::common;

use std::path::{Path, PathBuf};
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

/// The pendulum FMU's source with `on_load` run by the dynamic loader when its binary is opened.
fn misbehaving_fmu(dir: &Path, name: &str, on_load: &str) -> PathBuf {
    let source = dir.join(name);
    std::fs::create_dir_all(&source).unwrap();
    let copied = std::process::Command::new("cp").arg("-r").arg(pendulum_source().join(".")).arg(&source).status();
    assert!(copied.unwrap().success());
    let c = source.join("fmi2.c");
    let code = std::fs::read_to_string(&c).unwrap();
    let hook = format!(
        "\n#include <signal.h>\n#include <stdlib.h>\n#include <unistd.h>\n\
         __attribute__((constructor)) static void misbehave_on_load(void) {{ {on_load} }}\n"
    );
    std::fs::write(&c, code + &hook).unwrap();
    let fmu = dir.join(format!("{name}.fmu"));
    build_fmu(&source, Version::Fmi2, &fmu).unwrap();
    fmu
}

/// The launcher runs none of an FMU's code: an FMU that exits, crashes or sleeps as it is loaded
/// does so in the plant process, which fails the run in one line (never a run that passes with no
/// loop at all, never a hang), and leaves nothing behind.
#[test]
fn an_fmu_that_exits_crashes_or_hangs_while_loading_fails_the_run_it_never_passes() {
    let dir = fresh_dir("fmu-misbehaving");
    std::fs::create_dir_all(&dir).unwrap();
    let cases = [
        ("exits", "exit(0);", "plant exited with status 0 during start-up"),
        ("crashes", "signal(SIGSEGV, SIG_DFL); raise(SIGSEGV);", "plant exited with status signal 11 during start-up"),
        ("sleeps", "sleep(3600);", "not ready after 1 s (supervision.ready_timeout_s): "),
    ];
    for (name, on_load, expected) in cases {
        let fmu = misbehaving_fmu(&dir, name, on_load);
        let out = dir.join(format!("{name}-run"));
        let output = launcher()
            .args(["run", LAUNCH, "--duration", "1", "-q", "--set", "supervision.ready_timeout_s=1", "--set"])
            .arg(format!("plant.fmu=\"{}\"", fmu.display()))
            .arg("--out")
            .arg(&out)
            .output()
            .unwrap();
        let stderr = String::from_utf8_lossy(&output.stderr);
        assert_eq!(output.status.code(), Some(1), "{name}: {stderr}");
        assert!(stderr.contains(expected), "{name}: {stderr}\n  should say: {expected}");
        assert!(stderr.contains("plant"), "{name}: the plant is named: {stderr}");
        assert_nothing_left(&load_summary(&out));
    }
    let _ = std::fs::remove_dir_all(&dir);
}

/// An FMU's unpack folder is its process's own (0700); one left by a process that is gone is
/// removed by `looplab clean`, one of a live process is not.
#[test]
fn fmu_unpack_folders_are_private_and_those_of_dead_processes_are_cleaned() {
    let tmp = std::env::temp_dir();
    // A pid that is not running: the highest the kernel hands out, past any real one here.
    let max: i32 = std::fs::read_to_string("/proc/sys/kernel/pid_max").unwrap().trim().parse().unwrap();
    let dead = tmp.join(format!("looplab-fmu-{}-test{}", max, std::process::id()));
    let live = tmp.join(format!("looplab-fmu-{}-test", std::process::id()));
    for folder in [&dead, &live] {
        std::fs::create_dir_all(folder.join("binaries")).unwrap();
        std::fs::write(folder.join("binaries/model.so"), b"x").unwrap();
    }
    let output = looplab().arg("clean").output().unwrap();
    assert!(output.status.success(), "{}", String::from_utf8_lossy(&output.stderr));
    let said = String::from_utf8_lossy(&output.stdout);
    assert!(!dead.exists(), "{said}");
    assert!(said.contains(&format!("removed {}", dead.display())), "{said}");
    assert!(live.exists(), "a live process's folder is left alone");
    std::fs::remove_dir_all(&live).unwrap();
}

/// An open-loop replay plays the plant back from the recording: it neither checks nor loads the
/// FMU the run used, so one replaced since (here by a file that is no FMU) changes nothing.
#[test]
fn an_open_loop_replay_neither_checks_nor_loads_the_recorded_fmu() {
    let dir = fresh_dir("fmu-replay");
    std::fs::create_dir_all(&dir).unwrap();
    let own = dir.join("plant.fmu");
    std::fs::copy(fmu(Version::Fmi2), &own).unwrap();
    let run = run_from(
        launcher(),
        "fmu-recorded",
        &[LAUNCH, "--mode", "lockstep", "--duration", "1", "--set", &format!("plant.fmu=\"{}\"", own.display())],
    );
    assert!(run.summary().completed, "{:?}", run.summary().stopped_because);
    std::fs::write(&own, b"not a zip").unwrap();
    let out = dir.join("replay");
    let output =
        launcher().arg("replay").arg(&run.dir).args(["--stage", "controller", "--out"]).arg(&out).output().unwrap();
    let stderr = String::from_utf8_lossy(&output.stderr);
    assert_eq!(output.status.code(), Some(0), "{stderr}");
    let _ = std::fs::remove_dir_all(&dir);
}
