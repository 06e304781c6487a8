//! The latency budget: the report's `budget (ms):` line says what summary.json's
//! `latency_budget` says, and a delay sweep bisects to the margin and gives it in ms.

use crate::common;

use common::*;

/// The number after `label` in `line`.
fn number_after(line: &str, label: &str) -> f64 {
    let rest = &line[line.find(label).unwrap_or_else(|| panic!("no {label:?} in {line}")) + label.len()..];
    let text: String = rest.chars().take_while(|c| c.is_ascii_digit() || *c == '.' || *c == '-').collect();
    text.parse().unwrap_or_else(|_| panic!("no number after {label:?} in {line}"))
}

#[test]
fn the_budget_line_says_what_the_summary_says() {
    let run = run("budget", &["pendulum", "--mode", "realtime", "--duration", "1"]);
    let stdout = run.stdout();
    let line = stdout.lines().find(|l| l.starts_with("  budget (ms): ")).expect(&stdout);
    let b = &run.summary["latency_budget"];
    let json = |key: &str| b[key].as_f64().unwrap_or_else(|| panic!("no {key} in {b}"));
    for (label, key) in [
        ("p99 ", "p99_ms"),
        ("p99.9 ", "p999_ms"),
        ("max ", "max_ms"),
        ("deadline ", "deadline_ms"),
        ("delay margin ", "delay_margin_ms"),
        ("headroom at p99.9: ", "headroom_to_deadline_ms"),
        (", ", "headroom_to_margin_ms"),
    ] {
        // The last headroom follows the last ", " of the line.
        let at = if label == ", " { &line[line.rfind(", ").unwrap()..] } else { line };
        assert_eq!(number_after(at, label), json(key), "{label:?} in {line}");
    }
    assert_eq!(json("deadline_ms"), 1.0, "one period at 1 kHz");
    assert_eq!(b["delay_margin_ticks"], 31, "the stock law's theory: {b}");
    assert!(json("p99_ms") > 0.0 && json("p99_ms") <= json("p999_ms") && json("p999_ms") <= json("max_ms"), "{b}");
}

#[test]
fn a_delay_sweep_bisects_to_the_margin_and_gives_it_in_ms() {
    let dir = fresh_dir("bisect");
    let output = looplab()
        .args(["sweep", "pendulum", "--duration", "30", "--param", "faults.0.delay_ticks"])
        .args(["--from", "25", "--to", "35", "--step", "5"])
        .args(["--set", "sensors.encoder.quantum=0", "--set", "sensors.wheel_speed.noise_std=0"])
        .args(["--fault", "delay controller by 0 ticks at 2s", "--out"])
        .arg(&dir)
        .output()
        .unwrap();
    let stdout = String::from_utf8_lossy(&output.stdout);
    assert!(output.status.success(), "{stdout}\n{}", String::from_utf8_lossy(&output.stderr));
    let report: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.join("sweep.json")).unwrap()).unwrap();
    let values: Vec<f64> = report["points"].as_array().unwrap().iter().map(|p| p["value"].as_f64().unwrap()).collect();
    // 25, 30, 35 swept; 32 and 31 bisected; 30 stable and 31 unstable are neighbours.
    assert_eq!(values, [25.0, 30.0, 31.0, 32.0, 35.0], "{stdout}");
    assert_eq!(report["first_unstable"], 31.0);
    assert_eq!(
        (report["first_unstable_ticks"].as_f64(), report["first_unstable_ms"].as_f64()),
        (Some(31.0), Some(31.0))
    );
    assert_eq!(report["theory_ms"].as_f64(), Some(31.0));
    assert!(stdout.contains("unstable at faults.0.delay_ticks = 31 (31 ticks = 31.000 ms)"), "{stdout}");
    assert!(stdout.contains("goes unstable at 31 ticks = 31.000 ms"), "{stdout}");
    assert!(stdout.contains("agree within one tick"), "{stdout}");
    std::fs::remove_dir_all(&dir).unwrap();
}
