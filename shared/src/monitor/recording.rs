//! The recorder: takes the loop's messages in any order, joins them by loop, feeds the
//! statistics, the fault trackers and the scenario's metrics, passes each loop to the sinks, and
//! ends with the [`MonitorReport`]. No IPC, no threads, no output but the sinks': the monitor
//! process feeds it from iceoryx2, an in-process run feeds it directly.

use std::path::{Path, PathBuf};

use anyhow::Result;

use crate::config::launch::{LaunchConfig, Mode};
use crate::contract::msg::{Command, Estimate, Header, MONITOR_BUFFER, Measurements, PlantCounters};
use crate::contract::protocol::MonitorStatus;
use crate::contract::report::{HOPS, MonitorReport};
use crate::contract::role::{Role, Topic};
use crate::model::layout::VectorLayout;
use crate::model::scenario::{ErrorMeasure, Metrics, Row, Scenario};
use crate::monitor::cause::{self, Explanation};
use crate::monitor::crossing::Crossing;
use crate::monitor::fault_effect::FaultTracker;
use crate::monitor::injections::{self, Injection};
use crate::monitor::join::{Joiner, LoopParts, PerTopic, Sample};
use crate::monitor::live::Live;
use crate::monitor::resume::{self, Frozen, Thawed};
use crate::monitor::sinks::{self, FileEnd, JoinedLoop, RunSink, SinkSetup};
use crate::monitor::stats::LoopStats;

/// A loop still missing parts once this many newer loops have arrived is written as it is: by
/// then the monitor's buffer of that topic has overflowed past it.
const JOIN_WINDOW: u64 = 2 * MONITOR_BUFFER as u64;

/// Called with the live numbers at each [`Recording::checkpoint`].
pub type StatusCallback = Box<dyn FnMut(&MonitorStatus) -> Result<()> + Send>;

pub struct Recording {
    rate_hz: f64,
    joiner: Joiner,
    layout: VectorLayout,
    stats: LoopStats,
    metrics: Box<dyn Metrics>,
    measure: ErrorMeasure,
    faults: Vec<FaultTracker>,
    sinks: Vec<Box<dyn RunSink>>,
    report: MonitorReport,
    /// The plant's counters in the newest state written.
    last_counters: PlantCounters,
    status: Option<StatusCallback>,
    /// What the next status reports of the loops since the last (only with a status callback).
    live: Option<Live>,
    /// A restarted monitor starts at the first loop it sees; the first one starts at 0.
    started: bool,
    restarted: bool,
    /// Which monitor this is (0 the first): a monitor's kill is over once another records.
    incarnation: u32,
    /// Where the files go.
    run_dir: PathBuf,
    /// A replay of a real-time recording: what goes out marked lost stands for a message that
    /// never came, and is left out, as the recording has none.
    leave_out_lost: bool,
    /// Where the running state goes at each checkpoint, for the next monitor ([`resume`]).
    snapshot: Option<PathBuf>,
    /// The first loop this recording has no state of: 0, or where the last monitor's snapshot
    /// ended (a restarted monitor's loops before its first are missing from here on).
    resume_k: u64,
    /// The highest loop-record sequence number received, by this monitor or the ones before.
    last_record_sequence: u64,
    /// This monitor's first loop record came (a restarted one counts those before it).
    records_started: bool,
    /// Restarted without the last monitor's metrics: they cover the loops from this one on.
    metrics_from: Option<u64>,
    /// Why the last monitor's snapshot could not be used.
    resume_failed: Option<String>,
    /// Real time: where the launcher says when it injected each kill and stop.
    injections: Option<PathBuf>,
    /// Why that could not be read, the last time it could not.
    injections_failed: Option<String>,
    /// The newest measurements, estimate and command seen: what each stage's output holds at a
    /// loop it gave none (a stopped or dead stage), for the metrics.
    held: (Option<Measurements>, Option<Estimate>, Option<Command>),
    /// Real time: a loop can miss its deadline.
    wall_clock: bool,
    /// Loops over this end-to-end latency are explained too (`explain_over_us`), ns.
    explain_over_ns: Option<u64>,
    /// The header of the newest message written from each topic: what a stage sent last before
    /// a loop it skipped.
    last_outputs: PerTopic<Option<Header>>,
}

