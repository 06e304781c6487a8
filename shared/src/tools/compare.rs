//! `looplab compare RUN_A RUN_B [...]`: finished runs side by side (latency per hop and end to
//! end, deadline misses, loops, wait strategy and mode, the scenario's metrics) with ratios
//! against the first run, and their latency distributions on one chart.
//!
//! Latencies are of loops.csv's samples, over the loops whose command reached the plant, taken
//! through the monitor's histogram: the numbers of the run's report, to the digit. The loops
//! without a command are counted beside them. A ratio is the quotient of the two numbers
//! printed, so that a reader can check it.

use std::fmt::Write as _;
use std::path::{Path, PathBuf};

use anyhow::Context as _;

use crate::config::wait::WaitSettings;
use crate::contract::report::Stats;
use crate::contract::role::Role;
use crate::contract::run_format::files;
use crate::launcher::summary::Summary;
use crate::tools::ToolError;
use crate::tools::plot::latency::{self, END_TO_END, Panel, Series, missed_count, stats_of};
use crate::tools::run_folder::RunFolder;

/// The files of a run folder compare reads.
const INPUTS: [&str; 3] = [files::SUMMARY, files::LOOPS, files::LAUNCH];

/// A field of the report's statistics.
type StatsField = fn(&Stats) -> Option<u64>;

/// The percentiles compared, as (label, its field).
const PERCENTILES: [(&str, StatsField); 4] =
    [("p50", |s| s.p50), ("p99", |s| s.p99), ("p99.9", |s| s.p999), ("max", |s| s.max)];

/// The width of a ratio ("×0.0042"), after each run's value but the first's.
const RATIO_WIDTH: usize = 8;

/// What compare reads of one run folder.
struct Run {
    /// The folder's own name (of the folder a link such as runs/latest points at).
    name: String,
    summary: Summary,
    /// The wait strategy in words ("adaptive", "block (controller spin), pinned").
    wait: String,
    /// Per hop (compute time included), then end to end, from loops.csv.
    latencies: Vec<Series>,
}

/// Reads the runs, prints nothing: returns the table and the chart's path once it is written.
pub fn compare(dirs: &[PathBuf], out: Option<&Path>) -> Result<(String, PathBuf), ToolError> {
    if dirs.len() < 2 {
        let got = dirs.first().map_or("none".into(), |d| format!("only {}", d.display()));
        return Err(ToolError::BadInput(format!("compare needs two or more run folders; got {got}")));
    }
    let runs = dirs.iter().map(|d| read_run(d)).collect::<Result<Vec<Run>, ToolError>>()?;
    let out = match out {
        Some(out) => checked_out(out)?,
        None => default_out(&dirs[0], &runs),
    };
    latency::cdf_panels(&out, &panels(&runs)).map_err(ToolError::Failed)?;
    Ok((render(&runs), out))
}

fn read_run(dir: &Path) -> Result<Run, ToolError> {
    let folder = RunFolder::open(dir, &INPUTS)?;
    let summary = folder.summary()?;
    let wait = read_wait(&folder.text(files::LAUNCH)?)
        .map_err(|e| ToolError::BadInput(format!("{}: launch.toml: {e:#}", dir.display())))?;
    let latencies = latency::latencies_from_loops(&folder.table(files::LOOPS)?)?;
    let canonical = dir.canonicalize().unwrap_or_else(|_| dir.to_path_buf());
    let name = canonical.file_name().map_or_else(|| dir.display().to_string(), |n| n.to_string_lossy().into_owned());
    Ok(Run { name, summary, wait, latencies })
}

/// The run's `[wait]` section, from the text of its resolved launch file, in words.
fn read_wait(launch: &str) -> anyhow::Result<String> {
    let document: toml::Table = toml::from_str(launch)?;
    let wait: WaitSettings = match document.get("wait") {
        Some(section) => section.clone().try_into().context("[wait]")?,
        None => WaitSettings::default(),
    };
    Ok(describe_wait(&wait))
}

/// "adaptive"; "block (controller spin)" where a process has its own; ", pinned" with `pin`.
fn describe_wait(wait: &WaitSettings) -> String {
    let own: Vec<String> = Role::LOOP
        .iter()
        .filter(|role| wait.for_process(**role) != wait.strategy)
        .map(|role| format!("{} {}", role.name(), wait.for_process(*role).name()))
        .collect();
    let mut text = wait.strategy.name().to_owned();
    if !own.is_empty() {
        text.push_str(&format!(" ({})", own.join(", ")));
    }
    if wait.pin {
        text.push_str(", pinned");
    }
    text
}

