//! `summary.json`: its types, and the builder that makes one from explicit inputs (the
//! processes' reports, their starts and what the supervisor saw), so that a run without child
//! processes can build it from its own reports. Its JSON Schema, generated from these types, is
//! kept in `shared/schema/summary.schema.json`.

use std::collections::BTreeMap;
use std::path::Path;

use anyhow::Result;
use schemars::{JsonSchema, Schema, SchemaGenerator, json_schema};
use serde::{Deserialize, Serialize, Serializer};

use crate::config::faults::FaultKind;
use crate::config::launch::{LaunchConfig, Mode};
use crate::contract::protocol::{BridgeReport, PlantReport, StageReport, WaitCounts};
use crate::contract::report::{CauseTally, FaultEffect, MissingLoops, MonitorReport, Stats};
use crate::contract::role::Role;
use crate::launcher::budget::{self, LatencyBudget};
use crate::launcher::child::Start;
use crate::launcher::inject::{DetectedBy, FaultSeen, target};
use crate::launcher::network::{self, Network};
use crate::launcher::outcome::{Exit, Outcome, StopReason};
use crate::launcher::restart::RestartRecord;
use crate::launcher::run_dir::write_atomically;
use crate::launcher::verdict::{self, LimitsVerdict};
pub use crate::model::scenario::ErrorMeasureInfo;
use crate::model::scenario::Scenario;
use crate::runtime::realtime::Scheduling;

/// The layout version of `summary.json`: bump it on any incompatible change (a key removed,
/// renamed, retyped or given another meaning). New keys are compatible.
pub const SCHEMA_VERSION: u32 = 1;

