//! `looplab diff`: real lockstep runs of the pendulum (in this process, the same trajectory as
//! five processes) compared. Two runs of the same settings are identical (exit 0); a changed
//! observer gain moves the estimate from the first loop on and the rest of the loop after it
//! (exit 1, the fields and the first loop named), within a loose enough tolerance (exit 0); runs
//! that cannot be compared and bad options are one line and exit 2. The figure is decoded and
//! checked: not blank, data in every panel.

use crate::common;
use crate::figure_check;

use std::path::Path;
use std::process::Output;

use common::{Run, fresh_dir, looplab, run_in_process};
use figure_check::assert_figure;

/// A one-second lockstep run of the pendulum with `args` on top.
fn pendulum(name: &str, args: &[&str]) -> Run {
    run_in_process(name, &[&["pendulum", "--duration", "1"], args].concat())
}

fn diff(a: &Path, b: &Path, args: &[&str]) -> Output {
    looplab().arg("diff").arg(a).arg(b).args(args).output().expect("start looplab")
}

fn stdout(output: &Output) -> String {
    String::from_utf8_lossy(&output.stdout).into_owned()
}

fn stderr(output: &Output) -> String {
    String::from_utf8_lossy(&output.stderr).into_owned()
}

/// The last line printed before the files' paths: the verdict.
fn verdict(output: &Output) -> String {
    let text = stdout(output);
    let lines: Vec<&str> =
        text.lines().filter(|l| !l.starts_with("figure: ") && !l.starts_with("diff.json: ")).collect();
    lines.last().expect("a verdict").to_string()
}

fn diff_json(path: &Path) -> serde_json::Value {
    serde_json::from_str(&std::fs::read_to_string(path).expect("diff.json")).expect("diff.json is JSON")
}

/// The trajectory's fields of the pendulum: 3 state, 2 measurements, 4 estimate, command, applied.
const PENDULUM_FIELDS: usize = 11;

#[test]
fn two_runs_of_the_same_settings_are_identical_in_every_loop() {
    let a = pendulum("diff-same-a", &[]);
    let b = pendulum("diff-same-b", &[]);
    let out = diff(&a.dir, &b.dir, &[]);
    assert_eq!(out.status.code(), Some(0), "{}\n{}", stdout(&out), stderr(&out));
    let text = stdout(&out);
    assert_eq!(verdict(&out), "identical in every loop", "{text}");
    // The trajectory's fields and the metrics (bias_true_rad among them: the same in any run).
    let fields = PENDULUM_FIELDS + b.summary["metrics"].as_object().unwrap().len();
    let header = format!("pendulum · lockstep · 1000 Hz · 1000 loops · {fields} fields · tolerance 0 (exact)");
    assert!(text.contains(&header), "{text}");
    // No field is listed; the latency's ratios are, not judged.
    assert!(!text.contains("max |B−A|") && !text.contains("est.theta_rad"), "{text}");
    assert!(text.contains("not judged (--tolerance latency=R judges it)"), "{text}");
    assert!(text.contains(&format!("figure: {}", b.dir.join("diff.png").display())), "{text}");

    // One "no difference" panel, drawn.
    assert_figure(&b.dir.join("diff.png"), 1, false);
    let json = diff_json(&b.dir.join("diff.json"));
    assert_eq!(json["within_tolerance"], true);
    assert_eq!(json["verdict"], "identical in every loop");
    let fields = json["fields"].as_array().unwrap();
    assert_eq!(fields.len(), PENDULUM_FIELDS + b.summary["metrics"].as_object().unwrap().len());
    for f in fields {
        assert_eq!((f["differing"].as_u64(), f["over"].as_u64(), f["max_abs"].as_f64()), (Some(0), Some(0), Some(0.0)));
    }
    assert_eq!(fields[0]["compared"], 1000);

    // The latency judged too: the same run against itself has every ratio 1.
    let out = diff(&a.dir, &a.dir, &["--tolerance", "latency=1", "--no-figure"]);
    assert_eq!(out.status.code(), Some(0), "{}", stdout(&out));
    assert_eq!(verdict(&out), "identical in every loop; latency within [1/1, 1]");
}

