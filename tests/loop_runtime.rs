//! The loop as processes: start-up without loss, the summary contract, determinism, isolation of
//! concurrent runs, and clean shutdown on signals and on a dead process.

use crate::common;

use std::time::{Duration, Instant};

use common::{
    Exit, Mode, Role, StopReason, Summary, Table, alive, assert_loops_csv_integers, assert_nothing_left, fresh_dir,
    last_incarnations, load_summary, looplab, run,
};

const STATS_FIELDS: [&str; 8] = ["count", "min", "p50", "p90", "p99", "p999", "max", "mean"];
const HOPS: [&str; 7] = [
    "plant_to_sensors",
    "sensors_compute",
    "sensors_to_estimator",
    "estimator_compute",
    "estimator_to_controller",
    "controller_compute",
    "controller_to_plant",
];

fn assert_no_files_left(run_id: &str) {
    let left = looplab_shared::runtime::storage::run_storage::files_of_run(run_id);
    assert!(left.is_empty(), "files of run {run_id} left behind: {left:?}");
}

fn assert_processes_gone(summary: &Summary) {
    assert_eq!(summary.processes.len(), 5);
    for p in &summary.processes {
        assert!(!alive(i64::from(p.pid)), "{} (pid {}) is still running", p.name, p.pid);
        assert_ne!(p.exit, Exit::Running);
    }
}

#[test]
fn realtime_run_writes_the_summary_contract_and_records_every_loop_it_got() {
    let r = run("realtime", &["pendulum", "--duration", "2"]);
    // The keys scripts rely on, null or not: the typed summary below would read a missing
    // optional one as None.
    let json = &r.summary;
    for key in ["scenario", "mode", "rate_hz", "duration_s", "seed", "loops", "deadline_misses", "processes", "metrics"]
    {
        assert!(json.get(key).is_some(), "summary.json has no {key}");
    }
    for field in STATS_FIELDS {
        assert!(json["latency_ns"]["end_to_end"].get(field).is_some(), "end_to_end has no {field}");
        assert!(json["jitter_ns"]["plant_tick"].get(field).is_some(), "plant_tick jitter has no {field}");
    }
    let s = r.summary();
    assert_eq!(s.scenario, "pendulum");
    assert_eq!(s.mode, Mode::Realtime);
    assert_eq!(s.rate_hz, 1000.0);
    assert_eq!(s.loops, 2000);
    assert!(s.completed);
    let names: Vec<Role> = s.processes.iter().map(|p| p.name).collect();
    for name in Role::ALL {
        assert!(names.contains(&name), "no process {name} in {names:?}");
    }
    for p in &s.processes {
        assert!(p.pid > 0);
        assert_eq!(p.exit, Exit::Status(0), "{p:?}");
    }

    let records = s.monitor.records;
    let published = s.loops - s.skipped_ticks;
    assert_eq!(records + s.monitor.lost + s.loops_without_command, published, "nothing lost silently");
    let e2e = &s.latency_ns.end_to_end;
    assert_eq!(e2e.count, records);
    let (min, p50, p99, max) = (e2e.min.unwrap(), e2e.p50.unwrap(), e2e.p99.unwrap(), e2e.max.unwrap());
    assert!(0 < min && min <= p50 && p50 <= p99 && p99 <= max, "{e2e:?}");
    let mut hop_sum = 0.0;
    for hop in HOPS {
        let h = s.latency_ns.hops.get(hop).unwrap_or_else(|| panic!("no hop {hop}"));
        assert_eq!(h.count, records, "hop {hop}");
        hop_sum += h.mean.unwrap();
    }
    // The hops partition each loop, so their means add up to the end-to-end mean.
    let e2e_mean = e2e.mean.unwrap();
    assert!((hop_sum - e2e_mean).abs() < 1.0, "hops {hop_sum} vs e2e {e2e_mean}");
    // One period per published state after the first.
    assert_eq!(s.jitter_ns.plant_tick.count + 1, s.monitor.received["state"]);
    assert!(s.shared_memory.clean);
    assert_processes_gone(s);
    assert_no_files_left(&s.run_id);

    // The run folder.
    for file in ["summary.json", "trajectory.csv", "loops.csv", "latency.hlog", "launch.toml"] {
        assert!(r.dir.join(file).is_file(), "no {file} in the run folder");
    }
    let resolved = std::fs::read_to_string(r.dir.join("launch.toml")).unwrap();
    assert!(resolved.contains("duration_s = 2.0"), "the resolved launch file has the override");
    let loops = Table::read(&r.dir.join("loops.csv"));
    // One row per loop seen (a skipped tick after the last published state has none).
    let rows = assert_loops_csv_integers(&r.dir) as u64;
    assert_eq!(rows, loops.rows.len() as u64);
    assert!(published <= rows && rows <= s.loops, "{rows} rows");
    let trajectory = r.trajectory();
    for column in [
        "t_s",
        "theta_rad",
        "theta_dot_rad_per_s",
        "wheel_speed_rad_per_s",
        "meas.encoder_rad",
        "meas.wheel_speed_rad_per_s",
        "est.bias_rad",
        "cmd.current_A",
    ] {
        assert!(trajectory.columns.contains_key(column), "trajectory.csv has no {column}");
    }

    // latency.hlog is a standard HdrHistogram interval log holding every end-to-end sample,
    // tagged end_to_end and again untagged (what the reference tools read by default).
    let hlog = std::fs::read(r.dir.join("latency.hlog")).unwrap();
    let (mut e2e_count, mut untagged_count) = (0, 0);
    for entry in hdrhistogram::serialization::interval_log::IntervalLogIterator::new(&hlog) {
        if let Ok(hdrhistogram::serialization::interval_log::LogEntry::Interval(h)) = entry {
            let bytes = base64_decode(h.encoded_histogram());
            let hist: hdrhistogram::Histogram<u64> =
                hdrhistogram::serialization::Deserializer::new().deserialize(&mut bytes.as_slice()).unwrap();
            match h.tag().map(|t| t.as_str()) {
                Some("end_to_end") => e2e_count += hist.len(),
                None => untagged_count += hist.len(),
                Some(_) => {}
            }
        }
    }
    assert_eq!(e2e_count, records);
    assert_eq!(untagged_count, records);
}

