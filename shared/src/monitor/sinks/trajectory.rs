//! `trajectory.csv`: one row per tick in simulation time only: the true state, each sensor's
//! held value, the estimate and the command. Byte for byte the same for a lockstep run of the
//! same launch file and seed.

use std::fs::File;
use std::io::{BufWriter, Write};
use std::path::PathBuf;

use anyhow::Result;

use crate::contract::report::MonitorReport;
use crate::monitor::sinks::{JoinedLoop, RunSink, SinkSetup, create, flush};

pub struct TrajectoryCsv {
    file: BufWriter<File>,
    run_dir: PathBuf,
    n_state: usize,
    sensor_dims: Vec<usize>,
    n_estimate: usize,
    n_input: usize,
}

impl TrajectoryCsv {
    pub fn open(setup: &SinkSetup) -> Result<Self> {
        let layout = setup.layout;
        let (mut file, new) = create(setup.run_dir, "trajectory.csv", setup.restarted)?;
        let mut columns: Vec<String> = vec!["k".into(), "t".into()];
        columns.extend(layout.state.iter().cloned());
        for (name, components) in &layout.sensors {
            match &components[..] {
                [_] => columns.push(format!("meas.{name}")),
                components => columns.extend(components.iter().map(|c| format!("meas.{name}.{c}"))),
            }
        }
        columns.extend(layout.estimate.iter().map(|n| format!("est.{n}")));
        columns.extend(layout.input.iter().map(|n| format!("cmd.{n}")));
        if new {
            writeln!(file, "{}", columns.join(","))?;
        }
        Ok(Self {
            file,
            run_dir: setup.run_dir.to_path_buf(),
            n_state: layout.state.len(),
            sensor_dims: layout.sensor_dims(),
            n_estimate: layout.estimate.len(),
            n_input: layout.input.len(),
        })
    }
}

impl RunSink for TrajectoryCsv {
    fn loop_joined(&mut self, joined: &JoinedLoop) -> Result<()> {
        let part = joined.parts;
        let mut row = format!("{},{}", joined.k, joined.t);
        // A part that did not arrive leaves its cells empty.
        let mut push = |values: Option<&[f64]>, n: usize| match values {
            Some(v) => v[..n].iter().for_each(|x| row.push_str(&format!(",{x}"))),
            None => row.push_str(&",".repeat(n)),
        };
        push(part.state.as_ref().map(|s| &s.x[..]), self.n_state);
        for (i, dim) in self.sensor_dims.iter().enumerate() {
            push(part.measurements.as_ref().map(|m| &m.readings[i].value[..]), *dim);
        }
        push(part.estimate.as_ref().map(|e| &e.x[..]), self.n_estimate);
        push(part.command.as_ref().map(|c| &c.u[..]), self.n_input);
        writeln!(self.file, "{row}")?;
        Ok(())
    }

    fn flush(&mut self) -> Result<()> {
        flush(&mut self.file, &self.run_dir)
    }

    fn finish(&mut self, _report: &MonitorReport) -> Result<()> {
        self.flush()
    }
}
