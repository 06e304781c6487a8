//! One number for one question, everywhere: a real-time run with a stopped controller (loops
//! late, and loops whose command never came), its headline numbers computed here from
//! loops.csv alone, and the report, summary.json, the figures' titles and legends and
//! `compare` each checked to say the same. Latencies are over the loops whose command reached
//! the plant, through the monitor's histogram; the loops without one are counted beside them.
//! Counts are compared with each other, never with a wall-clock threshold.

use crate::common;
use crate::figure_check;

use common::{looplab, run};
use figure_check::{assert_charts, assert_figure};
use looplab_shared::contract::report::Stats;
use looplab_shared::monitor::distribution::Distribution;
use looplab_shared::tools::plot::figure::Cell;
use looplab_shared::tools::plot::latency::{self, duration_label, legend_stats};
use looplab_shared::tools::plot::run::{RunData, tick_period_figure};
use looplab_shared::tools::run_folder::RunFolder;

/// The headline numbers, from loops.csv alone.
struct FromLoops {
    rows: u64,
    misses_flagged: u64,
    /// Loops whose state went out (the plant ran them).
    ran: u64,
    without_command: u64,
    end_to_end: Stats,
    /// In the order of `contract::report::HOPS`.
    hops: Vec<Stats>,
}

/// loops.csv read by hand: a header, then rows of numbers or empty cells.
fn from_loops(dir: &std::path::Path) -> FromLoops {
    let text = std::fs::read_to_string(dir.join("loops.csv")).unwrap();
    let mut lines = text.lines();
    let header: Vec<&str> = lines.next().unwrap().split(',').collect();
    let at = |name: &str| header.iter().position(|h| *h == name).unwrap_or_else(|| panic!("no column {name}"));
    let (e2e, miss, ticked) = (at("end_to_end_ns"), at("deadline_miss"), at("tick_scheduled_ns"));
    let hop_columns: Vec<(usize, usize)> = looplab_shared::contract::report::HOPS
        .iter()
        .map(|(name, _, _)| match name.split_once("_to_") {
            Some((from, to)) => (at(&format!("{from}_publish_ns")), at(&format!("{to}_receive_ns"))),
            None => {
                let stage = name.trim_end_matches("_compute");
                (at(&format!("{stage}_receive_ns")), at(&format!("{stage}_publish_ns")))
            }
        })
        .collect();
    let mut end_to_end = Distribution::default();
    let mut hops: Vec<Distribution> = hop_columns.iter().map(|_| Distribution::default()).collect();
    let (mut rows, mut misses_flagged, mut ran, mut without_command) = (0, 0, 0, 0);
    for line in lines {
        let cells: Vec<&str> = line.split(',').collect();
        let number = |i: usize| cells[i].parse::<u64>().ok();
        rows += 1;
        misses_flagged += u64::from(number(miss) == Some(1));
        ran += u64::from(number(ticked).is_some());
        match number(e2e) {
            Some(ns) => {
                end_to_end.record(ns);
                for (d, (from, to)) in hops.iter_mut().zip(&hop_columns) {
                    d.record(number(*to).unwrap().saturating_sub(number(*from).unwrap()));
                }
            }
            None if number(miss) == Some(1) && number(ticked).is_some() => without_command += 1,
            None => {}
        }
    }
    let hops = hops.iter().map(Distribution::stats).collect();
    FromLoops { rows, misses_flagged, ran, without_command, end_to_end: end_to_end.stats(), hops }
}

/// A latency as the report and compare print it: µs with one decimal.
fn micros(ns: Option<u64>) -> String {
    format!("{:.1}", ns.unwrap() as f64 / 1e3)
}

