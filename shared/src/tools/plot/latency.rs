//! Latency charts: distributions on log-log axes (bench, plot, compare) and latency against
//! payload size (bench).

use std::path::Path;

use anyhow::Result;
use plotters::prelude::*;

use crate::tools::plot::{FONT, colour, legend_mark, plot_error, png};

/// A latency tick label in µs: whole numbers without a decimal point.
fn micros_label(us: &f64) -> String {
    if *us >= 1.0 { format!("{us:.0}") } else { format!("{us:.1}") }
}

/// A share of the samples as a percentage: "10%", "0.1%".
fn share_label(share: &f64) -> String {
    let percent = share * 100.0;
    if percent >= 1.0 {
        format!("{percent:.0}%")
    } else {
        format!("{}%", format!("{percent:.4}").trim_end_matches('0'))
    }
}

/// A payload size tick label in decimal units, as the log axis ticks at powers of ten:
/// "100 B", "10 kB", "1 MB".
fn bytes_label(bytes: &f64) -> String {
    match *bytes {
        b if b >= 1e6 => format!("{} MB", b / 1e6),
        b if b >= 1e3 => format!("{} kB", b / 1e3),
        b => format!("{b:.0} B"),
    }
}

/// Latency distributions on log-log axes: for each (name, sorted samples in ns), the share of
/// samples at or above each latency. The tail reads downwards (1 %, 0.1 %, ...) instead of being
/// squeezed into the top of a linear CDF. A series of one value is a vertical line (a floor).
pub fn cdf(path: &Path, title: &str, series: &[(String, Vec<u64>)]) -> Result<()> {
    let root = png(path, (900, 560))?;
    let us = |ns: u64| (ns as f64 / 1e3).max(0.1);
    let lo = series.iter().filter_map(|(_, s)| s.first()).map(|v| us(*v)).fold(f64::MAX, f64::min).max(0.1);
    let hi = series.iter().filter_map(|(_, s)| s.last()).map(|v| us(*v)).fold(1.0, f64::max);
    let most = series.iter().map(|(_, s)| s.len()).max().unwrap_or(1).max(10) as f64;
    let floor_share = 0.8 / most;
    let mut chart = ChartBuilder::on(&root)
        .caption(title, (FONT, 20))
        .margin(15)
        .x_label_area_size(45)
        .y_label_area_size(60)
        .build_cartesian_2d((lo * 0.8..hi * 1.2).log_scale(), (floor_share..1.0).log_scale())
        .map_err(plot_error)?;
    chart
        .configure_mesh()
        .x_desc("latency, µs (log)")
        .y_desc("samples at or above (log)")
        .x_label_formatter(&micros_label)
        .y_label_formatter(&share_label)
        .draw()
        .map_err(plot_error)?;
    for (i, (name, samples)) in series.iter().enumerate() {
        if samples.is_empty() {
            continue;
        }
        let colour = colour(i);
        let n = samples.len();
        let points: Vec<(f64, f64)> = if n == 1 {
            vec![(us(samples[0]), floor_share), (us(samples[0]), 1.0)]
        } else {
            // At most 2000 points per curve, and every point of the last 1 % (the tail).
            let step = n.div_ceil(2000).max(1);
            let tail = n - n.div_ceil(100);
            (0..tail).step_by(step).chain(tail..n).map(|j| (us(samples[j]), (n - j) as f64 / n as f64)).collect()
        };
        chart
            .draw_series(LineSeries::new(points, colour.stroke_width(2)))
            .map_err(plot_error)?
            .label(name.clone())
            .legend(move |(x, y)| legend_mark(x, y, colour));
    }
    chart
        .configure_series_labels()
        // Lower right: the curves fall from the top left, so this corner is the emptiest; see
        // through, for a tail that reaches it.
        .position(SeriesLabelPosition::LowerRight)
        .background_style(WHITE.mix(0.5))
        .border_style(BLACK)
        .draw()
        .map_err(plot_error)?;
    root.present().map_err(plot_error)
}

/// Median one-way latency against payload size, log-log: one curve per transport.
pub fn payload(path: &Path, series: &[(String, Vec<(usize, f64)>)]) -> Result<()> {
    let root = png(path, (900, 560))?;
    let xs = series.iter().flat_map(|(_, p)| p.iter().map(|(b, _)| *b as f64));
    let (x_lo, x_hi) = xs.fold((f64::MAX, 1.0f64), |(lo, hi), x| (lo.min(x), hi.max(x)));
    let ys = series.iter().flat_map(|(_, p)| p.iter().map(|(_, us)| *us));
    let (y_lo, y_hi) = ys.fold((f64::MAX, 1.0f64), |(lo, hi), y| (lo.min(y), hi.max(y)));
    let mut chart = ChartBuilder::on(&root)
        .caption("one-way latency against payload size (median)", (FONT, 20))
        .margin(15)
        .x_label_area_size(45)
        .y_label_area_size(55)
        .build_cartesian_2d((x_lo * 0.8..x_hi * 1.25).log_scale(), (y_lo.max(0.1) * 0.8..y_hi * 1.25).log_scale())
        .map_err(plot_error)?;
    chart
        .configure_mesh()
        .x_desc("payload (log)")
        .y_desc("latency, µs (log)")
        .x_label_formatter(&bytes_label)
        .y_label_formatter(&micros_label)
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
        .background_style(WHITE.mix(0.8))
        .border_style(BLACK)
        .draw()
        .map_err(plot_error)?;
    root.present().map_err(plot_error)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn tick_labels_read_as_numbers_with_units() {
        assert_eq!(micros_label(&1000.0), "1000");
        assert_eq!(micros_label(&0.5), "0.5");
        assert_eq!(bytes_label(&64.0), "64 B");
        assert_eq!(bytes_label(&10000.0), "10 kB");
        assert_eq!(bytes_label(&1e6), "1 MB");
        assert_eq!(share_label(&1.0), "100%");
        assert_eq!(share_label(&0.01), "1%");
        assert_eq!(share_label(&0.001), "0.1%");
        assert_eq!(share_label(&0.0001), "0.01%");
    }
}
