//! The in-process twin of the five processes: the same plant core and the same stage runners
//! and tasks, called in loop order in one thread, with no IPC. Lockstep only: it is the
//! lockstep run without the transport, so its trajectory is byte-identical to the five-process
//! run's (tests/trajectory_hashes.rs proves it for every scenario and case). Faults done to a process
//! from outside (kill, stop) need processes and are refused.

use std::collections::BTreeMap;

use anyhow::{Result, bail};

use crate::config::faults::FaultKind;
use crate::config::launch::{LaunchConfig, Mode};
use crate::contract::clock::now_ns;
use crate::contract::msg::{Command, Estimate, LoopMessage, Measurements, Message, PlantState, TickTiming};
use crate::contract::protocol::{PlantReport, StageReport};
use crate::contract::role::Role;
use crate::model::scenario::Scenario;
use crate::runtime::replay::playback::Playback;
use crate::runtime::signals::StopFlag;
use crate::runtime::stage::plant::PlantCore;
use crate::runtime::stage::task::{ControllerTask, EstimatorTask, SensorsTask, StageRunner, Task};

/// What the in-process run's "processes" report at its end.
#[derive(Debug, Clone)]
pub struct InProcessReports {
    pub plant: PlantReport,
    /// Each stage's reports by incarnation (a replay's stage restarts where its recording did).
    pub stages: BTreeMap<Role, BTreeMap<u32, StageReport>>,
}

/// Why `config` cannot run in one process, if it cannot.
pub fn refusal(config: &LaunchConfig) -> Option<String> {
    if config.mode != Mode::Lockstep {
        return Some("only lockstep runs in one process (real time needs the processes it measures)".into());
    }
    if let Some((host, _)) = config.hosts.remote() {
        return Some(format!("the launch file places a stage on host {host}; one process runs on one machine"));
    }
    if config.realtime.any() {
        return Some(
            "[realtime] sets the priority of the loop's processes, and one process has none of its own".into(),
        );
    }
    if config.trace_sched {
        return Some(
            "trace_sched names the processes that waited for the CPU, and one process has none of its own".into(),
        );
    }
    if let Some(plant) = &config.stages.plant {
        return Some(format!(
            "plant.python runs the plant as a Python process of its own (`{}`); run it as five processes",
            crate::config::python_plant::spec(plant)
        ));
    }
    if let Some((role, stage)) = config.stages.commands.iter().next() {
        return Some(format!("stages.{role}.command runs the {role} as a process of its own (`{}`)", stage.text()));
    }
    // A replay's stage restarts where its recording did (`kill` faults): in one process its
    // task is made again and thaws what the last one froze.
    let replayed = config.replay.as_ref().filter(|r| !r.closed_loop).map(|r| r.stage.as_str());
    config
        .faults
        .iter()
        .filter(|f| !(f.kind == FaultKind::Kill && Some(f.process.as_str()) == replayed))
        .find(|f| f.kind.from_outside())
        .map(|f| format!("`{}` needs a process to {} (kill and stop faults do)", f.describe(), f.kind.name()))
}

/// Runs every loop of `config` in order, handing each message to `observe` as the monitor
/// would receive it, until the run ends or a stop is requested. In an open-loop replay
/// (`runtime::replay::playback`) the processes other than the replayed stage play the recording back.
pub fn run(
    config: &LaunchConfig,
    scenario: &dyn Scenario,
    stop: &StopFlag,
    observe: impl FnMut(LoopMessage) -> Result<()>,
) -> Result<InProcessReports> {
    if let Some(why) = refusal(config) {
        bail!("cannot run in one process: {why}");
    }
    let sensors = || SensorsTask::new(config, scenario);
    let estimator = || EstimatorTask::new(config, scenario);
    let controller = || ControllerTask::new(config, scenario);
    let Some(playback) = Playback::load(config, scenario)? else {
        let plant = PlantCore::new(config, scenario, 0);
        return Loop { config, stop, plant }.run(sensors, estimator, controller, observe);
    };
    let plant = PlantCore::with_plant(config, scenario.input_limits(), playback.plant(), 0);
    let run = Loop { config, stop, plant };
    match config.replay.as_ref().map(|r| r.role()) {
        Some(Role::Sensors) => run.run(sensors, || playback.estimator(), || playback.controller(), observe),
        Some(Role::Estimator) => run.run(|| playback.sensors(), estimator, || playback.controller(), observe),
        _ => run.run(|| playback.sensors(), || playback.estimator(), controller, observe),
    }
}

