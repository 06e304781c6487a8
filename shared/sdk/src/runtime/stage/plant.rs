//! The plant process: the truth of the loop. It integrates the scenario's model tick by tick
//! with the command in effect (zero-order hold), publishes the state, and turns each command
//! that reaches it into the loop's record.
//!
//! Fail-safes:
//! - a command that is not finite or out of the input's range is rejected and the last valid
//!   one held (counted);
//! - real time: once the newest command is older than `supervision.command_timeout_s`, the
//!   plant applies `supervision.on_stale` (hold or zero) and counts the ticks;
//! - lockstep: if command k has not come after `supervision.lockstep_stall_s`, the run ends as
//!   stalled instead of hanging; once the launcher says a stage was lost (`lost` on stdin,
//!   `on_death = "continue"`), every tick goes on at once with `on_stale` applied.
//!
//! The physical system does not stop when its simulator dies. After each tick the plant writes
//! a snapshot (state, command in effect, counters, schedule) to a small shared-memory file; a
//! restarted plant reads it back and, in real time, integrates the ticks it missed with the
//! command that was in effect (or `on_stale`), then goes on at the same schedule.

use std::collections::{BTreeSet, VecDeque};
use std::time::{Duration, Instant};

use anyhow::{Context as _, Result};

use crate::config::faults::OnStale;
use crate::config::launch::{LaunchConfig, Mode};
use crate::contract::clock::{TickTimer, now_ns};
use crate::contract::msg::*;
use crate::contract::protocol::{ChildEvent, PlantReport};
use crate::contract::role::{Role, Topic};
use crate::model::scenario::Scenario;
use crate::runtime::stage::child::{Context, WAIT_SLICE, emit, line_written, wait_for_line, wait_for_lines};
use crate::runtime::stage::sched::{RunQueue, clamp};
use crate::runtime::storage::snapshot::{FrozenSnapshot, MAX_MODEL_BYTES, Snapshot};
use crate::runtime::transport::ipc::Wake;
use crate::runtime::transport::ipc::{TopicPublisher, TopicSubscriber};
use crate::runtime::transport::wait::{ArrivalModel, Waiter, reader_blocks, writer_wakes};

/// Real-time mode: after the last tick, how long the plant still waits for late commands, so
/// that their latency is recorded.
const LATE_COMMAND_GRACE: Duration = Duration::from_millis(50);

/// The plant's state between ticks: the truth, the commands, and the counters. Pure: the
/// caller passes the times and sends the messages (the process below, or the in-process twin).
pub struct PlantCore {
    plant: Box<dyn crate::model::scenario::Plant>,
    limits: Vec<(f64, f64)>,
    dt: f64,
    /// The loop period, ns (`LaunchConfig::period_ns`): the real-time schedule's.
    period_ns: u64,
    incarnation: u32,
    /// Real-time mode: when tick 0 was and the period (ns); tick j is due at start + j·period.
    /// None in lockstep mode, where every command is in time by construction.
    schedule: Option<(u64, u64)>,
    /// Real time: command k is in time if it arrives by tick k's due time + this (ns).
    deadline_ns: u64,
    /// The command in effect (zero-order hold): the last valid one that has taken effect.
    held: [f64; MAX_INPUT],
    /// What the actuator applied over the last period: the held command, or what the
    /// scenario's actuator made of it.
    applied: [f64; MAX_INPUT],
    /// When the command in effect arrived (real time; 0: none yet).
    held_arrived: u64,
    command_timeout_ns: u64,
    on_stale: OnStale,
    /// Valid commands that arrived but have not taken effect yet: (arrival, command).
    queued: VecDeque<(u64, [f64; MAX_INPUT])>,
    /// The newest loop whose command arrived in time (valid or not).
    pub in_time_k: Option<u64>,
    /// The newest loop whose command arrived at all, in time or late.
    pub arrived_k: Option<u64>,
    /// The newest tick whose state was published.
    pub published_k: Option<u64>,
    pub counters: PlantCounters,
    pub report: PlantReport,
    /// The current tick: the plant's state is at t = k·dt.
    pub k: u64,
    /// When commands arrive after their tick's state goes out (real time).
    arrivals: ArrivalModel,
    /// Lockstep: a stage was lost (`on_death = "continue"`), so no command will come: every
    /// tick from here on is stale and gets `on_stale`.
    pub open_loop: bool,
}

