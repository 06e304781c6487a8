//! The monitor: a passive reader of every topic that records latency, jitter and the trajectory
//! without slowing the loop.
//!
//! Its readers have no listeners, so publishing never wakes it; it polls every few milliseconds
//! with deep buffers (real-time mode: safe overflow, so a slow monitor loses samples, counted,
//! and never blocks a stage). The receive loop only copies samples out of shared memory and
//! passes them over a channel to a writer thread, which joins the five messages of each loop
//! by k, feeds the histograms and the scenario's metrics, and writes `trajectory.csv`,
//! `loops.csv` and `latency.hlog`.

use std::collections::BTreeMap;
use std::fs::File;
use std::io::{BufWriter, Write};
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant, SystemTime, UNIX_EPOCH};

use anyhow::{Context as _, Result, anyhow};
use crossbeam_channel::{Receiver, RecvTimeoutError};
use hdrhistogram::Histogram;
use hdrhistogram::serialization::V2DeflateSerializer;
use hdrhistogram::serialization::interval_log::{IntervalLogIterator, IntervalLogWriterBuilder, LogEntry, Tag};
use serde::{Deserialize, Serialize};

use crate::clock::now_ns;
use crate::faults::FaultKind;
use crate::ipc::{MONITOR_BUFFER, Topic, TopicSubscriber};
use crate::launch::Mode;
use crate::msg::*;
use crate::protocol::{ChildEvent, MonitorStatus, emit};
use crate::scenarios::{ErrorMeasure, Metrics, Row};
use crate::stages::Context;

/// Sleep between drains when the queues were nearly empty.
const POLL_PERIOD: Duration = Duration::from_millis(5);
/// How often the live status goes to the launcher; it is also the monitor's heartbeat, and the
/// files are flushed as often, so that a killed monitor loses little.
const STATUS_PERIOD: Duration = Duration::from_millis(100);
/// Length of one interval histogram in `latency.hlog`, in wall-clock time.
const HLOG_INTERVAL_NS: u64 = 1_000_000_000;
/// A loop still missing parts once this many newer loops have arrived is written as it is.
const JOIN_WINDOW: u64 = 2 * MONITOR_BUFFER as u64;
/// Most missing ranges listed in the report.
const MAX_MISSING_RANGES: usize = 100;
/// Histogram range: 1 ns to 60 s at 3 significant digits.
const HISTOGRAM_MAX_NS: u64 = 60_000_000_000;

/// The hops of one loop, as (name, index of the start stamp, index of the end stamp) in
/// `LoopTrace::stamps()`.
pub const HOPS: [(&str, usize, usize); 7] = [
    ("plant_to_sensors", 0, 1),
    ("sensors_compute", 1, 2),
    ("sensors_to_estimator", 2, 3),
    ("estimator_compute", 3, 4),
    ("estimator_to_controller", 4, 5),
    ("controller_compute", 5, 6),
    ("controller_to_plant", 6, 7),
];

/// A latency distribution as the summary reports it, in nanoseconds. Percentiles come from the
/// HDR histogram (within 0.1%); count, min, max and mean are exact. All `None` when empty.
#[derive(Debug, Clone, Default, Serialize, Deserialize, PartialEq)]
pub struct Stats {
    pub count: u64,
    pub min: Option<u64>,
    pub p50: Option<u64>,
    pub p90: Option<u64>,
    pub p99: Option<u64>,
    pub p999: Option<u64>,
    pub max: Option<u64>,
    pub mean: Option<f64>,
}

/// An HDR histogram with exact extremes, plus the current interval for the interval log.
struct Recorder {
    total: Histogram<u64>,
    interval: Histogram<u64>,
    min: u64,
    max: u64,
    sum: u128,
}

impl Recorder {
    fn new() -> Self {
        let h = Histogram::new_with_bounds(1, HISTOGRAM_MAX_NS, 3).expect("valid histogram bounds");
        Self { total: h.clone(), interval: h, min: u64::MAX, max: 0, sum: 0 }
    }

    fn record(&mut self, ns: u64) {
        self.total.saturating_record(ns);
        self.interval.saturating_record(ns);
        self.min = self.min.min(ns);
        self.max = self.max.max(ns);
        self.sum += u128::from(ns);
    }

    fn stats(&self) -> Stats {
        let count = self.total.len();
        if count == 0 {
            return Stats::default();
        }
        // HDR reports a bucket's highest equivalent value; keep it inside the exact extremes.
        let q = |q: f64| Some(self.total.value_at_quantile(q).clamp(self.min, self.max));
        Stats {
            count,
            min: Some(self.min),
            p50: q(0.50),
            p90: q(0.90),
            p99: q(0.99),
            p999: q(0.999),
            max: Some(self.max),
            mean: Some(self.sum as f64 / count as f64),
        }
    }
}

