//! `looplab plot RUN_DIR`: a run's figures, as PNG in the run folder: truth against estimate,
//! the commands, each sensor's held values against the truth it measures, a declared system's
//! state and outputs against its reference, the tick period error and the deadline misses by
//! cause, with every fault marked on the time axis; over the whole run or `--from`/`--to`.
//!
//! The CSV files are read by column name through the run folder's reader, the names a run of
//! the launch file writes (`VectorLayout::trajectory_columns`, `loops::columns`).

use std::ops::Range;
use std::path::{Path, PathBuf};

use crate::config::launch::{LaunchConfig, Mode};
use crate::config::schema::Component;
use crate::contract::run_format::files;
use crate::launcher::summary::Summary;
use crate::model::catalog::Catalog;
use crate::model::figure::RunColumns;
use crate::model::figure::runs;
use crate::model::layout::VectorLayout;
use crate::model::reference::{Between, Signal};
use crate::model::scenario::Scenario;
use crate::tools::plot::figure::{Colour, Curve, Draw as _, FaultMark, Figure, Line, Panel, series, steps, tick_label};
use crate::tools::plot::latency;
use crate::tools::plot::misses::{Miss, crosses_by_cause, read_misses};
use crate::tools::run_folder::RunFolder;
use crate::tools::{RUN_FILES, ToolError};

/// Where each vector lies among trajectory.csv's columns, in the layout's order (the order the
/// monitor writes them: k, t, state, each sensor's components, estimate, command, applied input).
#[derive(Debug, Clone, PartialEq)]
pub struct Columns {
    pub state: Range<usize>,
    /// Per sensor, in the layout's order.
    pub sensors: Vec<Range<usize>>,
    pub estimate: Range<usize>,
    pub command: Range<usize>,
    /// What the actuator applied over the period that ended at each row's tick.
    pub applied: Range<usize>,
    pub count: usize,
}

impl Columns {
    pub fn of(layout: &VectorLayout) -> Self {
        let mut next = 2;
        let mut take = |n: usize| {
            next += n;
            next - n..next
        };
        let state = take(layout.state.len());
        let sensors = layout.sensor_dims().into_iter().map(&mut take).collect();
        let estimate = take(layout.estimate.len());
        let command = take(layout.input.len());
        let applied = take(layout.input.len());
        Columns { state, sensors, estimate, command, applied, count: next }
    }
}

/// The plant's ticks, from loops.csv.
pub struct Ticks {
    pub t: Vec<f64>,
    /// Time since the previous wake-up, ns (0 on the first tick).
    pub period_ns: Vec<f64>,
    /// 1 where the loop missed its deadline (its command came late or never).
    pub deadline_miss: Vec<f64>,
}

/// A run folder, read.
pub struct RunData {
    pub config: LaunchConfig,
    pub scenario: Box<dyn Scenario>,
    pub layout: VectorLayout,
    pub columns: Columns,
    /// trajectory.csv, column by column in the layout's order, each read by its name.
    pub trajectory: Vec<Vec<f64>>,
    pub ticks: Ticks,
    /// The loops loops.csv flags as deadline misses, with their causes.
    pub misses: Vec<Miss>,
    pub faults: Vec<FaultMark>,
    pub summary: Summary,
    /// The figures over time show this window of simulation time, s (None: the whole run).
    pub window: Option<Range<f64>>,
}

impl RunData {
    pub fn read(run_dir: &Path, catalog: &Catalog) -> Result<Self, ToolError> {
        let folder = RunFolder::open(run_dir, &RUN_FILES)?;
        let (config, scenario) = folder.launch(catalog)?;
        let layout = VectorLayout::new(&config, scenario.as_ref());
        let columns = Columns::of(&layout);
        let summary = folder.summary()?;
        let table = folder.table(files::TRAJECTORY)?;
        let trajectory = layout.trajectory_columns().iter().map(|name| table.floats(name)).collect::<Result<_, _>>()?;
        let loops = folder.table(files::LOOPS)?;
        let ticks = Ticks {
            t: loops.floats("t_s")?,
            period_ns: loops.floats("tick_period_ns")?,
            deadline_miss: loops.floats("deadline_miss")?,
        };
        let misses = read_misses(&loops)?;
        let faults = summary
            .faults
            .iter()
            .map(|f| FaultMark { t: f.at_s, label: format!("{} {}", <&str>::from(f.kind), f.process) })
            .collect();
        Ok(RunData { config, scenario, layout, columns, trajectory, ticks, misses, faults, summary, window: None })
    }

