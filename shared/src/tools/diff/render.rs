//! What `looplab diff` prints and draws.

use std::fmt::Write as _;

use super::*;

impl RunDiff {
    /// The text `looplab diff` prints.
    pub fn render(&self) -> String {
        let mut out = String::new();
        let _ = writeln!(out, "LoopLab diff · A {} · B {}", self.a.display(), self.b.display());
        let mode = match &self.modes {
            [a, b] if a == b => a.clone(),
            [a, b] => format!("A {a}, B {b}"),
        };
        let tolerances = if self.fields.iter().any(|f| f.tolerance != 0.0) || self.rtol != 0.0 {
            format!("tolerance as given, rtol {}", self.rtol)
        } else {
            "tolerance 0 (exact)".into()
        };
        let _ = writeln!(
            out,
            "  {} · {mode} · {} Hz · {} loops · {} fields · {tolerances}",
            self.scenario,
            self.rate_hz,
            self.loops,
            self.fields.len()
        );
        let differing: Vec<&FieldDiff> = self.differing().filter(|f| f.group != Group::Metrics).collect();
        if !differing.is_empty() {
            let _ = writeln!(out);
            let header = ["field", "max |B−A|", "at loop", "RMS", "tolerance", "loops over", "first over", "empty A/B"];
            // A group's title (Err) above its fields' rows (Ok).
            let mut rows: Vec<Result<Vec<String>, Group>> = Vec::new();
            for f in &differing {
                if rows.iter().rev().find_map(|r| r.as_ref().err()) != Some(&f.group) {
                    rows.push(Err(f.group));
                }
                rows.push(Ok(field_row(f)));
            }
            table(&mut out, &header, &rows);
        }
        let metrics: Vec<&FieldDiff> = self.differing().filter(|f| f.group == Group::Metrics).collect();
        if !metrics.is_empty() {
            let _ = writeln!(out);
            let header = ["metric (summary.json)", "A", "B", "|B−A|", "tolerance", "over"];
            let rows: Vec<Result<Vec<String>, Group>> = metrics.iter().map(|f| Ok(metric_row(f))).collect();
            table(&mut out, &header, &rows);
        }
        if !self.latency.is_empty() {
            let _ = writeln!(out);
            let judged = match self.latency_tolerance {
                Some(r) => format!("judged: each within [1/{r}, {r}]"),
                None => "not judged (--tolerance latency=R judges it)".into(),
            };
            let _ = writeln!(out, "  latency B ÷ A (p50, p99, max; from summary.json), {judged}");
            let rows: Vec<Result<Vec<String>, Group>> = self
                .latency
                .iter()
                .map(|l| {
                    let cells = (0..3).map(|i| {
                        let mark = if l.within.is_some_and(|w| !w[i]) { " over" } else { "" };
                        format!("{}{mark}", l.ratio[i].map_or("—".into(), ratio_label))
                    });
                    Ok(std::iter::once(l.name.clone()).chain(cells).collect())
                })
                .collect();
            table(&mut out, &["hop", "p50", "p99", "max"], &rows);
        }
        let _ = writeln!(out);
        let _ = writeln!(out, "{}", self.verdict());
        out
    }

    /// The one-line verdict.
    pub fn verdict(&self) -> String {
        let over: Vec<&FieldDiff> = self.fields.iter().filter(|f| f.over > 0).collect();
        let plural = |n: usize| if n == 1 { "field" } else { "fields" };
        let mut verdict = if let Some(first) = over.iter().filter(|f| f.first_over.is_some()).min_by_key(|f| {
            // The earliest loop; fields in the file's order at one loop.
            f.first_over.map(|at| at.k)
        }) {
            let at = first.first_over.expect("filtered");
            format!(
                "{} {} over tolerance; first: {} at loop {} (t = {} s)",
                over.len(),
                plural(over.len()),
                first.name,
                at.k,
                at.t_s
            )
        } else if let Some(first) = over.first() {
            format!("{} {} over tolerance; first: metric {}", over.len(), plural(over.len()), first.name)
        } else {
            match self.differing().count() {
                0 => "identical in every loop".to_string(),
                1 => "1 field differs, within its tolerance".to_string(),
                n => format!("{n} fields differ, each within its tolerance"),
            }
        };
        if let Some(r) = self.latency_tolerance {
            let outside: Vec<String> = self
                .latency
                .iter()
                .flat_map(|l| {
                    l.over().map(move |i| {
                        format!("{} {} {}", l.name, LATENCY_STATS[i], l.ratio[i].map_or("—".into(), ratio_label))
                    })
                })
                .collect();
            match outside.first() {
                None => verdict.push_str(&format!("; latency within [1/{r}, {r}]")),
                Some(first) => verdict.push_str(&format!(
                    "; latency: {} of {} ratios outside [1/{r}, {r}], first: {first}",
                    outside.len(),
                    self.latency.len() * 3
                )),
            }
        }
        verdict
    }

