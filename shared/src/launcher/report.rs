//! What the user sees at the end of a run: the report printed from its summary, the error
//! line and the exit code.

use std::collections::BTreeMap;
use std::fmt::Write as _;

// The scenarios' old path to this type, until issue 11 moves it below them.
use crate::config::launch::Mode;
use crate::contract::report::{CauseTally, HOPS, MissingLoops, Stats};
use crate::contract::run_format::files;
use crate::launcher::outcome::{EXIT_FAILED, EXIT_INTERRUPTED, EXIT_OK, Outcome};
pub use crate::launcher::summary::ErrorMeasureInfo;
use crate::launcher::summary::Summary;

/// The launcher's exit code for a finished run, and the error line it prints, if any.
pub fn exit_code(outcome: &Outcome, summary: &Summary) -> (u8, Option<String>) {
    match outcome {
        Outcome::Completed if !summary.lost_stages.is_empty() && summary.loops == summary.loops_planned => {
            (EXIT_FAILED, Some(format!("the run ran its {} loops {}", summary.loops, lost_text(summary))))
        }
        Outcome::Completed if !summary.completed => {
            let why =
                summary.stopped_because.as_ref().map_or("it ran fewer loops than planned".into(), |r| r.to_string());
            let error =
                format!("the run did not complete: {why} ({} of {} loops)", summary.loops, summary.loops_planned);
            (EXIT_FAILED, Some(error))
        }
        Outcome::Completed | Outcome::Quit if summary.shared_memory.clean => (EXIT_OK, None),
        Outcome::Completed | Outcome::Quit => {
            let error = format!("files of the run were left behind: {}", summary.shared_memory.leftover.join(", "));
            (EXIT_FAILED, Some(error))
        }
        Outcome::Interrupted => (EXIT_INTERRUPTED, None),
        Outcome::Failed(why) => (EXIT_FAILED, Some(why.clone())),
    }
}