impl PlantCore {
    pub fn new(config: &LaunchConfig, scenario: &dyn Scenario, incarnation: u32) -> Self {
        Self::with_plant(config, scenario.input_limits(), scenario.plant(), incarnation)
    }

    /// [`PlantCore::new`] with `plant` in place of the scenario's (a plant model of the user's
    /// own, a recording's states) and the commands it applies clamped to `limits`.
    pub fn with_plant(
        config: &LaunchConfig,
        limits: Vec<(f64, f64)>,
        plant: Box<dyn crate::model::scenario::Plant>,
        incarnation: u32,
    ) -> Self {
        let supervision = &config.supervision;
        let mut held = [0.0; MAX_INPUT];
        if let Some(u) = plant.initial_input() {
            held[..u.len()].copy_from_slice(u);
        }
        Self {
            plant,
            limits,
            dt: config.dt(),
            period_ns: config.period_ns(),
            incarnation,
            schedule: None,
            deadline_ns: config.deadline_ns(),
            held,
            applied: held,
            held_arrived: 0,
            // At most an hour (checked at load): well within u64 nanoseconds.
            command_timeout_ns: (supervision.command_timeout_s * 1e9) as u64,
            on_stale: supervision.on_stale,
            queued: VecDeque::new(),
            in_time_k: None,
            arrived_k: None,
            published_k: None,
            counters: PlantCounters::default(),
            report: PlantReport::default(),
            k: 0,
            arrivals: ArrivalModel::new(config.period_ns()),
            open_loop: false,
        }
    }

    /// When tick `tick` is due (real-time mode).
    fn due(&self, tick: u64) -> Option<u64> {
        self.schedule.map(|(start, period)| start + tick * period)
    }

    /// The state at tick k, with the command that was held over the last period, published at
    /// `published_ns`.
    pub fn state_message(&mut self, timing: TickTiming, published_ns: u64) -> PlantState {
        let mut msg = PlantState {
            header: Header { k: self.k, t: self.k as f64 * self.dt, ..Default::default() },
            u_applied: self.applied,
            timing,
            counters: self.counters,
            ..Default::default()
        };
        msg.header.set_incarnation(Role::Plant, self.incarnation);
        msg.header.lost = u32::from(self.plant.withheld(self.k));
        let x = self.plant.state();
        msg.x[..x.len()].copy_from_slice(x);
        msg.header.trace.stamp_published(Role::Plant, published_ns);
        // A plant restarted from the snapshot kept after its state went out (lockstep: killed
        // inside its step) sends that state again: the same loop, counted once.
        if self.published_k != Some(self.k) {
            if self.report.published == 0 {
                self.report.first_publish_ns = published_ns;
            }
            self.report.published += 1;
        }
        self.published_k = Some(self.k);
        self.report.last_publish_ns = published_ns;
        msg
    }

    /// Takes one command that arrived at `arrived`: queues it if valid, and returns the loop
    /// record. The command of loop k is in time if it arrives by tick k's due time + the
    /// deadline (by default one period: before tick k+1 is due).
    pub fn accept(&mut self, command: &Command, arrived: u64) -> LoopRecord {
        let k = command.header.k;
        let m = self.limits.len();
        let lost = command.header.lost != 0;
        let valid = command.u[..m].iter().zip(&self.limits).all(|(u, (lo, hi))| u.is_finite() && lo <= u && u <= hi);
        let in_time = self.due(k).is_none_or(|due| arrived <= due + self.deadline_ns);
        if lost {
            self.counters.lost_commands += 1;
        } else if valid {
            self.queued.push_back((arrived, command.u));
        } else {
            self.counters.rejected_commands += 1;
        }
        if in_time {
            self.in_time_k = self.in_time_k.max(Some(k));
        }
        self.arrived_k = self.arrived_k.max(Some(k));
        self.arrivals.observe(k, command.header.trace.get(Stamp::PlantPublish), arrived);
        self.report.commands += 1;
        let mut record = LoopRecord {
            header: command.header,
            deadline_miss: u32::from(!in_time),
            rejected: u32::from(!lost && !valid),
            lost: u32::from(lost),
            _reserved: 0,
            sequence: self.report.commands,
        };
        record.header.trace.stamp_received(Role::Plant, arrived);
        record
    }

