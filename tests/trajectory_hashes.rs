//! Golden hashes: the exact bytes of `trajectory.csv` for short lockstep runs of every launch
//! file, each scenario by name, a mass step and the in-loop faults (delay, drop, corrupt).
//!
//! These hashes were recorded on commit 817977e (the tilt-rotor rows with issue 12, when the
//! scenario was added) and must never change in a refactor: a refactor
//! that changes one of them has changed what the loop computes (or how it writes it). Only a
//! deliberate model change may re-record them, and its commit says which rows changed and why.
//! On a mismatch the test prints every row that differs with the hash it got, so a deliberate
//! change can copy them all at once.
//!
//! Every case runs twice: through the five processes, and with `--in-process` (the same tasks
//! in loop order in one process). Both must give the recorded bytes, which proves the in-process
//! twin byte-identical to the real pipeline, faults included, for every scenario.
//!
//! Lockstep with a fixed seed is deterministic (the README promises byte-identical
//! `trajectory.csv`); every row was run twice when recorded and gave the same bytes. The runs
//! are short (2 s of simulated time, 2000–2400 loops, about half a second each).

mod common;

use std::sync::Mutex;
use std::sync::atomic::{AtomicUsize, Ordering};

use common::{fresh_dir, looplab};
use sha2::{Digest, Sha256};

/// Every row: lockstep, 2 s, seed 7.
const COMMON: &[&str] = &["--mode", "lockstep", "--duration", "2", "--seed", "7"];

/// (name, target and extra arguments, sha256 of trajectory.csv).
const CASES: &[(&str, &[&str], &str)] = &[
    (
        "launch/pendulum.toml",
        &["launch/pendulum.toml"],
        "baa50e9880cf25af5e854fb51808407d0ee40e8365acccab8cd5ae750e163cd0",
    ),
    // By name, the scenario's own launch file: the same bytes as the file.
    ("pendulum (by name)", &["pendulum"], "baa50e9880cf25af5e854fb51808407d0ee40e8365acccab8cd5ae750e163cd0"),
    (
        "launch/quadcopter.toml",
        &["launch/quadcopter.toml"],
        "8506a170afd5dd2c736eb5a3bc3c134b1c62bc820c5e1721a2baf26fd65736bf",
    ),
    ("quadcopter (by name)", &["quadcopter"], "8506a170afd5dd2c736eb5a3bc3c134b1c62bc820c5e1721a2baf26fd65736bf"),
    (
        "launch/quadcopter/1-analytic.toml",
        &["launch/quadcopter/1-analytic.toml"],
        "e3a085fc8e751b7d0a9fbfa82e5396407942087c05abc262a574db3694661354",
    ),
    (
        "launch/quadcopter/2-not-rich.toml",
        &["launch/quadcopter/2-not-rich.toml"],
        "805a4fd541115302e5812e8ec3843c289888f0f68da1e63bc2946cc1293fe782",
    ),
    (
        "launch/quadcopter/3-rich.toml",
        &["launch/quadcopter/3-rich.toml"],
        "1a43ac24f91539946037626fd2251017a27c39b8a21ee6814d57abd50f07b5b6",
    ),
    (
        "launch/quadcopter/4-closed-loop.toml",
        &["launch/quadcopter/4-closed-loop.toml"],
        "89fceae57a9903ae0d4e756a3caa1f49d0f8515512f76fa568f58b75d8517ef4",
    ),
    (
        "launch/quadcopter/5-stochastic-snr.toml",
        &["launch/quadcopter/5-stochastic-snr.toml"],
        "fc560e8bce20e119e4bec66797e8d9f599dca734747acefa6953314607a531fc",
    ),
    // Sets only mode and duration: the same bytes as launch/quadcopter.toml.
    (
        "launch/quadcopter/6-lemniscate.toml",
        &["launch/quadcopter/6-lemniscate.toml"],
        "8506a170afd5dd2c736eb5a3bc3c134b1c62bc820c5e1721a2baf26fd65736bf",
    ),
    // 1200 Hz, rate loop, held commands; its mass step (35.2 s) is past these 2 s ...
    (
        "launch/quadcopter/7-hover-mass-step.toml",
        &["launch/quadcopter/7-hover-mass-step.toml"],
        "fb9a7eb061a245f94bf40a1fe9b01982f94b5e0141c0de9e136f892c56042279",
    ),
    // ... so this row moves it to 1 s.
    (
        "launch/quadcopter/7-hover-mass-step.toml, mass step at 1 s",
        &["launch/quadcopter/7-hover-mass-step.toml", "--set", "plant.mass_step_at_s=1.0"],
        "62ba4dc14b436a8812f0fabf13bdc43338291cdfa84e1830a547c158869a2c58",
    ),
    // Added with the tilt-rotor (issue 12), recorded on its commit: 200 loops at 100 Hz.
    (
        "launch/tiltrotor.toml",
        &["launch/tiltrotor.toml"],
        "1ada356b499b4ea07d32ff250097e3b6e8e0cc827f89567374ab940c966aaba0",
    ),
    ("tiltrotor (by name)", &["tiltrotor"], "1ada356b499b4ea07d32ff250097e3b6e8e0cc827f89567374ab940c966aaba0"),
    // Sets only mode and the kind it already has: the same bytes as launch/tiltrotor.toml.
    (
        "launch/tiltrotor/1-nlls-2l.toml",
        &["launch/tiltrotor/1-nlls-2l.toml"],
        "1ada356b499b4ea07d32ff250097e3b6e8e0cc827f89567374ab940c966aaba0",
    ),
    (
        "launch/tiltrotor/2-nlpt-2l.toml",
        &["launch/tiltrotor/2-nlpt-2l.toml"],
        "9555469be2d28b5b50de757964ad14100eee5c81189e490ffa77af95266ba900",
    ),
    // In-loop faults in lockstep: applied by the processes by loop index, hence deterministic.
    (
        "pendulum, faults: delay controller, drop sensors, corrupt nan",
        &[
            "pendulum",
            "--fault",
            "delay controller by 3 ticks at 0.5s for 0.2s",
            "--fault",
            "drop sensors 20% at 0.8s for 0.3s",
            "--fault",
            "corrupt controller nan at 1.2s for 50ms",
        ],
        "3fda4286cb89c70022b8026d4f54c5569398a0dfa205bf312ae67fc33e495309",
    ),
    (
        "pendulum, faults: delay sensors and estimator, drop estimator and controller, corrupt inf and out-of-range",
        &[
            "pendulum",
            "--fault",
            "delay sensors by 2 ticks at 0.3s for 0.3s",
            "--fault",
            "delay estimator by 1 tick at 0.4s for 0.2s",
            "--fault",
            "drop estimator 30% at 0.7s for 0.3s",
            "--fault",
            "drop controller 25% at 1.0s for 0.2s",
            "--fault",
            "corrupt controller inf at 1.3s for 30ms",
            "--fault",
            "corrupt controller out-of-range at 1.5s for 100ms",
        ],
        "2dd6efd59e9d5e9bd3cdb66f498ae27b89ffae407d53ef69c21ca125ef9ce2a2",
    ),
];