    /// A figure of this run over simulation time `x`, titled "<the run's title>: <what>" (a
    /// declared system's by its launch file's own name, as the run was titled), with its faults
    /// marked.
    fn figure_over_time(&self, what: &str, panels: Vec<Panel>, x: Range<f64>) -> Figure {
        let title = format!("{}: {what}", self.summary.title);
        Figure {
            title,
            panels,
            x,
            x_desc: "t, s",
            faults: self.faults.clone(),
            faults_label: FAULTS_LABEL,
            caption: None,
        }
    }
}

impl RunColumns for RunData {
    fn config(&self) -> &LaunchConfig {
        &self.config
    }

    fn t(&self) -> &[f64] {
        &self.trajectory[1]
    }

    fn span(&self) -> Range<f64> {
        self.window.clone().unwrap_or(0.0..self.config.duration_s)
    }

    fn estimate(&self, name: &str) -> Option<&[f64]> {
        let i = self.layout.estimate.iter().position(|c| c.name == name)?;
        Some(&self.trajectory[self.columns.estimate.start + i])
    }

    fn state(&self, name: &str) -> Option<&[f64]> {
        let i = self.layout.state.iter().position(|c| c.name == name)?;
        Some(&self.trajectory[self.columns.state.start + i])
    }

    fn command(&self, name: &str) -> Option<&[f64]> {
        let i = self.layout.input.iter().position(|c| c.name == name)?;
        Some(&self.trajectory[self.columns.command.start + i])
    }
}

/// A component's unit as an axis reads it.
pub fn unit_desc(component: &Component) -> String {
    match component.unit {
        "1" => "dimensionless".into(),
        unit => unit.into(),
    }
}

/// The legend's name for the faults' markers in a run's figures.
const FAULTS_LABEL: &str = "fault injected";

/// The true state component an estimate component estimates: the same name, or the name with
/// a `_hat` (estimate) or `_prior` (a-priori estimate) suffix.
pub fn true_counterpart(estimate: &str, state: &[Component]) -> Option<(usize, &'static str)> {
    let base = estimate.strip_suffix("_hat").or_else(|| estimate.strip_suffix("_prior")).unwrap_or(estimate);
    state.iter().position(|s| s.name == base).map(|i| (i, state[i].name))
}

/// The value the launch file gives for an estimate-only component, if it gives one: a sensor's
/// bias for an estimated `bias`, where exactly one sensor has a non-zero bias.
fn known_value(data: &RunData, estimate: &str) -> Option<(String, f64)> {
    if estimate != "bias" {
        return None;
    }
    let biased: Vec<(&String, f64)> = data
        .config
        .sensors
        .iter()
        .filter(|(_, spec)| data.config.signal_of(spec).components.len() == 1)
        .map(|(name, spec)| (name, spec.bias.expand(1)[0]))
        .filter(|(_, bias)| *bias != 0.0)
        .collect();
    match biased[..] {
        [(name, bias)] => Some((format!("sensors.{name}.bias = {bias}"), bias)),
        _ => None,
    }
}

/// Truth against estimate, one panel per estimate component.
fn estimate_figure(data: &RunData) -> Figure {
    let t = data.t();
    let span = data.span();
    let vectors = data.scenario.vectors();
    let mut panels = Vec::new();
    for (i, component) in vectors.estimate.iter().enumerate() {
        let estimate = series(t, &data.trajectory[data.columns.estimate.start + i]);
        let mut curves = vec![Curve::new("estimate", estimate, Colour::Series(1), Line::Solid(2))];
        let title = match true_counterpart(component.name, &data.layout.state) {
            Some((s, name)) => {
                let truth = series(t, &data.trajectory[data.columns.state.start + s]);
                curves.push(Curve::new("truth", truth, Colour::Truth, Line::Solid(1)));
                if name == component.name {
                    component.name.to_string()
                } else {
                    format!("{} (truth: {name})", component.name)
                }
            }
            None => match known_value(data, component.name) {
                Some((label, value)) => {
                    curves.push(Curve::level("truth from the launch file", value, &span, Colour::Truth));
                    format!("{} (truth: {label})", component.name)
                }
                None => format!("{} (estimate only)", component.name),
            },
        };
        panels.push(Panel::new(title, unit_desc(component), curves));
    }
    data.figure_over_time("truth against estimate", panels, span)
}