/// The summary of one LoopLab run (`summary.json` in the run folder).
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq, JsonSchema)]
pub struct Summary {
    /// The layout version of this file, bumped on any incompatible change.
    #[serde(default)]
    pub schema_version: u32,
    /// The LoopLab version that wrote it.
    #[serde(default)]
    pub looplab_version: String,
    /// The git commit the launcher was built from, with "-dirty" if the work tree had changes,
    /// or "unknown" (built outside a git repository).
    #[serde(default)]
    pub git_commit: String,
    /// The launcher's command line, program first.
    #[serde(default)]
    pub command_line: Vec<String>,
    /// The machine it ran on.
    #[serde(default)]
    pub machine: Machine,
    pub scenario: String,
    /// One line naming the system and its variant.
    pub title: String,
    pub mode: Mode,
    pub rate_hz: f64,
    pub duration_s: f64,
    pub seed: u64,
    pub run_id: String,
    pub run_dir: String,
    /// Wall-clock start of the run (UTC, RFC 3339).
    pub started_at: String,
    /// Loops (ticks) that ran: states published plus skipped ticks.
    pub loops: u64,
    pub loops_planned: u64,
    /// Every planned loop ran and every process ended cleanly (a run that lost a stage is not).
    pub completed: bool,
    /// Why the run ended early, when it did.
    #[schemars(with = "Option<String>")]
    pub stopped_because: Option<StopReason>,
    /// Stages that died and were not restarted while the run went on to its planned end
    /// without them (`supervision.on_death = "continue"`).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub lost_stages: Vec<LostStage>,
    /// Real time: loop periods whose command did not reach the plant by the deadline: late,
    /// never (a loop without a command), or a tick the plant never woke for (`skipped_ticks`).
    /// Lockstep has no deadline: always 0 there.
    pub deadline_misses: u64,
    /// Real time: of `deadline_misses`, the loops whose state went out (the rest are skipped
    /// ticks).
    #[serde(default)]
    pub late_or_no_command: u64,
    /// Real time: every deadline miss by its primary cause (`timer`, `queued: controller`,
    /// `compute: estimator`, `transport: estimator->controller`, `fault: stop controller`,
    /// `skipped: controller`, `unknown`): how many, and the smallest, largest and total of that
    /// cause's part of their response time (from tick due to command in), ns. The counts add up
    /// to `deadline_misses` where the monitor saw every loop.
    #[serde(default)]
    pub misses_by_cause: BTreeMap<String, CauseTally>,
    /// With `explain_over_us`: every loop over that end-to-end latency, by primary cause.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub slow_loops: Option<SlowLoops>,
    /// Of the machine's CPU time during the run, the share the hypervisor gave to something else
    /// (steal, /proc/stat): a loop on a virtual machine misses more when it is high. None where
    /// it was not measured (an in-process run).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub steal_share: Option<f64>,
    /// With `trace_sched`: the scheduler trace kept, and how many `queued` loops it named a task
    /// for.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub sched_trace: Option<SchedTraceReport>,
    /// Real time: how long after its tick was due each loop's command had to reach the plant,
    /// µs (`deadline_us`, by default one loop period). None in lockstep, which has no deadline.
    #[serde(default)]
    pub deadline_us: Option<f64>,
    /// Real time: `deadline_misses` as a share of `loops` (0 to 1). None in lockstep.
    #[serde(default)]
    pub deadline_miss_share: Option<f64>,
    pub rejected_commands: u64,
    pub skipped_ticks: u64,
    /// Ticks integrated with `supervision.on_stale` applied (real time: no fresh command).
    pub stale_ticks: u64,
    /// Commands that arrived marked lost (lockstep `drop` faults).
    pub lost_commands: u64,
    /// Loops whose state went out but whose command never reached the plant: a stage was held
    /// up and a newer input replaced it (real-time mode; each is also a deadline miss).
    pub loops_without_command: u64,
    /// Wall-clock time from the first to the last state published.
    pub wall_time_s: f64,
    /// Loops per wall-clock second over that time.
    pub loops_per_s: f64,
    /// Restarts per process.
    #[serde(serialize_with = "by_name")]
    pub restarts: BTreeMap<Role, u32>,
    /// One entry per start of each process.
    pub processes: Vec<ProcessInfo>,
    /// Per process with an adaptive wait (real time): inputs caught by polling, and waits that
    /// gave up polling and blocked.
    #[serde(default, serialize_with = "by_name")]
    pub adaptive_waits: BTreeMap<Role, WaitCounts>,
    pub latency_ns: Latency,
    /// The latency budget in ms: end to end against the deadline and the delay margin.
    #[serde(default)]
    pub latency_budget: LatencyBudget,
    pub jitter_ns: Jitter,
    /// Per sensor: how old the sample behind command k was when command k took effect.
    pub data_age_ns: BTreeMap<String, Stats>,
    pub monitor: MonitorCounts,
    /// A metric that is not finite (the simulation diverged) is the string "NaN", "inf" or "-inf".
    #[serde(with = "crate::contract::report::metrics")]
    #[schemars(with = "BTreeMap<String, crate::contract::report::metrics::Metric>")]
    pub metrics: BTreeMap<String, f64>,
    /// What the scenario's metrics mean, in words (for example a parameter that could not be
    /// identified).
    #[serde(default)]
    pub notes: Vec<String>,
    /// The first loop whose true state was not finite: the simulation diverged there.
    #[serde(default)]
    pub diverged_at_loop: Option<u64>,
    /// What the fault report's errors measure, the band a recovery must reach and the limit
    /// the physical system must stay within.
    pub error_measure: ErrorMeasureInfo,
    /// The control outcome: the whole run judged against `error_measure`'s limit.
    #[serde(default)]
    pub limits: LimitsVerdict,
    pub faults: Vec<FaultReport>,
    /// What the launcher saw, in order: injections, exits, restarts, stalls.
    pub timeline: Vec<TimelineEntry>,
    /// Each restart, step by step, so that a slow one shows where its time went.
    #[serde(default)]
    pub restart_steps: Vec<RestartSteps>,
    pub shared_memory: SharedMemoryCheck,
    /// With a stage on another host: the link, the other host's clock and the crossing topics.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub network: Option<Network>,
    /// With `probe` (real time): how late the OS woke a bare timer beside the loop, at the
    /// plant's priority and the loop's rate (`launcher::probe`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub probe: Option<crate::launcher::probe::ProbeSummary>,
}

