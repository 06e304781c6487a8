//! `looplab plot RUN_DIR`: a run's figures, as PNG in the run folder: truth against estimate,
//! the commands, each sensor's held values against the truth it measures, and the tick period
//! error, with every fault marked on the time axis.
//!
//! The CSV files are read by column position from the launch file's layout (the order the
//! monitor writes: k, t, state, each sensor's components, estimate, command), never by header
//! name, so headers may carry units without breaking the figures.

use std::ops::Range;
use std::path::{Path, PathBuf};

use anyhow::{Context as _, anyhow};
use plotters::coord::Shift;
use plotters::coord::types::RangedCoordf64;
use plotters::prelude::*;

use crate::config::launch::{LaunchConfig, Mode};
use crate::config::schema::Component;
use crate::launcher::report::read_summary;
use crate::model::scenario::Scenario;
use crate::monitor::layout::Layout;
use crate::monitor::sinks::loops::column as loops_column;
use crate::scenarios;
use crate::tools::plot::{FONT, colour, latency, plot_error, png};
use crate::tools::{RUN_FILES, ToolError, check_run_folder};

/// Where each vector lies in trajectory.csv's columns.
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

/// A CSV file's data as columns of numbers, after checking the header's width; an empty cell
/// (a part that did not arrive) reads as NaN.
pub fn read_columns(text: &str, name: &str, count: usize) -> anyhow::Result<Vec<Vec<f64>>> {
    let mut lines = text.lines();
    let header = lines.next().ok_or_else(|| anyhow!("{name} is empty"))?;
    let found = header.split(',').count();
    if found != count {
        return Err(anyhow!("{name} has {found} columns, the launch file's run writes {count}"));
    }
    let mut columns = vec![Vec::new(); count];
    for (i, line) in lines.enumerate() {
        let cells: Vec<&str> = line.split(',').collect();
        if cells.len() != count {
            return Err(anyhow!("{name} line {}: {} cells, expected {count}", i + 2, cells.len()));
        }
        for (column, cell) in columns.iter_mut().zip(cells) {
            let value = if cell.is_empty() {
                f64::NAN
            } else {
                cell.parse().map_err(|e| anyhow!("{name} line {}: {cell:?}: {e}", i + 2))?
            };
            column.push(value);
        }
    }
    Ok(columns)
}

/// A vertical marker on every time axis: when a fault was injected, and what it was.
#[derive(Debug, Clone, PartialEq)]
pub struct FaultMark {
    pub t: f64,
    /// Its kind and target: "kill estimator".
    pub label: String,
}

/// A run folder, read.
pub struct RunData {
    pub config: LaunchConfig,
    pub scenario: Box<dyn Scenario>,
    pub layout: Layout,
    pub columns: Columns,
    /// trajectory.csv, column by column.
    pub trajectory: Vec<Vec<f64>>,
    /// loops.csv, column by column.
    pub loops: Vec<Vec<f64>>,
    pub faults: Vec<FaultMark>,
}

impl RunData {
    pub fn read(run_dir: &Path) -> Result<Self, ToolError> {
        let shown = run_dir.display();
        let bad = |why: String| ToolError::BadInput(format!("{shown}: {why}"));
        check_run_folder(run_dir, &RUN_FILES)?;
        let (config, scenario) =
            scenarios::load_resolved(&run_dir.join("launch.toml")).map_err(|e| bad(e.to_string()))?;
        let layout = Layout::new(&config, scenario.as_ref());
        let columns = Columns::of(&layout);
        let summary = read_summary(run_dir).map_err(|e| ToolError::BadInput(format!("{e:#}")))?;
        let read =
            |name: &str| std::fs::read_to_string(run_dir.join(name)).with_context(|| format!("read {shown}/{name}"));
        let trajectory =
            read_columns(&read("trajectory.csv")?, "trajectory.csv", columns.count).map_err(|e| bad(e.to_string()))?;
        let loops =
            read_columns(&read("loops.csv")?, "loops.csv", loops_column::COUNT).map_err(|e| bad(e.to_string()))?;
        let faults = summary
            .faults
            .iter()
            .map(|f| FaultMark { t: f.at_s, label: format!("{} {}", <&str>::from(f.kind), f.process) })
            .collect();
        Ok(RunData { config, scenario, layout, columns, trajectory, loops, faults })
    }

