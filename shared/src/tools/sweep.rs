//! `looplab sweep`: runs a scenario again and again in lockstep mode (or real time, where the
//! user sets it, with `--processes`; a `delay` means the same in both) while one launch-file key
//! varies, and reports the scenario's metrics and what the swept fault did at each value. For a
//! controller delay it finds the smallest delay at which the loop goes unstable and prints it
//! next to the delay margin the scenario's linearised model predicts. Each value runs in this
//! process (`launcher::in_process`, byte-identical to the five processes in lockstep) unless
//! `--processes` asks for the five-process pipeline.
//!
//! In lockstep a fault is judged against the same run without it (the fault-free baseline, run
//! once for a swept fault key, else once per value), so that a reference step inside the judged
//! window is not taken for the fault's effect; in real time, against zero error, with a warning
//! where a declared reference moves inside the window.

use std::collections::BTreeMap;
use std::fmt::Write as _;
use std::path::{Path, PathBuf};
use std::process::ExitCode;

use anyhow::Result;
use serde::Serialize;

use crate::config::faults::FaultKind;
use crate::config::gate::{Gate, GateKind};
use crate::config::launch::{LaunchConfig, Mode, Override};
use crate::contract::role::Role;
use crate::launcher::budget::theoretical_margin;
use crate::launcher::in_process::run_in_process;
use crate::launcher::inject::target;
use crate::launcher::verdict::Verdict as ControlVerdict;
use crate::launcher::{Binaries, EXIT_BAD_INPUT, EXIT_INTERRUPTED, Outcome, StopReason, Summary, run_once};
use crate::model::catalog::Catalog;
use crate::model::scenario::{Scenario, TheoreticalMargin};
use crate::runtime::in_process::refusal;
use crate::runtime::signals::StopFlag;
use crate::tools::{ToolError, twin};

/// The error's peak in the last second over its peak in the first second of the fault above
/// which the loop counts as unstable: the disturbance the fault caused grew instead of dying
/// out. In lockstep the error is the departure from the fault-free baseline. This judges the loop's linear stability where the fault's disturbance stands above the
/// sensors' noise and quantisation: sweep a delay margin with them off, as the theory assumes
/// (with them on, the noise floor and the actuator limit blur the verdict near the margin).
pub const UNSTABLE_GROWTH: f64 = 1.0;

pub struct SweepArgs {
    pub target: String,
    pub param: String,
    pub from: f64,
    pub to: f64,
    pub step: f64,
    /// --set, --fault, --duration and --seed, already as overrides.
    pub overrides: Vec<Override>,
    pub out: Option<PathBuf>,
    pub jobs: usize,
    /// Run each value as the five processes instead of in this process.
    pub processes: bool,
    /// Metrics to print beside each value.
    pub metrics: Vec<String>,
    /// `--fail-on`, judged on every value's run with the launch file's `[gate]`.
    pub gates: Vec<Gate>,
}

#[derive(Debug, Clone, Serialize)]
pub struct SweepPoint {
    pub value: f64,
    pub completed: bool,
    pub stopped_because: Option<StopReason>,
    pub verdict: Verdict,
    /// The swept fault's error peak, last second over first second.
    pub growth: Option<f64>,
    pub worst_error: Option<f64>,
    pub within_limits: Option<bool>,
    /// The whole run judged against the scenario's limits (summary.json's `limits`).
    pub control: ControlVerdict,
    pub metrics: BTreeMap<String, f64>,
    pub run_dir: String,
    /// The line of each gate this value's run failed.
    pub failed_gates: Vec<String>,
    /// Which kinds of gate failed (control, timing), for the exit code.
    #[serde(skip)]
    pub failed_kinds: (bool, bool),
}

/// What one value did to the loop.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, strum::Display)]
#[serde(rename_all = "lowercase")]
#[strum(serialize_all = "lowercase")]
pub enum Verdict {
    Stable,
    Unstable,
    /// The run did not complete.
    Failed,
    /// The run has no fault to judge, and it stayed within the scenario's limits.
    #[serde(rename = "no fault")]
    #[strum(serialize = "no fault")]
    NoFault,
    /// The loop held, but the run went beyond the scenario's limit: without a fault, or (judged
    /// against the fault-free baseline) with the fault where the run without it stayed within.
    #[serde(rename = "exceeded")]
    #[strum(serialize = "exceeded")]
    Exceeded,
    /// The run was lost (the pendulum fell; see `launcher::verdict`), whatever the fault did.
    Lost,
}

#[derive(Debug, Clone, Serialize)]
pub struct SweepReport {
    pub scenario: String,
    pub param: String,
    /// The runs' mode: lockstep unless `--set mode=realtime` (with `--processes`) asks otherwise.
    pub mode: String,
    pub points: Vec<SweepPoint>,
    /// The smallest swept value whose loop went unstable.
    pub first_unstable: Option<f64>,
    /// For a swept delay: the first unstable value as a delay in ticks and in ms.
    pub first_unstable_ticks: Option<f64>,
    pub first_unstable_ms: Option<f64>,
    /// For a controller delay: the scenario's theory for the loop swept, or why there is none.
    pub theory: Option<TheoreticalMargin>,
    /// The theory's margin in ms.
    pub theory_ms: Option<f64>,
    pub theory_unknown: Option<String>,
    /// What the fault's growth is measured against: "the fault-free baseline" or "zero error".
    pub judged_against: Option<String>,
    /// Warnings about the verdicts (a reference that moves inside a window judged against zero).
    pub warnings: Vec<String>,
}

