//! A declared linear loop's delay margin: the theory from A, B, K and the rate (the report's
//! budget line), the lockstep sweep and the real-time sweep (a `delay` fault is a transport
//! delay in both modes) agree.

use crate::common::*;

/// sweep.json's measured first unstable delay and the theory's, in ticks.
fn sweep(file: &std::path::Path, name: &str, extra: &[&str]) -> (f64, u64) {
    let out = fresh_dir(name);
    let args = [
        &["sweep", file.to_str().unwrap(), "--fault", "delay controller by 0 ticks at 1s", "--param"][..],
        &["faults.0.delay_ticks", "--from", "7", "--to", "11", "--duration", "4", "--out", out.to_str().unwrap()],
        extra,
    ]
    .concat();
    let said = looplab().args(&args).output().unwrap();
    assert_eq!(said.status.code(), Some(0), "{}", String::from_utf8_lossy(&said.stderr));
    let json: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("sweep.json")).unwrap()).unwrap();
    let measured = json["first_unstable"].as_f64().unwrap_or_else(|| panic!("{json}"));
    let theory = json["theory"]["ticks"].as_u64().unwrap_or_else(|| panic!("{json}"));
    std::fs::remove_dir_all(&out).unwrap();
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
