//! A stage of the user's own: their computation, LoopLab's runner. A launch file's
//! `[stages.<role>] command` starts the user's program in place of the built-in stage; that
//! program calls one of the functions here (directly from Rust, through the `looplab` Python
//! module or the `looplab_stage` C library), which runs the same relay as the built-in stages:
//! waiting, stamps, incarnations, in-loop faults, snapshots, the ready and report lines and the
//! signals. The user's code is called once per loop with the stage's input and output.
//!
//! A [`Step`] sees every stage as flat numbers (see [`StageInfo`] for the names):
//! - controller: the estimate in, the command out;
//! - estimator: each sensor's reading (its components, then `valid`, `fresh` and
//!   `sample_time`), then the applied input (`u_applied.<input>`) in; the estimate out;
//! - sensors: the plant's state, then the applied input in; each sensor's reading out (it starts
//!   as a valid, fresh sample at t: the step writes the values and may say otherwise).
//!
//! The output starts at zero every loop, as a built-in stage's does.

use std::path::Path;
use std::process::ExitCode;

use anyhow::{Context as _, Result, anyhow};

use crate::config::faults::CorruptValue;
use crate::config::launch::{LaunchConfig, load_run_config};
use crate::config::schema::Component;
use crate::contract::msg::{Command, Estimate, Measurements, Message, PlantState, layout_fingerprint, layout_mismatch};
use crate::contract::protocol::{ChildEvent, ProcessArgs, stage_env};
use crate::contract::role::Role;
use crate::model::reference::{NamedReference, declared_references};
use crate::model::scenario::{Controller, Estimator};
use crate::runtime::stage::child::{Context, keep_stdout_for_events, run_process_as};
use crate::runtime::stage::relay::relay;
use crate::runtime::stage::task::{ControllerTask, EstimatorTask, Task, corrupt_command};

pub use crate::runtime::storage::snapshot::MAX_FROZEN_BYTES;

/// What a user's stage is told when it starts.
pub struct StageInfo<'a> {
    pub role: Role,
    /// The run's resolved launch file (`config.document` is all of it; `config.schema` names the
    /// vectors and `config.input_limits` limits the input, as the launcher resolved them).
    pub config: &'a LaunchConfig,
    /// 0 for the first start in the run, then one more per restart.
    pub incarnation: u32,
    /// The names of the step's input numbers, in order.
    pub input_names: Vec<String>,
    /// The names of the step's output numbers, in order.
    pub output_names: Vec<String>,
    /// A declared system's references (`[reference]`), in order: what each names
    /// (`state.position`) and its signal; [`StageInfo::reference`] evaluates them.
    pub references: Vec<NamedReference>,
}

/// A user's computation of one stage, in any language.
pub trait Step {
    /// Computes this loop's `output` from its `input` at simulation time `t`; an error ends
    /// this incarnation of the stage (the restart policy applies).
    fn step(&mut self, t: f64, input: &[f64], output: &mut [f64]) -> Result<()>;
    /// State to keep across a restart (at most [`MAX_FROZEN_BYTES`]), taken after every loop.
    fn freeze(&self) -> Result<Option<Vec<u8>>> {
        Ok(None)
    }
    /// A restarted stage gets its predecessor's frozen state before its first step.
    fn thaw(&mut self, _frozen: &[u8]) -> Result<()> {
        Ok(())
    }
}

/// Runs the stage the launcher started (the environment says which) with `make`'s step.
pub fn run_step(make: impl FnOnce(&StageInfo) -> Result<Box<dyn Step>>) -> ExitCode {
    run_step_as_build(layout_fingerprint(), make)
}

/// [`run_step`] as a process built with message layouts of fingerprint `layout` would: only a
/// test that plays a stage from another build has a reason to call it.
#[doc(hidden)]
pub fn run_step_as_build(layout: &str, make: impl FnOnce(&StageInfo) -> Result<Box<dyn Step>>) -> ExitCode {
    run_stage(&Role::STAGES, layout, |context, role| {
        let layout = StageNumbers::new(&context.config);
        let info = layout.info(role, context)?;
        let step = make(&info).context("the stage's constructor failed")?;
        match role {
            Role::Sensors => relay(context, role, UserTask::sensors(step, layout)),
            Role::Estimator => relay(context, role, UserTask::estimator(step, layout)),
            _ => relay(context, role, UserTask::controller(step, layout, input_limits(&context.config))),
        }
    })
}