impl Recording {
    /// A recording of the run into `run_dir` by monitor `incarnation` (a restarted monitor, one
    /// above 0, appends to the files). `status` gets the live numbers at each checkpoint.
    pub fn new(
        config: &LaunchConfig,
        scenario: &dyn Scenario,
        run_dir: &Path,
        incarnation: u32,
        status: Option<StatusCallback>,
    ) -> Result<Self> {
        Self::open(config, scenario, run_dir, incarnation, status, false)
    }

    /// An in-process run's recording, which has a core to spare for its files
    /// ([`SinkSetup::spare_core`]).
    pub fn in_process(config: &LaunchConfig, scenario: &dyn Scenario, run_dir: &Path) -> Result<Self> {
        Self::open(config, scenario, run_dir, 0, None, true)
    }

    fn open(
        config: &LaunchConfig,
        scenario: &dyn Scenario,
        run_dir: &Path,
        incarnation: u32,
        status: Option<StatusCallback>,
        spare_core: bool,
    ) -> Result<Self> {
        let layout = VectorLayout::new(config, scenario);
        let restarted = incarnation > 0;
        let sinks = sinks::open(&SinkSetup { run_dir, restarted, config, layout: &layout, spare_core })?;
        let live = status.is_some().then(|| Live::new(&layout, config.rate_hz));
        // The one place the mode matters to the recording: in real time the loop runs in
        // wall-clock time, so a command's latency ages its data and a `stop` lasts for the loop.
        let wall_clock = config.mode == Mode::Realtime;
        Ok(Self {
            rate_hz: config.rate_hz,
            joiner: Joiner::new(JOIN_WINDOW),
            stats: LoopStats::new(layout.sensors.len(), config.period_ns(), wall_clock)
                .with_crossing(Crossing::new(config)),
            layout,
            metrics: scenario.metrics(),
            measure: scenario.error_measure(),
            faults: FaultTracker::for_faults(config, wall_clock),
            sinks,
            report: MonitorReport::default(),
            last_counters: PlantCounters::default(),
            live,
            status,
            started: !restarted,
            restarted,
            incarnation,
            run_dir: run_dir.to_path_buf(),
            leave_out_lost: config.replay.as_ref().is_some_and(|r| r.recorded_in_real_time),
            snapshot: None,
            resume_k: 0,
            last_record_sequence: 0,
            records_started: false,
            metrics_from: None,
            resume_failed: None,
            injections: None,
            injections_failed: None,
            held: (None, None, None),
            wall_clock,
            explain_over_ns: config.explain_over_ns(),
            last_outputs: PerTopic::default(),
        })
    }

    /// Judges each kill and stop from when the launcher says, in `path`, it injected it (real
    /// time), read at each checkpoint and at the end.
    pub fn with_injections(mut self, path: PathBuf) -> Self {
        self.injections = Some(path);
        self
    }

    /// Tells each fault tracker what the launcher wrote of its fault's injection.
    fn learn_injections(&mut self) {
        let Some(path) = &self.injections else { return };
        match injections::read(path) {
            Ok(injections) => {
                self.injections_failed = None;
                for (i, injection) in injections {
                    let Some(tracker) = self.faults.get_mut(i) else { continue };
                    match injection {
                        Injection::AtLoop(k) => tracker.injected_at(k, &self.measure),
                        Injection::NotInjected => tracker.not_injected(),
                    }
                }
            }
            Err(e) => self.injections_failed = Some(format!("{e:#}")),
        }
    }

    /// Writes the running state to `path` at each checkpoint; a restarted recording first goes
    /// on from the one there, if the last monitor wrote one (else, as without it, the loops
    /// before its first are missing and its numbers cover its own span).
    pub fn with_snapshot(mut self, path: PathBuf, scenario: &dyn Scenario) -> Self {
        if self.restarted {
            match resume::read(&path) {
                Ok(Some(frozen)) => {
                    if let Err(e) = self.thaw(frozen, scenario) {
                        self.resume_failed = Some(format!("{e:#}"));
                    }
                }
                Ok(None) => {}
                Err(e) => self.resume_failed = Some(format!("{e:#}")),
            }
        }
        self.snapshot = Some(path);
        self
    }

