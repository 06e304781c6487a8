//! `looplab run --in-process`: the run's loop in this one process (`runtime::in_process`),
//! recorded by the monitor's own recorder into the same run folder and summarised by the same
//! summary, with no children and no shared memory.

use std::collections::BTreeMap;
use std::path::Path;

use anyhow::Result;

use crate::config::launch::LaunchConfig;
use crate::launcher::outcome::Outcome;
use crate::launcher::run_dir::{begin_run, new_run_id};
use crate::launcher::summary::{self, Reports, RunLog, SharedMemoryCheck, Summary, SummaryInputs};
use crate::model::scenario::Scenario;
use crate::monitor::Recording;
use crate::monitor::recording_thread::{RecorderOptions, RecordingThread};
use crate::runtime::in_process;
use crate::runtime::signals::StopFlag;

/// Runs the loop of `config` in this process and writes the run folder.
pub fn run_in_process(config: &LaunchConfig, scenario: &dyn Scenario, run_dir: &Path) -> Result<(Summary, Outcome)> {
    let (_, started_at) = begin_run(run_dir, config, scenario)?;
    let stop = StopFlag::install()?;
    // The loop's thread only hands each message over; the recording runs beside it.
    let mut recording =
        RecordingThread::spawn(Recording::in_process(config, scenario, run_dir)?, RecorderOptions::IN_PROCESS)?;
    let ran = in_process::run(config, scenario, &stop, |message| recording.take(message));
    // The recording's own error first (a full disk): the loop only saw it stop.
    let monitor = recording.finish()?;
    let ran = ran?;
    let outcome = if stop.requested() { Outcome::Interrupted } else { Outcome::Completed };
    let reports =
        Reports { plant: Some(ran.plant), stages: ran.stages, monitor: Some(monitor), bridges: BTreeMap::new() };
    let summary = summary::build(SummaryInputs {
        config,
        scenario,
        run_id: &new_run_id(),
        run_dir,
        started_at,
        outcome: &outcome,
        reports: &reports,
        starts: &BTreeMap::new(),
        log: &RunLog::default(),
        shared_memory: SharedMemoryCheck { clean: true, ..Default::default() },
    });
    summary::write(&summary, run_dir)?;
    Ok((summary, outcome))
}