    pub fn t(&self) -> &[f64] {
        &self.trajectory[1]
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

    /// The estimate component of this name, as a column.
    pub fn estimate(&self, name: &str) -> Option<&[f64]> {
        let i = self.layout.estimate.iter().position(|c| c.name == name)?;
        Some(&self.trajectory[self.columns.estimate.start + i])
    }

    /// The true state component of this name, as a column.
    pub fn state(&self, name: &str) -> Option<&[f64]> {
        let i = self.layout.state.iter().position(|c| c.name == name)?;
        Some(&self.trajectory[self.columns.state.start + i])
    }

    /// The command component of this name, as a column.
    pub fn command(&self, name: &str) -> Option<&[f64]> {
        let i = self.layout.input.iter().position(|c| c.name == name)?;
        Some(&self.trajectory[self.columns.command.start + i])
    }

    /// The run's time span, s.
    pub fn span(&self) -> Range<f64> {
        0.0..self.config.duration_s
    }
}

/// (t, value) pairs, leaving out values that are not there (NaN: the part did not arrive).
pub fn series(t: &[f64], values: &[f64]) -> Vec<(f64, f64)> {
    t.iter().zip(values).filter(|(_, v)| v.is_finite()).map(|(t, v)| (*t, *v)).collect()
}

/// A held value drawn as steps: it keeps its value until the tick at which it changes, then
/// jumps there, so a zero-order hold reads as stairs and not as a ramp between samples.
pub fn steps(points: &[(f64, f64)]) -> Vec<(f64, f64)> {
    let mut out = Vec::with_capacity(points.len() * 2);
    for &(t, v) in points {
        if let Some(&(_, held)) = out.last()
            && held != v
        {
            out.push((t, held));
        }
        out.push((t, v));
    }
    out
}

/// At most about `max` points that keep each bucket's lowest and highest value, so a spike
/// stays visible when a long run is drawn at a figure's width.
pub fn thin(points: Vec<(f64, f64)>, max: usize) -> Vec<(f64, f64)> {
    let bucket = points.len().div_ceil(max / 2).max(1);
    if bucket <= 2 {
        return points;
    }
    let mut out = Vec::with_capacity(max + 2);
    for chunk in points.chunks(bucket) {
        let lowest = chunk.iter().enumerate().min_by(|a, b| a.1.1.total_cmp(&b.1.1)).map(|(i, _)| i).unwrap_or(0);
        let highest = chunk.iter().enumerate().max_by(|a, b| a.1.1.total_cmp(&b.1.1)).map(|(i, _)| i).unwrap_or(0);
        let (first, second) = if lowest <= highest { (lowest, highest) } else { (highest, lowest) };
        out.push(chunk[first]);
        if second != first {
            out.push(chunk[second]);
        }
    }
    out
}

/// A point count that a panel's width shows without losing anything.
const POINTS_PER_CURVE: usize = 3000;

/// How a curve is drawn.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Line {
    Solid(u32),
    Dashed,
}

/// One curve of a panel, and its legend entry's text.
pub struct Curve {
    pub label: String,
    pub points: Vec<(f64, f64)>,
    pub colour: RGBColor,
    pub line: Line,
}

impl Curve {
    pub fn new(label: impl Into<String>, points: Vec<(f64, f64)>, colour: RGBColor, line: Line) -> Self {
        Curve { label: label.into(), points, colour, line }
    }

    /// A horizontal line across the time span: a known value, a limit, a band's edge.
    pub fn level(label: impl Into<String>, y: f64, span: &Range<f64>, colour: RGBColor) -> Self {
        Curve::new(label, vec![(span.start, y), (span.end, y)], colour, Line::Dashed)
    }
}

/// One small chart: a title, the y axis's label (with its unit), its curves.
pub struct Panel {
    pub title: String,
    pub y_desc: String,
    pub curves: Vec<Curve>,
    /// Curves that do not widen the y range (limits): drawn only where the data reaches them.
    pub bounds: Vec<Curve>,
    /// Marks drawn as crosses (deadline misses).
    pub marks: Vec<(f64, f64)>,
}

impl Panel {
    /// The span of its curves and marks (bounds do not widen it).
    fn y_range(&self) -> Range<f64> {
        y_range(self.curves.iter().flat_map(|c| &c.points).chain(&self.marks).map(|p| p.1))
    }