/// A swept value as a delay in (ticks, ms), for a key that is one: `…delay_ticks`, `…delay_s`.
fn as_delay(param: &str, value: f64, rate_hz: f64) -> Option<(f64, f64)> {
    if param.ends_with(".delay_ticks") {
        Some((value, value * 1e3 / rate_hz))
    } else if param.ends_with(".delay_s") {
        Some((value * rate_hz, value * 1e3))
    } else {
        None
    }
}

/// The value halfway between a stable `a` and an unstable `b`, if one is left to try: whole
/// numbers for a sweep of whole numbers, else down to a sixteenth of the step.
fn between(a: f64, b: f64, step: f64, whole: bool) -> Option<f64> {
    let mid = if whole { ((a + b) / 2.0).floor() } else { (a + b) / 2.0 };
    let enough = if whole { b - a <= 1.0 } else { b - a <= step / 16.0 + 1e-12 };
    (!enough && mid > a && mid < b).then_some(mid)
}

impl Verdict {
    /// The loop did not hold: the fault's disturbance grew, or the run was lost.
    fn is_unstable(self) -> bool {
        matches!(self, Verdict::Unstable | Verdict::Lost)
    }
}

fn value_text(v: f64) -> String {
    if v.fract() == 0.0 && v.abs() < 1e15 { format!("{}", v as i64) } else { format!("{v}") }
}

/// The most values one sweep runs.
const MAX_SWEEP_VALUES: usize = 1000;

/// The swept values, from `from` to `to` inclusive.
fn values(from: f64, to: f64, step: f64) -> Vec<f64> {
    let n = ((to - from) / step + 1e-9).floor() as i64;
    // Rounded to 12 significant digits, so that 0.05 is not printed (and set) as
    // 0.05000000000000002.
    (0..=n.max(0))
        .map(|i| format!("{:.11e}", from + i as f64 * step).parse().expect("a formatted number parses"))
        .collect()
}

/// The index of the fault a `faults.N.…` key belongs to.
fn swept_fault(param: &str) -> Option<usize> {
    param.strip_prefix("faults.")?.split('.').next()?.parse().ok()
}

