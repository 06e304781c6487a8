//! `summary.json` and the report printed at the end of a run.

use std::collections::BTreeMap;
use std::fmt::Write as _;

use serde::{Deserialize, Serialize};

use crate::contract::report::{HOPS, Stats};
use crate::model::scenario::ErrorMeasureInfo;

#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
pub struct Summary {
    pub scenario: String,
    /// One line naming the system and its variant.
    pub title: String,
    pub mode: String,
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
    /// Every planned loop ran and every process ended cleanly.
    pub completed: bool,
    /// Why the run ended early, when it did.
    pub stopped_because: Option<String>,
    pub deadline_misses: u64,
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
    pub restarts: BTreeMap<String, u32>,
    /// One entry per start of each process.
    pub processes: Vec<ProcessInfo>,
    /// Per process with an adaptive wait (real time): inputs caught by polling, and waits that
    /// gave up polling and blocked.
    #[serde(default)]
    pub adaptive_waits: BTreeMap<String, crate::contract::protocol::WaitCounts>,
    pub latency_ns: Latency,
    pub jitter_ns: Jitter,
    /// Per sensor: how old the sample behind command k was when command k took effect.
    pub data_age_ns: BTreeMap<String, Stats>,
    pub monitor: MonitorCounts,
    pub metrics: BTreeMap<String, f64>,
    /// What the scenario's metrics mean, in words (for example a parameter that could not be
    /// identified).
    #[serde(default)]
    pub notes: Vec<String>,
    /// What the fault report's errors measure, the band a recovery must reach and the limit
    /// the physical system must stay within.
    pub error_measure: ErrorMeasureInfo,
    pub faults: Vec<FaultReport>,
    /// What the launcher saw, in order: injections, exits, restarts, stalls.
    pub timeline: Vec<TimelineEntry>,
    /// Each restart, step by step, so that a slow one shows where its time went.
    #[serde(default)]
    pub restart_steps: Vec<RestartSteps>,
    pub shared_memory: SharedMemoryCheck,
}

/// One injected fault: what the launcher saw (wall-clock, from the injection) and what it did
/// to the loop and the physical system (simulation time, from the monitor).
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
pub struct FaultReport {
    /// In the `--fault` form.
    pub fault: String,
    pub kind: String,
    pub process: String,
    /// Simulation time of the injection.
    pub at_s: f64,
    /// When the launcher injected it (kill, stop), ms after tick 0 in wall-clock time.
    pub injected_at_ms: Option<f64>,
    /// Kill: until the launcher saw the process exit. Stop: until the monitor's input deadline
    /// (or, for the monitor itself, its silent heartbeat) flagged it.
    pub detected_after_ms: Option<f64>,
    pub detected_by: Option<String>,
    /// Kill: until the restarted process reported its ports up.
    pub restarted_after_ms: Option<f64>,
    /// Stop: until SIGCONT was sent, and until the monitor saw the process handle input again.
    pub continued_after_ms: Option<f64>,
    pub resumed_after_ms: Option<f64>,
    /// None when the monitor has no record of the fault's loops.
    pub effect: Option<crate::contract::report::FaultEffect>,
}

#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
pub struct TimelineEntry {
    /// Wall-clock ms after tick 0.
    pub at_ms: f64,
    pub event: String,
}

#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
pub struct ProcessInfo {
    pub name: String,
    /// 0 for the first start, then one more per restart.
    pub incarnation: u32,
    pub pid: u32,
    /// Exit status as text: "0", "1", "signal 9", or "running" if it never ended.
    pub exit: String,
    /// User + system CPU time, seconds.
    pub cpu_s: f64,
    /// Sensors, estimator, controller: inputs handled, and loops never seen (real-time mode: a
    /// newer input replaced them, or the plant skipped the tick).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub processed: Option<u64>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub skipped: Option<u64>,
}

#[derive(Debug, Clone, Default, Serialize, Deserialize, PartialEq)]
pub struct Latency {
    pub end_to_end: Stats,
    pub hops: BTreeMap<String, Stats>,
}

#[derive(Debug, Clone, Default, Serialize, Deserialize, PartialEq)]
pub struct Jitter {
    /// |actual tick period − dt|, real-time mode only.
    pub plant_tick: Stats,
    /// Wake-up − scheduled tick time, real-time mode only.
    pub plant_wake_latency: Stats,
}

