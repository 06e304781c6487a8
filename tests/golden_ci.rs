//! A controller's regression test in CI, as a user sets it up: a golden run of a DC motor (a
//! declared plant) under a PD controller of the user's own in Python, recorded in a folder of
//! their repository; the repository moved (a CI checkout); the controller replayed on the golden
//! recording and diffed; and each gate's exit code: 0 the same, 3 control, 4 timing, 2 bad input.

use std::path::{Path, PathBuf};
use std::process::Output;

use crate::common::*;

/// θ̇ = ω, ω̇ = −ω/τ + (K/τ)·V with τ = 0.1 s, K = 10 rad/s/V; the reference steps to 1 rad at
/// 0.5 s, and the limits judge the angle from 1 s on, once the step has settled.
const MOTOR: &str = r#"
mode = "lockstep"
rate_hz = 100.0
duration_s = 2.0

[system]
state = [{ name = "angle", unit = "rad" }, { name = "speed", unit = "rad/s" }]
input = [{ name = "voltage", unit = "V", min = -12.0, max = 12.0 }]

[plant.linear]
a = [[0.0, 1.0], [0.0, -10.0]]
b = [[0.0], [100.0]]

[sensors.encoder]
reads = ["state.angle", "state.speed"]
period_s = 0.01

[reference]
track = "state.angle"
table = [[0.0, 0.0], [0.5, 1.0]]
between = "hold"

[limits]
of = ["state.angle"]
error_limit = 0.05
recovery_band = 0.02
judge_from_s = 1.0
"#;

/// The user's controller and its launch file: V = kp (r − θ) − kd ω, its gains and an optional
/// pause per step from `[parameters]`, r from `stage.reference(t)`.
const PD: &str = r#"import time
import looplab


class PD:
    def __init__(self, stage):
        p = stage.config["parameters"]
        self.kp, self.kd, self.pause = p["kp"], p["kd"], p["step_pause_s"]
        self.stage = stage

    def step(self, t, x, u):
        if self.pause:
            time.sleep(self.pause)
        u[0] = self.kp * (self.stage.reference(t)[0] - x[0]) - self.kd * x[1]


looplab.run(PD)
"#;

const PD_STAGE: &str = r#"
[stages.controller]
command = ["python3", "pd.py"]
dir = "controllers"

[parameters]
kp = 2.0
kd = 0.1
step_pause_s = 0.0

[gate]
fail_on = ["limits"]
"#;

/// The motor under the built-in state feedback V = −(2 (θ − r) + 0.1 ω), as `dir/motor.toml`.
pub fn motor_under_state_feedback(dir: &Path) -> PathBuf {
    std::fs::create_dir_all(dir).unwrap();
    let file = dir.join("motor.toml");
    std::fs::write(&file, format!("{MOTOR}\n[controller]\ngains = [[2.0, 0.1]]\n")).unwrap();
    file
}

/// The motor of [`motor_under_state_feedback`] run in this process into `dir/run`: its folder.
pub fn motor_run_in_process(dir: &Path) -> PathBuf {
    let file = motor_under_state_feedback(dir);
    let out = dir.join("run");
    let ran = looplab().arg("run").arg(&file).args(["--in-process", "-q", "--out"]).arg(&out).output().unwrap();
    assert!(ran.status.success(), "{}", String::from_utf8_lossy(&ran.stderr));
    out
}

/// `looplab <args>` in `dir` with the Python module importable.
fn looplab_in(dir: &Path, args: &[&str]) -> Output {
    python_launcher().current_dir(dir).args(args).output().expect("start looplab")
}

fn said(output: &Output) -> String {
    format!("{}\n{}", String::from_utf8_lossy(&output.stdout), String::from_utf8_lossy(&output.stderr))
}

/// A repository with the launch file and the controller, at `root/repo`.
fn repository(root: &Path) -> PathBuf {
    let repo = root.join("repo");
    std::fs::create_dir_all(repo.join("controllers")).unwrap();
    std::fs::write(repo.join("motor.toml"), format!("{MOTOR}{PD_STAGE}")).unwrap();
    std::fs::write(repo.join("controllers/pd.py"), PD).unwrap();
    repo
}