/// Runs `make`'s controller as the controller stage: a Rust crate of the user's own, with the
/// scenario's own [`Controller`] trait.
pub fn run_controller(make: impl FnOnce(&StageInfo) -> Result<Box<dyn Controller>>) -> ExitCode {
    run_stage(&[Role::Controller], layout_fingerprint(), |context, role| {
        let info = StageNumbers::new(&context.config).info(role, context)?;
        let controller = make(&info).context("the controller's constructor failed")?;
        relay(context, role, ControllerTask::with(controller, &context.config, input_limits(&context.config)))
    })
}

/// Runs `make`'s estimator as the estimator stage, as [`run_controller`] does a controller.
pub fn run_estimator(make: impl FnOnce(&StageInfo) -> Result<Box<dyn Estimator>>) -> ExitCode {
    run_stage(&[Role::Estimator], layout_fingerprint(), |context, role| {
        let info = StageNumbers::new(&context.config).info(role, context)?;
        let estimator = make(&info).context("the estimator's constructor failed")?;
        relay(context, role, EstimatorTask::with(estimator, &context.config))
    })
}

/// The process of a user's stage: the role and run from the environment, then `body`.
pub(crate) fn run_stage(
    roles: &[Role],
    layout: &str,
    body: impl FnOnce(&Context, Role) -> Result<ChildEvent>,
) -> ExitCode {
    let names = || roles.iter().map(|r| r.name()).collect::<Vec<_>>().join(", ");
    let Some((role_name, args)) = ProcessArgs::from_env() else {
        eprintln!(
            "error: this program is a LoopLab stage ({}): start it from a launch file's [stages.<role>] command \
             with `looplab run`, which sets {} and the run's other variables",
            names(),
            stage_env::ROLE
        );
        return ExitCode::from(2);
    };
    let role = match role_name.parse::<Role>() {
        Ok(role) if roles.contains(&role) => role,
        _ => {
            eprintln!("error: the launcher started this program as the {role_name}; it can run as: {}", names());
            return ExitCode::from(2);
        }
    };
    // The launcher's build against this one's, before anything connects: a stage from another
    // build is the one refused (every port checks it too, `runtime::transport::ipc`).
    if let Ok(theirs) = std::env::var(stage_env::LAYOUT)
        && theirs != layout
    {
        eprintln!("{role}: error: {}", layout_mismatch("the launcher's messages have", &theirs, layout));
        return ExitCode::FAILURE;
    }
    if let Err(e) = keep_stdout_for_events() {
        eprintln!("{role}: error: {e:#}");
        return ExitCode::FAILURE;
    }
    // The run's vectors from its launch.toml: a stage serves whatever catalog the launcher has.
    let load = |launch: &Path| Ok((load_run_config(launch)?, ()));
    run_process_as(role, &args, layout, load, |context, ()| body(context, role))
}

/// The input's limits the launcher resolved (a run's launch.toml read by `load_run_config` has
/// them).
pub(crate) fn input_limits(config: &LaunchConfig) -> Vec<(f64, f64)> {
    config.input_limits.clone().expect("a run's launch.toml has its vectors")
}

/// The names of `role`'s step input and output numbers, in order (what [`StageInfo`] says; the
/// C library computes them before its stage runs).
pub fn stage_names(role: Role, config: &LaunchConfig) -> (Vec<String>, Vec<String>) {
    let names = |list: &[Component]| list.iter().map(|c| c.name.to_owned()).collect::<Vec<_>>();
    let schema = &config.schema;
    let applied: Vec<String> = schema.input.iter().map(|c| format!("u_applied.{}", c.name)).collect();
    let mut readings = Vec::new();
    for (name, spec) in &config.sensors {
        for c in config.signal_of(spec).components {
            readings.push(format!("{name}.{}", c.name));
        }
        readings.extend(["valid", "fresh", "sample_time"].map(|extra| format!("{name}.{extra}")));
    }
    match role {
        Role::Sensors => ([names(schema.state), applied].concat(), readings),
        Role::Estimator => ([readings, applied].concat(), names(schema.estimate)),
        _ => {
            let references = appended_references(config).into_iter().map(|r| format!("reference.{}", r.track));
            (names(schema.estimate).into_iter().chain(references).collect(), names(schema.input))
        }
    }
}

/// The references a controller's input carries after the estimate (`[stages.controller]
/// with_reference = true`); none otherwise.
fn appended_references(config: &LaunchConfig) -> Vec<NamedReference> {
    let asked = config.stages.command(Role::Controller).is_some_and(|stage| stage.with_reference);
    // A launch file whose [reference] does not read is refused at load; none here.
    if asked { declared_references(config).unwrap_or_default() } else { Vec::new() }
}

