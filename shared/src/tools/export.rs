//! `looplab export RUN_DIR --mcap`: writes `run.mcap` for a run folder from its files
//! (launch.toml, trajectory.csv, loops.csv, summary.json), through the monitor's own MCAP sink.
//! The files keep less than the monitor saw: no sensor sample times or fresh flags, no lost
//! flags or incarnations (the schemas leave them out).

use std::path::{Path, PathBuf};

use crate::contract::msg::{Command, Estimate, LoopRecord, LoopTrace, Measurements, PlantState, TickTiming};
use crate::contract::report::FaultEffect;
use crate::contract::run_format::files;
use crate::model::catalog::Catalog;
use crate::model::layout::VectorLayout;
use crate::monitor::join::LoopParts;
use crate::monitor::sinks::mcap::{Detail, FILE, McapRecording};
use crate::monitor::sinks::{JoinedLoop, RunSink};
use crate::tools::run_folder::{RunFolder, Table};
use crate::tools::{RUN_FILES, ToolError};

/// Writes `run_dir/run.mcap` from the run folder's files; returns its path. A recording there
/// already (the monitor's, which keeps more than the files) is replaced only with `force`.
pub fn write_mcap(run_dir: &Path, catalog: &Catalog, force: bool) -> Result<PathBuf, ToolError> {
    let folder = RunFolder::open(run_dir, &RUN_FILES)?;
    let bad = |why: String| ToolError::BadInput(format!("{}: {why}", run_dir.display()));
    let path = run_dir.join(FILE);
    if !force && std::fs::symlink_metadata(&path).is_ok() {
        return Err(bad(format!(
            "{FILE} exists (the monitor's recording keeps more than the files: sample times, fresh flags, \
             incarnations); export writes one only where there is none: give --force to replace it"
        )));
    }
    let (config, scenario) = folder.launch(catalog)?;
    let layout = VectorLayout::new(&config, scenario.as_ref());
    let summary: serde_json::Value =
        serde_json::from_str(&folder.text(files::SUMMARY)?).map_err(|e| bad(format!("{}: {e}", files::SUMMARY)))?;
    // One effect per fault of the launch file, None where the monitor had no record of it.
    let effects: Vec<Option<FaultEffect>> = summary["faults"]
        .as_array()
        .map(|faults| faults.iter().map(|f| serde_json::from_value(f["effect"].clone()).ok()).collect())
        .unwrap_or_default();

    // Everything is read and checked before the recording's file is created.
    let trajectory = Trajectory::read(folder.table(files::TRAJECTORY)?, &layout)?;
    let loops = Loops::read(folder.table(files::LOOPS)?)?;
    if trajectory.k.len() != loops.k.len() {
        return Err(bad("trajectory.csv and loops.csv have different numbers of rows".into()));
    }
    let joined = |row: usize| -> Result<(u64, f64, LoopParts), ToolError> {
        let (k, t, mut parts) = trajectory.parts(row)?;
        let loop_k = loops.add_to(row, &mut parts)?;
        if loop_k != k {
            return Err(bad(format!("line {}: loop {k} in trajectory.csv, {loop_k} in loops.csv", row + 2)));
        }
        Ok((k, t, parts))
    };
    // A first pass checks every row, so that a bad file leaves no recording behind.
    for row in 0..loops.k.len() {
        joined(row)?;
    }

    let mut recording = McapRecording::create(&path, &config, &layout, Detail::Files)?;
    for row in 0..loops.k.len() {
        let (k, t, parts) = joined(row)?;
        recording.loop_joined(&JoinedLoop { k, t, parts: &parts, cause: None })?;
    }
    recording.finish_with(&effects)?;
    Ok(path)
}

/// Whole columns of a CSV file, each cell None where it is empty (the part did not arrive).
type Cells<T> = Vec<Vec<Option<T>>>;

/// The columns `names` of `table`.
fn columns<T: std::str::FromStr>(table: &Table, names: impl IntoIterator<Item = String>) -> Result<Cells<T>, ToolError>
where
    T::Err: std::fmt::Display,
{
    names.into_iter().map(|name| table.column(&name)).collect()
}

/// The values of `columns` in `row`: None if every cell is empty, an error if only some are.
fn values<T: Copy>(
    table: &Table,
    columns: &[Vec<Option<T>>],
    row: usize,
    what: &str,
) -> Result<Option<Vec<T>>, ToolError> {
    let cells: Vec<Option<T>> = columns.iter().map(|c| c[row]).collect();
    match cells.iter().filter(|c| c.is_some()).count() {
        0 => Ok(None),
        n if n == cells.len() => Ok(Some(cells.into_iter().flatten().collect())),
        _ => Err(table.error_at(row, format_args!("{what}: some cells are empty, not all"))),
    }
}

/// A row's first two cells, k and t, which every row has.
fn k_and_t(table: &Table, k: &[Option<u64>], t: &[Option<f64>], row: usize) -> Result<(u64, f64), ToolError> {
    match (k[row], t[row]) {
        (Some(k), Some(t)) => Ok((k, t)),
        _ => Err(table.error_at(row, "no k or t")),
    }
}