#[test]
fn a_moved_golden_run_replays_and_diffs_clean_and_each_gate_fails_with_its_own_exit_code() {
    let root = fresh_dir("golden-ci");
    let repo = repository(&root);
    let recorded = looplab_in(&repo, &["run", "motor.toml", "--out", "golden/run", "-q"]);
    assert_eq!(recorded.status.code(), Some(0), "{}", said(&recorded));
    let golden = load_summary(&repo.join("golden/run"));
    assert!(golden.limits.line().starts_with("within limits from t = 1 s: "), "{}", golden.limits.line());
    // The step response of the motor at rest, from 0 to 1 rad: its overshoot is the angle's
    // largest value past 1, its steady-state error 1 less the final angle.
    let m = &golden.metrics;
    assert!((m["step.state.angle.overshoot_pct"] - 100.0 * (m["state.angle.max_abs"] - 1.0)).abs() < 1e-9, "{m:?}");
    assert_eq!(m["step.state.angle.steady_state_error"], 1.0 - m["state.angle.final"], "{m:?}");
    assert!(m["step.state.angle.rise_time_s"] > 0.0 && m["step.state.angle.settling_time_s"] < 1.0, "{m:?}");
    // The run folder names the controller's folder from itself: it moves with the repository.
    let launch = std::fs::read_to_string(repo.join("golden/run/launch.toml")).unwrap();
    assert!(launch.contains("dir = \"../../controllers\""), "{launch}");

    // CI's checkout is elsewhere; the original is gone.
    let checkout = root.join("checkout");
    std::fs::rename(&repo, &checkout).unwrap();
    let replay = |name: &str, extra: &[&str]| {
        let out = root.join(name);
        let args = [&["replay", "golden/run", "--stage", "controller", "--out", out.to_str().unwrap()], extra].concat();
        (looplab_in(&checkout, &args), out)
    };
    let diff = |out: &Path| looplab_in(&checkout, &["diff", "golden/run", out.to_str().unwrap(), "--no-figure"]);

    let (same, out) = replay("same", &[]);
    assert_eq!(same.status.code(), Some(0), "{}", said(&same));
    assert!(
        said(&same).contains("outputs: identical to the recording's, bit for bit, in all 200 loops"),
        "{}",
        said(&same)
    );
    let diffed = diff(&out);
    assert_eq!(diffed.status.code(), Some(0), "{}", said(&diffed));
    assert!(said(&diffed).contains("identical in every loop"), "{}", said(&diffed));

    // A changed gain: the commands differ, a control failure.
    let (gain, out) = replay("gain", &["--set", "parameters.kp=3.0"]);
    assert_eq!(gain.status.code(), Some(0), "{}", said(&gain));
    let diffed = diff(&out);
    assert_eq!(diffed.status.code(), Some(3), "{}", said(&diffed));
    assert!(
        said(&diffed).contains("\n1 field over tolerance; first: cmd.voltage_V at loop 50 (t = 0.5 s)"),
        "{}",
        said(&diffed)
    );

    // A controller that takes 30 ms a step: its median end-to-end latency is at least that.
    let (slow, _) = replay("slow", &["--set", "parameters.step_pause_s=0.03", "--fail-on", "e2e.p50 > 20ms"]);
    assert_eq!(slow.status.code(), Some(4), "{}", said(&slow));
    let line = String::from_utf8_lossy(&slow.stderr).lines().find(|l| l.contains("gate")).map(str::to_owned);
    assert!(
        line.as_deref().is_some_and(|l| l.starts_with("timing gate failed: e2e.p50 > 20ms (measured ")),
        "{}",
        said(&slow)
    );

    // The golden folder alone, without the repository around it: where it looked, and how to say
    // where the controller is.
    let alone = root.join("alone");
    std::fs::rename(checkout.join("golden/run"), &alone).unwrap();
    let lost = looplab_in(&root, &["replay", "alone", "--stage", "controller", "--out", "lost"]);
    assert_eq!(lost.status.code(), Some(2), "{}", said(&lost));
    let expected = format!(
        "error: {}/launch.toml: key `stages.controller.command`: script pd.py is not found in {} (a moved recording: \
         give its folder with --set stages.ROLE.dir=FOLDER",
        alone.canonicalize().unwrap().display(),
        root.canonicalize().unwrap().parent().unwrap().join("controllers").display()
    );
    assert!(said(&lost).contains(&expected), "{}\nexpected: {expected}", said(&lost));
    assert!(!root.join("lost").exists(), "a refused replay writes no run folder");
    let found = looplab_in(
        &root,
        &[
            "replay",
            "alone",
            "--stage",
            "controller",
            "--set",
            "stages.controller.dir=checkout/controllers",
            "--out",
            "found",
        ],
    );
    assert_eq!(found.status.code(), Some(0), "{}", said(&found));
    let diffed = looplab_in(&root, &["diff", "alone", "found", "--no-figure"]);
    assert_eq!(diffed.status.code(), Some(0), "{}", said(&diffed));
    std::fs::remove_dir_all(&root).unwrap();
}

