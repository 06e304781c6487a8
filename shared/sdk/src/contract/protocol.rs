//! How the launcher and its children talk, outside the loop itself.
//!
//! - Each child writes one JSON object per line on its stdout: `ready` once all its iceoryx2
//!   ports exist, `status` (the monitor, a few times a second), and one report when it ends.
//! - The launcher writes `start` on the plant's stdin once every child is ready, so that no
//!   sample is sent before every reader, the monitor included, is connected.
//! - Everything for humans goes to stderr, which the launcher saves in the run folder.

use std::path::PathBuf;

use serde::{Deserialize, Serialize};

/// Arguments every loop process takes; the launcher fills them in.
#[derive(Debug)]
#[cfg_attr(feature = "cli", derive(clap::Parser))]
#[cfg_attr(feature = "cli", command(about = "A LoopLab loop process; started by `looplab run`, not by hand."))]
pub struct ProcessArgs {
    /// The resolved launch file of the run.
    #[cfg_attr(feature = "cli", arg(long))]
    pub launch: PathBuf,
    /// The run's id: it names the run's iceoryx2 services and files.
    #[cfg_attr(feature = "cli", arg(long))]
    pub run_id: String,
    /// The run folder, where the monitor writes its files.
    #[cfg_attr(feature = "cli", arg(long))]
    pub run_dir: PathBuf,
    /// 0 for the first start of this process in the run, then one more per restart.
    #[cfg_attr(feature = "cli", arg(long, default_value_t = 0))]
    pub incarnation: u32,
}

/// A loop process's exit status when it stopped because its disk is full: restarting it would
/// only fill the disk again, so the launcher does not.
pub const EXIT_DISK_FULL: u8 = 3;

/// The environment a user's own stage (`[stages.<role>] command`) is started with: the same
/// arguments, by name, since its command line is the user's.
pub mod stage_env {
    /// Which stage it runs: sensors, estimator or controller.
    pub const ROLE: &str = "LOOPLAB_ROLE";
    pub const LAUNCH: &str = "LOOPLAB_LAUNCH";
    pub const RUN_ID: &str = "LOOPLAB_RUN_ID";
    pub const RUN_DIR: &str = "LOOPLAB_RUN_DIR";
    pub const INCARNATION: &str = "LOOPLAB_INCARNATION";
    /// The launcher's message-layout fingerprint (`contract::msg::layout_fingerprint`).
    pub const LAYOUT: &str = "LOOPLAB_LAYOUT";
}

impl ProcessArgs {
    /// The arguments as the launcher's environment gives them to a user's own stage, with the
    /// role it started; None where the variables are missing (not started by the launcher).
    pub fn from_env() -> Option<(String, Self)> {
        let var = |name| std::env::var(name).ok();
        Some((
            var(stage_env::ROLE)?,
            Self {
                launch: var(stage_env::LAUNCH)?.into(),
                run_id: var(stage_env::RUN_ID)?,
                run_dir: var(stage_env::RUN_DIR)?.into(),
                incarnation: var(stage_env::INCARNATION)?.parse().ok()?,
            },
        ))
    }

    /// The variables [`Self::from_env`] reads, for `role`.
    pub fn to_env(&self, role: &str) -> Vec<(&'static str, String)> {
        vec![
            (stage_env::ROLE, role.to_owned()),
            (stage_env::LAUNCH, self.launch.display().to_string()),
            (stage_env::RUN_ID, self.run_id.clone()),
            (stage_env::RUN_DIR, self.run_dir.display().to_string()),
            (stage_env::INCARNATION, self.incarnation.to_string()),
            (stage_env::LAYOUT, crate::contract::msg::layout_fingerprint().to_owned()),
        ]
    }
}