/// An --out the chart can be written to: a .png in a folder that exists.
fn checked_out(out: &Path) -> Result<PathBuf, ToolError> {
    let bad = |why: &str| ToolError::BadInput(format!("--out {}: {why}", out.display()));
    if !out.extension().is_some_and(|e| e.eq_ignore_ascii_case("png")) {
        return Err(bad("the chart is a PNG; give a path ending in .png"));
    }
    let folder = out.parent().filter(|p| !p.as_os_str().is_empty()).unwrap_or(Path::new("."));
    if !folder.is_dir() {
        return Err(bad(&format!("no folder {}", folder.display())));
    }
    Ok(out.to_path_buf())
}

/// Beside the first run folder (in runs/ for runs in runs/): compare-A-vs-B.png.
fn default_out(first: &Path, runs: &[Run]) -> PathBuf {
    let first = first.canonicalize().unwrap_or_else(|_| first.to_path_buf());
    let folder = first.parent().unwrap_or(Path::new("."));
    let names: Vec<&str> = runs.iter().map(|r| r.name.as_str()).collect();
    folder.join(format!("compare-{}.png", names.join("-vs-")))
}

/// The letter that names run `i` in the table and the chart: A, B, ...
fn letter(i: usize) -> String {
    let letters = b"ABCDEFGHIJKLMNOPQRSTUVWXYZ";
    if i < letters.len() { (letters[i] as char).to_string() } else { format!("R{}", i + 1) }
}

/// The chart: end to end across the top, each hop below.
fn panels(runs: &[Run]) -> Vec<Panel> {
    let series = |index: usize, long: bool| -> Vec<Series> {
        runs.iter()
            .enumerate()
            .map(|(i, run)| {
                // The folder names the run where there is room; its wait strategy unless the
                // folder's name already says it (runs/block).
                let name = match long {
                    true if run.name.contains(&run.wait) => format!("{} · {}", letter(i), run.name),
                    true => format!("{} · {} · wait {}", letter(i), run.name, run.wait),
                    false => format!("{} · {}", letter(i), run.wait),
                };
                (name, run.latencies[index].1.clone())
            })
            .collect()
    };
    let end_to_end = runs[0].latencies.len() - 1;
    // Each run's deadline, once.
    let mut deadlines: Vec<u64> = runs.iter().filter_map(|r| latency::deadline_ns(&r.summary)).collect();
    deadlines.sort_unstable();
    deadlines.dedup();
    let first = Panel {
        title: "end-to-end loop latency".into(),
        series: series(end_to_end, true),
        deadlines_ns: deadlines.clone(),
    };
    let transport =
        runs[0].latencies[..end_to_end].iter().enumerate().filter(|(_, (hop, _))| latency::is_transport(hop));
    let hops = transport.map(|(h, (hop, _))| Panel {
        title: format!("hop {hop}"),
        series: series(h, false),
        deadlines_ns: deadlines.clone(),
    });
    std::iter::once(first).chain(hops).collect()
}

/// A ratio to two significant digits at least: "×0.42", "×1.00", "×12.3", "×150", "×0.042".
pub fn ratio_label(ratio: f64) -> String {
    let size = ratio.abs();
    let decimals = match size {
        0.0 => 0,
        _ if size >= 99.95 => 0,
        _ if size >= 9.995 => 1,
        _ if size >= 0.1 => 2,
        _ => (1 - size.log10().floor() as i32) as usize,
    };
    format!("×{ratio:.decimals$}")
}

/// The ratio of a printed number against the first run's printed number; "—" where there is
/// none (a number missing, or the first is 0).
fn ratio_of(text: &str, first: &str) -> String {
    match (text.parse::<f64>(), first.parse::<f64>()) {
        (Ok(value), Ok(reference)) if reference != 0.0 => ratio_label(value / reference),
        _ => "—".into(),
    }
}

/// A scenario metric to four significant digits: "0.08827", "0.7620", "1234", "5.103e-6".
pub fn metric_text(value: f64) -> String {
    if value == 0.0 || !value.is_finite() {
        return format!("{value}");
    }
    let magnitude = value.abs().log10().floor() as i32;
    if !(-4..7).contains(&magnitude) {
        return format!("{value:.3e}");
    }
    let decimals = (3 - magnitude).max(0) as usize;
    format!("{value:.decimals$}")
}

