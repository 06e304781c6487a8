//! A plant of the user's own in Python (issue 31): a declared system whose `[plant] python` names
//! a class that LoopLab's RK4 integrates in LoopLab's own plant process, started by the launcher
//! as python3 with the `looplab` module that cargo built. Five real processes over real shared
//! memory; numbers from lockstep runs, real-time runs checked for what happened.

use crate::common;

use std::path::{Path, PathBuf};

use common::*;
use looplab_shared::contract::role::Role;

const EXAMPLES: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/services/examples");

fn launcher() -> std::process::Command {
    python_launcher()
}

fn example(file: &str) -> String {
    format!("{EXAMPLES}/{file}")
}

fn trajectory_bytes(run: &Run) -> Vec<u8> {
    std::fs::read(run.dir.join("trajectory.csv")).expect("trajectory.csv")
}

fn log(dir: &Path, role: &str) -> String {
    std::fs::read_to_string(dir.join("logs").join(format!("{role}.log"))).unwrap_or_default()
}

/// The example's launch file in a folder of its own with its Python files, `plant.py` in place
/// of the example plant where given: a test's own plant beside the example's stages (in their
/// folders beside it, as the launch file names them).
fn declared_folder(name: &str, plant: Option<&str>) -> PathBuf {
    let root = fresh_dir(name);
    let dir = root.join("python-plant");
    for folder in ["python-plant", "estimator", "controller"] {
        std::fs::create_dir_all(root.join(folder)).unwrap();
    }
    for file in [
        "python-plant/pendulum_plant.toml",
        "python-plant/pendulum_plant.py",
        "estimator/pendulum_estimator.py",
        "controller/pendulum_controller.py",
    ] {
        std::fs::copy(example(file), root.join(file)).unwrap();
    }
    if let Some(source) = plant {
        std::fs::write(dir.join("pendulum_plant.py"), source).unwrap();
    }
    dir
}

#[test]
fn the_python_pendulum_plant_gives_the_builtin_pendulum_byte_for_byte() {
    let builtin = run_from(launcher(), "builtin", &["pendulum", "--mode", "lockstep", "--duration", "3"]);
    let python = run_from(
        launcher(),
        "python-plant",
        &[&example("python-plant/pendulum_plant.toml"), "--mode", "lockstep", "--duration", "3"],
    );
    let s = python.summary();
    assert!(s.completed, "{:?}", s.stopped_because);
    assert_eq!(python.trajectory().rows.len(), 3000);
    // The same arithmetic in the same order, the same sensors, observer and gains: the whole run
    // is the built-in one.
    assert!(trajectory_bytes(&python) == trajectory_bytes(&builtin), "the trajectories differ");
    assert!(log(&python.dir, "plant").is_empty() || !log(&python.dir, "plant").contains("Error"));
    assert_nothing_left(s);
}

#[test]
fn in_process_a_python_plant_is_refused_in_one_line() {
    let output = launcher()
        .args(["run", &example("python-plant/pendulum_plant.toml"), "--in-process", "-q", "--out"])
        .arg(fresh_dir("in-process"))
        .output()
        .unwrap();
    let said = String::from_utf8_lossy(&output.stderr);
    assert_eq!(output.status.code(), Some(2), "{said}");
    assert!(said.contains("plant.python runs the plant as a Python process of its own"), "{said}");
}