    /// The figure: B − A over time, one panel per field that differs loop by loop, in
    /// trajectory.csv's order (a field's own scale and unit: a group mixes units, rad beside
    /// rad/s, and its small differences would vanish beside its large ones), with its tolerance
    /// band ±(ABS + R·|A|) where it has one, or one "no difference" panel; the faults of both
    /// runs marked. The title counts the fields drawn, and the metrics apart (they have no loop).
    pub fn figure(&self) -> Figure {
        let t: Vec<f64> = self.at.iter().map(|at| at.t_s).collect();
        let end = t.iter().copied().filter(|t| t.is_finite()).fold(0.0, f64::max);
        let step = if self.rate_hz > 0.0 { 1.0 / self.rate_hz } else { 1.0 };
        let span = 0.0..end + step;
        let mut panels: Vec<Panel> = self
            .differing()
            .filter(|f| f.group != Group::Metrics)
            .map(|f| {
                let mut curves: Vec<Curve> = crate::model::figure::runs(&t, &f.delta, step)
                    .into_iter()
                    .map(|run| Curve::new(DELTA_LABEL, run, Colour::Series(0), Line::Solid(2)))
                    .collect();
                let exact = !f.band.iter().any(|b| *b > 0.0);
                if !exact {
                    for sign in [1.0, -1.0] {
                        let band: Vec<f64> = f.band.iter().map(|b| sign * b).collect();
                        curves.extend(
                            crate::model::figure::runs(&t, &band, step)
                                .into_iter()
                                .map(|run| Curve::new(BAND_LABEL, run, Colour::Limit, Line::Dashed)),
                        );
                    }
                }
                let largest = match f.max_at {
                    Some(at) => format!("largest {} at t = {} s", metric_text(f.max_abs), at.t_s),
                    None => "no finite difference".into(),
                };
                let tolerance = if exact { " · exact: no tolerance" } else { "" };
                let y_desc = match f.unit.as_deref() {
                    Some(unit) if !unit.is_empty() && unit != "1" => format!("B − A, {unit}"),
                    _ => "B − A".to_string(),
                };
                Panel::new(format!("{} · {largest}{tolerance}", f.name), y_desc, curves)
            })
            .collect();
        if panels.is_empty() {
            let zero =
                Curve::new(DELTA_LABEL, vec![(span.start, 0.0), (span.end, 0.0)], Colour::Series(0), Line::Solid(2));
            panels.push(Panel::new("no difference: B − A = 0 in every field and loop", "B − A", vec![zero]));
        }
        let metrics = self.differing().filter(|f| f.group == Group::Metrics).count();
        let drawn = self.differing().count() - metrics;
        let mut title = format!("{}: B − A over time · {}", self.scenario, self.verdict());
        if metrics > 0 {
            title.push_str(&format!(
                " · drawn: the {drawn} field(s) that differ loop by loop; {metrics} metric(s) differ too (diff.json)"
            ));
        }
        Figure {
            title,
            panels,
            x: span,
            x_desc: "t, s",
            faults: self.faults.clone(),
            faults_label: "fault injected (A, B: which run)",
            caption: None,
        }
    }
}

/// A table: its header, then rows of cells and group titles, the first column left-aligned and
/// the others right-aligned.
fn table(out: &mut String, header: &[&str], rows: &[Result<Vec<String>, Group>]) {
    let mut widths: Vec<usize> = header.iter().map(|h| h.chars().count()).collect();
    for cells in rows.iter().filter_map(|r| r.as_ref().ok()) {
        for (w, cell) in widths.iter_mut().zip(cells) {
            *w = (*w).max(cell.chars().count());
        }
    }
    let line = |out: &mut String, cells: &[String]| {
        let mut text = String::from("    ");
        for (i, (cell, w)) in cells.iter().zip(&widths).enumerate() {
            let pad = " ".repeat(w.saturating_sub(cell.chars().count()));
            if i == 0 {
                text.push_str(&format!("{cell}{pad}"));
            } else {
                text.push_str(&format!("  {pad}{cell}"));
            }
        }
        let _ = writeln!(out, "{}", text.trim_end());
    };
    line(out, &header.iter().map(|h| h.to_string()).collect::<Vec<_>>());
    for r in rows {
        match r {
            Ok(cells) => line(out, cells),
            Err(group) => {
                let _ = writeln!(out, "  {}", group.title());
            }
        }
    }
}

/// A trajectory field's row.
fn field_row(f: &FieldDiff) -> Vec<String> {
    let mut max = metric_text(f.max_abs);
    if f.non_finite > 0 {
        max.push_str(&format!(" (+{} NaN/inf)", f.non_finite));
    }
    let first = f.first_over.map_or("-".into(), |at| format!("{} (t = {} s)", at.k, at.t_s));
    let empty = match (f.empty_only_in_a, f.empty_only_in_b) {
        (0, 0) => "-".into(),
        (a, b) => format!("{a}/{b}"),
    };
    let at_loop = f.max_at.map_or("-".into(), |at| at.k.to_string());
    vec![
        f.name.clone(),
        max,
        at_loop,
        metric_text(f.rms),
        tolerance_text(f.tolerance),
        f.over.to_string(),
        first,
        empty,
    ]
}

/// A metric's row.
fn metric_row(f: &FieldDiff) -> Vec<String> {
    let (a, b) = f.values.unwrap_or((None, None));
    let text = |v: Option<f64>| v.map_or("-".into(), metric_text);
    let delta = match (a, b) {
        (Some(_), Some(_)) if f.non_finite > 0 => "NaN/inf".into(),
        (Some(_), Some(_)) => metric_text(f.max_abs),
        _ => "-".into(),
    };
    let over = if f.over > 0 { "over" } else { "within" };
    vec![f.name.clone(), text(a), text(b), delta, tolerance_text(f.tolerance), over.into()]
}

fn tolerance_text(tolerance: f64) -> String {
    if tolerance == 0.0 { "0".into() } else { format!("{tolerance}") }
}