/// The number at dotted `key` of a launch document (`"controller.gains.1"`: tables by name,
/// arrays by index); an integer reads as its float. None if missing or not a number.
pub fn config_number(document: &toml::Table, key: &str) -> Option<f64> {
    let mut parts = key.split('.');
    let mut value = document.get(parts.next()?)?;
    for part in parts {
        value = match value {
            toml::Value::Table(table) => table.get(part)?,
            toml::Value::Array(array) => array.get(part.parse::<usize>().ok()?)?,
            _ => return None,
        };
    }
    match value {
        toml::Value::Float(x) => Some(*x),
        toml::Value::Integer(i) => Some(*i as f64),
        _ => None,
    }
}

impl StageInfo<'_> {
    /// Each reference at simulation time `t`, in the order of [`StageInfo::references`].
    pub fn reference(&self, t: f64) -> Vec<f64> {
        self.references.iter().map(|r| r.signal.at(t)).collect()
    }

    /// The number at dotted `key` of the run's launch file ([`config_number`]), or an error
    /// naming the key.
    pub fn number(&self, key: &str) -> Result<f64> {
        config_number(&self.config.document, key).ok_or_else(|| anyhow!("the launch file has no number at {key}"))
    }
}

/// Where each stage's numbers are in its messages.
struct StageNumbers {
    state: usize,
    inputs: usize,
    estimates: usize,
    /// Each sensor's components.
    sensor_dims: Vec<usize>,
    /// Each sensor's samples so far (a user's sensors stage counts them here).
    sensor_seq: Vec<u64>,
    /// The references the controller's input carries after the estimate.
    references: Vec<NamedReference>,
}

/// A sensor's numbers after its components: valid, fresh, sample_time.
const READING_EXTRAS: usize = 3;

impl StageNumbers {
    fn new(config: &LaunchConfig) -> Self {
        let schema = &config.schema;
        let sensor_dims: Vec<usize> = config.sensors.values().map(|s| config.signal_of(s).components.len()).collect();
        Self {
            state: schema.state.len(),
            inputs: schema.input.len(),
            estimates: schema.estimate.len(),
            sensor_seq: vec![0; sensor_dims.len()],
            sensor_dims,
            references: appended_references(config),
        }
    }

    fn info<'a>(&self, role: Role, context: &'a Context) -> Result<StageInfo<'a>> {
        let config = &context.config;
        let (input_names, output_names) = stage_names(role, config);
        let references = declared_references(config)?;
        Ok(StageInfo { role, config, incarnation: context.incarnation, input_names, output_names, references })
    }

    fn readings_len(&self) -> usize {
        self.sensor_dims.iter().map(|d| d + READING_EXTRAS).sum()
    }

    fn read_readings(&self, meas: &Measurements, into: &mut [f64]) -> usize {
        let mut i = 0;
        for (reading, &dim) in meas.readings.iter().zip(&self.sensor_dims) {
            into[i..i + dim].copy_from_slice(&reading.value[..dim]);
            into[i + dim] = reading.valid as f64;
            into[i + dim + 1] = reading.fresh as f64;
            into[i + dim + 2] = reading.sample_time;
            i += dim + READING_EXTRAS;
        }
        i
    }
}

/// A [`Step`] as the task of one stage: copies its input out of the message and its output
/// into one (a few numbers; the user's code sees the same two buffers every loop).
struct UserTask<I, O> {
    step: Box<dyn Step>,
    layout: StageNumbers,
    input: Vec<f64>,
    output: Vec<f64>,
    read: fn(&StageNumbers, &I, &mut [f64]),
    start: fn(&StageNumbers, f64, &mut [f64]),
    write: fn(&mut StageNumbers, &I, &[f64], &mut O),
    limits: Vec<(f64, f64)>,
    corrupt: fn(&[(f64, f64)], &mut O, CorruptValue),
}

fn zeros(_: &StageNumbers, _t: f64, output: &mut [f64]) {
    output.fill(0.0);
}

fn no_corruption<O>(_: &[(f64, f64)], _: &mut O, _: CorruptValue) {}

impl<I, O> UserTask<I, O> {
    fn new(
        step: Box<dyn Step>,
        layout: StageNumbers,
        (inputs, outputs): (usize, usize),
        read: fn(&StageNumbers, &I, &mut [f64]),
        start: fn(&StageNumbers, f64, &mut [f64]),
        write: fn(&mut StageNumbers, &I, &[f64], &mut O),
    ) -> Self {
        Self {
            step,
            layout,
            input: vec![0.0; inputs],
            output: vec![0.0; outputs],
            read,
            start,
            write,
            limits: vec![],
            corrupt: no_corruption,
        }
    }
}