#[derive(Debug, Clone, Default, Serialize, Deserialize, PartialEq)]
pub struct MonitorReport {
    /// Loops written with their loop record (whole loops, plant to plant). A record that comes
    /// after its loop was written is only counted as received.
    pub records: u64,
    /// Loops the monitor saw any message of: 0 up to the newest k, plus one.
    pub loops_seen: u64,
    /// Samples received per topic.
    pub received: BTreeMap<String, u64>,
    /// Loops without a record, within the loops the monitor saw anything of.
    pub missing: MissingLoops,
    /// Loop records the plant published before this monitor's first one: 0 for the first
    /// monitor, which is up before the loop starts; a restarted one never could receive them.
    pub records_before_start: u64,
    pub end_to_end: Stats,
    pub hops: BTreeMap<String, Stats>,
    /// |actual tick period − dt| (real-time mode).
    pub plant_tick_jitter: Stats,
    /// Wake-up time − scheduled tick time (real-time mode).
    pub plant_wake_latency: Stats,
    /// Per sensor: age of the sample command k used, when command k took effect.
    pub data_age: BTreeMap<String, Stats>,
    /// Trajectory rows written with some part missing.
    pub partial_rows: u64,
    pub metrics: BTreeMap<String, f64>,
    /// The scenario's findings in words.
    pub notes: Vec<String>,
    /// What each fault of the launch file did to the loop, in its order.
    pub faults: Vec<FaultEffect>,
}

impl MonitorReport {
    /// Of the `published` loop records, those that never reached this monitor though it was
    /// there to receive them (its buffer overflowed).
    pub fn lost_records(&self, published: u64) -> u64 {
        let received = self.received.get(Topic::Loop.name()).copied().unwrap_or(0);
        published.saturating_sub(self.records_before_start + received)
    }
}

/// Loops without a loop record: every one counted, the first [`MAX_MISSING_RANGES`] ranges
/// listed. Serialized flat into the summary's `monitor` object.
#[derive(Debug, Clone, Default, Serialize, Deserialize, PartialEq)]
pub struct MissingLoops {
    /// Inclusive [first, last] ranges, in order.
    #[serde(rename = "missing")]
    pub ranges: Vec<[u64; 2]>,
    /// All loops without a record, listed or not.
    pub missing_loops: u64,
    /// Ranges left out of the list.
    pub missing_ranges_omitted: u64,
    /// Of `missing_loops`, those before the first loop of a restarted monitor: their records
    /// went to an earlier monitor (whose report died with it) or came while none ran.
    pub missing_before_restart: u64,
    /// The newest missing loop, listed or not: an omitted range grows while loops go on missing.
    #[serde(skip)]
    last: Option<u64>,
}

impl MissingLoops {
    /// Adds the loops `first..=last`, which come after every loop added so far.
    fn add(&mut self, first: u64, last: u64) {
        self.missing_loops += last - first + 1;
        let adjacent = self.last.is_some_and(|newest| newest + 1 == first);
        self.last = Some(last);
        let listed = self.ranges.len();
        match self.ranges.last_mut() {
            Some(range) if adjacent && range[1] + 1 == first => range[1] = last,
            // The range goes on past the list's end: it is counted already.
            _ if adjacent => {}
            _ if listed < MAX_MISSING_RANGES => self.ranges.push([first, last]),
            _ => self.missing_ranges_omitted += 1,
        }
    }

    /// With the loops from `loops_seen` up to the run's last loop added: the monitor saw nothing
    /// of those.
    pub fn up_to(mut self, loops_seen: u64, loops: u64) -> Self {
        if loops_seen < loops {
            self.add(loops_seen, loops - 1);
        }
        self
    }
}

/// What one fault did to the loop and to the physical system, in simulation time.
#[derive(Debug, Clone, Default, Serialize, Deserialize, PartialEq)]
pub struct FaultEffect {
    /// Ticks with no fresh command (none came, or it was late, rejected or lost) from the
    /// injection until the first fresh one after the fault ended (after a kill: the first that
    /// went through the restarted process).
    pub outage_ticks: u64,
    /// When fresh commands were back (None: not within the run).
    pub commands_back_at_s: Option<f64>,
    /// A killed process: the first loop its restarted incarnation handled.
    pub rejoined_at_s: Option<f64>,
    /// The scenario's error measure, worst value from the injection until fresh commands were
    /// back, and after that until the next fault or the end of the run.
    pub worst_error_during: Option<f64>,
    pub worst_error_after: Option<f64>,
    /// From the end of the fault (a kill: the injection) until the error is back within the
    /// scenario's band for good; None if it did not come back before the next fault or the end.
    pub recovery_s: Option<f64>,
    /// The error stayed below the scenario's limit from the injection to the next fault or the end.
    pub within_limits: bool,
    /// The largest error in the first second from the injection and in the last second before
    /// the next fault or the end: their ratio shows an oscillation growing (an unstable loop)
    /// or dying out.
    pub error_peak_first_s: Option<f64>,
    pub error_peak_last_s: Option<f64>,
}

/// Follows one fault through the loops the monitor writes.
struct FaultTracker {
    /// The process's slot in `Header::incarnations`, if it has one.
    slot: Option<usize>,
    from: u64,
    /// The first tick after the fault.
    end: u64,
    /// The first tick of the next fault, or the end of the run.
    window_end: u64,
    /// Ticks in a second.
    second: u64,
    incarnation_before: Option<u32>,
    /// A kill: the fault is over once the restarted process is in the loop.
    after_restart: bool,
    back: Option<u64>,
    rejoined: Option<u64>,
    last_outside: Option<u64>,
    effect: FaultEffect,
}