    /// Integrates one period, tick k → k+1, with the newest valid command that had arrived
    /// when tick k+1 was due (zero-order hold), or `on_stale` once that command is older than
    /// the timeout. If tick k's state went out and command k was not in by its deadline (at most
    /// one period, so by now), loop k missed it.
    pub fn advance(&mut self) -> Result<()> {
        let due = self.due(self.k + 1);
        while let Some(&(arrived, u)) = self.queued.front() {
            if due.is_some_and(|due| arrived > due) {
                break;
            }
            self.held = u;
            self.held_arrived = arrived;
            self.queued.pop_front();
        }
        if self.published_k == Some(self.k) && self.in_time_k.is_none_or(|k| k < self.k) {
            self.counters.deadline_misses += 1;
        }
        let m = self.limits.len();
        let stale =
            self.open_loop || due.is_some_and(|due| due.saturating_sub(self.held_arrived) > self.command_timeout_ns);
        if stale {
            self.counters.stale_ticks += 1;
            if self.on_stale == OnStale::Zero {
                self.held = [0.0; MAX_INPUT];
            }
        }
        let t = self.k as f64 * self.dt;
        self.plant.step(t, &self.held[..m], self.dt).with_context(|| format!("the plant failed at t = {t:.6} s"))?;
        if let Some(applied) = self.plant.applied_input() {
            self.applied[..m].copy_from_slice(applied);
        } else {
            self.applied = self.held;
        }
        self.k += 1;
        Ok(())
    }

    /// Real time: starts the schedule with tick 0 at `now_ns`, unless a restored snapshot holds
    /// one already; returns when tick 0 was.
    pub fn start_schedule(&mut self, now_ns: u64) -> u64 {
        self.schedule.get_or_insert((now_ns, self.period_ns)).0
    }

    /// A restarted plant catches up with the ticks that passed while it was down, to tick
    /// `current`: the system kept moving under the command in effect (or `on_stale`). Every
    /// tick from here to `current` goes without a state, this one too if the last plant died
    /// before publishing it.
    pub fn catch_up(&mut self, current: u64) -> Result<()> {
        if current <= self.k {
            return Ok(());
        }
        let unpublished_now = u64::from(self.published_k != Some(self.k));
        self.counters.skipped_ticks += current - self.k - 1 + unpublished_now;
        while self.k < current {
            self.advance()?;
        }
        Ok(())
    }

    /// Real time: the timer says `expired` periods passed; advances that many ticks, not past
    /// the run's `loops`, and returns how many. Only the newest tick's state goes out: the
    /// ticks passed over count as skipped. The run's last tick is never passed over: it goes out
    /// late, as a miss with its row in loops.csv (no later state would tell the monitor of it).
    pub fn advance_expired(&mut self, expired: u64, loops: u64) -> Result<u64> {
        let mut advanced = 0;
        let last = loops.saturating_sub(1);
        while advanced < expired && self.k < loops && !(advanced > 0 && self.k == last) {
            self.advance()?;
            advanced += 1;
        }
        self.counters.skipped_ticks += advanced.saturating_sub(1);
        Ok(advanced)
    }

    /// Completes the report at the end of a run of `loops` loops.
    pub fn finish(&mut self, loops: u64) {
        self.report.stopped_early = self.k < loops;
        self.report.counters = self.counters;
        self.report.loops = self.report.published + self.counters.skipped_ticks;
        self.report.last_applied = self.applied[..self.limits.len()].to_vec();
    }