/// What the scheduler trace told of the run (summary.json's `sched_trace`).
#[derive(Debug, Clone, Default, Serialize, Deserialize, PartialEq, JsonSchema)]
pub struct SchedTraceReport {
    /// The trace in the run folder, as the kernel printed it.
    pub file: String,
    /// Events the kernel's buffer could not keep: the trace lacks them.
    pub lost_events: u64,
    /// Explained loops with a `queued: <process>` cause, and those of them whose wait the trace
    /// shows another task running through (its name is in the cause's `behind`).
    pub queued_loops: u64,
    pub named: u64,
}

/// The loops over `explain_over_us` end to end, by primary cause.
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq, JsonSchema)]
pub struct SlowLoops {
    pub over_us: f64,
    pub by_cause: BTreeMap<String, CauseTally>,
}

impl Summary {
    /// The loop ran in one process (`--in-process`): no process was started, so its hops are
    /// calls, not IPC.
    pub fn ran_in_process(&self) -> bool {
        self.processes.is_empty()
    }
}

/// A map by process written with its keys in alphabetical order, as `summary.json` always had.
fn by_name<V: Serialize, S: Serializer>(map: &BTreeMap<Role, V>, serializer: S) -> Result<S::Ok, S::Error> {
    serializer.collect_map(map.iter().map(|(role, v)| (role.name(), v)).collect::<BTreeMap<_, _>>())
}

/// One injected fault: what the launcher saw (wall-clock, from the injection) and what it did
/// to the loop and the physical system (simulation time, from the monitor).
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq, JsonSchema)]
pub struct FaultReport {
    /// In the `--fault` form.
    pub fault: String,
    pub kind: FaultKind,
    pub process: Role,
    /// Simulation time of the injection.
    pub at_s: f64,
    /// When the launcher injected it (kill, stop), ms after tick 0 in wall-clock time.
    pub injected_at_ms: Option<f64>,
    /// Kill: until the launcher saw the process exit. Stop: until the monitor's input deadline
    /// (or, for the monitor itself, its silent heartbeat) flagged it. Cut: until the input
    /// deadline of the stage across the link flagged it.
    pub detected_after_ms: Option<f64>,
    pub detected_by: Option<DetectedBy>,
    /// Kill: until the restarted process reported its ports up.
    pub restarted_after_ms: Option<f64>,
    /// Stop: until SIGCONT was sent, and until the monitor saw the process handle input again.
    /// Cut (real time): until the link passed the loop again, and until the stage across it
    /// handled its input again.
    pub continued_after_ms: Option<f64>,
    pub resumed_after_ms: Option<f64>,
    /// Stop, cut: it was still on when the run ended, so it was continued (mended) then, before
    /// its time: the run is not held for it.
    #[serde(default)]
    pub continued_at_run_end: bool,
    /// None when the monitor has no record of the fault's loops.
    pub effect: Option<FaultEffect>,
}

#[derive(Debug, Clone, Serialize, Deserialize, PartialEq, JsonSchema)]
pub struct TimelineEntry {
    /// Wall-clock ms after tick 0.
    pub at_ms: f64,
    pub event: String,
}

