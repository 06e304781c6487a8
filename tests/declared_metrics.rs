//! A declared system's generic metrics, tracking error and `[limits]` verdict, end to end: the
//! numbers summary.json reports, recomputed here from the run's own trajectory.csv.

use crate::common;

use std::path::PathBuf;

use common::*;

/// A launch file in a folder of its own, removed when dropped.
struct LaunchFile(PathBuf);

impl LaunchFile {
    fn path(&self) -> &str {
        self.0.to_str().unwrap()
    }
}

impl Drop for LaunchFile {
    fn drop(&mut self) {
        let _ = std::fs::remove_dir_all(self.0.parent().unwrap());
    }
}

/// launch/declared.toml (the mass on a spring, held at rest) with its `[reference]` and
/// `[limits]` replaced by `tail`, written into a fresh folder.
fn declared_file(name: &str, tail: &str) -> LaunchFile {
    let text = include_str!("../launch/declared.toml");
    let head = &text[..text.find("\n[reference]").expect("launch/declared.toml has [reference]")];
    assert!(!head.contains("[limits]"), "[limits] follows [reference] in launch/declared.toml");
    let dir = fresh_dir(name);
    std::fs::create_dir_all(&dir).unwrap();
    let file = dir.join("declared.toml");
    std::fs::write(&file, format!("{head}\n{tail}")).unwrap();
    LaunchFile(file)
}

fn rms(v: &[f64]) -> f64 {
    (v.iter().map(|x| x * x).sum::<f64>() / v.len() as f64).sqrt()
}

fn max_abs(v: &[f64]) -> f64 {
    v.iter().fold(0.0, |m, x| m.max(x.abs()))
}

fn close(a: f64, b: f64) -> bool {
    (a - b).abs() <= 1e-12 * b.abs().max(1e-3)
}

/// Five processes, lockstep: per component final, max |x| and RMS, the tracking error of a
/// sine reference and the verdict's worst error are what the trajectory says.
#[test]
fn the_metrics_and_verdict_are_the_trajectorys() {
    let tail = "[reference]\ntrack = \"state.position\"\nexpression = \"0.05*sin(2*PI*t)\"\n\n\
                [limits]\nerror_limit = 0.5\nrecovery_band = 0.01\n";
    let file = declared_file("declared-metrics", tail);
    let run = run("declared-metrics", &[file.path(), "--mode", "lockstep", "--duration", "3"]);
    assert_nothing_left(run.summary());
    let trajectory = run.trajectory();
    let (t, position) = (trajectory.col("t_s"), trajectory.col("position_m"));
    for (metric, column) in [
        ("state.position", "position_m"),
        ("state.velocity", "velocity_m_per_s"),
        ("output.spring_force", "spring_force_N"),
        ("input.force", "applied.force_N"),
    ] {
        let v = trajectory.col(column);
        assert_eq!(v.len(), 300, "{column}");
        assert_eq!(run.metric(&format!("{metric}.final")), v[v.len() - 1], "{metric}");
        assert_eq!(run.metric(&format!("{metric}.max_abs")), max_abs(&v), "{metric}");
        assert!(close(run.metric(&format!("{metric}.rms")), rms(&v)), "{metric}");
    }
    let error: Vec<f64> =
        t.iter().zip(&position).map(|(t, p)| p - 0.05 * (2.0 * std::f64::consts::PI * t).sin()).collect();
    assert!(close(run.metric("tracking.state.position.rms"), rms(&error)));
    assert!(close(run.metric("tracking.state.position.max_abs"), max_abs(&error)));
    assert!(close(run.metric("tracking.state.position.final"), error[error.len() - 1]));
    let limits = &run.summary["limits"];
    assert_eq!(limits["verdict"], "within_limits", "{limits}");
    assert_eq!(limits["measure"], "|position − reference| m");
    assert_eq!(limits["limit_key"], "limits.error_limit");
    assert!(close(limits["worst_error"].as_f64().unwrap(), max_abs(&error)), "{limits}");
    assert_eq!(run.summary["error_measure"]["recovery_band"], 0.01);
}

