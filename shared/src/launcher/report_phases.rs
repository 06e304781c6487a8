//! The report's part on how the loop degraded at each fault: the run split before, during and
//! after it (loops, misses, end-to-end latency, the scenario's error), and what happened once a
//! killed stage never came back.

use std::fmt::Write as _;

use crate::config::launch::Mode;
use crate::contract::report::PhaseStats;
use crate::launcher::summary::Summary;

/// What "during" means, said once above the tables.
pub const DURING: &str = "during = from the injection to the first loop whose command was fresh again once the \
                          fault was over (after a kill: through the restarted process), or to the end of the run \
                          if that never came";

/// One table per fault: before, during, after.
/// `write_table` is the report's table writer (passed in: the report calls this module).
pub fn render(out: &mut String, s: &Summary, write_table: fn(&mut String, &[Vec<String>], &[bool])) {
    let split: Vec<_> = s.faults.iter().filter_map(|f| Some((f, f.effect.as_ref()?.phases.as_ref()?))).collect();
    if split.is_empty() {
        return;
    }
    let m = &s.error_measure;
    let _ = writeln!(out, "\n  each fault: the run before, during and after it ({DURING}; error = {})", m.name);
    let lockstep = s.mode == Mode::Lockstep;
    for (f, phases) in split {
        let _ = writeln!(out, "  {}", f.fault);
        let mut rows = vec![
            [
                "",
                "loops",
                "from s",
                "to s",
                "no command",
                "misses",
                "e2e p50 µs",
                "p99 µs",
                "max µs",
                "error max",
                "rms",
            ]
            .map(String::from)
            .to_vec(),
        ];
        for (name, p) in [("before", &phases.before), ("during", &phases.during), ("after", &phases.after)] {
            rows.push(row(name, p, s.rate_hz));
        }
        write_table(out, &rows, &[false, true, true, true, true, true, true, true, true, true, true]);
    }
    if lockstep {
        let _ = writeln!(out, "  (lockstep has no clock: a miss there is a loop whose command never came)");
    }
}

fn row(name: &str, p: &PhaseStats, rate_hz: f64) -> Vec<String> {
    let us = |ns: Option<u64>| ns.map_or("-".into(), |ns| format!("{:.1}", ns as f64 / 1e3));
    let value = |v: Option<f64>| v.map_or("-".into(), |v| format!("{v:.4}"));
    vec![
        name.into(),
        p.loops.to_string(),
        format!("{:.3}", p.from_k as f64 / rate_hz),
        format!("{:.3}", p.to_k as f64 / rate_hz),
        p.without_command.to_string(),
        p.misses.to_string(),
        us(p.end_to_end_ns.p50),
        us(p.end_to_end_ns.p99),
        us(p.end_to_end_ns.max),
        value(p.error_max),
        value(p.error_rms),
    ]
}

/// A note for each kill whose process never came back: what the loop and the physical system
/// did from the loss to the end.
pub fn render_never_back(out: &mut String, s: &Summary) {
    let m = &s.error_measure;
    for f in &s.faults {
        let Some(e) = f.effect.as_ref().filter(|e| e.never_back) else { continue };
        let during = e.phases.as_ref().map(|p| &p.during);
        let loops = during.map_or(String::new(), |d| {
            format!(" for {} loops ({} without a command)", d.to_k - d.from_k, d.without_command)
        });
        let limit = match e.limit_exceeded_at_s {
            Some(t) => format!("the limit {} was exceeded at t = {t:.3} s", m.limit),
            None => format!("it stayed within the limit {}", m.limit),
        };
        let worst = e.worst_error_during.map_or("-".into(), |v| format!("{v:.4}"));
        let _ = writeln!(
            out,
            "  note: `{}`: {} never came back; the loop ran without it{loops}, the plant applying its fail-safe \
             (supervision.on_stale); {} peaked at {worst} and {limit}",
            f.fault, f.process, m.name
        );
    }
}
