//! The loop processes: plant, sensors, estimator and controller. Each binary in `services/` is
//! one call into here; the monitor is in `crate::monitor`.

use std::collections::VecDeque;
use std::fmt::Debug;
use std::path::Path;
use std::process::ExitCode;
use std::time::Duration;

use anyhow::{Result, anyhow};
use iceoryx2::prelude::*;

use crate::clock::{TickTimer, now_ns};
use crate::ipc::{Ipc, Topic, TopicPublisher, TopicSubscriber};
use crate::launch::{LaunchConfig, Mode, load_resolved};
use crate::msg::*;
use crate::protocol::{ChildEvent, PlantReport, ProcessArgs, StageReport, emit, wait_for_start};
use crate::scenarios::Scenario;
use crate::sensors::SensorEmulator;
use crate::signals::StopFlag;

/// Longest a wait blocks before it looks at the stop flag again (a signal also ends it early).
const WAIT_SLICE: Duration = Duration::from_millis(100);
/// Real-time mode: after the last tick, how long the plant still waits for late commands, so
/// that their latency is recorded.
const LATE_COMMAND_GRACE: Duration = Duration::from_millis(50);

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
        let context = Context { config, scenario, ipc, stop, run_dir: args.run_dir };
        let report = body(&context)?;
        emit(&report)
    })();
    // Our node is gone now. If the launcher died (we were stopped by PR_SET_PDEATHSIG), nobody
    // else will tidy up: the last process of the run to go removes what is left of it.
    // SAFETY: as above.
    if unsafe { libc::getppid() } != launcher {
        let _ = crate::ipc::clean_up_run(&args.run_id);
    }
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("{name}: error: {e:#}");
            ExitCode::FAILURE
        }
    }
}

fn waitset() -> Result<WaitSet<ipc::Service>> {
    WaitSetBuilder::new()
        .signal_handling_mode(SignalHandlingMode::Disabled)
        .create::<ipc::Service>()
        .map_err(|e| anyhow!("cannot create a WaitSet: {e:?}"))
}

