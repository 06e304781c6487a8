//! Latency charts: distributions on log-log axes (bench, a run's figure, compare) and latency
//! against payload size (bench). A run's latencies are read from its loops.csv, through the run
//! folder's reader.

use std::path::{Path, PathBuf};

use anyhow::{Result, anyhow};
use plotters::coord::Shift;
use plotters::coord::combinators::{BindKeyPoints, LogCoord, WithKeyPoints};
use plotters::prelude::*;
use plotters::style::text_anchor::{HPos, Pos, VPos};

use crate::contract::report::{HOPS, Stats};
use crate::contract::run_format::files;
use crate::launcher::summary::Summary;
use crate::monitor::distribution::Distribution;
use crate::tools::ToolError;
use crate::tools::plot::{Canvas, FONT, colour, draw_png, legend_mark, plot_error};
use crate::tools::run_folder::{RunFolder, Table};

/// A series: its name and its samples in ns, sorted.
pub type Series = (String, Vec<u64>);

/// The sample of a loop whose state went out but whose command never reached the plant: not a
/// latency. It sorts after every latency and is left out of the percentiles and the curve (as
/// the report leaves it out), but kept in the series so that each view counts it beside them.
pub const MISSED: u64 = u64::MAX;

/// The name of the end-to-end series.
pub const END_TO_END: &str = "end to end";

/// The file a run's latency figure is written to, in the run folder.
pub const RUN_FIGURE: &str = "latency-cdf.png";

/// Every hop of [`HOPS`], as (name, from stamp, to stamp): from one process to the next
/// ("plant→sensors") and each stage's compute time ("sensors compute").
fn named_hops() -> impl Iterator<Item = (String, usize, usize)> {
    HOPS.iter().map(|(name, from, to)| (name.replace("_to_", "→").replace('_', " "), *from, *to))
}

/// Whether a series of [`latencies_from_loops`] is a hop from one process to the next (the
/// charts draw those and end to end; the stages' compute time is in compare's table).
pub fn is_transport(name: &str) -> bool {
    name.contains('→')
}

/// A run's latencies from its loops.csv, sorted, in ns: one series per hop of [`HOPS`] (each
/// stage's compute time, and receive − the previous process's publish), then end to end. Each is
/// over the loops whose command reached the plant (a loop record), as summary.json's; a loop
/// whose state went out but whose command never came is in end to end as [`MISSED`], counted
/// beside the latencies and never among them. A tick the plant skipped (no state: a deadline
/// miss too, but no loop ran) is in none.
///
/// loops.csv rather than latency.hlog: it has every loop's exact value, so the chart reaches
/// down to the single slowest loop; its percentiles are taken through the monitor's
/// [`Distribution`], so that they are the report's to the digit.
pub fn read_run_latencies(run_dir: &Path) -> Result<Vec<Series>, ToolError> {
    latencies_from_loops(&RunFolder::open(run_dir, &[files::LOOPS])?.table(files::LOOPS)?)
}

/// [`read_run_latencies`] on a loops.csv, read by column name.
pub fn latencies_from_loops(loops: &Table) -> Result<Vec<Series>, ToolError> {
    let hops: Vec<(String, usize, usize)> = named_hops().collect();
    let stamps = loops.stamps()?;
    let end_to_end = loops.column::<u64>("end_to_end_ns")?;
    let missed = loops.column::<u64>("deadline_miss")?;
    // A loop whose state went out has its tick's timing; a skipped tick has none.
    let ticked = loops.column::<u64>("tick_scheduled_ns")?;
    let mut samples: Vec<Vec<u64>> = vec![Vec::new(); hops.len() + 1];
    // A loop without a record has empty cells.
    for (row, end_to_end) in end_to_end.iter().enumerate() {
        let Some(end_to_end) = *end_to_end else {
            if missed[row] == Some(1) && ticked[row].is_some() {
                samples[hops.len()].push(MISSED);
            }
            continue;
        };
        for (series, (_, from, to)) in samples.iter_mut().zip(&hops) {
            let (Some(sent), Some(received)) = (stamps[*from][row], stamps[*to][row]) else {
                return Err(loops.error_at(row, "a loop with an end-to-end latency but not every stamp"));
            };
            // As the monitor counts a hop (monitor/join.rs).
            series.push(received.saturating_sub(sent));
        }
        samples[hops.len()].push(end_to_end);
    }
    let names = hops.into_iter().map(|(name, _, _)| name).chain([END_TO_END.to_owned()]);
    Ok(names
        .zip(samples)
        .map(|(name, mut s)| {
            s.sort_unstable();
            (name, s)
        })
        .collect())
}