    pub fn snapshot(&self) -> SnapshotData {
        let mut s = SnapshotData {
            k: self.k,
            held: self.held,
            held_arrived: self.held_arrived,
            schedule: self.schedule.map_or([0, 0], |(a, b)| [a, b]),
            in_time_k: self.in_time_k.map_or(-1, |k| k as i64),
            published_k: self.published_k.map_or(-1, |k| k as i64),
            counters: self.counters,
            published: self.report.published,
            commands: self.report.commands,
            first_publish_ns: self.report.first_publish_ns,
            last_publish_ns: self.report.last_publish_ns,
            ..Default::default()
        };
        let x = self.plant.state();
        s.x[..x.len()].copy_from_slice(x);
        s
    }

    pub fn restore(&mut self, s: &SnapshotData) {
        self.k = s.k;
        self.held = s.held;
        self.applied = s.held;
        self.held_arrived = s.held_arrived;
        self.schedule = (s.schedule[1] > 0).then_some((s.schedule[0], s.schedule[1]));
        self.in_time_k = u64::try_from(s.in_time_k).ok();
        self.arrived_k = self.in_time_k;
        self.published_k = u64::try_from(s.published_k).ok();
        self.counters = s.counters;
        self.report.published = s.published;
        self.report.commands = s.commands;
        self.report.first_publish_ns = s.first_publish_ns;
        self.report.last_publish_ns = s.last_publish_ns;
        let n = self.plant.state().len();
        self.plant.restore(&s.x[..n]);
    }
}

/// The plant process: the core, its two publishers, and the snapshot it writes after every
/// change, so that a restarted plant goes on from where this one died.
struct PlantProcess {
    core: PlantCore,
    state_out: TopicPublisher<PlantState>,
    loop_out: TopicPublisher<LoopRecord>,
    snapshot: Snapshot<SnapshotData>,
    /// The plant model's own bytes for the same tick, where it serialises itself (an FMU).
    model_snapshot: Option<FrozenSnapshot>,
    run_queue: RunQueue,
    /// Its run-queue wait before the last wake-up, stamped on what that wake-up sends.
    woke: SchedStamp,
}

impl std::ops::Deref for PlantProcess {
    type Target = PlantCore;
    fn deref(&self) -> &PlantCore {
        &self.core
    }
}

impl std::ops::DerefMut for PlantProcess {
    fn deref_mut(&mut self) -> &mut PlantCore {
        &mut self.core
    }
}

impl PlantProcess {
    fn publish_state(&mut self, timing: TickTiming) -> Result<()> {
        let mut msg = self.core.state_message(timing, now_ns());
        msg.header.sched = self.woke;
        self.state_out.send(&msg)?;
        self.keep();
        Ok(())
    }

    fn accept(&mut self, command: &Command) -> Result<()> {
        let mut record = self.core.accept(command, now_ns());
        record.header.sched = self.woke;
        self.loop_out.send(&record)
    }

    fn advance(&mut self) -> Result<()> {
        self.core.advance()?;
        self.keep();
        Ok(())
    }

    /// Takes every command in; called once per wake-up, which it reads the run-queue wait of.
    fn drain(&mut self, commands: &TopicSubscriber<Command>) -> Result<()> {
        self.woke = SchedStamp { queued_ns: clamp(self.run_queue.since_last()), compute_queued_ns: 0 };
        let mut cleared = false;
        while let Some(command) = commands.next(&mut cleared)? {
            self.accept(&command)?;
        }
        Ok(())
    }

    /// The model's bytes first, then the snapshot of the same tick (see [`FrozenSnapshot`]).
    fn keep(&mut self) {
        let s = self.core.snapshot();
        if let Some(model) = &mut self.model_snapshot {
            let kept = match self.core.plant.freeze() {
                Ok(Some(bytes)) => model.write(s.k, &bytes),
                Ok(None) => false,
                Err(e) => {
                    eprintln!("plant: cannot save the model's state ({e:#}); a restart goes on from the state vector");
                    false
                }
            };
            if !kept {
                self.model_snapshot = None;
            }
        }
        self.snapshot.write(&s);
    }