/// Blocks until the WaitSet has an event, the slice ends, or a signal arrives.
fn wait(ws: &WaitSet<ipc::Service>) -> Result<()> {
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
/// the input's header and this stage's two stamps added.
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

    let mut report = StageReport::default();
    let mut last_k: Option<u64> = None;
    while !context.stop.requested() {
        wait(&ws)?;
        // Consume the wake-ups first, then drain: a sample that lands after the drain also
        // leaves a fresh wake-up behind, so nothing can be missed.
        subscriber.clear_wakeups()?;
        while let Some(sample) = subscriber.receive()? {
            let received = now_ns();
            let mut out = Out::default();
            *out.header_mut() = *sample.header();
            compute(&sample, &mut out);
            let k = sample.header().k;
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
    Ok(ChildEvent::StageReport(report))
}

pub fn sensors(context: &Context) -> Result<ChildEvent> {
    let mut emulator = SensorEmulator::new(&context.config);
    let n = context.config.sensors.len();
    relay(context, Topic::State, Topic::Measurements, Stage::Sensors, |state: &PlantState, out: &mut Measurements| {
        emulator.tick(state.header.k, state.header.t, &state.x, &mut out.readings[..n]);
        out.u_applied = state.u_applied;
    })
}

pub fn estimator(context: &Context) -> Result<ChildEvent> {
    let mut estimator = context.scenario.estimator();
    let (n, m) = (context.config.sensors.len(), context.scenario.input_names().len());
    let dim = context.scenario.estimate_names().len();
    relay(context, Topic::Measurements, Topic::Estimate, Stage::Estimator, |meas: &Measurements, out: &mut Estimate| {
        estimator.update(meas.header.t, &meas.readings[..n], &meas.u_applied[..m], &mut out.x[..dim]);
    })
}

pub fn controller(context: &Context) -> Result<ChildEvent> {
    let mut controller = context.scenario.controller();
    let (dim, m) = (context.scenario.estimate_names().len(), context.scenario.input_names().len());
    relay(context, Topic::Estimate, Topic::Command, Stage::Controller, |est: &Estimate, out: &mut Command| {
        controller.update(est.header.t, &est.x[..dim], &mut out.u[..m]);
    })
}

/// The plant's state between ticks: the truth, the commands, and the counters.
struct PlantLoop {
    plant: Box<dyn crate::scenarios::Plant>,
    limits: Vec<(f64, f64)>,
    dt: f64,
    /// Real-time mode: when tick 0 was and the period (ns); tick j is due at start + j·period.
    /// None in lockstep mode, where every command is in time by construction.
    schedule: Option<(u64, u64)>,
    /// The command in effect (zero-order hold): the last valid one that has taken effect.
    held: [f64; MAX_INPUT],
    /// Valid commands that arrived but have not taken effect yet: (arrival, command).
    queued: VecDeque<(u64, [f64; MAX_INPUT])>,
    /// The newest loop whose command arrived in time (valid or not).
    in_time_k: Option<u64>,
    /// The newest tick whose state was published.
    published_k: Option<u64>,
    state_out: TopicPublisher<PlantState>,
    loop_out: TopicPublisher<LoopRecord>,
    counters: PlantCounters,
    report: PlantReport,
    /// The current tick: the plant's state is at t = k·dt.
    k: u64,
}

impl PlantLoop {
    /// When tick `tick` is due (real-time mode).
    fn due(&self, tick: u64) -> Option<u64> {
        self.schedule.map(|(start, period)| start + tick * period)
    }

    /// Publishes the state at tick k, with the command that was held over the last period.
    fn publish_state(&mut self, timing: TickTiming) -> Result<()> {
        let mut msg = PlantState {
            header: Header { k: self.k, t: self.k as f64 * self.dt, trace: LoopTrace::default() },
            u_applied: self.held,
            timing,
            counters: self.counters,
            ..Default::default()
        };
        let x = self.plant.state();
        msg.x[..x.len()].copy_from_slice(x);
        msg.header.trace.plant_publish = now_ns();
        self.state_out.send(&msg)?;
        self.published_k = Some(self.k);
        if self.report.published == 0 {
            self.report.first_publish_ns = msg.header.trace.plant_publish;
        }
        self.report.last_publish_ns = msg.header.trace.plant_publish;
        self.report.published += 1;
        Ok(())
    }

    /// Takes one command: stamps its arrival, queues it if valid, publishes the loop record.
    /// The command of loop k is in time if it arrives before tick k+1 is due.
    fn accept(&mut self, command: &Command) -> Result<()> {
        let arrived = now_ns();
        let k = command.header.k;
        let m = self.limits.len();
        let valid = command.u[..m].iter().zip(&self.limits).all(|(u, (lo, hi))| u.is_finite() && lo <= u && u <= hi);
        let in_time = self.due(k + 1).is_none_or(|due| arrived <= due);
        if valid {
            self.queued.push_back((arrived, command.u));
        } else {
            self.counters.rejected_commands += 1;
        }
        if in_time {
            self.in_time_k = self.in_time_k.max(Some(k));
        }
        self.report.commands += 1;
        let mut record =
            LoopRecord { header: command.header, deadline_miss: u32::from(!in_time), rejected: u32::from(!valid) };
        record.header.trace.plant_receive = arrived;
        self.loop_out.send(&record)
    }

    /// Integrates one period, tick k → k+1, with the newest valid command that had arrived
    /// when tick k+1 was due (zero-order hold). If tick k's state went out and command k was
    /// not in by then, loop k missed its deadline.
    fn advance(&mut self) {
        let due = self.due(self.k + 1);
        while let Some(&(arrived, u)) = self.queued.front() {
            if due.is_some_and(|due| arrived > due) {
                break;
            }
            self.held = u;
            self.queued.pop_front();
        }
        if self.published_k == Some(self.k) && self.in_time_k.is_none_or(|k| k < self.k) {
            self.counters.deadline_misses += 1;
        }
        let m = self.limits.len();
        self.plant.step(&self.held[..m], self.dt);
        self.k += 1;
    }

    fn drain(&mut self, commands: &TopicSubscriber<Command>) -> Result<()> {
        commands.clear_wakeups()?;
        while let Some(command) = commands.receive()? {
            self.accept(&command)?;
        }
        Ok(())
    }
}

pub fn plant(context: &Context) -> Result<ChildEvent> {
    let commands: TopicSubscriber<Command> = context.ipc.stage_subscriber(Topic::Command)?;
    let mut p = PlantLoop {
        plant: context.scenario.plant(),
        limits: context.scenario.input_limits(),
        dt: context.config.dt(),
        schedule: None,
        held: [0.0; MAX_INPUT],
        queued: VecDeque::new(),
        in_time_k: None,
        published_k: None,
        state_out: context.ipc.publisher(Topic::State, true)?,
        loop_out: context.ipc.publisher(Topic::Loop, false)?,
        counters: PlantCounters::default(),
        report: PlantReport::default(),
        k: 0,
    };
    let ws = waitset()?;
    let _wake = ws
        .attach_notification(commands.listener().expect("stage subscribers have a listener"))
        .map_err(|e| anyhow!("cannot attach the command listener: {e:?}"))?;
    commands.connect(&context.stop)?;
    emit(&ChildEvent::Ready)?;
    if !wait_for_start(&context.stop)? {
        p.report.stopped_early = true;
        return Ok(ChildEvent::PlantReport(p.report));
    }

    let loops = context.config.loops();
    match context.config.mode {
        Mode::Lockstep => {
            p.publish_state(TickTiming::default())?;
            while p.k < loops && !context.stop.requested() {
                wait(&ws)?;
                p.drain(&commands)?;
                // Tick k → k+1 only once command k is in (if it was rejected, the last valid
                // one is held).
                if p.in_time_k == Some(p.k) {
                    p.advance();
                    if p.k < loops {
                        p.publish_state(TickTiming::default())?;
                    }
                }
            }
        }
        Mode::Realtime => {
            // Tick 0 is now; the timer's first expiry is tick 1.
            let period_ns = (p.dt * 1e9).round() as u64;
            let start_ns = now_ns();
            p.schedule = Some((start_ns, period_ns));
            let timer = TickTimer::new(start_ns + period_ns, period_ns)?;
            let _tick = ws.attach_notification(&timer).map_err(|e| anyhow!("cannot attach the tick timer: {e:?}"))?;
            let mut previous_wake = start_ns;
            p.publish_state(TickTiming { scheduled_ns: start_ns, wake_ns: start_ns, period_ns: 0 })?;
            while p.k < loops && !context.stop.requested() {
                wait(&ws)?;
                let woke = now_ns();
                p.drain(&commands)?;
                let expired = timer.expirations();
                let mut advanced = 0;
                while advanced < expired && p.k < loops {
                    p.advance();
                    advanced += 1;
                }
                if advanced == 0 {
                    continue;
                }
                // Only the newest state goes out; the ticks passed over have none.
                p.counters.skipped_ticks += advanced - 1;
                if p.k < loops {
                    let timing = TickTiming {
                        scheduled_ns: start_ns + p.k * period_ns,
                        wake_ns: woke,
                        period_ns: woke - previous_wake,
                    };
                    previous_wake = woke;
                    p.publish_state(timing)?;
                }
            }
            // Record the last commands even when they come late.
            let grace_end = now_ns() + LATE_COMMAND_GRACE.as_nanos() as u64;
            while p.report.commands < p.report.published && now_ns() < grace_end && !context.stop.requested() {
                wait(&ws)?;
                p.drain(&commands)?;
            }
        }
    }
    p.report.stopped_early = p.k < loops;
    p.report.deadline_misses = p.counters.deadline_misses;
    p.report.rejected_commands = p.counters.rejected_commands;
    p.report.skipped_ticks = p.counters.skipped_ticks;
    p.report.loops = p.report.published + p.report.skipped_ticks;
    let (state_waited, state_dropped) = p.state_out.backpressure();
    let (loop_waited, loop_dropped) = p.loop_out.backpressure();
    (p.report.waited, p.report.dropped) = (state_waited + loop_waited, state_dropped + loop_dropped);
    Ok(ChildEvent::PlantReport(p.report))
}
