//! What LoopLab says about a declared system's control without knowing the system: per state,
//! output and input component its final value, max |x| and RMS (`state.theta.rms`,
//! `input.current.max_abs`; an input's values are what the actuator applied); per
//! `[[reference]]` the tracking error e = component − r(t) (`tracking.output.y.rms`) and, where
//! the reference steps, the step response (`step.output.y.rise_time_s`, `overshoot_pct`,
//! `settling_time_s`, `steady_state_error`: `step_response`); and the error that fault reports
//! and the `[limits]` verdict judge:
//!
//! ```toml
//! [limits]
//! of = ["output.y"]      # the components judged (default: those with a [[reference]])
//! error_limit = 0.5      # the error beyond which the limits are exceeded
//! recovery_band = 0.05   # the error within which a fault counts as recovered from
//! lost_beyond = 2.0      # optional: the point of no return (the run is lost)
//! judge_from_s = 1.0     # optional: the verdict judges loops from this time on (after a step
//!                        # at t = 0 settles); fault reports judge every loop
//! ```
//!
//! The error at one loop is the largest over the judged components of |component − r(t)| for
//! one with a reference, |component| for one without (a regulator's setpoint is zero).
//!
//! Without `[limits]` nothing is judged: the limit and the recovery band are unbounded (the
//! verdict is "within limits" unless the state stops being a number, which is "lost"), every
//! state component is watched, and the report's notes say so.
//!
//! The plant's state message carries the state, then the outputs (`plant.rs`): an output's
//! index there is the state's length plus its own.

use std::collections::BTreeMap;
use std::sync::{Arc, Mutex};

use serde::{Deserialize, Serialize};

use super::reference::{self, Part, Signal, Tracked};
use super::step_response::StepResponse;
use crate::config::launch::declared::SystemSection;
use crate::config::launch::{LaunchConfig, LaunchError};
use crate::config::validate::positive;
use crate::model::mean::max_keeping_nan;
use crate::model::scenario::{ErrorMeasure, Metrics, Row};

/// The declared names, in order ([system]).
#[derive(Debug, Clone, Copy)]
pub struct Declared<'a> {
    pub state: &'a [String],
    pub outputs: &'a [String],
    pub input: &'a [String],
    /// The unit of each state then output component (message order), for the error's name;
    /// may be empty.
    pub units: &'a [String],
}

impl Declared<'_> {
    /// Every component's key prefix ("state.theta") and source, state then outputs then input.
    fn observed(&self) -> Vec<(String, Source)> {
        let state = self.state.iter().enumerate().map(|(i, n)| (format!("state.{n}"), Source::State(i)));
        let outputs = (self.outputs.iter().enumerate())
            .map(|(i, n)| (format!("output.{n}"), Source::State(self.message_index(Part::Output, i))));
        let input = self.input.iter().enumerate().map(|(i, n)| (format!("input.{n}"), Source::Input(i)));
        state.chain(outputs).chain(input).collect()
    }

    /// The index in the state message of a state or output component.
    fn message_index(&self, part: Part, index: usize) -> usize {
        match part {
            Part::State => index,
            Part::Output => self.state.len() + index,
        }
    }
}

/// `[limits]` of a declared launch file.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
struct LimitsSection {
    #[serde(default)]
    of: Option<Vec<String>>,
    error_limit: f64,
    recovery_band: f64,
    #[serde(default)]
    lost_beyond: Option<f64>,
    #[serde(default)]
    judge_from_s: f64,
}

/// Where a metric's value comes from in a [`Row`].
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Source {
    /// The state message (state, then outputs).
    State(usize),
    /// The input the actuator applied.
    Input(usize),
}

/// A component judged by the error measure: its index in the state message and its reference.
#[derive(Debug, Clone)]
struct Judged {
    index: usize,
    reference: Option<Signal>,
}

/// The error of true state `x` at `t`: the largest |x_i − r_i(t)| over `judged` (NaN if any is).
fn error_of(judged: &[Judged], t: f64, x: &[f64]) -> f64 {
    judged.iter().fold(0.0, |worst, j| {
        let value = x.get(j.index).copied().unwrap_or(f64::NAN);
        let target = j.reference.as_ref().map_or(0.0, |r| r.at(t));
        max_keeping_nan(worst, (value - target).abs())
    })
}

/// A declared system's metrics and error measure, built once from its launch file.
#[derive(Debug, Clone)]
pub struct DeclaredMeasures {
    /// Key prefix ("state.theta") and source of each component's metrics.
    observed: Vec<(String, Source)>,
    /// Each reference: "tracking.<path>", the component's index in the state message, r(t).
    tracked: Vec<(String, usize, Signal)>,
    judged: Vec<Judged>,
    measure_name: &'static str,
    /// None: the file has no `[limits]`, and nothing is judged.
    limits: Option<LimitsSection>,
}

/// What the report notes when a file has no `[limits]`.
const NO_LIMITS: &str = "no [limits] in the launch file: the verdict judges nothing but a state that stops being a \
                         number; add [limits] error_limit, recovery_band (and of = [...]) to judge the run";

