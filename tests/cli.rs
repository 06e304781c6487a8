//! The command line: help, the scenario list, and bad input, which must give one clear error
//! naming the file and key, exit code 2, and leave nothing behind.

use crate::common;

use common::{fresh_dir, load_summary, looplab, png_size};

fn stdout_of(args: &[&str]) -> String {
    let out = looplab().args(args).output().unwrap();
    assert!(out.status.success(), "looplab {args:?}: {}", String::from_utf8_lossy(&out.stderr));
    String::from_utf8(out.stdout).unwrap()
}

#[test]
fn help_explains_the_commands_and_options() {
    let help = stdout_of(&["--help"]);
    for word in ["run", "list", "show", "Examples"] {
        assert!(help.contains(word), "--help lacks {word}:\n{help}");
    }
    let help = stdout_of(&["run", "--help"]);
    for word in ["--mode", "--duration", "--set", "--out", "realtime", "lockstep", "KEY=VALUE"] {
        assert!(help.contains(word), "run --help lacks {word}:\n{help}");
    }
}

#[test]
fn list_names_the_scenarios_and_show_prints_their_keys() {
    let list = stdout_of(&["list"]);
    assert!(list.contains("pendulum") && list.contains("launch/pendulum.toml"), "{list}");
    assert!(list.contains("[system]") && list.contains("launch/declared.toml"), "a system of your own: {list}");
    let show = stdout_of(&["show", "pendulum"]);
    assert_eq!(show, std::fs::read_to_string(concat!(env!("CARGO_MANIFEST_DIR"), "/launch/pendulum.toml")).unwrap());
}

/// Runs looplab with bad input; expects exit code 2, the given fragments in stderr, and no run
/// folder left behind.
fn rejects(args: &[&str], expected: &[&str]) {
    let out_dir = fresh_dir("rejected");
    let out = looplab().arg("run").args(args).arg("--out").arg(&out_dir).output().unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(2), "looplab run {args:?} should fail with 2:\n{stderr}");
    assert_eq!(stderr.lines().count(), 1, "one clear error line:\n{stderr}");
    for fragment in expected {
        assert!(stderr.contains(fragment), "error for {args:?} should contain {fragment:?}:\n{stderr}");
    }
    assert!(!out_dir.exists(), "bad input must not create the run folder");
}

#[test]
fn bad_input_is_one_clear_error_with_exit_code_2() {
    rejects(&["pendulm"], &["unknown scenario \"pendulm\"", "allowed: pendulum"]);
    // A control character in the input is shown escaped, never sent to the terminal.
    rejects(&["pendulum", "--set", "duration_s=1\u{1b}[2J"], &["--set duration_s=1\\u{1b}[2J: key `duration_s`"]);
    let escape = fresh_dir("escape");
    std::fs::create_dir_all(&escape).unwrap();
    let file = escape.join("launch.toml");
    std::fs::write(&file, "scenario = \"pendulum\"\n\"x\\u001b[31m\" = 1\n").unwrap();
    rejects(&[file.to_str().unwrap()], &["key `x\\u{1b}[31m`: unknown key"]);
    std::fs::remove_dir_all(&escape).unwrap();
    rejects(
        &["pendulum", "--set", "sensors.encoder.biass=1"],
        &["key `sensors.encoder.biass`", "unknown field", "`bias`"],
    );
    rejects(
        &["pendulum", "--set", "sensors.gyro.period_s=0.01"],
        &[
            "--set sensors.gyro.period_s=0.01",
            "key `sensors.gyro`",
            "has no `signal`: which one it measures; allowed: theta, wheel_speed",
        ],
    );
    rejects(&["pendulum", "--set", "estimator.kind=kalman"], &["key `estimator.kind`", "bias-observer", "no-bias"]);
    rejects(&["pendulum", "--rate", "0"], &["key `rate_hz`", "positive"]);
    rejects(&["pendulum", "--set", "rate_hz=-1000"], &["key `rate_hz`"]);
    rejects(
        &["pendulum", "--set", "sensors.wheel_speed.period_s=0.0025"],
        &["key `sensors.wheel_speed.period_s`", "multiple of the loop period"],
    );
    rejects(
        &["pendulum", "--set", "sensors.encoder.signal=height"],
        &["key `sensors.encoder.signal`", "theta, wheel_speed"],
    );
    rejects(&["pendulum", "--set", "controller.gains=[1, 2]"], &["key `controller.gains`"]);
    rejects(&["pendulum", "--set", "novalue"], &["expected KEY=VALUE"]);
}