    /// Opens the model's snapshot where the model serialises itself; a restarted plant goes on
    /// from the bytes of its snapshot's tick.
    fn open_model_snapshot(&mut self, run_id: &str, restored: Option<u64>) -> Result<()> {
        if !matches!(self.core.plant.freeze(), Ok(Some(_))) {
            return Ok(());
        }
        let model = FrozenSnapshot::open(run_id, "plant.model", MAX_MODEL_BYTES)?;
        if let Some(bytes) = restored.and_then(|k| model.read(k)) {
            self.core.plant.thaw(&bytes)?;
        }
        self.model_snapshot = Some(model);
        Ok(())
    }
}

/// The plant process with `plant` in place of the scenario's (`runtime::stage::user_plant`), the
/// commands it applies clamped to `limits`.
pub fn run_with(
    context: &Context,
    plant: Box<dyn crate::model::scenario::Plant>,
    limits: Vec<(f64, f64)>,
) -> Result<ChildEvent> {
    let (wait_settings, realtime) = (&context.config.wait, context.config.mode == Mode::Realtime);
    let listens = reader_blocks(wait_settings, Topic::Command, realtime);
    let commands: TopicSubscriber<Command> = context.ipc.stage_subscriber(Topic::Command, listens)?;
    let supervision = &context.config.supervision;
    let mut p = PlantProcess {
        core: PlantCore::with_plant(&context.config, limits, plant, context.incarnation),
        state_out: context.ipc.publisher(Topic::State, writer_wakes(&context.config, Topic::State))?,
        loop_out: context.ipc.publisher(Topic::Loop, Wake::Never)?,
        snapshot: Snapshot::open(&context.run_id, Role::Plant.name())?,
        model_snapshot: None,
        run_queue: RunQueue::open(),
        woke: SchedStamp::default(),
    };
    let restored = context.incarnation > 0 && p.snapshot.read().map(|s| p.core.restore(&s)).is_some();
    p.open_model_snapshot(&context.run_id, restored.then_some(p.k))?;
    p.report.restored_at = restored.then_some(p.k);
    if restored && p.model_snapshot.is_none() && context.config.is_declared() {
        p.report.resumed_note = Some(format!(
            "the plant restarted at loop {} went on from the state vector alone: its model does not serialise its \
             own state, so any internal state beyond the declared one started again from its initial values",
            p.k
        ));
    }
    commands.connect(&context.stop, context.config.supervision.connect_timeout())?;
    emit(&ChildEvent::Ready)?;
    if !wait_for_line(&context.stop, "start")? {
        p.report.stopped_early = true;
        return Ok(ChildEvent::PlantReport(p.core.report));
    }

    let loops = context.config.loops();
    match context.config.mode {
        Mode::Lockstep => {
            // The launcher injects a kill or stop with the loop held before the tick's state goes
            // out, so that the fault lands at the same loop every run.
            let pauses: BTreeSet<u64> = context
                .config
                .faults
                .iter()
                .filter(|f| f.kind.from_outside())
                .map(|f| f.ticks(context.config.rate_hz).0)
                .collect();
            // Positive, finite and at most an hour (checked at load), so this cannot panic.
            let stall_limit = Duration::from_secs_f64(supervision.lockstep_stall_s);
            emit(&ChildEvent::Started { start_ns: now_ns(), period_ns: 0, k: p.k })?;
            p.keep();
            let mut waiter = Waiter::new(&context.config.wait, Role::Plant, false, 0);
            'ticks: while p.k < loops && !context.stop.requested() {
                if pauses.contains(&p.k) {
                    emit(&ChildEvent::Paused { k: p.k })?;
                    // A stage killed at the pause and not restarted is lost before the `go`.
                    loop {
                        match wait_for_lines(&context.stop, &["go", "lost"])? {
                            Some("lost") => p.open_loop = true,
                            Some(_) => break,
                            None => break 'ticks,
                        }
                    }
                }
                p.publish_state(TickTiming::default())?;
                let published = Instant::now();
                // Tick k → k+1 only once command k is in (if it was rejected, the last valid
                // one is held), or, once a stage is lost, at once: no command will come.
                while !p.open_loop && p.in_time_k != Some(p.k) {
                    if context.stop.requested() {
                        break 'ticks;
                    }
                    if published.elapsed() > stall_limit {
                        p.report.stalled_at = Some(p.k);
                        break 'ticks;
                    }
                    let slice_end = now_ns() + WAIT_SLICE.as_nanos() as u64;
                    waiter.wait(
                        None,
                        slice_end,
                        || commands.has_samples(),
                        |until| commands.doze_until(until),
                        || commands.doze_until(slice_end),
                    )?;
                    p.drain(&commands)?;
                    // Only while command k is awaited: the launcher says so of a lost stage.
                    if p.in_time_k != Some(p.k) && line_written("lost") {
                        p.open_loop = true;
                    }
                }
                p.advance()?;
            }
        }
        Mode::Realtime => {
            let period_ns = p.period_ns;
            let start_ns = p.core.start_schedule(now_ns());
            emit(&ChildEvent::Started { start_ns, period_ns, k: p.k })?;
            // A restarted plant catches up with the ticks that passed while it was down.
            let woke = now_ns();
            let current = ((woke - start_ns) / period_ns).min(loops.saturating_sub(1));
            if current > p.k {
                p.core.catch_up(current)?;
                p.keep();
            }
            let timer = TickTimer::new(start_ns + (p.k + 1) * period_ns, period_ns)?;
            let mut previous_wake = woke;
            // A plant killed after publishing its newest tick (or after the run's last tick), and
            // restarted before the next is due, has no tick to publish: that state went out.
            if p.k < loops && p.published_k != Some(p.k) {
                let first = TickTiming { scheduled_ns: start_ns + p.k * period_ns, wake_ns: woke, period_ns: 0 };
                p.publish_state(first)?;
            }
            let mut waiter = Waiter::new(&context.config.wait, Role::Plant, true, period_ns);
            while p.k < loops && !context.stop.requested() {
                // Next: command k, if its state went out and it is not in yet, else the tick.
                let next_tick = start_ns + (p.k + 1) * period_ns;
                // A command that came after its deadline is not awaited any more either.
                let awaiting_command = p.published_k == Some(p.k) && p.arrived_k.is_none_or(|k| k < p.k);
                let command_due = p.arrivals.due(p.k).filter(|due| awaiting_command && *due < next_tick);
                waiter.wait(
                    Some(command_due.unwrap_or(next_tick)),
                    next_tick,
                    || Ok(commands.has_samples()? || now_ns() >= next_tick),
                    |until| commands.doze_until(until),
                    || commands.doze_until(next_tick),
                )?;
                let woke = now_ns();
                p.drain(&commands)?;
                let expired = timer.expirations();
                if p.core.advance_expired(expired, loops)? == 0 {
                    continue;
                }
                // Saved at once: after the run's last tick no state goes out to save it.
                p.keep();
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
            p.report.wait = waiter.counts;
            // Record the last commands even when they come late.
            let grace_end = now_ns() + LATE_COMMAND_GRACE.as_nanos() as u64;
            while p.report.commands < p.report.published && now_ns() < grace_end && !context.stop.requested() {
                commands.doze_until(grace_end)?;
                p.drain(&commands)?;
            }
        }
    }
    p.core.finish(loops);
    let (state_waited, state_dropped) = p.state_out.backpressure();
    let (loop_waited, loop_dropped) = p.loop_out.backpressure();
    (p.report.waited, p.report.dropped) = (state_waited + loop_waited, state_dropped + loop_dropped);
    Ok(ChildEvent::PlantReport(p.core.report))
}

/// What a restarted plant needs to go on where the last one stopped.
#[derive(Debug, Clone, Copy, Default)]
#[repr(C)]
pub struct SnapshotData {
    k: u64,
    x: [f64; MAX_STATE],
    held: [f64; MAX_INPUT],
    held_arrived: u64,
    /// Real time: [start, period] in ns; [0, 0] in lockstep.
    schedule: [u64; 2],
    /// The newest loop whose command came in time, and the newest tick published; −1 for none.
    in_time_k: i64,
    published_k: i64,
    counters: PlantCounters,
    published: u64,
    commands: u64,
    first_publish_ns: u64,
    last_publish_ns: u64,
}