/// Each input component over time: the commands as they came, with a gap wherever none came
/// (a stopped or dead controller, a lost command), and what the actuator applied (held, or
/// `on_stale`'s value) as steps beside them; the actuator's limits where they are reached.
pub fn commands_figure(data: &RunData) -> Figure {
    let t = data.t();
    let span = data.span();
    let dt = data.config.dt();
    let limits = data.scenario.input_limits();
    let panels = data
        .scenario
        .vectors()
        .input
        .iter()
        .enumerate()
        .map(|(i, component)| {
            // The commands thick, the applied steps thin over them: both stay visible where they
            // agree.
            let commands = runs(t, &data.trajectory[data.columns.command.start + i], dt);
            let mut curves: Vec<Curve> = commands
                .into_iter()
                .map(|run| Curve::new(COMMAND_LABEL, run, Colour::Series(0), Line::Solid(2)))
                .collect();
            curves.extend(
                applied_steps(data, i)
                    .into_iter()
                    .map(|run| Curve::new(APPLIED_LABEL, run, Colour::Series(1), Line::Solid(1))),
            );
            let mut panel = Panel::new(component.name, unit_desc(component), curves);
            if let Some((lo, hi)) = limits.get(i) {
                panel.bounds = vec![
                    Curve::level("limit", *lo, &span, Colour::Limit),
                    Curve::level("limit", *hi, &span, Colour::Limit),
                ];
            }
            panel
        })
        .collect();
    data.figure_over_time("commands and the applied input", panels, span)
}

/// Input component `i` as the actuator applied it, as steps, one run per stretch of rows that
/// have it (a row without the plant's state has none). Row k's value was applied over t(k−1) to
/// t(k), so it is drawn over that period; row 0's (the period before the run) is left out.
fn applied_steps(data: &RunData, i: usize) -> Vec<Vec<(f64, f64)>> {
    let dt = data.config.dt();
    let start: Vec<f64> = data.t().iter().skip(1).map(|t| t - dt).collect();
    let applied = data.trajectory[data.columns.applied.start + i].get(1..).unwrap_or(&[]);
    runs(&start, applied, 0.0)
        .into_iter()
        .map(|run| {
            let mut run = steps(&run);
            let &(end, value) = run.last().expect("a run has a value");
            run.push((end + dt, value));
            run
        })
        .collect()
}

/// The legend's names of the commands chart's curves: every run of commands has the first.
pub const COMMAND_LABEL: &str = "command (gaps: none came)";
pub const APPLIED_LABEL: &str = "applied by the actuator";

/// The time window of the sensors' figure: 25 samples of the slowest sensor (at least 50 ticks),
/// from the start, so that each hold's steps are wide enough to see.
fn sensor_window(config: &LaunchConfig) -> Range<f64> {
    let slowest = config.sensors.values().map(|s| s.period_s).fold(0.0, f64::max);
    let window = (25.0 * slowest).max(50.0 / config.rate_hz);
    0.0..window.min(config.duration_s)
}