#[test]
fn bad_launch_files_are_named_in_the_error() {
    let dir = fresh_dir("bad-files");
    std::fs::create_dir_all(&dir).unwrap();
    let write = |name: &str, text: &str| {
        let path = dir.join(name);
        std::fs::write(&path, text).unwrap();
        path.to_str().unwrap().to_owned()
    };
    let broken = write("broken.toml", "scenario = \"pendulum\"\nrate_hz = [\n");
    rejects(&[&broken], &[&broken, "not valid TOML: line 2, column"]);
    let unknown = write("unknown.toml", "scenario = \"rocket\"\n");
    rejects(&[&unknown], &[&unknown, "key `scenario`", "unknown scenario \"rocket\""]);
    let typo = write("typo.toml", "scenario = \"pendulum\"\n[plant.initial]\ntheta = 0.1\nomega = 2.0\n");
    rejects(&[&typo], &[&typo, "key `plant.initial.omega`"]);
    let missing = dir.join("absent.toml");
    rejects(&[missing.to_str().unwrap()], &["absent.toml", "cannot read"]);
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn a_missing_binary_is_named() {
    // A launcher alone in a folder, without its loop processes.
    let dir = fresh_dir("lonely");
    std::fs::create_dir_all(&dir).unwrap();
    let lonely = dir.join("looplab");
    std::fs::copy(env!("CARGO_BIN_EXE_looplab"), &lonely).unwrap();
    let out_dir = dir.join("out");
    // Another test thread forking while the copy was open for writing makes exec fail with
    // "text file busy" until that child has exec'd; try again.
    let out = (0..100)
        .find_map(|_| {
            let result = std::process::Command::new(&lonely)
                .env_remove("CARGO")
                .env_remove("CARGO_MANIFEST_DIR")
                .args(["run", "pendulum", "--out"])
                .arg(&out_dir)
                .output();
            match result {
                Err(e) if e.kind() == std::io::ErrorKind::ExecutableFileBusy => {
                    std::thread::sleep(std::time::Duration::from_millis(10));
                    None
                }
                other => Some(other.unwrap()),
            }
        })
        .expect("the copied launcher never became executable");
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(2), "{stderr}");
    assert!(
        stderr.contains("missing binary") && stderr.contains(&dir.join("looplab-monitor").display().to_string()),
        "{stderr}"
    );
    assert!(!out_dir.exists());
    std::fs::remove_dir_all(&dir).unwrap();
}