    /// Goes on from the last monitor's state, its files cut back to where it saved it (it may
    /// have written loops past its save, which this one counts missing or writes again); on an
    /// error, leaves the recording as it was.
    fn thaw(&mut self, frozen: Thawed, scenario: &dyn Scenario) -> Result<()> {
        let mut report: MonitorReport = serde_json::from_str(&frozen.report)?;
        for end in &frozen.files {
            end.cut_back(&self.run_dir)?;
        }
        report.missing.go_on_from(frozen.missing_newest);
        match &frozen.metrics {
            Some(bytes) => {
                let mut metrics = scenario.metrics();
                metrics.thaw(bytes)?;
                self.metrics = metrics;
            }
            // Marked at the first loop this monitor sees.
            None => self.metrics_from = Some(0),
        }
        self.report = report;
        self.stats = frozen.stats;
        self.faults = frozen.faults;
        self.last_counters = frozen.last_counters;
        self.resume_k = frozen.next_k;
        self.last_record_sequence = frozen.last_record_sequence;
        Ok(())
    }

    /// Writes the running state for the next monitor, with the files' lengths (`files`).
    fn freeze(&self, path: &Path, files: Vec<FileEnd>) -> Result<()> {
        let report = serde_json::to_string(&self.report)?;
        resume::write(
            path,
            &Frozen {
                // Loops still waiting for parts are not in the state: they are the next one's.
                next_k: self.joiner.next_k(),
                report,
                missing_newest: self.report.missing.newest(),
                last_record_sequence: self.last_record_sequence,
                stats: &self.stats,
                faults: &self.faults,
                metrics: self.metrics.freeze(),
                last_counters: self.last_counters,
                files,
            },
        )
    }

    /// Takes one message; writes every loop it completes.
    pub fn take(&mut self, sample: Sample) -> Result<()> {
        if self.leave_out_lost && !matches!(sample, Sample::Loop(_)) && sample.header().lost != 0 {
            return Ok(());
        }
        let (k, topic) = sample.key();
        if !self.started {
            // The loops from where the last monitor's state ended to this one went with it (or
            // came while none ran): this report has no record of them.
            self.started = true;
            let first = k.max(self.resume_k);
            self.joiner.start_at(first);
            if first > self.resume_k {
                self.report.missing.add(self.resume_k, first - 1);
                self.report.missing.missing_before_restart += first - self.resume_k;
            }
            if self.metrics_from.is_some() {
                self.metrics_from = Some(first);
            }
        }
        if let Sample::Loop(record) = &sample {
            if self.restarted && !self.records_started {
                // This monitor's first record: those since the last one counted went out while
                // no monitor was up to count them. (The first monitor is up before the loop starts.)
                self.report.records_before_start +=
                    record.sequence.saturating_sub(1).saturating_sub(self.last_record_sequence);
            }
            self.records_started = true;
            self.last_record_sequence = self.last_record_sequence.max(record.sequence);
            for stage in Role::STAGES {
                let incarnation = record.header.incarnations[stage.slot().expect("a stage has a slot")] as usize;
                let counts = self.report.records_by_incarnation.entry(stage).or_default();
                if counts.len() <= incarnation {
                    counts.resize(incarnation + 1, 0);
                }
                counts[incarnation] += 1;
            }
        }
        // Found without making the key: a loop's five samples allocate nothing.
        match self.report.received.get_mut(topic.name()) {
            Some(count) => *count += 1,
            None => {
                self.report.received.insert(topic.name().to_owned(), 1);
            }
        }
        // A part of a loop written already came too late: it stays counted as received.
        if self.joiner.put(sample) {
            while let Some((k, parts)) = self.joiner.next_settled() {
                self.write(k, &parts)?;
            }
        }
        Ok(())
    }

    /// Flushes every sink, then leaves the running state for the next monitor.
    fn save(&mut self) -> Result<()> {
        self.sinks.iter_mut().try_for_each(|sink| sink.flush())?;
        match &self.snapshot {
            Some(path) => self.freeze(path, self.sinks.iter().map(|sink| sink.end()).collect::<Result<_>>()?),
            None => Ok(()),
        }
    }

