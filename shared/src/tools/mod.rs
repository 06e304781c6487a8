//! Layer 7, the tools built on the launcher: `looplab sweep`, `looplab bench`, `looplab export`,
//! `looplab compare`, and the figures (`plot`).

pub mod bench;
pub mod compare;
pub mod export;
pub mod plot;
pub mod sweep;

use std::path::Path;

/// Why a tool (export, plot, compare) did not do its job.
#[derive(Debug)]
pub enum ToolError {
    /// A folder that is not there or not a run folder, a bad option (exit code 2).
    BadInput(String),
    /// Reading or writing failed.
    Failed(anyhow::Error),
}

impl From<anyhow::Error> for ToolError {
    fn from(e: anyhow::Error) -> Self {
        ToolError::Failed(e)
    }
}

/// The files of a finished run folder that export and plot read.
pub const RUN_FILES: [&str; 4] = ["launch.toml", "trajectory.csv", "loops.csv", "summary.json"];

/// A bad-input error for `dir` unless it is a folder holding each of `files`.
pub fn check_run_folder(dir: &Path, files: &[&str]) -> Result<(), ToolError> {
    let bad = |why: String| Err(ToolError::BadInput(format!("{}: {why}", dir.display())));
    if !dir.is_dir() {
        return bad(if dir.exists() { "not a folder".into() } else { "no such run folder".into() });
    }
    match files.iter().find(|name| !dir.join(name).is_file()) {
        Some(missing) => bad(format!("not a run folder (it has no {missing})")),
        None => Ok(()),
    }
}
