//! Golden hashes: the exact bytes of `trajectory.csv` for short lockstep runs of every launch
//! file, each scenario by name, a mass step and the in-loop faults (delay, drop, corrupt).
//!
//! These hashes were re-recorded with issue 13, when the columns got their units (`t_s`,
//! `theta_rad`, ...) and `t` became k / rate (`0.009`, not `0.009000000000000001`): the values
//! parse equal to those of 817977e (the tilt-rotor rows: issue 12), that commit says how it was
//! checked. They must never change in a refactor: a refactor that changes one of them has
//! changed what the loop computes (or how it writes it). Only a deliberate model or format
//! change may re-record them, and its commit says which rows changed and why.
//! Re-recorded with issue 30, which added the applied input's columns (`applied.*`) after the
//! command's: every file with those columns cut off has the bytes of the hash before.
//! Re-recorded with issue 34 for the pendulum's rows (its current limit is the drive's ±10 A peak,
//! not ±5 A: every pendulum row's current saturates in its first second) and for
//! launch/fip/5-experiment.toml (the filter starts at the measured rod direction, and a 0.25 N
//! vertical force error acts), and for the tilt-rotor's rows (the H2/H∞ gains; the LKFUI starts
//! from the launch's start); no other row changed.
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

use crate::common;

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
        "60c15b033268e52f261957d2292f96d1415a2855f0d452f8000bed24767e23a3",
    ),
    // By name, the scenario's own launch file: the same bytes as the file.
    ("pendulum (by name)", &["pendulum"], "60c15b033268e52f261957d2292f96d1415a2855f0d452f8000bed24767e23a3"),
    (
        "launch/quadcopter.toml",
        &["launch/quadcopter.toml"],
        "c958073500839e3e7ce74b6d1da89740c05aeb639e616f47feb4a11d09b9b3cc",
    ),
    ("quadcopter (by name)", &["quadcopter"], "c958073500839e3e7ce74b6d1da89740c05aeb639e616f47feb4a11d09b9b3cc"),
    (
        "launch/quadcopter/1-analytic.toml",
        &["launch/quadcopter/1-analytic.toml"],
        "fb5fa29cce1c6eec3e68d2540a250336e872670d97879b5a0b7c45ec6a8c0829",
    ),
    (
        "launch/quadcopter/2-not-rich.toml",
        &["launch/quadcopter/2-not-rich.toml"],
        "1c96e8a7582813dfe53d460a4f9ec3fceb1c0d3b90d8c24e037717c730669885",
    ),
    (
        "launch/quadcopter/3-rich.toml",
        &["launch/quadcopter/3-rich.toml"],
        "f6e2f228a3e33d24e9a86203fdb77575adb579535ba0d4464fffc9a4885cea75",
    ),
    (
        "launch/quadcopter/4-closed-loop.toml",
        &["launch/quadcopter/4-closed-loop.toml"],
        "df74025beb8d7d355ca8f4fc8e26322d65ced95170931890eb5e0c24fad8e5b6",
    ),
    (
        "launch/quadcopter/5-stochastic-snr.toml",
        &["launch/quadcopter/5-stochastic-snr.toml"],
        "481f9d88d3c3da0ab476c93c4bd300c51794451368e60820893a13305c08bdd4",
    ),
    // Sets only mode and duration: the same bytes as launch/quadcopter.toml.
    (
        "launch/quadcopter/6-lemniscate.toml",
        &["launch/quadcopter/6-lemniscate.toml"],
        "c958073500839e3e7ce74b6d1da89740c05aeb639e616f47feb4a11d09b9b3cc",
    ),
    // 1200 Hz, rate loop, held commands; its mass step (35.2 s) is past these 2 s ...
    (
        "launch/quadcopter/7-hover-mass-step.toml",
        &["launch/quadcopter/7-hover-mass-step.toml"],
        "2e6e41b94e59ea5fcb8085b7f4c1630bed521b95141d4918bd998054dd181e1d",
    ),
    // ... so this row moves it to 1 s.
    (
        "launch/quadcopter/7-hover-mass-step.toml, mass step at 1 s",
        &["launch/quadcopter/7-hover-mass-step.toml", "--set", "plant.mass_step_at_s=1.0"],
        "4d91824ca75780cb55a902893135ac4dfb95ae9dbfc6482da8571578387e8b35",
    ),
    // Added with the tilt-rotor (issue 12): 200 loops at 100 Hz; re-recorded with issue 34
    // (the H2/H∞ gains; the LKFUI starting from the launch's start).
    (
        "launch/tiltrotor.toml",
        &["launch/tiltrotor.toml"],
        "39d8438a26c0d62bf7d841fd8a4e8f7b620547520e2feb18083e766d226d21f5",
    ),
    ("tiltrotor (by name)", &["tiltrotor"], "39d8438a26c0d62bf7d841fd8a4e8f7b620547520e2feb18083e766d226d21f5"),
    // Sets only mode and the kind it already has: the same bytes as launch/tiltrotor.toml.
    (
        "launch/tiltrotor/1-nlls-2l.toml",
        &["launch/tiltrotor/1-nlls-2l.toml"],
        "39d8438a26c0d62bf7d841fd8a4e8f7b620547520e2feb18083e766d226d21f5",
    ),
    (
        "launch/tiltrotor/2-nlpt-2l.toml",
        &["launch/tiltrotor/2-nlpt-2l.toml"],
        "d0fe1621f97b086610599281d2d12504e8adacaa76fbb5e28758ce0c355f3afd",
    ),
    // Added with the flying inverted pendulum (issue 14), recorded on its commit: 2000 loops at 1 kHz.
    // The default is case (ii); cases 1 and 2 differ only in duration, overridden here.
    ("launch/fip.toml", &["launch/fip.toml"], "410dfc7e8804227e869c29df2f245bd339a6ffbc4597c20e623ff0d9a8094b87"),
    ("fip (by name)", &["fip"], "410dfc7e8804227e869c29df2f245bd339a6ffbc4597c20e623ff0d9a8094b87"),
    (
        "launch/fip/1-reference.toml",
        &["launch/fip/1-reference.toml"],
        "f731d0b4f7273dd5cf22908b1e4bcec06cb7d953289359280c3d686018439020",
    ),
    (
        "launch/fip/2-no-disturbance.toml",
        &["launch/fip/2-no-disturbance.toml"],
        "f731d0b4f7273dd5cf22908b1e4bcec06cb7d953289359280c3d686018439020",
    ),
    (
        "launch/fip/3-constant-disturbance.toml",
        &["launch/fip/3-constant-disturbance.toml"],
        "410dfc7e8804227e869c29df2f245bd339a6ffbc4597c20e623ff0d9a8094b87",
    ),
    (
        "launch/fip/4-stochastic-disturbance.toml",
        &["launch/fip/4-stochastic-disturbance.toml"],
        "5533372f4b13e83e323946db8a3814b06e6a18315f87fd2382a52eceda1dc7c9",
    ),
    (
        "launch/fip/5-experiment.toml",
        &["launch/fip/5-experiment.toml"],
        "7184c5a3f24fc763ec0e099a683b1920090ed7c97e2582b39f6c7039b0433f0a",
    ),
    // Added with the tethered aerial robot (issue 15), recorded on its commit: 2000 loops at 1 kHz.
    // Cases 1 and 2 differ from the default only after phase 1 (3 s or more).
    (
        "launch/tethered.toml",
        &["launch/tethered.toml"],
        "7c56622b9593852f814a25a6c18a1167bef90a743f1cb3ef204ae191c00eaa3a",
    ),
    ("tethered (by name)", &["tethered"], "7c56622b9593852f814a25a6c18a1167bef90a743f1cb3ef204ae191c00eaa3a"),
    (
        "launch/tethered/1-nominal.toml",
        &["launch/tethered/1-nominal.toml"],
        "7c56622b9593852f814a25a6c18a1167bef90a743f1cb3ef204ae191c00eaa3a",
    ),
    (
        "launch/tethered/2-durations.toml",
        &["launch/tethered/2-durations.toml"],
        "7c56622b9593852f814a25a6c18a1167bef90a743f1cb3ef204ae191c00eaa3a",
    ),
    (
        "launch/tethered/3-mass-deviation.toml",
        &["launch/tethered/3-mass-deviation.toml"],
        "9c8edbeb495ef199aa0c6775b79dbaa9d8b6b5a32dc0ab22b8b63cdc560efc75",
    ),
    (
        "launch/tethered/4-general-model.toml",
        &["launch/tethered/4-general-model.toml"],
        "480280c5a0314f81ee1fa9360dfde0ed4af251b6ad038fae3f1c3458abb2ac2c",
    ),
    (
        "launch/tethered/5-motor-lag.toml",
        &["launch/tethered/5-motor-lag.toml"],
        "17cee181d84b419238d7376ecd6b1d42e94ca28c2837cb2adf736fe35f0fb2c2",
    ),
    (
        "launch/tethered/6-noise.toml",
        &["launch/tethered/6-noise.toml"],
        "79367b4c9c6d23ea7833f028769eec403dc7ca26ac07d24103d26d0574030aa7",
    ),
    // Lockstep polls, blocks or hands off (`wait.lockstep`, auto picks by the CPUs): how a process waits
    // never changes what the loop computes.
    (
        "pendulum, lockstep polling",
        &["pendulum", "--set", "wait.lockstep=poll"],
        "60c15b033268e52f261957d2292f96d1415a2855f0d452f8000bed24767e23a3",
    ),
    (
        "pendulum, lockstep blocking",
        &["pendulum", "--set", "wait.lockstep=block"],
        "60c15b033268e52f261957d2292f96d1415a2855f0d452f8000bed24767e23a3",
    ),
    (
        "pendulum, lockstep handing off",
        &["pendulum", "--set", "wait.lockstep=handoff"],
        "60c15b033268e52f261957d2292f96d1415a2855f0d452f8000bed24767e23a3",
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
        "6f73e70d475343efc587bb4c972fbbaf7be30aba12b3c32a8d78334b01010456",
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
        "6f73e70d475343efc587bb4c972fbbaf7be30aba12b3c32a8d78334b01010456",
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
        "fe4d8a6bfb6cf60ff2b22a4fcb2b68fdb110cfd0f21c57a3189a86bc885e8994",
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
        "{} of {} trajectory.csv hashes ({scenario}, {}) differ from those recorded (with issue 34):\n{}",
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
