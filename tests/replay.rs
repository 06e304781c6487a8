//! `looplab replay` (issue 32): a recorded run played back into one stage, as processes over real
//! shared memory and in one process. A lockstep recording replayed into the same stage gives its
//! trajectory back byte for byte; a changed gain moves the stage's outputs from the loop it first
//! acts on; a real-time recording with a kill and a delay is replayed as what the stage saw (the
//! loops it skipped, the loop it restarted at, the loops it held), with its outputs bit for bit
//! where both computed one; a Python estimator takes the built-in one's place; bad input is one
//! line, exit 2, and nothing is written.

use crate::common;

use std::path::Path;
use std::process::Output;

use common::*;

const EXAMPLES: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/services/examples/estimator");

fn replay_with(mut launcher: std::process::Command, recording: &Path, out: &Path, args: &[&str]) -> Output {
    launcher.arg("replay").arg(recording).args(args).arg("--out").arg(out).output().expect("start looplab")
}

/// `looplab replay RECORDING ARGS --out OUT`, expected to succeed.
fn replay(recording: &Path, out: &Path, args: &[&str]) -> String {
    let output = replay_with(looplab(), recording, out, args);
    assert!(
        output.status.success(),
        "looplab replay {args:?} failed ({}):\n{}\n{}",
        output.status,
        String::from_utf8_lossy(&output.stdout),
        String::from_utf8_lossy(&output.stderr)
    );
    String::from_utf8_lossy(&output.stdout).into_owned()
}

fn replay_json(dir: &Path) -> serde_json::Value {
    serde_json::from_str(&std::fs::read_to_string(dir.join("replay.json")).expect("replay.json")).expect("JSON")
}

fn bytes(dir: &Path, file: &str) -> Vec<u8> {
    std::fs::read(dir.join(file)).unwrap_or_else(|e| panic!("{}: {e}", dir.join(file).display()))
}

fn diff(a: &Path, b: &Path, args: &[&str]) -> Output {
    looplab().arg("diff").arg(a).arg(b).args(args).output().expect("start looplab")
}

/// Inclusive ranges from a JSON array of pairs.
fn ranges(value: &serde_json::Value) -> Vec<[u64; 2]> {
    serde_json::from_value(value.clone()).expect("ranges")
}

/// The loops of a run of `loops` loops whose cells in `column` are empty, or that have no row
/// at all (a real-time run's last ticks may end before their data came), as inclusive ranges.
fn empty_ranges(table: &Table, column: &str, loops: u64) -> Vec<[u64; 2]> {
    let i = table.columns[column];
    let filled: std::collections::BTreeSet<u64> =
        table.rows.iter().filter(|row| !row[i].is_empty()).map(|row| row[0].parse().expect("k")).collect();
    let mut out: Vec<[u64; 2]> = Vec::new();
    for k in (0..loops).filter(|k| !filled.contains(k)) {
        match out.last_mut() {
            Some(last) if last[1] + 1 == k => last[1] = k,
            _ => out.push([k, k]),
        }
    }
    out
}