#[test]
fn report_summary_figures_and_compare_give_the_same_numbers() {
    let a = run(
        "one-number-stop",
        &["pendulum", "--duration", "3", "--fault", "stop controller at 1s for 100ms", "--plot"],
    );
    let b = run("one-number-plain", &["pendulum", "--duration", "1"]);
    let s = a.summary();
    let csv = from_loops(&a.dir);

    // summary.json against loops.csv. Ticks the plant skipped at the very end have no row:
    // each is a miss.
    assert!(csv.rows <= s.loops && csv.rows + s.skipped_ticks >= s.loops, "{} rows of {} loops", csv.rows, s.loops);
    let misses = csv.misses_flagged + (s.loops - csv.rows);
    assert_eq!(s.deadline_misses, misses, "deadline misses: late, no command or a skipped tick");
    assert_eq!(s.deadline_miss_share, Some(misses as f64 / s.loops as f64));
    assert_eq!(s.loops - s.skipped_ticks, csv.ran, "loops that ran");
    assert!(csv.without_command > 0, "the stop leaves loops without a command");
    assert_eq!(s.loops_without_command, csv.without_command);
    assert_eq!(s.latency_ns.end_to_end, csv.end_to_end, "end to end over the loops with a command");
    for ((hop, _, _), stats) in looplab_shared::contract::report::HOPS.iter().zip(&csv.hops) {
        assert_eq!(&s.latency_ns.hops[*hop], stats, "{hop}");
    }

    // The report.
    let report = a.stdout();
    let share = misses as f64 * 100.0 / s.loops as f64;
    let skipped = if s.skipped_ticks > 0 { format!(", {} ticks skipped", s.skipped_ticks) } else { String::new() };
    let ran = format!("completed: {} of {} loops ran in ", csv.ran, s.loops_planned);
    let missed = format!(" · deadline misses {misses} of {} ({share:.1} %{skipped}), deadline 1.000 ms", s.loops);
    let headline = report.lines().find(|l| l.contains(&ran)).unwrap_or_else(|| panic!("no `{ran}` in\n{report}"));
    assert!(headline.contains(&missed), "no `{missed}` in {headline}");
    let row = |label: &str| {
        let line = report.lines().find(|l| l.trim_start().starts_with(label)).unwrap_or_else(|| panic!("no {label}"));
        line[line.find(label).unwrap() + label.len()..].split_whitespace().map(String::from).collect::<Vec<_>>()
    };
    let printed = |stats: &Stats| {
        [stats.count.to_string(), micros(stats.min), micros(stats.p50), micros(stats.p90), micros(stats.p99)]
            .into_iter()
            .chain([micros(stats.p999), micros(stats.max)])
            .collect::<Vec<_>>()
    };
    assert_eq!(row("END TO END"), printed(&csv.end_to_end));
    for ((hop, _, _), stats) in looplab_shared::contract::report::HOPS.iter().zip(&csv.hops) {
        assert_eq!(row(&hop.replace('_', " ")), printed(stats), "{hop}");
    }
    let over =
        format!("over the {} loops with a command; {} had none{skipped}", csv.end_to_end.count, csv.without_command);
    assert!(report.contains(&over), "no `{over}` in\n{report}");

    // The figures: the latency chart's legends and the tick-period title, from the data they
    // are drawn from, and the images drawn with data in them.
    let loops = RunFolder::open(&a.dir, &["loops.csv"]).unwrap().table("loops.csv").unwrap();
    let chart = latency::run_latency_chart(&loops, s, "run").unwrap();
    let legend = |stats: &Stats| {
        let mut l = vec![
            format!("p50 {}", duration_label(stats.p50.unwrap())),
            format!("p99 {}", duration_label(stats.p99.unwrap())),
            format!("max {}", duration_label(stats.max.unwrap())),
        ];
        l.push(format!("over the {} loops with a command; {} had none", stats.count, csv.without_command));
        l
    };
    let (name, samples) = chart.series.last().unwrap();
    assert_eq!(name, latency::END_TO_END);
    assert_eq!(legend_stats(samples), legend(&csv.end_to_end));
    // The hops from one process to the next, as the chart names them.
    let transport =
        looplab_shared::contract::report::HOPS.iter().zip(&csv.hops).filter(|((h, _, _), _)| h.contains("_to_"));
    let drawn: Vec<_> = chart.series[..chart.series.len() - 1].iter().collect();
    assert_eq!(drawn.len(), 4);
    for (((hop, _, _), stats), (name, samples)) in transport.zip(drawn) {
        assert_eq!(name, &hop.replace("_to_", "→"));
        assert_eq!(legend_stats(samples)[..3], legend(stats)[..3], "{hop}");
    }
    let data = RunData::read(&a.dir, &looplab_shared::scenarios::builtin()).unwrap();
    let figure = tick_period_figure(&data).unwrap();
    let counted = format!(
        " · {} deadline misses of {} loops ({:.1} %)",
        csv.misses_flagged,
        s.loops,
        csv.misses_flagged as f64 * 100.0 / s.loops as f64
    );
    assert!(figure.panels[0].title.ends_with(&counted), "{}", figure.panels[0].title);
    assert_figure(&a.dir.join("tick-period.png"), 1, false);
    assert_charts(&a.dir.join(latency::RUN_FIGURE), &[Cell { x: 0..900, y: 0..520 }]);

    // compare: A's column.
    let out = looplab().arg("compare").arg(&a.dir).arg(&b.dir).output().unwrap();
    let stdout = String::from_utf8_lossy(&out.stdout).into_owned();
    assert!(out.status.success(), "{stdout}\n{}", String::from_utf8_lossy(&out.stderr));
    let lines: Vec<&str> = stdout.lines().collect();
    // The first cell after a label: A's.
    let first_cell = |label: &str, from: usize| -> String {
        let line =
            lines[from..].iter().find(|l| l.trim_start().starts_with(label)).unwrap_or_else(|| panic!("no {label}"));
        line.trim_start()[label.len()..].split_whitespace().next().unwrap().to_string()
    };
    let block = |label: &str, stats: &Stats| {
        let at = lines.iter().position(|l| l.trim_start().starts_with(label)).unwrap();
        let cells: Vec<String> = ["p50", "p99", "p99.9", "max"]
            .iter()
            .enumerate()
            .map(|(i, p)| {
                lines[at + i].trim_start().trim_start_matches(label).trim_start()[p.len()..]
                    .split_whitespace()
                    .next()
                    .unwrap()
                    .to_string()
            })
            .collect();
        assert_eq!(cells, [micros(stats.p50), micros(stats.p99), micros(stats.p999), micros(stats.max)], "{label}");
    };
    block("END TO END", &csv.end_to_end);
    for ((hop, _, _), stats) in looplab_shared::contract::report::HOPS.iter().zip(&csv.hops) {
        block(&hop.replace("_to_", "→").replace('_', " "), stats);
    }
    assert_eq!(first_cell("deadline misses", 0), misses.to_string());
    assert_eq!(first_cell("deadline misses, %", 0), format!("{share:.1}"));
    assert_eq!(first_cell("loops ran", 0), csv.ran.to_string());
    assert_eq!(first_cell("with a command", 0), csv.end_to_end.count.to_string());
    assert_eq!(first_cell("without a command", 0), csv.without_command.to_string());
    if let Some(chart) = stdout.lines().last().and_then(|l| l.strip_prefix("chart: ")) {
        let _ = std::fs::remove_file(chart);
    }
}