impl UserTask<PlantState, Measurements> {
    fn sensors(step: Box<dyn Step>, layout: StageNumbers) -> Self {
        let sizes = (layout.state + layout.inputs, layout.readings_len());
        let read = |l: &StageNumbers, s: &PlantState, into: &mut [f64]| {
            into[..l.state].copy_from_slice(&s.x[..l.state]);
            into[l.state..].copy_from_slice(&s.u_applied[..l.inputs]);
        };
        let start = |l: &StageNumbers, t: f64, out: &mut [f64]| {
            out.fill(0.0);
            let mut i = 0;
            for &dim in &l.sensor_dims {
                out[i + dim..i + dim + READING_EXTRAS].copy_from_slice(&[1.0, 1.0, t]);
                i += dim + READING_EXTRAS;
            }
        };
        let write = |l: &mut StageNumbers, s: &PlantState, from: &[f64], out: &mut Measurements| {
            let mut i = 0;
            for ((reading, &dim), seq) in out.readings.iter_mut().zip(&l.sensor_dims).zip(&mut l.sensor_seq) {
                reading.value[..dim].copy_from_slice(&from[i..i + dim]);
                reading.valid = (from[i + dim] != 0.0) as u32;
                reading.fresh = (from[i + dim + 1] != 0.0) as u32;
                reading.sample_time = from[i + dim + 2];
                reading.seq = seq.saturating_sub(1);
                if reading.fresh != 0 {
                    reading.seq = *seq;
                    *seq += 1;
                }
                i += dim + READING_EXTRAS;
            }
            out.u_applied = s.u_applied;
        };
        Self::new(step, layout, sizes, read, start, write)
    }
}

impl UserTask<Measurements, Estimate> {
    fn estimator(step: Box<dyn Step>, layout: StageNumbers) -> Self {
        let sizes = (layout.readings_len() + layout.inputs, layout.estimates);
        let read = |l: &StageNumbers, m: &Measurements, into: &mut [f64]| {
            let i = l.read_readings(m, into);
            into[i..].copy_from_slice(&m.u_applied[..l.inputs]);
        };
        let write = |l: &mut StageNumbers, _: &Measurements, from: &[f64], out: &mut Estimate| {
            out.x[..l.estimates].copy_from_slice(from);
        };
        Self::new(step, layout, sizes, read, zeros, write)
    }
}

impl UserTask<Estimate, Command> {
    fn controller(step: Box<dyn Step>, layout: StageNumbers, limits: Vec<(f64, f64)>) -> Self {
        let sizes = (layout.estimates + layout.references.len(), layout.inputs);
        let read = |l: &StageNumbers, e: &Estimate, into: &mut [f64]| {
            into[..l.estimates].copy_from_slice(&e.x[..l.estimates]);
            let t = e.header().t;
            for (value, reference) in into[l.estimates..].iter_mut().zip(&l.references) {
                *value = reference.signal.at(t);
            }
        };
        let write = |l: &mut StageNumbers, _: &Estimate, from: &[f64], out: &mut Command| {
            out.u[..l.inputs].copy_from_slice(from);
        };
        let mut task = Self::new(step, layout, sizes, read, zeros, write);
        task.limits = limits;
        task.corrupt = |limits, out, value| corrupt_command(out, limits, value);
        task
    }
}

impl<I: Message, O: Message> Task for UserTask<I, O> {
    type In = I;
    type Out = O;
    const FREEZES: bool = true;

    fn process(&mut self, input: &I, output: &mut O) -> Result<()> {
        let t = input.header().t;
        (self.read)(&self.layout, input, &mut self.input);
        (self.start)(&self.layout, t, &mut self.output);
        self.step.step(t, &self.input, &mut self.output).with_context(|| format!("step failed at t = {t:.6} s"))?;
        (self.write)(&mut self.layout, input, &self.output, output);
        Ok(())
    }

    fn freeze(&self) -> Result<Option<Vec<u8>>> {
        self.step.freeze().context("freeze failed")
    }

    fn thaw(&mut self, frozen: &[u8]) -> Result<()> {
        self.step.thaw(frozen).context("thaw failed")
    }

    fn corrupt(&self, output: &mut O, value: CorruptValue) {
        (self.corrupt)(&self.limits, output, value);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn config_numbers_by_dotted_key() {
        let document: toml::Table = toml::from_str("[controller]\ngains = [-378.0, -55, -1.5]\nkind = \"x\"").unwrap();
        let number = |key| config_number(&document, key);
        assert_eq!((number("controller.gains.0"), number("controller.gains.1")), (Some(-378.0), Some(-55.0)));
        assert_eq!(number("controller.gains.2"), Some(-1.5));
        for missing in ["controller.gains.3", "controller.gains", "controller.kind", "controller.x", "model", ""] {
            assert_eq!(number(missing), None, "{missing}");
        }
    }
}
