//! Gates: what fails a run in CI, each one condition on summary.json, given as
//! `--fail-on GATE` (repeatable) or in the launch file:
//!
//! ```toml
//! [gate]
//! fail_on = ["limits", "misses > 1%", "e2e.p99 > 2ms", "tracking.state.position.rms > 0.01"]
//! ```
//!
//! A gate is `limits` (the run's control verdict is `limits exceeded` or `lost`) or
//! `MEASURE > BOUND` / `MEASURE < BOUND`, the condition that fails it. Timing measures:
//! `misses` (the share of loops that missed their deadline: `1%` or `0.01`), `e2e.STAT` (end to
//! end), `hop.HOP.STAT` (one hop, as summary.json's `latency_ns.hops` names it),
//! `jitter.STAT` (the plant's tick period) with STAT one of p50 p90 p99 p999 max mean and a
//! time bound (`500us`, `2ms`, `0.1s`, `800ns`), and `restart` (the longest time from a
//! stage's death to its successor's ready, a time). Any other measure is one of the run's
//! metrics (`looplab run`'s `metrics`, summary.json's `metrics`), a control gate.
//! The launcher judges them (`launcher::gate`).

use std::fmt;

/// What a gate is about: its exit code says which kind failed.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord)]
pub enum GateKind {
    Control,
    Timing,
}

/// A statistic of a latency distribution.
#[derive(Debug, Clone, Copy, PartialEq, Eq, strum::Display, strum::EnumString)]
#[strum(serialize_all = "lowercase")]
pub enum Stat {
    P50,
    P90,
    P99,
    P999,
    Max,
    Mean,
}

/// What a gate measures.
#[derive(Debug, Clone, PartialEq)]
pub enum Measure {
    /// The control verdict against `[limits]`.
    Limits,
    /// The share of loops that missed their deadline (0 to 1).
    Misses,
    /// End-to-end latency, ns.
    EndToEnd(Stat),
    /// One hop's latency, ns.
    Hop(String, Stat),
    /// The plant's tick period, ns.
    Jitter(Stat),
    /// The longest restart, death to ready, ns.
    Restart,
    /// A metric of the run's summary.
    Metric(String),
}

/// Which side of the bound fails.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Fails {
    Above,
    Below,
}

/// One gate: fails when its measure is on `fails`' side of `bound` (ns for a time, 0 to 1 for
/// a share).
#[derive(Debug, Clone, PartialEq)]
pub struct Gate {
    /// As the user wrote it.
    pub text: String,
    pub measure: Measure,
    pub fails: Fails,
    pub bound: f64,
}

impl Measure {
    pub fn kind(&self) -> GateKind {
        match self {
            Measure::Limits | Measure::Metric(_) => GateKind::Control,
            _ => GateKind::Timing,
        }
    }

    /// Whether its value is a time (ns), a share or a plain number.
    fn unit(&self) -> Unit {
        match self {
            Measure::Limits | Measure::Metric(_) => Unit::Number,
            Measure::Misses => Unit::Share,
            _ => Unit::Time,
        }
    }

    /// `value` as the gate's line writes it.
    pub fn show(&self, value: f64) -> String {
        match self.unit() {
            Unit::Time if value >= 1e6 => format!("{:.3} ms", value / 1e6),
            Unit::Time => format!("{:.1} µs", value / 1e3),
            Unit::Share => format!("{:.2} %", value * 100.0),
            Unit::Number => format!("{value}"),
        }
    }
}

#[derive(Clone, Copy, PartialEq)]
enum Unit {
    Time,
    Share,
    Number,
}

/// What a gate may be, for error messages.
pub const GATE_SYNTAX: &str = "limits, or MEASURE > BOUND (or <): misses > 1%, e2e.p99 > 2ms, \
     hop.controller_compute.p99 > 500us, jitter.max > 1.5ms, restart > 200ms (STAT: p50 p90 p99 p999 max mean; \
     time units ns us ms s), or a metric of the run: tracking.state.position.rms > 0.01";

impl Gate {
    /// Reads one gate; Err: what is wrong, in words.
    pub fn parse(text: &str) -> Result<Gate, String> {
        let bad = |why: String| format!("\"{text}\": {why}; a gate is {GATE_SYNTAX}");
        let trimmed = text.trim();
        if trimmed == "limits" {
            return Ok(Gate { text: trimmed.into(), measure: Measure::Limits, fails: Fails::Above, bound: 0.0 });
        }
        let (at, fails) = match (trimmed.find('>'), trimmed.find('<')) {
            (Some(i), None) => (i, Fails::Above),
            (None, Some(i)) => (i, Fails::Below),
            _ => return Err(bad("give one comparison, > or <".into())),
        };
        let (name, bound) = (trimmed[..at].trim(), trimmed[at + 1..].trim());
        let measure = measure(name).map_err(bad)?;
        let bound = parse_bound(bound, measure.unit()).map_err(bad)?;
        Ok(Gate { text: trimmed.into(), measure, fails, bound })
    }