/// Each sensor component's held value (steps) against the truth its signal reads.
fn sensors_figure(data: &RunData) -> Figure {
    let t = data.t();
    let vectors = data.scenario.vectors();
    let state = |row: usize| -> Vec<f64> { data.columns.state.clone().map(|c| data.trajectory[c][row]).collect() };
    let applied = |row: usize| -> Vec<f64> { data.columns.applied.clone().map(|c| data.trajectory[c][row]).collect() };
    let window = data.window.clone().unwrap_or_else(|| sensor_window(&data.config));
    let rows = t.iter().position(|t| *t >= window.start).unwrap_or(t.len())
        ..t.iter().take_while(|t| **t <= window.end).count();
    let mut panels = Vec::new();
    for ((name, _), columns) in data.layout.sensors.iter().zip(&data.columns.sensors) {
        let signal = vectors.signal(&data.config.sensors[name].signal).expect("sensor signals are checked at load");
        // The truth as the signal reads it: the true state and the input applied over the last
        // interval, as the sensors' process read it.
        let mut truth = vec![Vec::new(); columns.len()];
        let mut out = vec![0.0; columns.len()];
        for row in rows.clone() {
            let at = t[row];
            let applied: Vec<f64> = applied(row).into_iter().map(|u| if u.is_finite() { u } else { 0.0 }).collect();
            let x = state(row);
            if x.iter().all(|v| v.is_finite()) {
                signal.read.apply(at, &x, &applied, &mut out);
                truth.iter_mut().zip(&out).for_each(|(series, v)| series.push((at, *v)));
            }
        }
        for ((component, column), truth) in signal.components.iter().zip(columns.clone()).zip(truth) {
            let held = steps(&series(&t[rows.clone()], &data.trajectory[column][rows.clone()]));
            let spec = &data.config.sensors[name];
            let bias = spec.bias.expand(columns.len())[column - columns.start];
            let bias =
                if bias != 0.0 { format!(", bias {} {}", tick_label(&bias), component.unit) } else { String::new() };
            let title = format!("{name}: {} (every {}{bias})", component.name, seconds(spec.period_s));
            panels.push(Panel::new(
                title,
                unit_desc(component),
                vec![
                    Curve::new("held value", held, Colour::Series(0), Line::Solid(2)),
                    Curve::new("truth", truth, Colour::Truth, Line::Solid(1)),
                ],
            ));
        }
    }
    let zoom = if window.start > 0.0 {
        format!(", t = {} to {} of {}", seconds(window.start), seconds(window.end), seconds(data.config.duration_s))
    } else if window.end < data.config.duration_s {
        format!(", first {} of {}", seconds(window.end), seconds(data.config.duration_s))
    } else {
        String::new()
    };
    data.figure_over_time(&format!("sensors' held values against the truth{zoom}"), panels, window)
}

/// A declared system's state and output components over time, each against its `[reference]`
/// where it has one; None for a built-in scenario (its paper's figures say more).
fn outputs_figure(data: &RunData) -> Option<Figure> {
    if !data.config.is_declared() {
        return None;
    }
    let references = crate::model::reference::declared_references(&data.config).ok()?;
    let (t, span) = (data.t(), data.span());
    let panels = data
        .layout
        .state
        .iter()
        .enumerate()
        .map(|(i, component)| {
            let values = series(t, &data.trajectory[data.columns.state.start + i]);
            let mut curves = vec![Curve::new("the plant's value", values, Colour::Series(0), Line::Solid(2))];
            let tracked =
                references.iter().find(|r| r.track.split_once('.').map(|(_, name)| name) == Some(component.name));
            let title = match tracked {
                Some(reference) => {
                    let points: Vec<(f64, f64)> = t.iter().map(|&t| (t, reference.signal.at(t))).collect();
                    let hold = matches!(reference.signal, Signal::Table { between: Between::Hold, .. });
                    let points = if hold { steps(&points) } else { points };
                    curves.push(Curve::new("reference", points, Colour::Series(1), Line::Dashed));
                    format!("{} against its reference", reference.track)
                }
                None => component.name.to_string(),
            };
            Panel::new(title, unit_desc(component), curves)
        })
        .collect();
    Some(data.figure_over_time("state and outputs against the reference", panels, span))
}

/// The file of a declared system's state and outputs figure, in the run folder.
pub const OUTPUTS_FIGURE: &str = "outputs.png";

/// A duration for a title: "10 ms", "0.25 s".
fn seconds(s: f64) -> String {
    if s < 1.0 { format!("{} ms", tick_label(&(s * 1e3))) } else { format!("{} s", tick_label(&s)) }
}

