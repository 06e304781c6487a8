//! Fault injection, supervision and the delay margin, with the real processes over real
//! iceoryx2 shared memory. Numbers come from lockstep runs, which are deterministic; real-time
//! runs are checked for what happened, never for how fast.

use crate::common;

use common::*;

fn assert_clean(s: &Summary) {
    assert!(s.shared_memory.clean, "{:?}", s.shared_memory);
    let left = looplab_shared::runtime::storage::run_storage::files_of_run(&s.run_id);
    assert!(left.is_empty(), "files left behind: {left:?}");
    for p in &s.processes {
        assert!(!alive(i64::from(p.pid)), "{p:?} is still running");
    }
}

/// Every process's last incarnation ended cleanly.
fn assert_every_process_ended_alive(s: &Summary) {
    let last = last_incarnations(s);
    assert_eq!(last.len(), 5);
    for (name, p) in last {
        assert_eq!(p.exit, Exit::Status(0), "{name}'s last incarnation: {:?}", s.processes);
    }
}

/// The fault's effect, which the monitor recorded.
fn effect(f: &FaultReport) -> &looplab_shared::contract::report::FaultEffect {
    f.effect.as_ref().unwrap_or_else(|| panic!("no effect recorded: {f:?}"))
}

#[test]
fn each_loop_process_killed_in_lockstep_restarts_where_it_died_and_the_pendulum_stays_up() {
    let r = run(
        "kill-lockstep",
        &[
            "--mode",
            "lockstep",
            "--duration",
            "6",
            "--fault",
            "kill plant at 1.5s",
            "--fault",
            "kill sensors at 2.5s",
            "--fault",
            "kill estimator at 3.5s",
            "--fault",
            "kill controller at 4.5s",
        ],
    );
    let s = r.summary();
    assert!(s.completed, "{:?}", s.stopped_because);
    assert_eq!(s.loops, 6000);
    for (i, (process, at)) in
        [(Role::Plant, 1.5), (Role::Sensors, 2.5), (Role::Estimator, 3.5), (Role::Controller, 4.5)].iter().enumerate()
    {
        assert_eq!(s.restarts[process], 1, "{process}");
        let f = &s.faults[i];
        assert_eq!(f.detected_by, Some(DetectedBy::ProcessExited), "{f:?}");
        assert!(f.detected_after_ms.is_some() && f.restarted_after_ms.is_some(), "{f:?}");
        let e = effect(f);
        // Lockstep holds the loop while the process is replaced: the restarted one handles the
        // very loop at which its predecessor was killed, and not one command is missed.
        assert_eq!(e.rejoined_at_s, Some(*at), "{process}: {e:?}");
        assert_eq!(e.outage_ticks, 0, "{process}: {e:?}");
        assert!(e.within_limits, "{process}: {e:?}");
        assert_eq!(e.recovery_s, Some(0.0), "{process}: {e:?}");
    }
    // Every loop has its record: the restarted plant went on from its snapshot.
    assert_eq!(s.monitor.records, 6000);
    assert!(r.metric("theta_max_abs_rad") < 0.1);
    assert!((r.metric("bias_estimate_final_rad") - 0.1).abs() < 0.002, "the estimator kept its calibration");
    assert_every_process_ended_alive(s);
    assert_clean(s);
}

#[test]
fn each_loop_process_killed_in_real_time_restarts_and_the_loop_goes_on() {
    let r = run(
        "kill-realtime",
        &[
            "--duration",
            "3.5",
            "--fault",
            "kill plant at 1s",
            "--fault",
            "kill sensors at 1.5s",
            "--fault",
            "kill estimator at 2s",
            "--fault",
            "kill controller at 2.5s",
        ],
    );
    let s = r.summary();
    assert!(s.completed, "{:?}", s.stopped_because);
    assert_eq!(s.loops, 3500, "the restarted plant keeps the schedule: ticks it missed are integrated");
    for (i, process) in [Role::Plant, Role::Sensors, Role::Estimator, Role::Controller].iter().enumerate() {
        assert_eq!(s.restarts[process], 1);
        let f = &s.faults[i];
        // Whether the pendulum stays up (`within_limits`) depends on how long the restart
        // takes, which is the machine's business; the lockstep test above checks it.
        let e = effect(f);
        assert!(f.restarted_after_ms.is_some(), "{f:?}");
        assert!(e.rejoined_at_s.is_some(), "{process}: the restarted process never handled a loop: {e:?}");
        assert!(e.outage_ticks > 0, "a real outage has missed commands: {e:?}");
    }
    let timeline: Vec<&str> = s.timeline.iter().map(|t| t.event.as_str()).collect();
    assert!(timeline.contains(&"inject: kill estimator at 2s"), "{timeline:?}");
    assert!(timeline.contains(&"estimator ready again"), "{timeline:?}");
    assert!(r.stdout().contains("timeline"), "the printed report has the timeline");
    // Loops whose record a dead process never sent leave their stamps' cells empty.
    assert_loops_csv_integers(&r.dir);
    assert_every_process_ended_alive(s);
    assert_clean(s);
}