#[test]
fn a_lockstep_replay_of_the_same_estimator_gives_the_recording_back_byte_for_byte() {
    // A drop upstream (loops the estimator passes on), a delay of the estimator itself (its
    // delay line) and a kill of it (a restart that thaws its bias) are all replayed.
    let recording = run(
        "replay-lockstep-recording",
        &[
            "pendulum",
            "--mode",
            "lockstep",
            "--duration",
            "2",
            "--fault",
            "drop sensors 30% at 0.5s for 200ms",
            "--fault",
            "delay estimator by 2 ticks at 1s for 300ms",
            "--fault",
            "kill estimator at 1.5s",
        ],
    );
    let processes = fresh_dir("replay-lockstep-processes");
    let said = replay(&recording.dir, &processes, &["--stage", "estimator"]);
    assert!(said.contains("open loop: the plant, sensors, controller played the recording back"), "{said}");
    assert!(said.contains("outputs: identical to the recording's, bit for bit, in all"), "{said}");
    assert!(said.contains("restarts: the recorded estimator restarted at loop 1500"), "{said}");
    assert!(bytes(&processes, "trajectory.csv") == bytes(&recording.dir, "trajectory.csv"), "the trajectories differ");
    let report = replay_json(&processes);
    assert_eq!(report["restarts"], serde_json::json!([1500]));
    assert_eq!(report["delayed"], serde_json::json!([[1000, 1299]]));
    // The loops the drop took from the estimator, skipped again.
    let skipped = ranges(&report["skipped"]);
    assert!(!skipped.is_empty() && skipped.iter().all(|[a, b]| (500..700).contains(a) && (500..700).contains(b)));
    assert_eq!(report["skipped_in_replay"], report["skipped"]);
    // The replayed estimator restarted as its recording did.
    let summary = load_summary(&processes);
    assert_eq!(last_incarnations(&summary)[&Role::Estimator].incarnation, 1);
    assert_nothing_left(&summary);
    let same = diff(&recording.dir, &processes, &[]);
    assert_eq!(same.status.code(), Some(0), "{}", String::from_utf8_lossy(&same.stdout));

    // The controller of the same recording: the estimator plays back, its delay line and the
    // loops it passed on marked lost included.
    let controller = fresh_dir("replay-lockstep-controller");
    replay(&recording.dir, &controller, &["--stage", "controller"]);
    assert!(bytes(&controller, "trajectory.csv") == bytes(&recording.dir, "trajectory.csv"), "controller differs");
    let _ = std::fs::remove_dir_all(controller);

    // In one process: the same bytes.
    let one = fresh_dir("replay-lockstep-in-process");
    replay(&recording.dir, &one, &["--stage", "estimator", "--in-process"]);
    assert!(bytes(&one, "trajectory.csv") == bytes(&processes, "trajectory.csv"), "in-process differs");

    // Closed loop with the same controller: the whole run again, the same bytes.
    let closed = fresh_dir("replay-lockstep-closed");
    let said = replay(&recording.dir, &closed, &["--stage", "controller", "--closed-loop"]);
    assert!(said.contains("state: identical to the recording's, bit for bit, in all 2000 loops"), "{said}");
    assert!(bytes(&closed, "trajectory.csv") == bytes(&recording.dir, "trajectory.csv"), "closed loop differs");
    for dir in [processes, one, closed] {
        let _ = std::fs::remove_dir_all(dir);
    }
}

#[test]
fn a_changed_observer_gain_moves_the_estimate_from_the_loop_it_first_acts_on() {
    let recording = run("replay-gain-recording", &["pendulum", "--mode", "lockstep", "--duration", "1"]);
    let out = fresh_dir("replay-gain");
    let said = replay(
        &recording.dir,
        &out,
        &["--stage", "estimator", "--set", "estimator.bias-observer.poles=[-30.0, -35.0, -40.0]"],
    );
    // The first loop where any estimate differs, found here from the two trajectories.
    let (a, b) = (Table::read(&recording.dir.join("trajectory.csv")), Table::read(&out.join("trajectory.csv")));
    let columns: Vec<&String> = a.columns.keys().filter(|c| c.starts_with("est.")).collect();
    let first = (0..a.rows.len())
        .find(|&k| columns.iter().any(|c| a.rows[k][a.columns[*c]] != b.rows[k][b.columns[*c]]))
        .expect("the gain moves the estimate");
    assert!(said.contains(&format!("differ from the recording's, the first at loop {first}")), "{said}");
    assert!(said.contains("est.theta_rad"), "{said}");
    // Open loop: everything else is the recording's.
    for column in a.columns.keys().filter(|c| !c.starts_with("est.")) {
        assert_eq!(a.col(column), b.col(column), "{column}");
    }

    let moved = diff(&recording.dir, &out, &[]);
    let text = String::from_utf8_lossy(&moved.stdout);
    assert_eq!(moved.status.code(), Some(3), "{text}");
    assert!(text.contains(&format!("first: est.theta_rad at loop {first}")), "{text}");
    let _ = std::fs::remove_dir_all(out);
}