#[derive(Debug, Clone, Serialize, Deserialize, PartialEq, JsonSchema)]
pub struct ProcessInfo {
    pub name: Role,
    /// 0 for the first start, then one more per restart.
    pub incarnation: u32,
    pub pid: u32,
    /// Exit status as text: "0", "1", "signal 9", or "running" if it never ended.
    #[schemars(schema_with = "exit_schema")]
    pub exit: Exit,
    /// User + system CPU time, seconds.
    pub cpu_s: f64,
    /// Times it slept and was woken (voluntary context switches, all its threads): what its
    /// waiting costs the machine, a count that does not move with a noisy machine's timing.
    pub wakeups: u64,
    /// Times another task took its CPU while it could run (involuntary context switches).
    pub preemptions: u64,
    /// Sensors, estimator, controller: this incarnation's inputs handled, and loops it never saw
    /// (real-time mode: a newer input replaced them, or the plant skipped the tick). An
    /// incarnation that sent no report (killed) has, for `processed`, the loop records the
    /// monitor received with its mark, and no `skipped`.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub processed: Option<u64>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub skipped: Option<u64>,
    /// A stage of the user's own (`[stages.<role>] command`): its command, as one line.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub command: Option<String>,
    /// With `[realtime]`: how the kernel scheduled it once it was ready, and its locked memory.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub scheduling: Option<Scheduling>,
}

#[derive(Debug, Clone, Default, Serialize, Deserialize, PartialEq, JsonSchema)]
pub struct Latency {
    pub end_to_end: Stats,
    pub hops: BTreeMap<String, Stats>,
}

#[derive(Debug, Clone, Default, Serialize, Deserialize, PartialEq, JsonSchema)]
pub struct Jitter {
    /// |actual tick period − dt|, real-time mode only.
    pub plant_tick: Stats,
    /// Wake-up − scheduled tick time, real-time mode only.
    pub plant_wake_latency: Stats,
}

/// What the monitor recorded of the loop.
#[derive(Debug, Clone, Default, Serialize, Deserialize, PartialEq, JsonSchema)]
pub struct MonitorCounts {
    /// Loops with their loop record, over the whole run (a restarted monitor goes on from the
    /// last one's count).
    pub records: u64,
    /// Loop records the plant published that never reached the monitor while it ran.
    pub lost: u64,
    /// Which loops have no record (`missing`, as inclusive ranges, the first 100 listed), how
    /// many (`missing_loops`: `records` + `missing_loops` = `loops`), and why: not published
    /// (skipped ticks, loops without command), lost, or while the monitor restarted
    /// (`missing_before_restart`).
    #[serde(flatten)]
    pub missing: MissingLoops,
    /// Samples the monitor received per topic.
    pub received: BTreeMap<String, u64>,
    /// Trajectory rows with some part missing.
    pub partial_rows: u64,
    /// Lockstep only: samples a stage had to hold back because the monitor's buffer was full
    /// (lockstep keeps every record, so a slow monitor holds the loop instead of losing them),
    /// and samples dropped for it after the 5 s limit.
    pub loop_waits: u64,
    pub dropped_for_monitor: u64,
}

/// The machine a run ran on.
#[derive(Debug, Clone, Default, Serialize, Deserialize, PartialEq, JsonSchema)]
pub struct Machine {
    /// CPUs this process could use (available parallelism).
    pub cpus: u32,
    /// The CPU's `model name` in /proc/cpuinfo, if it has one.
    pub cpu_model: Option<String>,
    /// The kernel's release (`uname -r`).
    pub kernel: String,
    pub hostname: String,
}

/// The machine's CPU time, from /proc/stat's `cpu` line (USER_HZ ticks): all of it, and the part
/// the hypervisor gave to something else while this machine could have run (steal).
#[derive(Debug, Clone, Copy)]
pub struct CpuTimes {
    total: u64,
    steal: u64,
}

impl CpuTimes {
    /// Now; None where /proc/stat cannot be read.
    pub fn now() -> Option<Self> {
        let stat = std::fs::read_to_string("/proc/stat").ok()?;
        let line = stat.lines().find(|l| l.starts_with("cpu "))?;
        // user nice system idle iowait irq softirq steal [guest guest_nice: already in user, nice]
        let ticks: Vec<u64> = line.split_whitespace().skip(1).take(8).filter_map(|n| n.parse().ok()).collect();
        (ticks.len() == 8).then(|| CpuTimes { total: ticks.iter().sum(), steal: ticks[7] })
    }