#[derive(Debug, Clone, Default, Serialize, Deserialize, PartialEq)]
pub struct MonitorCounts {
    /// Loops with their loop record (the last monitor's, after restarts).
    pub records: u64,
    /// Loop records the plant published that never reached the monitor while it ran.
    pub lost: u64,
    /// Which loops have no record (`missing`, as inclusive ranges, the first 100 listed), how
    /// many (`missing_loops`: `records` + `missing_loops` = `loops`), and why: not published
    /// (skipped ticks, loops without command), lost, or before a restarted monitor's first
    /// loop (`missing_before_restart`).
    #[serde(flatten)]
    pub missing: crate::contract::report::MissingLoops,
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

#[derive(Debug, Clone, Default, Serialize, Deserialize, PartialEq)]
pub struct SharedMemoryCheck {
    /// No file of the run is left in /dev/shm or /tmp/iceoryx2.
    pub clean: bool,
    /// Stale resources of dead processes the launcher removed.
    pub removed_dead_nodes: u64,
    /// Files still there.
    pub leftover: Vec<String>,
}

fn micros(ns: Option<u64>) -> String {
    match ns {
        Some(ns) => format!("{:.1}", ns as f64 / 1000.0),
        None => "-".into(),
    }
}

fn stats_row(out: &mut String, label: &str, s: &Stats) {
    let _ = writeln!(
        out,
        "  {label:<26}{:>9}{:>9}{:>9}{:>9}{:>9}{:>9}{:>10}",
        s.count,
        micros(s.min),
        micros(s.p50),
        micros(s.p90),
        micros(s.p99),
        micros(s.p999),
        micros(s.max)
    );
}

/// The human-readable report.
pub fn render(s: &Summary) -> String {
    let mut out = String::new();
    let _ =
        writeln!(out, "\nLoopLab · {} · {} · {} Hz · {} s · seed {}", s.title, s.mode, s.rate_hz, s.duration_s, s.seed);
    let status = match (&s.stopped_because, s.completed) {
        (Some(why), _) => format!("stopped early: {why}"),
        (None, true) => "completed".into(),
        (None, false) => "did not complete".into(),
    };
    let _ = writeln!(
        out,
        "  {status}: {} of {} loops in {:.2} s ({:.0} loops/s) · deadline misses {} · rejected commands {}",
        s.loops, s.loops_planned, s.wall_time_s, s.loops_per_s, s.deadline_misses, s.rejected_commands
    );
    let _ = writeln!(
        out,
        "  monitor: {} loop records, {} lost; {} loops had no command (a stage skipped them), {} ticks were skipped{}",
        s.monitor.records,
        s.monitor.lost,
        s.loops_without_command,
        s.skipped_ticks,
        missing_text(&s.monitor.missing)
    );

    let _ = writeln!(
        out,
        "\n  {:<26}{:>9}{:>9}{:>9}{:>9}{:>9}{:>9}{:>10}",
        "latency (µs)", "count", "min", "p50", "p90", "p99", "p99.9", "max"
    );
    let empty = Stats::default();
    for (hop, _, _) in HOPS {
        stats_row(&mut out, &hop.replace('_', " "), s.latency_ns.hops.get(hop).unwrap_or(&empty));
    }
    stats_row(&mut out, "END TO END", &s.latency_ns.end_to_end);
    if s.jitter_ns.plant_tick.count > 0 || s.jitter_ns.plant_wake_latency.count > 0 {
        stats_row(&mut out, "tick period error |T−dt|", &s.jitter_ns.plant_tick);
        stats_row(&mut out, "tick wake-up latency", &s.jitter_ns.plant_wake_latency);
    }
    for (sensor, stats) in &s.data_age_ns {
        stats_row(&mut out, &format!("data age: {sensor}"), stats);
    }

    for (process, w) in &s.adaptive_waits {
        let _ = writeln!(
            out,
            "  adaptive wait, {process}: {} caught by polling, {} blocked after the cap",
            w.caught, w.blocked
        );
    }

    render_faults(&mut out, s);
    render_restarts(&mut out, s);

    let _ = writeln!(out, "\n  metrics");
    for (name, value) in &s.metrics {
        let _ = writeln!(out, "    {name:<34}{value:>14.6}");
    }
    for note in &s.notes {
        let _ = writeln!(out, "    note: {note}");
    }
    let _ = writeln!(
        out,
        "\n  processes: {}",
        s.processes
            .iter()
            .map(|p| {
                let again = if p.incarnation > 0 { format!(" restart {}", p.incarnation) } else { String::new() };
                format!("{}{again} (pid {}, exit {}, cpu {:.2} s)", p.name, p.pid, p.exit, p.cpu_s)
            })
            .collect::<Vec<_>>()
            .join(", ")
    );
    let _ = if s.shared_memory.clean {
        writeln!(out, "  shared memory: clean, no file of the run is left")
    } else {
        writeln!(out, "  shared memory: NOT CLEAN, left behind: {}", s.shared_memory.leftover.join(", "))
    };
    let _ = writeln!(out, "  run folder: {}", s.run_dir);
    out
}

/// The loops without a record, for the report's monitor line.
fn missing_text(m: &crate::contract::report::MissingLoops) -> String {
    if m.missing_loops == 0 {
        return String::new();
    }
    let ranges: Vec<String> = m.ranges.iter().map(|[a, b]| format!("{a}–{b}")).collect();
    let omitted = match m.missing_ranges_omitted {
        0 => String::new(),
        n => format!(" and {n} more ranges"),
    };
    let before_restart = match m.missing_before_restart {
        0 => String::new(),
        n => format!("; the first {n} were before the monitor restarted"),
    };
    format!("; no record for {} loops: {}{omitted}{before_restart}", m.missing_loops, ranges.join(", "))
}

fn ms(value: Option<f64>) -> String {
    value.map_or("-".into(), |v| format!("{v:.1}"))
}

/// Writes `rows` (the first is the header) as a table indented by two spaces, each column as
/// wide as its widest cell and two spaces from the next; `right[i]` aligns column i right.
fn write_table(out: &mut String, rows: &[Vec<String>], right: &[bool]) {
    let mut widths = vec![0; right.len()];
    for row in rows {
        for (width, cell) in widths.iter_mut().zip(row) {
            *width = (*width).max(cell.chars().count());
        }
    }
    for row in rows {
        let cells: Vec<String> = row
            .iter()
            .zip(&widths)
            .zip(right)
            .map(|((cell, &width), &right)| if right { format!("{cell:>width$}") } else { format!("{cell:<width$}") })
            .collect();
        let _ = writeln!(out, "  {}", cells.join("  ").trim_end());
    }
}

/// The faults table and the timeline.
fn render_faults(out: &mut String, s: &Summary) {
    if s.faults.is_empty() {
        return;
    }
    let m = &s.error_measure;
    let _ = writeln!(
        out,
        "\n  faults (wall-clock ms from the injection; error = {}, recovery band {}, limit {})",
        m.name, m.recovery_band, m.limit
    );
    let mut rows = vec![
        ["fault", "detected", "restarted", "outage", "worst in", "worst after", "recovery", "limits"]
            .map(String::from)
            .to_vec(),
    ];
    for f in &s.faults {
        let back = f.restarted_after_ms.or(f.resumed_after_ms);
        let (outage, during, after, recovery, limits) = match &f.effect {
            Some(e) => (
                format!("{} ticks", e.outage_ticks),
                e.worst_error_during.map_or("-".into(), |v| format!("{v:.4}")),
                e.worst_error_after.map_or("-".into(), |v| format!("{v:.4}")),
                e.recovery_s.map_or("never".into(), |v| format!("{v:.3} s")),
                if e.within_limits { "kept" } else { "EXCEEDED" },
            ),
            None => ("-".into(), "-".into(), "-".into(), "-".into(), "no record"),
        };
        rows.push(vec![
            f.fault.clone(),
            ms(f.detected_after_ms),
            ms(back),
            outage,
            during,
            after,
            recovery,
            limits.into(),
        ]);
    }
    // The fault and the verdict are text; the columns between them are numbers.
    write_table(out, &rows, &[false, true, true, true, true, true, true, false]);
    if !s.timeline.is_empty() {
        let _ = writeln!(out, "\n  timeline (wall-clock ms after tick 0)");
        for entry in &s.timeline {
            let _ = writeln!(out, "  {:>10.1}  {}", entry.at_ms, entry.event);
        }
    }
}

/// One restart, in wall-clock ms after the launcher saw the process die (its output closed and
/// it was reaped): its dead node's resources removed, the backoff, the new process started, its
/// ports up. `null` for a step that never came (the run ended first).
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
pub struct RestartSteps {
    pub process: String,
    /// The incarnation that was started.
    pub incarnation: u32,
    /// When the death was seen, ms after tick 0.
    pub died_at_ms: f64,
    pub cleaned_after_ms: Option<f64>,
    pub backoff_ms: f64,
    pub spawned_after_ms: Option<f64>,
    pub ready_after_ms: Option<f64>,
}

fn render_restarts(out: &mut String, s: &Summary) {
    if s.restart_steps.is_empty() {
        return;
    }
    let _ = writeln!(out, "\n  restarts (wall-clock ms after the death was seen)");
    let mut rows = vec![["process", "died at", "cleaned", "backoff", "started", "ready"].map(String::from).to_vec()];
    for r in &s.restart_steps {
        rows.push(vec![
            r.process.clone(),
            format!("{:.1}", r.died_at_ms),
            ms(r.cleaned_after_ms),
            format!("{:.1}", r.backoff_ms),
            ms(r.spawned_after_ms),
            ms(r.ready_after_ms),
        ]);
    }
    write_table(out, &rows, &[false, true, true, true, true, true]);
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::contract::report::FaultEffect;

    fn summary_with_fault() -> Summary {
        Summary {
            scenario: "pendulum".into(),
            title: "pendulum".into(),
            mode: "lockstep".into(),
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
            deadline_misses: 0,
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
            jitter_ns: Jitter::default(),
            data_age_ns: BTreeMap::new(),
            monitor: MonitorCounts::default(),
            metrics: BTreeMap::new(),
            notes: vec![],
            error_measure: ErrorMeasureInfo { name: "angle".into(), recovery_band: 0.05, limit: 1.0 },
            // The widths that used to run together: "206.0" filled its column, "200 ticks" too.
            faults: vec![FaultReport {
                fault: "kill controller at 1s".into(),
                kind: "kill".into(),
                process: "controller".into(),
                at_s: 1.0,
                injected_at_ms: Some(1000.0),
                detected_after_ms: Some(3.25),
                detected_by: None,
                restarted_after_ms: Some(206.0),
                continued_after_ms: None,
                resumed_after_ms: None,
                effect: Some(FaultEffect {
                    outage_ticks: 200,
                    worst_error_during: Some(0.0123),
                    worst_error_after: None,
                    recovery_s: Some(0.5),
                    within_limits: true,
                    ..Default::default()
                }),
            }],
            timeline: vec![],
            restart_steps: vec![],
            shared_memory: SharedMemoryCheck { clean: true, ..Default::default() },
        }
    }

    /// A line's cells: the text between runs of two or more spaces.
    fn cells(line: &str) -> Vec<String> {
        line.trim().split("  ").map(str::trim).filter(|c| !c.is_empty()).map(String::from).collect()
    }

    #[test]
    fn fault_table_columns_are_separated_and_aligned() {
        let text = render(&summary_with_fault());
        let lines: Vec<&str> = text.lines().collect();
        let header = lines.iter().position(|l| l.trim_start().starts_with("fault ")).expect("fault table header");
        assert_eq!(
            cells(lines[header]),
            ["fault", "detected", "restarted", "outage", "worst in", "worst after", "recovery", "limits"]
        );
        assert_eq!(
            cells(lines[header + 1]),
            ["kill controller at 1s", "3.2", "206.0", "200 ticks", "0.0123", "-", "0.500 s", "kept"]
        );
        // Numbers are right-aligned: each ends where its header ends.
        for (title, value) in [("restarted", "206.0"), ("outage", "200 ticks"), ("recovery", "0.500 s")] {
            let end_of = |line: &str, cell: &str| line.find(cell).map(|i| i + cell.len());
            assert_eq!(end_of(lines[header], title), end_of(lines[header + 1], value), "{title}");
        }
    }
}