/// `looplab bench` end to end, as short as it goes: every part runs and reports (the numbers
/// themselves are the benchmark's business, not the test's), the charts are written, and
/// nothing is left in shared memory.
#[test]
fn bench_quick_writes_every_part() {
    let dir = fresh_dir("bench");
    let output = looplab().args(["bench", "--quick", "--seconds", "1", "--out"]).arg(&dir).output().unwrap();
    assert!(output.status.success(), "{}", String::from_utf8_lossy(&output.stderr));
    let report: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.join("bench.json")).unwrap()).unwrap();
    for mode in ["block", "spin", "adaptive"] {
        assert!(report["floor_one_way_us"][mode]["n"].as_u64().unwrap() >= 1000, "{mode}");
    }
    let names: Vec<&str> = report["loops"].as_array().unwrap().iter().map(|l| l["name"].as_str().unwrap()).collect();
    let skipped: Vec<&str> = report["skipped"].as_array().unwrap().iter().map(|s| s.as_str().unwrap()).collect();
    let cpus = report["machine"]["cpus"].as_u64().unwrap();
    for expected in [
        "looplab block",
        "looplab spin",
        "looplab spin, pinned",
        "looplab adaptive",
        "looplab adaptive, pinned",
        "looplab adaptive 10 kHz",
        "looplab adaptive, monitor stopped",
        "unix socket + bincode (hand-written)",
    ] {
        // Spinning needs a CPU per process of the loop; without them the part is named as skipped.
        let ran = names.contains(&expected);
        let said_skipped = skipped.iter().any(|s| s.starts_with(&format!("{expected}: needs 5 CPUs")));
        assert_eq!((ran, said_skipped), (cpus >= 5 || !expected.contains("spin"), !ran), "{expected}: {names:?}");
    }
    // A controller of one's own runs where its stage can be prepared (the C one is compiled
    // here; the Python one needs the `looplab` module installed), or is named as skipped, with why.
    for own in ["looplab block, Python controller", "looplab block, C controller"] {
        let ran = names.contains(&own);
        let said_skipped = skipped.iter().any(|s| s.starts_with(&format!("{own}: ")));
        assert!(ran != said_skipped, "{own}: ran {ran}, skipped {skipped:?}");
    }
    assert!(names.contains(&"looplab block, C controller"), "cc and liblooplab_stage.so are here: {skipped:?}");
    // The physical floor and the hop's anatomy (this machine has two CPUs at least).
    assert!(cpus >= 2);
    let raw = &report["floor_raw_one_way_ns"];
    assert!(raw["n"].as_u64().unwrap() >= 1000 && raw["p50"].as_f64().unwrap() > 0.0, "{raw}");
    assert!(report["physical_limit_us"].as_f64().unwrap() > 4.0 * raw["p50"].as_f64().unwrap() / 1e3);
    let anatomy = report["hop_anatomy"].as_array().unwrap();
    assert_eq!(anatomy.len(), 4);
    for row in anatomy {
        for step in ["deliver", "wake", "seen", "take", "copy", "release"] {
            assert!(row["steps_us"][step]["n"].as_u64().unwrap() >= 500, "{step}: {row}");
        }
    }
    let baseline = report["loops"]
        .as_array()
        .unwrap()
        .iter()
        .find(|l| l["name"] == "unix socket + bincode (hand-written)")
        .unwrap();
    assert_eq!(baseline["loops"], 1000);
    assert!(baseline["end_to_end_us"]["n"].as_u64().unwrap() >= 990);
    let sizes: Vec<u64> = report["payload"].as_array().unwrap().iter().map(|p| p["bytes"].as_u64().unwrap()).collect();
    assert_eq!(sizes, (0..9).map(|i| 64u64 << (2 * i)).collect::<Vec<_>>());
    let auto = report["lockstep_auto"].as_str().unwrap();
    assert_eq!(auto, if cpus >= 5 { "poll" } else { "handoff" });
    for method in ["poll", "handoff", "block"] {
        let rate = report["lockstep_by_method"][method].as_f64().unwrap();
        assert!(rate > 0.0 && rate < report["in_process_loops_per_s"].as_f64().unwrap(), "{method}: {rate}");
    }
    assert_eq!(report["lockstep_loops_per_s"], report["lockstep_by_method"][auto]);
    for chart in ["latency-cdf.png", "floor-cdf.png", "payload.png"] {
        // 900 wide; the CDFs' height grows with their legend's rows (one per curve).
        assert_eq!(png_size(&dir.join(chart)).0, 900, "{chart}");
    }
    let stdout = String::from_utf8_lossy(&output.stdout);
    assert!(stdout.contains("÷ limit") && stdout.contains("zero copy") && stdout.contains("hop anatomy"), "{stdout}");
    assert!(stdout.contains(&format!("{cpus} CPUs")), "{stdout}");
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn bad_wait_strategy_names_the_allowed_values() {
    let output = looplab().args(["run", "pendulum", "--set", "wait.strategy=fast"]).output().unwrap();
    assert_eq!(output.status.code(), Some(2));
    let stderr = String::from_utf8_lossy(&output.stderr);
    assert!(stderr.contains("key `wait.strategy`") && stderr.contains("`block`, `spin`, `adaptive`"), "{stderr}");
}