impl FaultTracker {
    fn new(config: &crate::launch::LaunchConfig) -> Vec<Self> {
        let loops = config.loops();
        let starts: Vec<u64> = config.faults.iter().map(|f| f.ticks(config.rate_hz).0).collect();
        config
            .faults
            .iter()
            .zip(&starts)
            .map(|(f, &from)| {
                let end = match f.kind {
                    FaultKind::Kill => from,
                    // A stop lasts wall-clock time, which only passes for the loop in real time.
                    FaultKind::Stop if config.mode == Mode::Lockstep => from,
                    FaultKind::Stop => from + (f.duration_s.unwrap_or_default() * config.rate_hz).round() as u64,
                    _ => f.ticks(config.rate_hz).1.unwrap_or(loops),
                };
                let window_end = starts.iter().copied().filter(|&s| s > from).min().unwrap_or(loops);
                Self {
                    slot: crate::faults::PROCESSES.iter().position(|p| *p == f.process).filter(|&i| i < 4),
                    from,
                    end,
                    window_end,
                    second: config.rate_hz.round() as u64,
                    incarnation_before: None,
                    after_restart: f.kind == FaultKind::Kill,
                    back: None,
                    rejoined: None,
                    last_outside: None,
                    effect: FaultEffect { within_limits: true, ..Default::default() },
                }
            })
            .collect()
    }

    fn observe(&mut self, k: u64, part: &Partial, measure: &ErrorMeasure) {
        let incarnation = self.slot.zip(part.record.as_ref()).map(|(i, r)| r.header.incarnations[i]);
        if k < self.from {
            self.incarnation_before = incarnation.or(self.incarnation_before);
            return;
        }
        if k >= self.window_end {
            return;
        }
        if self.rejoined.is_none()
            && self.incarnation_before.is_some()
            && incarnation.is_some_and(|i| Some(i) != self.incarnation_before)
        {
            self.rejoined = Some(k);
        }
        let fresh = part.record.as_ref().is_some_and(|r| r.deadline_miss == 0 && r.rejected == 0 && r.lost == 0);
        // After a kill, commands are back once they carry the restarted process's work (a
        // command or two may still come from before the kill landed).
        let restarted = !self.after_restart || self.rejoined.is_some();
        if self.back.is_none() {
            if fresh && k >= self.end && restarted {
                self.back = Some(k);
            } else if !fresh {
                self.effect.outage_ticks += 1;
            }
        }
        if let Some(state) = &part.state {
            let error = (measure.of_state)(state.header.t, &state.x);
            let worst = if self.back.is_none() {
                &mut self.effect.worst_error_during
            } else {
                &mut self.effect.worst_error_after
            };
            *worst = Some(worst.map_or(error, |w: f64| w.max(error)));
            let peak = |p: &mut Option<f64>| *p = Some(p.map_or(error, |v: f64| v.max(error)));
            if k < self.from + self.second {
                peak(&mut self.effect.error_peak_first_s);
            }
            if k + self.second >= self.window_end {
                peak(&mut self.effect.error_peak_last_s);
            }
            // NaN counts as outside.
            if error.is_nan() || error >= measure.limit {
                self.effect.within_limits = false;
            }
            if error.is_nan() || error > measure.recovery_band {
                self.last_outside = Some(k);
            }
        }
    }

    fn finish(mut self, dt: f64) -> FaultEffect {
        let at = |k: u64| k as f64 * dt;
        self.effect.commands_back_at_s = self.back.map(at);
        self.effect.rejoined_at_s = self.rejoined.map(at);
        self.effect.recovery_s = match self.last_outside {
            _ if self.end >= self.window_end => None,
            None => Some(0.0),
            Some(k) if k < self.end => Some(0.0),
            Some(k) if k + 1 >= self.window_end => None,
            Some(k) => Some(at(k + 1 - self.end)),
        };
        self.effect
    }
}

/// Finds stalled processes from the data alone: a process whose newest input is newer than its
/// newest output for longer than the stall timeout has stopped handling its input (iceoryx2
/// reports a SIGSTOPped process as alive). In real time the plant must also publish every
/// period. Checked each time the monitor drains its queues, so detection comes within one poll
/// (5 ms) of the timeout.
struct StallWatch {
    timeout_ns: u64,
    mode: Mode,
    /// The plant's last tick: after it, silence is the end of the run.
    last_tick: u64,
    /// Newest k seen on state, measurements, estimate, command.
    newest: [Option<u64>; 4],
    /// When the monitor last saw a new state, and the loop period.
    state_seen_ns: u64,
    period_ns: u64,
    /// Per process (plant, sensors, estimator, controller): since when its input has waited.
    waiting: [Option<u64>; 4],
    stalled: [bool; 4],
}

impl StallWatch {
    fn new(context: &Context) -> Self {
        Self {
            timeout_ns: (context.config.supervision.stall_timeout_s * 1e9) as u64,
            mode: context.config.mode,
            last_tick: context.config.loops().saturating_sub(1),
            newest: [None; 4],
            state_seen_ns: now_ns(),
            period_ns: (context.config.dt() * 1e9) as u64,
            waiting: [None; 4],
            stalled: [false; 4],
        }
    }

    fn saw(&mut self, topic: usize, k: u64) {
        if topic == 0 && self.newest[0].is_none_or(|n| k > n) {
            self.state_seen_ns = now_ns();
        }
        self.newest[topic] = self.newest[topic].max(Some(k));
    }

