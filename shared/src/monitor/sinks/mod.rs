//! Where the joined loops go: each output of a run is a [`RunSink`]. A new output (an MCAP
//! recording, a live view) is one file in this folder and one line in [`open`].

pub mod hlog;
pub mod loops;
pub mod mcap;
pub mod text;
pub mod trajectory;

use std::fs::File;
use std::io::BufWriter;
use std::path::Path;

use anyhow::{Context as _, Result};
use serde::{Deserialize, Serialize};

use crate::config::launch::LaunchConfig;
use crate::contract::msg::TickTiming;
use crate::contract::report::MonitorReport;
use crate::model::layout::VectorLayout;
use crate::monitor::cause::Explanation;
use crate::monitor::join::LoopParts;
use crate::runtime::storage::run_file::{self, Existing};

/// What a sink is opened with.
pub struct SinkSetup<'a> {
    /// The run folder, where the files go.
    pub run_dir: &'a Path,
    /// A restarted monitor: append to what the last one wrote.
    pub restarted: bool,
    /// The run's launch file (its faults with their ticks, the rate, the seed).
    pub config: &'a LaunchConfig,
    pub layout: &'a VectorLayout,
    /// The run has a core to spare for the files (an in-process run): run.mcap's chunks are
    /// compressed on a thread of their own. The monitor process leaves the loop's processes theirs.
    pub spare_core: bool,
}

/// One loop as the recorder joined it. Loops come in order of k, each once; a restarted
/// monitor's first loop is past 0, and a part that never arrived is `None`.
pub struct JoinedLoop<'a> {
    pub k: u64,
    /// Simulation time of tick k.
    pub t: f64,
    pub parts: &'a LoopParts,
    /// Why it was late: a deadline miss (real time) or a loop over `explain_over_us`.
    pub cause: Option<Explanation>,
}

impl JoinedLoop<'_> {
    /// How the plant's clock behaved at this tick; None without the state or without a clock
    /// (lockstep, where the plant's timing is all zero).
    pub fn tick_timing(&self) -> Option<TickTiming> {
        self.parts.state.map(|s| s.timing).filter(|timing| *timing != TickTiming::default())
    }
}

/// One output of a run, fed every joined loop.
pub trait RunSink: Send {
    fn loop_joined(&mut self, joined: &JoinedLoop) -> Result<()>;
    /// Pushes what is buffered to the file, so that a killed monitor loses little.
    fn flush(&mut self) -> Result<()>;
    /// Its file and how long it is, everything written pushed to it (after [`flush`](Self::flush)):
    /// a restarted monitor cuts the file back to there, so that it holds the loops its
    /// predecessor's saved state covers and no more.
    fn end(&self) -> Result<FileEnd>;
    /// The run is over (every loop has been passed): writes what is left. `report` holds the
    /// run's numbers, what each fault did included.
    fn finish(&mut self, _report: &MonitorReport) -> Result<()> {
        self.flush()
    }
}

/// Opens every output of a run, in this order.
pub fn open(setup: &SinkSetup) -> Result<Vec<Box<dyn RunSink>>> {
    Ok(vec![
        Box::new(trajectory::TrajectoryCsv::open(setup)?),
        Box::new(loops::LoopsCsv::open(setup)?),
        Box::new(hlog::LatencyLog::open(setup)?),
        Box::new(mcap::McapRecording::open(setup)?),
    ])
}

/// An output file (by its name in the run folder) and its length, at a save.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct FileEnd {
    pub name: String,
    pub len: u64,
}

impl FileEnd {
    /// `file`, named `name`, as it is now.
    pub fn of(file: &BufWriter<File>, name: &str) -> Result<Self> {
        let len = file.get_ref().metadata().with_context(|| format!("the length of {name}"))?.len();
        Ok(Self { name: name.to_owned(), len })
    }

    /// Cuts the file back to this length in `dir` (never through a link); a file already no
    /// longer is left as it is.
    pub fn cut_back(&self, dir: &Path) -> Result<()> {
        let path = dir.join(&self.name);
        let file = run_file::open(&path, Existing::Append)?;
        if file.metadata()?.len() > self.len {
            file.set_len(self.len).with_context(|| format!("cut {} back to {} bytes", path.display(), self.len))?;
        }
        Ok(())
    }
}

/// Creates an output file, or, for a restarted monitor, appends to what the last one wrote;
/// returns whether the file is new (and needs its header).
pub fn create(dir: &Path, name: &str, restarted: bool) -> Result<(BufWriter<File>, bool)> {
    let path = dir.join(name);
    let append = restarted && path.exists();
    let file = run_file::open(&path, if append { Existing::Append } else { Existing::Replace })?;
    Ok((BufWriter::new(file), !append))
}

/// Flushes an output file of the run folder `dir`.
pub fn flush(file: &mut BufWriter<File>, dir: &Path) -> Result<()> {
    use std::io::Write as _;
    file.flush().with_context(|| format!("write to {}", dir.display()))
}