    /// The bounds that reach into its range, the only ones drawn.
    fn bounds_shown(&self) -> impl Iterator<Item = &Curve> {
        let y = self.y_range();
        self.bounds.iter().filter(move |c| c.points.iter().any(|p| y.contains(&p.1)))
    }

    pub fn new(title: impl Into<String>, y_desc: impl Into<String>, curves: Vec<Curve>) -> Self {
        Panel { title: title.into(), y_desc: y_desc.into(), curves, bounds: vec![], marks: vec![] }
    }
}

/// A component's unit as an axis reads it.
pub fn unit_desc(component: &Component) -> String {
    match component.unit {
        "1" => "dimensionless".into(),
        unit => unit.into(),
    }
}

/// The truth's look in every figure: a thin dark line drawn over the thicker estimate or held
/// value, so both stay visible where they agree.
pub const TRUTH: RGBColor = RGBColor(20, 20, 20);
/// The faults' markers.
const FAULT: RGBColor = RGBColor(200, 0, 0);
/// The actuator's limits.
const LIMIT: RGBColor = RGBColor(127, 127, 127);
/// The legend's name for the faults' markers in a run's figures.
const FAULTS_LABEL: &str = "fault injected";

/// A figure: a title, one legend for all panels, and the panels on a grid sharing the time
/// span `x`, with every fault marked.
pub struct Figure {
    pub title: String,
    pub panels: Vec<Panel>,
    pub x: Range<f64>,
    pub x_desc: &'static str,
    pub faults: Vec<FaultMark>,
    /// What the vertical markers are, in the legend.
    pub faults_label: &'static str,
    /// A line under the panels (a paper's figure caption).
    pub caption: Option<String>,
}

impl Figure {
    /// Columns of the grid: wide panels for a few, four across for many.
    fn grid_columns(&self) -> usize {
        match self.panels.len() {
            0..=2 => 1,
            3..=4 => 2,
            5..=9 => 3,
            _ => 4,
        }
    }

    /// The figure's size: panels readable at the image's natural size.
    pub fn size(&self) -> (u32, u32) {
        let columns = self.grid_columns() as u32;
        let rows = self.panels.len().div_ceil(columns as usize).max(1) as u32;
        let (w, h) = match (columns, rows) {
            (1, 1) => (1000, 460),
            (1, _) => (1000, 330),
            _ => (460, 280),
        };
        (w * columns, HEADER + h * rows + if self.caption.is_some() { CAPTION } else { 0 })
    }

    pub fn draw(&self, path: &Path) -> anyhow::Result<()> {
        let root = png(path, self.size())?;
        let (header, body) = root.split_vertically(HEADER);
        self.draw_header(&header)?;
        let body = match &self.caption {
            Some(caption) => {
                let (body, bottom) = body.split_vertically(body.dim_in_pixel().1 - CAPTION);
                bottom.draw_text(caption, &(FONT, 17).into_font().color(&BLACK), (16, 8)).map_err(plot_error)?;
                body
            }
            None => body,
        };
        let columns = self.grid_columns();
        let rows = self.panels.len().div_ceil(columns).max(1);
        for (area, panel) in body.split_evenly((rows, columns)).iter().zip(&self.panels) {
            self.draw_panel(area, panel)?;
        }
        root.present().map_err(plot_error)
    }