    /// Events for processes that stalled or came back since the last check.
    fn check(&mut self) -> Vec<ChildEvent> {
        let now = now_ns();
        let mut events = vec![];
        let plant_done = self.newest[0].is_some_and(|k| k >= self.last_tick);
        for process in 0..4 {
            // Whether the process's input waits, and since when if the data tells.
            let (waiting, since) = match process {
                // The plant's input is the command for its newest state (lockstep), or its
                // clock (real time): a state is due every period, so silence dates from the last.
                0 if plant_done => (false, None),
                0 => match self.mode {
                    Mode::Lockstep => (self.newest[3].is_some() && self.newest[3] >= self.newest[0], None),
                    Mode::Realtime => (now > self.state_seen_ns + self.period_ns, Some(self.state_seen_ns)),
                },
                p => (self.newest[p - 1].is_some_and(|input| self.newest[p].is_none_or(|output| input > output)), None),
            };
            let name = crate::faults::PROCESSES[process].to_owned();
            if !waiting {
                self.waiting[process] = None;
                if std::mem::take(&mut self.stalled[process]) {
                    events.push(ChildEvent::Resumed { process: name, at_ns: now });
                }
                continue;
            }
            let since = *self.waiting[process].get_or_insert(since.unwrap_or(now));
            if !self.stalled[process] && now - since >= self.timeout_ns {
                self.stalled[process] = true;
                events.push(ChildEvent::Stall { process: name, since_ns: since, detected_ns: now });
            }
        }
        events
    }
}

/// A message from the receive loop to the writer. Samples are moved, not boxed: one copy per
/// sample, no allocation on the receive path.
#[allow(clippy::large_enum_variant)]
enum Sample {
    State(PlantState),
    Measurements(Measurements),
    Estimate(Estimate),
    Command(Command),
    Record(LoopRecord),
}

/// The parts of one loop that have arrived.
#[derive(Default)]
struct Partial {
    state: Option<PlantState>,
    measurements: Option<Measurements>,
    estimate: Option<Estimate>,
    command: Option<Command>,
    record: Option<LoopRecord>,
}

impl Sample {
    /// The loop it belongs to, and its topic's index in [`TOPICS`].
    fn key(&self) -> (u64, usize) {
        match self {
            Sample::State(s) => (s.header.k, 0),
            Sample::Measurements(s) => (s.header.k, 1),
            Sample::Estimate(s) => (s.header.k, 2),
            Sample::Command(s) => (s.header.k, 3),
            Sample::Record(s) => (s.header.k, 4),
        }
    }
}

impl Partial {
    fn put(&mut self, sample: Sample) {
        match sample {
            Sample::State(s) => self.state = Some(s),
            Sample::Measurements(s) => self.measurements = Some(s),
            Sample::Estimate(s) => self.estimate = Some(s),
            Sample::Command(s) => self.command = Some(s),
            Sample::Record(s) => self.record = Some(s),
        }
    }

    /// Whether the part from topic index `topic` is here.
    fn has(&self, topic: usize) -> bool {
        [
            self.state.is_some(),
            self.measurements.is_some(),
            self.estimate.is_some(),
            self.command.is_some(),
            self.record.is_some(),
        ][topic]
    }
}

/// The topics the monitor reads, in the order data flows.
const TOPICS: [Topic; 5] = [Topic::State, Topic::Measurements, Topic::Estimate, Topic::Command, Topic::Loop];

pub fn run(context: &Context) -> Result<ChildEvent> {
    let ipc = &context.ipc;
    let states: TopicSubscriber<PlantState> = ipc.passive_subscriber(Topic::State)?;
    let measurements: TopicSubscriber<Measurements> = ipc.passive_subscriber(Topic::Measurements)?;
    let estimates: TopicSubscriber<Estimate> = ipc.passive_subscriber(Topic::Estimate)?;
    let commands: TopicSubscriber<Command> = ipc.passive_subscriber(Topic::Command)?;
    let records: TopicSubscriber<LoopRecord> = ipc.passive_subscriber(Topic::Loop)?;
    states.connect(&context.stop)?;
    measurements.connect(&context.stop)?;
    estimates.connect(&context.stop)?;
    commands.connect(&context.stop)?;
    records.connect(&context.stop)?;
    let writer = Writer::new(context)?;
    if context.config.mode == Mode::Realtime {
        // The monitor must never slow the loop: it runs at the lowest priority (its threads
        // inherit it). Its buffers hold a second of samples to catch up with.
        crate::wait::run_in_background();
    }
    emit(&ChildEvent::Ready)?;

    let (tx, rx) = crossbeam_channel::unbounded();
    let writer = std::thread::Builder::new().name("monitor-writer".into()).spawn(move || writer.run(rx))?;

    let mut watch = StallWatch::new(context);
    let mut drain = || -> Result<usize> {
        let mut n = 0;
        macro_rules! take {
            ($sub:expr, $variant:ident, $topic:expr) => {
                while let Some(s) = $sub.receive()? {
                    n += 1;
                    if let Some(topic) = $topic {
                        watch.saw(topic, s.header.k);
                    }
                    tx.send(Sample::$variant(s)).map_err(|_| anyhow!("the monitor's writer stopped"))?;
                }
            };
        }
        // In the order data flows, so a loop's parts tend to arrive together.
        take!(states, State, Some(0));
        take!(measurements, Measurements, Some(1));
        take!(estimates, Estimate, Some(2));
        take!(commands, Command, Some(3));
        take!(records, Record, None::<usize>);
        for event in watch.check() {
            emit(&event)?;
        }
        Ok(n)
    };
    while !context.stop.requested() {
        if drain()? < MONITOR_BUFFER / 8 {
            std::thread::sleep(POLL_PERIOD);
        }
    }
    // The launcher stops the monitor last: everything the loop sent is queued by now.
    while drain()? > 0 {}
    drop(tx);
    let report = writer.join().map_err(|_| anyhow!("the monitor's writer panicked"))??;
    Ok(ChildEvent::MonitorReport(Box::new(report)))
}