/// The deadline misses loops.csv flags, as the tick-period figure counts them: the times of the
/// misses, and how many loops no monitor was up to record (around a monitor's restart: their
/// misses are in summary.json's count but not here). Ticks the plant skipped at the very end
/// have no row either, but they published nothing and so missed nothing.
pub fn tick_misses(ticks: &Ticks, summary: &Summary) -> (Vec<f64>, u64) {
    let misses = ticks.t.iter().zip(&ticks.deadline_miss).filter(|(_, miss)| **miss > 0.0).map(|(t, _)| *t).collect();
    (misses, summary.monitor.missing.missing_before_restart)
}

/// The tick-period panel's title: the misses as the report counts them.
pub fn tick_period_title(nominal_s: f64, misses: usize, loops: u64, unrecorded: u64) -> String {
    let share = misses as f64 * 100.0 / loops.max(1) as f64;
    let mut title =
        format!("period − nominal {} · {misses} deadline misses of {loops} loops ({share:.1} %)", seconds(nominal_s));
    if unrecorded > 0 {
        title.push_str(&format!(" · {unrecorded} loops unrecorded (no monitor)"));
    }
    title
}

/// The tick period error over time, deadline misses marked along the top of the panel, where
/// they show whatever the period did; None in lockstep (no schedule).
pub fn tick_period_figure(data: &RunData) -> Option<Figure> {
    if data.config.mode == Mode::Lockstep {
        return None;
    }
    let nominal_ns = data.config.period_ns() as f64;
    let (t, period) = (&data.ticks.t, &data.ticks.period_ns);
    // The first tick has no previous wake-up: its period is 0.
    let error: Vec<(f64, f64)> = t
        .iter()
        .zip(period)
        .filter(|(_, p)| p.is_finite() && **p > 0.0)
        .map(|(t, p)| (*t, (p - nominal_ns) / 1e3))
        .collect();
    let (misses, unrecorded) = tick_misses(&data.ticks, &data.summary);
    // A rug above the highest error: a miss is seen whatever the period did at it.
    let (lo, hi) = error.iter().fold((0.0f64, 0.0f64), |(lo, hi), (_, e)| (lo.min(*e), hi.max(*e)));
    let top = hi + ((hi - lo) * 0.06).max(1.0);
    let mut panel = Panel::new(
        tick_period_title(nominal_ns / 1e9, misses.len(), data.summary.loops, unrecorded),
        "tick period error, µs",
        vec![Curve::new("tick period error", error, Colour::Series(0), Line::Solid(1))],
    );
    panel.marks = misses.into_iter().map(|t| (t, top)).collect();
    Some(data.figure_over_time("the plant's tick period error (real time)", vec![panel], data.span()))
}

/// The file of the deadline misses' figure, in the run folder.
pub const MISSES_FIGURE: &str = "misses.png";

/// The misses figure's title: the deadline misses as the report and summary.json count them
/// (late, no command or a skipped tick), and how many of them loops.csv has no row for (around
/// a monitor's restart, or ticks skipped at the very end), which are not drawn.
pub fn misses_title(misses: u64, loops: u64, drawn: usize) -> String {
    if misses == 0 {
        return format!("no deadline misses in {loops} loops");
    }
    let share = misses as f64 * 100.0 / loops.max(1) as f64;
    let mut title = format!("{misses} deadline misses of {loops} loops ({share:.1} %), by cause");
    let unrecorded = misses.saturating_sub(drawn as u64);
    if unrecorded > 0 {
        title.push_str(&format!(" · {unrecorded} not drawn (no row in loops.csv)"));
    }
    title
}

/// Each deadline miss over the run, a cross in its cause's colour at its response time (tick
/// due to command at the plant), above the deadline; a miss with no response time (no command,
/// or a tick the plant skipped) along the top. None in lockstep (no deadline).
pub fn misses_figure(data: &RunData) -> Option<Figure> {
    let deadline_ms = data.summary.deadline_us? / 1e3;
    let response_ms = |m: &Miss| m.response_ns.map(|ns| ns as f64 / 1e6);
    // The row of misses without a response time: above every one that has one.
    let highest = data.misses.iter().filter_map(response_ms).fold(deadline_ms, f64::max);
    let top = highest * 1.15;
    let span = data.span();
    // The deadline is a curve, not a bound: it keeps the axis down to it when every miss is on
    // the top row.
    let mut curves = vec![Curve::level("deadline", deadline_ms, &span, Colour::Limit)];
    curves.extend(crosses_by_cause(&data.misses, |m| response_ms(m).unwrap_or(top)));
    let panel = Panel::new(
        "each miss at its response time; along the top: no command came, or the tick was skipped",
        "response time, ms",
        curves,
    );
    let title = misses_title(data.summary.deadline_misses, data.summary.loops, data.misses.len());
    Some(data.figure_over_time(&title, vec![panel], span))
}

