//! `looplab plot`: a real five-process run with `--plot` writes its figures as PNG into the run
//! folder; `looplab plot` on something that is not a run folder says so and exits with 2. Each
//! figure is decoded and checked: not blank, data in every panel (`figure_check`), a check shown
//! to fail on a figure with an empty panel. The misses' figure counts what the report counts and
//! colours each miss by its cause.

use crate::common;
use crate::figure_check;

use std::collections::BTreeMap;
use std::path::Path;

use common::{FaultKind, Table, fresh_dir, looplab, run};
use figure_check::{Image, MIN_DATA_PIXELS, assert_charts, assert_figure, check, data_pixels};
use looplab_shared::model::figure::RunColumns;
use looplab_shared::tools::plot::figure::{Cell, Colour, Curve, Draw as _, FaultMark, Figure, Line, Panel, rgb};
use looplab_shared::tools::plot::misses::CauseKind;
use looplab_shared::tools::plot::run::{
    APPLIED_LABEL, COMMAND_LABEL, MISSES_FIGURE, RunData, commands_figure, misses_figure,
};

#[test]
fn a_real_time_run_with_a_kill_plots_its_figures() {
    let r = run("plot", &["pendulum", "--duration", "1", "--fault", "kill estimator at 0.5s", "--plot"]);
    let stdout = r.stdout();
    // Estimate: four components on a 2×2 grid; commands: one; sensors: two, stacked; tick period: one.
    // The kill's outage misses deadlines, so misses.png has crosses.
    let figures =
        [("estimate.png", 4), ("commands.png", 1), ("sensors.png", 2), ("tick-period.png", 1), (MISSES_FIGURE, 1)];
    for (name, panels) in figures {
        let path = r.dir.join(name);
        assert!(stdout.contains(&format!("wrote {}", path.display())), "{name} not reported:\n{stdout}");
        assert_figure(&path, panels, false);
    }
    let path = r.dir.join("latency-cdf.png");
    assert!(stdout.contains(&format!("wrote {}", path.display())), "latency-cdf.png not reported:\n{stdout}");
    let image = Image::read(&path);
    assert_eq!((image.width, image.height), (900, 654));
    // The chart above its legend.
    assert_charts(&path, &[Cell { x: 0..900, y: 0..520 }]);
}