/// The loops without a command ([`MISSED`]) among sorted samples.
pub fn missed_count(sorted: &[u64]) -> usize {
    sorted.len() - sorted.partition_point(|v| *v != MISSED)
}

/// The statistics of sorted samples as the report gives them: over the loops with a command
/// (those before the [`MISSED`] ones), through the monitor's [`Distribution`] (HDR percentiles
/// within the exact extremes), so that every view prints the report's numbers.
pub fn stats_of(sorted: &[u64]) -> Stats {
    let mut distribution = Distribution::default();
    sorted[..sorted.len() - missed_count(sorted)].iter().for_each(|ns| distribution.record(*ns));
    distribution.stats()
}

/// The run's deadline in ns (real time), from its summary.
pub fn deadline_ns(summary: &Summary) -> Option<u64> {
    summary.deadline_us.map(|us| (us * 1e3).round() as u64)
}

/// A run's latency chart as data: its title and series. An in-process run's hops are calls in
/// one thread, not IPC: only end to end is drawn, and the title says why.
pub fn run_latency_chart(loops: &Table, summary: &Summary, name: &str) -> Result<Panel, ToolError> {
    let mut series = latencies_from_loops(loops)?;
    let title = if summary.ran_in_process() {
        series.retain(|(name, _)| name == END_TO_END);
        format!("loop latency end to end · {name} · in one process: hops n/a (not IPC)")
    } else {
        series.retain(|(name, _)| is_transport(name) || name == END_TO_END);
        format!("loop latency per hop and end to end · {name}")
    };
    Ok(Panel { title, series, deadlines_ns: deadline_ns(summary).into_iter().collect() })
}

/// Writes the run's latency figure, `latency-cdf.png` in the run folder: per hop and end to end,
/// from loops.csv, with the deadline. Returns its path.
pub fn run_latency_figure(run_dir: &Path, summary: &Summary) -> Result<PathBuf, ToolError> {
    let loops = RunFolder::open(run_dir, &[files::LOOPS])?.table(files::LOOPS)?;
    let path = run_dir.join(RUN_FIGURE);
    let name = run_dir.canonicalize().ok().and_then(|d| d.file_name().map(|n| n.to_string_lossy().into_owned()));
    let chart = run_latency_chart(&loops, summary, name.as_deref().unwrap_or("run"))?;
    cdf(&path, &chart.title, &chart.series, &chart.deadlines_ns)?;
    Ok(path)
}

/// A latency as a legend shows it, to three significant digits: "4.12 µs", "20.3 µs", "143 µs",
/// "8.51 ms".
pub fn duration_label(ns: u64) -> String {
    let us = ns as f64 / 1e3;
    let ms = us / 1e3;
    match us {
        _ if us < 9.995 => format!("{us:.2} µs"),
        _ if us < 99.95 => format!("{us:.1} µs"),
        _ if us < 999.5 => format!("{us:.0} µs"),
        _ if ms < 9.995 => format!("{ms:.2} ms"),
        _ if ms < 99.95 => format!("{ms:.1} ms"),
        _ => format!("{ms:.0} ms"),
    }
}

/// A tick label on a log axis, whose ticks are 1, 2 or 5 (or any digit) times a power of ten:
/// as many decimals as the tick needs, "0.05", "0.5", "20", "2000".
fn tick_label(value: &f64) -> String {
    let decimals = if *value >= 1.0 { 0 } else { (-value.log10()).ceil() as usize };
    format!("{value:.decimals$}")
}

/// A share of the samples as a percentage: "10%", "0.1%", "0.001%".
fn share_label(share: &f64) -> String {
    format!("{}%", tick_label(&(share * 100.0)))
}

/// A payload size tick label in decimal units: "100 B", "10 kB", "1 MB".
fn bytes_label(bytes: &f64) -> String {
    match *bytes {
        b if b >= 1e6 => format!("{} MB", b / 1e6),
        b if b >= 1e3 => format!("{} kB", b / 1e3),
        b => format!("{b:.0} B"),
    }
}