/// Runs the sweep of `args.target`, a scenario of `catalog` or a launch file for one.
pub fn run(args: SweepArgs, catalog: &Catalog) -> ExitCode {
    let bad = |message: String| {
        tell!("error: {message}");
        ExitCode::from(EXIT_BAD_INPUT)
    };
    if !(args.step.is_finite() && args.step > 0.0 && args.from.is_finite() && args.to.is_finite()) {
        return bad(format!("--from, --to and --step must be numbers with --step > 0 (got step {})", args.step));
    }
    if args.to < args.from {
        return bad(format!("--to ({}) is below --from ({})", args.to, args.from));
    }
    // Each value is a whole run: a typo such as --to 1e9 must not queue a billion of them.
    let count = ((args.to - args.from) / args.step + 1e-9).floor() + 1.0;
    if count > MAX_SWEEP_VALUES as f64 {
        return bad(format!(
            "--from {} --to {} --step {} gives {count} values; at most {MAX_SWEEP_VALUES} are allowed",
            args.from, args.to, args.step
        ));
    }
    let values = values(args.from, args.to, args.step);
    // The launch file for one value; `fault_free`: the same without its faults (the baseline).
    let resolve_as = |value: f64, fault_free: bool| -> Result<(f64, LaunchConfig, Box<dyn Scenario>), String> {
        let mut overrides = vec![Override::parse("mode=lockstep").expect("valid")];
        overrides.extend(args.overrides.iter().cloned());
        overrides.push(Override::parse(&format!("{}={}", args.param, value_text(value))).map_err(|e| e.to_string())?);
        if fault_free {
            overrides.push(Override {
                key: "faults".into(),
                text: "faults=[] (the fault-free baseline)".into(),
                value: toml::Value::Array(vec![]),
                append: false,
            });
        }
        let (config, scenario) = catalog.resolve(&args.target, &overrides).map_err(|e| e.to_string())?;
        Ok((value, config, scenario))
    };
    let resolve = |value: f64| resolve_as(value, false);
    // Check every value's launch file before running any.
    let mut configs: Vec<(f64, LaunchConfig, Box<dyn Scenario>)> = vec![];
    for &value in &values {
        match resolve(value) {
            Ok(c) => configs.push(c),
            Err(e) => return bad(e),
        }
    }
    let fault_index = swept_fault(&args.param).or((!configs[0].1.faults.is_empty()).then_some(0));
    let binaries = if args.processes {
        match crate::launcher::locate_binaries() {
            Ok(b) => Some(b),
            Err(e) => return bad(format!("{e:#}")),
        }
    } else {
        // No silent fall-back to processes: the user asks for them.
        if let Some(why) = configs.iter().find_map(|(_, config, _)| refusal(config)) {
            return bad(format!(
                "cannot sweep in one process: {why}; add --processes to run each value as five processes"
            ));
        }
        None
    };
    let out = args.out.clone().unwrap_or_else(|| {
        let stamp = chrono::Local::now().format("%Y%m%d-%H%M%S");
        PathBuf::from("runs").join(format!("{stamp}-sweep-{}", configs[0].1.scenario))
    });
    if out.exists() && std::fs::read_dir(&out).map(|mut d| d.next().is_some()).unwrap_or(true) {
        return bad(format!("--out {}: the folder exists and is not empty; give a new or empty folder", out.display()));
    }

    tell!(
        "sweeping {} over {} values, {} at a time, in {} mode",
        args.param,
        values.len(),
        args.jobs,
        configs[0].1.mode.name()
    );
    let stop = match StopFlag::install() {
        Ok(stop) => stop,
        Err(e) => {
            tell!("error: cannot install the signal handlers: {e}");
            return ExitCode::FAILURE;
        }
    };
    // In lockstep the swept fault is judged against the same run without it: one baseline for
    // a swept fault key (every value's is the same), else one per value.
    let by_baseline = fault_index.is_some() && configs[0].1.mode == Mode::Lockstep;
    let one_baseline = swept_fault(&args.param).is_some();
    let mut baselines = Baselines::default();
    if by_baseline {
        let wanted: &[f64] = if one_baseline { &values[..1] } else { &values };
        let mut runs = vec![];
        for &value in wanted {
            match resolve_as(value, true) {
                Ok(c) => runs.push(c),
                Err(e) => return bad(e),
            }
        }
        tell!("running the fault-free baseline{} first", if one_baseline { "" } else { " of each value" });
        let names = |value: f64| baseline_name(&args.param, value, one_baseline);
        let results = run_all(&runs, binaries.as_ref(), &out, &names, args.jobs.max(1), &stop);
        if let Err(code) = baselines.add(&runs, results, &stop) {
            return code;
        }
    }
    let key = |value: f64| if one_baseline { values[0] } else { value };
    let judge = |baselines: &Baselines,
                 value: f64,
                 config: &LaunchConfig,
                 scenario: &dyn Scenario,
                 done: (Summary, Outcome)| {
        let (summary, outcome) = done;
        let judged = match baselines.get(key(value)) {
            Some(base) if by_baseline => against_baseline(config, scenario, &summary, base, fault_index),
            _ => Ok(against_zero(&summary, fault_index)),
        };
        judged
            .map_err(|e| format!("{e}"))
            .and_then(|judged| point(value, &summary, &outcome, fault_index, judged, &args.gates, config))
    };
    let names = |value: f64| format!("{}={}", args.param, value_text(value));
    let results = run_all(&configs, binaries.as_ref(), &out, &names, args.jobs.max(1), &stop);
    if stop.requested() {
        let done = results.iter().filter(|r| r.is_some()).count();
        tell!(
            "sweep interrupted after {done} of {} values; no verdict. Their run folders are in {}",
            configs.len(),
            out.display()
        );
        return ExitCode::from(EXIT_INTERRUPTED);
    }
    let mut points = vec![];
    for ((value, config, scenario), result) in configs.iter().zip(results) {
        match result.expect("without a stop request every value runs") {
            Ok(done) => match judge(&baselines, *value, config, scenario.as_ref(), done) {
                Ok(p) => points.push(p),
                Err(e) => return bad(e),
            },
            Err(e) => {
                tell!("error: the run for {} = {} failed: {e:#}", args.param, value_text(*value));
                return ExitCode::FAILURE;
            }
        }
    }
    // Bisect between the last stable value and the first unstable one, one run at a time (each
    // lockstep, so the answer is the same every time).
    let whole = [args.from, args.step].iter().all(|v| v.fract() == 0.0);
    while let Some(i) = points.iter().position(|p| p.verdict.is_unstable()) {
        let Some(mid) = i
            .checked_sub(1)
            .filter(|&j| matches!(points[j].verdict, Verdict::Stable | Verdict::Exceeded))
            .and_then(|j| between(points[j].value, points[i].value, args.step, whole))
        else {
            break;
        };
        let config = match resolve(mid) {
            Ok(c) => c,
            Err(e) => return bad(e),
        };
        tell!("bisecting: {} = {}", args.param, value_text(mid));
        if by_baseline && !one_baseline {
            let base = match resolve_as(mid, true) {
                Ok(c) => c,
                Err(e) => return bad(e),
            };
            let names = |value: f64| baseline_name(&args.param, value, false);
            let result = run_all(std::slice::from_ref(&base), binaries.as_ref(), &out, &names, 1, &stop);
            if let Err(code) = baselines.add(std::slice::from_ref(&base), result, &stop) {
                return code;
            }
        }
        let result = run_all(std::slice::from_ref(&config), binaries.as_ref(), &out, &names, 1, &stop);
        match result.into_iter().next().flatten() {
            Some(Ok(done)) => match judge(&baselines, mid, &config.1, config.2.as_ref(), done) {
                Ok(p) => points.insert(i, p),
                Err(e) => return bad(e),
            },
            Some(Err(e)) => {
                tell!("error: the run for {} = {} failed: {e:#}", args.param, value_text(mid));
                return ExitCode::FAILURE;
            }
            None => return ExitCode::from(EXIT_INTERRUPTED),
        }
    }
    let first_unstable = points.iter().find(|p| p.verdict.is_unstable()).map(|p| p.value);
    let (_, config, scenario) = &configs[0];
    let delay = first_unstable.and_then(|v| as_delay(&args.param, v, config.rate_hz));
    let controller_delay = fault_index
        .and_then(|i| config.faults.get(i))
        .is_some_and(|f| f.kind == FaultKind::Delay && target(f) == Role::Controller)
        && args.param.ends_with(".delay_ticks");
    let (theory, theory_unknown) = match controller_delay.then(|| theoretical_margin(config, scenario.as_ref())) {
        Some(Ok(theory)) => (Some(theory), None),
        Some(Err(why)) => (None, Some(why)),
        None => (None, None),
    };
    let judged_against =
        fault_index.map(|_| if by_baseline { "the fault-free baseline" } else { "zero error" }.to_owned());
    let mut warnings = vec![];
    if !by_baseline && let Some(window) = fault_index.and_then(|i| judged_window(config, i)) {
        warnings.extend(reference_moves(config, window));
    }
    let report = SweepReport {
        scenario: config.scenario.clone(),
        param: args.param.clone(),
        mode: config.mode.name().to_owned(),
        points,
        first_unstable,
        first_unstable_ticks: delay.map(|d| d.0),
        first_unstable_ms: delay.map(|d| d.1),
        theory_ms: theory.as_ref().map(|t| f64::from(t.ticks) * 1e3 / config.rate_hz),
        theory,
        theory_unknown,
        judged_against,
        warnings,
    };
    say_raw!("{}", render(&report, &args.metrics));
    for warning in &report.warnings {
        tell!("warning: {warning}");
    }
    for name in &args.metrics {
        if report.points.iter().all(|p| !p.metrics.contains_key(name)) {
            let known: Vec<&str> = report.points[0].metrics.keys().map(String::as_str).collect();
            tell!("warning: no run reported a metric {name}; the runs' metrics are {}", known.join(", "));
        }
    }
    let path = out.join("sweep.json");
    let written = serde_json::to_string_pretty(&report)
        .map_err(anyhow::Error::from)
        .and_then(|text| crate::runtime::storage::run_file::write(&path, (text + "\n").as_bytes()));
    if let Err(e) = written {
        tell!("error: {e:#}");
        return ExitCode::FAILURE;
    }
    if report.points.iter().any(|p| p.verdict == Verdict::Failed) {
        return ExitCode::FAILURE;
    }
    let control = report.points.iter().any(|p| p.failed_kinds.0);
    let timing = report.points.iter().any(|p| p.failed_kinds.1);
    crate::launcher::gate::exit_code(control, timing).map_or(ExitCode::SUCCESS, ExitCode::from)
}

