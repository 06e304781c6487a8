//! Stages of the user's own in Python (issue 28): the Python examples in services/examples run
//! by a real python3 with the `looplab` module that cargo built, as five real processes over real
//! shared memory. Numbers come from lockstep runs; real-time runs are checked for what happened.

use crate::common;

use common::*;

const EXAMPLES: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/services/examples");

/// Gains other than the defaults that still hold the pendulum up.
const OTHER_GAINS: &str = "controller.gains=[-450.0, -65.0, -1.2]";

fn launcher() -> std::process::Command {
    python_launcher()
}

fn example(file: &str) -> String {
    format!("{EXAMPLES}/{file}")
}

/// `--set` for a Python stage running `script`.
fn python_stage(role: &str, script: &str) -> String {
    format!("stages.{role}.command=[\"python3\", \"{script}\"]")
}

/// A fresh folder holding `source` as a script, and the `--set` that runs it as the controller;
/// `wrapping`: the script runs the example controller, whose path it is given.
fn controller_script(name: &str, source: &str, wrapping: bool) -> (std::path::PathBuf, String) {
    let dir = fresh_dir(name);
    std::fs::create_dir_all(&dir).unwrap();
    let script = dir.join(format!("{name}.py"));
    std::fs::write(&script, source).unwrap();
    let mut command = vec!["python3".to_owned(), script.display().to_string()];
    if wrapping {
        command.push(example("controller/pendulum_controller.py"));
    }
    let quoted: Vec<String> = command.iter().map(|c| format!("{c:?}")).collect();
    (dir, format!("stages.controller.command=[{}]", quoted.join(", ")))
}

fn trajectory_bytes(run: &Run) -> Vec<u8> {
    std::fs::read(run.dir.join("trajectory.csv")).expect("trajectory.csv")
}

fn log(run: &Run, role: &str) -> String {
    std::fs::read_to_string(run.dir.join("logs").join(format!("{role}.log"))).unwrap_or_default()
}

