//! A controller stage of one's own in C (liblooplab_stage.so, services/examples/c) and in Rust
//! (services/examples/controller/rust), run by the real launcher as the controller of the five
//! processes over real shared memory: the pendulum's built-in law ported, byte-identical to the
//! built-in controller's run in lockstep; a C step's error ends the run with its code named.
//! The C programs are compiled here with the machine's `cc`.

use crate::common;

use std::path::{Path, PathBuf};
use std::process::Command;
use std::sync::OnceLock;

use common::*;

const REPO: &str = env!("CARGO_MANIFEST_DIR");
const OTHER_GAINS: &str = "controller.gains=[-420.0, -61.5, -1.25]";

/// Compiles one C program against the library into its own fresh folder; returns the program.
pub(crate) fn compile_c(name: &str, source: &Path) -> PathBuf {
    let lib = built();
    let dir = fresh_dir(name);
    std::fs::create_dir_all(&dir).unwrap();
    let exe = dir.join(name);
    // -ffp-contract=off: no fused multiply-add, the built-in's arithmetic to the bit.
    let output = Command::new("cc")
        .args(["-O2", "-std=c11", "-ffp-contract=off", "-Wall", "-Wextra", "-Werror", "-I"])
        .arg(lib)
        .arg(source)
        .arg("-L")
        .arg(lib)
        .arg("-llooplab_stage")
        .arg(format!("-Wl,-rpath,{}", lib.display()))
        .arg("-o")
        .arg(&exe)
        .output()
        .expect("run cc");
    assert!(output.status.success(), "cc {} failed:\n{}", source.display(), String::from_utf8_lossy(&output.stderr));
    exe
}

/// The C example, compiled once.
fn c_controller() -> &'static Path {
    static EXE: OnceLock<PathBuf> = OnceLock::new();
    EXE.get_or_init(|| {
        compile_c("pendulum_controller", &Path::new(REPO).join("services/examples/controller/pendulum_controller.c"))
    })
}

/// `--set stages.controller.command=["<program>"]`.
fn controller_command(program: &Path) -> String {
    format!("stages.controller.command=[{:?}]", program.display().to_string())
}

/// trajectory.csv of a lockstep run of `target` with `sets`; no file of the run may be left.
fn trajectory(name: &str, target: &str, sets: &[String]) -> Vec<u8> {
    let mut args = vec![target, "--mode", "lockstep", "--duration", "3"];
    for set in sets {
        args.extend(["--set", set]);
    }
    let r = run(name, &args);
    assert_nothing_left(r.summary());
    assert_eq!(r.summary().processes.len(), 5, "{:?}", r.summary().processes);
    std::fs::read(r.dir.join("trajectory.csv")).expect("trajectory.csv")
}

/// The user's controller (the launch file `launch` with `program` as its command) against the
/// built-in one, with the default gains and with others.
fn assert_byte_identical_to_the_builtin(name: &str, launch: &str, program: &Path) {
    let launch = Path::new(REPO).join(launch).display().to_string();
    let mut builtins = Vec::new();
    for gains in [vec![], vec![OTHER_GAINS.to_owned()]] {
        let builtin = trajectory(&format!("{name}-builtin"), "pendulum", &gains);
        let own = trajectory(name, &launch, &[gains.clone(), vec![controller_command(program)]].concat());
        assert!(builtin == own, "{name} with {gains:?}: trajectory.csv differs from the built-in controller's");
        builtins.push(builtin);
    }
    // Otherwise the identity could hold for gains that nobody reads.
    assert!(builtins[0] != builtins[1], "other gains gave the same trajectory");
}

#[test]
fn a_c_controller_gives_the_builtin_controllers_trajectory_to_the_byte() {
    assert_byte_identical_to_the_builtin(
        "c-controller",
        "services/examples/controller/pendulum_c.toml",
        c_controller(),
    );
}

#[test]
fn a_rust_controller_crate_gives_the_builtin_controllers_trajectory_to_the_byte() {
    let program = built().join("looplab-example-controller");
    assert_byte_identical_to_the_builtin(
        "rust-controller",
        "services/examples/controller/rust/pendulum_rust.toml",
        &program,
    );
}

/// The launch file as written, run from another folder into a relative run folder: the stage
/// starts in the launch file's folder and still finds the run's files.
#[test]
fn a_launch_file_of_ones_own_runs_from_any_folder_into_a_relative_run_folder() {
    built();
    let here = fresh_dir("relative-out");
    std::fs::create_dir_all(&here).unwrap();
    let launch = Path::new(REPO).join("services/examples/controller/rust/pendulum_rust.toml");
    let output = looplab()
        .current_dir(&here)
        .arg("run")
        .arg(&launch)
        .args(["--mode", "lockstep", "--duration", "0.5", "-q", "--out", "run"])
        .output()
        .expect("start looplab");
    assert!(output.status.success(), "{}", String::from_utf8_lossy(&output.stderr));
    let s = load_summary(&here.join("run"));
    assert!(s.completed, "{:?}", s.stopped_because);
    assert_nothing_left(&s);
    std::fs::remove_dir_all(&here).unwrap();
}