/// A baseline's run folder: one for the sweep, or one per value.
fn baseline_name(param: &str, value: f64, one: bool) -> String {
    if one { "baseline".to_owned() } else { format!("baseline {param}={}", value_text(value)) }
}

/// The fault-free baselines' errors loop by loop, by swept value.
#[derive(Default)]
struct Baselines(BTreeMap<u64, Vec<f64>>);

impl Baselines {
    fn get(&self, value: f64) -> Option<&[f64]> {
        self.0.get(&value.to_bits()).map(Vec::as_slice)
    }

    /// Keeps the errors of the baselines `runs` ran as; Err: the exit code of a baseline that
    /// failed or was interrupted.
    fn add(
        &mut self,
        runs: &[(f64, LaunchConfig, Box<dyn Scenario>)],
        results: Vec<Option<Result<(Summary, Outcome)>>>,
        stop: &StopFlag,
    ) -> Result<(), ExitCode> {
        for ((value, config, scenario), result) in runs.iter().zip(results) {
            let failed = |why: String| {
                tell!("error: the fault-free baseline for {} failed: {why}", value_text(*value));
                ExitCode::FAILURE
            };
            let (summary, outcome) = match result {
                None => return Err(ExitCode::from(EXIT_INTERRUPTED)),
                Some(Err(e)) => return Err(failed(format!("{e:#}"))),
                Some(Ok(done)) => done,
            };
            if stop.requested() || outcome == Outcome::Interrupted {
                return Err(ExitCode::from(EXIT_INTERRUPTED));
            }
            if !summary.completed || outcome != Outcome::Completed {
                return Err(failed(format!("it did not complete ({})", summary.run_dir)));
            }
            let states = twin::plant_states(Path::new(&summary.run_dir), config, scenario.as_ref())
                .map_err(|e| failed(e.to_string()))?;
            self.0.insert(value.to_bits(), twin::errors(config, scenario.as_ref(), &states));
        }
        Ok(())
    }
}