    /// The title and one legend for every panel (each panel has the same curves).
    fn draw_header(&self, area: &DrawingArea<BitMapBackend<'_>, Shift>) -> anyhow::Result<()> {
        // The largest size at which the title fits the figure's width.
        let width = area.dim_in_pixel().0 as i32 - 32;
        let mut size = 22.0;
        let fits = |size: f64| {
            area.estimate_text_size(&self.title, &(FONT, size).into_font().color(&BLACK))
                .map(|(w, _)| w as i32 <= width)
                .unwrap_or(true)
        };
        while size > 12.0 && !fits(size) {
            size -= 1.0;
        }
        area.draw_text(&self.title, &(FONT, size).into_font().color(&BLACK), (16, 8)).map_err(plot_error)?;
        let mut entries: Vec<(String, RGBColor, Line)> = Vec::new();
        for panel in &self.panels {
            for c in panel.curves.iter().chain(panel.bounds_shown()) {
                if !entries.iter().any(|(label, ..)| *label == c.label) {
                    entries.push((c.label.clone(), c.colour, c.line));
                }
            }
        }
        let any_marks = self.panels.iter().any(|p| !p.marks.is_empty());
        let font = (FONT, 16).into_font().color(&BLACK);
        let mut x = 16;
        let y = 46;
        let mut entry = |label: &str, draw: &dyn Fn(i32) -> anyhow::Result<()>| -> anyhow::Result<()> {
            draw(x)?;
            area.draw_text(label, &font, (x + 34, y - 9)).map_err(plot_error)?;
            let (w, _) = area.estimate_text_size(label, &font).map_err(plot_error)?;
            x += 34 + w as i32 + 18;
            Ok(())
        };
        for (label, colour, line) in &entries {
            let style = match line {
                Line::Solid(w) => colour.stroke_width((*w).max(2)),
                Line::Dashed => colour.stroke_width(2),
            };
            entry(label, &|x| {
                if *line == Line::Dashed {
                    for s in [0, 11, 22] {
                        area.draw(&PathElement::new(vec![(x + s, y), (x + s + 6, y)], style)).map_err(plot_error)?;
                    }
                    Ok(())
                } else {
                    area.draw(&PathElement::new(vec![(x, y), (x + 28, y)], style)).map_err(plot_error)
                }
            })?;
        }
        if any_marks {
            entry("deadline miss", &|x| {
                area.draw(&Cross::new((x + 14, y), 5, FAULT.stroke_width(2))).map_err(plot_error)
            })?;
        }
        if self.faults.iter().any(|f| self.x.contains(&f.t)) {
            entry(self.faults_label, &|x| {
                area.draw(&PathElement::new(vec![(x + 14, y - 9), (x + 14, y + 9)], FAULT.stroke_width(2)))
                    .map_err(plot_error)
            })?;
        }
        Ok(())
    }

    fn draw_panel(&self, area: &DrawingArea<BitMapBackend<'_>, Shift>, panel: &Panel) -> anyhow::Result<()> {
        let y = panel.y_range();
        let mut chart = ChartBuilder::on(area)
            .caption(&panel.title, (FONT, 17))
            .margin(10)
            .margin_right(18)
            .x_label_area_size(40)
            .y_label_area_size(72)
            .build_cartesian_2d(self.x.clone(), y.clone())
            .map_err(plot_error)?;
        chart
            .configure_mesh()
            .x_desc(self.x_desc)
            .y_desc(&panel.y_desc)
            .x_labels(6)
            .y_labels(5)
            .label_style((FONT, 13))
            .axis_desc_style((FONT, 14))
            .light_line_style(WHITE.mix(0.0))
            .y_label_formatter(&|v| tick_label(&snap_to_zero(*v, &y)))
            .x_label_formatter(&tick_label)
            .draw()
            .map_err(plot_error)?;
        let area = &chart.plotting_area().clone();
        // Bounds first: a command at its limit stays visible over the limit's line.
        for curve in panel.bounds_shown().chain(&panel.curves) {
            let points: Vec<(f64, f64)> =
                curve.points.iter().copied().filter(|p| p.0 >= self.x.start && p.0 <= self.x.end).collect();
            let points = thin(points, POINTS_PER_CURVE);
            match curve.line {
                Line::Solid(width) => thick_line(area, &points, curve.colour, width)?,
                Line::Dashed => {
                    chart
                        .draw_series(DashedLineSeries::new(points, 8, 6, curve.colour.stroke_width(2)))
                        .map_err(plot_error)?;
                }
            }
        }
        chart.draw_series(panel.marks.iter().map(|p| Cross::new(*p, 5, FAULT.stroke_width(2)))).map_err(plot_error)?;
        let label_font = (FONT, 13).into_font().color(&FAULT);
        // Each label goes on the first line down where it overlaps no other label.
        let mut taken: Vec<Vec<Range<i32>>> = Vec::new();
        for fault in self.faults.iter().filter(|f| self.x.contains(&f.t)) {
            chart
                .draw_series(DashedLineSeries::new([(fault.t, y.start), (fault.t, y.end)], 6, 4, FAULT.stroke_width(2)))
                .map_err(plot_error)?;
            let (w, h) = area.estimate_text_size(&fault.label, &label_font).map_err(plot_error)?;
            let x = area.map_coordinate(&(fault.t, y.end)).0;
            let span = x..x + w as i32 + 8;
            let row = taken.iter().position(|r| r.iter().all(|o| o.end <= span.start || span.end <= o.start));
            let row = row.unwrap_or_else(|| {
                taken.push(Vec::new());
                taken.len() - 1
            });
            taken[row].push(span);
            let at = EmptyElement::at((fault.t, y.end));
            let offset = (4, 3 + (h as i32 + 4) * row as i32);
            let background =
                Rectangle::new([offset, (offset.0 + w as i32 + 2, offset.1 + h as i32 + 2)], WHITE.mix(0.85).filled());
            area.draw(&(at + background + Text::new(fault.label.clone(), offset, label_font.clone())))
                .map_err(plot_error)?;
        }
        Ok(())
    }
}