    /// Learns the launcher's injections, flushes every sink, saves the running state for the
    /// next monitor, then reports the status (if there is a callback).
    pub fn checkpoint(&mut self) -> Result<()> {
        self.learn_injections();
        // Saved before the status: the status says how far a successor would go on from.
        self.save()?;
        if let Some(callback) = &mut self.status {
            let status = MonitorStatus {
                loops_recorded: self.report.records,
                loops_written: self.joiner.next_k(),
                end_to_end_p99_ns: self.stats.end_to_end.quantile(0.99),
                deadline_misses: self.last_counters.deadline_misses + self.last_counters.skipped_ticks,
                live: self.live.as_mut().map(|live| live.take(&self.stats)),
            };
            callback(&status)?;
        }
        Ok(())
    }

    /// Everything has arrived: writes the loops still waiting for parts, finishes every sink and
    /// returns the report.
    pub fn finish(mut self) -> Result<MonitorReport> {
        while let Some((k, parts)) = self.joiner.next_remaining() {
            self.write(k, &parts)?;
        }
        // The launcher stops the monitor after its last injection.
        self.learn_injections();
        let mut report = std::mem::take(&mut self.report);
        if let Some(crossing) = &mut self.stats.crossing {
            report.crossing = Some(crossing.finish(&mut self.stats.hops));
        }
        let stats = &self.stats;
        report.loops_seen = self.joiner.next_k();
        report.end_to_end = stats.end_to_end.stats();
        report.hops = HOPS.iter().zip(&stats.hops).map(|((name, _, _), d)| (name.to_string(), d.stats())).collect();
        report.plant_tick_jitter = stats.plant_tick_jitter.stats();
        report.plant_wake_latency = stats.plant_wake_latency.stats();
        report.data_age = self
            .layout
            .sensors
            .iter()
            .map(|(name, _)| name.clone())
            .zip(stats.data_age.iter().map(|d| d.stats()))
            .collect();
        report.metrics = self.metrics.finish();
        report.notes = self.metrics.notes();
        if let Some(k) = self.metrics_from {
            report.notes.insert(
                0,
                format!(
                    "the metrics cover the loops from {k} on (t = {} s): the monitor restarted, and this scenario's \
                     metrics cannot be carried over a restart",
                    k as f64 / self.rate_hz
                ),
            );
        }
        if let Some(e) = &self.injections_failed {
            report.notes.insert(
                0,
                format!("the monitor could not read when the launcher injected its faults ({e}): those it never heard of are reported as not injected"),
            );
        }
        if let Some(e) = &self.resume_failed {
            report.notes.insert(
                0,
                format!("the monitor restarted and could not go on from the last one's numbers ({e}): the numbers cover its own span"),
            );
        }
        if let Some(k) = report.diverged_at {
            report.notes.insert(
                0,
                format!(
                    "the simulation diverged at loop {k} (t = {} s): the plant's state is not finite from there on, and \
                     the metrics that depend on it are not numbers",
                    k as f64 / self.rate_hz
                ),
            );
        }
        report.faults = self.faults.into_iter().map(|f| f.finish(self.rate_hz)).collect();
        for sink in &mut self.sinks {
            sink.finish(&report)?;
        }
        Ok(report)
    }

    /// Explains loop `k` if it missed its deadline (real time: late, no command, or a tick the
    /// plant never woke for) or took longer end to end than `explain_over_us`, and counts it.
    fn explain(&mut self, k: u64, parts: &LoopParts) -> Option<Explanation> {
        let missed = parts.deadline_missed(self.wall_clock) == Some(true);
        let slow = self.explain_over_ns.is_some_and(|limit| parts.end_to_end_ns().is_some_and(|ns| ns > limit));
        if !(missed || slow) {
            return None;
        }
        let (faults, joiner, last_outputs) = (&self.faults, &self.joiner, &self.last_outputs);
        let explanation = cause::explain(
            parts,
            faults.iter().find_map(|f| f.outage(k)),
            |role| faults.iter().find_map(|f| f.blames(k, role)),
            |stage| last_outputs[stage.output().expect("a stage has an output")],
            |stage| {
                let topic = stage.output().expect("a stage has an output");
                joiner.next_with(topic).and_then(|next| next.header(topic))
            },
        );
        let name = explanation.cause.to_string();
        if missed {
            self.report.miss_causes.entry(name.clone()).or_default().add(explanation.part_ns);
        }
        if slow {
            self.report.slow_causes.entry(name).or_default().add(explanation.part_ns);
        }
        Some(explanation)
    }

