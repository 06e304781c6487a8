//! What `looplab bench` reports: its numbers (`bench.json`) and the table it prints.

use std::collections::BTreeMap;
use std::fmt::Write as _;

use serde::Serialize;

use super::{BLOCK_C, BLOCK_PYTHON, anatomy, own_stage};
use crate::contract::role::Role;
use crate::tools::plot::latency::stats_of;

/// A latency distribution, µs.
#[derive(Debug, Clone, Default, Serialize)]
pub struct Dist {
    pub n: usize,
    pub p50: f64,
    pub p90: f64,
    pub p99: f64,
    pub p999: f64,
    pub max: f64,
}

impl Dist {
    /// The distribution of nanosecond values, in µs.
    pub(super) fn of(sorted: &[u64]) -> Self {
        Self::scaled(sorted, 1e-3)
    }

    /// Percentiles as a run's report and the charts' legends give them (the monitor's histogram),
    /// so that table, chart and report agree.
    pub(super) fn scaled(sorted: &[u64], unit: f64) -> Self {
        let s = stats_of(sorted);
        let at = |ns: Option<u64>| ns.map_or(0.0, |v| v as f64 * unit);
        Self { n: s.count as usize, p50: at(s.p50), p90: at(s.p90), p99: at(s.p99), p999: at(s.p999), max: at(s.max) }
    }
}

#[derive(Debug, Clone, Default, Serialize)]
pub struct LoopBench {
    pub name: String,
    pub rate_hz: f64,
    pub loops: u64,
    pub deadline_misses: u64,
    pub end_to_end_us: Dist,
    /// plant→sensors, sensors→estimator, estimator→controller, controller→plant.
    pub hops_us: [Dist; 4],
    /// Per loop, the three stages' own time, receive to publish, summed.
    pub stage_compute_us: Dist,
    /// The controller's own time, receive to publish.
    pub controller_compute_us: Dist,
    /// Per process, percent of one core.
    pub cpu_percent: BTreeMap<String, f64>,
    /// Of the loop's processes (the monitor apart).
    pub loop_cpu_percent: f64,
    /// The plant's tick wake-up latency, (p50, p99) µs, the median of the rounds.
    pub tick_wake_us: Option<[f64; 2]>,
    /// The probe's beside it (`launcher::probe`: the OS alone, at the plant's priority), likewise.
    pub probe_wake_us: Option<[f64; 2]>,
    #[serde(skip)]
    pub(super) e2e: Vec<u64>,
}

#[derive(Debug, Clone, Serialize)]
pub struct PayloadPoint {
    pub bytes: usize,
    pub iceoryx2_us: Dist,
    pub unix_socket_us: Dist,
}

#[derive(Debug, Clone, Serialize)]
pub struct Machine {
    pub cpus: usize,
    pub cpu_model: String,
    pub kernel: String,
    pub load_average: String,
    /// A 1 kHz timerfd: how late each wake-up was.
    pub timer_wake_error_us: Dist,
}

#[derive(Debug, Clone, Serialize)]
pub struct BenchReport {
    pub started_at: String,
    pub quick: bool,
    pub rounds: usize,
    pub machine: Machine,
    /// The parts not run, each with why (too few CPUs).
    pub skipped: Vec<String>,
    /// The physical floor: one cache line passed between two processes pinned to two CPUs,
    /// paced at 1 kHz, one way, in ns (the same percentiles as the other floors).
    pub floor_raw_one_way_ns: Option<Dist>,
    /// One-way iceoryx2 hop with the loop's message size (PlantState), paced at 1 kHz.
    pub floor_one_way_us: BTreeMap<String, Dist>,
    /// The loop's physical limit: 4 × the raw floor's p50 plus the stages' compute time (the
    /// least median among the 1 kHz configurations), µs.
    pub physical_limit_us: Option<f64>,
    pub message_bytes: usize,
    /// A hop through the loop's ports, step by step (needs 2 CPUs).
    pub hop_anatomy: Vec<anatomy::AnatomyRow>,
    pub loops: Vec<LoopBench>,
    pub payload: Vec<PayloadPoint>,
    /// Through the five processes, with the method `lockstep = "auto"` picks on this machine.
    pub lockstep_loops_per_s: f64,
    /// The method auto picks here: poll or handoff.
    pub lockstep_auto: String,
    /// Through the five processes, per method.
    pub lockstep_by_method: BTreeMap<String, f64>,
    pub in_process_loops_per_s: f64,
    pub wall_time_s: f64,
}

