//! A figure as data: panels of curves over one shared x axis, with vertical markers. A scenario
//! describes its paper's figures with these types beside its entry (scenarios sit below the
//! tools and cannot draw); `tools/plot/figure.rs` draws them with plotters.

use std::ops::Range;

use crate::config::launch::LaunchConfig;

/// A vertical marker on every time axis: when a fault was injected, and what it was.
#[derive(Debug, Clone, PartialEq)]
pub struct FaultMark {
    pub t: f64,
    /// Its kind and target: "kill estimator".
    pub label: String,
}

/// A curve's colour, named by its role; the drawing picks the pixels.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Colour {
    /// The colour of series `i` (matplotlib's first seven, which readers of papers know).
    Series(usize),
    /// The truth: a thin dark line drawn over the thicker estimate or held value, so both stay
    /// visible where they agree.
    Truth,
    /// An actuator's limits.
    Limit,
    /// A colour of a map the tool keeps itself (a deadline miss's cause: `tools/plot/misses.rs`).
    Rgb(u8, u8, u8),
}

/// How a curve is drawn.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Line {
    Solid(u32),
    Dashed,
    /// Each point a cross, not joined: events (deadline misses), not a signal.
    Crosses,
}

/// One curve of a panel, and its legend entry's text.
#[derive(Debug, Clone, PartialEq)]
pub struct Curve {
    pub label: String,
    pub points: Vec<(f64, f64)>,
    pub colour: Colour,
    pub line: Line,
}

impl Curve {
    pub fn new(label: impl Into<String>, points: Vec<(f64, f64)>, colour: Colour, line: Line) -> Self {
        Curve { label: label.into(), points, colour, line }
    }

    /// A horizontal line across the time span: a known value, a limit, a band's edge.
    pub fn level(label: impl Into<String>, y: f64, span: &Range<f64>, colour: Colour) -> Self {
        Curve::new(label, vec![(span.start, y), (span.end, y)], colour, Line::Dashed)
    }
}

/// One small chart: a title, the y axis's label (with its unit), its curves.
#[derive(Debug, Clone, PartialEq)]
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
    pub fn new(title: impl Into<String>, y_desc: impl Into<String>, curves: Vec<Curve>) -> Self {
        Panel { title: title.into(), y_desc: y_desc.into(), curves, bounds: vec![], marks: vec![] }
    }
}

/// A figure: a title, one legend for all panels, and the panels on a grid sharing the x span,
/// with every fault marked.
#[derive(Debug, Clone, PartialEq)]
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

/// (t, value) pairs, leaving out values that are not there (NaN: the part did not arrive).
pub fn series(t: &[f64], values: &[f64]) -> Vec<(f64, f64)> {
    t.iter().zip(values).filter(|(_, v)| v.is_finite()).map(|(t, v)| (*t, *v)).collect()
}

/// (t, value) pairs split where a value is not there (NaN: the part did not arrive), one run per
/// stretch of values: a line drawn through each run leaves a gap where none came, not a ramp
/// across it. A lone value becomes a level `hold` long (a command holds for one period), so it
/// stays visible.
pub fn runs(t: &[f64], values: &[f64], hold: f64) -> Vec<Vec<(f64, f64)>> {
    let mut out: Vec<Vec<(f64, f64)>> = Vec::new();
    let mut run: Vec<(f64, f64)> = Vec::new();
    for (&t, &v) in t.iter().zip(values).chain([(&f64::NAN, &f64::NAN)]) {
        if v.is_finite() {
            run.push((t, v));
            continue;
        }
        match run[..] {
            [] => {}
            [(t, v)] => out.push(vec![(t, v), (t + hold, v)]),
            _ => out.push(std::mem::take(&mut run)),
        }
        run.clear();
    }
    out
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

/// A finished run's columns by the names of the scenario's vectors, as the tools read them from
/// its run folder; NaN where a part did not arrive.
pub trait RunColumns {
    /// The run's resolved launch file.
    fn config(&self) -> &LaunchConfig;
    /// Simulation time of each row, s.
    fn t(&self) -> &[f64];
    /// The true state component of this name.
    fn state(&self, name: &str) -> Option<&[f64]>;
    /// The estimate component of this name.
    fn estimate(&self, name: &str) -> Option<&[f64]>;
    /// The command component of this name.
    fn command(&self, name: &str) -> Option<&[f64]>;

    /// The run's time span, s.
    fn span(&self) -> Range<f64> {
        0.0..self.config().duration_s
    }
}

/// Where a paper case's launch file comes from.
#[derive(Debug, Clone, Copy)]
pub enum PaperTarget {
    /// The scenario's built-in defaults.
    Scenario(&'static str),
    /// A launch file of the repository, compiled in so that the command works anywhere: (its
    /// file's name, its text).
    File(&'static str, &'static str),
}

/// One run of a paper's experiment.
#[derive(Debug, Clone, Copy)]
pub struct PaperCase {
    /// Its run folder's name under the output folder.
    pub name: &'static str,
    pub target: PaperTarget,
    /// Overrides on top of the launch file (every case runs in lockstep).
    pub overrides: &'static [&'static str],
}

/// A figure and its file's name.
pub type NamedFigure = (&'static str, Figure);

/// A scenario's paper figures: the runs behind them, and how they are drawn from those runs
/// (given in the cases' order).
pub struct PaperFigures {
    pub cases: &'static [PaperCase],
    pub draw: fn(&[&dyn RunColumns]) -> anyhow::Result<Vec<NamedFigure>>,
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_held_value_is_drawn_as_steps() {
        let held = [(0.0, 1.0), (0.1, 1.0), (0.2, 2.0), (0.3, 2.0), (0.4, 3.0)];
        assert_eq!(steps(&held), [(0.0, 1.0), (0.1, 1.0), (0.2, 1.0), (0.2, 2.0), (0.3, 2.0), (0.4, 2.0), (0.4, 3.0)]);
        assert_eq!(series(&[0.0, 0.1, 0.2], &[1.0, f64::NAN, 2.0]), [(0.0, 1.0), (0.2, 2.0)]);
    }

    #[test]
    fn values_that_did_not_come_split_a_line_into_runs() {
        let nan = f64::NAN;
        let t = [0.0, 1.0, 2.0, 3.0, 4.0, 5.0, 6.0, 7.0];
        assert_eq!(
            runs(&t, &[1.0, 2.0, nan, nan, 3.0, nan, 4.0, 5.0], 0.5),
            [vec![(0.0, 1.0), (1.0, 2.0)], vec![(4.0, 3.0), (4.5, 3.0)], vec![(6.0, 4.0), (7.0, 5.0)]]
        );
        assert!(runs(&t[..2], &[nan, nan], 0.5).is_empty());
    }
}
