//! A system declared in its launch file (no `scenario`, a `[system]` table), with the built-in
//! linear plant: five processes and in-process, real time with its plant killed, and bad files.

use crate::common;

use std::path::{Path, PathBuf};

use common::*;

const EXAMPLE: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/launch/declared.toml");

/// Writes `text` as `<name>.toml` in a fresh folder and returns its path.
fn launch_file(name: &str, text: &str) -> PathBuf {
    let dir = fresh_dir(name);
    std::fs::create_dir_all(&dir).unwrap();
    let path = dir.join(format!("{name}.toml"));
    std::fs::write(&path, text).unwrap();
    path
}

/// The example, five processes in lockstep: it completes, its columns are the declared names
/// (the state, then the outputs), the controller brings the mass to rest, and the in-process
/// run's trajectory.csv is the same bytes.
#[test]
fn a_declared_system_runs_in_five_processes_byte_identical_to_in_process() {
    let five = run("declared-five", &[EXAMPLE, "--mode", "lockstep"]);
    let s = five.summary();
    assert!(s.completed, "{:?}", s.stopped_because);
    assert_eq!(s.loops, 500);
    assert_nothing_left(s);
    let header = std::fs::read_to_string(five.dir.join("trajectory.csv")).unwrap();
    let header = header.lines().next().unwrap();
    assert!(
        header.starts_with("k,t_s,position_m,velocity_m_per_s,spring_force_N,meas.encoder_m,"),
        "the state message is the state, then the outputs: {header}"
    );
    let t = five.trajectory();
    let (x, spring) = (t.col("position_m"), t.col("spring_force_N"));
    assert_eq!(x[0], 0.1, "the declared initial position");
    assert!(x.last().unwrap().abs() < 1e-3, "state feedback brings it to rest: {}", x.last().unwrap());
    for (x, f) in x.iter().zip(&spring) {
        assert_eq!(*f, -2.0 * x, "y = C x");
    }
    assert_eq!(
        t.col("est.velocity_m_per_s"),
        t.col("velocity_m_per_s"),
        "exact sensors: the pass-through is the truth"
    );
    assert!(five.dir.join("run.mcap").is_file());

    let one = run_in_process("declared-in-process", &[EXAMPLE]);
    let bytes = |r: &Run| std::fs::read(r.dir.join("trajectory.csv")).unwrap();
    assert!(bytes(&five) == bytes(&one), "in-process differs from five processes");
}

/// A double integrator from (0, 1) with no force: position = t exactly (RK4 is exact on it). Its
/// plant is killed in real time; the restarted plant goes on from its snapshot (and integrates
/// the ticks it missed), so every row still has position = t, never the initial 0 again.
#[test]
fn a_declared_plant_killed_in_real_time_restarts_from_its_snapshot() {
    let file = launch_file(
        "coasting",
        r#"
mode = "realtime"
rate_hz = 200.0
duration_s = 2.0
[system]
state = [{ name = "position", unit = "m" }, { name = "velocity", unit = "m/s", initial = 1.0 }]
input = [{ name = "force", unit = "N", min = -1.0, max = 1.0 }]
[plant.linear]
a = [[0.0, 1.0], [0.0, 0.0]]
b = [[0.0], [1.0]]
[sensors.odometer]
reads = ["state.position", "state.velocity"]
period_s = 0.005
[controller]
gains = [[0.0, 0.0]]
"#,
    );
    let r = run("declared-kill", &[file.to_str().unwrap(), "--fault", "kill plant at 1s"]);
    let s = r.summary();
    assert!(s.completed, "{:?}", s.stopped_because);
    assert_eq!(s.restarts[&Role::Plant], 1);
    assert_eq!(s.faults[0].detected_by, Some(DetectedBy::ProcessExited), "{:?}", s.faults[0]);
    assert!(s.faults[0].restarted_after_ms.is_some(), "{:?}", s.faults[0]);
    // The linear model has no state of its own beyond the vector, and the report says what it went on from.
    assert!(s.notes.iter().any(|n| n.contains("went on from the state vector alone")), "{:?}", s.notes);
    assert_nothing_left(s);
    // Loops the dead plant never published have empty cells: only the rows with a state count.
    let text = std::fs::read_to_string(r.dir.join("trajectory.csv")).unwrap();
    let mut lines = text.lines();
    let header: Vec<&str> = lines.next().unwrap().split(',').collect();
    let column = |name: &str| header.iter().position(|h| *h == name).unwrap();
    let (t_at, x_at) = (column("t_s"), column("position_m"));
    let mut after = 0;
    for line in lines {
        let cells: Vec<&str> = line.split(',').collect();
        let (t, x): (f64, &str) = (cells[t_at].parse().unwrap(), cells[x_at]);
        let Ok(x) = x.parse::<f64>() else { continue };
        after += usize::from(t > 1.0);
        assert!((x - t).abs() < 1e-9, "position {x} at t = {t}: the restarted plant did not go on from its snapshot");
    }
    assert!(after > 100, "the restarted plant published the rest of the run: {after} rows after the kill");
}

