//! `looplab compare`: two real five-process runs with different wait strategies, side by side;
//! the table's structure, its numbers against the runs' summaries, its ratios against the
//! numbers it prints; and bad input.

use crate::common;
use crate::figure_check;

use std::path::Path;

use common::{Run, fresh_dir, looplab, run};
use figure_check::{Image, assert_charts};
use looplab_shared::tools::compare::{metric_text, ratio_label};
use looplab_shared::tools::plot::figure::Cell;

/// The rows of the table below its column header: (label words, the cells after the label).
struct Row {
    label: String,
    cells: Vec<String>,
}

fn compare(args: &[&Path]) -> std::process::Output {
    looplab().arg("compare").args(args).output().expect("start looplab")
}

/// Splits a row into its label and its cells: a cell is a number, "-", a ratio or one of the
/// run's words (block, adaptive, realtime).
fn parse_rows(body: &str) -> Vec<Row> {
    let is_cell = |w: &str| w.parse::<f64>().is_ok() || ["-", "—", "missed"].contains(&w) || w.starts_with('×');
    body.lines()
        .map(|line| {
            // A heading is indented by two spaces, a row by four.
            if !line.starts_with("   ") {
                return Row { label: line.trim().to_string(), cells: vec![] };
            }
            let words: Vec<&str> = line.split_whitespace().collect();
            // The control outcome's cells are words and numbers ("within limits", "LOST 1.2 s").
            if words[0] == "control" {
                return Row { label: "control".into(), cells: vec![] };
            }
            let first_cell = words.iter().position(|w| is_cell(w)).unwrap_or(words.len());
            let (label, cells) = if first_cell == words.len() && words.len() > 2 {
                // A row of words: the label is all but the last two.
                words.split_at(words.len() - 2)
            } else {
                words.split_at(first_cell)
            };
            Row { label: label.join(" "), cells: cells.iter().map(|c| c.to_string()).collect() }
        })
        .collect()
}

/// A latency as the table prints it: µs with one decimal.
fn micros(ns: Option<u64>) -> String {
    format!("{:.1}", ns.unwrap() as f64 / 1e3)
}