/// A solid line `width` pixels wide, drawn as that many one-pixel lines side by side: plotters
/// fills a wide line as one polygon, which leaves holes where a noisy curve crosses itself.
fn thick_line(
    area: &DrawingArea<BitMapBackend<'_>, Cartesian2d<RangedCoordf64, RangedCoordf64>>,
    points: &[(f64, f64)],
    colour: RGBColor,
    width: u32,
) -> anyhow::Result<()> {
    let flat = area.strip_coord_spec();
    let (bx, by) = flat.get_base_pixel();
    let mut pixels: Vec<(i32, i32)> = points
        .iter()
        .map(|p| {
            let (x, y) = area.map_coordinate(p);
            (x - bx, y - by)
        })
        .collect();
    pixels.dedup();
    let width = width.max(1) as i32;
    for dx in 0..width {
        for dy in 0..width {
            let shifted: Vec<(i32, i32)> = pixels.iter().map(|(x, y)| (x + dx, y + dy)).collect();
            flat.draw(&PathElement::new(shifted, colour.stroke_width(1))).map_err(plot_error)?;
        }
    }
    Ok(())
}

/// The figure's top: its title and the legend.
const HEADER: u32 = 64;
/// The caption's line under the panels.
const CAPTION: u32 = 36;

/// The y range of a panel's values: their span with a margin, or a small one around a constant.
fn y_range(values: impl Iterator<Item = f64>) -> Range<f64> {
    let (lo, hi) = values.filter(|v| v.is_finite()).fold((f64::MAX, f64::MIN), |(lo, hi), v| (lo.min(v), hi.max(v)));
    if lo > hi {
        return -1.0..1.0;
    }
    let span = hi - lo;
    let pad = if span > 1e-12 * hi.abs().max(lo.abs()).max(1e-300) { span * 0.08 } else { (hi.abs() * 0.1).max(1e-3) };
    lo - pad..hi + pad
}

/// A tick that is zero but for rounding (-1.1e-16 on an axis from -0.5 to 0.5) as zero.
fn snap_to_zero(v: f64, range: &Range<f64>) -> f64 {
    if v.abs() < (range.end - range.start) * 1e-9 { 0.0 } else { v }
}