    /// Of the CPU time since `self`, the share stolen (0 to 1); None if no time passed.
    pub fn steal_share_until(self, later: CpuTimes) -> Option<f64> {
        let total = later.total.checked_sub(self.total).filter(|&t| t > 0)?;
        Some(later.steal.saturating_sub(self.steal) as f64 / total as f64)
    }
}

impl Machine {
    /// This machine.
    pub fn this() -> Self {
        let cpus = std::thread::available_parallelism().map_or(1, |n| n.get() as u32);
        let cpu_model = std::fs::read_to_string("/proc/cpuinfo").ok().and_then(|info| {
            info.lines()
                .filter_map(|line| line.split_once(':'))
                .find(|(key, _)| key.trim() == "model name")
                .map(|(_, value)| value.trim().to_owned())
        });
        // SAFETY: uname fills the zeroed struct it is given; its fields are NUL-terminated.
        let (kernel, hostname) = unsafe {
            let mut names: libc::utsname = std::mem::zeroed();
            if libc::uname(&mut names) == 0 {
                let text =
                    |field: &[libc::c_char]| std::ffi::CStr::from_ptr(field.as_ptr()).to_string_lossy().into_owned();
                (text(&names.release), text(&names.nodename))
            } else {
                (String::new(), String::new())
            }
        };
        Self { cpus, cpu_model, kernel, hostname }
    }
}

/// The JSON Schema of `summary.json`, as kept in `shared/schema/summary.schema.json`: what a
/// summary is written as (serialized), pretty-printed with a final newline.
pub fn json_schema() -> String {
    let generator = schemars::generate::SchemaSettings::draft2020_12().for_serialize().into_generator();
    let schema = generator.into_root_schema_for::<Summary>();
    serde_json::to_string_pretty(&schema).expect("a schema is JSON") + "\n"
}

/// An [`Exit`] is written as its text.
fn exit_schema(_: &mut SchemaGenerator) -> Schema {
    json_schema!({ "type": "string", "pattern": "^(-?[0-9]+|signal [0-9]+|running)$" })
}

#[derive(Debug, Clone, Default, Serialize, Deserialize, PartialEq, JsonSchema)]
pub struct SharedMemoryCheck {
    /// No file of the run is left in /dev/shm or /tmp/iceoryx2.
    pub clean: bool,
    /// Stale resources of dead processes the launcher removed.
    pub removed_dead_nodes: u64,
    /// Files still there.
    pub leftover: Vec<String>,
    /// Entries named like the run's that another user made (not the run's; left where they are).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub foreign: Vec<String>,
}

/// One restart, in wall-clock ms after the launcher saw the process die (its output closed and
/// it was reaped): its dead node's resources removed, the backoff, the new process started, its
/// ports up. `null` for a step that never came (the run ended first).
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq, JsonSchema)]
pub struct RestartSteps {
    pub process: Role,
    /// The incarnation that was started.
    pub incarnation: u32,
    /// When the death was seen, ms after tick 0.
    pub died_at_ms: f64,
    pub cleaned_after_ms: Option<f64>,
    pub backoff_ms: f64,
    pub spawned_after_ms: Option<f64>,
    pub ready_after_ms: Option<f64>,
}

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

/// A stage that died, was not restarted, and whose run went on to its planned end without it
/// (`supervision.on_death = "continue"`).
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq, JsonSchema)]
pub struct LostStage {
    pub process: Role,
    /// When the launcher saw it die, wall-clock ms after tick 0.
    pub at_ms: f64,
    /// The loop from which it was missing: real time, the loop running when its death was seen;
    /// lockstep, the loop the plant was held at for its kill (None: it died by itself).
    pub at_loop: Option<u64>,
    /// How it died and why it was not restarted.
    pub why: String,
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
    let missing = monitor.missing.clone().up_to(monitor.loops_seen, plant.loops);
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
        loops: plant.loops,
        loops_planned: config.loops(),
        completed: *outcome == Outcome::Completed
            && !plant.stopped_early
            && plant.loops == config.loops()
            && log.lost.is_empty(),
        stopped_because: StopReason::of(outcome, plant.stopped_early),
        lost_stages: log.lost.clone(),
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
    write_atomically(&run_dir.join("summary.json"), &(serde_json::to_string_pretty(summary)? + "\n"))
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

#[cfg(test)]
pub(crate) mod tests {
    use super::*;
    use crate::config::launch::Override;
    use crate::scenarios::resolve;

