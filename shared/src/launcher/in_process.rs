//! `looplab run --in-process`: the run's loop in one process (`runtime::in_process`) recorded by
//! the monitor's own recorder into the same run folder, with no children and no shared memory.

use std::path::Path;

use anyhow::Result;

use crate::config::launch::LaunchConfig;
use crate::contract::report::MonitorReport;
use crate::monitor::Recording;
use crate::runtime::in_process::{self, InProcessReports};
use crate::runtime::signals::StopFlag;
use crate::model::scenario::Scenario;

/// Runs the loop in this process and records it in `run_dir`.
pub fn run(
    config: &LaunchConfig,
    scenario: &dyn Scenario,
    run_dir: &Path,
    stop: &StopFlag,
) -> Result<(InProcessReports, MonitorReport)> {
    let mut recording = Recording::new(config, scenario, run_dir, 0, None)?;
    let reports = in_process::run(config, scenario, stop, |message| recording.take(message))?;
    Ok((reports, recording.finish()?))
}