#[test]
fn a_c_step_that_returns_an_error_ends_the_run_and_names_its_code() {
    let dir = fresh_dir("c-step-error");
    std::fs::create_dir_all(&dir).unwrap();
    let source = dir.join("failing_step.c");
    std::fs::write(
        &source,
        r#"#include "looplab_stage.h"
static int step(void *user, double t, const double *in, size_t n_in, double *out, size_t n_out) {
    (void)user, (void)in, (void)n_in, (void)out, (void)n_out;
    return t >= 1.0 ? 7 : 0;
}
int main(void) { return looplab_run(step, 0); }
"#,
    )
    .unwrap();
    let program = compile_c("failing_step", &source);
    let out = dir.join("run");
    let launch = Path::new(REPO).join("services/examples/controller/pendulum_c.toml");
    let output = looplab()
        .arg("run")
        .arg(&launch)
        .args(["--mode", "lockstep", "--duration", "3", "--set", "supervision.controller.max_restarts=2"])
        .args(["--set", &controller_command(&program), "-q", "--out"])
        .arg(&out)
        .output()
        .expect("start looplab");
    let said = format!("{}{}", String::from_utf8_lossy(&output.stdout), String::from_utf8_lossy(&output.stderr));
    assert_eq!(output.status.code(), Some(1), "{said}");
    let s = load_summary(&out);
    let Some(StopReason::Failed(why)) = &s.stopped_because else { panic!("not a failure: {:?}", s.stopped_because) };
    assert!(why.contains("step returned 7"), "the failure does not name the code: {why}\n{said}");
    // The restart policy applied: each successor took over loop 1000 (lockstep keeps the input a
    // stage was handling) and failed on it again, until the restarts ran out.
    assert_eq!(s.restarts[&Role::Controller], 2, "{said}");
    let log = std::fs::read_to_string(out.join("logs/controller.log")).expect("logs/controller.log");
    assert_eq!(log.matches("step failed at t = 1.000000 s: step returned 7").count(), 3, "{log}");
    assert_nothing_left(&s);
    std::fs::remove_dir_all(&dir).unwrap();
}

/// The C example's law with a count of its steps kept across a restart (freeze and thaw).
const COUNTING_CONTROLLER: &str = r#"#include <stdio.h>
#include <string.h>
#include "looplab_stage.h"
struct law { double gains[3], limit; unsigned long long steps; };
static int step(void *user, double t, const double *x, size_t n_x, double *u, size_t n_u) {
    (void)t, (void)n_x, (void)n_u;
    struct law *k = user;
    k->steps++;
    double current = -(k->gains[0] * x[0] + k->gains[1] * x[1] + k->gains[2] * x[2]);
    u[0] = current < -k->limit ? -k->limit : current > k->limit ? k->limit : current;
    return 0;
}
static size_t freeze(void *user, uint8_t *buf, size_t cap) {
    const struct law *k = user;
    if (cap < sizeof k->steps) return 0;
    memcpy(buf, &k->steps, sizeof k->steps);
    return sizeof k->steps;
}
static int thaw(void *user, const uint8_t *buf, size_t len) {
    struct law *k = user;
    if (len != sizeof k->steps) return 3;
    memcpy(&k->steps, buf, len);
    fprintf(stderr, "thawed after %llu steps\n", k->steps);
    return 0;
}
int main(void) {
    struct law k = {.steps = 0};
    if (looplab_config_f64("controller.gains.0", &k.gains[0]) || looplab_config_f64("controller.gains.1", &k.gains[1])
        || looplab_config_f64("controller.gains.2", &k.gains[2]) || looplab_config_f64("model.current_limit_a", &k.limit))
        return 2;
    return looplab_run_with_state(step, freeze, thaw, &k);
}
"#;

