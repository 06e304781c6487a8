//! `looplab sweep`: runs a scenario again and again in lockstep mode (or real time, where the
//! user sets it, with `--processes`; a `delay` means the same in both) while one launch-file key
//! varies, and reports the scenario's metrics and what the swept fault did at each value. For a
//! controller delay it finds the smallest delay at which the loop goes unstable and prints it
//! next to the delay margin the scenario's linearised model predicts. Each value runs in this
//! process (`launcher::in_process`, byte-identical to the five processes in lockstep) unless
//! `--processes` asks for the five-process pipeline.

use std::collections::BTreeMap;
use std::fmt::Write as _;
use std::path::{Path, PathBuf};
use std::process::ExitCode;

use anyhow::Result;
use serde::Serialize;

use crate::config::faults::FaultKind;
use crate::config::launch::{LaunchConfig, Override};
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

/// The error's peak in the last second over its peak in the first second of the fault above
/// which the loop counts as unstable: the disturbance the fault caused grew instead of dying
/// out. This judges the loop's linear stability where the fault's disturbance stands above the
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
    /// No fault, but the run went beyond the scenario's limit (and came back).
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
    let resolve = |value: f64| -> Result<(f64, LaunchConfig, Box<dyn Scenario>), String> {
        let mut overrides = vec![Override::parse("mode=lockstep").expect("valid")];
        overrides.extend(args.overrides.iter().cloned());
        overrides.push(Override::parse(&format!("{}={}", args.param, value_text(value))).map_err(|e| e.to_string())?);
        let (config, scenario) = catalog.resolve(&args.target, &overrides).map_err(|e| e.to_string())?;
        Ok((value, config, scenario))
    };
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
    let results = run_all(&configs, binaries.as_ref(), &out, &args.param, args.jobs.max(1), &stop);
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
    for ((value, _, _), result) in configs.iter().zip(results) {
        match result.expect("without a stop request every value runs") {
            Ok((summary, outcome)) => points.push(point(*value, &summary, &outcome, fault_index)),
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
            .filter(|&j| points[j].verdict == Verdict::Stable)
            .and_then(|j| between(points[j].value, points[i].value, args.step, whole))
        else {
            break;
        };
        let config = match resolve(mid) {
            Ok(c) => c,
            Err(e) => return bad(e),
        };
        tell!("bisecting: {} = {}", args.param, value_text(mid));
        let result = run_all(std::slice::from_ref(&config), binaries.as_ref(), &out, &args.param, 1, &stop);
        match result.into_iter().next().flatten() {
            Some(Ok((summary, outcome))) => points.insert(i, point(mid, &summary, &outcome, fault_index)),
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
    };
    say_raw!("{}", render(&report, &args.metrics));
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
    if report.points.iter().any(|p| p.verdict == Verdict::Failed) { ExitCode::FAILURE } else { ExitCode::SUCCESS }
}

/// Runs every value, `jobs` at a time (each job a thread running one value at a time, as five
/// processes with `binaries`, else in the thread itself), until a stop request; results in the
/// order of `configs` (None: not run, or interrupted).
fn run_all(
    configs: &[(f64, LaunchConfig, Box<dyn Scenario>)],
    binaries: Option<&Binaries>,
    out: &Path,
    param: &str,
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
                    let dir = out.join(format!("{param}={}", value_text(*value)));
                    let result =
                        crate::launcher::create_run_dir(Some(&dir), &config.scenario).and_then(|dir| match binaries {
                            Some(binaries) => run_once(config, scenario.as_ref(), binaries, &dir, true),
                            None => run_in_process(config, scenario.as_ref(), &dir),
                        });
                    if matches!(result, Ok((_, Outcome::Interrupted))) {
                        break;
                    }
                    if let Ok((summary, _)) = &result {
                        progress.suspend(|| tell!("  {param} = {}: {} loops", value_text(*value), summary.loops));
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

fn point(value: f64, summary: &Summary, outcome: &Outcome, fault: Option<usize>) -> SweepPoint {
    let effect = fault.and_then(|i| summary.faults.get(i)).and_then(|f| f.effect.clone());
    let growth = effect.as_ref().and_then(|e| match (e.error_peak_first_s, e.error_peak_last_s) {
        (Some(first), Some(last)) if first > 0.0 => Some(last / first),
        _ => None,
    });
    let within_limits = effect.as_ref().map(|e| e.within_limits);
    let control = summary.limits.verdict;
    let verdict = if !summary.completed || *outcome != Outcome::Completed {
        Verdict::Failed
    } else if within_limits == Some(false) || growth.is_some_and(|g| g > UNSTABLE_GROWTH) {
        Verdict::Unstable
    } else if control == ControlVerdict::Lost {
        Verdict::Lost
    } else if effect.is_none() && control == ControlVerdict::LimitsExceeded {
        Verdict::Exceeded
    } else if effect.is_none() {
        Verdict::NoFault
    } else {
        Verdict::Stable
    };
    SweepPoint {
        value,
        completed: summary.completed,
        stopped_because: summary.stopped_because.clone(),
        verdict,
        growth,
        worst_error: effect
            .as_ref()
            .and_then(|e| [e.worst_error_during, e.worst_error_after].into_iter().flatten().reduce(f64::max)),
        within_limits,
        control,
        metrics: summary.metrics.clone(),
        run_dir: summary.run_dir.clone(),
    }
}

/// A metric's column: at least as wide as its name.
fn metric_width(name: &str) -> usize {
    name.chars().count().max(10)
}

fn render(r: &SweepReport, metrics: &[String]) -> String {
    let mut out = String::new();
    let _ = writeln!(out, "\nLoopLab sweep · {} · {} ({})", r.scenario, r.param, r.mode);
    let _ = write!(
        out,
        "  {:>10}  {:<9}{:>12}{:>14}  {:<13}  control",
        "value", "verdict", "growth", "worst error", "within limits"
    );
    for name in metrics {
        let _ = write!(out, "  {name:>width$}", width = metric_width(name));
    }
    let _ = writeln!(out);
    for p in &r.points {
        let mut line = String::new();
        let _ = write!(
            line,
            "  {:>10}  {:<9}{:>12}{:>14}  {:<13}  {:<15}",
            value_text(p.value),
            p.verdict,
            p.growth.map_or("-".into(), |g| format!("{g:.3}")),
            p.worst_error.map_or("-".into(), |e| format!("{e:.5}")),
            p.within_limits.map_or("-", |w| if w { "yes" } else { "NO" }),
            p.control.to_string()
        );
        for name in metrics {
            let value = p.metrics.get(name).map_or("-".into(), |v| format!("{v:.5}"));
            let _ = write!(line, "  {value:>width$}", width = metric_width(name));
        }
        let _ = writeln!(out, "{}", line.trim_end());
    }
    let _ = writeln!(out, "  control: the whole run against the scenario's limits (summary.json's `limits`)");
    if r.points.iter().all(|p| p.within_limits.is_none()) {
        let what = if metrics.is_empty() {
            "each run's summary.json has its metrics (--metric NAME shows one here)"
        } else {
            "the metrics above say what each value did"
        };
        let _ = writeln!(out, "\n  no fault to judge the loop by: {what}");
        return out;
    }
    let _ = writeln!(
        out,
        "  growth: the error's peak in the fault's last second over its first; above {UNSTABLE_GROWTH} the loop is unstable"
    );
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
        };
        let text = render(&report, &[]);
        assert!(text.contains("theory:   margin unknown (not the stock law"), "{text}");
        assert!(!text.contains("agree"), "{text}");
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