#[test]
fn a_changed_observer_gain_moves_the_estimate_from_the_first_loop() {
    let a = pendulum("diff-gain-a", &[]);
    let b = pendulum("diff-gain-b", &["--set", "estimator.bias-observer.poles=[-16.0, -20.0, -25.0]"]);
    let figure_dir = fresh_dir("diff-gain-figure");
    std::fs::create_dir_all(&figure_dir).unwrap();
    let figure = figure_dir.join("gain.png");
    let out = diff(&a.dir, &b.dir, &["--figure", figure.to_str().unwrap()]);
    assert_eq!(out.status.code(), Some(3), "{}\n{}", stdout(&out), stderr(&out));
    let text = stdout(&out);
    // The observer sees the same first measurement; its new gain moves the estimate at loop 1,
    // and the command and so the plant follow later. Every metric moves too.
    let json = diff_json(&figure_dir.join("gain.json"));
    let metrics = b.summary["metrics"].as_object().unwrap().len();
    let over = json["fields"].as_array().unwrap().iter().filter(|f| f["over"].as_u64() > Some(0)).count();
    assert_eq!(verdict(&out), format!("{over} fields over tolerance; first: est.theta_rad at loop 1 (t = 0.001 s)"));
    assert_eq!(json["within_tolerance"], false);
    let field = |name: &str| -> serde_json::Value {
        json["fields"]
            .as_array()
            .unwrap()
            .iter()
            .find(|f| f["name"] == name)
            .unwrap_or_else(|| panic!("{name}"))
            .clone()
    };
    for name in ["est.theta_rad", "est.theta_dot_rad_per_s", "est.bias_rad"] {
        assert_eq!(field(name)["first_over"]["k"], 1, "{name}");
        assert_eq!(field(name)["over"], 999, "{name}: every loop after the first");
        let line = text.lines().find(|l| l.trim_start().starts_with(&format!("{name} "))).expect(name);
        let words: Vec<&str> = line.split_whitespace().collect();
        // loops over, first over ("1 (t = 0.001 s)"), empty A/B.
        assert_eq!(words[words.len() - 7..], ["999", "1", "(t", "=", "0.001", "s)", "-"], "{line}");
    }
    // The command moves only once the estimate has moved it, the plant a loop later.
    let (cmd, applied) = (field("cmd.current_A"), field("applied.current_A"));
    let (first_cmd, first_applied) =
        (cmd["first_over"]["k"].as_u64().unwrap(), applied["first_over"]["k"].as_u64().unwrap());
    assert!(first_cmd > 1, "{cmd}");
    assert_eq!(first_applied, first_cmd + 1, "what the actuator applied follows the command by a loop");
    assert_eq!(field("theta_rad")["first_over"]["k"], first_applied);
    // Each field's unit, from the run's launch file: the figure's axis says it.
    assert_eq!(
        (field("theta_rad")["unit"].as_str(), field("cmd.current_A")["unit"].as_str()),
        (Some("rad"), Some("A"))
    );
    assert_eq!(over, PENDULUM_FIELDS + metrics - 1, "{text}");
    // Numbers that a reader can check: the largest difference is the one the JSON keeps.
    let largest = field("est.theta_rad")["max_abs"].as_f64().unwrap();
    assert!(largest > 0.0);
    assert!(text.contains("\n  estimate (est.*)\n    est.theta_rad "), "{text}");

    // One panel per field that moved, each with its curve.
    assert_figure(&figure, PENDULUM_FIELDS, false);

    // Loose enough: every group's tolerance well above its largest difference.
    let loose: Vec<String> = ["state", "meas", "est", "cmd", "applied", "metrics"]
        .iter()
        .flat_map(|g| ["--tolerance".to_string(), format!("{g}=100")])
        .collect();
    let mut args: Vec<&str> = loose.iter().map(String::as_str).collect();
    args.push("--no-figure");
    let out = diff(&a.dir, &b.dir, &args);
    assert_eq!(out.status.code(), Some(0), "{}", stdout(&out));
    // Every field but the true bias, which the launch file sets.
    assert_eq!(field("bias_true_rad")["differing"], 0);
    assert_eq!(verdict(&out), format!("{} fields differ, each within its tolerance", PENDULUM_FIELDS + metrics - 1));

    // A tolerance just below the estimate's largest difference: only that field is over it at
    // the loop of its largest difference (the other groups loose).
    let theta = format!("est.theta_rad={}", largest * (1.0 - 1e-9));
    let out = diff(&a.dir, &b.dir, &[&args[..args.len() - 1], &["--tolerance", &theta, "--no-figure"]].concat());
    assert_eq!(out.status.code(), Some(3), "{}", stdout(&out));
    let k = field("est.theta_rad")["max_at"]["k"].as_u64().unwrap();
    let t = field("est.theta_rad")["max_at"]["t_s"].as_f64().unwrap();
    assert_eq!(verdict(&out), format!("1 field over tolerance; first: est.theta_rad at loop {k} (t = {t} s)"));
    std::fs::remove_dir_all(&figure_dir).unwrap();
}

