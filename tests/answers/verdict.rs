//! The control outcome: every run judged against its scenario's `[limits]`, in the report,
//! summary.json's `limits`, and `--fail-on-limits`, the same as `--fail-on limits` (five processes, lockstep).

use crate::common;

use common::*;
use looplab_shared::launcher::verdict::Verdict;

/// Runs `looplab run pendulum <args> --fail-on-limits` in lockstep; the output and the summary.
fn run_failing_on_limits(name: &str, args: &[&str]) -> (std::process::Output, Summary, std::path::PathBuf) {
    let dir = fresh_dir(name);
    let output = looplab()
        .args(["run", "pendulum", "--mode", "lockstep", "--fail-on-limits", "-q", "--out"])
        .arg(&dir)
        .args(args)
        .output()
        .expect("start looplab");
    let summary = load_summary(&dir);
    (output, summary, dir)
}

/// Upright at θ₀ = 0 with the drive held to its continuous ±5 A
/// (launch/pendulum/1-continuous-5a.toml), the bias δ = 0.1 makes the observer command the full
/// current the wrong way: the pendulum falls, swings over (|θ| up to 5.2 rad), and the run
/// completes.
#[test]
fn a_fallen_pendulum_is_lost_and_fails_the_run_with_fail_on_limits() {
    let (output, s, dir) = run_failing_on_limits(
        "fallen",
        &["--duration", "2", "--set", "plant.initial.theta=0", "--set", "model.current_limit_a=5.0"],
    );
    let stdout = String::from_utf8_lossy(&output.stdout);
    let stderr = String::from_utf8_lossy(&output.stderr);
    assert_eq!(output.status.code(), Some(3), "a control gate failed: {stdout}\n{stderr}");
    assert!(s.completed, "the loop itself ran to the end");
    assert_nothing_left(&s);
    let limits = &s.limits;
    assert_eq!(limits.verdict, Verdict::Lost, "{limits:?}");
    assert_eq!(limits.limit_key, "limits.fall_angle_rad");
    let (exceeded, lost) = (limits.exceeded_at_s.unwrap(), limits.lost_at_s.unwrap());
    assert!(0.0 < exceeded && exceeded < lost && lost < 2.0, "{limits:?}");
    assert!(limits.worst_error.unwrap() > std::f64::consts::FRAC_PI_2, "{limits:?}");
    assert_eq!(limits.loops_judged, 2000);
    // The report says it near the top, and the error line why the run failed.
    let control = stdout.lines().position(|l| l.starts_with("  control: LOST at t = ")).expect(&stdout);
    assert!(control < 4, "{stdout}");
    assert!(stderr.contains("control gate failed: limits (LOST at t = "), "{stderr}");
    // summary.json's key, as JSON spells it.
    assert_eq!(read_summary(&dir)["limits"]["verdict"], "lost");
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn a_healthy_pendulum_is_within_limits_and_passes_with_fail_on_limits() {
    let (output, s, dir) = run_failing_on_limits("healthy", &["--duration", "2"]);
    let stdout = String::from_utf8_lossy(&output.stdout);
    assert_eq!(output.status.code(), Some(0), "{stdout}\n{}", String::from_utf8_lossy(&output.stderr));
    assert_nothing_left(&s);
    assert_eq!(s.limits.verdict, Verdict::WithinLimits, "{:?}", s.limits);
    assert_eq!((s.limits.exceeded_at_s, s.limits.lost_at_s), (None, None));
    assert!(s.limits.worst_error.unwrap() < s.limits.limit);
    assert!(stdout.contains("  control: within limits: |theta| rad stayed within 0.3"), "{stdout}");
    std::fs::remove_dir_all(&dir).unwrap();
}
