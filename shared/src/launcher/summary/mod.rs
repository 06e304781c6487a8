//! `summary.json`: its types here, and the builder that makes one from explicit inputs (`build`:
//! the processes' reports, their starts and what the supervisor saw), so that a run without
//! child processes can build it from its own reports. Its JSON Schema, generated from these
//! types, is kept in `shared/schema/summary.schema.json`.

mod build;
#[cfg(test)]
pub(crate) mod tests;

pub use build::{Reports, RunLog, SummaryInputs, build, write};

use std::collections::BTreeMap;

use anyhow::Result;
use schemars::{JsonSchema, Schema, SchemaGenerator, json_schema};
use serde::{Deserialize, Serialize, Serializer};

use crate::config::faults::FaultKind;
use crate::config::launch::Mode;
use crate::contract::protocol::WaitCounts;
use crate::contract::report::{CauseTally, FaultEffect, MissingLoops, Stats};
use crate::contract::role::Role;
use crate::launcher::budget::LatencyBudget;
use crate::launcher::inject::DetectedBy;
use crate::launcher::network::Network;
use crate::launcher::outcome::{Exit, StopReason};
use crate::launcher::verdict::LimitsVerdict;
pub use crate::model::scenario::ErrorMeasureInfo;
use crate::runtime::stage::realtime::Scheduling;

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
    /// With a stage lost: what the plant's fail-safe applied to the end, by input component.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub fail_safe: Option<FailSafe>,
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
    /// Lockstep: the fault's effect against the same run without the run's faults (None where
    /// it was not computed: real time, a replay, a stage that runs only as its own process).
    #[serde(default)]
    pub against_twin: Option<AgainstTwin>,
}

/// A lockstep run's fault against its fault-free twin: the same launch file without its faults,
/// run in LoopLab's own process (`tools::twin`), its state compared loop by loop.
#[derive(Debug, Clone, Default, Serialize, Deserialize, PartialEq, JsonSchema)]
pub struct AgainstTwin {
    /// The first loop from the injection on whose plant state is not the twin's (None: the
    /// state is the twin's bit for bit to the end: the fault had no effect on the plant).
    pub departed_at_s: Option<f64>,
    /// The largest error (`error_measure`) above the twin's at the same loop, from the injection on.
    pub worst_extra_error: f64,
    /// From the end of the fault until the error is back within the recovery band of the twin's
    /// for good (0 without a departure; None: not by the end of the run).
    pub recovery_s: Option<f64>,
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

/// What the plant applied once a stage was lost and no command came: `supervision.on_stale`'s
/// choice, and the input it applied in the run's last period, with units.
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq, JsonSchema)]
pub struct FailSafe {
    /// "hold" (the last command) or "zero".
    pub on_stale: String,
    /// Each input component: name, value, unit.
    pub applied: Vec<(String, f64, String)>,
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