/// Standard base64, as the interval log writes it.
fn base64_decode(text: &str) -> Vec<u8> {
    const ALPHABET: &[u8] = b"ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
    let mut out = Vec::new();
    let (mut acc, mut bits) = (0u32, 0);
    for c in text.bytes().filter(|c| *c != b'=') {
        acc = (acc << 6) | ALPHABET.iter().position(|a| *a == c).expect("base64") as u32;
        bits += 6;
        if bits >= 8 {
            bits -= 8;
            out.push((acc >> bits) as u8);
        }
    }
    out
}

#[test]
fn lockstep_records_loop_zero_and_every_loop_after_it() {
    let r = run("lockstep-all", &["pendulum", "--mode", "lockstep", "--duration", "3"]);
    let s = r.summary();
    assert_eq!(s.loops, 3000);
    assert_eq!(s.monitor.records, 3000);
    assert_eq!(s.monitor.lost, 0);
    assert_eq!(s.monitor.missing.ranges.len(), 0);
    assert_eq!(s.deadline_misses, 0);
    let loops = Table::read(&r.dir.join("loops.csv"));
    assert_eq!(loops.col("k")[0], 0.0);
    // Loop 0 has every stamp, in the order the data passed.
    let stamps: Vec<f64> = [
        "plant_publish_ns",
        "sensors_receive_ns",
        "sensors_publish_ns",
        "estimator_receive_ns",
        "estimator_publish_ns",
        "controller_receive_ns",
        "controller_publish_ns",
        "plant_receive_ns",
    ]
    .iter()
    .map(|c| loops.col(c)[0])
    .collect();
    assert!(stamps[0] > 0.0 && stamps.windows(2).all(|w| w[0] <= w[1]), "{stamps:?}");
    assert!(s.loops_per_s > 0.0);
}