struct Writer {
    mode: Mode,
    dt: f64,
    run_dir: PathBuf,
    sensor_names: Vec<String>,
    dims: (usize, usize, usize, Vec<usize>),
    metrics: Box<dyn Metrics>,
    trajectory: BufWriter<File>,
    loops: BufWriter<File>,
    hlog: IntervalLog,
    pending: BTreeMap<u64, Partial>,
    /// The next loop to write.
    next_k: u64,
    /// Per topic (as in [`TOPICS`]), the newest loop received.
    newest: [Option<u64>; 5],
    end_to_end: Recorder,
    hops: Vec<Recorder>,
    jitter: Recorder,
    wake: Recorder,
    data_age: Vec<Recorder>,
    /// Start of the current interval-log interval (CLOCK_MONOTONIC).
    interval_start: Option<u64>,
    last_counters: PlantCounters,
    report: MonitorReport,
    last_status: Instant,
    measure: ErrorMeasure,
    faults: Vec<FaultTracker>,
    /// A restarted monitor starts at the first loop it sees; the first one starts at 0.
    started: bool,
    restarted: bool,
}

/// Creates an output file, or, for a restarted monitor, appends to what the last one wrote;
/// returns whether the file is new (and needs its header).
fn create(dir: &Path, name: &str, restarted: bool) -> Result<(BufWriter<File>, bool)> {
    let path = dir.join(name);
    let append = restarted && path.exists();
    let file = std::fs::OpenOptions::new()
        .create(true)
        .write(true)
        .append(append)
        .truncate(!append)
        .open(&path)
        .with_context(|| format!("create {}", path.display()))?;
    Ok((BufWriter::new(file), !append))
}

/// The wall-clock time of a CLOCK_MONOTONIC time stamp.
fn wall_time(monotonic_ns: u64) -> SystemTime {
    SystemTime::now() - Duration::from_nanos(now_ns().saturating_sub(monotonic_ns))
}

/// `latency.hlog`. Interval time stamps count from its BaseTime, the run's first loop record: a
/// restarted monitor appends and reads the BaseTime back, so its time stamps go on from the last
/// monitor's instead of starting again from zero.
struct IntervalLog {
    file: BufWriter<File>,
    /// The log's BaseTime, once its header is written.
    base: Option<SystemTime>,
}

impl IntervalLog {
    fn open(dir: &Path, restarted: bool) -> Result<Self> {
        let (file, new) = create(dir, "latency.hlog", restarted)?;
        let base = if new {
            None
        } else {
            let path = dir.join("latency.hlog");
            let text = std::fs::read(&path).with_context(|| format!("read {}", path.display()))?;
            // Only the header matters; a killed monitor may have left a broken last line.
            IntervalLogIterator::new(&text).map_while(Result::ok).find_map(|entry| match entry {
                LogEntry::BaseTime(since_epoch) => Some(UNIX_EPOCH + since_epoch),
                _ => None,
            })
        };
        Ok(Self { file, base })
    }

    /// Writes the header with `first` as the time base, unless the log has one. Flushed at
    /// once, so that a monitor killed right after still leaves the base for the next.
    fn begin(&mut self, first: SystemTime) -> Result<()> {
        if self.base.is_some() {
            return Ok(());
        }
        // The header keeps milliseconds; the base is what a restarted monitor will read back.
        let since_epoch = first.duration_since(UNIX_EPOCH).unwrap_or_default();
        let base = UNIX_EPOCH + Duration::from_millis(since_epoch.as_millis() as u64);
        IntervalLogWriterBuilder::new()
            .add_comment("LoopLab latency per hop and end to end, in ns")
            .add_comment(
                "Tags: end_to_end and one per hop; one interval histogram per tag per second of wall-clock time",
            )
            .with_start_time(base)
            .with_base_time(base)
            .begin_log_with(&mut self.file, &mut V2DeflateSerializer::new())?;
        writeln!(
            self.file,
            "\"StartTimestamp\",\"Interval_Length\",\"Interval_Max\",\"Interval_Compressed_Histogram\""
        )?;
        self.file.flush()?;
        self.base = Some(base);
        Ok(())
    }

