//! The figure engine of `looplab plot` and `--paper`: draws a [`Figure`] (the description in
//! `model/figure.rs`) as PNG, panels on a grid under one title and one legend, with faults
//! marked on every time axis.

use std::ops::Range;
use std::path::Path;

use plotters::coord::Shift;
use plotters::coord::types::RangedCoordf64;
use plotters::prelude::*;

pub use crate::model::figure::{Colour, Curve, FaultMark, Figure, Line, Panel, series, steps};
use crate::tools::plot::{Canvas, FONT, PngBackend, colour, draw_png, plot_error};

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

/// The span of `panel`'s curves and marks over `x`, the figure's span (bounds do not widen it):
/// a figure of a window of the run is scaled to what it shows.
fn panel_range(panel: &Panel, x: &Range<f64>) -> Range<f64> {
    let points = panel.curves.iter().flat_map(|c| &c.points).chain(&panel.marks);
    y_range(points.filter(|p| p.0 >= x.start && p.0 <= x.end).map(|p| p.1))
}

/// The bounds that reach into `panel`'s range, the only ones drawn.
fn bounds_shown<'a>(panel: &'a Panel, x: &Range<f64>) -> impl Iterator<Item = &'a Curve> {
    let y = panel_range(panel, x);
    panel.bounds.iter().filter(move |c| c.points.iter().any(|p| y.contains(&p.1)))
}

/// The truth's look in every figure: a thin dark line drawn over the thicker estimate or held
/// value, so both stay visible where they agree.
const TRUTH: RGBColor = RGBColor(20, 20, 20);
/// The faults' markers.
pub const FAULT: RGBColor = RGBColor(200, 0, 0);
/// The actuator's limits.
const LIMIT: RGBColor = RGBColor(127, 127, 127);

/// A curve's colour in pixels.
pub fn rgb(colour_of: Colour) -> RGBColor {
    match colour_of {
        Colour::Series(i) => colour(i),
        Colour::Truth => TRUTH,
        Colour::Limit => LIMIT,
        Colour::Rgb(r, g, b) => RGBColor(r, g, b),
    }
}

/// Where a panel lies in the image, pixels: columns `x`, rows `y` (its title, axes and plot).
#[derive(Debug, Clone, PartialEq)]
pub struct Cell {
    pub x: Range<u32>,
    pub y: Range<u32>,
}

/// Columns of the grid: wide panels for a few, four across for many.
fn grid_columns(panels: usize) -> usize {
    match panels {
        0..=2 => 1,
        3..=4 => 2,
        5..=9 => 3,
        _ => 4,
    }
}

/// The size of a figure of `panels` panels (with a caption or not), and where each panel lies:
/// panels readable at the image's natural size, on the grid [`Figure::draw`] splits its body into.
pub fn grid(panels: usize, caption: bool) -> ((u32, u32), Vec<Cell>) {
    let columns = grid_columns(panels);
    let rows = panels.div_ceil(columns).max(1);
    let (w, h) = match (columns, rows) {
        (1, 1) => (1000, 460),
        (1, _) => (1000, 330),
        _ => (460, 280),
    };
    let size = (w * columns as u32, HEADER + h * rows as u32 + if caption { CAPTION } else { 0 });
    let cells = (0..panels)
        .map(|i| {
            let (row, column) = ((i / columns) as u32, (i % columns) as u32);
            Cell { x: column * w..(column + 1) * w, y: HEADER + row * h..HEADER + (row + 1) * h }
        })
        .collect();
    (size, cells)
}

/// Drawing a [`Figure`] (its description is the model's, in the stage SDK, which draws nothing).
pub trait Draw {
    /// The figure's size: panels readable at the image's natural size.
    fn size(&self) -> (u32, u32);
    /// Where each panel lies in the image.
    fn cells(&self) -> Vec<Cell>;
    fn draw(&self, path: &Path) -> anyhow::Result<()>;
}

impl Draw for Figure {
    fn size(&self) -> (u32, u32) {
        grid(self.panels.len(), self.caption.is_some()).0
    }

    fn cells(&self) -> Vec<Cell> {
        grid(self.panels.len(), self.caption.is_some()).1
    }

    fn draw(&self, path: &Path) -> anyhow::Result<()> {
        draw_png(path, self.size(), |root| draw_figure(self, root))
    }
}

/// `figure` on `root`: its title and legend, then its panels.
fn draw_figure(figure: &Figure, root: &Canvas<'_>) -> anyhow::Result<()> {
    let (header, body) = root.split_vertically(HEADER);
    draw_header(figure, &header)?;
    let body = match &figure.caption {
        Some(caption) => {
            let (body, bottom) = body.split_vertically(body.dim_in_pixel().1 - CAPTION);
            bottom.draw_text(caption, &(FONT, 17).into_font().color(&BLACK), (16, 8)).map_err(plot_error)?;
            body
        }
        None => body,
    };
    let columns = grid_columns(figure.panels.len());
    let rows = figure.panels.len().div_ceil(columns).max(1);
    for (area, panel) in body.split_evenly((rows, columns)).iter().zip(&figure.panels) {
        draw_panel(figure, area, panel)?;
    }
    Ok(())
}

