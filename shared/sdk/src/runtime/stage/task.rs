//! Stages as tasks. A task is the plain computation of one stage, input message to output
//! message: it knows nothing of iceoryx2, the clock or the mode. The [`StageRunner`] around it
//! does what every stage does the same way: incarnations, the in-loop faults (delay, drop,
//! corrupt) by loop index, and the counts of the stage's report. The process runner
//! (`runtime::stage::relay`) adds waiting, stamping and publishing; the in-process runner
//! (`runtime::in_process`) calls the same runners in loop order.

use std::collections::VecDeque;
use std::time::Duration;

use anyhow::Result;

use crate::config::faults::CorruptValue;
use crate::config::launch::{LaunchConfig, Mode};
use crate::contract::msg::{Command, Estimate, Measurements, Message, PlantState};
use crate::contract::protocol::StageReport;
use crate::contract::role::Role;
use crate::model::scenario::{Controller, Estimator, Scenario};
use crate::model::sensors::SensorEmulator;
use crate::runtime::stage::faults::{AddedDelay, StageFaults};

/// One stage's computation.
pub trait Task {
    type In: Message;
    type Out: Message;
    /// Whether the task has state to freeze (the process runner then keeps a snapshot).
    const FREEZES: bool = false;
    /// Whether it plays a recording back (`runtime::replay::playback`): its output of each loop is the
    /// recorded one, a loop passed on marked lost included.
    const PLAYS_BACK: bool = false;
    /// Computes this loop's output from its input (the header is the runner's business). An
    /// error (a user's stage that raised) ends the process's incarnation.
    fn process(&mut self, input: &Self::In, output: &mut Self::Out) -> Result<()>;
    /// State worth keeping across a restart (an estimator's calibrated bias, a controller's
    /// integrators), frozen after every loop: at most
    /// [`MAX_FROZEN_BYTES`](crate::runtime::storage::snapshot::MAX_FROZEN_BYTES).
    fn freeze(&self) -> Result<Option<Vec<u8>>> {
        Ok(None)
    }
    /// A restarted task gets its predecessor's frozen state before its first input.
    fn thaw(&mut self, _frozen: &[u8]) -> Result<()> {
        Ok(())
    }
    /// Replaces the output by a corrupt value (`corrupt` faults, which target the command).
    fn corrupt(&self, _output: &mut Self::Out, _value: CorruptValue) {}
    /// Whether this task has no output for loop k (a playback whose recording has none): the
    /// runner sends the loop on marked lost, as a drop fault does in lockstep, so that the
    /// stages after it skip it too.
    fn withheld(&self, _k: u64) -> bool {
        false
    }
}

/// The sensors: every sensor's held reading at the plant's tick.
pub struct SensorsTask {
    emulator: SensorEmulator,
    sensors: usize,
    inputs: usize,
}

impl SensorsTask {
    pub fn new(config: &LaunchConfig, scenario: &dyn Scenario) -> Self {
        let vectors = scenario.vectors();
        Self {
            emulator: SensorEmulator::new(config, vectors.signals),
            sensors: config.sensors.len(),
            inputs: vectors.input.len(),
        }
    }
}

impl Task for SensorsTask {
    type In = PlantState;
    type Out = Measurements;
    fn process(&mut self, state: &PlantState, out: &mut Measurements) -> Result<()> {
        let (k, t) = (state.header.k, state.header.t);
        let u_applied = &state.u_applied[..self.inputs];
        self.emulator.tick(k, t, &state.x, u_applied, &mut out.readings[..self.sensors]);
        out.u_applied = state.u_applied;
        Ok(())
    }
}

/// The scenario's estimator.
pub struct EstimatorTask {
    estimator: Box<dyn Estimator>,
    sensors: usize,
    inputs: usize,
    estimates: usize,
}

impl EstimatorTask {
    pub fn new(config: &LaunchConfig, scenario: &dyn Scenario) -> Self {
        Self::with(scenario.estimator(), config)
    }

    /// Runs `estimator` (a user's own, `runtime::stage::user_stage`) in place of the scenario's.
    pub fn with(estimator: Box<dyn Estimator>, config: &LaunchConfig) -> Self {
        Self {
            estimator,
            sensors: config.sensors.len(),
            inputs: config.schema.input.len(),
            estimates: config.schema.estimate.len(),
        }
    }
}

impl Task for EstimatorTask {
    type In = Measurements;
    type Out = Estimate;
    const FREEZES: bool = true;
    fn process(&mut self, meas: &Measurements, out: &mut Estimate) -> Result<()> {
        let readings = &meas.readings[..self.sensors];
        self.estimator.update(meas.header.t, readings, &meas.u_applied[..self.inputs], &mut out.x[..self.estimates]);
        Ok(())
    }
    fn freeze(&self) -> Result<Option<Vec<u8>>> {
        Ok(self.estimator.freeze())
    }
    fn thaw(&mut self, frozen: &[u8]) -> Result<()> {
        self.estimator.thaw(frozen)
    }
}

/// The scenario's controller.
pub struct ControllerTask {
    controller: Box<dyn Controller>,
    estimates: usize,
    limits: Vec<(f64, f64)>,
}

impl ControllerTask {
    pub fn new(config: &LaunchConfig, scenario: &dyn Scenario) -> Self {
        Self::with(scenario.controller(), config, scenario.input_limits())
    }

    /// Runs `controller` (a user's own, `runtime::stage::user_stage`) in place of the scenario's, its
    /// output clamped to `limits`.
    pub fn with(controller: Box<dyn Controller>, config: &LaunchConfig, limits: Vec<(f64, f64)>) -> Self {
        Self { controller, estimates: config.schema.estimate.len(), limits }
    }
}

