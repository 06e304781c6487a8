//! The loop's stages: sensors, estimator and controller, and what every loop process shares.
//! Each binary in `services/` is one call into here; the plant is in `crate::plant`, the monitor
//! in `crate::monitor`.

use std::collections::VecDeque;
use std::fmt::Debug;
use std::path::Path;
use std::process::ExitCode;
use std::time::Duration;

use anyhow::{Result, anyhow};
use iceoryx2::prelude::*;

use crate::clock::now_ns;
use crate::faults::{AddedDelay, CorruptValue, StageFaults};
use crate::ipc::{Ipc, Topic, TopicPublisher, TopicSubscriber};
use crate::config::launch::{LaunchConfig, Mode};
use crate::scenarios::load_resolved;
use crate::msg::*;
use crate::protocol::{ChildEvent, ProcessArgs, StageReport, emit};
use crate::scenarios::{Calibration, Scenario};
use crate::sensors::SensorEmulator;
use crate::signals::StopFlag;
use crate::snapshot::Snapshot;
use crate::wait::{ArrivalModel, Waiter};

/// Longest a wait blocks before it looks at the stop flag again (a signal also ends it early).
const WAIT_SLICE: Duration = Duration::from_millis(100);

/// Every message carries the loop header.
pub trait Message: Copy + Default + Debug + ZeroCopySend + 'static {
    fn header(&self) -> &Header;
    fn header_mut(&mut self) -> &mut Header;
}

macro_rules! impl_message {
    ($($t:ty),*) => {$(
        impl Message for $t {
            fn header(&self) -> &Header { &self.header }
            fn header_mut(&mut self) -> &mut Header { &mut self.header }
        }
    )*};
}
impl_message!(PlantState, Measurements, Estimate, Command, LoopRecord);

/// What every loop process starts with.
pub struct Context {
    pub config: LaunchConfig,
    pub scenario: Box<dyn Scenario>,
    pub ipc: Ipc,
    pub stop: StopFlag,
    pub run_dir: std::path::PathBuf,
    pub run_id: String,
    /// 0 for the first start of this process, then one more per restart.
    pub incarnation: u32,
}

/// Parses the arguments, loads the run's launch file and connects to iceoryx2, runs `body`,
/// and turns a failure into a message on stderr and exit code 1.
pub fn process_main(name: &str, body: fn(&Context) -> Result<ChildEvent>) -> ExitCode {
    use clap::Parser;
    let args = ProcessArgs::parse();
    // SAFETY: getppid has no preconditions.
    let launcher = unsafe { libc::getppid() };
    let result = (|| -> Result<()> {
        let stop = StopFlag::install()?;
        let (config, scenario) = load_resolved(Path::new(&args.launch))?;
        let ipc = Ipc::new(name, &args.run_id, config.mode)?;
        let context = Context {
            config,
            scenario,
            ipc,
            stop,
            run_dir: args.run_dir.clone(),
            run_id: args.run_id.clone(),
            incarnation: args.incarnation,
        };
        let report = body(&context)?;
        emit(&report)
    })();
    // Our node is gone now. If the launcher died (we were stopped by PR_SET_PDEATHSIG), nobody
    // else will tidy up: the last process of the run to go removes what is left of it. The others
    // are exiting at the same moment, so each waits a little for them to go (a frozen one never
    // goes: `looplab clean`, and every `looplab run`, removes the run once its launcher is gone).
    // SAFETY: as above.
    if unsafe { libc::getppid() } != launcher {
        let until = std::time::Instant::now() + std::time::Duration::from_secs(2);
        while crate::ipc::clean_up_run(&args.run_id).is_ok_and(|c| !c.leftover.is_empty())
            && std::time::Instant::now() < until
        {
            std::thread::sleep(std::time::Duration::from_millis(20));
        }
    }
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("{name}: error: {e:#}");
            ExitCode::FAILURE
        }
    }
}