impl DeclaredMeasures {
    /// [`DeclaredMeasures::load`] for the system `[system]` declares.
    pub fn from_system(c: &LaunchConfig, system: &SystemSection) -> Result<Self, LaunchError> {
        let names = |items: &mut dyn Iterator<Item = &String>| items.cloned().collect::<Vec<String>>();
        let state = names(&mut system.state.iter().map(|s| &s.name));
        let outputs = names(&mut system.outputs.iter().map(|s| &s.name));
        let input = names(&mut system.input.iter().map(|s| &s.name));
        let units = names(&mut system.state.iter().map(|s| &s.unit).chain(system.outputs.iter().map(|s| &s.unit)));
        Self::load(c, Declared { state: &state, outputs: &outputs, input: &input, units: &units })
    }

    /// The metrics, references and `[limits]` of `c` for the system `names` declares.
    pub fn load(c: &LaunchConfig, names: Declared) -> Result<Self, LaunchError> {
        let observed = names.observed();
        let references: Vec<Tracked> = reference::load(c, names.state, names.outputs)?;
        let tracked = references
            .iter()
            .map(|r| (format!("tracking.{}", r.path), names.message_index(r.part, r.index), r.signal.clone()))
            .collect();
        let limits = load_limits(c)?;
        let of: Vec<String> = match limits.as_ref().and_then(|l| l.of.clone()) {
            Some(of) => of,
            None if !references.is_empty() => references.iter().map(|r| r.path.clone()).collect(),
            None if limits.is_none() => names.state.iter().map(|n| format!("state.{n}")).collect(),
            None => Vec::new(),
        };
        if of.is_empty() {
            return Err(c.error(
                "limits.of",
                "name the components the limits judge (\"state.<name>\" or \"output.<name>\"); with no \
                 [[reference]] there is no default",
            ));
        }
        let mut judged = Vec::new();
        let mut words = Vec::new();
        for path in &of {
            let (part, index) =
                reference::locate(path, names.state, names.outputs).map_err(|e| c.error("limits.of", e))?;
            let reference = references.iter().find(|r| &r.path == path).map(|r| r.signal.clone());
            let name = path.split_once('.').map_or(path.as_str(), |(_, name)| name);
            let at = names.message_index(part, index);
            let unit = names.units.get(at).map_or(String::new(), |u| format!(" {u}"));
            words.push(if reference.is_some() {
                format!("|{name} − reference|{unit}")
            } else {
                format!("|{name}|{unit}")
            });
            judged.push(Judged { index: at, reference });
        }
        let measure_name = match words.as_slice() {
            [one] => one.clone(),
            many => format!("max of {}", many.join(", ")),
        };
        Ok(DeclaredMeasures {
            observed,
            tracked,
            judged,
            // The error measure names itself with a &'static str; one per scenario built.
            measure_name: measure_name.leak(),
            limits,
        })
    }

    /// The metrics, fresh for a run.
    pub fn metrics(&self) -> Box<dyn Metrics> {
        Box::new(DeclaredMetrics {
            observed: self.observed.clone(),
            tracked: self.tracked.clone(),
            stats: vec![Stats::default(); self.observed.len()],
            tracking: vec![Stats::default(); self.tracked.len()],
            steps: self.step_responses(),
            last_t: None,
            no_limits: self.limits.is_none(),
        })
    }

    /// Each reference that steps: "step.<path>", the component's index, its first step.
    fn step_responses(&self) -> Vec<(String, usize, StepResponse)> {
        let steps = self.tracked.iter().filter_map(|(prefix, index, signal)| {
            let path = prefix.strip_prefix("tracking.").expect("tracking.<path>");
            StepResponse::of(signal).map(|step| (format!("step.{path}"), *index, step))
        });
        steps.collect()
    }

    /// How fault reports and the verdict judge the system: `[limits]`.
    pub fn error_measure(&self) -> ErrorMeasure {
        let judged = Arc::new(Mutex::new(self.judged.clone()));
        let (limit, band) = self.limits.as_ref().map_or((f64::MAX, f64::MAX), |l| (l.error_limit, l.recovery_band));
        let measure = ErrorMeasure {
            name: self.measure_name,
            of_state: Arc::new(move |t, x| error_of(&judged.lock().expect("judged lock"), t, x)),
            recovery_band: band,
            limit,
            limit_key: "limits.error_limit",
            lost_beyond: None,
            judged_from_s: self.limits.as_ref().map_or(0.0, |l| l.judge_from_s),
        };
        match self.limits.as_ref().and_then(|l| l.lost_beyond) {
            Some(value) => measure.lost_beyond(value, "past limits.lost_beyond, the point of no return"),
            None => measure,
        }
    }
}