/// The built-in controller of a declared system follows the reference, u = −K (x̂ − r): the
/// type-1 motor settles on the step exactly. Judged over the whole run the step itself exceeds
/// the limit; judged from 1 s on, after it has settled, the run is within it.
#[test]
fn a_step_reference_is_followed_and_judged_after_it_settles() {
    let root = fresh_dir("step-settles");
    let file = motor_under_state_feedback(&root);
    let settled = run_in_process("step-settled", &[file.to_str().unwrap(), "--fail-on", "limits"]);
    assert!(settled.metric("state.angle.final") > 0.9999 && settled.metric("state.angle.final") < 1.0001);
    assert!(settled.metric("tracking.state.angle.final").abs() < 1e-4);
    let limits = &settled.summary().limits;
    assert_eq!((limits.judged_from_s, limits.loops_judged), (1.0, 100));
    assert!(limits.line().starts_with("within limits from t = 1 s: |angle − reference| rad stayed within 0.05"));

    let whole = looplab()
        .args([
            "run",
            file.to_str().unwrap(),
            "--in-process",
            "-q",
            "--set",
            "limits.judge_from_s=0",
            "--fail-on",
            "limits",
        ])
        .arg("--out")
        .arg(root.join("whole"))
        .output()
        .unwrap();
    assert_eq!(whole.status.code(), Some(3), "{}", said(&whole));
    let stderr = String::from_utf8_lossy(&whole.stderr);
    assert!(
        stderr.contains("control gate failed: limits (limits exceeded at t = 0.5 s (limits.error_limit = 0.05); worst 1 at t = 0.5 s; back within it by the end)"),
        "{stderr}"
    );
    std::fs::remove_dir_all(&root).unwrap();
}

/// A controller killed before the reference steps, restarted in lockstep, changes nothing the
/// motor does: against the same run without the fault it had no effect, where the error
/// against zero would count the step's own transient as the kill's recovery.
#[test]
fn a_kill_with_no_effect_on_the_plant_reports_no_degradation() {
    let root = fresh_dir("kill-no-effect");
    let file = motor_under_state_feedback(&root);
    let killed = run("kill-no-effect-run", &[file.to_str().unwrap(), "--fault", "kill controller at 0.4s"]);
    let fault = &killed.summary().faults[0];
    assert!(fault.restarted_after_ms.is_some(), "{fault:?}");
    let twin = fault.against_twin.as_ref().expect("a lockstep run's fault is judged against its twin");
    assert_eq!((twin.departed_at_s, twin.worst_extra_error, twin.recovery_s), (None, 0.0, Some(0.0)));
    // Against zero error, the step at 0.5 s reads as a recovery of the kill's.
    assert!(fault.effect.as_ref().unwrap().recovery_s.unwrap() > 0.2, "{fault:?}");
    assert!(
        killed.stdout().contains(
            "against the same run without faults: `kill controller at 400ms`: no effect: the plant's state is that run's, bit for bit"
        ),
        "{}",
        killed.stdout()
    );
    let row = killed.stdout().lines().find(|l| l.starts_with("  kill controller at 400ms ")).map(str::to_owned);
    assert!(row.as_deref().is_some_and(|r| r.ends_with("0.000 s  no effect")), "{row:?}");
    // The twin's files are not left in the run folder.
    assert!(!killed.dir.join("twin").exists());
    std::fs::remove_dir_all(&root).unwrap();
}

/// `with_reference = true`: the controller's input carries the reference after the estimate
/// (`reference.state.angle`), and a controller that reads it there runs the very loop of one
/// that asks `stage.reference(t)`, byte for byte.
#[test]
fn a_controller_given_the_reference_in_its_input_runs_the_loop_of_one_that_asks_for_it() {
    let root = fresh_dir("with-reference");
    let repo = repository(&root);
    let from_input = r#"import looplab


class PD:
    def __init__(self, stage):
        assert stage.input_names == ["angle", "speed", "reference.state.angle"], stage.input_names
        p = stage.config["parameters"]
        self.kp, self.kd = p["kp"], p["kd"]

    def step(self, t, x, u):
        u[0] = self.kp * (x[2] - x[0]) - self.kd * x[1]


looplab.run(PD)
"#;
    std::fs::write(repo.join("controllers/pd_input.py"), from_input).unwrap();
    let stage = |name: &str, extra: &[&str]| {
        let out = root.join(name);
        let args = [&["run", "motor.toml", "-q", "--out", out.to_str().unwrap()], extra].concat();
        let ran = looplab_in(&repo, &args);
        assert_eq!(ran.status.code(), Some(0), "{}", said(&ran));
        std::fs::read(out.join("trajectory.csv")).unwrap()
    };
    let asked = stage("asked", &[]);
    let given = stage(
        "given",
        &[
            "--set",
            "stages.controller.command=[\"python3\", \"pd_input.py\"]",
            "--set",
            "stages.controller.with_reference=true",
        ],
    );
    assert!(asked == given, "the two controllers' runs differ");
    // Without a [reference] there is nothing to append: one line, exit 2.
    let none = looplab_in(
        &repo,
        &[
            "run",
            "motor.toml",
            "--set",
            "stages.controller.with_reference=true",
            "--set",
            "reference={}",
            "--set",
            "limits.of=[\"state.angle\"]",
        ],
    );
    assert_eq!(none.status.code(), Some(2), "{}", said(&none));
    assert!(
        said(&none).contains("key `stages.controller.with_reference`: appends a declared system's [reference] to the controller's input; this launch file has none"),
        "{}",
        said(&none)
    );
    std::fs::remove_dir_all(&root).unwrap();
}