pub(crate) fn waitset() -> Result<WaitSet<ipc::Service>> {
    WaitSetBuilder::new()
        .signal_handling_mode(SignalHandlingMode::Disabled)
        .create::<ipc::Service>()
        .map_err(|e| anyhow!("cannot create a WaitSet: {e:?}"))
}

/// Blocks until the WaitSet has an event, the slice ends, or a signal arrives.
pub(crate) fn wait(ws: &WaitSet<ipc::Service>) -> Result<()> {
    ws.wait_and_process_once_with_timeout(|_| CallbackProgression::Continue, WAIT_SLICE)
        .map(|_| ())
        .map_err(|e| anyhow!("WaitSet wait failed: {e:?}"))
}

/// Which stage of the loop trace a process stamps.
#[derive(Clone, Copy)]
enum Stage {
    Sensors,
    Estimator,
    Controller,
}

impl Stage {
    fn name(self) -> &'static str {
        match self {
            Stage::Sensors => "sensors",
            Stage::Estimator => "estimator",
            Stage::Controller => "controller",
        }
    }

    /// Its slot in `Header::incarnations` (the plant's is 0).
    fn index(self) -> usize {
        self as usize + 1
    }

    fn stamp(self, trace: &mut LoopTrace, received: u64, published: u64) {
        let (r, p) = match self {
            Stage::Sensors => (&mut trace.sensors_receive, &mut trace.sensors_publish),
            Stage::Estimator => (&mut trace.estimator_receive, &mut trace.estimator_publish),
            Stage::Controller => (&mut trace.controller_receive, &mut trace.controller_publish),
        };
        *r = received;
        *p = published;
    }
}

/// The shape of the sensors, estimator and controller: wake on input, compute, publish with
/// the input's header and this stage's two stamps added, and apply this stage's own faults.
///
/// A restart upstream shows in the data: every header carries the incarnation of each process
/// that handled the loop, so a stage sees a new one arrive, logs it and counts it. A restarted
/// stage itself starts from nothing: the estimator from the next measurements, the controller
/// with a fresh state.
fn relay<In: Message, Out: Message>(
    context: &Context,
    input: Topic,
    output: Topic,
    stage: Stage,
    mut compute: impl FnMut(&In, &mut Out),
) -> Result<ChildEvent> {
    let subscriber: TopicSubscriber<In> = context.ipc.stage_subscriber(input)?;
    let publisher: TopicPublisher<Out> = context.ipc.publisher(output, true)?;
    let ws = waitset()?;
    let _wake = ws
        .attach_notification(subscriber.listener().expect("stage subscribers have a listener"))
        .map_err(|e| anyhow!("cannot attach the {} listener: {e:?}", input.name()))?;
    subscriber.connect(&context.stop)?;
    emit(&ChildEvent::Ready)?;

    let mut faults = StageFaults::for_process(&context.config, stage.name());
    // Lockstep delay line: the outputs computed in the last loops, newest last.
    let mut computed: VecDeque<Out> = VecDeque::new();
    let keep = faults.max_delay_ticks() as usize + 1;
    let mut upstream: Option<[u32; 4]> = None;
    let mut report = StageReport::default();
    let mut last_k: Option<u64> = None;
    let realtime = context.config.mode == Mode::Realtime;
    let mut waiter = Waiter::new(&context.config.wait, stage.name().parse().expect("a stage is a role"), realtime);
    let mut arrivals = ArrivalModel::new((context.config.dt() * 1e9).round() as u64);
    while !context.stop.requested() {
        let due = last_k.and_then(|k| arrivals.due(k + 1));
        let slice_end = now_ns() + WAIT_SLICE.as_nanos() as u64;
        waiter.wait(due, slice_end, || subscriber.has_samples(), || wait(&ws))?;
        let mut cleared = false;
        while let Some(sample) = subscriber.next(&mut cleared)? {
            let received = now_ns();
            let header = *sample.header();
            let k = header.k;
            arrivals.observe(k, header.trace.plant_publish, received);
            let mut seen = header.incarnations;
            seen[stage.index()..].fill(0);
            if upstream.is_some_and(|u| u != seen) {
                report.upstream_restarts += 1;
                eprintln!("{}: loop {k}: an upstream process restarted (incarnations {seen:?})", stage.name());
            }
            upstream = Some(seen);

            // A loop dropped upstream (lockstep) is passed on, not computed: like a lost
            // message in real time, this stage does not run for it.
            let mut out = if header.lost == 0 {
                let mut out = Out::default();
                compute(&sample, &mut out);
                out
            } else {
                computed.back().copied().unwrap_or_default()
            };
            computed.push_back(out);
            if computed.len() > keep {
                computed.pop_front();
            }
            match faults.delay(k) {
                Some(AddedDelay::Wall(d)) => std::thread::sleep(d),
                Some(AddedDelay::Ticks(d)) => {
                    // What was computed d loops ago, or the oldest kept at the start of a run.
                    out = computed[computed.len().saturating_sub(1 + d as usize)];
                }
                None => {}
            }
            *out.header_mut() = header;
            out.header_mut().incarnations[stage.index()] = context.incarnation;
            if faults.drops(k) {
                report.dropped_by_fault += 1;
                match context.config.mode {
                    Mode::Realtime => continue,
                    Mode::Lockstep => out.header_mut().lost = 1,
                }
            }
            stage.stamp(&mut out.header_mut().trace, received, now_ns());
            publisher.send(&out)?;
            report.processed += 1;
            if let Some(last) = last_k {
                report.skipped += k.saturating_sub(last + 1);
            }
            last_k = Some(k);
        }
    }
    (report.waited, report.dropped) = publisher.backpressure();
    report.wait = waiter.counts;
    Ok(ChildEvent::StageReport(report))
}

