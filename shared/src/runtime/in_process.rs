//! The in-process twin of the five processes: the same plant core and the same stage runners
//! and tasks, called in loop order in one thread, with no IPC. Lockstep only: it is the
//! lockstep run without the transport, so its trajectory is byte-identical to the five-process
//! run's (tests/trajectory_hashes.rs proves it for every scenario and case). Faults done to a process
//! from outside (kill, stop) need processes and are refused.

use anyhow::{Result, bail};

use crate::config::launch::{LaunchConfig, Mode};
use crate::contract::clock::now_ns;
use crate::contract::msg::{LoopMessage, Message, TickTiming};
use crate::contract::protocol::{PlantReport, StageReport};
use crate::contract::role::Role;
use crate::model::scenario::Scenario;
use crate::runtime::plant::PlantCore;
use crate::runtime::signals::StopFlag;
use crate::runtime::task::{ControllerTask, EstimatorTask, SensorsTask, StageRunner, Task};

/// What the in-process run's "processes" report at its end.
#[derive(Debug, Clone)]
pub struct InProcessReports {
    pub plant: PlantReport,
    pub sensors: StageReport,
    pub estimator: StageReport,
    pub controller: StageReport,
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
    if let Some(plant) = &config.stages.plant {
        return Some(format!(
            "plant.python runs the plant as a Python process of its own (`{}`); run it as five processes",
            crate::config::python_plant::spec(plant)
        ));
    }
    if let Some((role, stage)) = config.stages.commands.iter().next() {
        return Some(format!("stages.{role}.command runs the {role} as a process of its own (`{}`)", stage.text()));
    }
    config
        .faults
        .iter()
        .find(|f| f.kind.from_outside())
        .map(|f| format!("`{}` needs a process to {} (kill and stop faults do)", f.describe(), f.kind.name()))
}

/// Handles the input of one stage and stamps its output, as the stage's process would.
fn pass<T: Task>(runner: &mut StageRunner<T>, role: Role, input: &T::In) -> Result<T::Out> {
    let received = now_ns();
    let mut out = runner.handle(input)?.output.expect("lockstep sends a dropped output marked lost");
    out.header_mut().trace.stamp(role, received, now_ns());
    Ok(out)
}

/// Runs every loop of `config` in order, handing each message to `observe` as the monitor
/// would receive it, until the run ends or a stop is requested.
pub fn run(
    config: &LaunchConfig,
    scenario: &dyn Scenario,
    stop: &StopFlag,
    mut observe: impl FnMut(LoopMessage) -> Result<()>,
) -> Result<InProcessReports> {
    if let Some(why) = refusal(config) {
        bail!("cannot run in one process: {why}");
    }
    let mut plant = PlantCore::new(config, scenario, 0);
    let mut sensors = StageRunner::new(SensorsTask::new(config, scenario), Role::Sensors, config, 0);
    let mut estimator = StageRunner::new(EstimatorTask::new(config, scenario), Role::Estimator, config, 0);
    let mut controller = StageRunner::new(ControllerTask::new(scenario), Role::Controller, config, 0);
    let loops = config.loops();
    while plant.k < loops && !stop.requested() {
        let state = plant.state_message(TickTiming::default(), now_ns());
        observe(LoopMessage::State(state))?;
        let measurements = pass(&mut sensors, Role::Sensors, &state)?;
        observe(LoopMessage::Measurements(measurements))?;
        let estimate = pass(&mut estimator, Role::Estimator, &measurements)?;
        observe(LoopMessage::Estimate(estimate))?;
        let command = pass(&mut controller, Role::Controller, &estimate)?;
        observe(LoopMessage::Command(command))?;
        let record = plant.accept(&command, now_ns());
        observe(LoopMessage::Loop(record))?;
        plant.advance()?;
    }
    plant.finish(loops);
    Ok(InProcessReports {
        plant: plant.report.clone(),
        sensors: sensors.report,
        estimator: estimator.report,
        controller: controller.report,
    })
}