#[test]
fn the_python_controller_port_is_byte_identical_to_the_builtin_with_default_and_other_gains() {
    let launch = example("controller/pendulum_python.toml");
    for gains in [None, Some(OTHER_GAINS)] {
        let mut args = vec!["--mode", "lockstep", "--duration", "3"];
        args.extend(gains.iter().flat_map(|g| ["--set", g]));
        let builtin = run_from(launcher(), "builtin-controller", &[&["pendulum"], args.as_slice()].concat());
        let python = run_from(launcher(), "python-controller", &[&[launch.as_str()], args.as_slice()].concat());
        assert!(python.summary().completed, "{:?}", python.summary().stopped_because);
        assert!(python.metric("theta_max_abs_rad") < 0.1, "{gains:?} should hold the pendulum up");
        assert!(trajectory_bytes(&python) == trajectory_bytes(&builtin), "{gains:?}: the trajectories differ");
        assert_nothing_left(python.summary());
    }
    // The stage that ran was the Python one: without the module it cannot start.
    let dir = fresh_dir("python-without-module");
    let output = looplab()
        .env("PYTHONPATH", &dir)
        .args(["run", &launch, "--duration", "1", "-q", "--out"])
        .arg(&dir)
        .output()
        .unwrap();
    assert!(!output.status.success());
    let said = String::from_utf8_lossy(&output.stderr);
    assert!(said.contains("No module named 'looplab'"), "{said}");
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn the_python_bias_observer_gives_the_builtin_estimates() {
    let common = ["pendulum", "--mode", "lockstep", "--duration", "3"];
    let builtin = run_from(launcher(), "builtin-estimator", &common);
    let stage = python_stage("estimator", &example("estimator/pendulum_estimator.py"));
    let python = run_from(launcher(), "python-estimator", &[&common[..], &["--set", &stage]].concat());
    let (ours, theirs) = (python.trajectory(), builtin.trajectory());
    assert_eq!(ours.rows.len(), 3000);
    for column in ["est.theta_rad", "est.theta_dot_rad_per_s", "est.wheel_speed_rad_per_s", "est.bias_rad"] {
        let worst = ours.col(column).iter().zip(theirs.col(column)).map(|(a, b)| (a - b).abs()).fold(0.0, f64::max);
        assert!(worst <= 1e-9, "{column}: the Python estimate is {worst} from the built-in's");
    }
    // The same arithmetic in the same order: the whole run is the built-in one, byte for byte.
    assert!(trajectory_bytes(&python) == trajectory_bytes(&builtin), "within 1e-9 but not byte-identical");
    assert_nothing_left(python.summary());
}

/// Noise-free sensors sampled every loop, built in and in Python (`ideal_sensors.py` copies the
/// true state): the same readings, so the same run, byte for byte.
#[test]
fn python_sensors_reading_the_truth_give_the_builtin_ideal_sensors_run() {
    let ideal = [
        "--set",
        "sensors.encoder.bias=0.0",
        "--set",
        "sensors.encoder.quantum=0.0",
        "--set",
        "sensors.wheel_speed.period_s=0.001",
        "--set",
        "sensors.wheel_speed.noise_std=0.0",
    ];
    let common = [&["pendulum", "--mode", "lockstep", "--duration", "2"][..], &ideal[..]].concat();
    let builtin = run_from(launcher(), "builtin-ideal-sensors", &common);
    let stage = python_stage("sensors", &example("sensors/ideal_sensors.py"));
    let python = run_from(launcher(), "python-ideal-sensors", &[&common[..], &["--set", &stage]].concat());
    assert!(python.summary().completed, "{:?}", python.summary().stopped_because);
    assert!(trajectory_bytes(&python) == trajectory_bytes(&builtin), "the trajectories differ");
    assert_nothing_left(python.summary());
}

#[test]
fn an_integrating_python_controller_killed_in_lockstep_resumes_its_integrator() {
    // The plant holds the loop while the controller is replaced, so a restarted controller that
    // thawed its integrator continues the very run without the kill; one that started from
    // zero would command otherwise.
    let stage = python_stage("controller", &example("controller/integrating_controller.py"));
    let killed = killed_in_lockstep_like_the_nominal("integrating", &stage);
    assert!(log(&killed, "controller").contains("thawed: integral"), "{}", log(&killed, "controller"));
}

/// The pendulum in lockstep for 3 s with the controller `stage`, and again with it killed at 2 s:
/// restarted once, the run without the kill byte for byte, nothing left. Returns the killed run.
fn killed_in_lockstep_like_the_nominal(name: &str, stage: &str) -> Run {
    let common = ["pendulum", "--mode", "lockstep", "--duration", "3", "--set", stage];
    let nominal = run_from(launcher(), &format!("{name}-nominal"), &common);
    let killed =
        run_from(launcher(), &format!("{name}-killed"), &[&common[..], &["--fault", "kill controller at 2s"]].concat());
    let s = killed.summary();
    assert_eq!(s.restarts[&Role::Controller], 1, "{:?}", s.restarts);
    assert!(trajectory_bytes(&killed) == trajectory_bytes(&nominal), "the restarted controller did not resume");
    assert_nothing_left(s);
    killed
}

/// A controller whose integral runs over a window of the last 8190 loops: its whole state (the
/// window, where it writes next and the last step's time: 64 KiB, `looplab.MAX_FROZEN_BYTES`)
/// decides every command, so a run killed in lockstep is the run without the kill only if all of
/// it came back.
const WINDOWED_CONTROLLER: &str = r#"import math
import struct
import sys
from array import array

import looplab

WINDOW = (looplab.MAX_FROZEN_BYTES - 16) // 8  # theta·dt of the last WINDOW loops


class WindowedController:
    def __init__(self, stage):
        self.k1, self.k2, self.k3 = stage.config["controller"]["gains"]
        self.limit = stage.config["model"]["current_limit_a"]
        self.window = array("d", bytes(8 * WINDOW))
        self.next = 0
        self.t_last = None

    def step(self, t, x, u):
        if self.t_last is not None:
            self.window[self.next] = x[0] * (t - self.t_last)
            self.next = (self.next + 1) % WINDOW
        self.t_last = t
        integral = math.fsum(self.window)
        current = -(self.k1 * x[0] + self.k2 * x[1] + self.k3 * x[2] - 20.0 * integral)
        u[0] = min(max(current, -self.limit), self.limit)

    def freeze(self):
        if self.t_last is None:
            return None
        return struct.pack("<qd", self.next, self.t_last) + self.window.tobytes()

    def thaw(self, data):
        self.next, self.t_last = struct.unpack_from("<qd", data)
        self.window = array("d")
        self.window.frombytes(data[16:])
        print(f"thawed {len(data)} bytes", file=sys.stderr)


looplab.run(WindowedController)
"#;

#[test]
fn a_python_stage_keeps_64_kib_across_a_kill_and_more_ends_it_with_one_line() {
    let dir = fresh_dir("frozen-64k");
    std::fs::create_dir_all(&dir).unwrap();
    let script = dir.join("windowed_controller.py");
    std::fs::write(&script, WINDOWED_CONTROLLER).unwrap();
    let stage = python_stage("controller", script.to_str().unwrap());
    let killed = killed_in_lockstep_like_the_nominal("windowed", &stage);
    assert!(log(&killed, "controller").contains("thawed 65536 bytes"), "{}", log(&killed, "controller"));

    // One byte more than a snapshot holds ends the incarnation with the reason.
    let script = dir.join("too_much.py");
    std::fs::write(
        &script,
        "import looplab\n\n\nclass TooMuch:\n    def __init__(self, stage):\n        pass\n\n    \
         def step(self, t, x, u):\n        pass\n\n    def freeze(self):\n        \
         return bytes(looplab.MAX_FROZEN_BYTES + 1)\n\n\nlooplab.run(TooMuch)\n",
    )
    .unwrap();
    let (why, s) = failed_controller_run(&script, "1", &dir.join("run"));
    let line = "controller: error: freeze returned 65537 bytes; a snapshot keeps at most 65536";
    assert!(why.contains(line), "{why}");
    assert_nothing_left(&s);
    std::fs::remove_dir_all(&dir).unwrap();
}

/// A lockstep run of the pendulum, `duration_s` long, with `script` as its controller and no
/// restart, into `out`; it must fail (exit 1): why, and its summary.
fn failed_controller_run(script: &std::path::Path, duration_s: &str, out: &std::path::Path) -> (String, Summary) {
    let stage = python_stage("controller", script.to_str().unwrap());
    let output = launcher()
        .args(["run", "pendulum", "--mode", "lockstep", "--duration", duration_s, "-q", "--set", &stage])
        .args(["--set", "supervision.controller.restart=never", "--out"])
        .arg(out)
        .output()
        .unwrap();
    assert_eq!(output.status.code(), Some(1), "{}", String::from_utf8_lossy(&output.stderr));
    let s = load_summary(out);
    match &s.stopped_because {
        Some(StopReason::Failed(why)) => (why.clone(), s),
        other => panic!("not a failure: {other:?}"),
    }
}

/// The thawed integrator's (integral, t) from the controller's log.
fn thawed(log: &str) -> Option<(f64, f64)> {
    let line = log.lines().find_map(|l| l.strip_prefix("thawed: integral "))?;
    let (integral, rest) = line.split_once(" rad·s at t = ")?;
    Some((integral.parse().ok()?, rest.strip_suffix(" s")?.parse().ok()?))
}

#[test]
fn an_integrating_python_controller_in_real_time_survives_a_kill_a_stop_and_a_delay() {
    let stage = python_stage("controller", &example("controller/integrating_controller.py"));
    let faults = ["kill controller at 2s", "stop controller at 2s for 150ms", "delay controller by 3ms at 2s for 0.5s"];
    for fault in faults {
        let r = run_from(
            launcher(),
            "integrating-realtime",
            &["pendulum", "--duration", "3", "--set", &stage, "--fault", fault],
        );
        let s = r.summary();
        assert!(s.completed, "{fault}: {:?}", s.stopped_because);
        let f = &s.faults[0];
        let log = log(&r, "controller");
        if fault.starts_with("kill") {
            assert_eq!(s.restarts[&Role::Controller], 1, "{fault}: {:?}", s.restarts);
            assert_eq!(f.detected_by, Some(DetectedBy::ProcessExited), "{f:?}");
            assert!(f.restarted_after_ms.is_some(), "{f:?}");
            // The restarted controller thawed its predecessor's integrator as it was near the kill.
            let (integral, t) = thawed(&log).unwrap_or_else(|| panic!("no thaw in the log:\n{log}"));
            assert!(integral != 0.0 && t > 1.0 && t < 3.0, "thawed {integral} at {t} s");
        } else {
            assert_eq!(s.restarts[&Role::Controller], 0, "{fault}: a live process is not restarted");
            assert!(!log.contains("thawed"), "{fault}: {log}");
        }
        if fault.starts_with("stop") {
            assert_eq!(f.detected_by, Some(DetectedBy::InputDeadline), "{f:?}");
        }
        assert!(f.effect.is_some(), "{fault}: no effect recorded: {f:?}");
        for p in last_incarnations(s).values() {
            assert_eq!(p.exit, Exit::Status(0), "{fault}: {:?}", s.processes);
        }
        assert_nothing_left(s);
    }
}

/// A controller whose step raises from t = 1 s on.
const RAISING: &str = "import looplab\n\n\nclass Raising:\n    def __init__(self, stage):\n        pass\n\n    \
                       def step(self, t, x, u):\n        if t >= 1.0:\n            raise ValueError(\"boom\")\n\n\n\
                       looplab.run(Raising)\n";

#[test]
fn a_python_step_that_raises_ends_the_run_with_its_last_line() {
    let dir = fresh_dir("raising");
    std::fs::create_dir_all(&dir).unwrap();
    let script = dir.join("raising_controller.py");
    std::fs::write(&script, RAISING).unwrap();
    let out = dir.join("run");
    let (why, s) = failed_controller_run(&script, "3", &out);
    let last = "controller: error: step failed at t = 1.000000 s: ValueError: boom";
    assert!(why.contains(&format!("controller exited with status 1: {last}")), "{why}");
    // The whole traceback is in the stage's log, the error line last.
    let log = std::fs::read_to_string(out.join("logs/controller.log")).unwrap();
    assert!(log.contains("Traceback (most recent call last):") && log.contains("raise ValueError(\"boom\")"), "{log}");
    assert_eq!(log.lines().last(), Some(last), "{log}");
    assert_nothing_left(&s);
    std::fs::remove_dir_all(&dir).unwrap();
}

/// A step that raises at the same point on every start is a crash loop: after three starts it is
/// not restarted again (not ten times with a growing backoff), and the run says why.
#[test]
fn a_python_step_that_fails_on_every_start_is_a_crash_loop_and_not_restarted_again() {
    let dir = fresh_dir("crash-loop");
    std::fs::create_dir_all(&dir).unwrap();
    let script = dir.join("raising_controller.py");
    std::fs::write(&script, RAISING).unwrap();
    let out = dir.join("run");
    let stage = python_stage("controller", script.to_str().unwrap());
    let output = launcher()
        .args(["run", "pendulum", "--mode", "lockstep", "--duration", "3", "-q", "--set", &stage, "--out"])
        .arg(&out)
        .output()
        .unwrap();
    assert_eq!(output.status.code(), Some(1), "{}", String::from_utf8_lossy(&output.stderr));
    let s = load_summary(&out);
    assert_eq!(s.restarts[&Role::Controller], 2, "{:?}", s.restarts);
    let why = match &s.stopped_because {
        Some(StopReason::Failed(why)) => why.clone(),
        other => panic!("not a failure: {other:?}"),
    };
    assert!(
        why.contains("ValueError: boom; not restarted: a crash loop, the same error on each of its last 3 starts"),
        "{why}"
    );
    assert_nothing_left(&s);
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn a_python_step_gets_the_stage_and_the_same_two_float64_views_every_loop() {
    let dir = fresh_dir("views");
    std::fs::create_dir_all(&dir).unwrap();
    let script = dir.join("checking_controller.py");
    // Any failed check raises in the stage, which ends the run.
    std::fs::write(
        &script,
        r#"import looplab


class Checking:
    def __init__(self, stage):
        assert stage.role == "controller" and stage.incarnation == 0, stage
        assert stage.input_names == ["theta", "theta_dot", "wheel_speed", "bias"], stage.input_names
        assert stage.output_names == ["current"], stage.output_names
        assert stage.config["scenario"] == "pendulum" and stage.config["model"]["current_limit_a"] == 10.0
        self.k = stage.config["controller"]["gains"]
        self.views = None

    def step(self, t, x, u):
        if self.views is None:
            self.views = (x, u)
            assert x.format == "d" and u.format == "d" and x.readonly and not u.readonly
            assert (len(x), len(u)) == (4, 1)
            try:
                x[0] = 1.0
                raise AssertionError("x is writable")
            except TypeError:
                pass
        assert x is self.views[0] and u is self.views[1], "new views"
        assert u[0] == 0.0, "u starts at zero every loop"
        u[0] = min(max(-(self.k[0] * x[0] + self.k[1] * x[1] + self.k[2] * x[2]), -5.0), 5.0)


looplab.run(Checking)
"#,
    )
    .unwrap();
    let stage = python_stage("controller", script.to_str().unwrap());
    let r = run_from(launcher(), "views", &["pendulum", "--mode", "lockstep", "--duration", "1", "--set", &stage]);
    assert!(r.summary().completed, "{:?}", r.summary().stopped_because);
    assert!(r.metric("theta_max_abs_rad") < 0.1, "the views' command reached the plant");
    assert_nothing_left(r.summary());
    std::fs::remove_dir_all(&dir).unwrap();
}

/// A controller that starts two children before it runs: one holds its output, one closed its
/// descriptors. Each prints their pids on stderr.
const CONTROLLER_WITH_CHILDREN: &str = r#"import runpy
import subprocess
import sys

holder = subprocess.Popen(["sleep", "300"])
quiet = subprocess.Popen(["sleep", "301"], stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL,
                         stderr=subprocess.DEVNULL)
print(f"children {holder.pid} {quiet.pid}", file=sys.stderr, flush=True)
runpy.run_path(sys.argv[1], run_name="__main__")
"#;

/// What a stage starts ends with it: a child holding its output neither hides its death (killed
/// mid-run, it is restarted) nor hangs the launcher at the end, and every child is killed and
/// named in the summary's notes, in each incarnation.
#[test]
fn the_children_a_stage_leaves_behind_are_killed_and_named_and_hang_nothing() {
    let (dir, stage) = controller_script("stage-children", CONTROLLER_WITH_CHILDREN, true);
    let common = ["pendulum", "--mode", "lockstep", "--duration", "2", "--set", &stage];
    let run = run_from(launcher(), "stage-children", &[&common[..], &["--fault", "kill controller at 1s"]].concat());
    let s = run.summary();
    assert!(s.completed, "{:?}", s.stopped_because);
    assert_eq!(s.restarts[&Role::Controller], 1, "{:?}", s.restarts);
    let children: Vec<(u32, u32)> = log(&run, "controller")
        .lines()
        .filter_map(|l| l.strip_prefix("children "))
        .map(|pids| {
            let (holder, quiet) = pids.split_once(' ').unwrap();
            (holder.parse().unwrap(), quiet.parse().unwrap())
        })
        .collect();
    assert_eq!(children.len(), 2, "one pair per incarnation: {children:?}");
    for (holder, quiet) in children {
        let said = format!(
            "controller exited leaving 2 process(es) it started running: pid {} (sleep), pid {} (sleep); killed them",
            holder.min(quiet),
            holder.max(quiet)
        );
        assert!(s.notes.contains(&said), "{said} not in {:?}", s.notes);
        assert!(!alive(holder.into()) && !alive(quiet.into()), "{holder} or {quiet} outlived the run");
    }
    assert_nothing_left(s);
    std::fs::remove_dir_all(&dir).unwrap();
}

const CONTROLLER_THAT_WILL_NOT_EXIT: &str = r#"import runpy
import signal
import sys
import time

runpy.run_path(sys.argv[1], run_name="__main__")
# LoopLab's runner returned at the run's end; this stage then refuses to exit.
signal.signal(signal.SIGTERM, signal.SIG_IGN)
time.sleep(300)
"#;

/// A stage that will not exit at the run's end is killed and said to be, not reported as if it
/// had crashed on its own.
#[test]
fn a_stage_killed_at_the_runs_end_because_it_would_not_exit_is_said_so() {
    let (dir, stage) = controller_script("will-not-exit", CONTROLLER_THAT_WILL_NOT_EXIT, true);
    let out = dir.join("run");
    let output = launcher()
        .args(["run", "pendulum", "--mode", "lockstep", "--duration", "1", "-q", "--set", &stage, "--out"])
        .arg(&out)
        .output()
        .unwrap();
    let said = String::from_utf8_lossy(&output.stderr);
    assert_eq!(output.status.code(), Some(1), "{said}");
    assert!(
        said.contains(
            "controller did not exit within 5 s of the launcher's SIGTERM at the run's end, and was killed; see the \
             logs folder"
        ),
        "{said}"
    );
    let s = load_summary(&out);
    assert_eq!(s.loops, 1000, "the loop itself ran to its end");
    assert_nothing_left(&s);
    std::fs::remove_dir_all(&dir).unwrap();
}

/// The example controller, but its first incarnation ends itself with status 0 at t = 0.5 s
/// (`os._exit(0)`; the marker beside the script says a first one ran).
const CONTROLLER_THAT_EXITS_CLEANLY_ONCE: &str = r#"import os
import sys
import looplab

MARKER = os.path.join(os.path.dirname(os.path.abspath(__file__)), "exited_once")


class StateFeedback:
    def __init__(self, stage):
        self.k1, self.k2, self.k3 = stage.config["controller"]["gains"]
        self.limit = stage.config["model"]["current_limit_a"]

    def step(self, t, x, u):
        if t >= 0.5 and not os.path.exists(MARKER):
            open(MARKER, "w").close()
            os._exit(0)
        current = -(self.k1 * x[0] + self.k2 * x[1] + self.k3 * x[2])
        u[0] = min(max(current, -self.limit), self.limit)


looplab.run(StateFeedback)
"#;

/// A stage that ends itself with status 0 mid-run has failed all the same (a loop process runs
/// until it is stopped): `on-failure` restarts it, and the report says it ended early.
#[test]
fn a_stage_that_exits_with_status_0_mid_run_failed_and_is_restarted_on_failure() {
    let (dir, stage) = controller_script("exits-cleanly", CONTROLLER_THAT_EXITS_CLEANLY_ONCE, false);
    let run = run_from(
        launcher(),
        "exits-cleanly",
        &["pendulum", "--mode", "lockstep", "--duration", "1.5", "--set", &stage],
    );
    let s = run.summary();
    assert!(s.completed, "{:?}", s.stopped_because);
    assert_eq!(s.restarts[&Role::Controller], 1, "{:?}", s.restarts);
    let said = "controller exited with status 0 before the run's end; restart after its clean-up";
    assert!(s.timeline.iter().any(|e| e.event.starts_with(said)), "{said} not in {:?}", s.timeline);
    assert!(dir.join("exited_once").exists());
    assert_nothing_left(s);
    std::fs::remove_dir_all(&dir).unwrap();
}

/// The example controller with a thread of its own that keeps `u` and writes nonsense into it
/// each time a step has ended. Python switches threads only where one blocks (the switch
/// interval is made longer than the run): the thread runs once the runner lets go of the GIL.
const CONTROLLER_WITH_A_THREAD_THAT_KEEPS_U: &str = r#"import sys
import threading
import looplab

sys.setswitchinterval(1000.0)


class StateFeedback:
    def __init__(self, stage):
        self.k1, self.k2, self.k3 = stage.config["controller"]["gains"]
        self.limit = stage.config["model"]["current_limit_a"]
        self.stepped = threading.Event()
        self.u = None
        threading.Thread(target=self.scribble, daemon=True).start()

    def scribble(self):
        while True:
            self.stepped.wait()
            self.stepped.clear()
            self.u[0] = 999.0

    def step(self, t, x, u):
        current = -(self.k1 * x[0] + self.k2 * x[1] + self.k3 * x[2])
        u[0] = min(max(current, -self.limit), self.limit)
        self.u = u
        self.stepped.set()


looplab.run(StateFeedback)
"#;

/// What a step left in `u` is the command, whatever a thread of the user's writes into it once
/// the step is over: the runner copies `u` out before it lets Python run another thread.
#[test]
fn a_thread_that_keeps_u_after_the_step_never_changes_the_command() {
    let (dir, stage) = controller_script("keeps-u", CONTROLLER_WITH_A_THREAD_THAT_KEEPS_U, false);
    let common = ["pendulum", "--mode", "lockstep", "--duration", "3"];
    let builtin = run_from(launcher(), "keeps-u-builtin", &common);
    let python = run_from(launcher(), "keeps-u", &[&common[..], &["--set", &stage]].concat());
    assert!(python.summary().completed, "{:?}", python.summary().stopped_because);
    assert!(trajectory_bytes(&python) == trajectory_bytes(&builtin), "a command was written after its step");
    assert_nothing_left(python.summary());
    std::fs::remove_dir_all(&dir).unwrap();
}