pub fn sensors(context: &Context) -> Result<ChildEvent> {
    let mut emulator = SensorEmulator::new(&context.config, context.scenario.vectors().signals);
    let (n, m) = (context.config.sensors.len(), context.scenario.vectors().input.len());
    relay(context, Topic::State, Topic::Measurements, Stage::Sensors, |state: &PlantState, out: &mut Measurements| {
        emulator.tick(state.header.k, state.header.t, &state.x[..], &state.u_applied[..m], &mut out.readings[..n]);
        out.u_applied = state.u_applied;
    })
}

pub fn estimator(context: &Context) -> Result<ChildEvent> {
    let mut estimator = context.scenario.estimator();
    let (n, m) = (context.config.sensors.len(), context.scenario.input_names().len());
    let dim = context.scenario.estimate_names().len();
    let mut kept: Snapshot<Calibration> = Snapshot::open(&context.run_id, "estimator")?;
    if context.incarnation > 0
        && let Some(calibration) = kept.read()
    {
        estimator.resume(&calibration);
    }
    relay(context, Topic::Measurements, Topic::Estimate, Stage::Estimator, |meas: &Measurements, out: &mut Estimate| {
        estimator.update(meas.header.t, &meas.readings[..n], &meas.u_applied[..m], &mut out.x[..dim]);
        if let Some(calibration) = estimator.calibration() {
            kept.write(&calibration);
        }
    })
}

pub fn controller(context: &Context) -> Result<ChildEvent> {
    let mut controller = context.scenario.controller();
    let (dim, m) = (context.scenario.estimate_names().len(), context.scenario.input_names().len());
    let limits = context.scenario.input_limits();
    let faults = StageFaults::for_process(&context.config, "controller");
    relay(context, Topic::Estimate, Topic::Command, Stage::Controller, |est: &Estimate, out: &mut Command| {
        controller.update(est.header.t, &est.x[..dim], &mut out.u[..m]);
        if let Some(value) = faults.corrupt(est.header.k) {
            for (u, (_, hi)) in out.u[..m].iter_mut().zip(&limits) {
                *u = match value {
                    CorruptValue::Nan => f64::NAN,
                    CorruptValue::Inf => f64::INFINITY,
                    CorruptValue::OutOfRange => 10.0 * hi.abs().max(1.0),
                };
            }
        }
    })
}