#[test]
fn a_stopped_controller_is_detected_by_its_input_deadline_and_the_plant_applies_on_stale() {
    let r = run(
        "stop",
        &["--duration", "2", "--set", "supervision.on_stale=zero", "--fault", "stop controller at 1s for 150ms"],
    );
    let s = r.summary();
    assert!(s.completed, "{:?}", s.stopped_because);
    let f = &s.faults[0];
    assert_eq!(f.detected_by, Some(DetectedBy::InputDeadline), "{f:?}");
    let detected = f.detected_after_ms.unwrap();
    let resumed = f.resumed_after_ms.unwrap();
    assert!(detected < resumed, "detected while stopped: {f:?}");
    assert!(f.continued_after_ms.unwrap() <= resumed, "{f:?}");
    // 150 ms without commands with a 20 ms command timeout: the plant applied zero current for
    // the rest of the stop.
    assert!(s.stale_ticks > 50, "{}", s.stale_ticks);
    assert!(effect(f).outage_ticks >= 100, "{f:?}");
    assert_eq!(s.restarts[&Role::Controller], 0, "a stopped process is not restarted");
    assert_clean(s);
}

#[test]
fn corrupt_commands_are_rejected_and_never_reach_the_plants_state() {
    let r = run(
        "corrupt",
        &[
            "--mode",
            "lockstep",
            "--duration",
            "4",
            "--fault",
            "corrupt controller nan at 2s for 100ms",
            "--fault",
            "corrupt controller out-of-range at 3s for 50ms",
        ],
    );
    let s = r.summary();
    assert_eq!(s.rejected_commands, 150);
    assert_eq!(effect(&s.faults[0]).outage_ticks, 100);
    assert_eq!(effect(&s.faults[1]).outage_ticks, 50);
    let trajectory = r.trajectory();
    for column in ["theta_rad", "theta_dot_rad_per_s", "wheel_speed_rad_per_s"] {
        let values = trajectory.col(column);
        assert_eq!(values.len(), 4000);
        assert!(values.iter().all(|v| v.is_finite()), "a non-finite {column} reached the plant");
    }
    // The commands themselves were corrupt: the monitor saw them.
    let commands = trajectory.col("cmd.current_A");
    assert!(commands[2000..2100].iter().all(|u| u.is_nan()));
    // Out of range: ten times the ±10 A limit.
    assert!(commands[3000..3050].iter().all(|u| *u == 100.0));
    assert!(effect(&s.faults[0]).within_limits && effect(&s.faults[1]).within_limits);
}

#[test]
fn drops_and_delays_in_lockstep_are_deterministic() {
    let args = [
        "--mode",
        "lockstep",
        "--duration",
        "3",
        "--fault",
        "drop sensors 30% at 1s for 1s",
        "--fault",
        "delay estimator by 4 ticks at 2s",
    ];
    let a = run("drop-a", &args);
    let b = run("drop-b", &args);
    let lost = a.summary().lost_commands;
    assert!((200..400).contains(&lost), "about 30% of 1000 loops: {lost}");
    assert_eq!(a.summary().lost_commands, b.summary().lost_commands);
    assert_eq!(effect(&a.summary().faults[0]).outage_ticks, lost);
    assert!(a.trajectory().rows == b.trajectory().rows, "two lockstep runs with the same faults differ");
}