/// A latency in the table: µs with one decimal, as the run's report prints it.
fn micros_text(ns: Option<u64>) -> String {
    match ns {
        None => "-".into(),
        Some(ns) => format!("{:.1}", ns as f64 / 1e3),
    }
}

/// A line of the table below its header.
enum Line {
    Heading(&'static str),
    /// A label and each run's number, with a ratio against the first.
    Numbers(String, Vec<String>),
    /// A label and each run's words (the wait strategy, the mode).
    Words(String, Vec<String>),
}

/// The table.
fn render(runs: &[Run]) -> String {
    let mut out = String::new();
    let _ = writeln!(out, "LoopLab compare · {} runs · ratios against A (run ÷ A, of the numbers printed)", runs.len());
    let name_width = runs.iter().map(|r| r.name.chars().count()).max().unwrap_or(0);
    for (i, run) in runs.iter().enumerate() {
        let s = &run.summary;
        let _ = writeln!(
            out,
            "  {}  {:<name_width$}  {} · {} · wait {} · {} Hz · {} s",
            letter(i),
            run.name,
            s.scenario,
            s.mode.name(),
            run.wait,
            s.rate_hz,
            s.duration_s
        );
    }
    let mut scenarios: Vec<&str> = runs.iter().map(|r| r.summary.scenario.as_str()).collect();
    scenarios.sort();
    scenarios.dedup();
    if scenarios.len() > 1 {
        let _ =
            writeln!(out, "  note: the runs are of different scenarios; metrics are compared where their names match");
    }
    let _ = writeln!(out);
    let lines = lines(runs);
    let label_width = lines.iter().map(|l| match l {
        Line::Heading(_) => 0,
        Line::Numbers(label, _) | Line::Words(label, _) => label.chars().count(),
    });
    let label_width = label_width.max().unwrap_or(0) + 2;
    let value_width = lines.iter().flat_map(|l| match l {
        Line::Heading(_) => [].iter(),
        Line::Numbers(_, values) | Line::Words(_, values) => values.iter(),
    });
    let value_width = value_width.map(|v| v.chars().count()).max().unwrap_or(0).max(8) + 2;
    let letters = (0..runs.len()).map(letter).collect();
    for line in std::iter::once(Line::Words(String::new(), letters)).chain(lines) {
        let (label, values, ratios) = match line {
            Line::Heading(heading) => {
                let _ = writeln!(out, "  {heading}");
                continue;
            }
            Line::Numbers(label, values) => (label, values, true),
            Line::Words(label, values) => (label, values, false),
        };
        let _ = write!(out, "  {label:<label_width$}{:>value_width$}", values[0]);
        for value in &values[1..] {
            let ratio = if ratios { ratio_of(value, &values[0]) } else { String::new() };
            let _ = write!(out, "{value:>value_width$} {ratio:<RATIO_WIDTH$}");
        }
        out.truncate(out.trim_end().len());
        out.push('\n');
    }
    out
}

/// The control outcome in a cell: "within limits", "exceeded 1.234 s", "lost 0.512 s".
fn control_text(s: &Summary) -> String {
    use crate::launcher::verdict::Verdict;
    let l = &s.limits;
    match (l.verdict, l.exceeded_at_s, l.lost_at_s) {
        (Verdict::LimitsExceeded, Some(t), _) => format!("exceeded {t} s"),
        (Verdict::Lost, _, Some(t)) => format!("LOST {t} s"),
        (verdict, _, _) => verdict.to_string(),
    }
}

/// The table's lines: latency per hop and end to end, the loop, the scenario's metrics.
fn lines(runs: &[Run]) -> Vec<Line> {
    let mut lines = vec![Line::Heading("latency, µs (from loops.csv; over the loops with a command, as the report)")];
    for (h, (series, _)) in runs[0].latencies.iter().enumerate() {
        let stats: Vec<Stats> = runs.iter().map(|r| stats_of(&r.latencies[h].1)).collect();
        for (p, (percentile, field)) in PERCENTILES.iter().enumerate() {
            let values = stats.iter().map(|s| micros_text(field(s))).collect();
            let name = match (p, series.as_str()) {
                (0, END_TO_END) => "END TO END",
                (0, hop) => hop,
                _ => "",
            };
            lines.push(Line::Numbers(format!("  {name:<22}{percentile}"), values));
        }
    }
    let each = |f: &dyn Fn(&Summary) -> String| runs.iter().map(|r| f(&r.summary)).collect::<Vec<_>>();
    let end_to_end: Vec<&[u64]> = runs.iter().map(|r| &r.latencies[r.latencies.len() - 1].1[..]).collect();
    lines.extend([
        Line::Heading("loop (deadline misses: late, no command or a skipped tick; share of loops)"),
        Line::Numbers("  loops".into(), each(&|s| s.loops.to_string())),
        // A skipped tick was integrated, but no loop ran for it.
        Line::Numbers("  loops ran".into(), each(&|s| (s.loops - s.skipped_ticks).to_string())),
        Line::Numbers("  with a command".into(), end_to_end.iter().map(|e| stats_of(e).count.to_string()).collect()),
        Line::Numbers("  without a command".into(), end_to_end.iter().map(|e| missed_count(e).to_string()).collect()),
        Line::Numbers("  ticks skipped".into(), each(&|s| s.skipped_ticks.to_string())),
        Line::Numbers("  deadline misses".into(), each(&|s| s.deadline_misses.to_string())),
        Line::Numbers(
            "  deadline misses, %".into(),
            each(&|s| s.deadline_miss_share.map_or("-".into(), |share| format!("{:.1}", share * 100.0))),
        ),
        Line::Numbers("  loops/s".into(), each(&|s| format!("{:.0}", s.loops_per_s))),
        Line::Words("  wait strategy".into(), runs.iter().map(|r| r.wait.clone()).collect()),
        Line::Words("  mode".into(), each(&|s| s.mode.name().to_owned())),
        Line::Words("  control".into(), each(&control_text)),
    ]);
    let mut metrics: Vec<&String> = runs.iter().flat_map(|r| r.summary.metrics.keys()).collect();
    metrics.sort();
    metrics.dedup();
    if !metrics.is_empty() {
        lines.push(Line::Heading("metrics"));
    }
    for metric in metrics {
        let values = each(&|s| s.metrics.get(metric).map_or("-".into(), |v| metric_text(*v)));
        lines.push(Line::Numbers(format!("  {metric}"), values));
    }
    lines
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::config::wait::Strategy;

    #[test]
    fn ratios_keep_two_significant_digits() {
        assert_eq!(ratio_label(0.42), "×0.42");
        assert_eq!(ratio_label(1.0), "×1.00");
        assert_eq!(ratio_label(0.999), "×1.00");
        assert_eq!(ratio_label(2.374), "×2.37");
        assert_eq!(ratio_label(12.34), "×12.3");
        assert_eq!(ratio_label(150.2), "×150");
        assert_eq!(ratio_label(0.042), "×0.042");
        assert_eq!(ratio_label(0.00421), "×0.0042");
        assert_eq!(ratio_label(0.0), "×0");
        assert_eq!(ratio_label(-0.5), "×-0.50");
    }

    #[test]
    fn a_ratio_is_of_the_numbers_printed() {
        assert_eq!(ratio_of("8.1", "20.3"), "×0.40");
        assert_eq!(ratio_of("3", "0"), "—");
        assert_eq!(ratio_of("0", "0"), "—");
        assert_eq!(ratio_of("-", "20.3"), "—");
        assert_eq!(ratio_of("5.103e-6", "1.000e-5"), "×0.51");
    }

    #[test]
    fn metrics_keep_four_significant_digits() {
        assert_eq!(metric_text(0.08827385309684214), "0.08827");
        assert_eq!(metric_text(0.762), "0.7620");
        assert_eq!(metric_text(-0.1363822045416827), "-0.1364");
        assert_eq!(metric_text(1234.4), "1234");
        assert_eq!(metric_text(123456.0), "123456");
        assert_eq!(metric_text(5.102998915164437e-6), "5.103e-6");
        assert_eq!(metric_text(0.0), "0");
    }

    #[test]
    fn the_wait_strategy_in_words() {
        let mut wait = WaitSettings::default();
        assert_eq!(describe_wait(&wait), "block");
        wait.strategy = Strategy::Adaptive;
        wait.controller = Some(Strategy::Spin);
        wait.pin = true;
        assert_eq!(describe_wait(&wait), "adaptive (controller spin), pinned");
    }

    #[test]
    fn runs_are_lettered() {
        assert_eq!([0, 1, 25, 26].map(letter), ["A", "B", "Z", "R27"]);
    }
}
