//! The deadline, counted the same everywhere: real-time runs whose controller is stopped or
//! killed, where summary.json's `deadline_misses` is the count that loops.csv flags, that the
//! tick-period figure's title gives, and beside which the latency CDF's legend counts the loops
//! without a command (its percentiles over those with one, as the report's); `deadline_us` is checked at
//! load with one line naming the key and the allowed range. The counts are compared with each
//! other, never with a wall-clock threshold.

use crate::common;
use crate::figure_check;

use common::{Mode, fresh_dir, load_summary, looplab, run};
use figure_check::assert_figure;
use looplab_shared::tools::plot::latency::duration_label;
use looplab_shared::tools::plot::latency::{self, END_TO_END, MISSED, cdf_points, legend_stats, missed_count};
use looplab_shared::tools::plot::run::{RunData, tick_period_figure};
use looplab_shared::tools::run_folder::RunFolder;

/// A real-time pendulum run with `fault`, its figures drawn; checks that every count of its
/// deadline misses is summary.json's and returns that count and the loops at +∞.
fn misses_agree(name: &str, fault: &str) -> (u64, usize) {
    let r = run(name, &["pendulum", "--duration", "1.5", "--fault", fault, "--plot"]);
    misses_agree_in(&r.dir, r.summary(), &r.stdout())
}

/// The same, for a run whose controller is killed and never restarted while the run goes on
/// (`restart = "never"`, `on_death = "continue"`: it exits 1, a stage lost).
#[test]
fn a_controller_lost_for_good_misses_the_same_loops_in_every_count() {
    let dir = fresh_dir("deadline-never");
    let output = looplab()
        .args(["run", "pendulum", "--duration", "1.5", "--fault", "kill controller at 0.5s", "--plot", "-q"])
        .args(["--set", "supervision.controller.restart=\"never\""])
        .args(["--set", "supervision.controller.on_death=\"continue\"", "--out"])
        .arg(&dir)
        .output()
        .unwrap();
    assert_eq!(output.status.code(), Some(1), "{}", String::from_utf8_lossy(&output.stderr));
    let s = load_summary(&dir);
    assert_eq!(s.lost_stages.len(), 1);
    let (misses, without_command) = misses_agree_in(&dir, &s, &String::from_utf8_lossy(&output.stdout));
    assert!(without_command as u64 * 2 > misses, "after the loss no command comes: {without_command} of {misses}");
}

