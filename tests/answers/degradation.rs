//! A stage that dies and stays dead (`restart = "never"`, `on_death = "continue"`): the run goes
//! on to its planned end under the plant's fail-safe, says the stage was lost, and splits each
//! fault's statistics before, during and after it.

use crate::common;

use common::*;
use looplab_shared::contract::report::FaultPhases;

const LOST: [&str; 4] =
    ["--set", "supervision.controller.restart=never", "--set", "supervision.controller.on_death=continue"];

fn run_losing_controller(name: &str, args: &[&str]) -> (std::process::Output, std::path::PathBuf, Summary) {
    let dir = fresh_dir(name);
    let output = looplab()
        .args(["run", "pendulum", "--duration", "2", "--fault", "kill controller at 0.5s"])
        .args(LOST)
        .args(args)
        .arg("--out")
        .arg(&dir)
        .arg("-q")
        .output()
        .unwrap();
    let summary = load_summary(&dir);
    (output, dir, summary)
}

fn phases(s: &Summary) -> &FaultPhases {
    s.faults[0].effect.as_ref().unwrap().phases.as_ref().unwrap()
}

#[test]
fn a_lockstep_run_without_its_controller_runs_every_loop_and_its_phases_add_up() {
    let (output, dir, s) = run_losing_controller("lockstep", &["--mode", "lockstep"]);
    assert_eq!(output.status.code(), Some(1), "a lost stage is not a success");
    let stderr = String::from_utf8_lossy(&output.stderr);
    assert!(stderr.contains("with a stage LOST: controller died at loop 500"), "{stderr}");
    assert_eq!((s.loops, s.loops_planned), (2000, 2000));
    assert!(!s.completed && s.stopped_because.is_none());
    assert_eq!(s.lost_stages.len(), 1);
    assert_eq!(s.stale_ticks, 1500, "the plant applied on_stale from the loss on");
    // The fail-safe held the last command: the report and summary.json say what it was.
    let applied = Table::read(&dir.join("trajectory.csv")).col("applied.current_A");
    let held = s.fail_safe.as_ref().expect("what the fail-safe held");
    assert_eq!(held.on_stale, "hold");
    assert_eq!(held.applied, [("current".to_string(), applied[1999], "A".to_string())]);
    assert_eq!(applied[1999], applied[500], "held since the loss");
    let said = format!(
        "the plant's fail-safe held its last command (supervision.on_stale = \"hold\"): current = {} A",
        applied[1999]
    );
    assert!(stderr.contains(&said), "{stderr}");
    let effect = s.faults[0].effect.as_ref().unwrap();
    assert!(effect.never_back && effect.recovery_s.is_none(), "{effect:?}");
    let p = phases(&s);
    assert_eq!([p.before.to_k, p.during.from_k, p.during.to_k, p.after.from_k], [500, 500, 2000, 2000]);
    // Lockstep: every loop recorded; each phase's loops and misses add up to the run's.
    assert_eq!(p.before.loops + p.during.loops + p.after.loops, s.loops);
    assert_eq!(p.before.misses + p.during.misses + p.after.misses, s.loops_without_command);
    assert_eq!(p.during.without_command, 1500);
    assert_eq!(p.before.end_to_end_ns.count + p.during.end_to_end_ns.count, s.latency_ns.end_to_end.count);
    // The metrics follow the pendulum after the loss too: its largest angle is the verdict's.
    assert_eq!(Some(s.metrics["theta_max_abs_rad"]), s.limits.worst_error, "{:?}", s.metrics);
    assert!(s.metrics["theta_max_abs_rad"] > 1.0, "it fell without its controller: {:?}", s.metrics);
    let report = String::from_utf8_lossy(&output.stdout);
    assert!(report.contains("never: controller lost") && !report.contains(" kept"), "{report}");
    assert!(report.contains("during = from the injection"), "{report}");
    assert_nothing_left(&s);
    std::fs::remove_dir_all(dir).unwrap();
}

#[test]
fn a_real_time_run_without_its_controller_runs_to_its_end_and_draws_the_fault() {
    let (output, dir, s) = run_losing_controller("realtime", &[]);
    assert_eq!(output.status.code(), Some(1));
    assert_eq!(s.loops, s.loops_planned, "ran to its planned loop count");
    assert!(s.stale_ticks > 0, "the plant's fail-safe applied");
    let effect = s.faults[0].effect.as_ref().unwrap();
    assert!(effect.never_back && effect.recovery_s.is_none(), "{effect:?}");
    let p = phases(&s);
    // The spans cover the run; the loops recorded in them are the monitor's, each miss a loop
    // recorded without a command in time, none after a loss that never ended.
    assert_eq!((p.before.from_k, p.during.to_k, p.after.to_k), (0, s.loops, s.loops));
    assert_eq!(p.after.loops, 0);
    assert!(p.during.without_command > 0 && p.during.without_command <= p.during.misses);
    assert_eq!(p.during.end_to_end_ns.count + p.during.without_command, p.during.loops, "a latency per command");
    let plot = looplab().arg("plot").arg(&dir).output().unwrap();
    assert!(plot.status.success(), "{}", String::from_utf8_lossy(&plot.stderr));
    assert!(dir.join("fault-1-kill-controller.png").is_file());
    assert_nothing_left(&s);
    std::fs::remove_dir_all(dir).unwrap();
}

#[test]
fn on_death_continue_is_refused_for_the_plant() {
    let output = looplab()
        .args(["run", "pendulum", "--duration", "1", "-q", "--set", "supervision.plant.on_death=continue"])
        .output()
        .unwrap();
    assert_eq!(output.status.code(), Some(2));
    let stderr = String::from_utf8_lossy(&output.stderr);
    assert!(stderr.contains("supervision.plant.on_death") && stderr.contains("must be \"end\""), "{stderr}");
}
