//! The builder of `summary.json` (`build`): a [`Summary`] from the processes' reports, their
//! starts and what the supervisor saw ([`RunLog`]), and its file (`write`).

use std::collections::BTreeMap;
use std::path::Path;

use anyhow::Result;

use crate::config::launch::{LaunchConfig, Mode};
use crate::contract::protocol::{BridgeReport, PlantReport, StageReport, WaitCounts};
use crate::contract::report::MonitorReport;
use crate::contract::role::Role;
use crate::contract::run_format::files;
use crate::launcher::child::Start;
use crate::launcher::inject::{FaultSeen, target};
use crate::launcher::outcome::{Outcome, StopReason};
use crate::launcher::restart::RestartRecord;
use crate::launcher::run_dir::write_atomically;
use crate::launcher::summary::{
    FailSafe, FaultReport, Jitter, Latency, LostStage, Machine, MonitorCounts, ProcessInfo, RestartSteps,
    SCHEMA_VERSION, SharedMemoryCheck, SlowLoops, Summary, TimelineEntry,
};
use crate::launcher::{budget, network, verdict};
use crate::model::layout::VectorLayout;
use crate::model::scenario::Scenario;
use crate::runtime::stage::realtime::Scheduling;

/// What the processes reported when they ended.
#[derive(Debug, Clone, Default)]
pub struct Reports {
    /// The last plant's.
    pub plant: Option<PlantReport>,
    /// Per stage, the report of each incarnation that sent one (ended cleanly), by incarnation.
    pub stages: BTreeMap<Role, BTreeMap<u32, StageReport>>,
    /// The last monitor's.
    pub monitor: Option<MonitorReport>,
    /// Each bridge's, by incarnation (when a stage runs on another host).
    pub bridges: BTreeMap<Role, BTreeMap<u32, BridgeReport>>,
}

/// What the supervisor saw during a run, in CLOCK_MONOTONIC ns; empty for a run without child
/// processes.
#[derive(Debug, Clone, Default)]
pub struct RunLog {
    /// Tick 0 of the plant's schedule, once it started.
    pub plant_start_ns: Option<u64>,
    /// What was seen of each fault of the launch file, in its order (empty: nothing of any).
    pub faults: Vec<FaultSeen>,
    pub timeline: Vec<TimelineEntry>,
    pub restarts: Vec<RestartRecord>,
    /// How each loop process was scheduled once it was ready, by role and incarnation (read
    /// only when `[realtime]` asks for something).
    pub scheduling: BTreeMap<(Role, u32), Scheduling>,
    /// The stages that died and were not restarted while the run went on (`on_death = "continue"`).
    pub lost: Vec<LostStage>,
}

impl RunLog {
    /// Milliseconds since tick 0 (0 before the plant started).
    pub fn since_start_ms(&self, ns: u64) -> f64 {
        self.plant_start_ns.map_or(0.0, |start| (ns as f64 - start as f64) / 1e6)
    }

    /// Adds `event` to the timeline, at `ns`.
    pub fn note(&mut self, ns: u64, event: String) {
        self.timeline.push(TimelineEntry { at_ms: self.since_start_ms(ns), event });
    }
}

/// Everything a summary is made of.
pub struct SummaryInputs<'a> {
    pub config: &'a LaunchConfig,
    pub scenario: &'a dyn Scenario,
    pub run_id: &'a str,
    pub run_dir: &'a Path,
    /// Wall-clock start of the run (UTC, RFC 3339).
    pub started_at: String,
    pub outcome: &'a Outcome,
    pub reports: &'a Reports,
    /// Every start of each process, per role (the `processes` list follows the start order).
    pub starts: &'a BTreeMap<Role, Vec<Start>>,
    pub log: &'a RunLog,
    pub shared_memory: SharedMemoryCheck,
}