/// The title and one legend for every panel (each panel has the same curves).
fn draw_header(figure: &Figure, area: &DrawingArea<PngBackend<'_>, Shift>) -> anyhow::Result<()> {
    // The largest size at which the title fits the figure's width.
    let width = area.dim_in_pixel().0 as i32 - 32;
    let mut size = 22.0;
    let fits = |size: f64| {
        area.estimate_text_size(&figure.title, &(FONT, size).into_font().color(&BLACK))
            .map(|(w, _)| w as i32 <= width)
            .unwrap_or(true)
    };
    while size > 12.0 && !fits(size) {
        size -= 1.0;
    }
    area.draw_text(&figure.title, &(FONT, size).into_font().color(&BLACK), (16, 8)).map_err(plot_error)?;
    let mut entries: Vec<(String, RGBColor, Line)> = Vec::new();
    for panel in &figure.panels {
        for c in panel.curves.iter().chain(bounds_shown(panel, &figure.x)) {
            if !entries.iter().any(|(label, ..)| *label == c.label) {
                entries.push((c.label.clone(), rgb(c.colour), c.line));
            }
        }
    }
    let any_marks = figure.panels.iter().any(|p| !p.marks.is_empty());
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
            Line::Dashed | Line::Crosses => colour.stroke_width(2),
        };
        entry(label, &|x| {
            if *line == Line::Crosses {
                area.draw(&Cross::new((x + 14, y), 5, style)).map_err(plot_error)
            } else if *line == Line::Dashed {
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
        entry("deadline miss", &|x| area.draw(&Cross::new((x + 14, y), 5, FAULT.stroke_width(2))).map_err(plot_error))?;
    }
    if figure.faults.iter().any(|f| figure.x.contains(&f.t)) {
        entry(figure.faults_label, &|x| {
            area.draw(&PathElement::new(vec![(x + 14, y - 9), (x + 14, y + 9)], FAULT.stroke_width(2)))
                .map_err(plot_error)
        })?;
    }
    Ok(())
}

fn draw_panel(figure: &Figure, area: &DrawingArea<PngBackend<'_>, Shift>, panel: &Panel) -> anyhow::Result<()> {
    let y = panel_range(panel, &figure.x);
    let mut chart = ChartBuilder::on(area)
        .caption(&panel.title, (FONT, 17))
        .margin(10)
        .margin_right(18)
        .x_label_area_size(40)
        .y_label_area_size(72)
        .build_cartesian_2d(figure.x.clone(), y.clone())
        .map_err(plot_error)?;
    chart
        .configure_mesh()
        .x_desc(figure.x_desc)
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
    for curve in bounds_shown(panel, &figure.x).chain(&panel.curves) {
        let points: Vec<(f64, f64)> =
            curve.points.iter().copied().filter(|p| p.0 >= figure.x.start && p.0 <= figure.x.end).collect();
        match curve.line {
            Line::Solid(width) => thick_line(area, &thin(points, POINTS_PER_CURVE), rgb(curve.colour), width)?,
            Line::Dashed => {
                let points = thin(points, POINTS_PER_CURVE);
                chart
                    .draw_series(DashedLineSeries::new(points, 8, 6, rgb(curve.colour).stroke_width(2)))
                    .map_err(plot_error)?;
            }
            // Events, not a signal: every one is drawn, where thinning would drop some.
            Line::Crosses => {
                let style = rgb(curve.colour).stroke_width(2);
                chart.draw_series(points.iter().map(|p| Cross::new(*p, 5, style))).map_err(plot_error)?;
            }
        }
    }
    chart.draw_series(panel.marks.iter().map(|p| Cross::new(*p, 5, FAULT.stroke_width(2)))).map_err(plot_error)?;
    let label_font = (FONT, 13).into_font().color(&FAULT);
    // Each label goes on the first line down where it overlaps no other label.
    let mut taken: Vec<Vec<Range<i32>>> = Vec::new();
    for fault in figure.faults.iter().filter(|f| figure.x.contains(&f.t)) {
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

/// A solid line `width` pixels wide, drawn as that many one-pixel lines side by side: plotters
/// fills a wide line as one polygon, which leaves holes where a noisy curve crosses itself.
fn thick_line(
    area: &DrawingArea<PngBackend<'_>, Cartesian2d<RangedCoordf64, RangedCoordf64>>,
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

/// Values beyond this magnitude (a simulation that diverged) are left out of a panel's range: an
/// axis spanning them would overflow, and the axis's tick search would never end.
const PLOTTABLE: f64 = 1e150;

/// The y range of a panel's values: their span with a margin, or a small one around a constant.
fn y_range(values: impl Iterator<Item = f64>) -> Range<f64> {
    let (lo, hi) = values
        .filter(|v| v.is_finite() && v.abs() < PLOTTABLE)
        .fold((f64::MAX, f64::MIN), |(lo, hi), v| (lo.min(v), hi.max(v)));
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
#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn thinning_keeps_each_buckets_extremes() {
        let points: Vec<(f64, f64)> = (0..12).map(|i| (i as f64, if i == 5 { 9.0 } else { 0.0 })).collect();
        // Buckets of 6: the first keeps its low and the spike, the second its first and last.
        assert_eq!(thin(points, 4), [(0.0, 0.0), (5.0, 9.0), (6.0, 0.0), (11.0, 0.0)]);
    }

    #[test]
    fn tick_labels_have_no_trailing_zeros() {
        assert_eq!(tick_label(&0.05), "0.05");
        assert_eq!(tick_label(&-2.0), "-2");
        assert_eq!(tick_label(&0.0), "0");
        assert_eq!(tick_label(&1.25), "1.25");
        assert_eq!(tick_label(&2e-6), "2.0e-6");
    }

    #[test]
    fn the_grid_holds_every_panel_inside_the_figure() {
        let ((w, h), cells) = grid(4, false);
        assert_eq!((w, h), (920, 624));
        assert_eq!(cells[3], Cell { x: 460..920, y: 344..624 });
        let ((w, h), cells) = grid(2, true);
        assert_eq!((w, h), (1000, 760));
        assert_eq!(cells[1], Cell { x: 0..1000, y: 394..724 });
    }
}