    pub fn kind(&self) -> GateKind {
        self.measure.kind()
    }

    /// Whether `value` fails it.
    pub fn fails(&self, value: f64) -> bool {
        match self.fails {
            Fails::Above => value > self.bound,
            Fails::Below => value < self.bound,
        }
    }
}

impl fmt::Display for GateKind {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            GateKind::Control => "control",
            GateKind::Timing => "timing",
        })
    }
}

fn measure(name: &str) -> Result<Measure, String> {
    let stat =
        |s: &str| s.parse::<Stat>().map_err(|_| format!("\"{s}\" is not a statistic (p50 p90 p99 p999 max mean)"));
    let parts: Vec<&str> = name.split('.').collect();
    Ok(match parts.as_slice() {
        [] | [""] => return Err("no measure before the comparison".into()),
        ["misses"] => Measure::Misses,
        ["restart"] => Measure::Restart,
        ["e2e", s] => Measure::EndToEnd(stat(s)?),
        ["jitter", s] => Measure::Jitter(stat(s)?),
        ["hop", hop, s] => Measure::Hop((*hop).to_owned(), stat(s)?),
        ["e2e" | "jitter" | "hop", ..] => return Err(format!("\"{name}\" is e2e.STAT, jitter.STAT or hop.HOP.STAT")),
        _ if name.chars().any(char::is_whitespace) => return Err(format!("\"{name}\" is not one measure")),
        _ => Measure::Metric(name.to_owned()),
    })
}

fn parse_bound(text: &str, unit: Unit) -> Result<f64, String> {
    let split =
        text.find(|c: char| !(c.is_ascii_digit() || matches!(c, '.' | '-' | '+' | 'e' | 'E'))).unwrap_or(text.len());
    // An exponent's `e` stays with the number; a unit's letters start at its first non-digit.
    let (number, suffix) = text.split_at(split);
    let value: f64 = number.parse().map_err(|_| format!("the bound \"{text}\" is not a number"))?;
    if !value.is_finite() {
        return Err(format!("the bound \"{text}\" is not finite"));
    }
    let scale = match (unit, suffix.trim()) {
        (Unit::Time, "ns") => 1.0,
        (Unit::Time, "us" | "µs") => 1e3,
        (Unit::Time, "ms") => 1e6,
        (Unit::Time, "s") => 1e9,
        (Unit::Time, other) => return Err(format!("a time needs its unit (ns, us, ms, s), got \"{other}\"")),
        (Unit::Share, "%") => 0.01,
        (Unit::Share, "") => 1.0,
        (Unit::Share, other) => return Err(format!("a share is a fraction or a percentage, got \"{other}\"")),
        (Unit::Number, "") => 1.0,
        (Unit::Number, other) => return Err(format!("a metric's bound is a plain number, got \"{other}\"")),
    };
    Ok(value * scale)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn gates_read_their_measure_side_and_bound_in_base_units() {
        let g = Gate::parse("e2e.p99 > 2ms").unwrap();
        assert_eq!((g.measure, g.fails, g.bound), (Measure::EndToEnd(Stat::P99), Fails::Above, 2e6));
        let g = Gate::parse(" misses>1.5% ").unwrap();
        assert_eq!((g.measure.clone(), g.bound, g.text.as_str()), (Measure::Misses, 0.015, "misses>1.5%"));
        assert!(g.fails(0.016) && !g.fails(0.015));
        let g = Gate::parse("hop.controller_compute.p999 > 500us").unwrap();
        assert_eq!(g.measure, Measure::Hop("controller_compute".into(), Stat::P999));
        assert_eq!(g.bound, 5e5);
        let g = Gate::parse("tracking.state.position.rms > 1e-3").unwrap();
        assert_eq!((g.measure.kind(), g.bound), (GateKind::Control, 1e-3));
        let g = Gate::parse("loops.completed < 100").unwrap();
        assert!(g.fails(99.0) && !g.fails(100.0));
        assert_eq!(Gate::parse("restart > 0.2s").unwrap().kind(), GateKind::Timing);
        assert_eq!(Gate::parse("limits").unwrap().kind(), GateKind::Control);
    }

    #[test]
    fn a_bad_gate_says_what_is_wrong_and_what_a_gate_is() {
        let e = Gate::parse("e2e.p99 > 2").unwrap_err();
        assert!(
            e.starts_with("\"e2e.p99 > 2\": a time needs its unit (ns, us, ms, s), got \"\"; a gate is limits"),
            "{e}"
        );
        assert!(Gate::parse("e2e.p98 > 2ms").unwrap_err().contains("\"p98\" is not a statistic"));
        assert!(Gate::parse("misses").unwrap_err().contains("give one comparison"));
        assert!(Gate::parse("misses > 1 %x").unwrap_err().contains("a share is a fraction or a percentage"));
        assert!(Gate::parse("rms > 1ms").unwrap_err().contains("a metric's bound is a plain number"));
        assert!(Gate::parse("> 1").unwrap_err().contains("no measure"));
    }
}
