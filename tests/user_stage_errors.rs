//! A stage of the user's own that cannot run: a command that never connects, a missing program
//! or script, a stage built with other message layouts. Each is one clear line and the right
//! exit code, and nothing of the run is left: no process, no shared-memory file.
//!
//! This file has its own `main` (Cargo.toml: `harness = false`): started by the launcher as a
//! stage (LOOPLAB_ROLE is set), it plays a controller from another LoopLab build, one whose
//! message layouts have another fingerprint.

mod common;

use std::path::Path;
use std::process::Output;

use common::{Exit, fresh_dir, load_summary, looplab};

/// The fingerprint the stage from "another build" claims.
const OTHER_LAYOUT: &str = "0123456789abcdef";

fn main() -> std::process::ExitCode {
    if std::env::var_os("LOOPLAB_ROLE").is_some() {
        return looplab_shared::runtime::stage::user_stage::run_step_as_build(OTHER_LAYOUT, |_| {
            Ok(Box::new(NeverSteps))
        });
    }
    let tests: [(&str, fn()); 5] = [
        ("every_port_refuses_a_service_made_with_other_layouts_naming_both", port_refuses_other_layouts),
        ("a_command_that_never_connects_fails_after_the_ready_timeout_naming_it", never_connects),
        ("a_missing_program_or_script_is_bad_input_and_nothing_starts", missing_program_or_script),
        ("a_stage_built_with_other_message_layouts_is_refused_at_connect", other_layouts),
        ("a_stage_program_started_by_hand_says_how_it_is_started", started_by_hand),
    ];
    let mut failed = 0;
    for (name, test) in tests {
        let passed = std::panic::catch_unwind(test).is_ok();
        println!("test {name} ... {}", if passed { "ok" } else { "FAILED" });
        failed += usize::from(!passed);
    }
    println!(
        "\ntest result: {}. {} passed; {failed} failed",
        if failed == 0 { "ok" } else { "FAILED" },
        tests.len() - failed
    );
    if failed == 0 { std::process::ExitCode::SUCCESS } else { std::process::ExitCode::FAILURE }
}

/// The stage from another build: it is refused before its first loop.
struct NeverSteps;

impl looplab_shared::runtime::stage::user_stage::Step for NeverSteps {
    fn step(&mut self, _t: f64, _input: &[f64], _output: &mut [f64]) -> anyhow::Result<()> {
        anyhow::bail!("a stage from another build never gets its input")
    }
}

fn run_pendulum(name: &str, args: &[&str]) -> (Output, std::path::PathBuf) {
    let dir = fresh_dir(name);
    let output = looplab()
        .args(["run", "pendulum", "--mode", "lockstep", "--duration", "1"])
        .args(args)
        .arg("--out")
        .arg(&dir)
        .arg("-q")
        .output()
        .expect("start looplab");
    (output, dir)
}

fn stderr(output: &Output) -> String {
    String::from_utf8_lossy(&output.stderr).into_owned()
}

/// The run ended: every process gone, no shared-memory file of it left.
fn assert_run_left_nothing(dir: &Path) {
    common::assert_nothing_left(&load_summary(dir));
    let _ = std::fs::remove_dir_all(dir);
}

fn never_connects() {
    let (output, dir) = run_pendulum(
        "never-connects",
        &["--set", r#"stages.controller.command=["sleep","100"]"#, "--set", "supervision.ready_timeout_s=1"],
    );
    assert_eq!(output.status.code(), Some(1), "{}", stderr(&output));
    let said = stderr(&output);
    assert_eq!(said.lines().count(), 1, "one line: {said}");
    let folder = std::env::current_dir().unwrap();
    assert_eq!(
        said.trim_end(),
        format!(
            "error: not ready after 1 s (supervision.ready_timeout_s): controller: the command `sleep 100` (started \
             in {}) never said ready; it must hand its step to LoopLab's runner (looplab.run, looplab_run, \
             run_step); its stderr is in logs/controller.log",
            folder.display()
        )
    );
    let controller =
        load_summary(&dir).processes.into_iter().find(|p| p.name == common::Role::Controller).expect("a controller");
    assert_eq!(controller.exit, Exit::Signal(libc::SIGTERM), "the launcher stopped it");
    assert_run_left_nothing(&dir);
}

fn missing_program_or_script() {
    let cases = [
        (r#"stages.controller.command=["no-such-python-ll","c.py"]"#, "program no-such-python-ll is not found on PATH"),
        (r#"stages.estimator.command=["sh","no_such_estimator.py"]"#, "script no_such_estimator.py is not found in "),
    ];
    for (set, why) in cases {
        let (output, dir) = run_pendulum("missing", &["--set", set]);
        assert_eq!(output.status.code(), Some(2), "{}", stderr(&output));
        let said = stderr(&output);
        let key = set.split('=').next().unwrap();
        let expected = format!("error: --set {set}: key `{key}`: {why}");
        assert!(said.starts_with(&expected) && said.lines().count() == 1, "{said}\nexpected: {expected}");
        assert!(!dir.exists(), "nothing started, no run folder");
    }
}

fn other_layouts() {
    let me = std::env::current_exe().unwrap();
    let set = format!("stages.controller.command=[\"{}\"]", me.display());
    let (output, dir) = run_pendulum("other-layouts", &["--set", &set]);
    assert_eq!(output.status.code(), Some(1), "{}", stderr(&output));
    let said = stderr(&output);
    let ours = looplab_shared::contract::msg::layout_fingerprint();
    let expected = format!(
        "error: controller exited with status 1 during start-up: controller: error: the launcher's messages have \
         layout fingerprint {ours}, this process was built with {OTHER_LAYOUT}: build it from the same LoopLab as \
         the launcher (the Python package: pip install ./services/python); see logs/controller.log"
    );
    assert_eq!(said.trim_end(), expected);
    assert_run_left_nothing(&dir);
}

fn started_by_hand() {
    let me = std::env::current_exe().unwrap();
    let output = std::process::Command::new(me).env("LOOPLAB_ROLE", "controller").output().unwrap();
    assert_eq!(output.status.code(), Some(2));
    assert_eq!(
        stderr(&output).trim_end(),
        "error: this program is a LoopLab stage (sensors, estimator, controller): start it from a launch file's \
         [stages.<role>] command with `looplab run`, which sets LOOPLAB_ROLE and the run's other variables"
    );
}

fn port_refuses_other_layouts() {
    use looplab_shared::contract::msg::{Command, layout_fingerprint};
    use looplab_shared::runtime::storage::run_storage::{clean_up_run, create_run_storage};
    use looplab_shared::runtime::transport::ipc::{Ipc, Topic};
    let run_id = looplab_shared::launcher::run_dir::new_run_id();
    let lock = create_run_storage(&run_id).unwrap();
    let refused = {
        let other = Ipc::with_layout("other", &run_id, common::Mode::Lockstep, OTHER_LAYOUT).unwrap();
        let _publisher =
            other.publisher::<Command>(Topic::Command, looplab_shared::runtime::transport::ipc::Wake::Never).unwrap();
        let ours = Ipc::new("ours", &run_id, common::Mode::Lockstep).unwrap();
        ours.stage_subscriber::<Command>(Topic::Command, false).err().expect("refused")
    };
    assert_eq!(
        refused.to_string(),
        format!(
            "the run's command messages have layout fingerprint {OTHER_LAYOUT}, this process was built with {}: \
             build it from the same LoopLab as the launcher (the Python package: pip install ./services/python)",
            layout_fingerprint()
        )
    );
    assert!(clean_up_run(&run_id).unwrap().leftover.is_empty());
    drop(lock);
}