    /// Writes loop `k` (whatever arrived of it).
    fn write(&mut self, k: u64, parts: &LoopParts) -> Result<()> {
        // k / rate is the closest double to the exact time (k·dt prints 0.009000000000000001).
        let t = k as f64 / self.rate_hz;
        if let Some(state) = &parts.state {
            self.last_counters = state.counters;
            if self.report.diverged_at.is_none() && state.x[..self.layout.state.len()].iter().any(|v| !v.is_finite()) {
                self.report.diverged_at = Some(k);
            }
            if t >= self.measure.judged_from_s {
                let error = (self.measure.of_state)(t, &state.x[..self.layout.state.len()]);
                let lost_beyond = self.measure.lost_beyond.map(|(value, _)| value);
                self.report.limits.observe(t, error, self.measure.limit, lost_beyond);
            }
        }
        self.stats.observe(t, parts);
        if let Some(live) = &mut self.live {
            live.observe(k, t, parts, &self.stats);
        }
        if parts.record.is_some() {
            self.report.records += 1;
        } else {
            self.report.missing.add(k, k);
        }
        for fault in &mut self.faults {
            fault.observe(k, parts, self.incarnation, &self.measure);
        }
        let cause = self.explain(k, parts);
        for topic in Topic::ALL {
            if let Some(header) = parts.header(topic) {
                self.last_outputs[topic] = Some(header);
            }
        }
        let joined = JoinedLoop { k, t, parts, cause };
        for sink in &mut self.sinks {
            sink.loop_joined(&joined)?;
        }
        if parts.state.is_none() || parts.measurements.is_none() || parts.estimate.is_none() || parts.command.is_none()
        {
            self.report.partial_rows += 1;
        }
        // The metrics follow the physical system through every loop with a state: a part that
        // did not come is the newest one seen, which is what that stage's output held (so a
        // pendulum that falls while its controller is dead is seen falling).
        let held = &mut self.held;
        held.0 = parts.measurements.or(held.0);
        held.1 = parts.estimate.or(held.1);
        held.2 = parts.command.or(held.2);
        let layout = &self.layout;
        if let (Some(s), (Some(m), Some(e), Some(c))) = (&parts.state, &self.held) {
            self.metrics.observe(&Row {
                k,
                t,
                state: &s.x[..layout.state.len()],
                readings: &m.readings[..layout.sensors.len()],
                estimate: &e.x[..layout.estimate.len()],
                command: &c.u[..layout.input.len()],
                applied: &s.u_applied[..layout.input.len()],
            })
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::config::launch::Override;
    use crate::contract::run_format::files;
    use crate::monitor::join::tests::{command, estimate, measurements, record, state, whole};
    use crate::scenarios::resolve;

    /// A lockstep pendulum run of 6 loops, recorded into a fresh folder.
    fn setup(name: &str) -> (LaunchConfig, Box<dyn Scenario>, std::path::PathBuf) {
        setup_with(name, &[])
    }

    fn setup_with(name: &str, faults: &[&str]) -> (LaunchConfig, Box<dyn Scenario>, std::path::PathBuf) {
        setup_in("lockstep", name, faults)
    }

    fn setup_in(mode: &str, name: &str, faults: &[&str]) -> (LaunchConfig, Box<dyn Scenario>, std::path::PathBuf) {
        let mut overrides: Vec<Override> =
            [&format!("mode={mode}"), "duration_s=0.006"].iter().map(|o| Override::parse(o).unwrap()).collect();
        overrides.extend(faults.iter().map(|f| Override::fault(f).unwrap()));
        let (config, scenario) = resolve("pendulum", &overrides).unwrap();
        let dir = std::env::temp_dir().join(format!("looplab-recording-{name}-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        std::fs::create_dir_all(&dir).unwrap();
        (config, scenario, dir)
    }

    fn loops_csv_rows(dir: &Path) -> Vec<String> {
        std::fs::read_to_string(dir.join("loops.csv")).unwrap().lines().skip(1).map(String::from).collect()
    }

    #[test]
    fn loops_without_a_record_are_missing_and_late_parts_only_counted() {
        let (config, scenario, dir) = setup("missing");
        let mut recording = Recording::new(&config, scenario.as_ref(), &dir, 0, None).unwrap();
        let mut samples: Vec<Sample> = vec![];
        samples.extend(whole(0));
        samples.extend(whole(1));
        // Loop 2's record is lost; its other parts come out of order, after loop 3's state.
        samples.extend([state(2), state(3), command(2), estimate(2), measurements(2)]);
        samples.extend([measurements(3), estimate(3), command(3), record(3)]);
        samples.extend(whole(4));
        // Loop 5: only the state came.
        samples.push(state(5));
        for sample in samples {
            recording.take(sample).unwrap();
        }
        // Written already (loop 3's record settled it): counted as received, not joined.
        recording.take(record(2)).unwrap();
        let report = recording.finish().unwrap();

        assert_eq!(report.records, 4);
        assert_eq!(report.loops_seen, 6);
        assert_eq!(report.missing.ranges, [[2, 2], [5, 5]]);
        assert_eq!(report.missing.missing_loops, 2);
        assert_eq!(report.partial_rows, 1, "loop 5");
        assert_eq!(report.received["loop"], 5);
        assert_eq!(report.received["state"], 6);
        assert_eq!(report.lost_records(6), 1);
        assert_eq!(report.end_to_end.count, 4);
        let rows = loops_csv_rows(&dir);
        let trajectory = std::fs::read_to_string(dir.join("trajectory.csv")).unwrap();
        std::fs::remove_dir_all(&dir).unwrap();
        assert_eq!(rows.len(), 6);
        // Lockstep: no record, no tick timing, the cells stay empty; the run-queue waits of the
        // parts that came, and no cause (lockstep misses no deadline).
        assert_eq!(rows[2], format!("2,0.002{},0,0,0,0,0,0,0,,,,", ",".repeat(14)));
        assert_eq!(rows[3], "3,0.003,0,0,0,0,0,0,0,0,0,0,0,,,,0,0,0,0,0,0,0,0,,,");
        assert_eq!(trajectory.lines().count(), 7);
    }

    #[test]
    fn a_restarted_recording_counts_the_loops_before_it_as_missing() {
        let (config, scenario, dir) = setup("restart");
        let mut first = Recording::new(&config, scenario.as_ref(), &dir, 0, None).unwrap();
        for k in 0..2 {
            whole(k).into_iter().try_for_each(|s| first.take(s)).unwrap();
        }
        drop(first);
        let statuses = std::sync::Arc::new(std::sync::Mutex::new(vec![]));
        let seen = statuses.clone();
        let status: StatusCallback = Box::new(move |s| {
            seen.lock().unwrap().push(s.clone());
            Ok(())
        });
        let mut second = Recording::new(&config, scenario.as_ref(), &dir, 1, Some(status)).unwrap();
        // It comes up at loop 3; loop 3's record is the plant's fourth.
        for k in 3..6 {
            whole(k).into_iter().try_for_each(|s| second.take(s)).unwrap();
        }
        second.checkpoint().unwrap();
        let report = second.finish().unwrap();
        let rows = loops_csv_rows(&dir);
        std::fs::remove_dir_all(&dir).unwrap();

        assert_eq!(report.missing.ranges, [[0, 2]]);
        assert_eq!(report.missing.missing_before_restart, 3);
        assert_eq!(report.records_before_start, 3);
        assert_eq!((report.records, report.loops_seen), (3, 6));
        assert_eq!(report.lost_records(6), 0);
        let statuses = statuses.lock().unwrap();
        let [status] = &statuses[..] else { panic!("one status: {statuses:?}") };
        assert_eq!((status.loops_recorded, status.end_to_end_p99_ns, status.deadline_misses), (3, Some(0), 0));
        // The live part covers the three loops since it started; no point falls on a tenth loop.
        let live = status.live.as_ref().expect("a status for a watcher has its live part");
        assert_eq!((live.end_to_end.count, live.hops.len(), live.points.len()), (3, 7, 0));
        // The first recording was dropped without finishing: what it wrote stays, and the second
        // appends (loop 2 went to neither).
        let ks: Vec<&str> = rows.iter().map(|r| r.split(',').next().unwrap()).collect();
        assert_eq!(ks, ["0", "1", "3", "4", "5"]);
    }

    #[test]
    fn a_restarted_recording_goes_on_from_the_last_ones_snapshot() {
        // The first fault's window (loops 3 and 4) falls wholly while no monitor runs.
        let (config, scenario, dir) = setup_with("resume", &["stop controller at 3ms for 1ms", "kill sensors at 5ms"]);
        let snapshot = dir.join("monitor.state");
        let mut first = Recording::new(&config, scenario.as_ref(), &dir, 0, None)
            .unwrap()
            .with_snapshot(snapshot.clone(), &*scenario);
        for k in 0..3 {
            whole(k).into_iter().try_for_each(|s| first.take(s)).unwrap();
        }
        first.checkpoint().unwrap();
        // Loop 3 reaches it after its last checkpoint, and its rows reach the files: it dies
        // with it all the same.
        whole(3).into_iter().try_for_each(|s| first.take(s)).unwrap();
        first.sinks.iter_mut().try_for_each(|sink| sink.flush()).unwrap();
        drop(first);
        let mut second =
            Recording::new(&config, scenario.as_ref(), &dir, 1, None).unwrap().with_snapshot(snapshot, &*scenario);
        for k in 5..6 {
            whole(k).into_iter().try_for_each(|s| second.take(s)).unwrap();
        }
        let report = second.finish().unwrap();
        let rows = loops_csv_rows(&dir);
        let trajectory = std::fs::read_to_string(dir.join(files::TRAJECTORY)).unwrap();
        std::fs::remove_dir_all(&dir).unwrap();

        // The files hold what the report counts: loop 3 was cut back out of them.
        let ks = |rows: Vec<&str>| rows.iter().map(|r| r.split(',').next().unwrap().to_owned()).collect::<Vec<_>>();
        assert_eq!(ks(rows.iter().map(String::as_str).collect()), ["0", "1", "2", "5"]);
        assert_eq!(ks(trajectory.lines().skip(1).collect()), ["0", "1", "2", "5"]);
        assert_eq!((report.records, report.loops_seen), (4, 6));
        assert_eq!(report.missing.ranges, [[3, 4]]);
        assert_eq!((report.missing.missing_loops, report.missing.missing_before_restart), (2, 2));
        assert_eq!(report.received["loop"], 4, "the three before the snapshot and this monitor's one");
        // Records 4 and 5 went out while no monitor counted (4 reached the first after its
        // checkpoint): not lost.
        assert_eq!(report.records_before_start, 2);
        assert_eq!(report.lost_records(6), 0);
        assert_eq!(report.end_to_end.count, 4);
        assert_eq!(report.records_by_incarnation[&Role::Controller], [4]);
        assert!(report.notes.iter().all(|n| !n.contains("restart")), "{:?}", report.notes);
        assert!(report.faults[0].unrecorded, "{:?}", report.faults[0]);
        assert!(!report.faults[1].unrecorded, "{:?}", report.faults[1]);
    }

    #[test]
    fn real_time_faults_are_judged_from_the_loop_the_launcher_says_it_injected_them_at() {
        let faults = ["stop controller at 1ms for 1ms", "kill sensors at 2ms", "kill estimator at 3ms"];
        let (config, scenario, dir) = setup_in("realtime", "injections", &faults);
        let injections = dir.join("injections.json");
        let mut recording =
            Recording::new(&config, scenario.as_ref(), &dir, 0, None).unwrap().with_injections(injections.clone());
        // The launcher, late, stopped the controller before loop 3 (planned: 1).
        let mut told = injections::Injections::from([(0, Injection::AtLoop(3))]);
        injections::write(&injections, &told).unwrap();
        for k in 0..4 {
            whole(k).into_iter().try_for_each(|s| recording.take(s)).unwrap();
        }
        recording.checkpoint().unwrap();
        // Then found the sensors not running; the estimator's kill never came.
        told.insert(1, Injection::NotInjected);
        injections::write(&injections, &told).unwrap();
        for k in 4..6 {
            whole(k).into_iter().try_for_each(|s| recording.take(s)).unwrap();
        }
        let report = recording.finish().unwrap();
        std::fs::remove_dir_all(&dir).unwrap();

        // Every loop's command was fresh: back at the stop's end, 1 ms after its real injection.
        assert_eq!(report.faults[0].commands_back_at_s, Some(0.004), "{:?}", report.faults[0]);
        assert!(!report.faults[0].not_injected);
        assert!(report.faults[1].not_injected && report.faults[2].not_injected, "{:?}", report.faults);
    }
}