    /// A complete lockstep run's summary, for the tests of what reads one.
    pub(crate) fn summary() -> Summary {
        Summary {
            schema_version: SCHEMA_VERSION,
            looplab_version: "0.1.0".into(),
            git_commit: "unknown".into(),
            command_line: vec!["looplab".into(), "run".into()],
            machine: Machine::default(),
            scenario: "pendulum".into(),
            title: "pendulum".into(),
            mode: Mode::Lockstep,
            rate_hz: 200.0,
            duration_s: 5.0,
            seed: 1,
            run_id: "r".into(),
            run_dir: "/tmp/r".into(),
            started_at: "2024-01-01T00:00:00Z".into(),
            loops: 1000,
            loops_planned: 1000,
            completed: true,
            stopped_because: None,
            lost_stages: vec![],
            deadline_misses: 0,
            late_or_no_command: 0,
            misses_by_cause: BTreeMap::new(),
            slow_loops: None,
            sched_trace: None,
            steal_share: None,
            deadline_us: None,
            deadline_miss_share: None,
            rejected_commands: 0,
            skipped_ticks: 0,
            stale_ticks: 0,
            lost_commands: 0,
            loops_without_command: 0,
            wall_time_s: 1.0,
            loops_per_s: 1000.0,
            restarts: BTreeMap::new(),
            processes: vec![],
            adaptive_waits: BTreeMap::new(),
            latency_ns: Latency::default(),
            latency_budget: LatencyBudget::default(),
            jitter_ns: Jitter::default(),
            data_age_ns: BTreeMap::new(),
            monitor: MonitorCounts::default(),
            metrics: BTreeMap::new(),
            notes: vec![],
            diverged_at_loop: None,
            error_measure: ErrorMeasureInfo {
                name: "angle".into(),
                recovery_band: 0.05,
                limit: 1.0,
                ..Default::default()
            },
            limits: LimitsVerdict::default(),
            faults: vec![],
            timeline: vec![],
            restart_steps: vec![],
            shared_memory: SharedMemoryCheck { clean: true, ..Default::default() },
            network: None,
            probe: None,
        }
    }