/// The loops a fault's growth is judged over: from its start to the next fault's start (or the
/// run's end), as the monitor's fault effect takes them (`monitor::fault_effect`).
fn judged_window(config: &LaunchConfig, fault: usize) -> Option<(usize, usize)> {
    let loops = (config.duration_s * config.rate_hz).round() as usize;
    let from = config.faults.get(fault)?.ticks(config.rate_hz).0 as usize;
    let end = config.faults.iter().map(|f| f.ticks(config.rate_hz).0 as usize).filter(|&s| s > from).min();
    Some((from.min(loops), end.unwrap_or(loops).min(loops)))
}

/// The peak of `values` over the window's first second and over its last second.
fn peaks(values: impl Fn(usize) -> f64, (from, end): (usize, usize), second: usize) -> (f64, f64) {
    let peak = |range: std::ops::Range<usize>| range.map(&values).fold(0.0, f64::max);
    (peak(from..(from + second).min(end)), peak(end.saturating_sub(second).max(from)..end))
}

/// What the swept fault did to the loop.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
struct FaultJudged {
    /// The disturbance's peak in the fault's last second over its first.
    growth: Option<f64>,
    /// The disturbance's largest value in the fault's window.
    worst: Option<f64>,
    /// Whether the loop stayed within the scenario's limits where the fault had its effect.
    within_limits: Option<bool>,
    /// Judged against zero error, a run beyond the limits counts as unstable (the error cannot
    /// tell the fault's effect from the rest); against the baseline only growth does.
    beyond_is_unstable: bool,
    /// The run was lost: past a point of no return (against zero error: beyond the limits at
    /// its end, too).
    lost: bool,
}

/// The swept fault judged in the monitor's terms, the error measured against zero: the error's
/// peak in the fault's last second over its first, and the fault effect's limits.
fn against_zero(summary: &Summary, fault: Option<usize>) -> FaultJudged {
    let lost = summary.limits.verdict == ControlVerdict::Lost;
    let Some(effect) = fault.and_then(|i| summary.faults.get(i)).and_then(|f| f.effect.as_ref()) else {
        return FaultJudged { lost, beyond_is_unstable: true, ..Default::default() };
    };
    let growth = match (effect.error_peak_first_s, effect.error_peak_last_s) {
        (Some(first), Some(last)) if first > 0.0 => Some(last / first),
        _ => None,
    };
    FaultJudged {
        growth,
        worst: [effect.worst_error_during, effect.worst_error_after].into_iter().flatten().reduce(f64::max),
        within_limits: Some(effect.within_limits),
        beyond_is_unstable: true,
        lost,
    }
}

/// The swept fault judged against the fault-free baseline: the growth of |error − the
/// baseline's error| from the fault's first second to its last (None: the fault changed nothing
/// in its first second), and whether the run went beyond the limits in the window at a loop
/// where the baseline did not.
fn against_baseline(
    config: &LaunchConfig,
    scenario: &dyn Scenario,
    summary: &Summary,
    base: &[f64],
    fault: Option<usize>,
) -> Result<FaultJudged, ToolError> {
    let measure = scenario.error_measure();
    let lost = summary.limits.verdict == ControlVerdict::Lost && measure.lost_beyond.is_some();
    let Some(window) = fault.and_then(|i| judged_window(config, i)) else {
        return Ok(FaultJudged { lost, ..Default::default() });
    };
    let states = twin::plant_states(Path::new(&summary.run_dir), config, scenario)?;
    let run = twin::errors(config, scenario, &states);
    if run.len() != base.len() {
        return Err(ToolError::Failed(anyhow::anyhow!(
            "{} ran {} loops and its fault-free baseline {}",
            summary.run_dir,
            run.len(),
            base.len()
        )));
    }
    let departure = |k: usize| if k < run.len() { (run[k] - base[k]).abs() } else { 0.0 };
    // NaN (a run that blew up) is the largest departure there is.
    let departure = |k: usize| if departure(k).is_nan() { f64::INFINITY } else { departure(k) };
    let (first, last) = peaks(departure, window, config.rate_hz.round() as usize);
    let growth = if last.is_infinite() { Some(f64::INFINITY) } else { (first > 0.0).then(|| last / first) };
    let beyond_alone = (window.0..window.1).any(|k| measure.beyond(run[k]) && !measure.beyond(base[k]));
    Ok(FaultJudged {
        growth,
        worst: Some((window.0..window.1).map(departure).fold(0.0, f64::max)),
        within_limits: Some(!beyond_alone),
        beyond_is_unstable: false,
        lost,
    })
}

/// A warning where a declared reference moves inside the window judged against zero error: the
/// tracking error there is the reference's, not the fault's.
fn reference_moves(config: &LaunchConfig, (from, end): (usize, usize)) -> Option<String> {
    let references = crate::model::reference::declared_references(config).ok()?;
    let at = |k: usize| k as f64 / config.rate_hz;
    let moving = references.iter().find(|r| (from..end).any(|k| r.signal.at(at(k)) != r.signal.at(at(from))))?;
    Some(format!(
        "the reference of {} moves between t = {} s and {} s, inside the window the fault is judged over against zero error; \
         its tracking error counts as the fault's (in lockstep the sweep judges against the fault-free baseline instead)",
        moving.track,
        at(from),
        at(end)
    ))
}