#[test]
fn a_python_plant_and_a_python_controller_killed_in_real_time_restart_and_resume_from_the_snapshot() {
    let dir = declared_folder("killed", None);
    let r = run_from(
        launcher(),
        "killed",
        &[
            dir.join("pendulum_plant.toml").to_str().unwrap(),
            "--mode",
            "realtime",
            "--duration",
            "3",
            "--fault",
            "kill plant at 1s",
            "--fault",
            "kill controller at 2s",
        ],
    );
    let s = r.summary();
    assert!(s.completed, "{:?}", s.stopped_because);
    assert_eq!(s.loops, 3000, "the restarted plant keeps the schedule");
    for (i, role) in [Role::Plant, Role::Controller].into_iter().enumerate() {
        assert_eq!(s.restarts[&role], 1, "{role}: {:?}", s.restarts);
        let f = &s.faults[i];
        assert_eq!(f.detected_by, Some(DetectedBy::ProcessExited), "{f:?}");
        assert!(f.restarted_after_ms.is_some(), "{role}: {f:?}");
    }
    // Resumed from the snapshot: the first state the restarted plant published goes on from the
    // last one before the kill (the wheel spinning, a few ticks of motion later), not from the
    // initial state (θ = 0.05, everything else at rest).
    let t = r.trajectory();
    let (k, wheel) = (t.columns["k"], t.columns["wheel_speed_rad_per_s"]);
    // The ticks whose state the monitor recorded (a tick the plant was down for has empty cells).
    let states: Vec<(f64, f64)> =
        t.rows.iter().filter_map(|row| Some((row[k].parse().ok()?, row[wheel].parse().ok()?))).collect();
    let gap = states.windows(2).position(|w| w[0].0 >= 900.0 && w[1].0 - w[0].0 > 1.0);
    let ((k_before, before), (k_after, after)) = match gap {
        Some(i) => (states[i], states[i + 1]),
        None => panic!("no outage in the plant's states around the kill at tick 1000"),
    };
    assert!(before != 0.0 && after != 0.0, "the wheel turns before the kill and after the restart");
    // The ticks go on (none published twice), and the wheel speed changed by at most what the
    // physics allows over the outage: |φ̈| ≤ k·10 A·(1/J_r + 1/J₀) + a ≈ 310 + 50 rad/s² per second,
    // 0.36 rad/s per tick (the lockstep test below proves the state is the snapshot's exactly).
    assert!(states.windows(2).all(|w| w[1].0 > w[0].0), "a tick was published twice");
    let ticks = k_after - k_before;
    assert!((after - before).abs() <= 0.36 * ticks, "{before} at tick {k_before} → {after} at tick {k_after}");
    for p in last_incarnations(s).values() {
        assert_eq!(p.exit, Exit::Status(0), "{:?}", s.processes);
    }
    assert_nothing_left(s);
    std::fs::remove_dir_all(dir.parent().unwrap()).unwrap();
}

#[test]
fn a_python_plant_killed_in_lockstep_goes_on_from_its_snapshot_byte_for_byte() {
    // The loop is held while the plant is replaced: a plant that went on from its snapshot gives
    // the very run without the kill; one that started again from the initial state would not.
    let common = [&example("python-plant/pendulum_plant.toml")[..], "--mode", "lockstep", "--duration", "2"];
    let nominal = run_from(launcher(), "lockstep-nominal", &common);
    let killed = run_from(launcher(), "lockstep-killed", &[&common[..], &["--fault", "kill plant at 1s"]].concat());
    let s = killed.summary();
    assert_eq!(s.restarts[&Role::Plant], 1, "{:?}", s.restarts);
    assert!(trajectory_bytes(&killed) == trajectory_bytes(&nominal), "the restarted plant did not resume");
    assert_nothing_left(s);
}

/// `looplab run` of the folder's launch file with `args` into `out`, expected to fail (exit 1):
/// its summary and why it failed.
fn failed_run(dir: &Path, out: &Path, args: &[&str]) -> (Summary, String) {
    let output = launcher()
        .arg("run")
        .arg(dir.join("pendulum_plant.toml"))
        .args(args)
        .args(["-q", "--out"])
        .arg(out)
        .output()
        .unwrap();
    assert_eq!(output.status.code(), Some(1), "{}", String::from_utf8_lossy(&output.stderr));
    let s = load_summary(out);
    let why = match &s.stopped_because {
        Some(StopReason::Failed(why)) => why.clone(),
        other => panic!("not a failure: {other:?}"),
    };
    (s, why)
}

