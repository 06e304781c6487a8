//! The bench's controllers of the user's own: the pendulum's law as a Python stage (the
//! `looplab` module) and as a C stage (`liblooplab_stage.so`), from `services/examples/`, run in
//! the same loop as the built-in controller. A language whose stage cannot be prepared here (no
//! module installed, no C compiler, no examples beside this build) is skipped and says why.

use std::fmt::Write as _;
use std::path::{Path, PathBuf};

use super::LoopBench;

/// A controller stage of the user's own, in one language.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum OwnController {
    Python,
    C,
}

/// The examples of this source tree (the bench is a developer's tool: it runs from a checkout).
fn examples() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../services/examples")
}

impl OwnController {
    /// The `stages.controller.command` override that runs it, or why it cannot run here. The C
    /// stage is compiled into `out` against the library and header beside the launcher.
    pub fn command_override(self, out: &Path) -> Result<String, String> {
        let command = match self {
            OwnController::Python => {
                let script = examples().join("controller/pendulum_controller.py");
                if !script.is_file() {
                    return Err(format!("{} is missing", script.display()));
                }
                vec!["python3".to_owned(), script.display().to_string()]
            }
            OwnController::C => vec![compile_c(out)?.display().to_string()],
        };
        let quoted: Vec<String> = command.iter().map(|c| format!("{c:?}")).collect();
        Ok(format!("stages.controller.command=[{}]", quoted.join(",")))
    }
}

/// Compiles the C example into `out`, linked to `liblooplab_stage.so` beside this executable.
fn compile_c(out: &Path) -> Result<PathBuf, String> {
    let exe = std::env::current_exe().map_err(|e| e.to_string())?;
    let lib = exe.parent().ok_or("the launcher has no folder")?.to_path_buf();
    if !lib.join("liblooplab_stage.so").is_file() || !lib.join("looplab_stage.h").is_file() {
        return Err(format!("no liblooplab_stage.so and looplab_stage.h in {} (cargo build --release)", lib.display()));
    }
    let source = examples().join("controller/pendulum_controller.c");
    let binary = out.join("pendulum_controller_c");
    let status = std::process::Command::new("cc")
        .args(["-O2", "-ffp-contract=off", "-o"])
        .arg(&binary)
        .arg(&source)
        .arg(format!("-I{}", lib.display()))
        .arg(format!("-L{}", lib.display()))
        .arg(format!("-Wl,-rpath,{}", lib.display()))
        .arg("-llooplab_stage")
        .status()
        .map_err(|e| format!("cannot run cc: {e}"))?;
    if !status.success() {
        return Err(format!("cc {} failed ({status})", source.display()));
    }
    Ok(binary)
}

/// The table of the controllers side by side: the controller's compute (receive to publish) and
/// end to end, against the built-in controller's run (`builtin`) of the same bench.
pub fn render(s: &mut String, builtin: &str, loops: &[LoopBench], names: &[&str]) {
    let Some(base) = loops.iter().find(|l| l.name == builtin) else { return };
    let rows: Vec<&LoopBench> =
        std::iter::once(base).chain(names.iter().filter_map(|name| loops.iter().find(|l| l.name == *name))).collect();
    if rows.len() < 2 {
        return;
    }
    let _ = writeln!(s, "\n  your own controller, 1 kHz, block (µs): the controller's compute and end to end");
    let _ = writeln!(
        s,
        "    {:<36}{:>9}{:>9}{:>10}{:>9}{:>9}{:>10}",
        "configuration", "ctl p50", "ctl p99", "Δ p50", "e2e p50", "e2e p99", "Δ p50"
    );
    for l in rows {
        let (c, e) = (&l.controller_compute_us, &l.end_to_end_us);
        let _ = writeln!(
            s,
            "    {:<36}{:>9.2}{:>9.2}{:>+10.2}{:>9.1}{:>9.1}{:>+10.1}",
            l.name,
            c.p50,
            c.p99,
            c.p50 - base.controller_compute_us.p50,
            e.p50,
            e.p99,
            e.p50 - base.end_to_end_us.p50
        );
    }
}