/// Inputs that once made a process panic, made the run's report vanish or hung: each is now
/// rejected at validation, before any process starts.
#[test]
fn out_of_range_and_non_finite_inputs_are_one_clear_error() {
    rejects(
        &["pendulum", "--fault", "stop controller at 1s for 1e19s"],
        &["--fault stop controller at 1s for 1e19s", "key `faults.0.duration_s`", "at most 3600"],
    );
    rejects(
        &["pendulum", "--fault", "delay controller by 1e20s at 1s"],
        &["key `faults.0.delay_s`", "less than the run's duration_s"],
    );
    rejects(
        &["pendulum", "--explain-over", "-5"],
        &["--set explain_over_us=-5.0", "key `explain_over_us`", "a positive number of µs"],
    );
    rejects(
        &["pendulum", "--set", "supervision.backoff_s=2e19"],
        &["--set supervision.backoff_s=2e19", "key `supervision.backoff_s`", "0 to 60 seconds"],
    );
    rejects(
        &["quadcopter", "--set", "supervision.lockstep_stall_s=1e20"],
        &["key `supervision.lockstep_stall_s`", "at most 3600"],
    );
    for (scenario, key) in [
        ("pendulum", "plant.initial.theta"),
        ("pendulum", "plant.initial.wheel_speed"),
        ("quadcopter", "plant.initial.position_m.2"),
        ("quadcopter", "plant.initial.rate_rad_s.0"),
    ] {
        for value in ["nan", "inf", "-inf"] {
            let set = format!("{key}={value}");
            rejects(&[scenario, "--set", &set], &[&format!("--set {set}"), &format!("key `{key}`"), "finite"]);
        }
    }
    rejects(&["pendulum", "--set", "model.m_p=nan"], &["key `model.m_p`", "finite"]);
    rejects(&["quadcopter", "--set", "model.inertia_kg_m2=[6e-3, nan, 1e-3]"], &["key `model.inertia_kg_m2.1`"]);

    let dir = fresh_dir("non-finite");
    std::fs::create_dir_all(&dir).unwrap();
    let file = dir.join("nan.toml");
    std::fs::write(&file, "scenario = \"pendulum\"\n[plant.initial]\ntheta = nan\n").unwrap();
    let file = file.to_str().unwrap();
    rejects(&[file], &[file, "key `plant.initial.theta`", "finite"]);
    std::fs::remove_dir_all(&dir).unwrap();
}

/// The tilt-rotor's own keys get the same one-line errors.
#[test]
fn bad_tiltrotor_keys_are_one_clear_error() {
    rejects(
        &["tiltrotor", "--set", "model.uncertainty_fraction=1.5"],
        &["key `model.uncertainty_fraction`", "below 1"],
    );
    rejects(&["tiltrotor", "--set", "controller.kind=nlls-3l"], &["key `controller.kind`", "nlls-2l", "nlpt-2l"]);
    rejects(
        &["tiltrotor", "--set", "metrics.d_hat_window_s=[10.0, 20.0]"],
        &["key `metrics.d_hat_window_s`", "disturbance is constant"],
    );
    rejects(
        &["tiltrotor", "--set", "sensors.velocity.period_s=0.2"],
        &["key `sensors.velocity.period_s`", "position sensor's period"],
    );
    rejects(&["tiltrotor", "--set", "reference.x_moves=[[1.0, 0.0, 2.0]]"], &["key `reference.x_moves.0.1`"]);
    rejects(&["tiltrotor", "--set", "plant.initial.load_rad=[2.0, 0.0]"], &["key `plant.initial.load_rad.0`"]);
    rejects(
        &["tiltrotor", "--set", "disturbance.pulses=[[1.0, -2.0, 0.0, 0.0, 1.0]]"],
        &["key `disturbance.pulses.0.1`"],
    );
    rejects(&["tiltrotor", "--set", "estimator.r_position_m=0"], &["key `estimator.r_position_m`", "positive"]);
    // Gains that destabilise their loop's design model (poles 3.63, −0.31 ± 0.42i).
    rejects(&["tiltrotor", "--set", "controller.xy_gains=[1.0, 2.0, 3.0]"], &["key `controller.xy_gains`", "Re s < 0"]);
    rejects(
        &["tiltrotor", "--set", "controller.swing_gains=[-1.0, 2.0]"],
        &["key `controller.swing_gains.0`", "positive"],
    );
}