/// A real-time run whose controller is stopped for a second (`on_stale = "hold"`, the pendulum's
/// default): trajectory.csv has no command across the stop and the applied input held at one
/// value; the commands chart's series have a gap there (no segment crosses it, where the old
/// chart drew a ramp), the applied input's steps run on across it, and commands.png is written.
#[test]
fn a_stopped_controller_leaves_a_gap_in_the_commands_and_the_held_input_beside_it() {
    let r = run("plot-stop", &["pendulum", "--duration", "3", "--fault", "stop controller at 1s for 1s", "--plot"]);
    let data = RunData::read(&r.dir, &looplab_shared::scenarios::builtin()).unwrap();
    let t = data.t().to_vec();
    let command = data.command("current").unwrap().to_vec();
    let applied = data.trajectory[data.columns.applied.start].clone();
    assert_eq!(r.trajectory().columns.get("applied.current_A"), Some(&(data.columns.applied.start)));

    // The longest stretch of rows without a command: the stop (a second of a 1 kHz loop).
    let mut gap = 0..0;
    let mut start = None;
    for (row, u) in command.iter().chain([&0.0]).enumerate() {
        match (u.is_nan(), start) {
            (true, None) => start = Some(row),
            (false, Some(s)) => {
                if row - s > gap.len() {
                    gap = s..row;
                }
                start = None;
            }
            _ => {}
        }
    }
    // The stop took effect when the launcher sent it (a tick is due each ms from tick 0): the
    // loops whose commands were not out by then are in the gap too, more of them the further
    // the loop lagged behind its schedule (a loaded machine).
    let stop = r.summary().faults.iter().find(|f| f.kind == FaultKind::Stop).expect("the stop's report");
    let injected_ms = stop.injected_at_ms.expect("the launcher's injection time");
    let (first, last) = (t[gap.start] * 1e3, t[gap.end - 1] * 1e3);
    assert!(
        gap.len() >= 500 && first <= injected_ms.ceil() && last >= injected_ms,
        "no stretch without commands at the stop ({injected_ms:.3} ms after tick 0): {gap:?}"
    );
    // Across the stop the plant applies nothing new: in the rows that have its state (a tick
    // the plant skipped on a loaded machine has neither), each applied value is a command sent
    // before the stop, and once the newest of them has taken effect (on a loaded machine it may
    // arrive ticks into the gap, late) it is held to the end of the stop.
    let before: Vec<f64> = command[..gap.start].iter().filter(|u| u.is_finite()).copied().collect();
    let in_stop: Vec<(usize, f64)> =
        (gap.start..gap.end).filter(|&r| applied[r].is_finite()).map(|r| (r, applied[r])).collect();
    let held = *before.last().expect("commands before the stop");
    let held_from =
        in_stop.iter().position(|(_, u)| *u == held).expect("the newest command before the stop takes effect");
    assert!(
        in_stop[held_from..].iter().all(|(_, u)| *u == held),
        "the applied input changed after the newest command took effect"
    );
    assert!(
        in_stop[..held_from].iter().all(|(_, u)| before.contains(u)),
        "a value applied during the stop was no command: {in_stop:?}"
    );
    let held_row = in_stop[held_from].0;

    let figure = commands_figure(&data);
    let (gap_t0, gap_t1) = (t[gap.start], t[gap.end - 1]);
    let commands: Vec<&Curve> = figure.panels[0].curves.iter().filter(|c| c.label == COMMAND_LABEL).collect();
    assert!(commands.len() >= 2, "the commands before and after the stop are separate runs");
    for curve in &commands {
        for pair in curve.points.windows(2) {
            assert!(
                pair[1].0 <= gap_t0 || pair[0].0 >= gap_t1,
                "a command segment {:?} → {:?} crosses the stop {gap_t0}..{gap_t1}",
                pair[0],
                pair[1]
            );
        }
    }
    // The applied input's steps cover the stop at the held value.
    let applied_points: Vec<(f64, f64)> = figure.panels[0]
        .curves
        .iter()
        .filter(|c| c.label == APPLIED_LABEL)
        .flat_map(|c| c.points.iter().copied())
        .filter(|(at, _)| (t[held_row]..gap_t1).contains(at))
        .collect();
    assert!(!applied_points.is_empty() && applied_points.iter().all(|(_, u)| *u == held), "{applied_points:?}");
    assert_figure(&r.dir.join("commands.png"), 1, false);
}

/// The pixels of `path` in exactly this colour.
fn pixels_of(path: &Path, colour: Colour) -> usize {
    let c = rgb(colour);
    Image::read(path).pixels.iter().filter(|p| **p == [c.0, c.1, c.2]).count()
}

/// A real-time run whose controller is stopped for 300 ms: misses.png's title counts summary.json's
/// deadline misses, the number the report's headline gives; its legend counts loops.csv's misses
/// by the kind of their cause (counted here from loops.csv's text); the PNG has data and crosses
/// in the fault cause's colour, and so has the stop's zoomed figure.
#[test]
fn a_stopped_controllers_misses_are_drawn_in_their_causes_colour() {
    let r = run(
        "plot-misses",
        &["pendulum", "--duration", "1.5", "--fault", "stop controller at 0.5s for 300ms", "--plot"],
    );
    let s = r.summary();
    let headline = format!("deadline misses {} of {}", s.deadline_misses, s.loops);
    assert!(r.stdout().contains(&headline), "no `{headline}` in\n{}", r.stdout());

    let loops = Table::read(&r.dir.join("loops.csv"));
    let (missed, cause) = (loops.columns["deadline_miss"], loops.columns["cause"]);
    let mut by_kind: BTreeMap<String, usize> = BTreeMap::new();
    for row in loops.rows.iter().filter(|row| row[missed] == "1") {
        *by_kind.entry(row[cause].split(':').next().unwrap().to_owned()).or_default() += 1;
    }
    assert!(by_kind.get("fault").is_some_and(|n| *n >= 200), "a 300 ms stop at 1 kHz: {by_kind:?}");

    let data = RunData::read(&r.dir, &looplab_shared::scenarios::builtin()).unwrap();
    let figure = misses_figure(&data).expect("a real-time run's misses figure");
    let counted = format!(": {} deadline misses of {} loops (", s.deadline_misses, s.loops);
    assert!(figure.title.contains(&counted), "no `{counted}` in {}", figure.title);
    let legend: BTreeMap<String, usize> = figure.panels[0]
        .curves
        .iter()
        .filter(|c| c.line == Line::Crosses)
        .map(|c| (c.label.clone(), c.points.len()))
        .collect();
    let expected: BTreeMap<String, usize> = by_kind.iter().map(|(kind, n)| (format!("{kind} ({n})"), *n)).collect();
    assert_eq!(legend, expected);

    let path = r.dir.join(MISSES_FIGURE);
    assert!(r.stdout().contains(&format!("wrote {}", path.display())), "{MISSES_FIGURE} not reported");
    assert_figure(&path, 1, false);
    let fault = CauseKind::Fault.colour();
    assert!(pixels_of(&path, fault) >= MIN_DATA_PIXELS, "no crosses in the fault cause's colour");
    let zoom = r.dir.join("fault-1-stop-controller.png");
    assert_figure(&zoom, 2, false);
    assert!(pixels_of(&zoom, fault) >= MIN_DATA_PIXELS, "the zoom has no crosses in the fault cause's colour");
}