/// `[limits]`, None where the file has none (or an empty one).
fn load_limits(c: &LaunchConfig) -> Result<Option<LimitsSection>, LaunchError> {
    match c.document.get("limits") {
        None => return Ok(None),
        Some(toml::Value::Table(t)) if t.is_empty() => return Ok(None),
        Some(_) => {}
    }
    let limits: LimitsSection = c.section("limits")?;
    positive(c, "limits.error_limit", limits.error_limit)?;
    positive(c, "limits.recovery_band", limits.recovery_band)?;
    if !(limits.judge_from_s >= 0.0 && limits.judge_from_s < c.duration_s) {
        return Err(c.error(
            "limits.judge_from_s",
            format!("is {}; give a time from 0 to the run's duration ({} s), s", limits.judge_from_s, c.duration_s),
        ));
    }
    if limits.recovery_band > limits.error_limit {
        return Err(c.error(
            "limits.recovery_band",
            format!(
                "is {}, more than limits.error_limit = {}: it must lie within it",
                limits.recovery_band, limits.error_limit
            ),
        ));
    }
    if let Some(beyond) = limits.lost_beyond
        && !(beyond.is_finite() && beyond > limits.error_limit)
    {
        return Err(c.error(
            "limits.lost_beyond",
            format!(
                "is {beyond}; the point of no return must be a number beyond limits.error_limit = {}",
                limits.error_limit
            ),
        ));
    }
    Ok(Some(limits))
}

/// Final value, largest magnitude and RMS of one series.
#[derive(Debug, Clone, Default, Serialize, Deserialize)]
struct Stats {
    n: u64,
    sum_sq: f64,
    max_abs: f64,
    last: f64,
}

impl Stats {
    fn observe(&mut self, v: f64) {
        self.n += 1;
        self.sum_sq += v * v;
        self.max_abs = max_keeping_nan(self.max_abs, v.abs());
        self.last = v;
    }

    fn write(&self, prefix: &str, m: &mut BTreeMap<String, f64>) {
        if self.n == 0 {
            return;
        }
        m.insert(format!("{prefix}.final"), self.last);
        m.insert(format!("{prefix}.max_abs"), self.max_abs);
        m.insert(format!("{prefix}.rms"), (self.sum_sq / self.n as f64).sqrt());
    }
}

struct DeclaredMetrics {
    observed: Vec<(String, Source)>,
    tracked: Vec<(String, usize, Signal)>,
    stats: Vec<Stats>,
    tracking: Vec<Stats>,
    /// Each reference that steps: "step.<path>", the component's index, its response.
    steps: Vec<(String, usize, StepResponse)>,
    last_t: Option<f64>,
    /// The file has no `[limits]` (a note).
    no_limits: bool,
}

impl Metrics for DeclaredMetrics {
    frozen_fields!(stats, tracking, steps, last_t);

    fn observe(&mut self, row: &Row) {
        let at = |values: &[f64], i: usize| values.get(i).copied().unwrap_or(f64::NAN);
        for ((_, source), stats) in self.observed.iter().zip(&mut self.stats) {
            stats.observe(match *source {
                Source::State(i) => at(row.state, i),
                Source::Input(i) => at(row.applied, i),
            });
        }
        for ((_, index, signal), stats) in self.tracked.iter().zip(&mut self.tracking) {
            stats.observe(at(row.state, *index) - signal.at(row.t));
        }
        for (_, index, step) in &mut self.steps {
            step.observe(row.t, at(row.state, *index));
        }
        self.last_t = Some(row.t);
    }

    fn finish(&self) -> BTreeMap<String, f64> {
        let mut m = BTreeMap::new();
        for ((prefix, _), stats) in self.observed.iter().zip(&self.stats) {
            stats.write(prefix, &mut m);
        }
        for ((prefix, _, _), stats) in self.tracked.iter().zip(&self.tracking) {
            stats.write(prefix, &mut m);
        }
        for (prefix, _, step) in &self.steps {
            step.write(prefix, &mut m);
        }
        m
    }

    fn notes(&self) -> Vec<String> {
        let Some(last_t) = self.last_t else { return Vec::new() };
        let no_limits = self.no_limits.then(|| NO_LIMITS.to_owned());
        let table_ends = self.tracked.iter().filter_map(|(prefix, _, signal)| match signal {
            Signal::Table { t, .. } if t[t.len() - 1] < last_t => Some(format!(
                "{prefix}: the reference table ends at t = {} s; its last value held to the end ({last_t} s)",
                t[t.len() - 1]
            )),
            _ => None,
        });
        let steps = self.steps.iter().flat_map(|(prefix, _, step)| step.notes(prefix));
        no_limits.into_iter().chain(table_ends).chain(steps).collect()
    }
}

/// The generic metrics alone (no reference): per state, output and input component.
pub fn generic(names: Declared) -> Box<dyn Metrics> {
    let observed = names.observed();
    let stats = vec![Stats::default(); observed.len()];
    Box::new(DeclaredMetrics {
        observed,
        tracked: Vec::new(),
        stats,
        tracking: Vec::new(),
        steps: Vec::new(),
        last_t: None,
        no_limits: false,
    })
}

#[cfg(test)]
#[path = "metrics_tests.rs"]
mod tests;
