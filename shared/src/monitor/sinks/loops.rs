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
use crate::model::layout::column_name;
use crate::monitor::sinks::text::{push_f64, push_int};
use crate::monitor::sinks::{JoinedLoop, RunSink, SinkSetup, create, flush};

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
        let (mut file, new) = create(setup.run_dir, "loops.csv", setup.restarted)?;
        if new {
            writeln!(file, "{}", columns().join(","))?;
        }
        let wall_clock = setup.config.mode == Mode::Realtime;
        Ok(Self { file, row: Vec::with_capacity(256), run_dir: setup.run_dir.to_path_buf(), wall_clock })
    }
}

/// Where loops.csv's columns lie, for readers that read it by position: k and t first, then the
/// loop trace's stamps in order, end to end, deadline miss, rejected, and the tick's scheduled
/// time, wake-up and period.
pub mod column {
    use crate::contract::msg::LoopTrace;
    pub const FIRST_STAMP: usize = 2;
    pub const END_TO_END: usize = FIRST_STAMP + LoopTrace::STAMP_NAMES.len();
    pub const DEADLINE_MISS: usize = END_TO_END + 1;
    pub const TICK_PERIOD: usize = DEADLINE_MISS + 4;
    pub const COUNT: usize = TICK_PERIOD + 1;
}

/// The header of `loops.csv`: every column but `t_s` holds a whole number (or nothing).
pub fn columns() -> Vec<String> {
    let mut columns = vec!["k".to_string(), column_name("t", "s")];
    columns.extend(LoopTrace::STAMP_NAMES.iter().map(|s| format!("{s}_ns")));
    columns.extend(
        ["end_to_end_ns", "deadline_miss", "rejected", "tick_scheduled_ns", "tick_wake_ns", "tick_period_ns"]
            .map(String::from),
    );
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
        row.push(b'\n');
        self.file.write_all(row)?;
        Ok(())
    }

    fn flush(&mut self) -> Result<()> {
        flush(&mut self.file, &self.run_dir)
    }
}