#[test]
fn a_random_storm_of_kills_and_stops_leaves_every_process_alive_and_nothing_behind() {
    // 20 faults at seeded random times over a 30 s run, on every process, the monitor too.
    let processes = Role::ALL;
    let mut state: u64 = 0x9e37_79b9_7f4a_7c15;
    let mut next = move || {
        state = state.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
        state >> 33
    };
    let mut ticks: Vec<u64> = vec![];
    while ticks.len() < 20 {
        let tick = 500 + next() % 29_000;
        if !ticks.contains(&tick) {
            ticks.push(tick);
        }
    }
    ticks.sort();
    let faults: Vec<String> = ticks
        .iter()
        .map(|tick| {
            let process = processes[(next() % 5) as usize];
            let at = *tick as f64 / 1000.0;
            if next() % 2 == 0 {
                format!("kill {process} at {at}s")
            } else {
                format!("stop {process} at {at}s for {}ms", 20 + next() % 100)
            }
        })
        .collect();
    let mut args = vec!["--mode", "lockstep", "--duration", "30"];
    for f in &faults {
        args.extend(["--fault", f.as_str()]);
    }
    let r = run("storm", &args);
    let s = r.summary();
    assert!(s.completed, "{:?}: {faults:?}", s.stopped_because);
    assert_eq!(s.loops, 30_000);
    assert_every_process_ended_alive(s);
    let missing = listed_missing(s);
    assert_eq!(s.monitor.records, 30_000 - missing, "{:?}", s.monitor);
    let kills = faults.iter().filter(|f| f.starts_with("kill")).count() as u32;
    let restarts: u32 = s.restarts.values().sum();
    assert_eq!(restarts, kills, "{faults:?}");
    assert_clean(s);
}

#[test]
fn a_restarted_monitor_accounts_for_every_loop_and_continues_the_latency_log() {
    let r = run(
        "kill-monitor",
        &["--mode", "lockstep", "--duration", "4", "--fault", "kill monitor at 1s", "--fault", "kill monitor at 2.5s"],
    );
    let s = r.summary();
    let m = &s.monitor;
    assert!(s.completed, "{:?}", s.stopped_because);
    assert_eq!(s.restarts[&Role::Monitor], 2);
    let loops = s.loops;
    assert_eq!(loops, 4000);
    // Every loop is either recorded or accounted for as missing; lockstep loses no record.
    assert_eq!(m.records + m.missing.missing_loops, loops, "{m:?}");
    assert_eq!(m.lost, 0, "{m:?}");
    assert_eq!(m.missing.missing_ranges_omitted, 0, "{m:?}");
    assert_eq!(listed_missing(s), m.missing.missing_loops, "{m:?}");
    // Each restarted monitor went on from the last one's last checkpoint: only the loops
    // between that and its own first loop are missing, with that reason, and the rest is recorded.
    assert_eq!(m.missing.missing_before_restart, m.missing.missing_loops, "{m:?}");
    assert!(m.records > 1500, "the first monitors' loops count, not only the last one's 1500: {m:?}");

    // The interval log's time stamps go on across the restarts.
    let hlog = std::fs::read(r.dir.join("latency.hlog")).unwrap();
    let starts: Vec<std::time::Duration> = hdrhistogram::serialization::interval_log::IntervalLogIterator::new(&hlog)
        .filter_map(|entry| match entry.expect("a valid interval log") {
            hdrhistogram::serialization::interval_log::LogEntry::Interval(i) => Some(i.start_timestamp()),
            _ => None,
        })
        .collect();
    assert!(!starts.is_empty(), "latency.hlog has no interval");
    assert!(starts.windows(2).all(|w| w[0] <= w[1]), "interval start times go back: {starts:?}");
    // Three monitors wrote loops.csv, each appending after what the last one saved (cut back
    // to its last checkpoint).
    let rows = assert_loops_csv_integers(&r.dir) as u64;
    assert!(rows >= m.records, "{rows} rows, {} recorded", m.records);
    assert_every_process_ended_alive(s);
    assert_clean(s);
}

#[test]
fn a_restarted_monitor_reports_the_whole_run_as_if_it_had_never_died() {
    // The pendulum leans most in its first loops (its initial angle); the controller's kill
    // (which lockstep makes harmless) is over by loop 101; the monitor dies at loop 2500.
    let common = ["--mode", "lockstep", "--duration", "3.5", "--fault", "kill controller at 0.1s"];
    let killed = run("kill-monitor-whole", &[&common[..], &["--fault", "kill monitor at 2.5s"]].concat());
    let whole = run("kill-monitor-baseline", &common);
    let (s, m) = (killed.summary(), &killed.summary().monitor);
    assert!(s.completed, "{:?}", s.stopped_because);
    assert_eq!(s.restarts[&Role::Monitor], 1);
    assert_eq!(m.records + m.missing.missing_loops, s.loops, "{m:?}");
    assert_eq!(m.lost, 0, "{m:?}");
    // Lockstep holds the kill until the monitor has written and saved every loop before it:
    // its successor goes on from loop 2500 and no loop is missing.
    assert_eq!((m.records, m.missing.missing_loops), (s.loops, 0), "{m:?}");
    // The files too: the successor appended where its predecessor stopped, byte for byte.
    let trajectory = |dir: &std::path::Path| std::fs::read(dir.join("trajectory.csv")).unwrap();
    assert!(trajectory(&killed.dir) == trajectory(&whole.dir), "trajectory.csv differs from the run without the kill");
    assert_eq!(killed.metric("theta_max_abs_rad"), whole.metric("theta_max_abs_rad"));
    assert_eq!(killed.metric("current_at_limit_s"), whole.metric("current_at_limit_s"));
    // The controller's kill, before the restart, keeps the effect the first monitor saw.
    let (during, before) = (effect(&s.faults[0]), effect(&whole.summary().faults[0]));
    assert!(!during.unrecorded && during.error_peak_first_s.is_some(), "{during:?}");
    assert_eq!(
        (during.outage_ticks, during.commands_back_at_s, during.rejoined_at_s, during.error_peak_first_s),
        (before.outage_ticks, before.commands_back_at_s, before.rejoined_at_s, before.error_peak_first_s)
    );
    assert_clean(s);
}