/// launch/declared.toml as it is, in one process and through five: the very same metrics, bit
/// for bit; its position starts at 0.1 m within its 0.2 m limit.
#[test]
fn in_process_metrics_equal_the_five_process_ones() {
    let args = ["launch/declared.toml", "--mode", "lockstep", "--duration", "2"];
    let five = run("declared-metrics-five", &args);
    let one = run_in_process("declared-metrics-one", &args);
    assert_eq!(five.summary["metrics"], one.summary["metrics"]);
    assert!(five.summary["metrics"].as_object().unwrap().contains_key("tracking.state.position.rms"));
    assert_eq!(five.summary["limits"]["verdict"], "within_limits", "{}", five.summary["limits"]);
    assert_eq!(five.summary["limits"]["worst_error"], 0.1);
}

/// Beyond the limit at the start (0.1 m against 0.05 m), back within it by the end.
#[test]
fn a_limit_passed_and_come_back_from_is_limits_exceeded() {
    let tail = "[limits]\nof = [\"state.position\"]\nerror_limit = 0.05\nrecovery_band = 0.01\n";
    let file = declared_file("declared-exceeded", tail);
    let run = run("declared-exceeded", &[file.path(), "--mode", "lockstep", "--duration", "5"]);
    let limits = &run.summary["limits"];
    assert_eq!(limits["verdict"], "limits_exceeded", "{limits}");
    assert_eq!(limits["exceeded_at_s"], 0.0, "{limits}");
    assert_eq!(limits["measure"], "|position| m");
}

/// A bad [limits] or [reference]: one line naming the file and the key, exit 2, nothing run.
#[test]
fn bad_limits_and_references_are_one_line_and_exit_2() {
    for (tail, key) in [
        ("[limits]\nof = [\"state.position\"]\nerror_limit = 0.1\nrecovery_band = 0.5\n", "limits.recovery_band"),
        ("[limits]\nerror_limit = 0.1\nrecovery_band = 0.05\n", "limits.of"),
        ("[reference]\ntrack = \"state.mass\"\nexpression = \"t\"\n", "reference.track"),
        ("[reference]\ntrack = \"state.position\"\nexpression = \"sin(w*t)\"\n", "reference.expression"),
    ] {
        let file = declared_file("declared-bad", tail);
        let out = looplab().args(["run", file.path(), "--mode", "lockstep", "-q"]).output().unwrap();
        let stderr = String::from_utf8_lossy(&out.stderr);
        assert_eq!(out.status.code(), Some(2), "{tail}: {stderr}");
        let lines: Vec<&str> = stderr.lines().collect();
        assert_eq!(lines.len(), 1, "{tail}: {stderr}");
        assert!(lines[0].contains("declared.toml") && lines[0].contains(&format!("key `{key}`")), "{stderr}");
    }
}

/// `looplab bench --plants FILE`: the step cost, the five-process tick and both loop rates of
/// the declared linear plant, positive numbers in plants.json.
#[test]
fn bench_plants_measures_a_declared_plant() {
    let out = fresh_dir("bench-plants");
    let status =
        looplab().args(["bench", "--plants", "launch/declared.toml", "--quick", "--out"]).arg(&out).output().unwrap();
    assert!(status.status.success(), "{}", String::from_utf8_lossy(&status.stderr));
    let text = std::fs::read_to_string(out.join("plants.json")).unwrap();
    let rows: serde_json::Value = serde_json::from_str(&text).unwrap();
    let row = &rows[0];
    for key in ["step_ns_per_tick", "five_process_plant_tick_ns", "five_process_loops_per_s", "in_process_loops_per_s"]
    {
        assert!(row[key].as_f64().is_some_and(|v| v > 0.0 && v.is_finite()), "{key}: {row}");
    }
    assert!(String::from_utf8_lossy(&status.stdout).contains("launch/declared.toml"));
    let _ = std::fs::remove_dir_all(&out);
}