#[test]
fn a_real_time_recording_with_a_kill_and_a_delay_is_replayed_as_what_the_estimator_saw() {
    let recording = run(
        "replay-realtime-recording",
        &[
            "pendulum",
            "--duration",
            "3",
            "--fault",
            "kill estimator at 1s",
            "--fault",
            "delay estimator by 5ms at 2s for 300ms",
        ],
    );
    let out = fresh_dir("replay-realtime");
    let said = replay(&recording.dir, &out, &["--stage", "estimator"]);
    let report = replay_json(&out);
    let table = Table::read(&recording.dir.join("trajectory.csv"));

    // Skipped: exactly the loops the recording has no estimate of, and the replay skipped them.
    let skipped = ranges(&report["skipped"]);
    let planned = recording.summary().loops_planned;
    assert_eq!(skipped, empty_ranges(&table, "est.theta_rad", planned), "{said}");
    // A kill between the recorded estimator's send and its keep (a microsecond's window) made
    // its successor thaw one loop older; the replay then withholds that loop too, and says so.
    let thawed_older: Vec<u64> = serde_json::from_value(report["thawed_older"].clone()).unwrap();
    let mut expected: std::collections::BTreeSet<u64> = skipped.iter().flat_map(|[a, b]| *a..=*b).collect();
    expected.extend(&thawed_older);
    let in_replay: std::collections::BTreeSet<u64> =
        ranges(&report["skipped_in_replay"]).iter().flat_map(|[a, b]| *a..=*b).collect();
    assert_eq!(in_replay, expected, "{said}");
    // It restarted once, after the kill, at its recording's first output of incarnation 1.
    let restarts: Vec<u64> = serde_json::from_value(report["restarts"].clone()).unwrap();
    assert_eq!(restarts.len(), 1, "{said}");
    // From the kill (tick j is due j ms after tick 0) to the restart it computed nothing.
    let kill = recording.summary().faults.iter().find(|f| f.kind == FaultKind::Kill).expect("the kill's report");
    let killed_ms = kill.injected_at_ms.expect("the launcher's injection time");
    assert!(restarts[0] as f64 > killed_ms, "{said}");
    assert!((killed_ms.ceil() as u64 + 1..restarts[0]).all(|k| expected.contains(&k)), "{said}");
    // Delayed: the fault's loops, each held back as a transport delay: its estimate reached the
    // controller at least 5 ms after the estimator computed it (its publish stamp).
    assert_eq!(report["delayed"], serde_json::json!([[2000, 2299]]), "{said}");
    let loops = Table::read(&recording.dir.join("loops.csv"));
    let (published, received) = (loops.columns["estimator_publish_ns"], loops.columns["controller_receive_ns"]);
    let held: Vec<(u64, u64)> = loops
        .rows
        .iter()
        .filter_map(|r| {
            let k: u64 = r[0].parse().unwrap();
            let (a, b) = (r[published].parse::<u64>().ok()?, r[received].parse::<u64>().ok()?);
            (2000..2300).contains(&k).then_some((k, b.saturating_sub(a)))
        })
        .collect();
    assert!(!held.is_empty() && held.iter().all(|(_, ns)| *ns >= 5_000_000), "{held:?}");
    // The outputs, where both computed one, are the recording's bit for bit: the estimator saw
    // the same messages in the same order.
    let outputs = &report["outputs"];
    assert_eq!(outputs["first_difference"], serde_json::Value::Null, "{said}");
    assert_eq!(outputs["identical"], outputs["compared"]);
    let computed = planned - in_replay.len() as u64;
    assert_eq!(outputs["compared"], computed);
    // So diff, which reads the files, finds the recording in the replay: the loops the
    // estimator skipped are left out of the replay's files as the recording has none.
    let same = diff(&recording.dir, &out, &["--no-figure"]);
    assert_eq!(same.status.code(), Some(0), "{}", String::from_utf8_lossy(&same.stdout));

    // The sensors of the same recording: the ticks the real-time plant skipped are withheld from
    // them, so their noise draws line up, and their readings are the recording's.
    let sensors = fresh_dir("replay-realtime-sensors");
    let said = replay(&recording.dir, &sensors, &["--stage", "sensors"]);
    let report = replay_json(&sensors);
    assert_eq!(report["outputs"]["first_difference"], serde_json::Value::Null, "{said}");
    assert_eq!(report["skipped_in_replay"], report["skipped"], "{said}");
    assert_eq!(ranges(&report["skipped"]), empty_ranges(&table, "meas.encoder_rad", planned), "{said}");
    for dir in [out, sensors] {
        let _ = std::fs::remove_dir_all(dir);
    }
}

