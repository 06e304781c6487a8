//! Golden hashes: the exact bytes of `trajectory.csv` for short lockstep runs of every launch
//! file, each scenario by name, a mass step and the in-loop faults (delay, drop, corrupt).
//!
//! These hashes were re-recorded with issue 13, when the columns got their units (`t_s`,
//! `theta_rad`, ...) and `t` became k / rate (`0.009`, not `0.009000000000000001`): the values
//! parse equal to those of 817977e (the tilt-rotor rows: issue 12), that commit says how it was
//! checked. They must never change in a refactor: a refactor that changes one of them has
//! changed what the loop computes (or how it writes it). Only a deliberate model or format
//! change may re-record them, and its commit says which rows changed and why.
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
        "6cedfd494f6be9aeae62d8500c72b293b18dcc8db27c64e39540ef487af7ea3d",
    ),
    // By name, the scenario's own launch file: the same bytes as the file.
    ("pendulum (by name)", &["pendulum"], "6cedfd494f6be9aeae62d8500c72b293b18dcc8db27c64e39540ef487af7ea3d"),
    (
        "launch/quadcopter.toml",
        &["launch/quadcopter.toml"],
        "d24bdf7ea684518c6374697a9b27a203df081477870e6aae54301ab01ec5649a",
    ),
    ("quadcopter (by name)", &["quadcopter"], "d24bdf7ea684518c6374697a9b27a203df081477870e6aae54301ab01ec5649a"),
    (
        "launch/quadcopter/1-analytic.toml",
        &["launch/quadcopter/1-analytic.toml"],
        "bf0dfee8a94e5b43ac5c9a55f1dd6fe14e9f006d7b962f576f53efe3672284ee",
    ),
    (
        "launch/quadcopter/2-not-rich.toml",
        &["launch/quadcopter/2-not-rich.toml"],
        "1a96b000062ad01b655a1ddd7a0d9b5d044a4db96022ed2fd30f52c6e8fc4e8e",
    ),
    (
        "launch/quadcopter/3-rich.toml",
        &["launch/quadcopter/3-rich.toml"],
        "78437070485cdfb380034bdffadd90d108af0c9d78cab183fdeeb2f0b14c7e78",
    ),
    (
        "launch/quadcopter/4-closed-loop.toml",
        &["launch/quadcopter/4-closed-loop.toml"],
        "181ede7bae5e92a7eac99ed4c88a8dd3e9058ed384787df632569d200743a68f",
    ),
    (
        "launch/quadcopter/5-stochastic-snr.toml",
        &["launch/quadcopter/5-stochastic-snr.toml"],
        "dff828ec5d8b9d0d18cf0c3c088f471e502711e71ade6179c1678f85f971f62e",
    ),
    // Sets only mode and duration: the same bytes as launch/quadcopter.toml.
    (
        "launch/quadcopter/6-lemniscate.toml",
        &["launch/quadcopter/6-lemniscate.toml"],
        "d24bdf7ea684518c6374697a9b27a203df081477870e6aae54301ab01ec5649a",
    ),
    // 1200 Hz, rate loop, held commands; its mass step (35.2 s) is past these 2 s ...
    (
        "launch/quadcopter/7-hover-mass-step.toml",
        &["launch/quadcopter/7-hover-mass-step.toml"],
        "13b4c8c5fe6b49c23d0ae3a3c66706155de943b637572323837f4c6c748455be",
    ),
    // ... so this row moves it to 1 s.
    (
        "launch/quadcopter/7-hover-mass-step.toml, mass step at 1 s",
        &["launch/quadcopter/7-hover-mass-step.toml", "--set", "plant.mass_step_at_s=1.0"],
        "edabe9152269dfabc3e2d8dd0b041649e89fe0558943be466c17f41fff746cec",
    ),
    // Added with the tilt-rotor (issue 12), recorded on its commit: 200 loops at 100 Hz.
    (
        "launch/tiltrotor.toml",
        &["launch/tiltrotor.toml"],
        "a3f834ec63be502d51ed43d6aaab5c75b72818327e968d8bb89bfee86225ef17",
    ),
    ("tiltrotor (by name)", &["tiltrotor"], "a3f834ec63be502d51ed43d6aaab5c75b72818327e968d8bb89bfee86225ef17"),
    // Sets only mode and the kind it already has: the same bytes as launch/tiltrotor.toml.
    (
        "launch/tiltrotor/1-nlls-2l.toml",
        &["launch/tiltrotor/1-nlls-2l.toml"],
        "a3f834ec63be502d51ed43d6aaab5c75b72818327e968d8bb89bfee86225ef17",
    ),
    (
        "launch/tiltrotor/2-nlpt-2l.toml",
        &["launch/tiltrotor/2-nlpt-2l.toml"],
        "3e80c10dde26ce66c1767cc9c12af40fefaed1a60bca5feb6879de4fe90b1586",
    ),
    // Added with the flying inverted pendulum (issue 14), recorded on its commit: 2000 loops at 1 kHz.
    // The default is case (ii); cases 1 and 2 differ only in duration, overridden here.
    ("launch/fip.toml", &["launch/fip.toml"], "4161872281e8fbe2a8ad84e6cf22bfc3f6b330cc6dd0c8f004a38120a419748e"),
    ("fip (by name)", &["fip"], "4161872281e8fbe2a8ad84e6cf22bfc3f6b330cc6dd0c8f004a38120a419748e"),
    (
        "launch/fip/1-reference.toml",
        &["launch/fip/1-reference.toml"],
        "9f285bbbb0295d6922a298ce1f992d0b33c8adfef44186040519a82c28192382",
    ),
    (
        "launch/fip/2-no-disturbance.toml",
        &["launch/fip/2-no-disturbance.toml"],
        "9f285bbbb0295d6922a298ce1f992d0b33c8adfef44186040519a82c28192382",
    ),
    (
        "launch/fip/3-constant-disturbance.toml",
        &["launch/fip/3-constant-disturbance.toml"],
        "4161872281e8fbe2a8ad84e6cf22bfc3f6b330cc6dd0c8f004a38120a419748e",
    ),
    (
        "launch/fip/4-stochastic-disturbance.toml",
        &["launch/fip/4-stochastic-disturbance.toml"],
        "ee0f081f7fb12f120b5defc650f40a2fd9ef8b9086c9e3716bc73fc970862849",
    ),
    (
        "launch/fip/5-experiment.toml",
        &["launch/fip/5-experiment.toml"],
        "576e847128c887cb15695b058f632bc0736b06134dcaa4c8a627172edc6e7453",
    ),
    // Added with the tethered aerial robot (issue 15), recorded on its commit: 2000 loops at 1 kHz.
    // Cases 1 and 2 differ from the default only after phase 1 (3 s or more).
    (
        "launch/tethered.toml",
        &["launch/tethered.toml"],
        "bb5cef38d0800ecb3dd97476448ee2649c111529bb23da0a760f5132f0b5396e",
    ),
    ("tethered (by name)", &["tethered"], "bb5cef38d0800ecb3dd97476448ee2649c111529bb23da0a760f5132f0b5396e"),
    (
        "launch/tethered/1-nominal.toml",
        &["launch/tethered/1-nominal.toml"],
        "bb5cef38d0800ecb3dd97476448ee2649c111529bb23da0a760f5132f0b5396e",
    ),
    (
        "launch/tethered/2-durations.toml",
        &["launch/tethered/2-durations.toml"],
        "bb5cef38d0800ecb3dd97476448ee2649c111529bb23da0a760f5132f0b5396e",
    ),
    (
        "launch/tethered/3-mass-deviation.toml",
        &["launch/tethered/3-mass-deviation.toml"],
        "52a7906709c529944545cf88de9ca8ac3522a707807a4660aa80907c9bef15f4",
    ),
    (
        "launch/tethered/4-general-model.toml",
        &["launch/tethered/4-general-model.toml"],
        "9f397703515ab4d8c1ad059a685a0c37d559d537b85d07cd277c4bbc55d79b4a",
    ),
    (
        "launch/tethered/5-motor-lag.toml",
        &["launch/tethered/5-motor-lag.toml"],
        "5764076b4aeb1b9732cab6038da83b77562422e304ad0bcd4f53e59fff93c57f",
    ),
    (
        "launch/tethered/6-noise.toml",
        &["launch/tethered/6-noise.toml"],
        "7078068ca4d8bb0ca2332797ec7441f33b7ab2e2ae5a81598a33703db9d7d9b2",
    ),
    // Lockstep polls or blocks (`wait.lockstep`, auto picks by the CPUs): how a process waits
    // never changes what the loop computes.
    (
        "pendulum, lockstep polling",
        &["pendulum", "--set", "wait.lockstep=poll"],
        "6cedfd494f6be9aeae62d8500c72b293b18dcc8db27c64e39540ef487af7ea3d",
    ),
    (
        "pendulum, lockstep blocking",
        &["pendulum", "--set", "wait.lockstep=block"],
        "6cedfd494f6be9aeae62d8500c72b293b18dcc8db27c64e39540ef487af7ea3d",
    ),
    (
        "pendulum, lockstep polling, faults: delay controller, drop sensors, corrupt nan",
        &[
            "pendulum",
            "--set",
            "wait.lockstep=poll",
            "--fault",
            "delay controller by 3 ticks at 0.5s for 0.2s",
            "--fault",
            "drop sensors 20% at 0.8s for 0.3s",
            "--fault",
            "corrupt controller nan at 1.2s for 50ms",
        ],
        "c3f26b40252948db8fa59e00da87a0138d2ef8abdb866590c039b3927494a82e",
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
        "c3f26b40252948db8fa59e00da87a0138d2ef8abdb866590c039b3927494a82e",
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
        "2dc0d1d0b2e4143ed878a80d976199c17f8bde300df4d4ab361d50291907c190",
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
        "{} of {} trajectory.csv hashes ({scenario}, {}) differ from those recorded (with issue 13):\n{}",
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

#[test]
fn fip_five_processes_give_the_recorded_bytes() {
    check("fip", false);
}

#[test]
fn fip_in_process_gives_the_same_bytes() {
    check("fip", true);
}

#[test]
fn tethered_five_processes_give_the_recorded_bytes() {
    check("tethered", false);
}

#[test]
fn tethered_in_process_gives_the_same_bytes() {
    check("tethered", true);
}