/// "with a stage LOST: controller died at loop 1000 (t = 1 s) and was not restarted (on_death = continue)".
fn lost_text(s: &Summary) -> String {
    let lost: Vec<String> = s
        .lost_stages
        .iter()
        .map(|l| match l.at_loop {
            Some(k) => format!("{} died at loop {k} (t = {} s)", l.process, k as f64 / s.rate_hz),
            None => format!("{} died {:.0} ms after tick 0 (wall clock)", l.process, l.at_ms),
        })
        .collect();
    let stage = if lost.len() == 1 { "a stage" } else { "stages" };
    let held = s.fail_safe.as_ref().map_or(String::new(), |f| {
        let applied: Vec<String> = f.applied.iter().map(|(name, v, unit)| format!("{name} = {v} {unit}")).collect();
        let what = if f.on_stale == "hold" { "held its last command" } else { "applied zero" };
        format!(
            "; the plant's fail-safe {what} (supervision.on_stale = \"{}\"): {} at the end",
            f.on_stale,
            applied.join(", ")
        )
    });
    format!("with {stage} LOST: {} and was not restarted (on_death = continue){held}", lost.join(", "))
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

/// The loop's timer beside the OS's own: the probe's p99 wake-up latency and the plant's tick's.
fn probe_line(s: &Summary, probe: &crate::launcher::probe::ProbeSummary) -> String {
    let p99 = |st: &Stats| st.p99.map_or("n/a".to_owned(), |ns| format!("{:.0} µs", ns as f64 / 1e3));
    let ratio = match (s.jitter_ns.plant_wake_latency.p99, probe.wake_latency_ns.p99) {
        (Some(plant), Some(os)) if os > 0 => format!(" ({:.1}× the probe's)", plant as f64 / os as f64),
        _ => String::new(),
    };
    let how = if probe.priority > 0 { format!("{} {}", probe.policy, probe.priority) } else { probe.policy.clone() };
    let note = probe.note.as_ref().map_or(String::new(), |n| format!("; {n}"));
    format!(
        "  the OS alone woke the probe p99 {} late ({how}, every {:.0} µs, half a period after each tick); \
         the plant's tick p99 {}{ratio}{note}",
        p99(&probe.wake_latency_ns),
        probe.interval_ns as f64 / 1e3,
        p99(&s.jitter_ns.plant_wake_latency),
    )
}

/// With `[realtime]`: how the kernel scheduled each loop process once it was ready (its last
/// start), and the memory it had locked.
fn scheduling_line(s: &Summary) -> Option<String> {
    let mut last = std::collections::BTreeMap::new();
    for p in &s.processes {
        if let Some(scheduling) = &p.scheduling {
            last.insert(p.name.slot(), (p.name, scheduling));
        }
    }
    let each: Vec<String> = last
        .values()
        .map(|(role, sch)| {
            let policy = if sch.policy == "normal" {
                "normal priority".into()
            } else {
                format!("{} {}", sch.policy, sch.priority)
            };
            format!("{role} {policy}, {:.1} MiB locked", sch.locked_kib as f64 / 1024.0)
        })
        .collect();
    (!each.is_empty()).then(|| format!("  real time, as the kernel reports it: {}", each.join(" · ")))
}

/// The human-readable report.
/// A finished run's summary.json, read back for `looplab report`.
pub fn read_summary(run_dir: &std::path::Path) -> anyhow::Result<Summary> {
    use anyhow::Context as _;
    let path = run_dir.join(files::SUMMARY);
    if !run_dir.is_dir() {
        anyhow::bail!("{}: no such run folder", run_dir.display());
    }
    if std::fs::symlink_metadata(&path).is_err() {
        anyhow::bail!("{}: not a finished run folder (no summary.json)", run_dir.display());
    }
    let bytes = crate::runtime::storage::run_file::read(&path)?;
    serde_json::from_slice(&bytes).with_context(|| format!("{}: not a summary LoopLab wrote", path.display()))
}

pub fn render(s: &Summary) -> String {
    let mut out = String::new();
    let _ = writeln!(
        out,
        "\nLoopLab · {} · {} · {} Hz · {} s · seed {}",
        s.title,
        s.mode.name(),
        s.rate_hz,
        s.duration_s,
        s.seed
    );
    let status = match (&s.stopped_because, s.completed) {
        (Some(why), _) => format!("stopped early: {why}"),
        (None, true) => "completed".into(),
        (None, false) => "did not complete".into(),
    };
    let status = match (&s.stopped_because, s.lost_stages.is_empty()) {
        (None, false) => format!("ran every loop {}", lost_text(s)),
        _ => status,
    };
    let status = match s.diverged_at_loop {
        Some(k) => format!("{status}, the simulation DIVERGED at loop {k}"),
        None => status,
    };
    // Lockstep has no clock, so no deadline to miss: a 0 there would read as a result.
    let misses = match s.mode {
        Mode::Realtime => deadline_text(s),
        Mode::Lockstep => "n/a (lockstep)".into(),
    };
    // Loops the plant ran: a skipped tick was integrated, but no loop ran for it.
    let _ = writeln!(
        out,
        "  {status}: {} of {} loops ran in {:.2} s ({:.0} loops/s) · deadline misses {misses} · rejected commands {}",
        s.loops - s.skipped_ticks,
        s.loops_planned,
        s.wall_time_s,
        s.loops_per_s,
        s.rejected_commands
    );
    if let Some(line) = causes_line("why the deadline misses", s.deadline_misses, &s.misses_by_cause) {
        let _ = writeln!(out, "{line}");
    }
    if let (Some(steal), Mode::Realtime) = (s.steal_share, s.mode) {
        let _ = writeln!(
            out,
            "  machine: the hypervisor took {:.1} % of the CPU time during the run (steal: `timer` and `compute` include it)",
            steal * 100.0
        );
    }
    if let Some(slow) = &s.slow_loops {
        let over = format!("why the loops over {} µs end to end", slow.over_us);
        let count = slow.by_cause.values().map(|c| c.loops).sum();
        let _ = writeln!(out, "{}", causes_line(&over, count, &slow.by_cause).unwrap_or(format!("  {over}: none")));
    }
    let _ = writeln!(out, "  control: {}", s.limits.line());
    let _ = writeln!(out, "  {}", s.latency_budget.line());
    let _ = writeln!(
        out,
        "  monitor: {} loop records, {} lost; {} loops had no command (a stage skipped them), {} ticks were skipped{}",
        s.monitor.records,
        s.monitor.lost,
        s.loops_without_command,
        s.skipped_ticks,
        missing_text(&s.monitor.missing)
    );
    if let Some(line) = scheduling_line(s) {
        let _ = writeln!(out, "{line}");
    }

    let _ = writeln!(
        out,
        "\n  {:<26}{:>9}{:>9}{:>9}{:>9}{:>9}{:>9}{:>10}",
        "latency (µs)", "count", "min", "p50", "p90", "p99", "p99.9", "max"
    );
    let empty = Stats::default();
    let crossing = |hop: &str| s.network.as_ref().is_some_and(|n| n.crossing_hops.iter().any(|h| h == hop));
    for (hop, _, _) in HOPS {
        let label = if crossing(hop) { format!("{} ⇄", hop.replace('_', " ")) } else { hop.replace('_', " ") };
        if s.ran_in_process() && hop.contains("_to_") {
            // Calls in one thread: a hop from one process to the next has no meaning there.
            let _ = writeln!(
                out,
                "  {label:<26}{:>9}      n/a: in one process, not IPC",
                s.latency_ns.hops.get(hop).map_or(0, |h| h.count)
            );
        } else {
            stats_row(&mut out, &label, s.latency_ns.hops.get(hop).unwrap_or(&empty));
        }
    }
    stats_row(&mut out, "END TO END", &s.latency_ns.end_to_end);
    if let Some(line) = with_command_line(s) {
        let _ = writeln!(out, "{line}");
    }
    if let Some(network) = &s.network {
        stats_row(&mut out, "link round trip", &network.round_trip_ns);
    }
    if s.jitter_ns.plant_tick.count > 0 || s.jitter_ns.plant_wake_latency.count > 0 {
        stats_row(&mut out, "tick period error |T−dt|", &s.jitter_ns.plant_tick);
        stats_row(&mut out, "tick wake-up latency", &s.jitter_ns.plant_wake_latency);
    }
    if let Some(probe) = &s.probe {
        stats_row(&mut out, "probe wake-up latency", &probe.wake_latency_ns);
        let _ = writeln!(out, "{}", probe_line(s, probe));
    }
    for (sensor, stats) in &s.data_age_ns {
        stats_row(&mut out, &format!("data age: {sensor}"), stats);
    }

    // By name, as the report always listed them.
    let mut waits: Vec<_> = s.adaptive_waits.iter().collect();
    waits.sort_by_key(|(process, _)| process.name());
    for (process, w) in waits {
        let _ = writeln!(
            out,
            "  adaptive wait, {process}: {} caught by polling, {} blocked after the cap{}",
            w.caught,
            w.blocked,
            if w.busy > 0 { format!(", {} blocked while the CPU was busy", w.busy) } else { String::new() }
        );
    }

    render_network(&mut out, s);
    render_faults(&mut out, s);
    render_restarts(&mut out, s);

    let _ = writeln!(out, "\n  metrics");
    for (name, value) in &s.metrics {
        let _ = writeln!(out, "    {name:<34}{value:>14.6}");
    }
    for note in &s.notes {
        let _ = writeln!(out, "    note: {note}");
    }
    let processes: Vec<String> = s
        .processes
        .iter()
        .map(|p| {
            let again = if p.incarnation > 0 { format!(" restart {}", p.incarnation) } else { String::new() };
            let own = p.command.as_ref().map(|c| format!("your own: `{c}`, ")).unwrap_or_default();
            let cpu = format!("cpu {:.2} s, {} wake-ups", p.cpu_s, p.wakeups);
            format!("{}{again} ({own}pid {}, exit {}, {cpu})", p.name, p.pid, p.exit)
        })
        .collect();
    let processes =
        if processes.is_empty() { "none: the loop ran in-process".to_string() } else { processes.join(", ") };
    let _ = writeln!(out, "\n  processes: {processes}");
    let _ = if s.shared_memory.clean {
        writeln!(out, "  shared memory: clean, no file of the run is left")
    } else {
        writeln!(out, "  shared memory: NOT CLEAN, left behind: {}", s.shared_memory.leftover.join(", "))
    };
    if !s.shared_memory.foreign.is_empty() {
        let _ = writeln!(
            out,
            "  shared memory: another user made entries named like this run's (not the run's, left there): {}",
            s.shared_memory.foreign.join(", ")
        );
    }
    let _ = writeln!(out, "  run folder: {}", s.run_dir);
    let _ = writeln!(
        out,
        "  look at it: looplab plot {dir} (figures) · looplab compare {dir} OTHER_RUN · {dir}/run.mcap opens in Foxglove or PlotJuggler",
        dir = s.run_dir
    );
    out
}

/// Under the latencies, where some loops have none: "    over the 9801 loops with a command;
/// 102 had none, 97 ticks skipped" (every view of a latency says it so: `tools::plot::latency`).
fn with_command_line(s: &Summary) -> Option<String> {
    if s.loops_without_command == 0 && s.skipped_ticks == 0 {
        return None;
    }
    let skipped = if s.skipped_ticks > 0 { format!(", {} ticks skipped", s.skipped_ticks) } else { String::new() };
    Some(format!(
        "    over the {} loops with a command; {} had none{skipped}",
        s.latency_ns.end_to_end.count, s.loops_without_command
    ))
}

/// Real time: "1508 of 10000 (15.1 %, 217 ticks skipped), deadline 1.000 ms".
fn deadline_text(s: &Summary) -> String {
    let share = s.deadline_miss_share.unwrap_or(s.deadline_misses as f64 / s.loops.max(1) as f64);
    let deadline = s.deadline_us.map_or(String::new(), |us| format!(", deadline {:.3} ms", us / 1e3));
    let skipped = if s.skipped_ticks > 0 { format!(", {} ticks skipped", s.skipped_ticks) } else { String::new() };
    format!("{} of {} ({:.1} %{skipped}){deadline}", s.deadline_misses, s.loops, share * 100.0)
}

/// "  why the deadline misses (25): 14 timer (600–900 µs), 8 queued: controller (300–700 µs), …":
/// each cause's count and the range of its part of those loops' response time. None when no
/// loop was explained.
fn causes_line(what: &str, count: u64, causes: &BTreeMap<String, CauseTally>) -> Option<String> {
    if causes.is_empty() {
        return None;
    }
    let mut by_count: Vec<_> = causes.iter().collect();
    by_count.sort_by(|a, b| b.1.loops.cmp(&a.1.loops).then(a.0.cmp(b.0)));
    let us = |ns: u64| format!("{:.0}", ns as f64 / 1e3);
    let parts: Vec<String> = by_count
        .into_iter()
        .map(|(cause, tally)| {
            let mut says = match (tally.min_part_ns, tally.max_part_ns) {
                (Some(min), Some(max)) if us(min) == us(max) => vec![format!("{} µs", us(max))],
                (Some(min), Some(max)) => vec![format!("{}–{} µs", us(min), us(max))],
                _ => vec![],
            };
            // The task the scheduler trace shows running instead most often.
            if let Some((task, n)) = tally.behind.iter().max_by_key(|(_, n)| **n) {
                says.push(format!("behind {task} in {n}"));
            }
            match says.is_empty() {
                true => format!("{} {cause}", tally.loops),
                false => format!("{} {cause} ({})", tally.loops, says.join("; ")),
            }
        })
        .collect();
    Some(format!("  {what} ({count}; the largest part of each one's response time): {}", parts.join(", ")))
}

/// The loops without a record, for the report's monitor line.
fn missing_text(m: &MissingLoops) -> String {
    if m.missing_loops == 0 {
        return String::new();
    }
    // A few ranges read at a glance; summary.json keeps them all.
    const SHOWN: usize = 6;
    let ranges: Vec<String> =
        m.ranges.iter().take(SHOWN).map(|[a, b]| if a == b { a.to_string() } else { format!("{a}–{b}") }).collect();
    let omitted = match m.missing_ranges_omitted + m.ranges.len().saturating_sub(SHOWN) as u64 {
        0 => String::new(),
        n => format!(" and {n} more ranges"),
    };
    let before_restart = match m.missing_before_restart {
        0 => String::new(),
        n => format!("; {n} of them while the monitor restarted"),
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
/// The other host: its clock, what crossed and the link's outages.
fn render_network(out: &mut String, s: &Summary) {
    let Some(n) = &s.network else { return };
    let stages: Vec<&str> = n.stages.iter().map(|r| r.name()).collect();
    let _ = writeln!(
        out,
        "\n  other host: {} on {} ({}); ⇄ hops cross the link, corrected for its clock",
        stages.join(", "),
        n.host,
        n.endpoint
    );
    match &n.clock {
        Some(c) => {
            let _ = writeln!(
                out,
                "    its clock: {:+.6} s against this one's, ± {:.1} µs; drift {:+.2} ppm ({} windows)",
                c.offset_ns / 1e9,
                c.uncertainty_ns / 1e3,
                c.drift_ppm,
                c.windows
            );
        }
        None => {
            let _ = writeln!(out, "    its clock: unknown (no loop went there and back)");
        }
    }
    if n.unreported_bridges > 0 {
        let _ = writeln!(
            out,
            "    {} bridge start(s) ended without a report (killed): their frames are not counted",
            n.unreported_bridges
        );
    }
    for (topic, t) in &n.topics {
        let _ = writeln!(
            out,
            "    {topic}: {} sent, {} received, {} lost, {} gaps ({} loops missed){}",
            t.sent,
            t.received,
            t.lost.map_or("unknown".into(), |l| l.to_string()),
            t.gaps,
            t.missing,
            if t.malformed > 0 { format!(", {} malformed", t.malformed) } else { String::new() }
        );
    }
    let outages: Vec<String> = n
        .link
        .outages
        .iter()
        .map(|o| match o.outage_ms {
            Some(ms) => format!("{ms:.0} ms"),
            None => "until the end".into(),
        })
        .collect();
    let _ = writeln!(
        out,
        "    link: {} losses, {} reconnects{}",
        n.link.losses,
        n.link.reconnects,
        if outages.is_empty() { String::new() } else { format!("; outages {}", outages.join(", ")) }
    );
}

/// A kill or stop injected later than this after its time is named as late.
const LATE_INJECTION_MS: f64 = 50.0;

/// A fault against its fault-free twin, in words.
fn twin_line(twin: &crate::launcher::summary::AgainstTwin) -> String {
    match twin.departed_at_s {
        None => "no effect: the plant's state is that run's, bit for bit".into(),
        Some(at) => format!(
            "departed from it at t = {at} s; worst error above it {:.4}; {}",
            twin.worst_extra_error,
            twin.recovery_s.map_or("not back within the recovery band of it by the end".into(), |r| format!(
                "back within the recovery band of it {r:.3} s after the fault"
            ))
        ),
    }
}

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
            Some(e) if e.not_injected => ("-".into(), "-".into(), "-".into(), "-".into(), "not injected"),
            Some(e) if e.unrecorded => ("-".into(), "-".into(), "-".into(), "-".into(), "unrecorded"),
            Some(e) => (
                format!("{} ticks", e.outage_ticks),
                e.worst_error_during.map_or("-".into(), |v| format!("{v:.4}")),
                e.worst_error_after.map_or("-".into(), |v| format!("{v:.4}")),
                // Against the fault-free twin where there is one: the run's own error is not the fault's.
                match (e.recovery_s, &f.against_twin) {
                    _ if e.never_back => format!("never: {} lost", f.process),
                    (_, Some(twin)) => twin.recovery_s.map_or("never".into(), |v| format!("{v:.3} s")),
                    (Some(v), None) => format!("{v:.3} s"),
                    (None, None) => "never".into(),
                },
                match &f.against_twin {
                    Some(twin) if twin.departed_at_s.is_none() => "no effect",
                    _ if e.within_limits => "kept",
                    _ => "EXCEEDED",
                },
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
    for f in s.faults.iter().filter(|f| f.effect.as_ref().is_some_and(|e| e.unrecorded && !e.not_injected)) {
        let _ = writeln!(
            out,
            "  note: no loop after `{}` was recorded (the monitor was restarting, or the run had ended): its effect is unknown",
            f.fault
        );
    }
    for f in &s.faults {
        if let Some(twin) = &f.against_twin {
            let _ = writeln!(out, "  against the same run without faults: `{}`: {}", f.fault, twin_line(twin));
        }
    }
    crate::launcher::report_phases::render_never_back(out, s);
    // Real time: a kill or stop the launcher sent later than planned (it was stopped or starved).
    for f in &s.faults {
        if let Some(late) = f.injected_at_ms.map(|at| at - f.at_s * 1e3).filter(|late| *late > LATE_INJECTION_MS) {
            let _ = writeln!(out, "  note: `{}` was injected {late:.0} ms after its time", f.fault);
        }
        if f.continued_at_run_end {
            let after = f.continued_after_ms.map_or(String::new(), |ms| format!(" after {ms:.0} ms"));
            let _ = writeln!(out, "  note: `{}` was cut short by the run's end (continued{after})", f.fault);
        }
    }
    crate::launcher::report_phases::render(out, s, write_table);
    if !s.timeline.is_empty() {
        let _ = writeln!(out, "\n  timeline (wall-clock ms after tick 0)");
        for entry in &s.timeline {
            let _ = writeln!(out, "  {:>10.1}  {}", entry.at_ms, entry.event);
        }
    }
}

fn render_restarts(out: &mut String, s: &Summary) {
    if s.restart_steps.is_empty() {
        return;
    }
    let _ = writeln!(out, "\n  restarts (wall-clock ms after the death was seen)");
    let mut rows = vec![["process", "died at", "cleaned", "backoff", "started", "ready"].map(String::from).to_vec()];
    for r in &s.restart_steps {
        rows.push(vec![
            r.process.to_string(),
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
    use crate::config::faults::FaultKind;
    use crate::contract::protocol::WaitCounts;
    use crate::contract::report::FaultEffect;
    use crate::contract::role::Role;
    use crate::launcher::outcome::StopReason;
    use crate::launcher::summary::tests::summary;
    use crate::launcher::summary::{FaultReport, RestartSteps};

    #[test]
    fn missing_loops_show_six_ranges_and_count_the_rest() {
        let mut missing = MissingLoops::default();
        for k in [3, 10, 20, 30, 40, 50, 60, 70] {
            missing.add(k, k);
        }
        missing.add(71, 75);
        assert_eq!(missing_text(&missing), "; no record for 13 loops: 3, 10, 20, 30, 40, 50 and 2 more ranges");
    }

    fn summary_with_fault() -> Summary {
        Summary {
            // The widths that used to run together: "206.0" filled its column, "200 ticks" too.
            faults: vec![FaultReport {
                fault: "kill controller at 1s".into(),
                kind: FaultKind::Kill,
                process: Role::Controller,
                at_s: 1.0,
                injected_at_ms: Some(1000.0),
                detected_after_ms: Some(3.25),
                detected_by: None,
                restarted_after_ms: Some(206.0),
                continued_after_ms: None,
                resumed_after_ms: None,
                continued_at_run_end: false,
                effect: Some(FaultEffect {
                    outage_ticks: 200,
                    worst_error_during: Some(0.0123),
                    worst_error_after: None,
                    recovery_s: Some(0.5),
                    within_limits: true,
                    ..Default::default()
                }),
                against_twin: None,
            }],
            ..summary()
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

    #[test]
    fn a_fault_no_monitor_recorded_is_not_kept_but_unrecorded() {
        let mut s = summary_with_fault();
        s.faults[0].effect = Some(FaultEffect { unrecorded: true, within_limits: true, ..Default::default() });
        let text = render(&s);
        let row = text.lines().find(|l| l.trim_start().starts_with("kill controller at 1s")).expect("its row");
        assert_eq!(cells(row)[3..], ["-", "-", "-", "-", "unrecorded"]);
        assert!(
            text.contains("note: no loop after `kill controller at 1s` was recorded (the monitor was restarting"),
            "{text}"
        );
    }

    #[test]
    fn a_fault_never_injected_says_so_not_kept_nor_unrecorded() {
        let mut s = summary_with_fault();
        s.faults[0].effect =
            Some(FaultEffect { not_injected: true, unrecorded: true, within_limits: true, ..Default::default() });
        let text = render(&s);
        let row = text.lines().find(|l| l.trim_start().starts_with("kill controller at 1s")).expect("its row");
        assert_eq!(cells(row)[3..], ["-", "-", "-", "-", "not injected"]);
        assert!(!text.contains("was recorded"), "{text}");
    }

    #[test]
    fn each_outcome_has_its_exit_code_and_error_line() {
        let done = summary();
        assert_eq!(exit_code(&Outcome::Completed, &done), (0, None));
        assert_eq!(exit_code(&Outcome::Interrupted, &done), (130, None));
        assert_eq!(exit_code(&Outcome::Quit, &done), (0, None));
        assert_eq!(
            exit_code(&Outcome::Failed("sensors could not be restarted".into()), &done),
            (1, Some("sensors could not be restarted".into()))
        );

        let mut short = summary();
        short.completed = false;
        short.loops = 10;
        assert_eq!(
            exit_code(&Outcome::Completed, &short),
            (1, Some("the run did not complete: it ran fewer loops than planned (10 of 1000 loops)".into()))
        );
        short.stopped_because = Some(StopReason::PlantStoppedEarly);
        assert_eq!(
            exit_code(&Outcome::Completed, &short),
            (1, Some("the run did not complete: the plant stopped before the last loop (10 of 1000 loops)".into()))
        );

        let mut left = summary();
        left.shared_memory.clean = false;
        left.shared_memory.leftover = vec!["/dev/shm/a".into(), "/dev/shm/b".into()];
        assert_eq!(
            exit_code(&Outcome::Completed, &left),
            (1, Some("files of the run were left behind: /dev/shm/a, /dev/shm/b".into()))
        );
    }

    #[test]
    fn the_status_line_restarts_table_and_adaptive_waits_are_printed() {
        let mut s = summary();
        s.restart_steps = vec![RestartSteps {
            process: Role::Sensors,
            incarnation: 1,
            died_at_ms: 1500.3,
            cleaned_after_ms: Some(4.0),
            backoff_ms: 10.0,
            spawned_after_ms: Some(12.5),
            ready_after_ms: None,
        }];
        s.adaptive_waits = [
            (Role::Plant, WaitCounts { caught: 5, blocked: 1, busy: 7 }),
            (Role::Controller, WaitCounts { caught: 2, blocked: 0, busy: 0 }),
        ]
        .into();
        let text = render(&s);
        let lines: Vec<&str> = text.lines().collect();
        assert!(lines[2].starts_with("  completed: 1000 of 1000 loops ran in 1.00 s (1000 loops/s)"), "{}", lines[2]);
        // Lockstep has no deadline: no count that would read as a result.
        assert!(lines[2].contains(" · deadline misses n/a (lockstep) · "), "{}", lines[2]);
        let realtime = render(&Summary {
            mode: Mode::Realtime,
            deadline_misses: 27,
            deadline_us: Some(1000.0),
            deadline_miss_share: Some(0.027),
            ..s.clone()
        });
        let line = realtime.lines().nth(2).unwrap();
        assert!(line.contains(" · deadline misses 27 of 1000 (2.7 %), deadline 1.000 ms · "), "{realtime}");
        // Skipped ticks are misses too, and every miss has a cause.
        let tally = |loops, min, max| CauseTally { loops, min_part_ns: min, max_part_ns: max, ..Default::default() };
        let explained = render(&Summary {
            mode: Mode::Realtime,
            deadline_misses: 30,
            skipped_ticks: 3,
            deadline_us: Some(1000.0),
            deadline_miss_share: Some(0.03),
            misses_by_cause: [
                ("timer".to_owned(), tally(20, Some(600_000), Some(900_400))),
                (
                    "queued: controller".to_owned(),
                    CauseTally {
                        behind: [("hog (pid 7, nice 0)".to_owned(), 6)].into(),
                        ..tally(7, Some(1_000_100), Some(999_900))
                    },
                ),
                ("skipped: estimator".to_owned(), tally(3, None, None)),
            ]
            .into(),
            ..s.clone()
        });
        let lines_explained: Vec<&str> = explained.lines().collect();
        assert!(lines_explained[2].starts_with("  completed: 997 of 1000 loops ran"), "{}", lines_explained[2]);
        assert!(
            lines_explained[2].contains(" · deadline misses 30 of 1000 (3.0 %, 3 ticks skipped), deadline 1.000 ms")
        );
        assert_eq!(
            lines_explained[3],
            "  why the deadline misses (30; the largest part of each one's response time): 20 timer (600–900 µs), 7 \
             queued: controller (1000 µs; behind hog (pid 7, nice 0) in 6), 3 skipped: estimator"
        );
        let header = lines.iter().position(|l| l.trim_start().starts_with("process ")).expect("restarts table");
        assert_eq!(cells(lines[header]), ["process", "died at", "cleaned", "backoff", "started", "ready"]);
        assert_eq!(cells(lines[header + 1]), ["sensors", "1500.3", "4.0", "10.0", "12.5", "-"]);
        let waits: Vec<&str> = lines.iter().filter(|l| l.contains("adaptive wait")).copied().collect();
        assert_eq!(
            waits,
            [
                "  adaptive wait, controller: 2 caught by polling, 0 blocked after the cap",
                "  adaptive wait, plant: 5 caught by polling, 1 blocked after the cap, 7 blocked while the CPU was busy"
            ]
        );
    }
}