    /// Writes each non-empty histogram as the interval from `start`, `length` long, and resets it.
    fn write<'a>(
        &mut self,
        start: SystemTime,
        length: Duration,
        histograms: impl Iterator<Item = (&'a str, &'a mut Histogram<u64>)>,
    ) -> Result<()> {
        self.begin(start)?;
        let base = self.base.unwrap_or(start);
        let offset = start.duration_since(base).unwrap_or_default();
        let mut serializer = V2DeflateSerializer::new();
        let mut log = IntervalLogWriterBuilder::new().begin_log_with(&mut self.file, &mut serializer)?;
        for (tag, histogram) in histograms {
            if histogram.is_empty() {
                continue;
            }
            log.write_histogram(histogram, offset, length, Tag::new(tag))
                .map_err(|e| anyhow!("write latency.hlog: {e}"))?;
            histogram.reset();
        }
        Ok(())
    }
}

impl Writer {
    fn new(context: &Context) -> Result<Self> {
        let scenario = context.scenario.as_ref();
        let config = &context.config;
        let dir = &context.run_dir;
        let sensor_names: Vec<String> = config.sensors.keys().cloned().collect();
        let sensor_dims: Vec<usize> = config.sensors.values().map(|s| config.signal_of(s).components.len()).collect();

        let restarted = context.incarnation > 0;
        let (mut trajectory, new_trajectory) = create(dir, "trajectory.csv", restarted)?;
        let mut columns: Vec<String> = vec!["k".into(), "t".into()];
        columns.extend(scenario.state_names().iter().map(|n| n.to_string()));
        for (name, spec) in &config.sensors {
            match config.signal_of(spec).components {
                [_] => columns.push(format!("meas.{name}")),
                components => columns.extend(components.iter().map(|c| format!("meas.{name}.{c}"))),
            }
        }
        columns.extend(scenario.estimate_names().iter().map(|n| format!("est.{n}")));
        columns.extend(scenario.input_names().iter().map(|n| format!("cmd.{n}")));
        if new_trajectory {
            writeln!(trajectory, "{}", columns.join(","))?;
        }

        let (mut loops, new_loops) = create(dir, "loops.csv", restarted)?;
        let mut columns: Vec<String> = vec!["k".into(), "t".into()];
        columns.extend(LoopTrace::STAMP_NAMES.iter().map(|s| format!("{s}_ns")));
        columns.extend(
            ["end_to_end_ns", "deadline_miss", "rejected", "tick_scheduled_ns", "tick_wake_ns", "tick_period_ns"]
                .map(String::from),
        );
        if new_loops {
            writeln!(loops, "{}", columns.join(","))?;
        }

        let hlog = IntervalLog::open(dir, restarted)?;

        Ok(Self {
            mode: config.mode,
            dt: config.dt(),
            run_dir: dir.clone(),
            dims: (
                scenario.state_names().len(),
                scenario.estimate_names().len(),
                scenario.input_names().len(),
                sensor_dims,
            ),
            data_age: sensor_names.iter().map(|_| Recorder::new()).collect(),
            sensor_names,
            metrics: scenario.metrics(),
            trajectory,
            loops,
            hlog,
            pending: BTreeMap::new(),
            next_k: 0,
            newest: [None; 5],
            end_to_end: Recorder::new(),
            hops: HOPS.iter().map(|_| Recorder::new()).collect(),
            jitter: Recorder::new(),
            wake: Recorder::new(),
            interval_start: None,
            last_counters: PlantCounters::default(),
            report: MonitorReport::default(),
            last_status: Instant::now(),
            measure: scenario.error_measure(),
            faults: FaultTracker::new(config),
            started: context.incarnation == 0,
            restarted: context.incarnation > 0,
        })
    }

    fn run(mut self, rx: Receiver<Sample>) -> Result<MonitorReport> {
        loop {
            match rx.recv_timeout(STATUS_PERIOD) {
                Ok(sample) => self.take(sample)?,
                Err(RecvTimeoutError::Timeout) => {}
                Err(RecvTimeoutError::Disconnected) => break,
            }
            if self.last_status.elapsed() >= STATUS_PERIOD {
                self.last_status = Instant::now();
                self.status()?;
                for file in [&mut self.trajectory, &mut self.loops, &mut self.hlog.file] {
                    file.flush().with_context(|| format!("write to {}", self.run_dir.display()))?;
                }
            }
        }
        // Everything has arrived: write the loops still waiting for parts.
        while self.newest_any().is_some_and(|newest| self.next_k <= newest) {
            self.write_next()?;
        }
        self.finish()
    }

    fn newest_any(&self) -> Option<u64> {
        self.newest.iter().flatten().copied().max()
    }

