//! Gates judged against a finished run's summary (`config::gate`: what a gate is): one line per
//! gate that failed, naming the gate and the value, and the exit code that says which kind
//! failed (`EXIT_CONTROL_GATE`, `EXIT_TIMING_GATE`, both: `EXIT_BOTH_GATES`).

use clap::Args;

use crate::config::gate::{Gate, GateKind, Measure, Stat};
use crate::contract::report::Stats;
use crate::launcher::outcome::{EXIT_BOTH_GATES, EXIT_CONTROL_GATE, EXIT_TIMING_GATE};
use crate::launcher::summary::Summary;

/// `--fail-on`, as `run`, `replay` and `diff` take it.
#[derive(Debug, Default, Clone, Args)]
pub struct GateArgs {
    /// Fail on this condition of the finished run, for CI; repeatable, added to the launch file's
    /// [gate] fail_on. `limits` (the control verdict), or MEASURE > BOUND (or <): timing:
    /// `misses > 1%`, `e2e.p99 > 2ms`, `hop.controller_compute.p99 > 500us`, `jitter.max > 1.5ms`,
    /// `restart > 200ms`; control: a metric of the run, `tracking.state.position.rms > 0.01`.
    /// Exit 3: a control gate failed, 4: a timing gate, 5: both
    #[arg(long = "fail-on", value_name = "GATE")]
    pub fail_on: Vec<String>,
}

impl GateArgs {
    /// The gates, checked; Err: the line for a bad one.
    pub fn gates(&self) -> Result<Vec<Gate>, String> {
        self.fail_on.iter().map(|text| Gate::parse(text).map_err(|e| format!("--fail-on {e}"))).collect()
    }
}

/// What the gates found.
#[derive(Debug, Default, Clone, PartialEq)]
pub struct Judged {
    /// The kinds of the gates that failed, each with its line.
    pub failed: Vec<(GateKind, String)>,
    /// Gates the run gave nothing to judge by (lockstep has no deadlines; no restart): one line each.
    pub not_judged: Vec<String>,
}

impl Judged {
    /// Whether a gate of `kind` failed.
    pub fn failed(&self, kind: GateKind) -> bool {
        self.failed.iter().any(|(k, _)| *k == kind)
    }

    /// The exit code: None where every gate passed.
    pub fn exit_code(&self) -> Option<u8> {
        exit_code(self.failed(GateKind::Control), self.failed(GateKind::Timing))
    }

    /// Each line, failures first.
    pub fn lines(&self) -> impl Iterator<Item = &String> {
        self.failed.iter().map(|(_, line)| line).chain(&self.not_judged)
    }
}

/// The exit code for what failed: None where nothing did.
pub fn exit_code(control: bool, timing: bool) -> Option<u8> {
    match (control, timing) {
        (true, true) => Some(EXIT_BOTH_GATES),
        (true, false) => Some(EXIT_CONTROL_GATE),
        (false, true) => Some(EXIT_TIMING_GATE),
        (false, false) => None,
    }
}

/// Judges `gates` against `summary`. Err: a gate names what the run does not have (a hop, a
/// metric), with what it has.
pub fn judge(gates: &[Gate], summary: &Summary) -> Result<Judged, String> {
    let mut judged = Judged::default();
    for gate in gates {
        match value(&gate.measure, summary)? {
            Measured::Value(value) if gate.fails(value) => judged.failed.push((
                gate.kind(),
                format!("{} gate failed: {} (measured {})", gate.kind(), gate.text, gate.measure.show(value)),
            )),
            Measured::Value(_) => {}
            Measured::Verdict(failed, line) => {
                if failed {
                    judged.failed.push((gate.kind(), format!("{} gate failed: {} ({line})", gate.kind(), gate.text)));
                }
            }
            Measured::Nothing(why) => {
                judged.not_judged.push(format!("{} gate not judged: {} ({why})", gate.kind(), gate.text))
            }
        }
    }
    Ok(judged)
}

enum Measured {
    Value(f64),
    /// The limits verdict: failed?, and in words.
    Verdict(bool, String),
    /// The run has nothing to judge it by, and why.
    Nothing(String),
}

fn value(measure: &Measure, s: &Summary) -> Result<Measured, String> {
    let stat = |stats: &Stats, stat: Stat| match stat {
        Stat::P50 => stats.p50.map(|v| v as f64),
        Stat::P90 => stats.p90.map(|v| v as f64),
        Stat::P99 => stats.p99.map(|v| v as f64),
        Stat::P999 => stats.p999.map(|v| v as f64),
        Stat::Max => stats.max.map(|v| v as f64),
        Stat::Mean => stats.mean,
    };
    let measured = |value: Option<f64>, why: &str| value.map_or_else(|| Measured::Nothing(why.into()), Measured::Value);
    Ok(match measure {
        Measure::Limits => {
            let verdict = s.limits.verdict;
            if verdict == crate::launcher::verdict::Verdict::NotJudged {
                Measured::Nothing(crate::launcher::verdict::Verdict::NotJudged.to_string())
            } else {
                Measured::Verdict(verdict.failed(), s.limits.line())
            }
        }
        Measure::Misses => measured(
            s.deadline_miss_share.or((s.mode == crate::config::launch::Mode::Realtime && s.loops > 0)
                .then(|| s.deadline_misses as f64 / s.loops as f64)),
            "lockstep has no deadlines",
        ),
        Measure::EndToEnd(st) => measured(stat(&s.latency_ns.end_to_end, *st), "no loop was measured end to end"),
        Measure::Jitter(st) => measured(stat(&s.jitter_ns.plant_tick, *st), "no plant tick was measured"),
        Measure::Hop(hop, st) => {
            let stats = s.latency_ns.hops.get(hop).ok_or_else(|| {
                format!(
                    "hop \"{hop}\": the run has no such hop; its hops: {}",
                    s.latency_ns.hops.keys().cloned().collect::<Vec<_>>().join(", ")
                )
            })?;
            measured(stat(stats, *st), "the hop was not measured")
        }
        Measure::Restart => measured(
            s.restart_steps.iter().filter_map(|r| r.ready_after_ms).map(|ms| ms * 1e6).reduce(f64::max),
            "no stage restarted",
        ),
        Measure::Metric(name) => match s.metrics.get(name) {
            Some(value) => Measured::Value(*value),
            None => {
                return Err(format!(
                    "\"{name}\" is not a metric of this run; its metrics: {}",
                    s.metrics.keys().cloned().collect::<Vec<_>>().join(", ")
                ));
            }
        },
    })
}
