//! What the monitor hands the launcher when it ends: the recorded loop's numbers, serialised
//! into the `monitor` event and from there into `summary.json`.

use std::collections::BTreeMap;

use serde::{Deserialize, Serialize};

use crate::contract::msg::Stamp;
use crate::contract::role::{Role, Topic};

/// Metrics as JSON: a finite number as itself, and NaN and the infinities (a simulation that
/// diverged) as the strings "NaN", "inf" and "-inf": JSON has no such numbers, and a null would
/// make the whole report unreadable and say nothing of which it was.
pub mod metrics {
    use std::collections::BTreeMap;

    use serde::{Deserialize, Deserializer, Serialize, Serializer};

    /// A metric as JSON has it, for the schema.
    #[derive(Serialize, Deserialize, schemars::JsonSchema)]
    #[serde(untagged)]
    pub enum Metric {
        Number(f64),
        NotFinite(NotFinite),
    }

    #[derive(Serialize, Deserialize, schemars::JsonSchema)]
    pub enum NotFinite {
        #[serde(rename = "NaN")]
        NaN,
        #[serde(rename = "inf")]
        Inf,
        #[serde(rename = "-inf")]
        NegInf,
    }

    impl Metric {
        fn of(v: f64) -> Self {
            match v {
                v if v.is_finite() => Metric::Number(v),
                v if v.is_nan() => Metric::NotFinite(NotFinite::NaN),
                v if v > 0.0 => Metric::NotFinite(NotFinite::Inf),
                _ => Metric::NotFinite(NotFinite::NegInf),
            }
        }

        fn value(self) -> f64 {
            match self {
                Metric::Number(v) => v,
                Metric::NotFinite(NotFinite::NaN) => f64::NAN,
                Metric::NotFinite(NotFinite::Inf) => f64::INFINITY,
                Metric::NotFinite(NotFinite::NegInf) => f64::NEG_INFINITY,
            }
        }
    }

    pub fn serialize<S: Serializer>(map: &BTreeMap<String, f64>, serializer: S) -> Result<S::Ok, S::Error> {
        serializer.collect_map(map.iter().map(|(name, v)| (name, Metric::of(*v))))
    }

    pub fn deserialize<'de, D: Deserializer<'de>>(deserializer: D) -> Result<BTreeMap<String, f64>, D::Error> {
        let map = BTreeMap::<String, Metric>::deserialize(deserializer)?;
        Ok(map.into_iter().map(|(name, m)| (name, m.value())).collect())
    }
}

/// Most missing ranges listed in the report.
pub const MAX_MISSING_RANGES: usize = 100;

/// The hops of one loop, as (name, index of the start stamp, index of the end stamp) in
/// `LoopTrace::stamps()`.
pub const HOPS: [(&str, usize, usize); 7] = [
    ("plant_to_sensors", Stamp::PlantPublish.index(), Stamp::SensorsReceive.index()),
    ("sensors_compute", Stamp::SensorsReceive.index(), Stamp::SensorsPublish.index()),
    ("sensors_to_estimator", Stamp::SensorsPublish.index(), Stamp::EstimatorReceive.index()),
    ("estimator_compute", Stamp::EstimatorReceive.index(), Stamp::EstimatorPublish.index()),
    ("estimator_to_controller", Stamp::EstimatorPublish.index(), Stamp::ControllerReceive.index()),
    ("controller_compute", Stamp::ControllerReceive.index(), Stamp::ControllerPublish.index()),
    ("controller_to_plant", Stamp::ControllerPublish.index(), Stamp::PlantReceive.index()),
];

/// A latency distribution as the summary reports it, in nanoseconds. Percentiles come from the
/// HDR histogram (within 0.1%); count, min, max and mean are exact. All `None` when empty.
#[derive(Debug, Clone, Default, Serialize, Deserialize, PartialEq, schemars::JsonSchema)]
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

