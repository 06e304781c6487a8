//! `trajectory.csv`: one row per tick in simulation time only: the true state, each sensor's
//! held value, the estimate, the command and the input the actuator applied. Byte for byte the
//! same for a lockstep run of the same launch file and seed.
//!
//! Row k's `cmd.*` is command k, computed from tick k's data (empty where none came); its
//! `applied.*` is the plant's state message k's `u_applied`: what the actuator applied over the
//! period that ended at tick k, t(k−1) to t(k) (the command held then, `on_stale`'s value once
//! it was stale, or what the scenario's actuator made of it; at k = 0, the plant's initial
//! input). So in time, command k shows up as applied in row k+1, and across a silent
//! controller `cmd.*` is empty while `applied.*` shows what the plant held.

use std::fs::File;
use std::io::{BufWriter, Write};
use std::path::PathBuf;

use anyhow::Result;

use crate::contract::run_format::files;
use crate::monitor::sinks::text::{push_f64, push_int};
use crate::monitor::sinks::{FileEnd, JoinedLoop, RunSink, SinkSetup, create, flush};

pub struct TrajectoryCsv {
    file: BufWriter<File>,
    /// The row being written, reused.
    row: Vec<u8>,
    run_dir: PathBuf,
    n_state: usize,
    sensor_dims: Vec<usize>,
    n_estimate: usize,
    n_input: usize,
}

impl TrajectoryCsv {
    pub fn open(setup: &SinkSetup) -> Result<Self> {
        let layout = setup.layout;
        let (mut file, new) = create(setup.run_dir, files::TRAJECTORY, setup.restarted)?;
        if new {
            writeln!(file, "{}", layout.trajectory_columns().join(","))?;
        }
        Ok(Self {
            file,
            row: Vec::with_capacity(1024),
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
        let row = &mut self.row;
        row.clear();
        push_int(row, joined.k);
        row.push(b',');
        push_f64(row, joined.t);
        // A part that did not arrive leaves its cells empty.
        let mut push = |values: Option<&[f64]>, n: usize| match values {
            Some(v) => v[..n].iter().for_each(|&x| {
                row.push(b',');
                push_f64(row, x);
            }),
            None => row.resize(row.len() + n, b','),
        };
        push(part.state.as_ref().map(|s| &s.x[..]), self.n_state);
        for (i, dim) in self.sensor_dims.iter().enumerate() {
            push(part.measurements.as_ref().map(|m| &m.readings[i].value[..]), *dim);
        }
        push(part.estimate.as_ref().map(|e| &e.x[..]), self.n_estimate);
        push(part.command.as_ref().map(|c| &c.u[..]), self.n_input);
        push(part.state.as_ref().map(|s| &s.u_applied[..]), self.n_input);
        row.push(b'\n');
        self.file.write_all(row)?;
        Ok(())
    }

    fn flush(&mut self) -> Result<()> {
        flush(&mut self.file, &self.run_dir)
    }

    fn end(&self) -> Result<FileEnd> {
        FileEnd::of(&self.file, files::TRAJECTORY)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::contract::msg::{Command, Estimate, Measurements, PlantState};
    use crate::contract::report::MonitorReport;
    use crate::model::layout::VectorLayout;
    use crate::monitor::join::LoopParts;

    fn layout() -> VectorLayout {
        VectorLayout::example()
    }

    fn whole_loop() -> LoopParts {
        let mut state = PlantState::default();
        state.x[..2].copy_from_slice(&[0.5, -1.25]);
        state.u_applied[0] = -0.5;
        let mut measurements = Measurements::default();
        measurements.readings[0].value[0] = 0.1;
        measurements.readings[1].value[..2].copy_from_slice(&[2.0, 3.0]);
        let mut estimate = Estimate::default();
        estimate.x[0] = 0.25;
        let mut command = Command::default();
        command.u[0] = -0.75;
        LoopParts {
            state: Some(state),
            measurements: Some(measurements),
            estimate: Some(estimate),
            command: Some(command),
            record: None,
        }
    }

    #[test]
    fn rows_hold_each_vector_and_leave_missing_parts_empty() {
        let dir = std::env::temp_dir().join(format!("looplab-trajectory-test-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let config = crate::scenarios::resolve("pendulum", &[]).unwrap().0;
        let layout = layout();
        let setup =
            |restarted| SinkSetup { run_dir: &dir, restarted, config: &config, layout: &layout, spare_core: false };

        let mut sink = TrajectoryCsv::open(&setup(false)).unwrap();
        let whole = whole_loop();
        sink.loop_joined(&JoinedLoop { k: 0, t: 0.0, parts: &whole, cause: None }).unwrap();
        let partial = LoopParts { measurements: None, estimate: None, ..whole_loop() };
        sink.loop_joined(&JoinedLoop { k: 1, t: 0.001, parts: &partial, cause: None }).unwrap();
        // No command: the applied input is still there.
        let silent = LoopParts { command: None, ..whole_loop() };
        sink.loop_joined(&JoinedLoop { k: 2, t: 0.002, parts: &silent, cause: None }).unwrap();
        sink.finish(&MonitorReport::default()).unwrap();
        drop(sink);
        // A restarted monitor appends, without a second header.
        let mut sink = TrajectoryCsv::open(&setup(true)).unwrap();
        sink.loop_joined(&JoinedLoop { k: 5, t: 0.005, parts: &LoopParts::default(), cause: None }).unwrap();
        sink.finish(&MonitorReport::default()).unwrap();

        let text = std::fs::read_to_string(dir.join("trajectory.csv")).unwrap();
        std::fs::remove_dir_all(&dir).unwrap();
        assert_eq!(
            text,
            "k,t_s,theta_rad,omega_rad_per_s,meas.encoder_rad,meas.imu.x_m_per_s2,meas.imu.y,est.theta_rad,cmd.u_N_m,\
             applied.u_N_m\n\
             0,0,0.5,-1.25,0.1,2,3,0.25,-0.75,-0.5\n\
             1,0.001,0.5,-1.25,,,,,-0.75,-0.5\n\
             2,0.002,0.5,-1.25,0.1,2,3,0.25,,-0.5\n\
             5,0.005,,,,,,,,\n"
        );
    }

    #[test]
    fn every_built_in_column_is_ascii_and_unique() {
        for entry in crate::scenarios::ALL {
            let (config, scenario) = crate::scenarios::resolve(entry.name, &[]).unwrap();
            let columns = crate::model::layout::VectorLayout::new(&config, scenario.as_ref()).trajectory_columns();
            for column in &columns {
                let allowed = |ch: char| ch.is_ascii_alphanumeric() || ch == '_' || ch == '.';
                assert!(column.chars().all(allowed), "{}: column {column:?}", entry.name);
            }
            let unique: std::collections::HashSet<&String> = columns.iter().collect();
            assert_eq!(unique.len(), columns.len(), "{}: {columns:?}", entry.name);
        }
    }
}