    /// What a run without child processes has: the reports, nothing the supervisor saw.
    #[test]
    fn a_summary_builds_from_the_reports_alone() {
        let overrides = [Override::parse("mode=lockstep").unwrap(), Override::parse("duration_s=0.5").unwrap()];
        let (config, scenario) = resolve("pendulum", &overrides).unwrap();
        let plant = PlantReport {
            loops: 500,
            published: 500,
            commands: 500,
            first_publish_ns: 1_000_000_000,
            last_publish_ns: 1_499_000_000,
            waited: 2,
            ..Default::default()
        };
        let stage = StageReport {
            processed: 500,
            waited: 1,
            wait: WaitCounts { caught: 3, blocked: 4, busy: 0 },
            ..Default::default()
        };
        let monitor = MonitorReport { records: 500, loops_seen: 500, ..Default::default() };
        let reports = Reports {
            plant: Some(plant),
            stages: Role::STAGES.into_iter().map(|r| (r, [(0, stage.clone())].into())).collect(),
            monitor: Some(monitor),
            ..Default::default()
        };
        let starts: BTreeMap<Role, Vec<Start>> =
            [(Role::Sensors, vec![Start { pid: 7, exit: Exit::Status(0), cpu_s: 0.5, wakeups: 0, preemptions: 0 }])]
                .into();
        let summary = build(SummaryInputs {
            config: &config,
            scenario: scenario.as_ref(),
            run_id: "0123",
            run_dir: Path::new("/tmp/run"),
            started_at: "2024-01-01T00:00:00Z".into(),
            outcome: &Outcome::Completed,
            reports: &reports,
            starts: &starts,
            log: &RunLog::default(),
            shared_memory: SharedMemoryCheck { clean: true, ..Default::default() },
        });
        assert!(summary.completed);
        assert_eq!(summary.stopped_because, None);
        assert_eq!((summary.loops, summary.loops_planned, summary.loops_without_command), (500, 500, 0));
        assert_eq!(summary.mode, Mode::Lockstep);
        let wall_time_s = 499_000_000f64 * 1e-9;
        assert_eq!(summary.wall_time_s, wall_time_s);
        assert_eq!(summary.loops_per_s, 499.0 / wall_time_s);
        assert_eq!(summary.monitor.records, 500);
        assert_eq!(summary.monitor.missing.missing_loops, 0);
        assert_eq!(summary.monitor.loop_waits, 2 + 3);
        assert_eq!(summary.restarts, [(Role::Sensors, 0)].into());
        assert_eq!(summary.processes.len(), 1);
        assert_eq!((summary.processes[0].name, summary.processes[0].processed), (Role::Sensors, Some(500)));
        let waits: Vec<_> = summary.adaptive_waits.iter().map(|(r, w)| (*r, w.caught, w.blocked)).collect();
        assert_eq!(waits, [(Role::Sensors, 3, 4), (Role::Estimator, 3, 4), (Role::Controller, 3, 4)]);
        assert!(summary.faults.is_empty() && summary.timeline.is_empty() && summary.restart_steps.is_empty());

        // The plant ran short: not completed, and said why.
        let short = Reports {
            plant: Some(PlantReport { loops: 400, stopped_early: true, ..Default::default() }),
            monitor: Some(MonitorReport { records: 300, loops_seen: 300, ..Default::default() }),
            ..reports
        };
        let summary = summary_of(&config, scenario.as_ref(), &short, &BTreeMap::new());
        assert!(!summary.completed);
        assert_eq!(summary.stopped_because, Some(StopReason::PlantStoppedEarly));
        assert_eq!(summary.monitor.missing.ranges, [[300, 399]], "the loops after the last the monitor saw");
    }

    /// The summary of a completed run with these reports and process starts, the rest default.
    fn summary_of(
        config: &LaunchConfig,
        scenario: &dyn Scenario,
        reports: &Reports,
        starts: &BTreeMap<Role, Vec<Start>>,
    ) -> Summary {
        build(SummaryInputs {
            config,
            scenario,
            run_id: "0123",
            run_dir: Path::new("/tmp/run"),
            started_at: String::new(),
            outcome: &Outcome::Completed,
            reports,
            starts,
            log: &RunLog::default(),
            shared_memory: SharedMemoryCheck::default(),
        })
    }

    /// The schema kept in the repo is the one the types make; `LOOPLAB_WRITE_SCHEMA=1` rewrites it.
    #[test]
    fn summary_schema_is_the_file_in_the_repo() {
        let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("schema/summary.schema.json");
        let schema = json_schema();
        if std::env::var_os("LOOPLAB_WRITE_SCHEMA").is_some() {
            std::fs::create_dir_all(path.parent().unwrap()).unwrap();
            std::fs::write(&path, &schema).unwrap();
        }
        let kept = std::fs::read_to_string(&path).unwrap_or_default();
        assert!(
            kept == schema,
            "{} is not the schema of `Summary`; regenerate it with \
             `LOOPLAB_WRITE_SCHEMA=1 cargo test --release -p looplab-shared summary_schema`",
            path.display()
        );
    }

