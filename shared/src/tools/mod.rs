//! Layer 7, the tools built on the launcher: `looplab sweep`, `looplab bench`, `looplab export`
//! (run.mcap; run.perfetto-trace: `perfetto`),
//! `looplab compare`, and the figures (`plot`).

use crate::contract::run_format::files;

pub mod bench;
pub mod compare;
pub mod diff;
pub mod export;
pub mod perfetto;
pub mod plot;
pub mod replay;
pub mod run_folder;
pub mod sweep;
pub mod twin;

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

impl std::fmt::Display for ToolError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            ToolError::BadInput(why) => f.write_str(why),
            ToolError::Failed(e) => write!(f, "{e:#}"),
        }
    }
}

impl std::error::Error for ToolError {}

/// The files of a finished run folder that export and plot read.
pub const RUN_FILES: [&str; 4] = [files::LAUNCH, files::TRAJECTORY, files::LOOPS, files::SUMMARY];
