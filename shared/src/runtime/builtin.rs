//! The bodies of LoopLab's own loop processes (`services/`, and a crate of its own that builds
//! them with its catalog: `runtime::stage::child::process_main_with`): each runs its part of the
//! scenario, or in an open-loop replay plays its recording back.

use anyhow::Result;

use crate::contract::protocol::ChildEvent;
use crate::contract::role::Role;
use crate::model::scenario::Scenario;
use crate::runtime::replay::playback::Playback;
use crate::runtime::stage::child::Context;
use crate::runtime::stage::plant::run_with;
use crate::runtime::stage::relay::relay;
use crate::runtime::stage::task::{ControllerTask, EstimatorTask, SensorsTask};

pub fn plant(context: &Context, scenario: &dyn Scenario) -> Result<ChildEvent> {
    let limits = scenario.input_limits();
    match playback(context, scenario, Role::Plant)? {
        Some(playback) => run_with(context, playback.plant(), limits),
        None => run_with(context, scenario.plant(), limits),
    }
}

pub fn sensors(context: &Context, scenario: &dyn Scenario) -> Result<ChildEvent> {
    match playback(context, scenario, Role::Sensors)? {
        Some(playback) => relay(context, Role::Sensors, playback.sensors()),
        None => relay(context, Role::Sensors, SensorsTask::new(&context.config, scenario)),
    }
}

pub fn estimator(context: &Context, scenario: &dyn Scenario) -> Result<ChildEvent> {
    match playback(context, scenario, Role::Estimator)? {
        Some(playback) => relay(context, Role::Estimator, playback.estimator()),
        None => relay(context, Role::Estimator, EstimatorTask::new(&context.config, scenario)),
    }
}

pub fn controller(context: &Context, scenario: &dyn Scenario) -> Result<ChildEvent> {
    match playback(context, scenario, Role::Controller)? {
        Some(playback) => relay(context, Role::Controller, playback.controller()),
        None => relay(context, Role::Controller, ControllerTask::new(&context.config, scenario)),
    }
}

/// The recording `role` plays back, when it does (an open-loop replay's other processes).
fn playback(context: &Context, scenario: &dyn Scenario, role: Role) -> Result<Option<Playback>> {
    if !context.config.replay.as_ref().is_some_and(|r| r.plays_back(role)) {
        return Ok(None);
    }
    Playback::load(&context.config, scenario)
}