    fn take(&mut self, sample: Sample) -> Result<()> {
        let (k, topic) = sample.key();
        if !self.started {
            // The loops before this one were the last monitor's; this report has no record of them.
            self.started = true;
            self.next_k = k;
            if k > 0 {
                self.report.missing.add(0, k - 1);
                self.report.missing.missing_before_restart = k;
            }
        }
        if let Sample::Record(record) = &sample
            && self.restarted
            && !self.report.received.contains_key(Topic::Loop.name())
        {
            // The first record: those before it went out before this monitor was up. (The
            // first monitor is up before the loop starts.)
            self.report.records_before_start = record.sequence.saturating_sub(1);
        }
        *self.report.received.entry(TOPICS[topic].name().to_owned()).or_default() += 1;
        self.newest[topic] = self.newest[topic].max(Some(k));
        if k < self.next_k {
            // That loop was written without this part, which came too late; it stays counted
            // as received.
            return Ok(());
        }
        self.pending.entry(k).or_default().put(sample);
        // Write loops in order, each once every part is either here or will never come: each
        // topic delivers in loop order, so a newer loop on a topic means this loop's part from
        // it was skipped or lost. A loop still open after JOIN_WINDOW newer ones goes as it is.
        while let Some(newest) = self.newest_any() {
            let k = self.next_k;
            let part = self.pending.get(&k);
            let settled =
                (0..TOPICS.len()).all(|t| part.is_some_and(|p| p.has(t)) || self.newest[t].is_some_and(|n| n > k));
            if k > newest || !(settled || newest >= k + JOIN_WINDOW) {
                break;
            }
            self.write_next()?;
        }
        Ok(())
    }

    /// Writes the loop `next_k` (whatever arrived of it) and moves on.
    fn write_next(&mut self) -> Result<()> {
        let k = self.next_k;
        let part = self.pending.remove(&k).unwrap_or_default();
        self.next_k = k + 1;
        let t = k as f64 * self.dt;

        if let Some(state) = &part.state {
            self.last_counters = state.counters;
            if self.mode == Mode::Realtime {
                let timing = state.timing;
                // Tick 0 is published at start, not on a timer wake-up.
                if timing.period_ns > 0 {
                    let period = (self.dt * 1e9).round() as i64;
                    self.jitter.record((timing.period_ns as i64 - period).unsigned_abs());
                    self.wake.record(timing.wake_ns.saturating_sub(timing.scheduled_ns));
                }
            }
        }

        let end_to_end = match &part.record {
            None => {
                self.report.missing.add(k, k);
                None
            }
            Some(record) => {
                self.report.records += 1;
                let stamps = record.header.trace.stamps();
                let e2e = stamps[7].saturating_sub(stamps[0]);
                self.end_to_end.record(e2e);
                for (recorder, (_, from, to)) in self.hops.iter_mut().zip(HOPS) {
                    recorder.record(stamps[to].saturating_sub(stamps[from]));
                }
                self.interval_log(stamps[0])?;
                Some(e2e)
            }
        };

        if let (Some(meas), Some(e2e)) = (&part.measurements, end_to_end) {
            // Simulation-time age of the sample used, plus (real time) the wall-clock time the
            // command took to take effect.
            let actuation = if self.mode == Mode::Realtime { e2e as f64 } else { 0.0 };
            for (recorder, reading) in self.data_age.iter_mut().zip(&meas.readings) {
                if reading.valid != 0 {
                    recorder.record(((t - reading.sample_time) * 1e9 + actuation).round().max(0.0) as u64);
                }
            }
        }

        for fault in &mut self.faults {
            fault.observe(k, &part, &self.measure);
        }
        self.write_loop_row(k, t, &part, end_to_end)?;
        self.write_trajectory_row(k, t, &part)
    }

    fn write_loop_row(&mut self, k: u64, t: f64, part: &Partial, e2e: Option<u64>) -> Result<()> {
        let mut row = format!("{k},{t}");
        match &part.record {
            Some(r) => {
                for s in r.header.trace.stamps() {
                    row.push_str(&format!(",{s}"));
                }
                row.push_str(&format!(",{},{},{}", e2e.unwrap_or(0), r.deadline_miss, r.rejected));
            }
            None => row.push_str(&",".repeat(11)),
        }
        match &part.state {
            Some(s) if self.mode == Mode::Realtime => {
                let tm = s.timing;
                row.push_str(&format!(",{},{},{}", tm.scheduled_ns, tm.wake_ns, tm.period_ns));
            }
            _ => row.push_str(",,,"),
        }
        writeln!(self.loops, "{row}")?;
        Ok(())
    }

    fn write_trajectory_row(&mut self, k: u64, t: f64, part: &Partial) -> Result<()> {
        let (n_state, n_est, n_input, sensor_dims) = &self.dims;
        let mut row = format!("{k},{t}");
        let mut push = |values: Option<&[f64]>, n: usize| match values {
            Some(v) => v[..n].iter().for_each(|x| row.push_str(&format!(",{x}"))),
            None => row.push_str(&",".repeat(n)),
        };
        push(part.state.as_ref().map(|s| &s.x[..]), *n_state);
        for (i, dim) in sensor_dims.iter().enumerate() {
            push(part.measurements.as_ref().map(|m| &m.readings[i].value[..]), *dim);
        }
        push(part.estimate.as_ref().map(|e| &e.x[..]), *n_est);
        push(part.command.as_ref().map(|c| &c.u[..]), *n_input);
        writeln!(self.trajectory, "{row}")?;

        match (&part.state, &part.measurements, &part.estimate, &part.command) {
            (Some(s), Some(m), Some(e), Some(c)) => self.metrics.observe(&Row {
                k,
                t,
                state: &s.x[..*n_state],
                readings: &m.readings[..sensor_dims.len()],
                estimate: &e.x[..*n_est],
                command: &c.u[..*n_input],
                applied: &s.u_applied[..*n_input],
            }),
            _ => self.report.partial_rows += 1,
        }
        Ok(())
    }