pub(super) fn render(r: &BenchReport) -> String {
    let mut s = String::new();
    let m = &r.machine;
    let _ = writeln!(
        s,
        "\nLoopLab bench · {} CPUs ({}) · Linux {} · load {} · {} round(s){}",
        m.cpus,
        m.cpu_model,
        m.kernel,
        m.load_average,
        r.rounds,
        if r.quick { " · quick" } else { "" }
    );
    let t = &m.timer_wake_error_us;
    let _ = writeln!(s, "  timer wake-up error at 1 kHz (µs): p50 {:.1}, p99 {:.1}, max {:.1}", t.p50, t.p99, t.max);
    for part in &r.skipped {
        let _ = writeln!(s, "  skipped (this machine has {} CPUs): {part}", m.cpus);
    }
    let _ = writeln!(s, "\n  floors: one-way hop, paced at 1 kHz (µs)");
    let _ = writeln!(s, "    {:<34}{:>8}{:>9}{:>9}{:>9}", "hop", "p50", "p90", "p99", "p99.9");
    if let Some(d) = &r.floor_raw_one_way_ns {
        let raw = "one cache line, pinned (physical)";
        let _ = writeln!(
            s,
            "    {raw:<34}{:>8.2}{:>9.2}{:>9.2}{:>9.2}",
            d.p50 / 1e3,
            d.p90 / 1e3,
            d.p99 / 1e3,
            d.p999 / 1e3
        );
    }
    for (mode, d) in &r.floor_one_way_us {
        let name = format!("iceoryx2, {} B, {mode}", r.message_bytes);
        let _ = writeln!(s, "    {name:<34}{:>8.2}{:>9.2}{:>9.2}{:>9.2}", d.p50, d.p90, d.p99, d.p999);
    }
    if !r.hop_anatomy.is_empty() {
        let _ = writeln!(s, "\n  hop anatomy: the loop's ports, pinned writer → spinning pinned reader (p50, µs)");
        let _ = write!(s, "    {:<46}", "variant");
        for step in anatomy::STEPS {
            let _ = write!(s, "{step:>9}");
        }
        let _ = writeln!(s, "{:>9}{:>9}", "before", "now");
        for row in &r.hop_anatomy {
            let _ = write!(s, "    {:<46}", format!("{} ({} B)", row.variant, row.message_bytes));
            for step in anatomy::STEPS {
                let _ = write!(s, "{:>9.2}", row.steps_us[step].p50);
            }
            let _ = writeln!(s, "{:>9.2}{:>9.2}", row.hop_before_us.p50, row.hop_now_us.p50);
        }
        let _ = writeln!(
            s,
            "    seen from the start of deliver; before = to release (copied out, released before the stage ran); now = to take"
        );
    }
    let floor4 = r.floor_one_way_us.get("spin").map_or(f64::NAN, |d| 4.0 * d.p50);
    let baseline = r.loops.iter().find(|l| l.name.starts_with("unix")).map_or(f64::NAN, |l| l.end_to_end_us.p50);
    let limit = r.physical_limit_us.unwrap_or(f64::NAN);
    // As a run's report counts them.
    let _ = writeln!(
        s,
        "\n  loop: end to end (µs, over the loops with a command; misses: late, no command or a skipped tick, \
         of every loop); floor = 4 spin hops = {floor4:.2} µs"
    );
    if let (Some(raw), Some(limit)) = (&r.floor_raw_one_way_ns, r.physical_limit_us) {
        let _ = writeln!(
            s,
            "  physical limit = 4 raw hops ({:.2} µs) + the stages' compute ({:.2} µs) = {limit:.2} µs",
            4.0 * raw.p50 / 1e3,
            limit - 4.0 * raw.p50 / 1e3
        );
    }
    let _ = writeln!(
        s,
        "    {:<36}{:>8}{:>9}{:>9}{:>9}{:>10}{:>9}{:>10}{:>10}{:>10}",
        "configuration", "p50", "p99", "p99.9", "max", "misses", "CPU %", "÷ floor", "÷ limit", "÷ socket"
    );
    for l in &r.loops {
        let e = &l.end_to_end_us;
        let misses = format!("{:.2}%", 100.0 * l.deadline_misses as f64 / l.loops.max(1) as f64);
        let _ = writeln!(
            s,
            "    {:<36}{:>8.1}{:>9.1}{:>9.1}{:>9.1}{:>10}{:>9.1}{:>10.1}{:>10.1}{:>10.2}",
            l.name,
            e.p50,
            e.p99,
            e.p999,
            e.max,
            misses,
            l.loop_cpu_percent,
            e.p50 / floor4,
            e.p50 / limit,
            e.p50 / baseline
        );
    }
    let _ = writeln!(
        s,
        "    p50 (µs): hops plant→sensors, sensors→estimator, estimator→controller, controller→plant; stages' compute"
    );
    for l in &r.loops {
        let h = &l.hops_us;
        let _ = writeln!(
            s,
            "    {:<36}{:>8.1}{:>8.1}{:>8.1}{:>8.1}{:>10.1}",
            l.name, h[0].p50, h[1].p50, h[2].p50, h[3].p50, l.stage_compute_us.p50
        );
    }
    let _ = writeln!(
        s,
        "    timer wake-up latency (µs, p50 / p99, the median of the rounds): the plant's tick; the probe beside it \
         (the OS alone, at the plant's priority)"
    );
    for l in &r.loops {
        if let (Some(tick), Some(probe)) = (l.tick_wake_us, l.probe_wake_us) {
            let _ = writeln!(
                s,
                "    {:<36}{:>8.1}{:>8.1}   probe {:>7.1}{:>8.1}   ({:.1}× at p99)",
                l.name,
                tick[0],
                tick[1],
                probe[0],
                probe[1],
                tick[1] / probe[1]
            );
        }
    }
    own_stage::render(&mut s, "looplab block", &r.loops, &[BLOCK_PYTHON, BLOCK_C]);
    if let Some(monitor) =
        r.loops.iter().find(|l| l.name == "looplab adaptive").and_then(|l| l.cpu_percent.get(Role::Monitor.name()))
    {
        let _ = writeln!(s, "    monitor CPU in the adaptive run: {monitor:.1}% of a core");
    }
    let _ = writeln!(s, "\n  zero copy: one-way latency against payload (µs, p50; blocking reads both)");
    let _ = writeln!(s, "    {:>10}{:>12}{:>14}{:>10}", "bytes", "iceoryx2", "unix socket", "ratio");
    for p in &r.payload {
        let _ = writeln!(
            s,
            "    {:>10}{:>12.1}{:>14.1}{:>10.2}",
            p.bytes,
            p.iceoryx2_us.p50,
            p.unix_socket_us.p50,
            p.unix_socket_us.p50 / p.iceoryx2_us.p50
        );
    }
    let _ = writeln!(s, "\n  lockstep, loops/s: {:.0} in one process (the ceiling)", r.in_process_loops_per_s);
    for (method, rate) in &r.lockstep_by_method {
        let auto = if *method == r.lockstep_auto { ", what auto picks here" } else { "" };
        let ratio = rate / r.in_process_loops_per_s;
        let _ = writeln!(s, "    {method:<6}{rate:>10.0} through the five processes (÷ ceiling {ratio:.3}){auto}");
    }
    let _ = writeln!(s, "  wall time {:.0} s", r.wall_time_s);
    s
}