const RAISING_PLANT: &str = "\
class Pendulum:
    def __init__(self, plant):
        pass

    def derivative(self, t, x, u, dx):
        if t >= 1.0:
            raise ValueError(\"the model broke\")
        dx[0] = x[1]
";

#[test]
fn a_python_plant_that_raises_ends_the_run_with_one_clear_line() {
    let dir = declared_folder("raising", Some(RAISING_PLANT));
    let out = dir.join("run");
    let (s, why) = failed_run(&dir, &out, &["--duration", "2", "--set", "supervision.plant.restart=never"]);
    assert!(why.contains("plant exited with status 1") && why.contains("ValueError: the model broke"), "{why}");
    let log = log(&out, "plant");
    assert!(log.contains("Traceback (most recent call last):"), "the traceback is in the plant's log: {log}");
    let last = log.lines().last().unwrap_or_default();
    assert!(last.starts_with("plant: error: ") && last.ends_with("ValueError: the model broke"), "{log}");
    assert_nothing_left(&s);
    std::fs::remove_dir_all(dir.parent().unwrap()).unwrap();
}

/// A plant whose model crashes the process (a null pointer read through ctypes: a real SIGSEGV)
/// at t = 1 s, before it wrote a word.
const CRASHING_PLANT: &str = "\
import ctypes

class Pendulum:
    def __init__(self, plant):
        pass

    def derivative(self, t, x, u, dx):
        if t >= 1.0:
            ctypes.string_at(0)
        dx[0] = x[1]
";

/// A crash with nothing in the plant's log is said to be one, not pointed at an empty log.
#[test]
fn a_python_plant_that_segfaults_is_said_to_have_died_of_it_and_its_empty_log_is_not_pointed_at() {
    let dir = declared_folder("crashing", Some(CRASHING_PLANT));
    let out = dir.join("run");
    let (s, why) = failed_run(&dir, &out, &["--duration", "2", "--set", "supervision.plant.restart=never"]);
    assert_eq!(log(&out, "plant"), "", "the plant wrote nothing");
    assert!(
        why.starts_with("plant exited with status signal 11")
            && why.ends_with("; logs/plant.log is empty: it wrote nothing before it ended"),
        "{why}"
    );
    assert_nothing_left(&s);
    std::fs::remove_dir_all(dir.parent().unwrap()).unwrap();
}

#[test]
fn a_python_plant_that_cannot_load_is_bad_input_in_one_line_and_nothing_starts() {
    let no_method = "class Pendulum:\n    def __init__(self, plant):\n        pass\n";
    let import_error = "import no_such_module_ll\n";
    let cases = [
        (None, "pendulum_plant.py:Pendulu", "pendulum_plant.py has no class Pendulu (its classes: Pendulum)"),
        (Some(no_method), "pendulum_plant.py:Pendulum", "class Pendulum in pendulum_plant.py has no derivative"),
        (
            Some(import_error),
            "pendulum_plant.py:Pendulum",
            "pendulum_plant.py does not import: ModuleNotFoundError: No module named 'no_such_module_ll'",
        ),
        (None, "missing_plant.py:Pendulum", "missing_plant.py is not found in "),
    ];
    for (plant, spec, expected) in cases {
        let dir = declared_folder("bad-plant", plant);
        let launch = dir.join("pendulum_plant.toml");
        let text = std::fs::read_to_string(&launch).unwrap();
        let named = text.replace("python = \"pendulum_plant.py:Pendulum\"", &format!("python = \"{spec}\""));
        assert!(named.contains(spec));
        std::fs::write(&launch, named).unwrap();
        let out = dir.join("run");
        let output = launcher().arg("run").arg(&launch).args(["-q", "--out"]).arg(&out).output().unwrap();
        let said = String::from_utf8_lossy(&output.stderr);
        assert_eq!(output.status.code(), Some(2), "{spec}: {said}");
        assert_eq!(said.trim().lines().count(), 1, "{spec}: one line: {said}");
        assert!(said.contains("plant.python") && said.contains(expected), "{spec}: {said}");
        assert!(!out.exists(), "{spec}: nothing starts, no run folder");
        std::fs::remove_dir_all(dir.parent().unwrap()).unwrap();
    }
}

/// The example pendulum whose `derivative` never returns from t = 1 s on: once (the first
/// incarnation leaves `hung_once` beside it), or on every start.
fn hanging_plant(dir: &Path, every_start: bool) -> String {
    let example = std::fs::read_to_string(example("python-plant/pendulum_plant.py")).unwrap();
    let marker = dir.join("hung_once");
    let condition = if every_start { String::new() } else { format!(" and not os.path.exists({marker:?})") };
    let hang = format!(
        "    def derivative(self, t, x, u, dx):\n        if t >= 1.0{condition}:\n            \
         open({marker:?}, \"w\").close()\n            time.sleep(3600)\n        self.model(t, x, u, dx)\n\n    \
         def model(self, t, x, u, dx):"
    );
    let source = example.replace("    def derivative(self, t, x, u, dx):", &hang);
    format!("import os\nimport time\n{source}")
}

/// A plant stuck inside its model neither hangs the run nor passes unseen: stalled for
/// `hang_timeout_s`, it is killed and restarted, and goes on from its snapshot as if it had not
/// hung (lockstep, byte for byte).
#[test]
fn a_python_plant_that_hangs_once_is_killed_restarted_and_goes_on_byte_for_byte() {
    let dir = declared_folder("hangs-once", None);
    std::fs::write(dir.join("pendulum_plant.py"), hanging_plant(&dir, false)).unwrap();
    let common = ["--mode", "lockstep", "--duration", "2"];
    let nominal = run_from(
        launcher(),
        "hang-nominal",
        &[&[&example("python-plant/pendulum_plant.toml")[..]], &common[..]].concat(),
    );
    let launch = dir.join("pendulum_plant.toml");
    let hung = run_from(
        launcher(),
        "hangs-once",
        &[&[launch.to_str().unwrap()], &common[..], &["--set", "supervision.hang_timeout_s=1"]].concat(),
    );
    let s = hung.summary();
    assert!(s.completed, "{:?}", s.stopped_because);
    assert_eq!(s.restarts[&Role::Plant], 1, "{:?}", s.restarts);
    let killed = "inside its own code (supervision.hang_timeout_s = 1 s); killed it";
    let said = s.timeline.iter().filter(|e| e.event.starts_with("plant hung: stalled ") && e.event.ends_with(killed));
    assert_eq!(said.count(), 1, "{:?}", s.timeline);
    assert!(trajectory_bytes(&hung) == trajectory_bytes(&nominal), "the restarted plant did not go on");
    assert_nothing_left(s);
    std::fs::remove_dir_all(dir.parent().unwrap()).unwrap();
}

/// A plant that hangs on every start is a crash loop: the run ends after three hangs, says so,
/// and counts the loops the monitor recorded although the plant never reported.
#[test]
fn a_python_plant_that_hangs_on_every_start_ends_the_run_and_its_loops_are_counted() {
    let dir = declared_folder("hangs-always", None);
    std::fs::write(dir.join("pendulum_plant.py"), hanging_plant(&dir, true)).unwrap();
    let out = dir.join("run");
    let (s, why) =
        failed_run(&dir, &out, &["--mode", "lockstep", "--duration", "2", "--set", "supervision.hang_timeout_s=0.5"]);
    assert!(why.starts_with("plant hung: stalled "), "{why}");
    assert!(why.contains("inside its own code, and was killed; not restarted: a crash loop"), "{why}");
    assert_eq!(s.restarts[&Role::Plant], 2, "{:?}", s.restarts);
    // The plant hung in its step to t = 1 s (RK4 looks at t + dt): about 1000 loops were recorded.
    let rows = Table::read(&out.join("trajectory.csv")).rows.len() as u64;
    assert_eq!(s.loops, rows, "the summary's loops against trajectory.csv's rows");
    assert!(rows > 900, "{rows} rows");
    assert_nothing_left(&s);
    std::fs::remove_dir_all(dir.parent().unwrap()).unwrap();
}

/// A Python plant whose module never finishes importing is bad input within the ready timeout,
/// in one line, and nothing starts: its check runs in a child that is killed, never a hang.
#[test]
fn a_python_plant_whose_import_never_returns_is_bad_input_within_the_ready_timeout() {
    let dir = declared_folder("import-hangs", Some("import time\ntime.sleep(3600)\n"));
    let out = dir.join("run");
    let output = launcher()
        .arg("run")
        .arg(dir.join("pendulum_plant.toml"))
        .args(["--duration", "1", "-q", "--set", "supervision.ready_timeout_s=1", "--out"])
        .arg(&out)
        .output()
        .unwrap();
    let said = String::from_utf8_lossy(&output.stderr);
    assert_eq!(output.status.code(), Some(2), "{said}");
    assert!(said.contains("plant.python") && said.contains("did not finish within 1 s"), "{said}");
    assert_eq!(said.trim().lines().count(), 1, "{said}");
    assert!(!out.exists(), "nothing starts");
    std::fs::remove_dir_all(dir.parent().unwrap()).unwrap();
}