/// trajectory.csv by the names a run of the launch file writes: k, t, the state, each sensor's
/// reading, the estimate, the command and the applied input.
struct Trajectory {
    table: Table,
    k: Vec<Option<u64>>,
    t: Vec<Option<f64>>,
    state: Cells<f64>,
    /// Per sensor, in the layout's order.
    sensors: Vec<Cells<f64>>,
    estimate: Cells<f64>,
    command: Cells<f64>,
    /// The plant's `u_applied`, part of its state message.
    applied: Cells<f64>,
}

impl Trajectory {
    fn read(table: Table, layout: &VectorLayout) -> Result<Self, ToolError> {
        let mut names = layout.trajectory_columns().into_iter();
        let k = table.column(&names.next().expect("k"))?;
        let t = table.column(&names.next().expect("t"))?;
        let state = columns(&table, names.by_ref().take(layout.state.len()))?;
        let sensors = layout
            .sensor_dims()
            .into_iter()
            .map(|dim| columns(&table, names.by_ref().take(dim)))
            .collect::<Result<_, _>>()?;
        let estimate = columns(&table, names.by_ref().take(layout.estimate.len()))?;
        let command = columns(&table, names.by_ref().take(layout.input.len()))?;
        let applied = columns(&table, names)?;
        Ok(Trajectory { table, k, t, state, sensors, estimate, command, applied })
    }

    /// A row as the parts of its loop, with its k and t.
    fn parts(&self, row: usize) -> Result<(u64, f64, LoopParts), ToolError> {
        let table = &self.table;
        let (k, t) = k_and_t(table, &self.k, &self.t, row)?;
        let mut parts = LoopParts::default();
        if let Some(x) = values(table, &self.state, row, "the state")? {
            let mut state = PlantState::default();
            state.x[..x.len()].copy_from_slice(&x);
            if let Some(u) = values(table, &self.applied, row, "the applied input")? {
                state.u_applied[..u.len()].copy_from_slice(&u);
            }
            parts.state = Some(state);
        }
        let mut measurements = Measurements::default();
        let mut any_reading = false;
        for (reading, sensor) in measurements.readings.iter_mut().zip(&self.sensors) {
            if let Some(value) = values(table, sensor, row, "a sensor's reading")? {
                reading.value[..value.len()].copy_from_slice(&value);
                any_reading = true;
            }
        }
        parts.measurements = any_reading.then_some(measurements);
        if let Some(x) = values(table, &self.estimate, row, "the estimate")? {
            let mut estimate = Estimate::default();
            estimate.x[..x.len()].copy_from_slice(&x);
            parts.estimate = Some(estimate);
        }
        if let Some(u) = values(table, &self.command, row, "the command")? {
            let mut command = Command::default();
            command.u[..u.len()].copy_from_slice(&u);
            parts.command = Some(command);
        }
        Ok((k, t, parts))
    }
}

/// loops.csv by name: k, t, the loop trace's stamps, the record's flags and the tick's timing.
struct Loops {
    table: Table,
    k: Vec<Option<u64>>,
    t: Vec<Option<f64>>,
    stamps: Cells<u64>,
    /// Deadline miss, rejected.
    flags: Cells<u32>,
    /// Scheduled, wake-up, period.
    timing: Cells<u64>,
}

impl Loops {
    fn read(table: Table) -> Result<Self, ToolError> {
        let k = table.column("k")?;
        let t = table.column("t_s")?;
        let stamps = columns(&table, LoopTrace::STAMP_NAMES.iter().map(|s| format!("{s}_ns")))?;
        let flags = columns(&table, ["deadline_miss", "rejected"].map(String::from))?;
        let timing = columns(&table, ["tick_scheduled_ns", "tick_wake_ns", "tick_period_ns"].map(String::from))?;
        Ok(Loops { table, k, t, stamps, flags, timing })
    }

    /// Adds a row to its loop: the record, the trace in every part's header (the log time in real
    /// time) and the plant's tick timing. Returns the row's k.
    fn add_to(&self, row: usize, parts: &mut LoopParts) -> Result<u64, ToolError> {
        let table = &self.table;
        let (k, t) = k_and_t(table, &self.k, &self.t, row)?;
        let stamps = values(table, &self.stamps, row, "the stamps")?;
        let flags = values(table, &self.flags, row, "the flags")?;
        let timing = values(table, &self.timing, row, "the tick's timing")?;
        let trace = stamps
            .as_deref()
            .and_then(|s| <[u64; 8]>::try_from(s).ok())
            .map_or_else(LoopTrace::default, LoopTrace::from_stamps);
        let set = |header: &mut crate::contract::msg::Header| {
            header.k = k;
            header.t = t;
            header.trace = trace;
        };
        if let Some(state) = &mut parts.state {
            set(&mut state.header);
            if let Some(timing) = &timing {
                state.timing = TickTiming { scheduled_ns: timing[0], wake_ns: timing[1], period_ns: timing[2] };
            }
        }
        parts.measurements.iter_mut().for_each(|m| set(&mut m.header));
        parts.estimate.iter_mut().for_each(|m| set(&mut m.header));
        parts.command.iter_mut().for_each(|m| set(&mut m.header));
        if stamps.is_some() {
            let mut record = LoopRecord::default();
            set(&mut record.header);
            if let Some(flags) = flags {
                (record.deadline_miss, record.rejected) = (flags[0], flags[1]);
            }
            parts.record = Some(record);
        }
        Ok(k)
    }
}