/// Ticks for a log axis over `lo..hi`: labelled ("bold") at the fewest of powers of ten; 1, 2
/// and 5 times them; or every digit times them that gives at least four labels, so that labels
/// never crowd at the top of a decade (plotters labels 10, 20, ... 90, 100 and these overlap),
/// and a range within one decade still gets labels. Unlabelled grid lines at every digit.
/// Returns the labelled ticks, the grid lines and where the axis may start: the labelled tick at
/// or below `lo` when that is near (1, 2, 5: within a factor 2.5), else `lo`.
fn log_ticks(lo: f64, hi: f64) -> (Vec<f64>, Vec<f64>, f64) {
    let decades = lo.log10().floor() as i32 - 1..=hi.log10().ceil() as i32;
    let ticks = |mantissas: &[u32]| -> Vec<f64> {
        decades.clone().flat_map(|e| mantissas.iter().map(move |m| f64::from(*m) * 10f64.powi(e))).collect()
    };
    let within = |ticks: &[f64]| -> Vec<f64> { ticks.iter().copied().filter(|v| (lo..=hi).contains(v)).collect() };
    let every_digit = ticks(&[1, 2, 3, 4, 5, 6, 7, 8, 9]);
    let bold =
        [ticks(&[1]), ticks(&[1, 2, 5])].into_iter().find(|t| within(t).len() >= 4).unwrap_or(every_digit.clone());
    let below = bold.iter().copied().filter(|v| *v <= lo).fold(lo, |_, v| v);
    (within(&bold), within(&every_digit), if lo / below <= 2.5 { below } else { lo })
}

/// A log axis over `lo..hi` with [`log_ticks`]; with `from_tick`, it starts at the labelled tick
/// at or below `lo`, so that its first label is at its start.
fn log_axis(lo: f64, hi: f64, from_tick: bool) -> WithKeyPoints<LogCoord<f64>> {
    let lo = if from_tick { log_ticks(lo, hi).2 } else { lo };
    let (bold, light, _) = log_ticks(lo, hi);
    (lo..hi).log_scale().with_key_points(bold).with_light_points(light)
}

/// Text sizes of a chart, px.
#[derive(Clone, Copy)]
struct Sizes {
    caption: u32,
    text: u32,
}

const LARGE: Sizes = Sizes { caption: 20, text: 15 };
const SMALL: Sizes = Sizes { caption: 17, text: 13 };

/// The legend's height for `n` series: one line each.
fn legend_height(n: usize, sizes: Sizes) -> u32 {
    n as u32 * (sizes.text + 9) + 14
}

/// One chart of a figure of several: a title, its series and the deadlines to mark (ns).
pub struct Panel {
    pub title: String,
    pub series: Vec<Series>,
    pub deadlines_ns: Vec<u64>,
}

/// Latency distributions on log-log axes: for each series, the share of samples at or above each
/// latency, down to the single slowest (1/N). The tail reads downwards (1 %, 0.1 %, ...) instead
/// of being squeezed into the top of a linear CDF. A series of one value is a vertical line (a
/// floor). A series' loops without a command ([`MISSED`]) are not drawn: its shares are of the
/// loops with one, and its legend says how many had none. Each deadline is a dashed vertical
/// line. Below the chart, a legend with each series' p50, p99 and max.
pub fn cdf(path: &Path, title: &str, series: &[Series], deadlines_ns: &[u64]) -> Result<()> {
    draw_png(path, (900, 520 + legend_height(series.len(), LARGE)), |root| {
        draw_cdf(root, title, series, deadlines_ns, LARGE)
    })
}