/// The late loops of one cause, for the report and summary.json.
#[derive(Debug, Clone, Default, Serialize, Deserialize, PartialEq, schemars::JsonSchema)]
pub struct CauseTally {
    /// Loops with this primary cause.
    pub loops: u64,
    /// The smallest and largest primary part among them, ns (None: none was measured, as for
    /// loops with no command).
    pub min_part_ns: Option<u64>,
    pub max_part_ns: Option<u64>,
    /// The primary parts added up, ns.
    pub total_part_ns: u64,
    /// With a scheduler trace (`--trace-sched`), for `queued` causes: the task that ran instead,
    /// and in how many of these loops.
    #[serde(default, skip_serializing_if = "BTreeMap::is_empty")]
    pub behind: BTreeMap<String, u64>,
}

impl CauseTally {
    /// One more late loop of this cause, its primary part `part_ns` (None: not measured).
    pub fn add(&mut self, part_ns: Option<u64>) {
        self.loops += 1;
        if let Some(part) = part_ns {
            self.min_part_ns = Some(self.min_part_ns.map_or(part, |m| m.min(part)));
            self.max_part_ns = Some(self.max_part_ns.map_or(part, |m| m.max(part)));
            self.total_part_ns += part;
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
    #[serde(with = "metrics")]
    pub metrics: BTreeMap<String, f64>,
    /// The first loop whose true state was not finite: the simulation diverged there.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub diverged_at: Option<u64>,
    /// The scenario's findings in words.
    pub notes: Vec<String>,
    /// What each fault of the launch file did to the loop, in its order.
    pub faults: Vec<FaultEffect>,
    /// Per stage, the loop records received that each of its incarnations handled (index:
    /// incarnation): the counts of a killed incarnation, which sent no report.
    #[serde(default)]
    pub records_by_incarnation: BTreeMap<Role, Vec<u64>>,
    /// With a stage on another host: its clock and the link's round trip, from the loops' stamps.
    #[serde(default)]
    pub crossing: Option<CrossingReport>,
    /// The error against the scenario's limits over every loop recorded (the run's verdict).
    #[serde(default)]
    pub limits: crate::contract::limits::LimitsWatch,
    /// Every deadline miss (real time: a period whose command did not reach the plant by its
    /// deadline, a skipped tick included), by primary cause (`monitor::cause`).
    #[serde(default)]
    pub miss_causes: BTreeMap<String, CauseTally>,
    /// Every loop whose end-to-end latency was over `explain_over_us`, by primary cause.
    #[serde(default)]
    pub slow_causes: BTreeMap<String, CauseTally>,
}

/// What the loops' own stamps tell of the other host: each loop that goes there and back is an
/// NTP exchange (t1 leaves here, t2 arrives there, t3 leaves there, t4 arrives here).
#[derive(Debug, Clone, Default, Serialize, Deserialize, PartialEq, schemars::JsonSchema)]
pub struct CrossingReport {
    /// The hops (`hops` names) between the hosts, clock-corrected with `clock`.
    pub hops: Vec<String>,
    /// The round trip over the link per loop, (t4 − t1) − (t3 − t2): no clock offset needed.
    pub round_trip: Stats,
    /// None until a loop has gone there and back.
    pub clock: Option<ClockReport>,
}

/// The other host's CLOCK_MONOTONIC against this one's, fitted to the loops' best exchanges.
#[derive(Debug, Clone, Default, Serialize, Deserialize, PartialEq, schemars::JsonSchema)]
pub struct ClockReport {
    /// There minus here, ns, at `at_ns` (here).
    pub offset_ns: f64,
    /// How much faster it runs, parts per million.
    pub drift_ppm: f64,
    /// The offset (and every corrected crossing hop) is within ± this, ns.
    pub uncertainty_ns: f64,
    pub at_ns: u64,
    /// Windows of loops fitted, one best exchange each.
    pub windows: u64,
    /// The smallest round trip seen, ns: the offset can be no surer than half of it.
    pub min_round_trip_ns: f64,
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
#[derive(Debug, Clone, Default, Serialize, Deserialize, PartialEq, schemars::JsonSchema)]
pub struct MissingLoops {
    /// Inclusive [first, last] ranges, in order.
    #[serde(rename = "missing")]
    pub ranges: Vec<[u64; 2]>,
    /// All loops without a record, listed or not.
    pub missing_loops: u64,
    /// Ranges left out of the list.
    pub missing_ranges_omitted: u64,
    /// Of `missing_loops`, those no monitor recorded around its restarts: from where the last
    /// monitor's saved state ended (its last checkpoint, or loop 0 if it saved none) to the
    /// restarted monitor's first loop.
    pub missing_before_restart: u64,
    /// The newest missing loop, listed or not: an omitted range grows while loops go on missing.
    #[serde(skip)]
    pub(crate) last: Option<u64>,
}

impl MissingLoops {
    /// The newest loop added (a restarted monitor goes on from it).
    pub fn newest(&self) -> Option<u64> {
        self.last
    }

    /// Goes on from a predecessor whose newest loop was `newest`.
    pub fn go_on_from(&mut self, newest: Option<u64>) {
        self.last = newest;
    }

    /// Adds the loops `first..=last`, which come after every loop added so far.
    pub fn add(&mut self, first: u64, last: u64) {
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
#[derive(Debug, Clone, Default, Serialize, Deserialize, PartialEq, schemars::JsonSchema)]
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
    /// No loop from the injection to the next fault or the end was recorded: no monitor ran
    /// then (it was restarting), or the run ended before it. Nothing is known of its effect,
    /// and `within_limits` says nothing.
    #[serde(default)]
    pub unrecorded: bool,
    /// Real time: the launcher never injected it (its process was not running at its time, or
    /// the run ended first). `unrecorded` too: it had no effect to judge.
    #[serde(default)]
    pub not_injected: bool,
    /// A kill whose process never came back (not restarted, or not before the next fault or
    /// the end): the loop ran without it from the injection on, and it did not recover.
    #[serde(default)]
    pub never_back: bool,
    /// The first time from the injection the error reached the scenario's limit.
    #[serde(default)]
    pub limit_exceeded_at_s: Option<f64>,
    /// The whole run split at this fault: before it, during it, after it (None: not injected).
    #[serde(default)]
    pub phases: Option<FaultPhases>,
}

/// The run split at one fault into three spans of loops that together cover every loop:
/// before (from loop 0 to the injection), during (from the injection to the first loop whose
/// command was fresh again once the fault was over, through the restarted process after a
/// kill; to the end of the run if that never came) and after (from there to the end).
#[derive(Debug, Clone, Default, Serialize, Deserialize, PartialEq, schemars::JsonSchema)]
pub struct FaultPhases {
    pub before: PhaseStats,
    pub during: PhaseStats,
    pub after: PhaseStats,
}

/// The loop over one span of a run, loops `from_k` to `to_k` (exclusive).
#[derive(Debug, Clone, Default, Serialize, Deserialize, PartialEq, schemars::JsonSchema)]
pub struct PhaseStats {
    pub from_k: u64,
    pub to_k: u64,
    /// Loops of the span whose state the monitor recorded.
    pub loops: u64,
    /// Of those, loops whose command never reached the plant.
    pub without_command: u64,
    /// Of those, loops with no command in time: none came, or it came after the next tick
    /// (lockstep has no clock: there, a miss is a loop without a command).
    pub misses: u64,
    /// End to end, over the loops with a command.
    pub end_to_end_ns: Stats,
    /// The scenario's error measure (the fault report's) over the span: its largest value and
    /// its root mean square.
    pub error_max: Option<f64>,
    pub error_rms: Option<f64>,
}

#[cfg(test)]
mod tests {
    use super::*;

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
    fn adjacent_missing_loops_make_one_range() {
        let mut missing = MissingLoops::default();
        missing.add(3, 3);
        missing.add(4, 6);
        missing.add(9, 9);
        assert_eq!(missing.ranges, [[3, 6], [9, 9]]);
        assert_eq!(missing.missing_loops, 5);
        // The summary's `monitor` object spells it flat, with the ranges as `missing`.
        let json = serde_json::to_value(&missing).unwrap();
        assert_eq!(
            json,
            serde_json::json!({
                "missing": [[3, 6], [9, 9]],
                "missing_loops": 5,
                "missing_ranges_omitted": 0,
                "missing_before_restart": 0
            })
        );
    }
}
