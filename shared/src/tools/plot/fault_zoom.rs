//! One figure per fault, zoomed on it: `fault-<n>-<kind>-<process>.png`, from a little before
//! the injection to a little after the loop was whole again (the whole of its "during", to the
//! run's end for a stage that never came back): the scenario's error against its limit, and each loop's end-to-end
//! latency with its deadline misses, each in its cause's colour (`misses.rs`).

use std::path::{Path, PathBuf};

use crate::contract::run_format::files;
use crate::launcher::summary::FaultReport;
use crate::model::figure::{RunColumns, runs};
use crate::model::scenario::Scenario;
use crate::tools::ToolError;
use crate::tools::plot::figure::{Colour, Curve, Draw as _, FaultMark, Figure, Line, Panel};
use crate::tools::plot::misses::{crosses_by_cause, read_misses};
use crate::tools::run_folder::RunFolder;

/// Shown before the injection and after the end of "during", s (at least 50 loops).
const MARGIN_S: f64 = 0.5;

/// `fault-1-kill-controller.png`: numbered from 1 in the launch file's order.
pub fn file_name(n: usize, f: &FaultReport) -> String {
    format!("fault-{n}-{}-{}.png", <&str>::from(f.kind), f.process)
}

/// Draws each fault's zoomed figure into the run folder; returns the paths written.
pub fn plot_faults(
    run_dir: &Path,
    folder: &RunFolder,
    scenario: &dyn Scenario,
    data: &dyn RunColumns,
) -> Result<Vec<PathBuf>, ToolError> {
    let summary = folder.summary()?;
    if summary.faults.is_empty() {
        return Ok(vec![]);
    }
    let loops = folder.table(files::LOOPS)?;
    let (t_loops, end_to_end) = (loops.floats("t_s")?, loops.floats("end_to_end_ns")?);
    let latency_us: Vec<f64> = end_to_end.iter().map(|ns| ns / 1e3).collect();
    let misses = read_misses(&loops)?;
    // The deadline in µs (real time only; lockstep has none).
    let deadline_us = summary.deadline_us;
    let measure = scenario.error_measure();
    let t = data.t();
    let names: Vec<&str> = scenario.vectors().state.iter().map(|c| c.name).collect();
    let state: Vec<&[f64]> = names.iter().filter_map(|n| data.state(n)).collect();
    let error: Vec<(f64, f64)> = (0..t.len())
        .filter_map(|row| {
            let x: Vec<f64> = state.iter().map(|column| column[row]).collect();
            let e = (measure.of_state)(t[row], &x);
            e.is_finite().then_some((t[row], e))
        })
        .collect();
    let rate = data.config().rate_hz;
    let mut written = vec![];
    for (i, f) in summary.faults.iter().enumerate() {
        let during_end =
            f.effect.as_ref().and_then(|e| e.phases.as_ref()).map_or(f.at_s, |p| p.during.to_k as f64 / rate);
        let window =
            f.at_s - MARGIN_S.max(50.0 / rate)..(during_end + MARGIN_S.max(50.0 / rate)).min(data.config().duration_s);
        let window = window.start.max(0.0)..window.end.max(window.start.max(0.0) + 1.0 / rate);
        let within = |points: &[(f64, f64)]| -> Vec<(f64, f64)> {
            points.iter().copied().filter(|(t, _)| window.contains(t)).collect()
        };
        let mut error_panel = Panel::new(
            format!("{} (limit {})", measure.name, measure.limit),
            measure.name,
            vec![Curve::new(measure.name, within(&error), Colour::Series(0), Line::Solid(2))],
        );
        error_panel.bounds = vec![Curve::level("limit", measure.limit, &window, Colour::Limit)];
        // Each stretch of loops with a command drawn apart: a loop without one leaves a gap,
        // not a ramp across the outage, and each miss is a cross along the top.
        let latency: Vec<Curve> = runs(&t_loops, &latency_us, 1.0 / rate)
            .into_iter()
            .map(|run| within(&run))
            .filter(|run| !run.is_empty())
            .map(|run| Curve::new("end to end", run, Colour::Series(1), Line::Solid(1)))
            .collect();
        let in_view: Vec<_> = misses.iter().filter(|m| window.contains(&m.t)).collect();
        let top = latency.iter().flat_map(|c| &c.points).map(|p| p.1).fold(deadline_us.unwrap_or(0.0), f64::max) * 1.06;
        let title = match deadline_us {
            Some(_) => format!(
                "end to end · {} deadline misses in view (crosses by cause: late, no command or a skipped tick)",
                in_view.len()
            ),
            None => "end to end, each loop with a command (lockstep: no deadline)".into(),
        };
        let mut latency_panel = Panel::new(title, "latency, µs", latency);
        if let Some(deadline) = deadline_us {
            latency_panel.bounds = vec![Curve::level("deadline", deadline, &window, Colour::Limit)];
            latency_panel.curves.extend(crosses_by_cause(in_view, |_| top));
        }
        let figure = Figure {
            title: format!("{}: {} (during: {:.3} s to {:.3} s)", summary.title, f.fault, f.at_s, during_end),
            panels: vec![error_panel, latency_panel],
            x: window.clone(),
            x_desc: "t, s",
            faults: vec![FaultMark { t: f.at_s, label: format!("{} {}", <&str>::from(f.kind), f.process) }],
            faults_label: "fault",
            caption: None,
        };
        let path = run_dir.join(file_name(i + 1, f));
        figure.draw(&path)?;
        written.push(path);
    }
    Ok(written)
}