/// A run so short that the plant is gone microseconds after it starts: the monitor must still
/// have every loop, because every reader connects before the loop starts.
#[test]
fn very_short_runs_record_every_loop() {
    for _ in 0..8 {
        let r = run("very-short", &["pendulum", "--mode", "lockstep", "--duration", "0.005"]);
        let s = r.summary();
        assert_eq!(s.loops, 5);
        assert_eq!(s.monitor.records, 5, "{:?}", s.monitor);
        for topic in ["state", "measurements", "estimate", "command", "loop"] {
            assert_eq!(s.monitor.received.get(topic), Some(&5), "{topic}: {:?}", s.monitor);
        }
    }
}

#[test]
fn lockstep_runs_are_deterministic_and_concurrent_runs_are_isolated() {
    let args = |seed: &'static str| {
        ["pendulum", "--mode", "lockstep", "--duration", "3", "--set", "sensors.encoder.noise_std=0.001", "--set", seed]
    };
    let (a, b) = std::thread::scope(|scope| {
        let a = scope.spawn(|| run("determinism-a", &args("seed=42")));
        let b = scope.spawn(|| run("determinism-b", &args("seed=42")));
        (a.join().unwrap(), b.join().unwrap())
    });
    assert_ne!(a.summary().run_id, b.summary().run_id);
    for r in [&a, &b] {
        assert_eq!(r.summary().monitor.records, 3000, "a concurrent run must not see the other's messages");
        assert_eq!(r.summary().monitor.received.get("state"), Some(&3000));
    }
    let trajectory = |r: &common::Run| std::fs::read(r.dir.join("trajectory.csv")).unwrap();
    assert!(trajectory(&a) == trajectory(&b), "two lockstep runs with one seed differ");

    let other_seed = run("determinism-c", &args("seed=43"));
    assert!(trajectory(&a) != trajectory(&other_seed), "the seed should change the noise");
}

#[test]
fn a_launch_file_path_runs() {
    let dir = fresh_dir("launch-file");
    std::fs::create_dir_all(&dir).unwrap();
    let file = dir.join("short.toml");
    std::fs::write(
        &file,
        "scenario = \"pendulum\"\nmode = \"lockstep\"\nduration_s = 0.5\n[sensors.encoder]\nbias = 0.02\n",
    )
    .unwrap();
    let r = run("launch-file-run", &[file.to_str().unwrap()]);
    assert_eq!(r.summary().loops, 500);
    assert_eq!(r.metric("bias_true_rad"), 0.02);
    std::fs::remove_dir_all(&dir).unwrap();
}

/// Starts a long real-time run and returns it with its run folder once the loop is running.
fn start_long_run(name: &str, extra: &[&str]) -> (std::process::Child, std::path::PathBuf) {
    let dir = fresh_dir(name);
    let child = looplab()
        .args(["run", "pendulum", "--duration", "60", "-q"])
        .args(extra)
        .arg("--out")
        .arg(&dir)
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    // The loop is running once the monitor has written loop rows (it flushes as it goes).
    let until = Instant::now() + Duration::from_secs(30);
    while std::fs::metadata(dir.join("loops.csv")).map_or(0, |m| m.len()) < 100_000 {
        assert!(Instant::now() < until, "the run did not start");
        std::thread::sleep(Duration::from_millis(50));
    }
    (child, dir)
}

fn wait_exit(mut child: std::process::Child) -> std::process::ExitStatus {
    let until = Instant::now() + Duration::from_secs(60);
    loop {
        if let Some(status) = child.try_wait().unwrap() {
            return status;
        }
        assert!(Instant::now() < until, "looplab did not stop");
        std::thread::sleep(Duration::from_millis(20));
    }
}

#[test]
fn sigint_sigterm_and_sighup_stop_the_run_cleanly_with_a_report() {
    // SIGHUP: the terminal the run was started from closed.
    for (signal, name) in [(libc::SIGINT, "sigint"), (libc::SIGTERM, "sigterm"), (libc::SIGHUP, "sighup")] {
        let (child, dir) = start_long_run(name, &[]);
        unsafe { libc::kill(child.id() as i32, signal) };
        let status = wait_exit(child);
        assert_eq!(status.code(), Some(130), "{name}: exit status");
        let s = load_summary(&dir);
        assert!(!s.completed);
        assert_eq!(s.stopped_because, Some(StopReason::Interrupted));
        assert!(s.loops > 0);
        assert!(s.shared_memory.clean, "{name}: {:?}", s.shared_memory);
        for p in &s.processes {
            assert_eq!(p.exit, Exit::Status(0), "{name}: every process exits cleanly: {p:?}");
        }
        assert_processes_gone(&s);
        assert_no_files_left(&s.run_id);
        std::fs::remove_dir_all(&dir).unwrap();
    }
}

