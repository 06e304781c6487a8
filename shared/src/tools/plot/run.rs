//! `looplab plot RUN_DIR`: a run's figures, as PNG in the run folder: truth against estimate,
//! the commands, each sensor's held values against the truth it measures, and the tick period
//! error, with every fault marked on the time axis.
//!
//! The CSV files are read by column name through the run folder's reader, the names a run of
//! the launch file writes (`Layout::trajectory_columns`, `loops::columns`).

use std::ops::Range;
use std::path::{Path, PathBuf};

use crate::config::launch::{LaunchConfig, Mode};
use crate::config::schema::Component;
use crate::model::catalog::Catalog;
use crate::model::figure::RunColumns;
use crate::model::scenario::Scenario;
use crate::monitor::layout::Layout;
use crate::tools::plot::figure::{Colour, Curve, FaultMark, Figure, Line, Panel, series, steps, tick_label};
use crate::tools::plot::latency;
use crate::tools::run_folder::RunFolder;
use crate::tools::{RUN_FILES, ToolError};

/// Where each vector lies among trajectory.csv's columns, in the layout's order (the order the
/// monitor writes them: k, t, state, each sensor's components, estimate, command).
#[derive(Debug, Clone, PartialEq)]
pub struct Columns {
    pub state: Range<usize>,
    /// Per sensor, in the layout's order.
    pub sensors: Vec<Range<usize>>,
    pub estimate: Range<usize>,
    pub command: Range<usize>,
    pub count: usize,
}

impl Columns {
    pub fn of(layout: &Layout) -> Self {
        let mut next = 2;
        let mut take = |n: usize| {
            next += n;
            next - n..next
        };
        let state = take(layout.state.len());
        let sensors = layout.sensor_dims().into_iter().map(&mut take).collect();
        let estimate = take(layout.estimate.len());
        let command = take(layout.input.len());
        Columns { state, sensors, estimate, command, count: next }
    }
}

/// The plant's ticks, from loops.csv.
pub struct Ticks {
    pub t: Vec<f64>,
    /// Time since the previous wake-up, ns (0 on the first tick).
    pub period_ns: Vec<f64>,
    /// 1 where the loop missed its deadline.
    pub deadline_miss: Vec<f64>,
}

/// A run folder, read.
pub struct RunData {
    pub config: LaunchConfig,
    pub scenario: Box<dyn Scenario>,
    pub layout: Layout,
    pub columns: Columns,
    /// trajectory.csv, column by column in the layout's order, each read by its name.
    pub trajectory: Vec<Vec<f64>>,
    pub ticks: Ticks,
    pub faults: Vec<FaultMark>,
}

impl RunData {
    pub fn read(run_dir: &Path, catalog: &Catalog) -> Result<Self, ToolError> {
        let folder = RunFolder::open(run_dir, &RUN_FILES)?;
        let (config, scenario) = folder.launch(catalog)?;
        let layout = Layout::new(&config, scenario.as_ref());
        let columns = Columns::of(&layout);
        let summary = folder.summary()?;
        let table = folder.table("trajectory.csv")?;
        let trajectory = layout.trajectory_columns().iter().map(|name| table.floats(name)).collect::<Result<_, _>>()?;
        let loops = folder.table("loops.csv")?;
        let ticks = Ticks {
            t: loops.floats("t_s")?,
            period_ns: loops.floats("tick_period_ns")?,
            deadline_miss: loops.floats("deadline_miss")?,
        };
        let faults = summary
            .faults
            .iter()
            .map(|f| FaultMark { t: f.at_s, label: format!("{} {}", <&str>::from(f.kind), f.process) })
            .collect();
        Ok(RunData { config, scenario, layout, columns, trajectory, ticks, faults })
    }