/// A tick label with no trailing zeros: "0.05", "-2", "1.5e-6".
pub fn tick_label(v: &f64) -> String {
    let v = *v;
    if v == 0.0 {
        return "0".into();
    }
    let a = v.abs();
    if !(1e-3..1e6).contains(&a) {
        return format!("{v:.1e}");
    }
    let text = format!("{v:.6}");
    text.trim_end_matches('0').trim_end_matches('.').to_string()
}

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
        let mut curves = vec![Curve::new("estimate", estimate, colour(1), Line::Solid(2))];
        let title = match true_counterpart(component.name, &data.layout.state) {
            Some((s, name)) => {
                let truth = series(t, &data.trajectory[data.columns.state.start + s]);
                curves.push(Curve::new("truth", truth, TRUTH, Line::Solid(1)));
                if name == component.name {
                    component.name.to_string()
                } else {
                    format!("{} (truth: {name})", component.name)
                }
            }
            None => match known_value(data, component.name) {
                Some((label, value)) => {
                    curves.push(Curve::level("truth from the launch file", value, &span, TRUTH));
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
                vec![Curve::new("command", command, colour(0), Line::Solid(2))],
            );
            if let Some((lo, hi)) = limits.get(i) {
                panel.bounds = vec![Curve::level("limit", *lo, &span, LIMIT), Curve::level("limit", *hi, &span, LIMIT)];
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
                    Curve::new("held value", held, colour(0), Line::Solid(2)),
                    Curve::new("truth", truth, TRUTH, Line::Solid(1)),
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
    let t = &data.loops[1];
    let period = &data.loops[loops_column::TICK_PERIOD];
    // The first tick has no previous wake-up: its period is 0.
    let error: Vec<(f64, f64)> = t
        .iter()
        .zip(period)
        .filter(|(_, p)| p.is_finite() && **p > 0.0)
        .map(|(t, p)| (*t, (p - nominal_ns) / 1e3))
        .collect();
    let misses: Vec<(f64, f64)> = t
        .iter()
        .zip(&data.loops[loops_column::DEADLINE_MISS])
        .zip(period)
        .filter(|((_, miss), _)| **miss > 0.0)
        .map(|((t, _), p)| (*t, if p.is_finite() && *p > 0.0 { (p - nominal_ns) / 1e3 } else { 0.0 }))
        .collect();
    let mut panel = Panel::new(
        format!("period − nominal {}, {} deadline misses", seconds(nominal_ns / 1e9), misses.len()),
        "tick period error, µs",
        vec![Curve::new("tick period error", error, colour(0), Line::Solid(1))],
    );
    panel.marks = misses;
    Some(data.figure_over_time("the plant's tick period error (real time)", vec![panel], data.span()))
}

/// The figures of a run folder, written into it: estimate.png, commands.png, sensors.png, in real
/// time tick-period.png, and latency-cdf.png. Returns the paths written.
pub fn plot_run(run_dir: &Path) -> Result<Vec<PathBuf>, ToolError> {
    let data = RunData::read(run_dir)?;
    let mut written = Vec::new();
    let mut figures = vec![
        ("estimate.png", estimate_figure(&data)),
        ("commands.png", commands_figure(&data)),
        ("sensors.png", sensors_figure(&data)),
    ];
    match tick_period_figure(&data) {
        Some(figure) => figures.push(("tick-period.png", figure)),
        None => eprintln!(
            "tick-period.png: not drawn, a lockstep run has no tick schedule (the plant waits for each command)"
        ),
    }
    for (name, figure) in figures {
        let path = run_dir.join(name);
        figure.draw(&path)?;
        written.push(path);
    }
    written.push(latency::run_latency_figure(run_dir)?);
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
    fn columns_are_read_by_position_whatever_the_headers_say() {
        let text = "k,t_s,theta_rad\n0,0,0.5\n1,0.001,\n";
        let columns = read_columns(text, "trajectory.csv", 3).unwrap();
        assert_eq!(columns[0], [0.0, 1.0]);
        assert_eq!(columns[1], [0.0, 0.001]);
        assert_eq!(columns[2][0], 0.5);
        assert!(columns[2][1].is_nan());
        let err = read_columns(text, "trajectory.csv", 4).unwrap_err().to_string();
        assert_eq!(err, "trajectory.csv has 3 columns, the launch file's run writes 4");
    }

    #[test]
    fn a_held_value_is_drawn_as_steps() {
        let held = [(0.0, 1.0), (0.1, 1.0), (0.2, 2.0), (0.3, 2.0), (0.4, 3.0)];
        assert_eq!(steps(&held), [(0.0, 1.0), (0.1, 1.0), (0.2, 1.0), (0.2, 2.0), (0.3, 2.0), (0.4, 2.0), (0.4, 3.0)]);
        assert_eq!(series(&[0.0, 0.1, 0.2], &[1.0, f64::NAN, 2.0]), [(0.0, 1.0), (0.2, 2.0)]);
    }

    #[test]
    fn thinning_keeps_each_buckets_extremes() {
        let points: Vec<(f64, f64)> = (0..12).map(|i| (i as f64, if i == 5 { 9.0 } else { 0.0 })).collect();
        // Buckets of 6: the first keeps its low and the spike, the second its first and last.
        assert_eq!(thin(points, 4), [(0.0, 0.0), (5.0, 9.0), (6.0, 0.0), (11.0, 0.0)]);
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
    fn tick_labels_have_no_trailing_zeros() {
        assert_eq!(tick_label(&0.05), "0.05");
        assert_eq!(tick_label(&-2.0), "-2");
        assert_eq!(tick_label(&0.0), "0");
        assert_eq!(tick_label(&1.25), "1.25");
        assert_eq!(tick_label(&2e-6), "2.0e-6");
        assert_eq!(seconds(0.25), "250 ms");
        assert_eq!(seconds(3.0), "3 s");
    }
}