/// Runs `looplab diff` and expects exit 2 and exactly `expected` as its one line.
fn assert_bad_input(a: &Path, b: &Path, args: &[&str], expected: &str) {
    let out = diff(a, b, args);
    assert_eq!(out.status.code(), Some(2), "{}\n{}", stdout(&out), stderr(&out));
    assert_eq!(stderr(&out), format!("error: {expected}\n"));
    assert_eq!(stdout(&out), "");
}

#[test]
fn runs_that_cannot_be_compared_and_bad_options_are_one_line() {
    let a = pendulum("diff-bad-a", &[]);
    let other = run_in_process("diff-bad-tiltrotor", &["tiltrotor", "--duration", "1"]);
    assert_bad_input(&a.dir, &other.dir, &[], "cannot compare: RUN_A is scenario pendulum, RUN_B is tiltrotor");
    let rate = pendulum("diff-bad-rate", &["--rate", "500", "--set", "sensors.encoder.period_s=0.002"]);
    assert_bad_input(&a.dir, &rate.dir, &[], "cannot compare: RUN_A runs at 1000 Hz, RUN_B at 500 Hz");
    let longer = run_in_process("diff-bad-longer", &["pendulum", "--duration", "2"]);
    assert_bad_input(&a.dir, &longer.dir, &[], "cannot compare: RUN_A lasts 1 s, RUN_B 2 s");
    assert_bad_input(&longer.dir, &a.dir, &[], "cannot compare: RUN_A lasts 2 s, RUN_B 1 s");

    let missing = fresh_dir("diff-bad-missing");
    assert_bad_input(&a.dir, &missing, &[], &format!("{}: no such run folder", missing.display()));
    let empty = fresh_dir("diff-bad-empty");
    std::fs::create_dir_all(&empty).unwrap();
    assert_bad_input(&empty, &a.dir, &[], &format!("{}: not a run folder (it has no launch.toml)", empty.display()));
    std::fs::remove_dir(&empty).unwrap();

    assert_bad_input(
        &a.dir,
        &a.dir,
        &["--tolerance", "est.nosuch=1"],
        "--tolerance est.nosuch=1: no field est.nosuch; give a column of trajectory.csv (for example est.theta_rad), \
         a group (state, meas, est, cmd, applied, metrics), a metric of summary.json or latency",
    );
    assert_bad_input(&a.dir, &a.dir, &["--tolerance", "est=abc"], "--tolerance est=abc: \"abc\" is not a number");
    assert_bad_input(
        &a.dir,
        &a.dir,
        &["--tolerance", "latency=0.5"],
        "--tolerance latency=0.5: latency=R takes a ratio of 1 or more (2: B within half to twice A)",
    );
    assert_bad_input(
        &a.dir,
        &a.dir,
        &["--figure", "diff.svg"],
        "--figure diff.svg: the figure is a PNG; give a path ending in .png",
    );

    // A trajectory.csv with another column (a run of another estimator's layout).
    let renamed = pendulum("diff-bad-columns", &[]);
    let path = renamed.dir.join("trajectory.csv");
    let text = std::fs::read_to_string(&path).unwrap();
    std::fs::write(&path, text.replacen("est.bias_rad", "est.offset_rad", 1)).unwrap();
    assert_bad_input(
        &a.dir,
        &renamed.dir,
        &[],
        "cannot compare: RUN_A's trajectory.csv has column est.bias_rad, RUN_B's has not",
    );
    // Nothing was written for any of them.
    for dir in [&a.dir, &other.dir, &rate.dir, &longer.dir, &renamed.dir] {
        assert!(!dir.join("diff.png").exists() && !dir.join("diff.json").exists(), "{}", dir.display());
    }
}