impl Task for ControllerTask {
    type In = Estimate;
    type Out = Command;
    const FREEZES: bool = true;
    fn process(&mut self, est: &Estimate, out: &mut Command) -> Result<()> {
        let m = self.limits.len();
        self.controller.update(est.header.t, &est.x[..self.estimates], &mut out.u[..m]);
        Ok(())
    }
    fn freeze(&self) -> Result<Option<Vec<u8>>> {
        Ok(self.controller.freeze())
    }
    fn thaw(&mut self, frozen: &[u8]) -> Result<()> {
        self.controller.thaw(frozen)
    }
    fn corrupt(&self, out: &mut Command, value: CorruptValue) {
        corrupt_command(out, &self.limits, value);
    }
}

/// A `corrupt` fault's command: every input NaN, infinite, or ten times its limit.
pub fn corrupt_command(out: &mut Command, limits: &[(f64, f64)], value: CorruptValue) {
    for (u, (_, hi)) in out.u.iter_mut().zip(limits) {
        *u = match value {
            CorruptValue::Nan => f64::NAN,
            CorruptValue::Inf => f64::INFINITY,
            CorruptValue::OutOfRange => 10.0 * hi.abs().max(1.0),
        };
    }
}

/// What became of one input.
pub struct Handled<Out> {
    /// Real time: a delay fault holds the output back this long before it goes out, while the
    /// stage goes on with the next loops (a transport delay, pipelined as lockstep's).
    pub hold: Option<Duration>,
    /// The output to publish, header set (stamps aside); None if a drop fault took it.
    pub output: Option<Out>,
}

/// Runs one task the way every stage runs: see the module's documentation.
///
/// A restart upstream shows in the data: every header carries the incarnation of each process
/// that handled the loop, so the runner sees a new one arrive, logs it and counts it. A restarted
/// stage itself starts from nothing but its task's frozen state.
pub struct StageRunner<T: Task> {
    pub task: T,
    role: Role,
    slot: usize,
    incarnation: u32,
    faults: StageFaults,
    /// Lockstep delay line: the outputs computed in the last loops, newest last.
    computed: VecDeque<T::Out>,
    keep: usize,
    /// Real time: a dropped output is not sent; lockstep: it is sent marked lost, so the loop
    /// goes on and the plant holds its command.
    drop_sends_lost: bool,
    upstream: Option<[u32; 4]>,
    last_k: Option<u64>,
    /// A replay's stage: the loops its recording skipped, which it skips again (passes on
    /// marked lost, as a lost input).
    replay_skips: Vec<[u64; 2]>,
    pub report: StageReport,
}

impl<T: Task> StageRunner<T> {
    pub fn new(task: T, role: Role, config: &LaunchConfig, incarnation: u32) -> Self {
        let faults = StageFaults::for_role(config, role);
        let keep = faults.max_delay_ticks() as usize + 1;
        Self {
            task,
            role,
            slot: role.slot().expect("a stage has an incarnation slot"),
            incarnation,
            faults,
            computed: VecDeque::new(),
            keep,
            drop_sends_lost: config.mode == Mode::Lockstep,
            upstream: None,
            last_k: None,
            replay_skips: config
                .replay
                .as_ref()
                .filter(|r| !r.closed_loop && r.stage == role.name())
                .map(|r| r.skipped.clone())
                .unwrap_or_default(),
            report: StageReport::default(),
        }
    }

    /// Handles the input of one loop; an error of the task's computation ends the stage.
    pub fn handle(&mut self, input: &T::In) -> Result<Handled<T::Out>> {
        let header = *input.header();
        let k = header.k;
        let mut seen = header.incarnations;
        seen[self.slot..].fill(0);
        if self.upstream.is_some_and(|u| u != seen) {
            self.report.upstream_restarts += 1;
            eprintln!("{}: loop {k}: an upstream process restarted (incarnations {seen:?})", self.role);
        }
        self.upstream = Some(seen);

        // A loop dropped upstream (lockstep) is passed on, not computed: like a lost message in
        // real time, this stage does not run for it; nor for a loop a replay's recording of it
        // skipped. A playback's output is the recorded one either way.
        let skipped = self.replay_skips.iter().any(|[from, to]| (*from..=*to).contains(&k));
        let mut out = if (header.lost == 0 && !skipped) || T::PLAYS_BACK {
            let mut out = T::Out::default();
            self.task.process(input, &mut out)?;
            if let Some(value) = self.faults.corrupt(k) {
                self.task.corrupt(&mut out, value);
            }
            out
        } else {
            self.computed.back().copied().unwrap_or_default()
        };
        self.computed.push_back(out);
        if self.computed.len() > self.keep {
            self.computed.pop_front();
        }
        let mut hold = None;
        match self.faults.delay(k) {
            Some(AddedDelay::Wall(d)) => hold = Some(d),
            Some(AddedDelay::Ticks(d)) => {
                // What was computed d loops ago, or the oldest kept at the start of a run.
                out = self.computed[self.computed.len().saturating_sub(1 + d as usize)];
            }
            None => {}
        }
        *out.header_mut() = header;
        out.header_mut().set_incarnation(self.role, self.incarnation);
        if self.task.withheld(k) || skipped {
            out.header_mut().lost = 1;
        } else if self.faults.drops(k) {
            self.report.dropped_by_fault += 1;
            if !self.drop_sends_lost {
                return Ok(Handled { hold, output: None });
            }
            out.header_mut().lost = 1;
        }
        self.report.processed += 1;
        if let Some(last) = self.last_k {
            self.report.skipped += k.saturating_sub(last + 1);
        }
        self.last_k = Some(k);
        Ok(Handled { hold, output: Some(out) })
    }
}