/// The launcher's children: (role name, pid, command line); the role is read off the binary's
/// name, `looplab-<role>` (the kernel's `comm` cuts it at 15 bytes).
fn children_of(launcher: u32) -> Vec<(String, i32, String)> {
    std::fs::read_to_string(format!("/proc/{launcher}/task/{launcher}/children"))
        .unwrap()
        .split_whitespace()
        .map(|pid| pid.parse::<i32>().unwrap())
        .filter_map(|pid| {
            let cmdline = std::fs::read_to_string(format!("/proc/{pid}/cmdline")).ok()?.replace('\0', " ");
            let binary = std::path::Path::new(cmdline.split(' ').next()?).file_name()?.to_str()?.to_owned();
            Some((binary.strip_prefix("looplab-").unwrap_or(&binary).to_owned(), pid, cmdline))
        })
        .collect()
}

#[test]
fn a_killed_process_is_reported_and_its_shared_memory_removed() {
    let (child, dir) = start_long_run("killed", &["--set", "supervision.restart=never"]);
    let estimator = children_of(child.id())
        .into_iter()
        .find(|(name, _, _)| name == Role::Estimator.name())
        .expect("the estimator runs")
        .1;
    unsafe { libc::kill(estimator, libc::SIGKILL) };
    let status = wait_exit(child);
    assert_eq!(status.code(), Some(1));
    let s = load_summary(&dir);
    let Some(StopReason::Failed(why)) = &s.stopped_because else { panic!("not a failure: {:?}", s.stopped_because) };
    assert!(why.contains("estimator exited with status signal 9"), "{why}");
    assert!(s.shared_memory.clean, "{:?}", s.shared_memory);
    assert_processes_gone(&s);
    assert_no_files_left(&s.run_id);
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn a_killed_launcher_leaves_no_process_and_no_file_behind() {
    let (launcher, dir) = start_long_run("launcher-killed", &[]);
    let children = children_of(launcher.id());
    assert_eq!(children.len(), 5, "{children:?}");
    let cmdline = &children[0].2;
    let run_id = cmdline.split_whitespace().skip_while(|a| *a != "--run-id").nth(1).expect("--run-id").to_owned();
    unsafe { libc::kill(launcher.id() as i32, libc::SIGKILL) };
    wait_exit(launcher);
    let until = Instant::now() + Duration::from_secs(20);
    while children.iter().any(|(_, pid, _)| alive(i64::from(*pid))) {
        assert!(Instant::now() < until, "children outlived the launcher: {children:?}");
        std::thread::sleep(Duration::from_millis(20));
    }
    assert_no_files_left(&run_id);
    std::fs::remove_dir_all(&dir).unwrap();
}

/// The run id from a loop process's command line.
fn run_id_of(children: &[(String, i32, String)]) -> String {
    let cmdline = &children[0].2;
    cmdline.split_whitespace().skip_while(|a| *a != "--run-id").nth(1).expect("--run-id").to_owned()
}

#[test]
fn a_run_killed_all_at_once_is_removed_by_looplab_clean_with_its_frozen_orphan() {
    let (launcher, dir) = start_long_run("all-killed", &[]);
    let children = children_of(launcher.id());
    assert_eq!(children.len(), 5, "{children:?}");
    let run_id = run_id_of(&children);
    // The monitor frozen (it cannot act on the launcher's death), everything else killed at once:
    // nobody is left to tidy up.
    let monitor = children.iter().find(|(name, _, _)| name == Role::Monitor.name()).expect("the monitor runs").1;
    unsafe { libc::kill(monitor, libc::SIGSTOP) };
    unsafe { libc::kill(launcher.id() as i32, libc::SIGKILL) };
    for (_, pid, _) in children.iter().filter(|(_, pid, _)| *pid != monitor) {
        unsafe { libc::kill(*pid, libc::SIGKILL) };
    }
    wait_exit(launcher);
    let until = Instant::now() + Duration::from_secs(20);
    while children.iter().any(|(_, pid, _)| *pid != monitor && alive(i64::from(*pid))) {
        assert!(Instant::now() < until, "killed children still alive: {children:?}");
        std::thread::sleep(Duration::from_millis(20));
    }
    // Nobody is left to tidy up. `looplab clean` removes the run, unless the start of another
    // test's run (which cleans abandoned runs too) got to it first.
    let output = looplab().arg("clean").output().unwrap();
    let stderr = String::from_utf8_lossy(&output.stderr);
    assert!(output.status.success(), "looplab clean: {stderr}");
    let until = Instant::now() + Duration::from_secs(20);
    while alive(i64::from(monitor)) {
        assert!(Instant::now() < until, "looplab clean left the orphaned monitor running: {stderr}");
        std::thread::sleep(Duration::from_millis(20));
    }
    assert_no_files_left(&run_id);
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn a_second_stop_request_kills_what_is_left_and_still_cleans_up() {
    let (child, dir) = start_long_run("second-sigint", &[]);
    let children = children_of(child.id());
    let run_id = run_id_of(&children);
    // A frozen controller cannot act on SIGTERM until it is continued; the second Ctrl-C must
    // not wait for it.
    let controller =
        children.iter().find(|(name, _, _)| name == Role::Controller.name()).expect("the controller runs").1;
    unsafe { libc::kill(controller, libc::SIGSTOP) };
    // Two different signals, so that neither is merged into the other while pending.
    unsafe { libc::kill(child.id() as i32, libc::SIGINT) };
    unsafe { libc::kill(child.id() as i32, libc::SIGTERM) };
    let status = wait_exit(child);
    assert_eq!(status.code(), Some(130));
    let s = load_summary(&dir);
    assert_eq!(s.stopped_because, Some(StopReason::Interrupted));
    for p in &s.processes {
        assert_eq!(p.exit, Exit::Signal(9), "every process is killed, none asked: {p:?}");
    }
    assert_processes_gone(&s);
    assert_no_files_left(&run_id);
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn a_plant_killed_at_the_last_tick_still_makes_a_complete_run() {
    // The plant dies after publishing one of the last ticks, and its successor starts after the
    // run's end: no tick may count twice, and the run completed.
    let r = run("kill-last-tick", &["--duration", "2", "--fault", "kill plant at 1.999"]);
    let s = r.summary();
    assert!(s.completed, "{:?}", s.stopped_because);
    assert_eq!(s.loops, 2000);
    assert_eq!(s.restarts[&Role::Plant], 1);
}

/// Another user plants an entry named like a run's in /dev/shm: the run's clean-up reports it as
/// foreign and leaves it, and the run is still clean (it is not the run's, and a user who is not
/// root could not remove it anyway).
#[test]
#[cfg_attr(netns_unavailable, ignore = "needs root, to plant a file as another user")]
fn an_entry_another_user_planted_with_a_runs_name_is_reported_not_fatal() {
    use looplab_shared::runtime::storage::run_storage::{clean_up_run, create_run_storage, file_prefix};
    let run_id = looplab_shared::launcher::run_dir::new_run_id();
    let lock = create_run_storage(&run_id).unwrap();
    let planted = std::path::Path::new("/dev/shm").join(format!("{}planted", file_prefix(&run_id)));
    std::fs::write(&planted, b"junk").unwrap();
    let path = std::ffi::CString::new(planted.display().to_string()).unwrap();
    // SAFETY: chown of the file this test just made, to the user nobody.
    assert_eq!(unsafe { libc::chown(path.as_ptr(), 65534, 65534) }, 0);
    let cleanup = clean_up_run(&run_id).unwrap();
    assert_eq!(cleanup.leftover, Vec::<String>::new(), "the run's own files are gone");
    assert_eq!(cleanup.foreign, vec![planted.display().to_string()]);
    assert!(planted.exists(), "another user's file is left where it is");
    std::fs::remove_file(&planted).unwrap();
    drop(lock);
}

/// The newest loop the monitor has written to `loops.csv` so far.
fn newest_loop(dir: &std::path::Path) -> u64 {
    let text = std::fs::read_to_string(dir.join("loops.csv")).unwrap_or_default();
    let whole = &text[..text.rfind('\n').unwrap_or(0)];
    whole.rsplit('\n').next().and_then(|line| line.split(',').next()?.parse().ok()).unwrap_or(0)
}

/// Waits until the monitor has written loop `k`; `what` says what it means if it never does.
fn wait_for_loop(dir: &std::path::Path, k: u64, what: &str) {
    let until = Instant::now() + Duration::from_secs(60);
    while newest_loop(dir) < k {
        assert!(Instant::now() < until, "{what}");
        std::thread::sleep(Duration::from_millis(20));
    }
}

/// A real-time pendulum run of `duration` with one `fault`, its report and errors piped.
fn spawn_faulted_run(name: &str, duration: &str, fault: &str) -> (std::process::Child, std::path::PathBuf) {
    let dir = fresh_dir(name);
    let child = looplab()
        .args(["run", "pendulum", "--duration", duration, "-q", "--fault", fault, "--out"])
        .arg(&dir)
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    (child, dir)
}

/// A launcher stopped (SIGSTOP) past a kill's time injects it late: the timeline says the
/// launcher did not run, and the report says by how much the fault was late.
#[test]
fn a_stopped_launcher_says_it_fell_behind_and_which_fault_went_late() {
    let (child, dir) = spawn_faulted_run("launcher-stopped", "4", "kill controller at 2.5s");
    let launcher = child.id() as i32;
    // Stopped as soon as the loop runs: the monitor, at nice 19, may write its rows seconds
    // behind the loop on a busy machine, so neither a later row nor its pace is a clock here.
    wait_for_loop(&dir, 1, "the run did not start");
    unsafe { libc::kill(launcher, libc::SIGSTOP) };
    // Stopped for 3 s of the real-time schedule, which began before loop 1 was written: the kill
    // due at 2.5 s after tick 0 comes at least 0.5 s late. (The time stopped is what is tested.)
    std::thread::sleep(Duration::from_secs(3));
    unsafe { libc::kill(launcher, libc::SIGCONT) };
    let output = child.wait_with_output().unwrap();
    let report = String::from_utf8_lossy(&output.stdout);
    assert!(output.status.success(), "{report}");
    let s = load_summary(&dir);
    assert!(s.timeline.iter().any(|e| e.event.starts_with("the launcher did not run for ")), "{:?}", s.timeline);
    let late = s.faults[0].injected_at_ms.expect("injected once the launcher went on") - 2500.0;
    assert!(late >= 500.0, "injected {late} ms late");
    assert!(report.contains("note: `kill controller at 2.5s` was injected "), "{report}");
    std::fs::remove_dir_all(&dir).unwrap();
}

/// The run folder removed mid-run, then a kill: the restart is impossible (no folder for its log)
/// and the summary cannot be written; the error names both, the first one first.
#[test]
fn a_removed_run_folder_does_not_hide_why_the_run_failed() {
    let (child, dir) = spawn_faulted_run("folder-removed", "3", "kill controller at 1.5s");
    // Removed as soon as the loop runs (the monitor's rows may lag the loop by seconds).
    wait_for_loop(&dir, 1, "the run did not start");
    std::fs::remove_dir_all(&dir).unwrap();
    let output = child.wait_with_output().unwrap();
    assert_eq!(output.status.code(), Some(1));
    let said = String::from_utf8_lossy(&output.stderr);
    let why = said.lines().find(|l| l.starts_with("error: ")).unwrap_or_else(|| panic!("no error line: {said}"));
    assert!(why.starts_with("error: controller could not be restarted: "), "{why}");
    assert!(why.contains("; and cannot write ") && why.contains("summary.json"), "{why}");
    assert!(String::from_utf8_lossy(&output.stdout).contains("latency (µs)"), "the report is still printed");
}

/// A run folder on a disk that fills up: the monitor stops once with "disk full" and is not
/// restarted into it, the loop runs to its end, and the error names the file that could not be
/// written; the report is still printed. Root only (it mounts a small tmpfs).
#[test]
#[cfg_attr(netns_unavailable, ignore = "needs root, to mount a small file system")]
fn a_full_disk_stops_the_monitor_once_and_the_error_names_the_file() {
    let disk = fresh_dir("full-disk");
    std::fs::create_dir_all(&disk).unwrap();
    let mounted = std::process::Command::new("mount")
        .args(["-t", "tmpfs", "-o", "size=256k", "tmpfs"])
        .arg(&disk)
        .status()
        .unwrap();
    assert!(mounted.success(), "mount a 256 KiB tmpfs");
    let out = disk.join("run");
    let output = looplab().args(["run", "pendulum", "--duration", "3", "-q", "--out"]).arg(&out).output().unwrap();
    let umounted = std::process::Command::new("umount").arg(&disk).status().unwrap();
    let said = String::from_utf8_lossy(&output.stderr).into_owned();
    let report = String::from_utf8_lossy(&output.stdout).into_owned();
    assert!(umounted.success());
    std::fs::remove_dir_all(&disk).unwrap();
    assert_eq!(output.status.code(), Some(1), "{said}");
    assert!(said.starts_with("error: monitor exited with status 3 (its disk is full)"), "{said}");
    assert!(said.contains(&format!("cannot write {}: No space left on device", out.join("summary.json").display())));
    assert!(report.contains(", exit 3, "), "the report is printed, with the monitor's exit: {report}");
    assert!(!report.contains("monitor restart 1"), "{report}");
}

/// `[realtime]` as root: each loop process runs at SCHED_FIFO 10 with its memory locked, as the
/// kernel reports it once the process is ready; the monitor keeps its normal low priority.
#[test]
#[cfg_attr(netns_unavailable, ignore = "needs root, for a real-time priority")]
fn real_time_priority_and_locked_memory_are_applied_and_read_back() {
    let sets = ["realtime.priority=10", "realtime.mlock=true", "wait.lockstep=\"block\""];
    let mut args = vec!["pendulum", "--mode", "lockstep", "--duration", "0.2"];
    args.extend(sets.iter().flat_map(|s| ["--set", s]));
    let run = run("realtime", &args);
    let last = last_incarnations(run.summary());
    for role in Role::LOOP {
        let scheduling = last[&role].scheduling.as_ref().unwrap_or_else(|| panic!("{role}: none read back"));
        assert_eq!((scheduling.policy.as_str(), scheduling.priority), ("fifo", 10), "{role}");
        assert!(scheduling.locked_kib > 0, "{role}: nothing locked");
    }
    assert_eq!(last[&Role::Monitor].scheduling, None);
    let report = String::from_utf8_lossy(&run.output.stdout);
    assert!(report.contains("real time, as the kernel reports it: plant fifo 10, "), "{report}");
    assert_nothing_left(run.summary());
}

/// Without CAP_SYS_NICE and with no real-time limit, a priority is refused before anything
/// starts: one line naming the file and the key, exit 2, no run folder.
#[test]
#[cfg_attr(netns_unavailable, ignore = "needs root, to drop a capability")]
fn a_real_time_priority_without_permission_is_refused_before_the_run() {
    let dir = fresh_dir("realtime-refused");
    let output = std::process::Command::new("prlimit")
        .args(["--rtprio=0", "setpriv", "--inh-caps=-sys_nice", "--bounding-set=-sys_nice"])
        .arg(env!("CARGO_BIN_EXE_looplab"))
        .args(["run", "pendulum", "--duration", "0.2", "--set", "realtime.priority=20", "--out"])
        .arg(&dir)
        .env_remove("CARGO")
        .env_remove("CARGO_MANIFEST_DIR")
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&output.stderr);
    assert_eq!(output.status.code(), Some(2), "{stderr}");
    assert_eq!(stderr.lines().count(), 1, "{stderr}");
    assert!(stderr.contains("--set realtime.priority=20: key `realtime.priority`"), "{stderr}");
    assert!(stderr.contains("CAP_SYS_NICE") && stderr.contains("now 0"), "{stderr}");
    assert!(!dir.exists(), "no run folder for a refused run");
}