/// Runs `looplab run` expecting the run to fail (exit 1); returns its summary.
fn run_failing(name: &str, args: &[&str]) -> Summary {
    let dir = fresh_dir(name);
    let output = looplab().arg("run").args(args).arg("-q").arg("--out").arg(&dir).output().unwrap();
    assert_eq!(output.status.code(), Some(1), "{}", String::from_utf8_lossy(&output.stderr));
    let s = load_summary(&dir);
    assert_clean(&s);
    std::fs::remove_dir_all(&dir).unwrap();
    s
}

#[test]
fn a_process_that_may_not_restart_ends_the_run_and_a_lockstep_stall_is_reported_not_hung() {
    let s = run_failing(
        "never",
        &["--mode", "lockstep", "--duration", "3", "--fault", "kill controller at 1s"]
            .into_iter()
            .chain(["--set", "supervision.controller.restart=never"])
            .collect::<Vec<_>>(),
    );
    let why = failure(&s);
    assert!(why.contains("controller exited with status signal 9; not restarted (restart = never)"), "{why}");

    let s = run_failing(
        "stall",
        &["--mode", "lockstep", "--duration", "3", "--fault", "stop estimator at 1s for 3s"]
            .into_iter()
            .chain(["--set", "supervision.lockstep_stall_s=0.3"])
            .collect::<Vec<_>>(),
    );
    let why = failure(&s);
    assert!(why.contains("the loop stalled at loop 1000"), "{why}");
    assert_eq!(s.faults[0].detected_by, Some(DetectedBy::InputDeadline));
}

/// Why a failed run stopped.
fn failure(s: &Summary) -> &str {
    match &s.stopped_because {
        Some(StopReason::Failed(why)) => why,
        other => panic!("not a failure: {other:?}"),
    }
}

#[test]
fn bad_faults_name_the_key_and_what_is_allowed() {
    let cases = [
        (
            vec!["--fault", "explode plant at 1s"],
            "unknown fault kind \"explode\"; allowed: kill, stop, delay, drop, corrupt, cut",
        ),
        (
            vec!["--fault", "delay plant by 3 ticks"],
            "key `faults.0.process`: a delay fault cannot target \"plant\"; allowed: sensors, estimator, controller",
        ),
        (vec!["--fault", "stop sensors at 1s"], "key `faults.0.duration_s`: a stop needs the seconds it lasts"),
        (vec!["--fault", "kill plant at 20s"], "key `faults.0.at_s`: must be a time within the run"),
        (vec!["--set", "supervision.restart=sometimes"], "key `supervision.restart`"),
        (
            vec!["--fault", "cut bridge at 1s for 300ms"],
            "key `faults.0.kind`: a cut needs a link, and no stage is placed on another host (hosts.<stage> = \"<host>\"); \
             allowed without one: kill, stop, delay, drop, corrupt",
        ),
    ];
    for (args, expected) in cases {
        let output = looplab().arg("run").args(&args).output().unwrap();
        assert_eq!(output.status.code(), Some(2), "{args:?}");
        let stderr = String::from_utf8_lossy(&output.stderr);
        assert!(stderr.contains(expected), "{args:?}: {stderr}");
        assert_eq!(stderr.lines().count(), 1, "one line: {stderr}");
    }
}