/// Several [`cdf`] charts in one figure: the first across the whole width, the others below it,
/// two to a row.
pub fn cdf_panels(path: &Path, panels: &[Panel]) -> Result<()> {
    let Some((first, others)) = panels.split_first() else { return Err(anyhow!("a figure of no charts")) };
    let (width, half) = (1200, 600);
    let first_height = 540 + legend_height(first.series.len(), LARGE);
    let rows: Vec<(&[Panel], u32)> = others
        .chunks(2)
        .map(|row| (row, 360 + legend_height(row.iter().map(|p| p.series.len()).max().unwrap_or(0), SMALL)))
        .collect();
    draw_png(path, (width, first_height + rows.iter().map(|(_, h)| h).sum::<u32>()), |root| {
        let (top, mut rest) = root.split_vertically(first_height);
        draw_cdf(&top, &first.title, &first.series, &first.deadlines_ns, LARGE)?;
        for (row, height) in rows {
            let (this_row, below) = rest.split_vertically(height);
            let (left, right) = this_row.split_horizontally(half);
            for (panel, area) in row.iter().zip([left, right]) {
                draw_cdf(&area, &panel.title, &panel.series, &panel.deadlines_ns, SMALL)?;
            }
            rest = below;
        }
        Ok(())
    })
}

type Area<'a> = DrawingArea<crate::tools::plot::PngBackend<'a>, Shift>;

/// A series' points on the chart, (µs, share at or above), as steps: at most 2000 points, and
/// every point of the last 1 % (the tail). Shares are of the loops with a command, as the
/// percentiles are; the [`MISSED`] ones are left out.
pub fn cdf_points(samples: &[u64], floor_share: f64) -> Vec<(f64, f64)> {
    let us = |ns: u64| (ns as f64 / 1e3).max(0.01);
    let n = samples.len() - missed_count(samples);
    let share = |j: usize| (n - j) as f64 / n as f64;
    match n {
        0 => vec![],
        1 => vec![(us(samples[0]), floor_share), (us(samples[0]), 1.0)],
        _ => {
            let step = n.div_ceil(2000).max(1);
            let tail = n.saturating_sub(n.div_ceil(100));
            let kept: Vec<usize> = (0..tail).step_by(step).chain(tail..n).collect();
            let steps =
                kept.windows(2).flat_map(|w| [(us(samples[w[1]]), share(w[0])), (us(samples[w[1]]), share(w[1]))]);
            std::iter::once((us(samples[0]), 1.0)).chain(steps).collect()
        }
    }
}

fn draw_cdf(area: &Area, title: &str, series: &[Series], deadlines_ns: &[u64], sizes: Sizes) -> Result<()> {
    let (_, height) = area.dim_in_pixel();
    let (plot, legend) = area.split_vertically(height - legend_height(series.len(), sizes));
    let us = |ns: u64| (ns as f64 / 1e3).max(0.01);
    let finite = |s: &[u64]| s.len() - missed_count(s);
    let lo = series.iter().filter_map(|(_, s)| s.first().filter(|v| **v != MISSED)).map(|v| us(*v));
    let lo = lo.chain(deadlines_ns.iter().map(|d| us(*d))).fold(f64::MAX, f64::min);
    let hi = series.iter().filter_map(|(_, s)| s[..finite(s)].last()).map(|v| us(*v));
    let hi = hi.chain(deadlines_ns.iter().map(|d| us(*d))).fold(0.0, f64::max);
    // No samples at all: an empty chart over 1 to 10 µs.
    let (lo, hi) = if lo <= hi { (lo, hi) } else { (1.0, 10.0) };
    let most = series.iter().map(|(_, s)| finite(s)).max().unwrap_or(1).max(10) as f64;
    let floor_share = 0.8 / most;
    let mut chart = ChartBuilder::on(&plot)
        .caption(title, (FONT, sizes.caption))
        .margin(12)
        .x_label_area_size(sizes.text * 3)
        .y_label_area_size(sizes.text * 4 + 5)
        .build_cartesian_2d(log_axis(lo * 0.8, hi * 1.25, true), log_axis(floor_share, 1.0, false))
        .map_err(plot_error)?;
    chart
        .configure_mesh()
        .x_desc("latency, µs (log)")
        .y_desc("share at or above (log)")
        .label_style((FONT, sizes.text - 1))
        .axis_desc_style((FONT, sizes.text))
        .x_label_formatter(&tick_label)
        .y_label_formatter(&share_label)
        .draw()
        .map_err(plot_error)?;
    for (i, (_, samples)) in series.iter().enumerate() {
        let points = cdf_points(samples, floor_share);
        chart.draw_series(LineSeries::new(points, colour(i).stroke_width(2))).map_err(plot_error)?;
    }
    // Left of its line, which may be at the chart's right edge.
    let label_style = (FONT, sizes.text - 1).into_font().color(&BLACK).pos(Pos::new(HPos::Right, VPos::Top));
    for deadline in deadlines_ns {
        let x = us(*deadline);
        chart
            .draw_series(DashedLineSeries::new([(x, floor_share), (x, 1.0)], 6, 4, BLACK.stroke_width(1)))
            .map_err(plot_error)?;
        let text = format!("deadline {}", duration_label(*deadline));
        let label = EmptyElement::at((x, 1.0)) + Text::new(text, (-4, 3), label_style.clone());
        chart.draw_series(std::iter::once(label)).map_err(plot_error)?;
    }
    let left = plot.get_base_pixel().0 + (sizes.text * 4 + 5) as i32 + 12 - area.get_base_pixel().0;
    draw_legend(&legend, left, series, sizes)
}