#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
#[serde(tag = "event", rename_all = "snake_case")]
pub enum ChildEvent {
    Ready,
    /// The plant started ticking: tick `k` was at `start_ns` + k·`period_ns` (CLOCK_MONOTONIC;
    /// period 0 in lockstep mode, which has no schedule).
    Started {
        start_ns: u64,
        period_ns: u64,
        k: u64,
    },
    /// Lockstep: the plant holds tick k before its state goes out, for a fault due there; it
    /// goes on when the launcher writes `go`.
    Paused {
        k: u64,
    },
    /// The monitor saw a process stop handling its input (`since_ns`: the input it has not
    /// handled arrived then) and noticed at `detected_ns`.
    Stall {
        process: String,
        since_ns: u64,
        detected_ns: u64,
    },
    /// ... and handle it again.
    Resumed {
        process: String,
        at_ns: u64,
    },
    /// This host's bridge lost the other host's bridge (its session closed or its lease ran
    /// out), or found it again.
    LinkLost {
        at_ns: u64,
    },
    LinkBack {
        at_ns: u64,
    },
    Status(Box<MonitorStatus>),
    /// The monitor's receive loop still runs: its heartbeat, a few times per status, so that a
    /// stop of the monitor is seen as soon as a stop of any other process.
    Alive,
    PlantReport(PlantReport),
    StageReport(StageReport),
    BridgeReport(BridgeReport),
    MonitorReport(Box<crate::contract::report::MonitorReport>),
}

/// The live numbers behind the launcher's status line and its dashboard.
#[derive(Debug, Clone, Default, Serialize, Deserialize, PartialEq)]
pub struct MonitorStatus {
    pub loops_recorded: u64,
    /// Every loop before this one is written and saved (a restarted monitor goes on from it).
    #[serde(default)]
    pub loops_written: u64,
    pub end_to_end_p99_ns: Option<u64>,
    pub deadline_misses: u64,
    /// What happened since the previous status (the monitor process sends it; a recording with
    /// no one watching has none).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub live: Option<LiveStatus>,
}

/// The deadline misses so far, with their share of the loops written: "12 (0.3 %)".
pub fn misses_text(status: &MonitorStatus) -> String {
    let share = status.deadline_misses as f64 * 100.0 / status.loops_written.max(1) as f64;
    format!("{} ({share:.1} %)", status.deadline_misses)
}

/// The loop since the previous status: latencies, tick timing and a few of the scenario's
/// signals, for the dashboard.
#[derive(Debug, Clone, Default, Serialize, Deserialize, PartialEq)]
pub struct LiveStatus {
    pub end_to_end: LiveLatency,
    /// In the order of `contract::report::HOPS`.
    pub hops: Vec<LiveLatency>,
    /// |tick period − dt| of the plant's clocked ticks (none in lockstep).
    pub tick_period_error: LiveLatency,
    /// The key signals (`monitor::live::key_signals`), a few points per status.
    pub points: Vec<SignalPoint>,
}

/// One latency (ns): the loops since the previous status (how many, the largest), the last second
/// of loops (p50, p99, max) and the run's maximum so far.
#[derive(Debug, Clone, Default, Serialize, Deserialize, PartialEq)]
pub struct LiveLatency {
    pub count: u64,
    pub latest_max: Option<u64>,
    pub p50: Option<u64>,
    pub p99: Option<u64>,
    pub max: Option<u64>,
    pub run_max: Option<u64>,
}

/// The key signals at simulation time `t`: per signal its true value and its estimate (None:
/// not estimated, missing or not finite).
#[derive(Debug, Clone, Default, Serialize, Deserialize, PartialEq)]
pub struct SignalPoint {
    pub t: f64,
    pub values: Vec<[Option<f64>; 2]>,
}

#[derive(Debug, Clone, Default, Serialize, Deserialize, PartialEq)]
pub struct PlantReport {
    /// Loops (ticks) that ran: states published plus skipped ticks.
    pub loops: u64,
    /// States published.
    pub published: u64,
    /// Commands received (in time or late).
    pub commands: u64,
    pub counters: crate::contract::msg::PlantCounters,
    /// A restarted plant: the tick its snapshot held.
    pub restored_at: Option<u64>,
    /// A restarted plant of the user's own model that went on from the state vector alone (its
    /// model does not serialise itself), in words for the report.
    #[serde(default)]
    pub resumed_note: Option<String>,
    /// Lockstep: the loop whose command never came (`supervision.lockstep_stall_s`).
    pub stalled_at: Option<u64>,
    /// CLOCK_MONOTONIC of the first and last state published.
    pub first_publish_ns: u64,
    pub last_publish_ns: u64,
    /// The run was stopped (signal) before all its loops ran.
    pub stopped_early: bool,
    /// Samples that waited for a full reader, and samples dropped for one (lockstep).
    pub waited: u64,
    pub dropped: u64,
    /// Adaptive waits: caught the command or tick by polling, or blocked after the cap.
    #[serde(default)]
    pub wait: WaitCounts,
    /// What the actuator applied over the last period it ran: after a stage was lost, what the
    /// fail-safe (`on_stale`) held.
    #[serde(default)]
    pub last_applied: Vec<f64>,
}