/// Runs every value, `jobs` at a time (each job a thread running one value at a time, as five
/// processes with `binaries`, else in the thread itself), until a stop request; results in the
/// order of `configs` (None: not run, or interrupted).
fn run_all(
    configs: &[(f64, LaunchConfig, Box<dyn Scenario>)],
    binaries: Option<&Binaries>,
    out: &Path,
    name: &(dyn Fn(f64) -> String + Sync),
    jobs: usize,
    stop: &StopFlag,
) -> Vec<Option<Result<(Summary, Outcome)>>> {
    let next = std::sync::atomic::AtomicUsize::new(0);
    let progress = progress_bar(configs.len() as u64, "values");
    type Slot = std::sync::Mutex<Option<Result<(Summary, Outcome)>>>;
    let results: Vec<Slot> = configs.iter().map(|_| std::sync::Mutex::new(None)).collect();
    std::thread::scope(|scope| {
        for _ in 0..jobs.min(configs.len()) {
            scope.spawn(|| {
                loop {
                    let i = next.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
                    let Some((value, config, scenario)) = configs.get(i) else { break };
                    if stop.requested() {
                        break;
                    }
                    let dir = out.join(name(*value));
                    let result =
                        crate::launcher::create_run_dir(Some(&dir), &config.scenario).and_then(|dir| match binaries {
                            Some(binaries) => run_once(config, scenario.as_ref(), binaries, &dir, true),
                            None => run_in_process(config, scenario.as_ref(), &dir),
                        });
                    if matches!(result, Ok((_, Outcome::Interrupted))) {
                        break;
                    }
                    if let Ok((summary, _)) = &result {
                        progress.suspend(|| tell!("  {}: {} loops", name(*value), summary.loops));
                    }
                    progress.inc(1);
                    *results[i].lock().expect("not poisoned") = Some(result);
                }
            });
        }
    });
    progress.finish_and_clear();
    results.into_iter().map(|r| r.into_inner().expect("not poisoned")).collect()
}

/// A progress bar on stderr with the time left, `len` steps of `what`; drawn only on a
/// terminal (a log gets the plain lines printed around it).
pub fn progress_bar(len: u64, what: &str) -> indicatif::ProgressBar {
    let bar = indicatif::ProgressBar::with_draw_target(Some(len), indicatif::ProgressDrawTarget::stderr());
    let template = format!("{{bar:24}} {{pos}}/{{len}} {what} · {{elapsed}} so far, about {{eta}} left");
    bar.set_style(indicatif::ProgressStyle::with_template(&template).expect("valid template"));
    bar
}

/// One value's point: its verdict from what the swept fault did, and `gates` judged on its
/// run (Err: a gate names what the run does not have).
fn point(
    value: f64,
    summary: &Summary,
    outcome: &Outcome,
    fault: Option<usize>,
    judged: FaultJudged,
    gates: &[Gate],
    config: &LaunchConfig,
) -> Result<SweepPoint, String> {
    let effect = fault.and_then(|i| summary.faults.get(i)).and_then(|f| f.effect.clone());
    let gates: Vec<Gate> = config.gates.iter().chain(gates).cloned().collect();
    let gated = crate::launcher::gate::judge(&gates, summary).map_err(|e| format!("--fail-on {e}"))?;
    let control = summary.limits.verdict;
    let FaultJudged { growth, worst, within_limits, beyond_is_unstable, lost } = judged;
    let verdict = if !summary.completed || *outcome != Outcome::Completed {
        Verdict::Failed
    } else if (beyond_is_unstable && within_limits == Some(false)) || growth.is_some_and(|g| g > UNSTABLE_GROWTH) {
        Verdict::Unstable
    } else if lost {
        Verdict::Lost
    } else if (effect.is_none() && control.failed()) || within_limits == Some(false) {
        Verdict::Exceeded
    } else if effect.is_none() {
        Verdict::NoFault
    } else {
        Verdict::Stable
    };
    Ok(SweepPoint {
        value,
        completed: summary.completed,
        stopped_because: summary.stopped_because.clone(),
        verdict,
        growth,
        worst_error: worst,
        within_limits,
        control,
        metrics: summary.metrics.clone(),
        run_dir: summary.run_dir.clone(),
        failed_gates: gated.lines().cloned().collect(),
        failed_kinds: (gated.failed(GateKind::Control), gated.failed(GateKind::Timing)),
    })
}

/// A metric's column: at least as wide as its name.
fn metric_width(name: &str) -> usize {
    name.chars().count().max(10)
}