/// A run with no --out goes to runs/<time>-<scenario>, and runs/latest points at the newest;
/// `looplab report` prints a finished run's report again, the same text the run printed.
#[test]
fn runs_latest_names_the_newest_run_and_report_reprints_it() {
    let dir = fresh_dir("latest");
    std::fs::create_dir_all(&dir).unwrap();
    let run = |seed: &str| {
        let out = looplab()
            .current_dir(&dir)
            .args(["run", "pendulum", "--mode", "lockstep", "--duration", "0.2", "--in-process", "-q", "--seed", seed])
            .output()
            .unwrap();
        assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
        String::from_utf8(out.stdout).unwrap()
    };
    let report_of = |target: &std::path::Path| {
        let out = looplab().current_dir(&dir).arg("report").arg(target).output().unwrap();
        assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
        String::from_utf8(out.stdout).unwrap()
    };
    let latest = std::path::Path::new("runs/latest");
    for seed in ["1", "2"] {
        let printed = run(seed);
        let target = std::fs::read_link(dir.join(latest)).unwrap();
        assert!(dir.join("runs").join(&target).join("summary.json").is_file(), "{target:?}");
        assert!(printed.contains(&format!("seed {seed}")), "{printed}");
        assert_eq!(report_of(latest), printed, "looplab report runs/latest after the run with seed {seed}");
    }
    let runs: Vec<_> = std::fs::read_dir(dir.join("runs")).unwrap().map(|e| e.unwrap().file_name()).collect();
    assert_eq!(runs.len(), 3, "two run folders and the link: {runs:?}");

    for (target, expected) in [("no-such-run", "no such run folder"), ("runs", "not a finished run folder")] {
        let out = looplab().current_dir(&dir).args(["report", target]).output().unwrap();
        let stderr = String::from_utf8_lossy(&out.stderr);
        assert_eq!(out.status.code(), Some(2), "{stderr}");
        assert_eq!(stderr.lines().count(), 1, "{stderr}");
        assert!(stderr.contains(target) && stderr.contains(expected), "{stderr}");
    }
    std::fs::remove_dir_all(&dir).unwrap();
}

/// Shell completions and the man page come from the same command definitions as --help.
#[test]
fn completions_and_the_man_page_describe_every_command() {
    let bash = stdout_of(&["completions", "bash"]);
    let check =
        std::process::Command::new("bash").args(["-n", "-c", &bash]).output().expect("bash checks the script's syntax");
    assert!(check.status.success(), "{}", String::from_utf8_lossy(&check.stderr));
    let man = stdout_of(&["man"]);
    assert!(man.contains(".TH looplab 1"), "{man}");
    for command in ["run", "list", "show", "sweep", "bench", "report", "clean", "completions"] {
        assert!(bash.contains(&format!("looplab__subcmd__{command}")), "bash completes {command}");
        assert!(man.contains(&format!("looplab\\-{command}")), "the man page lists {command}");
    }
    for shell in ["zsh", "fish"] {
        assert!(stdout_of(&["completions", shell]).contains("looplab"), "{shell}");
    }
}