/// Runs one case and returns the sha256 (hex) of its trajectory.csv, or why there is none.
fn trajectory_sha256(index: usize, args: &[&str], in_process: bool) -> Result<String, String> {
    let dir = fresh_dir(&format!("golden-{index}{}", if in_process { "-in-process" } else { "" }));
    let output = looplab()
        // The launch files' paths are relative to the repository.
        .current_dir(env!("CARGO_MANIFEST_DIR"))
        .arg("run")
        .args(args)
        .args(COMMON)
        .args(in_process.then_some("--in-process"))
        .arg("--out")
        .arg(&dir)
        .arg("-q")
        .output()
        .map_err(|e| format!("cannot start looplab: {e}"))?;
    let result = if output.status.success() {
        std::fs::read(dir.join("trajectory.csv"))
            .map(|bytes| Sha256::digest(&bytes).iter().map(|b| format!("{b:02x}")).collect())
            .map_err(|e| format!("trajectory.csv: {e}"))
    } else {
        Err(format!(
            "looplab run failed ({}):\n{}\n{}",
            output.status,
            String::from_utf8_lossy(&output.stdout),
            String::from_utf8_lossy(&output.stderr)
        ))
    };
    let _ = std::fs::remove_dir_all(&dir);
    result
}

/// Runs every case of `scenario` (its name starts the case's target) and fails listing each
/// hash that differs.
fn check(scenario: &str, in_process: bool) {
    let cases: Vec<usize> = (0..CASES.len())
        .filter(|&i| {
            let target = CASES[i].1[0];
            target.starts_with(scenario) || target.starts_with(&format!("launch/{scenario}"))
        })
        .collect();
    assert!(!cases.is_empty(), "no case for {scenario}");
    // Concurrent runs never see each other (each has its own run id); a few at a time.
    let workers = std::thread::available_parallelism().map_or(2, |n| n.get()).clamp(2, 4);
    let next = AtomicUsize::new(0);
    let results: Mutex<Vec<Option<Result<String, String>>>> = Mutex::new(vec![None; CASES.len()]);
    std::thread::scope(|scope| {
        for _ in 0..workers {
            scope.spawn(|| {
                while let Some(&i) = cases.get(next.fetch_add(1, Ordering::Relaxed)) {
                    let got = trajectory_sha256(i, CASES[i].1, in_process);
                    results.lock().unwrap()[i] = Some(got);
                }
            });
        }
    });

    let results = results.into_inner().unwrap();
    let mut failures = Vec::new();
    for (&i, got) in cases.iter().zip(cases.iter().map(|&i| results[i].clone())) {
        let (name, args, expected) = CASES[i];
        // A failed run reports why in place of the hash.
        let got = got.expect("every case ran").unwrap_or_else(|why| why);
        if got != *expected {
            failures.push(format!("{name}\n    args:     {args:?}\n    expected: {expected}\n    got:      {got}"));
        }
    }
    assert!(
        failures.is_empty(),
        "{} of {} trajectory.csv hashes ({scenario}, {}) differ from those recorded (817977e; the tilt-rotor rows with issue 12):\n{}",
        failures.len(),
        cases.len(),
        if in_process { "in-process" } else { "five processes" },
        failures.join("\n")
    );
}

#[test]
fn pendulum_five_processes_give_the_recorded_bytes() {
    check("pendulum", false);
}

#[test]
fn pendulum_in_process_gives_the_same_bytes() {
    check("pendulum", true);
}

#[test]
fn quadcopter_five_processes_give_the_recorded_bytes() {
    check("quadcopter", false);
}

#[test]
fn quadcopter_in_process_gives_the_same_bytes() {
    check("quadcopter", true);
}

#[test]
fn tiltrotor_five_processes_give_the_recorded_bytes() {
    check("tiltrotor", false);
}

#[test]
fn tiltrotor_in_process_gives_the_same_bytes() {
    check("tiltrotor", true);
}