    /// Closes the interval-log interval when a record starts past its end.
    fn interval_log(&mut self, publish_ns: u64) -> Result<()> {
        let Some(start) = self.interval_start else {
            // The first record of this monitor: the log's time base, unless an earlier monitor
            // of the run set it.
            self.hlog.begin(wall_time(publish_ns))?;
            self.interval_start = Some(publish_ns);
            return Ok(());
        };
        if publish_ns >= start + HLOG_INTERVAL_NS {
            self.flush_interval(start, publish_ns)?;
            self.interval_start = Some(publish_ns);
        }
        Ok(())
    }

    fn flush_interval(&mut self, start: u64, end: u64) -> Result<()> {
        let length = Duration::from_nanos(end.saturating_sub(start).max(1));
        let recorders = std::iter::once(("end_to_end", &mut self.end_to_end))
            .chain(HOPS.iter().map(|h| h.0).zip(self.hops.iter_mut()));
        self.hlog.write(wall_time(start), length, recorders.map(|(tag, r)| (tag, &mut r.interval)))
    }

    fn status(&self) -> Result<()> {
        let e2e = &self.end_to_end.total;
        emit(&ChildEvent::Status(MonitorStatus {
            loops_recorded: self.report.records,
            end_to_end_p99_ns: (!e2e.is_empty()).then(|| e2e.value_at_quantile(0.99)),
            deadline_misses: self.last_counters.deadline_misses,
        }))
    }

    fn finish(mut self) -> Result<MonitorReport> {
        if let Some(start) = self.interval_start {
            self.flush_interval(start, now_ns())?;
        }
        for file in [&mut self.trajectory, &mut self.loops, &mut self.hlog.file] {
            file.flush().with_context(|| format!("write to {}", self.run_dir.display()))?;
        }
        let mut report = self.report;
        report.loops_seen = self.next_k;
        report.end_to_end = self.end_to_end.stats();
        report.hops = HOPS.iter().zip(&self.hops).map(|((name, _, _), r)| (name.to_string(), r.stats())).collect();
        report.plant_tick_jitter = self.jitter.stats();
        report.plant_wake_latency = self.wake.stats();
        report.data_age = self.sensor_names.iter().cloned().zip(self.data_age.iter().map(Recorder::stats)).collect();
        report.metrics = self.metrics.finish();
        report.notes = self.metrics.notes();
        report.faults = self.faults.into_iter().map(|f| f.finish(self.dt)).collect();
        Ok(report)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The start time stamps of the intervals in a log, and its BaseTime entries.
    fn read_log(path: &Path) -> (Vec<Duration>, usize) {
        let text = std::fs::read(path).unwrap();
        let (mut starts, mut bases) = (vec![], 0);
        for entry in IntervalLogIterator::new(&text) {
            match entry.expect("a valid interval log") {
                LogEntry::Interval(interval) => starts.push(interval.start_timestamp()),
                LogEntry::BaseTime(_) => bases += 1,
                LogEntry::StartTime(_) => {}
            }
        }
        (starts, bases)
    }

    fn write_interval(log: &mut IntervalLog, start: SystemTime) {
        let mut histogram = Recorder::new().interval;
        histogram.record(1000).unwrap();
        log.write(start, Duration::from_secs(1), std::iter::once(("end_to_end", &mut histogram))).unwrap();
        log.file.flush().unwrap();
    }

    #[test]
    fn missing_loops_are_all_counted_when_the_list_is_full() {
        let mut missing = MissingLoops::default();
        missing.add(0, 9);
        for k in (20..20 + 2 * MAX_MISSING_RANGES as u64).step_by(2) {
            missing.add(k, k);
        }
        // A long run of missing loops past the list's end is one omitted range.
        for k in 1000..1010 {
            missing.add(k, k);
        }
        let missing = missing.up_to(1010, 1100);
        assert_eq!(missing.ranges.len(), MAX_MISSING_RANGES);
        assert_eq!(missing.ranges[..2], [[0, 9], [20, 20]]);
        assert_eq!(missing.missing_ranges_omitted, 2, "loop 218, then 1000–1099");
        assert_eq!(missing.missing_loops, 10 + MAX_MISSING_RANGES as u64 + 100);
    }

    #[test]
    fn a_restarted_monitor_continues_the_interval_log_time_base() {
        let dir = std::env::temp_dir().join(format!("looplab-hlog-test-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let run_start = UNIX_EPOCH + Duration::from_millis(1_700_000_000_123);
        let at = |ms: u64| run_start + Duration::from_millis(ms);

        let mut first = IntervalLog::open(&dir, false).unwrap();
        first.begin(at(0)).unwrap();
        write_interval(&mut first, at(0));
        write_interval(&mut first, at(1000));
        drop(first);

        // The restarted monitor's first record comes 2.5 s into the run.
        let mut second = IntervalLog::open(&dir, true).unwrap();
        second.begin(at(2500)).unwrap();
        write_interval(&mut second, at(2500));
        write_interval(&mut second, at(3500));
        drop(second);

        let (starts, bases) = read_log(&dir.join("latency.hlog"));
        std::fs::remove_dir_all(&dir).unwrap();
        assert_eq!(bases, 1, "one header, the first monitor's");
        assert_eq!(starts, [0, 1000, 2500, 3500].map(Duration::from_millis));
    }
}