/// A bad declared file: exit 2, one line on stderr naming the file, the key and what is wrong,
/// and no run folder (nothing started, so nothing is in shared memory either).
#[test]
fn bad_declared_files_are_one_clear_line_with_exit_2() {
    let example = std::fs::read_to_string(EXAMPLE).unwrap();
    let replace = |from: &str, to: &str| {
        assert!(example.contains(from), "{from}");
        example.replacen(from, to, 1)
    };
    let big_state: Vec<String> = (0..31).map(|i| format!("{{ name = \"x{i}\", unit = \"1\" }}")).collect();
    let too_large = replace(
        r#"    { name = "velocity", unit = "m/s" },"#,
        &format!("    {{ name = \"velocity\", unit = \"m/s\" }}, {},", big_state.join(", ")),
    );
    let cases: Vec<(&str, String, &str, &str)> = vec![
        (
            "too-large",
            too_large,
            "system.state",
            "the state and the outputs have 34 components, more than the 32 a state message carries",
        ),
        (
            "unknown-read",
            replace(r#"reads = ["state.position"]"#, r#"reads = ["state.angle"]"#),
            "sensors.encoder.reads.0",
            "the state has no component \"angle\"; it has: position, velocity",
        ),
        (
            "two-plants",
            replace("substeps = 10 ", "python = \"plant.py:Mass\"\nsubsteps = 10 "),
            "plant",
            "give exactly one plant model",
        ),
        ("shape", replace("b = [[0.0], [1.0]]", "b = [[0.0, 1.0]]"), "plant.linear.b", "must be 2 × 1"),
        ("no-controller", replace("gains = [[4.0, 2.0]]", ""), "controller", "needs a controller"),
        ("limits", replace("min = -10.0", "min = 11.0"), "system.input.0.min", "must be at most max"),
        (
            "signal",
            replace(r#"reads = ["state.position"]"#, r#"signal = "position""#),
            "sensors.encoder.signal",
            "reads",
        ),
        (
            "bad-name",
            replace(r#"name = "spring_force""#, r#"name = "spring force""#),
            "system.outputs.0.name",
            "not a name",
        ),
        (
            "unread-estimate",
            replace(r#"reads = ["state.velocity", "input.force"]"#, r#"reads = ["input.force"]"#),
            "system.estimate.1.name",
            "no sensor reads \"velocity\"",
        ),
    ];
    for (name, text, key, message) in cases {
        let file = launch_file(name, &text);
        let out_dir = fresh_dir("rejected");
        let out = looplab().arg("run").arg(&file).arg("--out").arg(&out_dir).output().unwrap();
        let stderr = String::from_utf8_lossy(&out.stderr);
        assert_eq!(out.status.code(), Some(2), "{name}: {stderr}");
        assert_eq!(stderr.trim_end().lines().count(), 1, "{name}: one line: {stderr}");
        let expected_key = format!("key `{key}`");
        for part in [file.to_str().unwrap(), expected_key.as_str(), message] {
            assert!(stderr.contains(part), "{name}: {part:?} not in {stderr}");
        }
        assert!(!Path::new(&out_dir).exists(), "{name}: a run folder was made");
    }
}