    /// A killed incarnation sends no report: its count comes from the monitor's loop records,
    /// the restarted one's from its own report, and neither repeats the other's.
    #[test]
    fn each_incarnation_of_a_stage_has_its_own_counts() {
        let overrides = [Override::parse("mode=lockstep").unwrap(), Override::parse("duration_s=2").unwrap()];
        let (config, scenario) = resolve("pendulum", &overrides).unwrap();
        let reported = StageReport { processed: 1500, skipped: 2, ..Default::default() };
        let reports = Reports {
            plant: Some(PlantReport { loops: 2000, ..Default::default() }),
            stages: [(Role::Estimator, [(1, reported)].into())].into(),
            monitor: Some(MonitorReport {
                records_by_incarnation: [(Role::Estimator, vec![500, 1500]), (Role::Sensors, vec![2000])].into(),
                ..Default::default()
            }),
            ..Default::default()
        };
        let start = |pid, exit| Start { pid, exit, cpu_s: 0.0, wakeups: 0, preemptions: 0 };
        let starts: BTreeMap<Role, Vec<Start>> = [
            (Role::Estimator, vec![start(1, Exit::Signal(9)), start(2, Exit::Status(0))]),
            (Role::Plant, vec![start(3, Exit::Status(0))]),
        ]
        .into();
        let summary = summary_of(&config, scenario.as_ref(), &reports, &starts);
        let counts: Vec<_> =
            summary.processes.iter().map(|p| (p.name, p.incarnation, p.processed, p.skipped)).collect();
        assert_eq!(
            counts,
            [
                (Role::Estimator, 0, Some(500), None),
                (Role::Estimator, 1, Some(1500), Some(2)),
                (Role::Plant, 0, None, None)
            ]
        );
    }

    #[test]
    fn a_summary_says_what_wrote_it_and_where() {
        let s = {
            let (config, scenario) = resolve("pendulum", &[]).unwrap();
            summary_of(&config, scenario.as_ref(), &Reports::default(), &BTreeMap::new())
        };
        assert_eq!((s.schema_version, s.looplab_version.as_str()), (1, env!("CARGO_PKG_VERSION")));
        assert_eq!(s.command_line, std::env::args().collect::<Vec<_>>());
        assert_eq!(s.machine.cpus as usize, std::thread::available_parallelism().unwrap().get());
        assert!(!s.machine.kernel.is_empty() && !s.machine.hostname.is_empty(), "{:?}", s.machine);
    }

    #[test]
    fn maps_by_process_keep_their_alphabetical_keys_and_every_value_reads_back() {
        let mut s = summary();
        s.restarts = Role::ALL.into_iter().map(|r| (r, 0)).collect();
        s.adaptive_waits =
            [(Role::Plant, WaitCounts { caught: 1, blocked: 0, busy: 0 }), (Role::Controller, WaitCounts::default())]
                .into();
        s.stopped_because = Some(StopReason::Interrupted);
        s.processes = vec![ProcessInfo {
            name: Role::Monitor,
            incarnation: 0,
            pid: 9,
            exit: Exit::Signal(9),
            cpu_s: 0.0,
            wakeups: 0,
            preemptions: 0,
            processed: None,
            skipped: None,
            command: None,
            scheduling: None,
        }];
        let json = serde_json::to_value(&s).unwrap();
        let keys: Vec<&String> = json["restarts"].as_object().unwrap().keys().collect();
        assert_eq!(keys, ["controller", "estimator", "monitor", "plant", "sensors"]);
        let text = serde_json::to_string(&s).unwrap();
        assert!(
            text.contains(
                r#""adaptive_waits":{"controller":{"caught":0,"blocked":0,"busy":0},"plant":{"caught":1,"blocked":0,"busy":0}}"#
            ),
            "{text}"
        );
        assert!(
            text.contains(r#""mode":"lockstep""#) && text.contains(r#""stopped_because":"interrupted by a signal""#)
        );
        assert!(text.contains(r#""name":"monitor","incarnation":0,"pid":9,"exit":"signal 9""#), "{text}");
        assert_eq!(serde_json::from_str::<Summary>(&text).unwrap(), s);
    }
}