#[test]
fn a_killed_c_controller_gets_its_frozen_state_back_and_the_run_matches_the_builtins() {
    let dir = fresh_dir("c-freeze");
    std::fs::create_dir_all(&dir).unwrap();
    let source = dir.join("counting_controller.c");
    std::fs::write(&source, COUNTING_CONTROLLER).unwrap();
    let program = compile_c("counting_controller", &source);
    let kill = "kill controller at 1s";
    let args = |launch: &str| {
        vec![
            launch.to_owned(),
            "--mode".into(),
            "lockstep".into(),
            "--duration".into(),
            "2".into(),
            "--fault".into(),
            kill.into(),
        ]
    };
    let builtin = run("c-freeze-builtin", &args("pendulum").iter().map(String::as_str).collect::<Vec<_>>());
    let launch = Path::new(REPO).join("services/examples/controller/pendulum_c.toml").display().to_string();
    let command = controller_command(&program);
    let own_args = [args(&launch), vec!["--set".into(), command]].concat();
    let own = run("c-freeze", &own_args.iter().map(String::as_str).collect::<Vec<_>>());
    let incarnations = own.summary().processes.iter().filter(|p| p.name == Role::Controller).count();
    assert_eq!(incarnations, 2, "the controller was killed once and restarted: {:?}", own.summary().processes);
    let log = std::fs::read_to_string(own.dir.join("logs/controller.log")).expect("logs/controller.log");
    assert!(log.contains("thawed after 1000 steps"), "the restarted controller did not get its count back: {log}");
    let trajectory = |r: &Run| std::fs::read(r.dir.join("trajectory.csv")).expect("trajectory.csv");
    assert!(trajectory(&builtin) == trajectory(&own), "trajectory.csv differs from the built-in's with the same kill");
    assert_nothing_left(own.summary());
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn the_c_header_compiles_on_its_own_under_strict_warnings() {
    let dir = fresh_dir("c-header");
    std::fs::create_dir_all(&dir).unwrap();
    let source = dir.join("header.c");
    std::fs::write(
        &source,
        "#include \"looplab_stage.h\"\nint main(void) { return LOOPLAB_MAX_FROZEN_BYTES != 65536; }\n",
    )
    .unwrap();
    let output = Command::new("cc")
        .args(["-Wall", "-Wextra", "-Werror", "-pedantic", "-std=c11", "-fsyntax-only", "-I"])
        .arg(built())
        .arg(&source)
        .output()
        .expect("run cc");
    assert!(output.status.success(), "{}", String::from_utf8_lossy(&output.stderr));
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn a_stage_is_built_before_its_run_and_again_only_when_what_its_build_names_changed() {
    let lib = built().display().to_string();
    let dir = fresh_dir("c-build");
    std::fs::create_dir_all(&dir).unwrap();
    let source =
        std::fs::read_to_string(Path::new(REPO).join("services/examples/controller/pendulum_controller.c")).unwrap();
    std::fs::write(dir.join("ctl.c"), &source).unwrap();
    let launch = dir.join("ctl.toml");
    std::fs::write(
        &launch,
        format!(
            "scenario = \"pendulum\"\n\n[stages.controller]\nbuild = [\"cc\", \"-O2\", \"-std=c11\", \
             \"-ffp-contract=off\", \"-I\", {lib:?}, \"ctl.c\", \"-L\", {lib:?}, \"-llooplab_stage\", \
             \"-Wl,-rpath,{lib}\", \"-o\", \"ctl\"]\ncommand = [\"./ctl\"]\n"
        ),
    )
    .unwrap();
    // Its own stamps, so that another test's (or an earlier run's) cannot say "unchanged".
    let cache = dir.join("cache");
    let run_it = |name: &str| {
        let out = dir.join(name);
        let output = looplab()
            .env("XDG_CACHE_HOME", &cache)
            .arg("run")
            .arg(&launch)
            .args(["--mode", "lockstep", "--duration", "1", "-q", "--out"])
            .arg(&out)
            .output()
            .expect("start looplab");
        (output, out)
    };
    let built_line = "controller: built with `cc -O2";
    let stderr = |output: &std::process::Output| String::from_utf8_lossy(&output.stderr).into_owned();

    let (first, out) = run_it("first");
    assert!(first.status.success() && stderr(&first).contains(built_line), "{}", stderr(&first));
    let builtin = run("c-build-builtin", &["pendulum", "--mode", "lockstep", "--duration", "1"]);
    let trajectory = |dir: &Path| std::fs::read(dir.join("trajectory.csv")).expect("trajectory.csv");
    assert!(trajectory(&out) == trajectory(&builtin.dir), "the program built is not the built-in law");
    assert_nothing_left(&load_summary(&out));

    let (second, _) = run_it("second");
    assert!(second.status.success(), "{}", stderr(&second));
    assert!(!stderr(&second).contains("built with"), "built again with nothing changed: {}", stderr(&second));

    std::fs::write(dir.join("ctl.c"), format!("{source}\n/* changed */\n")).unwrap();
    let (third, _) = run_it("third");
    assert!(third.status.success() && stderr(&third).contains(built_line), "not built again: {}", stderr(&third));

    // A build that fails is bad input: one line with the compiler's last one, exit 2, no run.
    std::fs::write(dir.join("ctl.c"), format!("#error this controller does not compile\n{source}")).unwrap();
    let (fourth, out) = run_it("fourth");
    let said = stderr(&fourth);
    assert_eq!(fourth.status.code(), Some(2), "{said}");
    assert_eq!(said.lines().count(), 1, "{said}");
    assert!(said.contains("stages.controller.build") && said.contains("this controller does not compile"), "{said}");
    assert!(!out.exists(), "a failed build must not create the run folder");
    std::fs::remove_dir_all(&dir).unwrap();
}