/// A figure of two panels over 0 to 1 s, the second with `second` as its curves, and a fault
/// marked on both.
fn two_panels(second: Vec<Curve>) -> Figure {
    let ramp: Vec<(f64, f64)> = (0..=100).map(|i| (i as f64 / 100.0, (i as f64 / 10.0).sin())).collect();
    Figure {
        title: "two panels".into(),
        panels: vec![
            Panel::new("one", "y", vec![Curve::new("a", ramp, Colour::Series(0), Line::Solid(2))]),
            Panel::new("two", "y", second),
        ],
        x: 0.0..1.0,
        x_desc: "t, s",
        faults: vec![FaultMark { t: 0.5, label: "kill estimator".into() }],
        faults_label: "fault injected",
        caption: None,
    }
}

/// The check itself: a figure with an empty panel (a fault marked on it, its axes drawn) fails
/// it, naming the panel; the same figure with data in both passes; a blank image fails.
#[test]
fn the_figure_check_fails_on_an_empty_panel_and_a_blank_image() {
    let dir = fresh_dir("figure-check");
    std::fs::create_dir_all(&dir).unwrap();
    let path = dir.join("figure.png");
    let truth_only = vec![Curve::new("truth", vec![(0.0, 0.0), (1.0, 1.0)], Colour::Truth, Line::Solid(1))];
    for (second, expected) in [
        (vec![], Err("panel 2 has 0 data pixels".to_string())),
        // The truth's dark line alone is not data that the check can tell from the axes.
        (truth_only, Err("panel 2 has 0 data pixels".to_string())),
        (vec![Curve::new("b", vec![(0.0, 1.0), (1.0, -1.0)], Colour::Series(1), Line::Solid(2))], Ok(())),
    ] {
        let figure = two_panels(second);
        figure.draw(&path).unwrap();
        let image = Image::read(&path);
        assert_eq!(check(&image, &figure.cells()), expected);
        assert!(data_pixels(&image, &figure.cells())[0] > 200, "the first panel's curve");
    }
    let blank = Image { width: 100, height: 100, pixels: vec![[255, 255, 255]; 100 * 100] };
    assert_eq!(check(&blank, &[]), Err("blank: 0 of 10000 pixels drawn".to_string()));
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn a_folder_that_is_not_a_run_is_bad_input() {
    let dir = fresh_dir("plot-not-a-run");
    std::fs::create_dir_all(&dir).unwrap();
    let output = looplab().arg("plot").arg(&dir).output().unwrap();
    assert_eq!(output.status.code(), Some(2));
    assert_eq!(
        String::from_utf8_lossy(&output.stderr),
        format!("error: {}: not a run folder (it has no launch.toml)\n", dir.display())
    );
    assert_eq!(std::fs::read_dir(&dir).unwrap().count(), 0, "nothing is left behind");
    std::fs::remove_dir(&dir).unwrap();

    let output = looplab().args(["plot", "--paper", "nosuch"]).output().unwrap();
    assert_eq!(output.status.code(), Some(2));
    assert_eq!(
        String::from_utf8_lossy(&output.stderr),
        "error: --paper nosuch: no paper figure for it; allowed: pendulum, quadcopter, tiltrotor, fip, tethered\n"
    );
}

/// `looplab plot --paper X` for every scenario with a paper figure: the paper's cases run in
/// lockstep in the process, one run folder each, and each figure is written where it says.
#[test]
fn every_paper_figure_is_drawn() {
    // Each figure's file and its number of panels.
    let cases: [(&str, &[(&str, usize)]); 5] = [
        ("pendulum", &[("paper-003-fig3-angle.png", 1), ("paper-003-fig4-flywheel-speed.png", 1)]),
        ("quadcopter", &[("paper-001-fig17-mass-estimate.png", 1)]),
        ("tiltrotor", &[("paper-004-fig4-x-prior-error.png", 2)]),
        ("fip", &[("paper-000-fig2-speed-thrust.png", 2), ("paper-000-fig4-disturbance-estimate.png", 3)]),
        ("tethered", &[("paper-002-fig8-noise.png", 3)]),
    ];
    std::thread::scope(|s| {
        for (scenario, figures) in cases {
            s.spawn(move || {
                let dir = fresh_dir(&format!("paper-{scenario}"));
                let output = looplab().args(["plot", "--paper", scenario, "--out"]).arg(&dir).output().unwrap();
                let stdout = String::from_utf8_lossy(&output.stdout);
                assert!(output.status.success(), "{scenario}: {stdout}\n{}", String::from_utf8_lossy(&output.stderr));
                for (name, panels) in figures {
                    let path = dir.join(name);
                    assert!(stdout.contains(&format!("wrote {}", path.display())), "{name} not reported:\n{stdout}");
                    assert_figure(&path, *panels, true);
                }
                std::fs::remove_dir_all(&dir).unwrap();
            });
        }
    });
}

/// A declared system's figures: outputs.png draws each state component, the angle against its
/// reference (a step, in the reference's colour), over the window `--from`/`--to` give; a
/// window outside the run is bad input in one line.
#[test]
fn a_declared_system_draws_its_state_against_the_reference_over_a_window() {
    let dir = fresh_dir("plot-declared");
    let out = crate::golden_ci::motor_run_in_process(&dir);
    let plotted = looplab().arg("plot").arg(&out).args(["--from", "0.3", "--to", "1.5"]).output().unwrap();
    assert!(plotted.status.success(), "{}", String::from_utf8_lossy(&plotted.stderr));
    let figure = out.join("outputs.png");
    assert!(String::from_utf8_lossy(&plotted.stdout).contains(&format!("wrote {}", figure.display())));
    assert_figure(&figure, 2, false);
    assert_figure(&out.join("sensors.png"), 2, false);
    // The reference's dashes across the window: far more than the legend's sample.
    assert!(pixels_of(&figure, Colour::Series(1)) > 300, "no reference drawn");
    let outside = looplab().arg("plot").arg(&out).args(["--from", "3"]).output().unwrap();
    assert_eq!(outside.status.code(), Some(2));
    assert_eq!(
        String::from_utf8_lossy(&outside.stderr),
        format!(
            "error: {}: --from 3 s to the end: the window must start within the run (0 to 2 s) and end after it starts\n",
            out.display()
        )
    );
    std::fs::remove_dir_all(&dir).unwrap();
}

/// A FIFO or a link planted where a figure goes: `looplab plot` says which file and why at once
/// (a FIFO no longer blocks it), and writes nothing through the link. The figure is drawn where
/// no one else can reach it and written through one checked descriptor, so there is no moment at
/// which a name swapped for a link is written through.
#[test]
fn a_fifo_or_a_link_where_a_figure_goes_is_refused_at_once() {
    let dir = fresh_dir("plot-planted");
    let out = crate::golden_ci::motor_run_in_process(&dir);
    let figure = out.join("estimate.png");
    let name = std::ffi::CString::new(figure.as_os_str().as_encoded_bytes()).unwrap();
    // SAFETY: a path of our own test folder.
    assert_eq!(unsafe { libc::mkfifo(name.as_ptr(), 0o600) }, 0);
    let plotted = looplab().arg("plot").arg(&out).output().unwrap();
    assert_eq!(plotted.status.code(), Some(1), "{}", String::from_utf8_lossy(&plotted.stderr));
    let said = String::from_utf8_lossy(&plotted.stderr).into_owned();
    assert!(said.contains(&format!("cannot write {}: it is not a regular file", figure.display())), "{said}");
    std::fs::remove_file(&figure).unwrap();
    let victim = dir.join("victim");
    std::fs::write(&victim, b"precious").unwrap();
    std::os::unix::fs::symlink(&victim, &figure).unwrap();
    let plotted = looplab().arg("plot").arg(&out).output().unwrap();
    assert_eq!(plotted.status.code(), Some(1));
    let said = String::from_utf8_lossy(&plotted.stderr).into_owned();
    assert!(said.contains(&format!("cannot write {}: it is a symbolic link", figure.display())), "{said}");
    assert_eq!(std::fs::read(&victim).unwrap(), b"precious");
    std::fs::remove_dir_all(&dir).unwrap();
}

/// A FIFO or a link planted in place of a run folder's file: `plot`, `diff` and `replay` say
/// which file and why at once (a FIFO no longer blocks them), and read nothing through the link.
#[test]
fn a_fifo_or_a_link_in_place_of_a_run_file_is_refused_at_once() {
    let dir = fresh_dir("read-planted");
    let out = crate::golden_ci::motor_run_in_process(&dir);
    let victim = dir.join("victim.json");
    std::fs::copy(out.join("summary.json"), &victim).unwrap();
    let plant = |file: &str, fifo: bool| {
        let path = out.join(file);
        std::fs::rename(&path, dir.join(file)).unwrap();
        if fifo {
            let name = std::ffi::CString::new(path.as_os_str().as_encoded_bytes()).unwrap();
            // SAFETY: a path of our own test folder.
            assert_eq!(unsafe { libc::mkfifo(name.as_ptr(), 0o600) }, 0);
        } else {
            std::os::unix::fs::symlink(&victim, &path).unwrap();
        }
        path
    };
    let restore = |file: &str| {
        std::fs::remove_file(out.join(file)).unwrap();
        std::fs::rename(dir.join(file), out.join(file)).unwrap();
    };
    let out_arg = out.to_str().unwrap();
    let unused = dir.join("unused");
    let unused = unused.to_str().unwrap();
    let export = vec!["export", out_arg, "--mcap", "--force"];
    let cases: [(&str, bool, Vec<&str>, &str); 5] = [
        ("trajectory.csv", true, vec!["plot", out_arg], "it is not a regular file"),
        ("trajectory.csv", false, export.clone(), "it is a symbolic link"),
        ("summary.json", false, vec!["plot", out_arg], "it is a symbolic link"),
        ("trajectory.csv", true, vec!["diff", out_arg, out_arg], "it is not a regular file"),
        (
            "run.mcap",
            true,
            vec!["replay", out_arg, "--stage", "controller", "--out", unused],
            "it is not a regular file",
        ),
    ];
    for (file, fifo, args, expected) in cases {
        let path = plant(file, fifo);
        let output = looplab().args(&args).output().unwrap();
        let said = String::from_utf8_lossy(&output.stderr).into_owned();
        assert_eq!(output.status.code(), Some(2), "{args:?}: {said}");
        assert!(said.contains(&format!("cannot read {}: {expected}", path.display())), "{args:?}: {said}");
        restore(file);
    }
    // The run's launch file too: export would put what it names into the recording it writes.
    let path = plant("launch.toml", false);
    let output = looplab().args(&export).output().unwrap();
    let said = String::from_utf8_lossy(&output.stderr).into_owned();
    assert_eq!(output.status.code(), Some(2), "{said}");
    let expected = format!("{}: cannot read the launch file: it is a symbolic link", path.display());
    assert!(said.contains(&expected), "{said}");
    restore("launch.toml");
    std::fs::remove_dir_all(&dir).unwrap();
}