#[test]
fn a_python_estimator_replayed_in_the_built_in_ones_place_gives_the_same_estimate() {
    let recording = run("replay-python-recording", &["pendulum", "--mode", "lockstep", "--duration", "1"]);
    let out = fresh_dir("replay-python");
    let stage = format!("estimator=python3 {EXAMPLES}/pendulum_estimator.py");
    let output = replay_with(python_launcher(), &recording.dir, &out, &["--stage", &stage]);
    let said = String::from_utf8_lossy(&output.stdout);
    assert!(output.status.success(), "{said}\n{}", String::from_utf8_lossy(&output.stderr));
    assert!(said.contains(&format!("program: python3 {EXAMPLES}/pendulum_estimator.py")), "{said}");
    assert!(said.contains("outputs: identical to the recording's, bit for bit, in all 1000 loops"), "{said}");
    assert!(bytes(&out, "trajectory.csv") == bytes(&recording.dir, "trajectory.csv"));
    // The estimator that ran was the Python one.
    let launch = std::fs::read_to_string(out.join("launch.toml")).unwrap();
    assert!(launch.contains("pendulum_estimator.py"), "{launch}");
    let _ = std::fs::remove_dir_all(out);
}

#[test]
fn bad_input_is_one_line_exit_2_and_writes_nothing() {
    let recording = run("replay-bad-recording", &["pendulum", "--mode", "lockstep", "--duration", "0.2"]);
    let no_mcap = fresh_dir("replay-bad-no-mcap");
    std::fs::create_dir_all(&no_mcap).unwrap();
    for file in ["launch.toml", "summary.json", "trajectory.csv"] {
        std::fs::copy(recording.dir.join(file), no_mcap.join(file)).unwrap();
    }
    let missing = fresh_dir("replay-bad-missing");
    let r = recording.dir.to_str().unwrap();
    let python_stage = format!("estimator=python3 {EXAMPLES}/pendulum_estimator.py");
    let cases: Vec<(Vec<&str>, String)> = vec![
        (vec![missing.to_str().unwrap(), "--stage", "estimator"], "cannot open the recording".into()),
        (
            vec![r, "--stage", "plant"],
            "--stage plant: unknown stage \"plant\"; allowed: sensors, estimator, controller".into(),
        ),
        (vec![r, "--stage", "estimator="], "expected a program and its arguments after `=`".into()),
        (
            vec![no_mcap.to_str().unwrap(), "--stage", "estimator"],
            "has no run.mcap; replay needs the recording a run writes".into(),
        ),
        (
            vec![r, "--stage", "estimator", "--set", "sensors.wheel_speed.enabled=false"],
            "needs a sensor with signal = \"wheel_speed\"".into(),
        ),
        (
            vec![r, "--stage", &python_stage, "--in-process"],
            "--in-process: stages.estimator.command runs the estimator as a process of its own".into(),
        ),
        (vec![r, "--stage", "estimator=python3 no-such-file.py"], "script no-such-file.py is not found".into()),
    ];
    for (args, expected) in cases {
        let out = fresh_dir("replay-bad-out");
        // With the Python module importable, so that the Python stage is refused for --in-process.
        let output = python_launcher().arg("replay").args(&args).arg("--out").arg(&out).output().unwrap();
        let stderr = String::from_utf8_lossy(&output.stderr);
        assert_eq!(output.status.code(), Some(2), "{args:?}: {stderr}");
        assert!(stderr.contains(&expected), "{args:?}: {stderr}");
        assert_eq!(stderr.trim().lines().count(), 1, "{args:?}: {stderr}");
        assert!(!out.exists(), "{args:?} wrote {}", out.display());
    }
    let _ = std::fs::remove_dir_all(no_mcap);
}