/// The figures of a run folder, written into it: estimate.png, commands.png, sensors.png, a
/// declared system's outputs.png, in real time tick-period.png and misses.png, and
/// latency-cdf.png; the figures over time over `window` (s) where given. Returns the paths
/// written.
pub fn plot_run(run_dir: &Path, catalog: &Catalog, window: Option<Range<f64>>) -> Result<Vec<PathBuf>, ToolError> {
    let mut data = RunData::read(run_dir, catalog)?;
    if let Some(w) = &window
        && !(w.start >= 0.0 && w.start < w.end && w.start < data.config.duration_s)
    {
        let to = if w.end.is_finite() { format!("{} s", w.end) } else { "the end".into() };
        return Err(ToolError::BadInput(format!(
            "{}: --from {} s to {to}: the window must start within the run (0 to {} s) and end after it starts",
            run_dir.display(),
            w.start,
            data.config.duration_s
        )));
    }
    data.window = window.map(|w| w.start..w.end.min(data.config.duration_s));
    let mut written = Vec::new();
    let mut figures = vec![
        ("estimate.png", estimate_figure(&data)),
        ("commands.png", commands_figure(&data)),
        ("sensors.png", sensors_figure(&data)),
    ];
    figures.extend(outputs_figure(&data).map(|figure| (OUTPUTS_FIGURE, figure)));
    match tick_period_figure(&data) {
        Some(figure) => figures.push(("tick-period.png", figure)),
        None => {
            tell!("tick-period.png: not drawn, a lockstep run has no tick schedule (the plant waits for each command)")
        }
    }
    match misses_figure(&data) {
        Some(figure) => figures.push((MISSES_FIGURE, figure)),
        None => tell!("{MISSES_FIGURE}: not drawn, a lockstep run has no deadline"),
    }
    for (name, figure) in figures {
        let path = run_dir.join(name);
        figure.draw(&path)?;
        written.push(path);
    }
    written.push(latency::run_latency_figure(run_dir, &data.summary)?);
    let folder = RunFolder::open(run_dir, &RUN_FILES)?;
    written.extend(crate::tools::plot::fault_zoom::plot_faults(run_dir, &folder, data.scenario.as_ref(), &data)?);
    Ok(written)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn columns_lie_in_the_monitors_order() {
        let columns = Columns::of(&VectorLayout::example());
        // k, t, theta, omega, encoder's angle, imu's x and y, theta's estimate, u, applied u.
        assert_eq!(
            columns,
            Columns {
                state: 2..4,
                sensors: vec![4..5, 5..7],
                estimate: 7..8,
                command: 8..9,
                applied: 9..10,
                count: 10
            }
        );
    }

    #[test]
    fn estimates_find_their_truth_by_name() {
        let state = [Component::new("x", "m"), Component::new("theta", "rad"), Component::new("mass", "kg")];
        assert_eq!(true_counterpart("theta", &state), Some((1, "theta")));
        assert_eq!(true_counterpart("x_hat", &state), Some((0, "x")));
        assert_eq!(true_counterpart("x_prior", &state), Some((0, "x")));
        assert_eq!(true_counterpart("bias", &state), None);
    }

    #[test]
    fn the_misses_title_counts_them_as_the_report_does() {
        assert_eq!(misses_title(0, 1000, 0), "no deadline misses in 1000 loops");
        assert_eq!(misses_title(27, 1000, 27), "27 deadline misses of 1000 loops (2.7 %), by cause");
        assert_eq!(
            misses_title(30, 1000, 28),
            "30 deadline misses of 1000 loops (3.0 %), by cause · 2 not drawn (no row in loops.csv)"
        );
    }

    #[test]
    fn durations_in_titles() {
        assert_eq!(seconds(0.25), "250 ms");
        assert_eq!(seconds(3.0), "3 s");
    }
}