#[derive(Debug, Clone, Default, Serialize, Deserialize, PartialEq)]
pub struct StageReport {
    /// Inputs handled.
    pub processed: u64,
    /// Loops this stage never saw (real-time mode): a newer input replaced them, or the plant
    /// skipped the tick.
    pub skipped: u64,
    /// Outputs that waited for a full reader (lockstep back-pressure).
    pub waited: u64,
    /// Outputs dropped for a reader that stayed full past the lockstep limit.
    pub dropped: u64,
    /// Outputs dropped by a `drop` fault.
    pub dropped_by_fault: u64,
    /// Times an upstream process was seen restarted (a new incarnation in the data).
    pub upstream_restarts: u64,
    /// Adaptive waits: caught the input by polling, or blocked after the cap.
    #[serde(default)]
    pub wait: WaitCounts,
}

/// What an adaptive wait did, for the process's report.
#[derive(Debug, Default, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, schemars::JsonSchema)]
pub struct WaitCounts {
    /// Waits that found the input within the poll window.
    pub caught: u64,
    /// Waits that gave up polling and blocked.
    pub blocked: u64,
    /// Waits that blocked without polling because the CPU was wanted by another task (a
    /// busy machine), or that stopped polling when they found so.
    #[serde(default)]
    pub busy: u64,
}

/// What a bridge carried over the link, per crossing topic, and what the link did.
#[derive(Debug, Clone, Default, Serialize, Deserialize, PartialEq, schemars::JsonSchema)]
pub struct BridgeReport {
    /// By topic name.
    pub topics: std::collections::BTreeMap<String, CrossingCounts>,
    pub link: LinkCounts,
    /// Files of the run still in shared memory on its host once it cleaned up there (the
    /// remote bridge, the last process of the run on its host).
    pub leftover: Vec<String>,
}

/// One crossing topic, as one bridge saw it.
#[derive(Debug, Clone, Copy, Default, Serialize, Deserialize, PartialEq, schemars::JsonSchema)]
pub struct CrossingCounts {
    /// Frames read from shared memory and sent over the link.
    pub sent: u64,
    /// Sends the link refused (congestion, no peer); those frames are lost.
    pub send_errors: u64,
    /// Frames received from the link and published into shared memory.
    pub received: u64,
    /// Times a received frame's loop number jumped ahead of the previous one's + 1.
    pub gaps: u64,
    /// Loops missed in those gaps.
    pub missing: u64,
    /// Received frames of the wrong size (a peer of another build), dropped.
    pub malformed: u64,
}

impl std::ops::AddAssign for CrossingCounts {
    fn add_assign(&mut self, c: Self) {
        self.sent += c.sent;
        self.send_errors += c.send_errors;
        self.received += c.received;
        self.gaps += c.gaps;
        self.missing += c.missing;
        self.malformed += c.malformed;
    }
}

/// The link to the other host's bridge, as one bridge saw it (its own CLOCK_MONOTONIC).
#[derive(Debug, Clone, Default, Serialize, Deserialize, PartialEq, schemars::JsonSchema)]
pub struct LinkCounts {
    /// Times the peer appeared; more than one means it reconnected.
    pub connects: u64,
    /// Times it was lost (its session closed, or its lease ran out).
    pub losses: u64,
    /// Each time without the peer after it was first seen.
    pub outages: Vec<Outage>,
}

#[derive(Debug, Clone, Copy, Default, Serialize, Deserialize, PartialEq, schemars::JsonSchema)]
pub struct Outage {
    pub lost_ns: u64,
    /// None: still lost when the bridge ended.
    pub back_ns: Option<u64>,
}