/// A recording whose launch file plans a week (`duration_s = 604800`, allowed) but holds 2 s:
/// the replay is sized by what was recorded, runs those 200 loops and exits 0 (it asked for
/// 1.6 TB and aborted, sized by the plan).
#[test]
fn a_recording_shorter_than_its_plan_is_replayed_as_far_as_it_goes() {
    let dir = fresh_dir("replay-short");
    let recording = crate::golden_ci::motor_run_in_process(&dir);
    let launch = std::fs::read_to_string(recording.join("launch.toml")).unwrap();
    let week = launch.replace("duration_s = 2.0", "duration_s = 604800.0");
    assert_ne!(launch, week, "the plan is in the file");
    std::fs::write(recording.join("launch.toml"), week).unwrap();
    let text = replay(&recording, &dir.join("replayed"), &["--stage", "controller"]);
    assert!(text.contains("outputs: identical to the recording's, bit for bit, in all 200 loops"), "{text}");
    std::fs::remove_dir_all(&dir).unwrap();
}

/// The byte offset of the first chunk record of an MCAP file (after the 8 magic bytes, records
/// are an opcode, a u64 length and the body; a chunk's opcode is 0x06).
fn first_chunk(mcap: &[u8]) -> usize {
    let mut at = 8;
    while mcap[at] != 0x06 {
        at += 9 + u64::from_le_bytes(mcap[at + 1..at + 9].try_into().unwrap()) as usize;
    }
    at
}

/// A corrupt `run.mcap` is refused in one line naming it, never read as far as it goes nor
/// blamed on the stage: one byte flipped inside a chunk fails its CRC; a chunk whose length runs
/// past the end of a finished file is no killed monitor's last chunk.
#[test]
fn a_corrupt_recording_is_refused_not_replayed_in_part() {
    let dir = fresh_dir("replay-corrupt");
    let recording = crate::golden_ci::motor_run_in_process(&dir);
    let good = std::fs::read(recording.join("run.mcap")).unwrap();
    let chunk = first_chunk(&good);
    let mut flipped = good.clone();
    // Well inside the chunk's compressed records (past its 9-byte record head and fixed fields).
    flipped[chunk + 200] ^= 0x01;
    let mut too_long = good.clone();
    too_long[chunk + 1..chunk + 9].copy_from_slice(&(1u64 << 62).to_le_bytes());
    for (name, bytes, expected) in [
        ("flipped", flipped, "run.mcap: corrupt: a chunk"),
        ("too-long", too_long, "run.mcap: corrupt: record with opcode 06 length exceeds limit"),
    ] {
        std::fs::write(recording.join("run.mcap"), &bytes).unwrap();
        let out = dir.join(name);
        let output = replay_with(looplab(), &recording, &out, &["--stage", "controller"]);
        let stderr = String::from_utf8_lossy(&output.stderr);
        assert_eq!(output.status.code(), Some(2), "{name}: {stderr}");
        assert!(stderr.contains(expected), "{name}: {stderr}");
        assert_eq!(stderr.trim().lines().count(), 1, "{name}: {stderr}");
        assert!(!out.exists(), "{name}: wrote {}", out.display());
    }
    std::fs::remove_dir_all(&dir).unwrap();
}
