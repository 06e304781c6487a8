//! A recorded run read back: every message of every loop as the monitor received it, from the
//! run folder's `run.mcap` (and a restarted monitor's `run.<n>.mcap`). What `looplab replay`
//! plays back into a stage.
//!
//! The recording keeps every field a stage reads (`monitor::sinks::mcap`, `Detail::Live`): the
//! state and the input applied, each sensor's value, sample time, sequence number and fresh and
//! valid flags, the estimate, the command, each message's `lost` flag and each loop's
//! incarnations. Floats are written shortest-round-trip and read back bit for bit (a
//! non-finite value, which JSON cannot hold, comes back as NaN). Timing (the loop trace, the
//! plant's tick timing and counters) is not played back: a replay stamps its own.

use std::path::Path;

use anyhow::Result;

use crate::contract::msg::{Command, Estimate, LoopRecord, Measurements, PlantState};
use crate::model::layout::Layout;

/// One loop of a recording: each message the monitor received for it (None: none came).
/// Headers hold k, t, `lost` and the incarnations; the loop trace is zero.
#[derive(Debug, Clone, Copy, Default)]
pub struct RecordedLoop {
    pub state: Option<PlantState>,
    pub measurements: Option<Measurements>,
    pub estimate: Option<Estimate>,
    pub command: Option<Command>,
    pub record: Option<LoopRecord>,
}

/// Every loop of the run recorded in `run_dir` by its monitor(s), indexed by k, `loops` long
/// (the run's planned loops; a loop nobody recorded is all None). `layout` is the recording's
/// (from its own launch file). Fails with one line naming the file when the folder has no
/// `run.mcap`, when it was written by `looplab export` (no sample times or flags), or by a
/// version of LoopLab that did not record a field a stage reads.
pub fn load(run_dir: &Path, layout: &Layout, loops: u64) -> Result<Vec<RecordedLoop>> {
    let _ = (run_dir, layout, loops);
    todo!("read run.mcap and run.<n>.mcap")
}
