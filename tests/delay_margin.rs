//! A declared linear loop's delay margin: the theory from A, B, K and the rate (the report's
//! budget line), the lockstep sweep and the real-time sweep (a `delay` fault is a transport
//! delay in both modes) agree.

use crate::common::*;

/// `looplab sweep` of the controller's delay, the fault from `at`, over 7 to 11 ticks: its exit
/// code, sweep.json and what it printed.
fn sweep_delays(
    file: &std::path::Path,
    name: &str,
    at: &str,
    extra: &[&str],
) -> (Option<i32>, serde_json::Value, String) {
    let out = fresh_dir(name);
    let fault = format!("delay controller by 0 ticks at {at}");
    let args = [
        &["sweep", file.to_str().unwrap(), "--fault", &fault, "--param"][..],
        &["faults.0.delay_ticks", "--from", "7", "--to", "11", "--out", out.to_str().unwrap()],
        extra,
    ]
    .concat();
    let said = looplab().args(&args).output().unwrap();
    let text = format!("{}{}", String::from_utf8_lossy(&said.stdout), String::from_utf8_lossy(&said.stderr));
    let json: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(out.join("sweep.json")).unwrap())
        .unwrap_or_else(|e| panic!("{e}: {text}"));
    std::fs::remove_dir_all(&out).unwrap();
    (said.status.code(), json, text)
}

/// sweep.json's measured first unstable delay and the theory's, in ticks, of a sweep that exits 0.
fn sweep(file: &std::path::Path, name: &str, extra: &[&str]) -> (f64, u64) {
    let (code, json, text) = sweep_delays(file, name, "1s", &[&["--duration", "4"], extra].concat());
    assert_eq!(code, Some(0), "{text}");
    let measured = json["first_unstable"].as_f64().unwrap_or_else(|| panic!("{json}"));
    let theory = json["theory"]["ticks"].as_u64().unwrap_or_else(|| panic!("{json}"));
    (measured, theory)
}

#[test]
fn a_declared_linear_loop_has_a_delay_margin_that_lockstep_and_real_time_measure_alike() {
    // The motor of golden_ci.rs under the built-in state feedback, for 4 s.
    let dir = fresh_dir("motor-margin");
    let file = crate::golden_ci::motor_under_state_feedback(&dir);
    // The report's budget line has it.
    let run = run_in_process("motor-margin-run", &[file.to_str().unwrap(), "--duration", "4"]);
    assert!(run.stdout().contains("delay margin 90.000 (9 ticks, theory: "), "{}", run.stdout());

    let (lockstep, theory) = sweep(&file, "motor-lockstep", &[]);
    assert_eq!((lockstep, theory), (9.0, 9), "lockstep is exact: the sweep runs the model the theory linearises");
    let (realtime, _) = sweep(&file, "motor-realtime", &["--set", "mode=\"realtime\"", "--processes"]);
    assert!((realtime - lockstep).abs() <= 1.0, "real time {realtime} ticks, lockstep {lockstep}");
    std::fs::remove_dir_all(&dir).unwrap();
}

/// The reference steps at 0.5 s, inside the window of a delay from 0.3 s: judged against the run
/// without the delay, the step's own tracking error is not the fault's, and the sweep still finds
/// the margin at 9 ticks (judged against zero error, the step made 7 and 8 ticks "unstable").
/// Stable delays that overshoot the limits read "exceeded"; `--fail-on limits` fails the sweep.
#[test]
fn a_reference_step_inside_the_fault_window_does_not_move_the_measured_margin() {
    let dir = fresh_dir("motor-step-margin");
    let file = crate::golden_ci::motor_under_state_feedback(&dir);
    let (code, json, text) =
        sweep_delays(&file, "motor-step-sweep", "0.3s", &["--duration", "3", "--fail-on", "limits"]);
    assert_eq!(code, Some(3), "a control gate failed: {text}");
    assert_eq!(json["judged_against"], "the fault-free baseline", "{json}");
    assert_eq!(json["first_unstable"], 9.0, "{text}");
    let verdicts: Vec<&str> =
        json["points"].as_array().unwrap().iter().map(|p| p["verdict"].as_str().unwrap()).collect();
    assert_eq!(verdicts, ["exceeded", "exceeded", "unstable", "unstable", "unstable"], "{text}");
    assert!(text.contains("faults.0.delay_ticks = 9: control gate failed: limits (LOST at t = "), "{text}");
    assert!(text.contains("measured and theory agree within one tick (+0 ticks)"), "{text}");
    std::fs::remove_dir_all(&dir).unwrap();
}
