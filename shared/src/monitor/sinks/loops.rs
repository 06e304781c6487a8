//! `loops.csv`: one row per loop with every CLOCK_MONOTONIC stamp of its trace, the end-to-end
//! latency, the deadline-miss and rejected flags and the plant's tick timing. A real-time loop
//! whose state went out but whose command never came has a row too: no stamps, no end to end,
//! flagged a deadline miss, as the plant counts it.

use std::fs::File;
use std::io::{BufWriter, Write};
use std::path::PathBuf;

use anyhow::Result;

use crate::config::launch::Mode;
use crate::contract::msg::LoopTrace;
use crate::contract::run_format::files;
use crate::model::layout::column_name;
use crate::monitor::sinks::text::{push_f64, push_int};
use crate::monitor::sinks::{FileEnd, JoinedLoop, RunSink, SinkSetup, create, flush};

pub struct LoopsCsv {
    file: BufWriter<File>,
    /// The row being written, reused.
    row: Vec<u8>,
    run_dir: PathBuf,
    /// Real time: a loop without a command missed its deadline.
    wall_clock: bool,
}

impl LoopsCsv {
    pub fn open(setup: &SinkSetup) -> Result<Self> {
        let (mut file, new) = create(setup.run_dir, files::LOOPS, setup.restarted)?;
        if new {
            writeln!(file, "{}", columns().join(","))?;
        }
        let wall_clock = setup.config.mode == Mode::Realtime;
        Ok(Self { file, row: Vec::with_capacity(256), run_dir: setup.run_dir.to_path_buf(), wall_clock })
    }
}

/// Where loops.csv's columns lie, for readers that read it by position: k and t first, then the
/// loop trace's stamps in order, end to end, deadline miss, rejected, the tick's scheduled
/// time, wake-up and period, then each loop process's run-queue waits, and the cause of a late
/// loop with its part of the response time.
pub mod column {
    use crate::contract::msg::LoopTrace;
    pub const FIRST_STAMP: usize = 2;
    pub const END_TO_END: usize = FIRST_STAMP + LoopTrace::STAMP_NAMES.len();
    pub const DEADLINE_MISS: usize = END_TO_END + 1;
    pub const TICK_PERIOD: usize = DEADLINE_MISS + 4;
    pub const FIRST_QUEUED: usize = TICK_PERIOD + 1;
    pub const CAUSE: usize = FIRST_QUEUED + super::QUEUED_COLUMNS.len();
    pub const COUNT: usize = CAUSE + 3;
}

/// The run-queue waits (`contract::msg::SchedStamp`) of each loop, ns: the plant's before it woke
/// for the tick and for the command, each stage's before it got its input and while it computed
/// (0 unless its computation took over `runtime::stage::sched::COMPUTE_READ_NS`).
pub const QUEUED_COLUMNS: [&str; 8] = [
    "plant_tick_queued_ns",
    "sensors_queued_ns",
    "sensors_compute_queued_ns",
    "estimator_queued_ns",
    "estimator_compute_queued_ns",
    "controller_queued_ns",
    "controller_compute_queued_ns",
    "plant_command_queued_ns",
];

/// The waits of [`QUEUED_COLUMNS`], each where its message came.
fn queued(parts: &crate::monitor::join::LoopParts) -> [Option<u32>; QUEUED_COLUMNS.len()] {
    let (state, meas, est, cmd, record) = (
        parts.state.map(|m| m.header.sched),
        parts.measurements.map(|m| m.header.sched),
        parts.estimate.map(|m| m.header.sched),
        parts.command.map(|m| m.header.sched),
        parts.record.map(|m| m.header.sched),
    );
    [
        state.map(|s| s.queued_ns),
        meas.map(|s| s.queued_ns),
        meas.map(|s| s.compute_queued_ns),
        est.map(|s| s.queued_ns),
        est.map(|s| s.compute_queued_ns),
        cmd.map(|s| s.queued_ns),
        cmd.map(|s| s.compute_queued_ns),
        record.map(|s| s.queued_ns),
    ]
}

/// The header of `loops.csv`: every column but `t_s` holds a whole number (or nothing).
pub fn columns() -> Vec<String> {
    let mut columns = vec!["k".to_string(), column_name("t", "s")];
    columns.extend(LoopTrace::STAMP_NAMES.iter().map(|s| format!("{s}_ns")));
    columns.extend(
        ["end_to_end_ns", "deadline_miss", "rejected", "tick_scheduled_ns", "tick_wake_ns", "tick_period_ns"]
            .map(String::from),
    );
    columns.extend(QUEUED_COLUMNS.map(String::from));
    columns.extend(["cause", "cause_part_ns", "response_ns"].map(String::from));
    columns
}

impl RunSink for LoopsCsv {
    fn loop_joined(&mut self, joined: &JoinedLoop) -> Result<()> {
        let row = &mut self.row;
        row.clear();
        push_int(row, joined.k);
        row.push(b',');
        push_f64(row, joined.t);
        let cell = |row: &mut Vec<u8>, value: u64| {
            row.push(b',');
            push_int(row, value);
        };
        match (&joined.parts.record, joined.parts.end_to_end_ns()) {
            (Some(r), Some(e2e)) => {
                for s in r.header.trace.stamps() {
                    cell(row, s);
                }
                cell(row, e2e);
                cell(row, r.deadline_miss.into());
                cell(row, r.rejected.into());
            }
            // No stamps and no end to end; the flags where the miss is known (a command that
            // never came was not rejected either).
            _ => {
                row.resize(row.len() + LoopTrace::STAMP_NAMES.len() + 1, b',');
                match joined.parts.deadline_missed(self.wall_clock) {
                    Some(missed) => {
                        cell(row, missed.into());
                        cell(row, 0);
                    }
                    None => row.extend_from_slice(b",,"),
                }
            }
        }
        match joined.tick_timing() {
            Some(tm) => [tm.scheduled_ns, tm.wake_ns, tm.period_ns].into_iter().for_each(|ns| cell(row, ns)),
            None => row.extend_from_slice(b",,,"),
        }
        for wait in queued(joined.parts) {
            row.push(b',');
            if let Some(ns) = wait {
                push_int(row, u64::from(ns));
            }
        }
        // Causes are plain words, colons, spaces and "->": nothing CSV must quote.
        match &joined.cause {
            Some(explanation) => {
                row.push(b',');
                row.extend_from_slice(explanation.cause.to_string().as_bytes());
                for ns in [explanation.part_ns, explanation.response_ns] {
                    row.push(b',');
                    if let Some(ns) = ns {
                        push_int(row, ns);
                    }
                }
            }
            None => row.extend_from_slice(b",,,"),
        }
        row.push(b'\n');
        self.file.write_all(row)?;
        Ok(())
    }

    fn flush(&mut self) -> Result<()> {
        flush(&mut self.file, &self.run_dir)
    }

    fn end(&self) -> Result<FileEnd> {
        FileEnd::of(&self.file, files::LOOPS)
    }
}