/// The summary of a finished run.
pub fn build(inputs: SummaryInputs<'_>) -> Summary {
    let SummaryInputs { config, scenario, run_id, run_dir, started_at, outcome, reports, starts, log, shared_memory } =
        inputs;
    let plant = reports.plant.clone().unwrap_or_default();
    let monitor = reports.monitor.clone().unwrap_or_default();
    let counters = plant.counters;
    let realtime = config.mode == Mode::Realtime;
    let wall_ns = plant.last_publish_ns.saturating_sub(plant.first_publish_ns);
    let wall_time_s = wall_ns as f64 * 1e-9;
    // A plant that never reported (killed, or hung and stopped) ran at least the loops the
    // monitor saw.
    let loops = reports.plant.as_ref().map_or(monitor.loops_seen, |p| p.loops);
    let missing = monitor.missing.clone().up_to(monitor.loops_seen, loops);
    let stage_total =
        |f: fn(&StageReport) -> u64| -> u64 { reports.stages.values().flat_map(|r| r.values()).map(f).sum() };
    Summary {
        schema_version: SCHEMA_VERSION,
        looplab_version: env!("CARGO_PKG_VERSION").into(),
        git_commit: env!("LOOPLAB_GIT_COMMIT").into(),
        command_line: std::env::args_os().map(|arg| arg.to_string_lossy().into_owned()).collect(),
        machine: Machine::this(),
        scenario: config.scenario.clone(),
        title: scenario.title(),
        mode: config.mode,
        rate_hz: config.rate_hz,
        duration_s: config.duration_s,
        seed: config.seed,
        run_id: run_id.into(),
        run_dir: run_dir.display().to_string(),
        started_at,
        loops,
        loops_planned: config.loops(),
        completed: *outcome == Outcome::Completed
            && !plant.stopped_early
            && plant.loops == config.loops()
            && log.lost.is_empty(),
        stopped_because: StopReason::of(outcome, plant.stopped_early),
        lost_stages: log.lost.clone(),
        fail_safe: (!log.lost.is_empty() && !plant.last_applied.is_empty()).then(|| FailSafe {
            on_stale: serde_json::to_value(config.supervision.on_stale)
                .ok()
                .and_then(|v| v.as_str().map(str::to_owned))
                .unwrap_or_default(),
            applied: VectorLayout::new(config, scenario)
                .input
                .iter()
                .zip(&plant.last_applied)
                .map(|(c, v)| (c.name.to_owned(), *v, c.unit.to_owned()))
                .collect(),
        }),
        deadline_misses: counters.deadline_misses + counters.skipped_ticks,
        late_or_no_command: counters.deadline_misses,
        misses_by_cause: monitor.miss_causes.clone(),
        slow_loops: config.explain_over_us.map(|over_us| SlowLoops { over_us, by_cause: monitor.slow_causes.clone() }),
        sched_trace: None,
        steal_share: None,
        deadline_us: realtime.then(|| config.deadline_ns() as f64 / 1e3),
        deadline_miss_share: realtime
            .then(|| (counters.deadline_misses + counters.skipped_ticks) as f64 / plant.loops.max(1) as f64),
        rejected_commands: counters.rejected_commands,
        skipped_ticks: counters.skipped_ticks,
        stale_ticks: counters.stale_ticks,
        lost_commands: counters.lost_commands,
        loops_without_command: plant.published.saturating_sub(plant.commands),
        wall_time_s,
        loops_per_s: if wall_ns > 0 { plant.loops.saturating_sub(1) as f64 / wall_time_s } else { 0.0 },
        restarts: starts.iter().map(|(&role, runs)| (role, runs.len().saturating_sub(1) as u32)).collect(),
        processes: processes(config, starts, reports, &monitor, &log.scheduling),
        adaptive_waits: adaptive_waits(&plant, reports),
        latency_ns: Latency { end_to_end: monitor.end_to_end.clone(), hops: monitor.hops.clone() },
        latency_budget: budget::build(config, scenario, &monitor.end_to_end),
        jitter_ns: Jitter {
            plant_tick: monitor.plant_tick_jitter.clone(),
            plant_wake_latency: monitor.plant_wake_latency.clone(),
        },
        data_age_ns: monitor.data_age.clone(),
        monitor: MonitorCounts {
            records: monitor.records,
            lost: monitor.lost_records(plant.commands),
            missing,
            received: monitor.received.clone(),
            partial_rows: monitor.partial_rows,
            loop_waits: plant.waited + stage_total(|r| r.waited),
            dropped_for_monitor: plant.dropped + stage_total(|r| r.dropped),
        },
        metrics: monitor.metrics.clone(),
        notes: monitor.notes.iter().chain(&plant.resumed_note).cloned().collect(),
        diverged_at_loop: monitor.diverged_at,
        error_measure: scenario.error_measure().describe(),
        limits: verdict::judge(&monitor.limits, &scenario.error_measure().describe()),
        faults: fault_reports(config, log, &monitor),
        timeline: log.timeline.clone(),
        restart_steps: log.restarts.iter().map(|r| restart_steps(r, log)).collect(),
        shared_memory,
        network: network::build(config, &reports.bridges, starts, &monitor),
        // The supervisor's, set once the run is over.
        probe: None,
    }
}