#[test]
fn a_sweep_over_too_many_values_is_refused_before_any_run() {
    let output = looplab()
        .args(["sweep", "pendulum", "--param", "faults.0.delay_ticks", "--from", "0", "--to", "1e9"])
        .args(["--fault", "delay controller by 0 ticks at 2s"])
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&output.stderr);
    assert_eq!(output.status.code(), Some(2), "{stderr}");
    assert!(stderr.contains("at most 1000 are allowed"), "{stderr}");
}

#[test]
fn a_sweep_with_a_fault_done_from_outside_needs_processes() {
    let out_dir = fresh_dir("sweep-refused");
    let output = looplab()
        .args(["sweep", "pendulum", "--param", "duration_s", "--from", "3", "--to", "4"])
        .args(["--fault", "kill estimator at 1s", "--out"])
        .arg(&out_dir)
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&output.stderr);
    assert_eq!(output.status.code(), Some(2), "{stderr}");
    assert_eq!(stderr.lines().count(), 1, "{stderr}");
    assert!(stderr.contains("`kill estimator at 1s`") && stderr.contains("add --processes"), "{stderr}");
    assert!(!out_dir.exists(), "a refused sweep leaves no folder");
}

/// `--in-process` runs lockstep (without `--mode` it implies it) without kill or stop faults;
/// anything else is one line naming the option and why, exit 2, and no run folder.
#[test]
fn in_process_implies_lockstep_and_refuses_real_time_and_faults_done_from_outside() {
    let out_dir = fresh_dir("in-process-implies-lockstep");
    let output = looplab()
        .args(["run", "pendulum", "--duration", "0.05", "-q", "--in-process", "--out"])
        .arg(&out_dir)
        .output()
        .unwrap();
    assert_eq!(output.status.code(), Some(0), "{}", String::from_utf8_lossy(&output.stderr));
    assert_eq!(load_summary(&out_dir).mode, looplab_shared::config::launch::Mode::Lockstep);
    std::fs::remove_dir_all(&out_dir).unwrap();
    for (args, why) in [
        (&["pendulum", "--mode", "realtime"][..], "only lockstep runs in one process"),
        (&["pendulum", "--mode", "lockstep", "--fault", "stop controller at 1s for 100ms"][..], "`stop controller"),
        (&["pendulum", "--set", "realtime.mlock=true"][..], "[realtime]"),
        (&["pendulum", "--trace-sched"][..], "trace_sched names the processes"),
    ] {
        let out_dir = fresh_dir("in-process-refused");
        let output = looplab().arg("run").args(args).arg("--in-process").arg("--out").arg(&out_dir).output().unwrap();
        let stderr = String::from_utf8_lossy(&output.stderr);
        assert_eq!(output.status.code(), Some(2), "{stderr}");
        assert_eq!(stderr.lines().count(), 1, "{stderr}");
        assert!(stderr.starts_with("error: --in-process: ") && stderr.contains(why), "{stderr}");
        assert!(!out_dir.exists(), "a refused run leaves no folder");
    }
}

/// `looplab man` documents every subcommand, each on a page of its own after looplab(1).
#[test]
fn man_has_a_page_for_every_subcommand() {
    let man = looplab().arg("man").output().unwrap();
    assert!(man.status.success());
    let text = String::from_utf8_lossy(&man.stdout);
    let titles: Vec<&str> =
        text.lines().filter_map(|l| l.strip_prefix(".TH ")).map(|l| l.split(' ').next().unwrap()).collect();
    for page in ["looplab", "looplab-run", "looplab-sweep", "looplab-plot", "looplab-export", "looplab-bench"] {
        assert!(titles.contains(&page), "{page} missing: {titles:?}");
    }
    assert!(!titles.contains(&"looplab-help"), "{titles:?}");
    let run_page = &text[text.find(".TH looplab-run ").unwrap()..];
    assert!(run_page.contains("in\\-process"), "the run page has run's options");
}