fn misses_agree_in(
    dir: &std::path::Path,
    s: &looplab_shared::launcher::summary::Summary,
    report: &str,
) -> (u64, usize) {
    assert_eq!(s.mode, Mode::Realtime);
    assert_eq!(s.deadline_us, Some(1000.0), "the default is one period");
    let misses = s.deadline_misses;
    assert!(misses > 0, "a controller that stops answering misses loops");
    assert_eq!(s.deadline_miss_share, Some(misses as f64 / s.loops as f64));

    // loops.csv: one row per loop up to the newest the monitor heard of (ticks the plant skipped
    // at the very end published nothing), the loops without a command flagged with no end to end.
    let loops = RunFolder::open(dir, &["loops.csv"]).unwrap().table("loops.csv").unwrap();
    let flags = loops.column::<u64>("deadline_miss").unwrap();
    let end_to_end = loops.column::<u64>("end_to_end_ns").unwrap();
    let rows = flags.len() as u64;
    assert!(rows <= s.loops && rows + s.skipped_ticks >= s.loops, "{rows} rows of {} loops", s.loops);
    assert_eq!(loops.column::<u64>("k").unwrap(), (0..rows).map(Some).collect::<Vec<_>>(), "a row for each loop");
    assert_eq!(flags.iter().filter(|f| **f == Some(1)).count() as u64, misses, "loops.csv's flags");
    // A loop whose state went out has its tick's timing; a skipped tick has none.
    let ticked = loops.column::<u64>("tick_scheduled_ns").unwrap();
    let without_command = (0..flags.len())
        .filter(|&row| flags[row] == Some(1) && end_to_end[row].is_none() && ticked[row].is_some())
        .count();
    assert_eq!(without_command as u64, s.loops_without_command, "summary.json counts the same loops");
    assert!(without_command > 0, "some loops got no command at all");

    // The tick-period figure's title, from the data it is drawn from; its marks above the curve.
    let data = RunData::read(dir, &looplab_shared::scenarios::builtin()).unwrap();
    let figure = tick_period_figure(&data).expect("a real-time run has a tick period");
    let panel = &figure.panels[0];
    let share = misses as f64 * 100.0 / s.loops as f64;
    let counted = format!(" · {misses} deadline misses of {} loops ({share:.1} %)", s.loops);
    assert!(panel.title.ends_with(&counted), "{} does not end with {counted}", panel.title);
    assert_eq!(panel.marks.len() as u64, misses);
    let highest = panel.curves[0].points.iter().map(|p| p.1).fold(f64::MIN, f64::max);
    assert!(panel.marks.iter().all(|m| m.1 > highest), "the misses are drawn above the period's curve");

    // The CDF: over the loops with a command, as the report's latencies; its legend counts
    // those without one beside them. Late commands are the rest of the misses, at their latency.
    let chart = latency::run_latency_chart(&loops, s, "run").unwrap();
    assert_eq!(chart.deadlines_ns, [1_000_000], "the deadline is marked");
    let (name, samples) = chart.series.last().unwrap();
    assert_eq!(name, END_TO_END);
    assert_eq!(missed_count(samples), without_command);
    assert_eq!(samples.len(), s.monitor.records as usize + without_command);
    let top = cdf_points(samples, 1e-6).last().copied().unwrap();
    assert_eq!(top.1, 1.0 / s.monitor.records as f64, "the curve ends at the slowest loop with a command");
    let stats = legend_stats(samples);
    let e2e = &s.latency_ns.end_to_end;
    let expected = [
        format!("p99 {}", duration_label(e2e.p99.unwrap())),
        format!("max {}", duration_label(e2e.max.unwrap())),
        format!("over the {} loops with a command; {without_command} had none", e2e.count),
    ];
    assert_eq!(stats[1..], expected, "the report's numbers");
    assert!(samples.iter().filter(|v| **v != MISSED).count() as u64 == s.monitor.records);

    // The figures are written, each with data in its panels.
    assert_figure(&dir.join("tick-period.png"), 1, false);
    assert!(dir.join("latency-cdf.png").is_file());
    // The zoom on the fault: the error, and the latency with each miss marked and the deadline.
    let fault = &s.faults[0];
    let zoom = looplab_shared::tools::plot::fault_zoom::file_name(1, fault);
    assert_figure(&dir.join(&zoom), 2, false);
    // The report says the share, the ticks skipped and the deadline.
    let skipped = if s.skipped_ticks > 0 { format!(", {} ticks skipped", s.skipped_ticks) } else { String::new() };
    let said = format!("deadline misses {misses} of {} ({share:.1} %{skipped}), deadline 1.000 ms", s.loops);
    assert!(report.contains(&said), "no `{said}` in\n{report}");
    (misses, without_command)
}

#[test]
fn a_stopped_controller_misses_the_same_loops_in_every_count() {
    let (misses, without_command) = misses_agree("deadline-stop", "stop controller at 0.3s for 0.8s");
    // Most of the stop's loops never got a command (those at its end may come late).
    assert!(without_command as u64 * 2 > misses, "{without_command} of {misses}");
}

#[test]
fn a_killed_controller_misses_the_same_loops_in_every_count() {
    misses_agree("deadline-kill", "kill controller at 0.5s");
}

#[test]
fn a_bad_deadline_is_one_line_naming_the_key_and_the_range() {
    for (value, origin) in [("0", "--set deadline_us=0"), ("1500", "--set deadline_us=1500")] {
        let output = looplab().args(["run", "pendulum", "--set", &format!("deadline_us={value}")]).output().unwrap();
        assert_eq!(output.status.code(), Some(2));
        let stderr = String::from_utf8_lossy(&output.stderr);
        assert_eq!(
            stderr,
            format!(
                "error: {origin}: key `deadline_us`: must be from 1 µs to one loop period (1000 µs at rate_hz = 1000), \
                 got {value}\n"
            )
        );
    }
    // In a launch file, the error names the file.
    let dir = fresh_dir("deadline-file");
    std::fs::create_dir_all(&dir).unwrap();
    let file = dir.join("short.toml");
    std::fs::write(&file, "scenario = \"pendulum\"\nrate_hz = 500.0\ndeadline_us = 2500.0\n").unwrap();
    let output = looplab().arg("run").arg(&file).output().unwrap();
    assert_eq!(output.status.code(), Some(2));
    assert_eq!(
        String::from_utf8_lossy(&output.stderr),
        format!(
            "error: {}: key `deadline_us`: must be from 1 µs to one loop period (2000 µs at rate_hz = 500), got 2500\n",
            file.display()
        )
    );
    std::fs::remove_dir_all(&dir).unwrap();
}