    /// A figure of this run over simulation time `x`, titled "<scenario>: <what>", with its faults
    /// marked.
    fn figure_over_time(&self, what: &str, panels: Vec<Panel>, x: Range<f64>) -> Figure {
        let title = format!("{}: {what}", self.scenario.title());
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

/// Each command component over time, with the actuator's limits where the command reaches them.
fn commands_figure(data: &RunData) -> Figure {
    let t = data.t();
    let span = data.span();
    let limits = data.scenario.input_limits();
    let panels = data
        .scenario
        .vectors()
        .input
        .iter()
        .enumerate()
        .map(|(i, component)| {
            let command = series(t, &data.trajectory[data.columns.command.start + i]);
            let mut panel = Panel::new(
                component.name,
                unit_desc(component),
                vec![Curve::new("command", command, Colour::Series(0), Line::Solid(2))],
            );
            if let Some((lo, hi)) = limits.get(i) {
                panel.bounds = vec![
                    Curve::level("limit", *lo, &span, Colour::Limit),
                    Curve::level("limit", *hi, &span, Colour::Limit),
                ];
            }
            panel
        })
        .collect();
    data.figure_over_time("commands", panels, span)
}

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
    let command = |row: usize| -> Vec<f64> { data.columns.command.clone().map(|c| data.trajectory[c][row]).collect() };
    let window = sensor_window(&data.config);
    let rows = t.iter().take_while(|t| **t <= window.end).count();
    let mut panels = Vec::new();
    for ((name, _), columns) in data.layout.sensors.iter().zip(&data.columns.sensors) {
        let signal = vectors.signal(&data.config.sensors[name].signal).expect("sensor signals are checked at load");
        // The truth as the signal reads it: the true state and the input applied over the last
        // interval (the previous tick's command).
        let mut truth = vec![Vec::new(); columns.len()];
        let mut out = vec![0.0; columns.len()];
        for (row, &at) in t.iter().enumerate().take(rows) {
            let applied = if row == 0 { vec![0.0; data.columns.command.len()] } else { command(row - 1) };
            let applied: Vec<f64> = applied.into_iter().map(|u| if u.is_finite() { u } else { 0.0 }).collect();
            let x = state(row);
            if x.iter().all(|v| v.is_finite()) {
                (signal.read)(at, &x, &applied, &mut out);
                truth.iter_mut().zip(&out).for_each(|(series, v)| series.push((at, *v)));
            }
        }
        for ((component, column), truth) in signal.components.iter().zip(columns.clone()).zip(truth) {
            let held = steps(&series(&t[..rows], &data.trajectory[column][..rows]));
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
    let zoom = if window.end < data.config.duration_s {
        format!(", first {} of {}", seconds(window.end), seconds(data.config.duration_s))
    } else {
        String::new()
    };
    data.figure_over_time(&format!("sensors' held values against the truth{zoom}"), panels, window)
}

/// A duration for a title: "10 ms", "0.25 s".
fn seconds(s: f64) -> String {
    if s < 1.0 { format!("{} ms", tick_label(&(s * 1e3))) } else { format!("{} s", tick_label(&s)) }
}

/// The tick period error over time, deadline misses marked; None in lockstep (no schedule).
fn tick_period_figure(data: &RunData) -> Option<Figure> {
    if data.config.mode == Mode::Lockstep {
        return None;
    }
    let nominal_ns = 1e9 / data.config.rate_hz;
    let (t, period) = (&data.ticks.t, &data.ticks.period_ns);
    // The first tick has no previous wake-up: its period is 0.
    let error: Vec<(f64, f64)> = t
        .iter()
        .zip(period)
        .filter(|(_, p)| p.is_finite() && **p > 0.0)
        .map(|(t, p)| (*t, (p - nominal_ns) / 1e3))
        .collect();
    let misses: Vec<(f64, f64)> = t
        .iter()
        .zip(&data.ticks.deadline_miss)
        .zip(period)
        .filter(|((_, miss), _)| **miss > 0.0)
        .map(|((t, _), p)| (*t, if p.is_finite() && *p > 0.0 { (p - nominal_ns) / 1e3 } else { 0.0 }))
        .collect();
    let mut panel = Panel::new(
        format!("period − nominal {}, {} deadline misses", seconds(nominal_ns / 1e9), misses.len()),
        "tick period error, µs",
        vec![Curve::new("tick period error", error, Colour::Series(0), Line::Solid(1))],
    );
    panel.marks = misses;
    Some(data.figure_over_time("the plant's tick period error (real time)", vec![panel], data.span()))
}

/// The figures of a run folder, written into it: estimate.png, commands.png, sensors.png, in real
/// time tick-period.png, and latency-cdf.png. Returns the paths written.
pub fn plot_run(run_dir: &Path, catalog: &Catalog) -> Result<Vec<PathBuf>, ToolError> {
    let data = RunData::read(run_dir, catalog)?;
    let mut written = Vec::new();
    let mut figures = vec![
        ("estimate.png", estimate_figure(&data)),
        ("commands.png", commands_figure(&data)),
        ("sensors.png", sensors_figure(&data)),
    ];
    match tick_period_figure(&data) {
        Some(figure) => figures.push(("tick-period.png", figure)),
        None => {
            tell!("tick-period.png: not drawn, a lockstep run has no tick schedule (the plant waits for each command)")
        }
    }
    for (name, figure) in figures {
        let path = run_dir.join(name);
        figure.draw(&path)?;
        written.push(path);
    }
    written.push(latency::run_latency_figure(run_dir)?);
    let folder = RunFolder::open(run_dir, &RUN_FILES)?;
    written.extend(crate::tools::plot::fault_zoom::plot_faults(run_dir, &folder, data.scenario.as_ref(), &data)?);
    Ok(written)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn columns_lie_in_the_monitors_order() {
        let columns = Columns::of(&Layout::example());
        // k, t, theta, omega, encoder's angle, imu's x and y, theta's estimate, u.
        assert_eq!(
            columns,
            Columns { state: 2..4, sensors: vec![4..5, 5..7], estimate: 7..8, command: 8..9, count: 9 }
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
    fn durations_in_titles() {
        assert_eq!(seconds(0.25), "250 ms");
        assert_eq!(seconds(3.0), "3 s");
    }
}