/// Standard output whose reader has gone (`looplab show pendulum | head -1`, a closed terminal):
/// the text is lost, not the run, and nothing panics.
#[test]
fn a_closed_stdout_loses_the_text_not_the_run() {
    use std::os::fd::FromRawFd;
    let closed_pipe = || {
        let mut fds = [0; 2];
        // SAFETY: pipe writes two new descriptors into `fds`; the read end is closed at once.
        assert_eq!(unsafe { libc::pipe(fds.as_mut_ptr()) }, 0);
        unsafe { libc::close(fds[0]) };
        // SAFETY: the write end is ours alone from here on.
        std::process::Stdio::from(unsafe { std::os::fd::OwnedFd::from_raw_fd(fds[1]) })
    };
    for args in [&["show", "pendulum"][..], &["completions", "fish"], &["completions", "bash"], &["man"]] {
        let shown = looplab().args(args).stdout(closed_pipe()).output().unwrap();
        assert_eq!(shown.status.code(), Some(0), "{args:?}: {}", String::from_utf8_lossy(&shown.stderr));
    }
    let dir = fresh_dir("closed-stdout");
    let run = looplab()
        .args(["run", "pendulum", "--mode", "lockstep", "--duration", "0.2", "--out"])
        .arg(&dir)
        .stdout(closed_pipe())
        .output()
        .unwrap();
    let said = String::from_utf8_lossy(&run.stderr);
    assert_eq!(run.status.code(), Some(0), "{said}");
    assert!(!said.contains("panicked"), "{said}");
    assert!(load_summary(&dir).completed);
    std::fs::remove_dir_all(&dir).unwrap();
}

/// `--out` into a folder that another user could write in (or owns): refused before anything
/// starts, so no link planted there can make a run write through it.
#[test]
fn an_out_folder_others_can_write_in_is_refused() {
    use std::os::unix::fs::PermissionsExt;
    let dir = fresh_dir("shared-out");
    std::fs::create_dir_all(&dir).unwrap();
    std::fs::set_permissions(&dir, std::fs::Permissions::from_mode(0o777)).unwrap();
    let run = |dir: &std::path::Path| {
        looplab()
            .args(["run", "pendulum", "--mode", "lockstep", "--duration", "0.1", "-q", "--out"])
            .arg(dir)
            .output()
            .unwrap()
    };
    let output = run(&dir);
    assert_eq!(output.status.code(), Some(2));
    assert_eq!(
        String::from_utf8_lossy(&output.stderr).trim_end(),
        format!(
            "error: --out {}: others may write in the folder (mode 777); give a folder only you can write in",
            dir.display()
        )
    );
    assert_eq!(std::fs::read_dir(&dir).unwrap().count(), 0, "nothing written");
    // As root (CI), a folder another user owns.
    // SAFETY: geteuid and chown on our own fresh folder.
    if unsafe { libc::geteuid() } == 0 {
        std::fs::set_permissions(&dir, std::fs::Permissions::from_mode(0o755)).unwrap();
        let path = std::ffi::CString::new(dir.display().to_string()).unwrap();
        assert_eq!(unsafe { libc::chown(path.as_ptr(), 65534, 65534) }, 0);
        let output = run(&dir);
        assert_eq!(output.status.code(), Some(2));
        let said = String::from_utf8_lossy(&output.stderr);
        assert!(said.contains("the folder belongs to another user (uid 65534)"), "{said}");
    }
    std::fs::remove_dir_all(&dir).unwrap();

    // A new --out in a folder others may write in (no sticky bit): they could rename the run
    // folder mid-run and put a link in its place. Under a sticky one (as /tmp) it is fine.
    let open = fresh_dir("open-parent");
    std::fs::create_dir_all(&open).unwrap();
    std::fs::set_permissions(&open, std::fs::Permissions::from_mode(0o777)).unwrap();
    let output = run(&open.join("run"));
    assert_eq!(output.status.code(), Some(2));
    assert_eq!(
        String::from_utf8_lossy(&output.stderr).trim_end(),
        format!(
            "error: --out {}: {} is writable by others without the sticky bit (mode 777); another user could swap \
             the run folder for a link mid-run; give a folder under folders only you (or root) can write in",
            open.join("run").display(),
            open.display()
        )
    );
    assert!(!open.join("run").exists(), "nothing made");
    std::fs::set_permissions(&open, std::fs::Permissions::from_mode(0o1777)).unwrap();
    assert_eq!(run(&open.join("run")).status.code(), Some(0));
    std::fs::remove_dir_all(&open).unwrap();
}