#[test]
fn the_measured_delay_margin_agrees_with_the_linearised_loop() {
    let dir = fresh_dir("sweep");
    let output = looplab()
        .args([
            "sweep",
            "pendulum",
            "--duration",
            "20",
            "--param",
            "faults.0.delay_ticks",
            "--from",
            "29",
            "--to",
            "32",
        ])
        .args(["--set", "sensors.encoder.quantum=0", "--set", "sensors.wheel_speed.noise_std=0"])
        .args(["--fault", "delay controller by 0 ticks at 2s", "--out"])
        .arg(&dir)
        .output()
        .unwrap();
    assert!(output.status.success(), "{}", String::from_utf8_lossy(&output.stderr));
    let report: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.join("sweep.json")).unwrap()).unwrap();
    let theory = report["theory"]["ticks"].as_u64().unwrap();
    let measured = report["first_unstable"].as_f64().unwrap() as u64;
    assert_eq!(theory, 31, "{}", report["theory"]);
    assert!(measured.abs_diff(theory) <= 1, "measured {measured}, theory {theory}");
    let verdicts: Vec<&str> =
        report["points"].as_array().unwrap().iter().map(|p| p["verdict"].as_str().unwrap()).collect();
    assert_eq!(verdicts[..2], ["stable", "stable"], "{verdicts:?}");
    assert_eq!(verdicts[3], "unstable", "{verdicts:?}");
    let stdout = String::from_utf8_lossy(&output.stdout);
    assert!(stdout.contains("agree within one tick"), "{stdout}");
    std::fs::remove_dir_all(&dir).unwrap();
}

/// A sweep's report without what differs from one sweep to the next: the run folders.
fn sweep_report(dir: &std::path::Path) -> serde_json::Value {
    let mut report: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.join("sweep.json")).unwrap()).unwrap();
    for point in report["points"].as_array_mut().unwrap() {
        point.as_object_mut().unwrap().remove("run_dir");
    }
    report
}

#[test]
fn a_sweep_as_five_processes_reports_what_the_in_process_sweep_reports() {
    let sweep = |name: &str, extra: &[&str]| {
        let dir = fresh_dir(name);
        let output = looplab()
            .args(["sweep", "pendulum", "--duration", "30", "--param", "faults.0.delay_ticks", "--from", "30"])
            .args(["--to", "31", "--set", "sensors.encoder.quantum=0", "--set", "sensors.wheel_speed.noise_std=0"])
            .args(["--fault", "delay controller by 0 ticks at 2s"])
            .args(extra)
            .arg("--out")
            .arg(&dir)
            .output()
            .unwrap();
        assert!(output.status.success(), "{}", String::from_utf8_lossy(&output.stderr));
        let report = sweep_report(&dir);
        std::fs::remove_dir_all(&dir).unwrap();
        (report, String::from_utf8(output.stdout).unwrap())
    };
    let (processes, processes_table) = sweep("sweep-processes", &["--processes"]);
    let (in_process, in_process_table) = sweep("sweep-in-process", &[]);
    let verdicts: Vec<&str> =
        processes["points"].as_array().unwrap().iter().map(|p| p["verdict"].as_str().unwrap()).collect();
    assert_eq!(verdicts, ["stable", "unstable"]);
    assert_eq!(processes, in_process);
    assert_eq!(processes_table, in_process_table);
}

/// A stop longer than the run ends with it: continued at the run's end, not at its time, and the
/// summary says so. Real time: the run's duration has passed; lockstep: a plant stopped past
/// `lockstep_stall_s` has stalled the loop, as any stopped stage would.
#[test]
fn a_stop_longer_than_the_run_is_cut_short_by_its_end() {
    let stop = "stop plant at 0.1s for 100s";
    let r = run("long-stop", &["pendulum", "--duration", "0.5", "--fault", stop]);
    let s = r.summary();
    assert!(s.completed && s.loops == 500, "{:?}", s.stopped_because);
    let f = &s.faults[0];
    assert!(f.continued_at_run_end, "{f:?}");
    // Continued before the stop's own end (at 100.1 s after tick 0): by the run's end.
    let continued_ms = f.injected_at_ms.unwrap() + f.continued_after_ms.unwrap();
    assert!(continued_ms < (f.at_s + 100.0) * 1e3, "continued {continued_ms} ms after tick 0: {f:?}");
    assert!(
        s.timeline.iter().any(|e| e.event == "SIGCONT plant, before its time: the run is over"),
        "{:?}",
        s.timeline
    );
    assert_clean(s);

    let s = run_failing(
        "long-stop-lockstep",
        &["--mode", "lockstep", "--duration", "0.5", "--fault", stop, "--set", "supervision.lockstep_stall_s=0.3"],
    );
    let why = failure(&s);
    assert!(why.starts_with("the loop stalled at loop 100: the plant was stopped for longer than 0.3 s"), "{why}");
    let f = &s.faults[0];
    assert!(f.continued_at_run_end, "{f:?}");
    assert!(f.continued_after_ms.unwrap() < 100e3, "{f:?}");
}