/// Writes `summary.json` into the run folder, whole or not at all.
pub fn write(summary: &Summary, run_dir: &Path) -> Result<()> {
    write_atomically(&run_dir.join(files::SUMMARY), &(serde_json::to_string_pretty(summary)? + "\n"))
}

/// One entry per start, in start order; a stage's with that incarnation's own counts: from its
/// report, or (killed, no report) the loop records the monitor received with its mark.
fn processes(
    config: &LaunchConfig,
    starts: &BTreeMap<Role, Vec<Start>>,
    reports: &Reports,
    monitor: &MonitorReport,
    scheduling: &BTreeMap<(Role, u32), Scheduling>,
) -> Vec<ProcessInfo> {
    let mut processes = vec![];
    for role in Role::BRIDGES.into_iter().chain(Role::START_ORDER) {
        let recorded = monitor.records_by_incarnation.get(&role);
        for (n, start) in starts.get(&role).into_iter().flatten().enumerate() {
            let incarnation = n as u32;
            let report = reports.stages.get(&role).and_then(|r| r.get(&incarnation));
            processes.push(ProcessInfo {
                name: role,
                incarnation,
                pid: start.pid,
                exit: start.exit,
                cpu_s: start.cpu_s,
                wakeups: start.wakeups,
                preemptions: start.preemptions,
                processed: report.map(|r| r.processed).or_else(|| recorded.map(|r| r.get(n).copied().unwrap_or(0))),
                skipped: report.map(|r| r.skipped),
                command: config.stages.command(role).map(|stage| stage.text()),
                scheduling: scheduling.get(&(role, incarnation)).cloned(),
            });
        }
    }
    processes
}

/// Adaptive-wait counts per process, summed over its incarnations; processes that never waited
/// adaptively are left out.
fn adaptive_waits(plant: &PlantReport, reports: &Reports) -> BTreeMap<Role, WaitCounts> {
    let mut all = BTreeMap::new();
    let mut add = |role: Role, w: WaitCounts| {
        if w.caught + w.blocked + w.busy > 0 {
            let entry: &mut WaitCounts = all.entry(role).or_default();
            entry.caught += w.caught;
            entry.blocked += w.blocked;
            entry.busy += w.busy;
        }
    };
    add(Role::Plant, plant.wait);
    for (&role, stage_reports) in &reports.stages {
        for r in stage_reports.values() {
            add(role, r.wait);
        }
    }
    all
}

/// Each fault of the launch file with what the supervisor saw of it and what the monitor
/// measured.
fn fault_reports(config: &LaunchConfig, log: &RunLog, monitor: &MonitorReport) -> Vec<FaultReport> {
    config
        .faults
        .iter()
        .enumerate()
        .map(|(i, spec)| {
            let seen = log.faults.get(i).cloned().unwrap_or_default();
            let after = |ns: Option<u64>| match (seen.injected_ns, ns) {
                (Some(a), Some(b)) => Some((b as f64 - a as f64) / 1e6),
                _ => None,
            };
            FaultReport {
                fault: spec.describe(),
                kind: spec.kind,
                process: target(spec),
                at_s: spec.at_s,
                injected_at_ms: seen.injected_ns.map(|ns| log.since_start_ms(ns)),
                detected_after_ms: after(seen.detected_ns),
                detected_by: seen.detected_by,
                restarted_after_ms: after(seen.restarted_ns),
                continued_after_ms: after(seen.continued_ns),
                resumed_after_ms: after(seen.resumed_ns),
                continued_at_run_end: seen.continued_at_run_end,
                effect: monitor.faults.get(i).cloned(),
                against_twin: None,
            }
        })
        .collect()
}

/// A restart's steps in ms after its death was seen.
fn restart_steps(r: &RestartRecord, log: &RunLog) -> RestartSteps {
    let after = |ns: Option<u64>| ns.map(|ns| (ns as f64 - r.died_ns as f64) / 1e6);
    RestartSteps {
        process: r.process,
        incarnation: r.incarnation,
        died_at_ms: log.since_start_ms(r.died_ns),
        cleaned_after_ms: after(r.cleaned_ns),
        backoff_ms: r.backoff.as_secs_f64() * 1e3,
        spawned_after_ms: after(r.spawned_ns),
        ready_after_ms: after(r.ready_ns),
    }
}