/// What the legend says of a series after its name: p50, p99 and max as the report gives them
/// ([`stats_of`]), and, where some loops had no command, over how many loops they are and how
/// many had none.
pub fn legend_stats(samples: &[u64]) -> Vec<String> {
    let s = stats_of(samples);
    let label = |ns: Option<u64>| ns.map_or("-".into(), duration_label);
    let mut stats: Vec<String> = match s.count {
        0 => vec!["no samples".into()],
        1 => vec![label(s.max)],
        _ => vec![format!("p50 {}", label(s.p50)), format!("p99 {}", label(s.p99)), format!("max {}", label(s.max))],
    };
    let missed = missed_count(samples);
    if missed > 0 {
        stats.push(format!("over the {} loops with a command; {missed} had none", s.count));
    }
    stats
}

/// The legend below a chart, in columns: a line in the series' colour, its name, p50, p99, max.
/// Below the chart rather than on it, where it would hide a tail.
fn draw_legend(area: &Area, left: i32, series: &[Series], sizes: Sizes) -> Result<()> {
    let style = (FONT, sizes.text).into_font().color(&BLACK);
    let rows: Vec<(String, Vec<String>)> = series.iter().map(|(name, s)| (name.clone(), legend_stats(s))).collect();
    let width = |text: &str| area.estimate_text_size(text, &style).map(|(w, _)| w as i32).map_err(plot_error);
    let mut columns = vec![left + 30];
    let name_width =
        rows.iter().map(|(name, _)| width(name)).collect::<Result<Vec<_>>>()?.into_iter().max().unwrap_or(0);
    columns.push(columns[0] + name_width + 24);
    for c in 0..rows.iter().map(|(_, stats)| stats.len()).max().unwrap_or(0) {
        let cells = rows.iter().filter_map(|(_, stats)| stats.get(c).map(|s| width(s)));
        let column_width = cells.collect::<Result<Vec<_>>>()?.into_iter().max().unwrap_or(0);
        columns.push(columns.last().copied().unwrap_or(0) + column_width + 18);
    }
    for (i, (name, stats)) in rows.iter().enumerate() {
        let y = 8 + i as i32 * (sizes.text as i32 + 9);
        area.draw(&legend_mark(left, y + sizes.text as i32 / 2, colour(i))).map_err(plot_error)?;
        for (text, x) in std::iter::once(name).chain(stats).zip(&columns) {
            area.draw_text(text, &style, (*x, y)).map_err(plot_error)?;
        }
    }
    Ok(())
}

/// Median one-way latency against payload size, log-log: one curve per transport.
pub fn payload(path: &Path, series: &[(String, Vec<(usize, f64)>)]) -> Result<()> {
    draw_png(path, (900, 560), |root| draw_payload(root, series))
}