/// The loop of one run in one thread.
struct Loop<'a> {
    config: &'a LaunchConfig,
    stop: &'a StopFlag,
    plant: PlantCore,
}

impl Loop<'_> {
    /// Runs the loop with the three stages' tasks from these makers. A stage that a `kill` fault
    /// targets (a replay's stage, where its recording restarted it) is made again at the fault's
    /// tick and thaws what the last one froze, as a restarted process does.
    fn run<S, E, C>(
        mut self,
        sensors: impl Fn() -> S,
        estimator: impl Fn() -> E,
        controller: impl Fn() -> C,
        mut observe: impl FnMut(LoopMessage) -> Result<()>,
    ) -> Result<InProcessReports>
    where
        S: Task<In = PlantState, Out = Measurements>,
        E: Task<In = Measurements, Out = Estimate>,
        C: Task<In = Estimate, Out = Command>,
    {
        let config = self.config;
        let mut s = Stage::new(sensors, Role::Sensors, config);
        let mut e = Stage::new(estimator, Role::Estimator, config);
        let mut c = Stage::new(controller, Role::Controller, config);
        let plant = &mut self.plant;
        let loops = config.loops();
        while plant.k < loops && !self.stop.requested() {
            let state = plant.state_message(TickTiming::default(), now_ns());
            observe(LoopMessage::State(state))?;
            let measurements = s.pass(&state)?;
            observe(LoopMessage::Measurements(measurements))?;
            let estimate = e.pass(&measurements)?;
            observe(LoopMessage::Estimate(estimate))?;
            let command = c.pass(&estimate)?;
            observe(LoopMessage::Command(command))?;
            let record = plant.accept(&command, now_ns());
            observe(LoopMessage::Loop(record))?;
            plant.advance()?;
        }
        plant.finish(loops);
        let stages = BTreeMap::from([s.reports(), e.reports(), c.reports()]);
        Ok(InProcessReports { plant: plant.report.clone(), stages })
    }
}

/// One stage of the in-process loop: its runner, and how to make its task again.
struct Stage<'a, T: Task, M: Fn() -> T> {
    make: M,
    runner: StageRunner<T>,
    role: Role,
    config: &'a LaunchConfig,
    /// The ticks at which a `kill` fault restarts it.
    kills: Vec<u64>,
    /// The reports of its earlier incarnations.
    earlier: BTreeMap<u32, StageReport>,
}

impl<'a, T: Task, M: Fn() -> T> Stage<'a, T, M> {
    fn new(make: M, role: Role, config: &'a LaunchConfig) -> Self {
        let kills = config
            .faults
            .iter()
            .filter(|f| f.kind == FaultKind::Kill && f.process == role.name())
            .map(|f| f.ticks(config.rate_hz).0)
            .collect();
        let runner = StageRunner::new(make(), role, config, 0);
        Self { make, runner, role, config, kills, earlier: BTreeMap::new() }
    }

    /// Handles the input of one stage and stamps its output, as the stage's process would.
    fn pass(&mut self, input: &T::In) -> Result<T::Out> {
        let k = input.header().k;
        if self.kills.contains(&k) {
            // The process keeps its frozen state before each output goes out (lockstep), and its
            // successor thaws it before its first input.
            let frozen = crate::runtime::storage::snapshot::stage_frozen(self.runner.task.freeze()?)?;
            let incarnation = self.earlier.len() as u32 + 1;
            let next = StageRunner::new((self.make)(), self.role, self.config, incarnation);
            let last = std::mem::replace(&mut self.runner, next);
            self.earlier.insert(incarnation - 1, last.report);
            if let Some(frozen) = frozen {
                self.runner.task.thaw(&frozen)?;
            }
        }
        let received = now_ns();
        let mut out = self.runner.handle(input)?.output.expect("lockstep sends a dropped output marked lost");
        out.header_mut().trace.stamp(self.role, received, now_ns());
        Ok(out)
    }

    fn reports(self) -> (Role, BTreeMap<u32, StageReport>) {
        let mut reports = self.earlier;
        reports.insert(reports.len() as u32, self.runner.report);
        (self.role, reports)
    }
}