#[test]
fn two_wait_strategies_side_by_side_with_ratios_of_the_printed_numbers() {
    let short = ["--duration", "0.5", "--set"];
    let block: Run = run("compare-block", &[&short[..], &["wait.strategy=block"]].concat());
    let adaptive: Run = run("compare-adaptive", &[&short[..], &["wait.strategy=adaptive"]].concat());
    let chart_dir = fresh_dir("compare-chart");
    std::fs::create_dir_all(&chart_dir).unwrap();
    let chart = chart_dir.join("chart.png");

    let out = looplab().arg("compare").arg(&block.dir).arg(&adaptive.dir).arg("--out").arg(&chart).output().unwrap();
    let stdout = String::from_utf8_lossy(&out.stdout).into_owned();
    assert!(out.status.success(), "{stdout}\n{}", String::from_utf8_lossy(&out.stderr));
    let lines: Vec<&str> = stdout.lines().collect();
    let name = |r: &Run| r.dir.file_name().unwrap().to_string_lossy().into_owned();
    assert_eq!(lines[0], "LoopLab compare · 2 runs · ratios against A (run ÷ A, of the numbers printed)");
    // The folder names padded to one width.
    let width = name(&block).len().max(name(&adaptive).len());
    let (a, b) = (name(&block), name(&adaptive));
    assert_eq!(lines[1], format!("  A  {a:<width$}  pendulum · realtime · wait block · 1000 Hz · 0.5 s"));
    assert_eq!(lines[2], format!("  B  {b:<width$}  pendulum · realtime · wait adaptive · 1000 Hz · 0.5 s"));
    assert_eq!(lines[3], "");
    assert_eq!(lines[4].split_whitespace().collect::<Vec<_>>(), ["A", "B"]);
    assert_eq!(lines.last().unwrap(), &format!("chart: {}", chart.display()));
    // The chart: end to end across the top (540 px above its legend of two lines, 62 px), then
    // the four hops two to a row (360 px above a legend of 58 px); each chart has data.
    let image = Image::read(&chart);
    assert_eq!((image.width, image.height), (1200, 602 + 2 * 418));
    let cell = |x: u32, y: u32, width: u32, height: u32| Cell { x: x..x + width, y: y..y + height };
    let hops = [(0, 602), (600, 602), (0, 1020), (600, 1020)].map(|(x, y)| cell(x, y, 600, 360));
    assert_charts(&chart, &[&[cell(0, 0, 1200, 540)][..], &hops].concat());

    // The table, less the blank line and the chart's path below it.
    assert_eq!(lines[lines.len() - 2], "");
    let rows = parse_rows(&lines[5..lines.len() - 2].join("\n"));
    let labels: Vec<&str> = rows.iter().map(|r| r.label.as_str()).collect();
    // Every hop the report has, the stages' compute time included.
    let hop_names = [
        ("plant→sensors", "plant_to_sensors"),
        ("sensors compute", "sensors_compute"),
        ("sensors→estimator", "sensors_to_estimator"),
        ("estimator compute", "estimator_compute"),
        ("estimator→controller", "estimator_to_controller"),
        ("controller compute", "controller_compute"),
        ("controller→plant", "controller_to_plant"),
    ];
    let latency_labels: Vec<String> = hop_names
        .iter()
        .map(|(hop, _)| *hop)
        .chain(["END TO END"])
        .flat_map(|hop| [format!("{hop} p50"), "p99".into(), "p99.9".into(), "max".into()])
        .collect();
    let metrics: Vec<&String> = block.summary().metrics.keys().collect();
    let loop_labels = [
        "loop (deadline misses: late, no command or a skipped tick; share of loops)",
        "loops",
        "loops ran",
        "with a command",
        "without a command",
        "ticks skipped",
        "deadline misses",
        "deadline misses, %",
        "loops/s",
        "wait strategy",
        "mode",
        "control",
        "metrics",
    ];
    let expected: Vec<&str> =
        std::iter::once("latency, µs (from loops.csv; over the loops with a command, as the report)")
            .chain(latency_labels.iter().map(String::as_str))
            .chain(loop_labels)
            .chain(metrics.iter().map(|m| m.as_str()))
            .collect();
    assert_eq!(labels, expected);

    // Every number of B has its ratio against A's, computed from the two numbers printed.
    let mut ratios = 0;
    for row in rows.iter().filter(|r| r.cells.len() == 3) {
        let [a, b, ratio] = [&row.cells[0], &row.cells[1], &row.cells[2]];
        ratios += 1;
        let (a, b): (f64, f64) = (a.parse().unwrap(), b.parse().unwrap());
        let expected = if a == 0.0 { "—".to_string() } else { ratio_label(b / a) };
        assert_eq!(ratio, &expected, "row {}", row.label);
    }
    assert_eq!(ratios, 32 + 8 + metrics.len());

    // The numbers are the runs'.
    let cells = |label: &str| &rows.iter().find(|r| r.label == label).unwrap().cells;
    for (i, r) in [&block, &adaptive].into_iter().enumerate() {
        let s = r.summary();
        assert_eq!(cells("loops")[i], s.loops.to_string());
        assert_eq!(cells("deadline misses")[i], s.deadline_misses.to_string());
        assert_eq!(cells("loops ran")[i], (s.loops - s.skipped_ticks).to_string());
        assert_eq!(cells("with a command")[i], s.latency_ns.end_to_end.count.to_string());
        assert_eq!(cells("ticks skipped")[i], s.skipped_ticks.to_string());
        for metric in &metrics {
            assert_eq!(cells(metric)[i], metric_text(s.metrics[*metric]), "{metric}");
        }
        // The percentiles of loops.csv through the monitor's histogram: the summary's, printed.
        let hops = hop_names.iter().map(|(hop, key)| (*hop, &s.latency_ns.hops[*key]));
        for (hop, stats) in hops.chain([("END TO END", &s.latency_ns.end_to_end)]) {
            let at = rows.iter().position(|r| r.label == format!("{hop} p50")).unwrap();
            let printed: Vec<&String> = rows[at..at + 4].iter().map(|r| &r.cells[i]).collect();
            let summary: [Option<u64>; 4] = [stats.p50, stats.p99, stats.p999, stats.max];
            assert_eq!(printed, summary.map(micros).iter().collect::<Vec<_>>(), "{hop}");
        }
    }
    assert_eq!(cells("wait strategy")[..], ["block", "adaptive"]);
    assert_eq!(cells("mode")[..], ["realtime", "realtime"]);

    // With no --out, the chart goes beside the first run folder.
    let out = compare(&[&block.dir, &adaptive.dir]);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let default = block.dir.parent().unwrap().join(format!("compare-{}-vs-{}.png", name(&block), name(&adaptive)));
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert_eq!(stdout.lines().last().unwrap(), format!("chart: {}", default.display()));
    assert!(default.is_file());
    std::fs::remove_file(&default).unwrap();

    // An --out that is no PNG: one line, exit 2, nothing written.
    let svg = chart_dir.join("chart.svg");
    let out = looplab().arg("compare").arg(&block.dir).arg(&adaptive.dir).arg("--out").arg(&svg).output().unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(2), "{stderr}");
    assert_eq!(stderr, format!("error: --out {}: the chart is a PNG; give a path ending in .png\n", svg.display()));
    assert!(!svg.exists());
    std::fs::remove_dir_all(&chart_dir).unwrap();
}

#[test]
fn bad_input_is_one_line_naming_the_folder_with_exit_code_2() {
    let missing = fresh_dir("compare-missing");
    let empty = fresh_dir("compare-empty");
    std::fs::create_dir_all(&empty).unwrap();
    let cases: [(Vec<&Path>, String); 4] = [
        (vec![], "error: compare needs two or more run folders; got none".into()),
        (vec![&empty], format!("error: compare needs two or more run folders; got only {}", empty.display())),
        (vec![&empty, &missing], format!("error: {}: not a run folder (it has no summary.json)", empty.display())),
        (vec![&missing, &empty], format!("error: {}: no such run folder", missing.display())),
    ];
    for (args, expected) in cases {
        let out = compare(&args);
        let stderr = String::from_utf8_lossy(&out.stderr);
        assert_eq!(out.status.code(), Some(2), "{args:?}: {stderr}");
        assert_eq!(stderr, format!("{expected}\n"));
        assert!(out.stdout.is_empty());
    }
    assert_eq!(std::fs::read_dir(&empty).unwrap().count(), 0, "nothing written");
    std::fs::remove_dir_all(&empty).unwrap();
}