fn draw_payload(root: &Canvas<'_>, series: &[(String, Vec<(usize, f64)>)]) -> Result<()> {
    let xs = series.iter().flat_map(|(_, p)| p.iter().map(|(b, _)| *b as f64));
    let (x_lo, x_hi) = xs.fold((f64::MAX, 1.0f64), |(lo, hi), x| (lo.min(x), hi.max(x)));
    let ys = series.iter().flat_map(|(_, p)| p.iter().map(|(_, us)| *us));
    let (y_lo, y_hi) = ys.fold((f64::MAX, 1.0f64), |(lo, hi), y| (lo.min(y), hi.max(y)));
    let mut chart = ChartBuilder::on(root)
        .caption("one-way latency against payload size (median)", (FONT, 20))
        .margin(15)
        .x_label_area_size(45)
        .y_label_area_size(55)
        .build_cartesian_2d(log_axis(x_lo * 0.8, x_hi * 1.25, false), log_axis(y_lo.max(0.1) * 0.8, y_hi * 1.25, true))
        .map_err(plot_error)?;
    chart
        .configure_mesh()
        .x_desc("payload (log)")
        .y_desc("latency, µs (log)")
        .label_style((FONT, 14))
        .axis_desc_style((FONT, 15))
        .x_label_formatter(&bytes_label)
        .y_label_formatter(&tick_label)
        .draw()
        .map_err(plot_error)?;
    for (i, (name, points)) in series.iter().enumerate() {
        let colour = colour(i);
        let points: Vec<(f64, f64)> = points.iter().map(|(b, us)| (*b as f64, *us)).collect();
        chart
            .draw_series(LineSeries::new(points.clone(), colour.stroke_width(2)))
            .map_err(plot_error)?
            .label(name.clone())
            .legend(move |(x, y)| legend_mark(x, y, colour));
        chart.draw_series(points.into_iter().map(|p| Circle::new(p, 3, colour.filled()))).map_err(plot_error)?;
    }
    chart
        .configure_series_labels()
        .position(SeriesLabelPosition::UpperLeft)
        .label_font((FONT, 15))
        .background_style(WHITE.mix(0.8))
        .border_style(BLACK)
        .draw()
        .map_err(plot_error)?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn tick_labels_read_as_numbers_with_units() {
        assert_eq!(tick_label(&1000.0), "1000");
        assert_eq!(tick_label(&0.5), "0.5");
        assert_eq!(tick_label(&0.05), "0.05");
        assert_eq!(tick_label(&(3.0 * 0.1)), "0.3");
        assert_eq!(bytes_label(&64.0), "64 B");
        assert_eq!(bytes_label(&10000.0), "10 kB");
        assert_eq!(bytes_label(&1e6), "1 MB");
        assert_eq!(share_label(&1.0), "100%");
        assert_eq!(share_label(&0.01), "1%");
        assert_eq!(share_label(&0.001), "0.1%");
        assert_eq!(share_label(&0.0001), "0.01%");
        assert_eq!(share_label(&1e-7), "0.00001%");
    }

    #[test]
    fn log_ticks_label_the_fewest_that_give_four() {
        // Four decades: powers of ten only.
        assert_eq!(log_ticks(0.8, 12000.0).0, [1.0, 10.0, 100.0, 1000.0, 10000.0]);
        // Two decades: 1, 2 and 5 times them, never 90 beside 100.
        assert_eq!(log_ticks(8.0, 500.0).0, [10.0, 20.0, 50.0, 100.0, 200.0, 500.0]);
        // Within one decade, far below 10 µs: every digit.
        assert_eq!(
            log_ticks(0.25, 0.9).0.iter().map(tick_label).collect::<Vec<_>>(),
            ["0.3", "0.4", "0.5", "0.6", "0.7", "0.8", "0.9"]
        );
        assert_eq!(log_ticks(8.0, 500.0).1.len(), 2 + 9 + 5);
        // The axis then starts at the labelled tick below.
        assert_eq!(log_ticks(22.4, 1250.0).2, 20.0);
        assert_eq!(log_ticks(0.8, 12000.0).2, 0.8);
    }

    #[test]
    fn durations_keep_three_significant_digits() {
        assert_eq!(duration_label(431), "0.43 µs");
        assert_eq!(duration_label(4_126), "4.13 µs");
        assert_eq!(duration_label(9_996), "10.0 µs");
        assert_eq!(duration_label(20_303), "20.3 µs");
        assert_eq!(duration_label(143_359), "143 µs");
        assert_eq!(duration_label(999_600), "1.00 ms");
        assert_eq!(duration_label(8_513_516), "8.51 ms");
        assert_eq!(duration_label(12_345_678), "12.3 ms");
        assert_eq!(duration_label(1_234_567_890), "1235 ms");
    }

    #[test]
    fn loops_without_a_command_are_counted_beside_the_latencies_not_among_them() {
        // 8 loops got a command (1 to 8 µs), 2 never did.
        let mut samples: Vec<u64> = (1..=8).map(|us| us * 1000).collect();
        samples.extend([MISSED, MISSED]);
        assert_eq!(missed_count(&samples), 2);
        let points = cdf_points(&samples, 0.01);
        assert_eq!(points.first(), Some(&(1.0, 1.0)));
        // Shares of the 8 with a command: the slowest is the last 1 of 8.
        assert_eq!(points[points.len() - 2..], [(8.0, 0.25), (8.0, 0.125)]);
        // HDR's bucket of 4000 reports its highest value, as the report does.
        let s = stats_of(&samples);
        assert_eq!((s.count, s.p50, s.p99, s.max), (8, Some(4001), Some(8000), Some(8000)));
        assert_eq!(
            legend_stats(&samples),
            ["p50 4.00 µs", "p99 8.00 µs", "max 8.00 µs", "over the 8 loops with a command; 2 had none"]
        );
        // Every loop without a command: nothing to draw.
        assert_eq!(cdf_points(&[MISSED], 0.01), []);
        assert_eq!(legend_stats(&[MISSED]), ["no samples", "over the 0 loops with a command; 1 had none"]);
    }

    #[test]
    fn percentiles_are_the_reports() {
        // The monitor's histogram, to the digit: HDR buckets within the exact extremes.
        let samples: Vec<u64> = (1..=2000).map(|i| i * 997).collect();
        let mut d = Distribution::default();
        samples.iter().for_each(|ns| d.record(*ns));
        assert_eq!(stats_of(&samples), d.stats());
    }

    #[test]
    fn hops_come_from_the_stamps_of_loops_csv() {
        // k, t, 8 stamps, end to end, deadline miss, rejected, tick timing; loop 1 has no record
        // (and no flag: not known), loop 3 got no command, loop 4 was a skipped tick.
        let stamps: Vec<String> =
            crate::contract::msg::LoopTrace::STAMP_NAMES.iter().map(|s| format!("{s}_ns")).collect();
        let header =
            format!("k,t_s,{},end_to_end_ns,deadline_miss,rejected,tick_scheduled_ns,tw,tp\n", stamps.join(","));
        let text = header
            + "\
                    0,0,1000,1500,1600,2600,2700,4700,4800,9000,8000,0,0,900,950,0\n\
                    1,0.001,,,,,,,,,,,,1900,1950,1000\n\
                    2,0.002,3000,3100,3300,3400,3500,3600,3700,3800,800,0,0,2900,2950,1000\n\
                    3,0.003,,,,,,,,,,1,0,3900,3950,1000\n\
                    4,0.004,,,,,,,,,,1,0,,,\n";
        let series = latencies_from_loops(&Table::parse("loops.csv", &text).unwrap()).unwrap();
        let expected: Vec<Series> = vec![
            ("plant→sensors".into(), vec![100, 500]),
            ("sensors compute".into(), vec![100, 200]),
            ("sensors→estimator".into(), vec![100, 1000]),
            ("estimator compute".into(), vec![100, 100]),
            ("estimator→controller".into(), vec![100, 2000]),
            ("controller compute".into(), vec![100, 100]),
            ("controller→plant".into(), vec![100, 4200]),
            ("end to end".into(), vec![800, 8000, MISSED]),
        ];
        assert_eq!(series, expected);
        assert_eq!(
            legend_stats(&series[7].1),
            ["p50 0.80 µs", "p99 8.00 µs", "max 8.00 µs", "over the 2 loops with a command; 1 had none"]
        );
        let bad = Table::parse("loops.csv", &text.replacen("9000", "x", 1)).unwrap();
        let why = latencies_from_loops(&bad).unwrap_err().to_string();
        assert_eq!(
            why,
            "loops.csv line 2: column \"plant_receive_ns\": \"x\" is not a number (invalid digit found in string)"
        );
        let no_column = Table::parse("loops.csv", "k,t_s\n").unwrap();
        let why = latencies_from_loops(&no_column).unwrap_err().to_string();
        assert_eq!(why, "loops.csv has no column \"plant_publish_ns\"");
    }
}