/// Two runs given the same new --out at the same moment: one takes it, the other is refused and
/// writes nothing into it.
#[test]
fn two_runs_into_one_new_out_folder_one_takes_it_the_other_is_refused() {
    let dir = fresh_dir("claimed-out");
    for _ in 0..5 {
        let _ = std::fs::remove_dir_all(&dir);
        let start = || {
            looplab()
                .args(["run", "pendulum", "--mode", "lockstep", "--duration", "0.2", "-q", "--out"])
                .arg(&dir)
                .stderr(std::process::Stdio::piped())
                .spawn()
                .unwrap()
        };
        let (first, second) = (start(), start());
        let outputs = [first.wait_with_output().unwrap(), second.wait_with_output().unwrap()];
        let codes: Vec<Option<i32>> = outputs.iter().map(|o| o.status.code()).collect();
        let said: Vec<String> = outputs.iter().map(|o| String::from_utf8_lossy(&o.stderr).into_owned()).collect();
        assert!(codes.contains(&Some(0)) && codes.contains(&Some(2)), "{codes:?}: {said:?}");
        let refused = &said[codes.iter().position(|c| *c == Some(2)).unwrap()];
        let taken = format!("--out {}: another run took the folder as this one started", dir.display());
        let not_empty = format!("--out {}: the folder exists and is not empty", dir.display());
        assert!(refused.contains(&taken) || refused.contains(&not_empty), "{refused}");
        let s = load_summary(&dir);
        assert!(s.completed, "{:?}", s.stopped_because);
        assert_eq!(s.loops, 200);
    }
    std::fs::remove_dir_all(&dir).unwrap();
}

/// A bad value in a launch file is reported even where a `--set` (or an option) replaces it.
#[test]
fn a_bad_value_in_the_file_is_reported_even_when_set_on_the_command_line() {
    let dir = fresh_dir("bad-in-file");
    std::fs::create_dir_all(&dir).unwrap();
    let file = dir.join("bad.toml");
    std::fs::write(&file, "scenario = \"pendulum\"\nmode = 3.7\n").unwrap();
    let output = looplab().arg("run").arg(&file).args(["--mode", "realtime", "--duration", "0.1"]).output().unwrap();
    assert_eq!(output.status.code(), Some(2));
    let said = String::from_utf8_lossy(&output.stderr);
    assert!(said.starts_with(&format!("error: {}: key `mode`: ", file.display())), "{said}");
    std::fs::remove_dir_all(&dir).unwrap();
}

/// A launch file that is a FIFO or a device is refused in one line, exit 2, at once: not read
/// forever (`/dev/zero`) nor waited on (a FIFO with no writer).
#[test]
fn a_launch_file_that_is_a_fifo_or_a_device_is_refused_at_once() {
    let dir = fresh_dir("launch-fifo");
    std::fs::create_dir_all(&dir).unwrap();
    let fifo = dir.join("launch.toml");
    let name = std::ffi::CString::new(fifo.as_os_str().as_encoded_bytes()).unwrap();
    // SAFETY: a path of our own test folder.
    assert_eq!(unsafe { libc::mkfifo(name.as_ptr(), 0o600) }, 0);
    for target in [fifo.to_str().unwrap(), "/dev/zero"] {
        let output = looplab().args(["run", target]).output().unwrap();
        assert_eq!(output.status.code(), Some(2), "{target}");
        assert_eq!(
            String::from_utf8_lossy(&output.stderr),
            format!(
                "error: {target}: cannot read the launch file: it is not a regular file (a FIFO, a device or a folder)\n"
            )
        );
    }
    std::fs::remove_dir_all(&dir).unwrap();
}
