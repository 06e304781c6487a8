//! `looplab export RUN_DIR --mcap`: writes `run.mcap` for a run folder from its files
//! (launch.toml, trajectory.csv, loops.csv, summary.json), through the monitor's own MCAP sink.
//! The files keep less than the monitor saw: no sensor sample times or fresh flags, no lost
//! flags or incarnations (the schemas leave them out).

use std::path::{Path, PathBuf};

use anyhow::{Context as _, Result, anyhow};

use crate::contract::msg::{Command, Estimate, LoopRecord, LoopTrace, Measurements, PlantState, TickTiming};
use crate::contract::report::FaultEffect;
use crate::monitor::join::LoopParts;
use crate::monitor::layout::Layout;
use crate::monitor::sinks::mcap::{Detail, FILE, McapRecording};
use crate::monitor::sinks::{JoinedLoop, RunSink, loops};
use crate::scenarios;
use crate::tools::{RUN_FILES, ToolError, check_run_folder};

/// Writes `run_dir/run.mcap` from the run folder's files; returns its path.
pub fn write_mcap(run_dir: &Path) -> Result<PathBuf, ToolError> {
    let shown = run_dir.display();
    let bad = |why: String| ToolError::BadInput(format!("{shown}: {why}"));
    check_run_folder(run_dir, &RUN_FILES)?;
    let (config, scenario) = scenarios::load_resolved(&run_dir.join("launch.toml")).map_err(|e| bad(e.to_string()))?;
    let layout = Layout::new(&config, scenario.as_ref());
    let read = |name: &str| std::fs::read_to_string(run_dir.join(name)).with_context(|| format!("read {shown}/{name}"));
    let summary: serde_json::Value =
        serde_json::from_str(&read("summary.json")?).map_err(|e| bad(format!("summary.json: {e}")))?;
    // One effect per fault of the launch file, None where the monitor had no record of it.
    let effects: Vec<Option<FaultEffect>> = summary["faults"]
        .as_array()
        .map(|faults| faults.iter().map(|f| serde_json::from_value(f["effect"].clone()).ok()).collect())
        .unwrap_or_default();

    let trajectory = read("trajectory.csv")?;
    let loops = read("loops.csv")?;
    let mut trajectory_rows =
        rows(&trajectory, "trajectory.csv", &layout.trajectory_columns()).map_err(|e| bad(e.to_string()))?;
    let mut loops_rows = rows(&loops, "loops.csv", &loops::columns()).map_err(|e| bad(e.to_string()))?;

    let path = run_dir.join(FILE);
    let mut recording = McapRecording::create(&path, &config, &layout, Detail::Files)?;
    let sensor_dims = layout.sensor_dims();
    for line in 2.. {
        let (trajectory_row, loops_row) = match (trajectory_rows.next(), loops_rows.next()) {
            (Some(a), Some(b)) => (a, b),
            (None, None) => break,
            _ => return Err(bad("trajectory.csv and loops.csv have different numbers of rows".into())),
        };
        let at = |file: &str, e: anyhow::Error| bad(format!("{file} line {line}: {e}"));
        let (k, t, parts) =
            parse_trajectory(&trajectory_row, &layout, &sensor_dims).map_err(|e| at("trajectory.csv", e))?;
        let mut parts = parts;
        let loop_k = add_loop(&loops_row, &mut parts).map_err(|e| at("loops.csv", e))?;
        if loop_k != k {
            return Err(bad(format!("line {line}: loop {k} in trajectory.csv, {loop_k} in loops.csv")));
        }
        recording.loop_joined(&JoinedLoop { k, t, parts: &parts })?;
    }
    recording.finish_with(&effects)?;
    Ok(path)
}

/// The data rows of a CSV file, each split into its cells, after checking that the header is
/// the one a run of the launch file writes (the cells are read by position).
fn rows<'a>(text: &'a str, name: &str, columns: &[String]) -> Result<impl Iterator<Item = Vec<&'a str>> + 'a> {
    let mut lines = text.lines();
    let header = lines.next().ok_or_else(|| anyhow!("{name} is empty"))?;
    let found: Vec<&str> = header.split(',').collect();
    if found != columns {
        // The first column that differs (or is missing, or is one too many).
        let at = (0..).find(|&i| found.get(i).copied() != columns.get(i).map(String::as_str)).expect("they differ");
        let show = |column: Option<&str>| column.map_or("nothing".to_string(), |c| format!("{c:?}"));
        return Err(anyhow!(
            "{name}: column {} is {}, a run of its launch.toml writes {} there (the header must be {:?})",
            at + 1,
            show(found.get(at).copied()),
            show(columns.get(at).map(String::as_str)),
            columns.join(",")
        ));
    }
    Ok(lines.map(|line| line.split(',').collect()))
}

/// The next `n` cells as numbers, or None if they are empty (the part did not arrive).
fn take<'a, T: std::str::FromStr>(cells: &mut impl Iterator<Item = &'a str>, n: usize) -> Result<Option<Vec<T>>>
where
    T::Err: std::fmt::Display,
{
    let cells: Vec<&str> = cells.take(n).collect();
    if cells.len() < n {
        return Err(anyhow!("too few cells"));
    }
    if cells.iter().all(|c| c.is_empty()) {
        return Ok(None);
    }
    cells.iter().map(|c| c.parse().map_err(|e| anyhow!("{c:?}: {e}"))).collect::<Result<_>>().map(Some)
}

/// A row of trajectory.csv as the parts of its loop.
fn parse_trajectory(row: &[&str], layout: &Layout, sensor_dims: &[usize]) -> Result<(u64, f64, LoopParts)> {
    let mut cells = row.iter().copied();
    let k = cells.next().unwrap_or_default().parse().context("k")?;
    let t = cells.next().unwrap_or_default().parse().context("t")?;
    let mut parts = LoopParts::default();
    if let Some(x) = take::<f64>(&mut cells, layout.state.len())? {
        let mut state = PlantState::default();
        state.x[..x.len()].copy_from_slice(&x);
        parts.state = Some(state);
    }
    let mut measurements = Measurements::default();
    let mut any_reading = false;
    for (reading, dim) in measurements.readings.iter_mut().zip(sensor_dims) {
        if let Some(value) = take::<f64>(&mut cells, *dim)? {
            reading.value[..value.len()].copy_from_slice(&value);
            any_reading = true;
        }
    }
    parts.measurements = any_reading.then_some(measurements);
    if let Some(x) = take::<f64>(&mut cells, layout.estimate.len())? {
        let mut estimate = Estimate::default();
        estimate.x[..x.len()].copy_from_slice(&x);
        parts.estimate = Some(estimate);
    }
    if let Some(u) = take::<f64>(&mut cells, layout.input.len())? {
        let mut command = Command::default();
        command.u[..u.len()].copy_from_slice(&u);
        parts.command = Some(command);
    }
    Ok((k, t, parts))
}

/// Adds a row of loops.csv to its loop: the record, the trace in every part's header (the log
/// time in real time) and the plant's tick timing. Returns the row's k.
fn add_loop(row: &[&str], parts: &mut LoopParts) -> Result<u64> {
    let mut cells = row.iter().copied();
    let k: u64 = cells.next().unwrap_or_default().parse().context("k")?;
    let t: f64 = cells.next().unwrap_or_default().parse().context("t")?;
    let stamps = take::<u64>(&mut cells, LoopTrace::STAMP_NAMES.len())?;
    let _end_to_end = take::<u64>(&mut cells, 1)?;
    let flags = take::<u32>(&mut cells, 2)?;
    let timing = take::<u64>(&mut cells, 3)?;
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