fn render(r: &SweepReport, metrics: &[String]) -> String {
    let mut out = String::new();
    let _ = writeln!(out, "\nLoopLab sweep · {} · {} ({})", r.scenario, r.param, r.mode);
    let against_zero = r.judged_against.as_deref() == Some("zero error");
    let worst = if against_zero { "worst error" } else { "departure" };
    let _ = write!(
        out,
        "  {:>10}  {:<9}{:>12}{:>14}  {:<13}  {:<15}  gates",
        "value", "verdict", "growth", worst, "within limits", "control"
    );
    for name in metrics {
        let _ = write!(out, "  {name:>width$}", width = metric_width(name));
    }
    let _ = writeln!(out);
    for p in &r.points {
        let mut line = String::new();
        let _ = write!(
            line,
            "  {:>10}  {:<9}{:>12}{:>14}  {:<13}  {:<15}  {:<5}",
            value_text(p.value),
            p.verdict,
            p.growth.map_or("-".into(), |g| format!("{g:.3}")),
            p.worst_error.map_or("-".into(), |e| format!("{e:.5}")),
            p.within_limits.map_or("-", |w| if w { "yes" } else { "NO" }),
            p.control.to_string(),
            if p.failed_kinds == (false, false) { "pass" } else { "FAIL" }
        );
        for name in metrics {
            let value = p.metrics.get(name).map_or("-".into(), |v| format!("{v:.5}"));
            let _ = write!(line, "  {value:>width$}", width = metric_width(name));
        }
        let _ = writeln!(out, "{}", line.trim_end());
    }
    let _ = writeln!(out, "  control: the whole run against the scenario's limits (summary.json's `limits`)");
    for p in r.points.iter().filter(|p| !p.failed_gates.is_empty()) {
        for line in &p.failed_gates {
            let _ = writeln!(out, "  {} = {}: {line}", r.param, value_text(p.value));
        }
    }
    if r.points.iter().all(|p| p.within_limits.is_none()) {
        let what = if metrics.is_empty() {
            "each run's summary.json has its metrics (--metric NAME shows one here)"
        } else {
            "the metrics above say what each value did"
        };
        let _ = writeln!(out, "\n  no fault to judge the loop by: {what}");
        return out;
    }
    if against_zero {
        let _ = writeln!(
            out,
            "  growth: the error's peak in the fault's last second over its first; above {UNSTABLE_GROWTH} the loop is unstable"
        );
    } else {
        let _ = writeln!(
            out,
            "  departure: |error − the error of the same run without the fault|, its largest in the fault's window\n  \
             growth: the departure's peak in the fault's last second over its first; above {UNSTABLE_GROWTH} the loop is unstable\n  \
             within limits: NO where the fault took the run beyond the limits and the run without it stayed within"
        );
    }
    match r.first_unstable {
        Some(v) => {
            let delay = match (r.first_unstable_ticks, r.first_unstable_ms) {
                (Some(ticks), Some(ms)) => format!(" ({} ticks = {ms:.3} ms)", value_text(ticks)),
                _ => String::new(),
            };
            let _ = writeln!(out, "\n  measured: the loop goes unstable at {} = {}{delay}", r.param, value_text(v));
        }
        None => {
            let _ = writeln!(out, "\n  measured: the loop stayed stable over the whole sweep");
        }
    }
    if let Some(t) = &r.theory {
        let _ = writeln!(
            out,
            "  theory:   the linearised sampled loop goes unstable at {} ticks = {:.3} ms (per-tick spectral radius {:.6} at {}, {:.6} at {})",
            t.ticks,
            r.theory_ms.unwrap_or(f64::NAN),
            t.radius_before,
            t.ticks.saturating_sub(1),
            t.radius_at_margin,
            t.ticks
        );
        if t.continuous_ticks.is_finite() {
            let _ = writeln!(
                out,
                "            continuous estimate: phase margin {:.1}° at {:.1} rad/s = {:.1} ticks; with the lags sampling adds, {:.1} ticks",
                t.phase_margin_deg, t.crossover_rad_s, t.continuous_ticks, t.lagged_ticks
            );
        } else {
            // A declared linear loop's margin comes from its sampled loop gain itself.
            let _ = writeln!(
                out,
                "            the sampled loop's phase margin {:.1}° at {:.1} rad/s = {:.2} ticks",
                t.phase_margin_deg, t.crossover_rad_s, t.lagged_ticks
            );
        }
        if let Some(v) = r.first_unstable {
            let diff = v - f64::from(t.ticks);
            let verdict = if diff.abs() <= 1.0 { "agree within one tick" } else { "DISAGREE by more than one tick" };
            let _ = writeln!(out, "  measured and theory {verdict} ({diff:+} ticks)");
        }
    }
    if let Some(why) = &r.theory_unknown {
        let _ = writeln!(out, "  theory:   margin unknown ({why}); only the measured margin applies");
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn swept_values_include_both_ends() {
        assert_eq!(values(0.0, 3.0, 1.0), [0.0, 1.0, 2.0, 3.0]);
        assert_eq!(values(0.0, 0.3, 0.1).len(), 4);
        assert_eq!(values(-0.1, 0.1, 0.05), [-0.1, -0.05, 0.0, 0.05, 0.1]);
        assert_eq!(values(1e-14, 3e-14, 1e-14), [1e-14, 2e-14, 3e-14]);
        assert_eq!(swept_fault("faults.2.delay_ticks"), Some(2));
        assert_eq!(swept_fault("sensors.encoder.bias"), None);
        assert_eq!(value_text(31.0), "31");
        assert_eq!(value_text(0.25), "0.25");
    }

    /// A sweep without a fault and without --metric says where the metrics are, not "above".
    #[test]
    fn a_sweep_without_a_fault_says_where_its_metrics_are() {
        let point = SweepPoint {
            value: 1.0,
            completed: true,
            stopped_because: None,
            verdict: Verdict::NoFault,
            growth: None,
            worst_error: None,
            within_limits: None,
            control: ControlVerdict::WithinLimits,
            metrics: [("theta_max_abs_rad".to_string(), 0.25)].into(),
            run_dir: "r".into(),
            failed_gates: vec![],
            failed_kinds: (false, false),
        };
        let report = SweepReport {
            scenario: "pendulum".into(),
            param: "seed".into(),
            mode: "lockstep".into(),
            points: vec![point],
            first_unstable: None,
            first_unstable_ticks: None,
            first_unstable_ms: None,
            theory: None,
            theory_unknown: None,
            theory_ms: None,
            judged_against: None,
            warnings: vec![],
        };
        let bare = render(&report, &[]);
        assert!(bare.ends_with("no fault to judge the loop by: each run's summary.json has its metrics (--metric NAME shows one here)\n"), "{bare}");
        let shown = render(&report, &["theta_max_abs_rad".to_string()]);
        assert!(shown.contains("0.25000") && shown.contains("the metrics above say what each value did"), "{shown}");
    }

    #[test]
    fn bisection_stops_at_neighbours() {
        assert_eq!(between(25.0, 35.0, 5.0, true), Some(30.0));
        assert_eq!(between(30.0, 32.0, 5.0, true), Some(31.0));
        assert_eq!(between(30.0, 31.0, 5.0, true), None);
        assert_eq!(between(0.0, 0.01, 0.01, false), Some(0.005));
        assert_eq!(between(0.0, 0.0005, 0.01, false), None);
        assert_eq!(as_delay("faults.0.delay_ticks", 31.0, 1000.0), Some((31.0, 31.0)));
        assert_eq!(as_delay("faults.0.delay_s", 0.004, 500.0), Some((2.0, 4.0)));
        assert_eq!(as_delay("seed", 1.0, 1000.0), None);
    }

    /// A loop with a controller of the user's own: no stock theory, no "agree".
    #[test]
    fn a_sweep_of_a_loop_not_the_stock_laws_does_not_claim_the_theory() {
        let point = |value: f64, verdict| SweepPoint {
            value,
            completed: true,
            stopped_because: None,
            verdict,
            growth: Some(1.0),
            worst_error: Some(0.1),
            within_limits: Some(true),
            control: ControlVerdict::WithinLimits,
            metrics: BTreeMap::new(),
            run_dir: "r".into(),
            failed_gates: vec![],
            failed_kinds: (false, false),
        };
        let report = SweepReport {
            scenario: "pendulum".into(),
            param: "faults.0.delay_ticks".into(),
            mode: "lockstep".into(),
            points: vec![point(30.0, Verdict::Stable), point(31.0, Verdict::Unstable)],
            first_unstable: Some(31.0),
            first_unstable_ticks: Some(31.0),
            first_unstable_ms: Some(31.0),
            theory: None,
            theory_ms: None,
            theory_unknown: Some("not the stock law: the controller is a stage of your own".into()),
            judged_against: Some("the fault-free baseline".into()),
            warnings: vec![],
        };
        let text = render(&report, &[]);
        assert!(text.contains("theory:   margin unknown (not the stock law"), "{text}");
        assert!(!text.contains("agree"), "{text}");
    }

    /// Judged against zero error, a reference step inside the fault's window is warned of; one
    /// before it is not.
    #[test]
    fn a_reference_that_moves_inside_the_judged_window_is_warned_of() {
        let file = concat!(env!("CARGO_MANIFEST_DIR"), "/../launch/declared.toml");
        let warning = |fault: &str| {
            let overrides =
                [Override::parse("reference.table=[[0.0, 0.0], [2.0, 0.1]]").unwrap(), Override::fault(fault).unwrap()];
            let (config, _) = crate::scenarios::resolve(file, &overrides).unwrap();
            reference_moves(&config, judged_window(&config, 0).unwrap())
        };
        let inside = warning("delay controller by 3 ticks at 1s").expect("the step at 2 s is inside [1 s, 5 s)");
        assert!(inside.starts_with("the reference of state.position moves between t = 1 s and 5 s"), "{inside}");
        assert_eq!(warning("delay controller by 3 ticks at 3s"), None);
    }

    #[test]
    fn verdicts_keep_their_text() {
        for (verdict, text) in [
            (Verdict::Stable, "stable"),
            (Verdict::Unstable, "unstable"),
            (Verdict::Failed, "failed"),
            (Verdict::NoFault, "no fault"),
            (Verdict::Exceeded, "exceeded"),
            (Verdict::Lost, "lost"),
        ] {
            assert_eq!(serde_json::to_value(verdict).unwrap(), text);
            assert_eq!(format!("{verdict:<9}|"), format!("{text:<9}|"));
        }
    }
}
