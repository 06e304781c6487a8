//! `looplab plot`: a real five-process run with `--plot` writes its figures as PNG into the run
//! folder; `looplab plot` on something that is not a run folder says so and exits with 2.

mod common;

use common::{fresh_dir, looplab, png_size, run};

#[test]
fn a_real_time_run_with_a_kill_plots_its_figures() {
    let r = run("plot", &["pendulum", "--duration", "1", "--fault", "kill estimator at 0.5s", "--plot"]);
    let stdout = r.stdout();
    // Estimate: four components on a 2×2 grid; commands: one; sensors: two, stacked; tick period: one.
    for (name, size) in [
        ("estimate.png", (920, 624)),
        ("commands.png", (1000, 524)),
        ("sensors.png", (1000, 724)),
        ("tick-period.png", (1000, 524)),
        ("latency-cdf.png", (900, 654)),
    ] {
        let path = r.dir.join(name);
        assert!(stdout.contains(&format!("wrote {}", path.display())), "{name} not reported:\n{stdout}");
        assert_eq!(png_size(&path), size, "{name}");
    }
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
    let cases: [(&str, &[&str]); 5] = [
        ("pendulum", &["paper-003-fig3-angle.png", "paper-003-fig4-flywheel-speed.png"]),
        ("quadcopter", &["paper-001-fig17-mass-estimate.png"]),
        ("tiltrotor", &["paper-004-fig4-x-prior-error.png"]),
        ("fip", &["paper-000-fig2-speed-thrust.png", "paper-000-fig4-disturbance-estimate.png"]),
        ("tethered", &["paper-002-fig8-noise.png"]),
    ];
    std::thread::scope(|s| {
        for (scenario, figures) in cases {
            s.spawn(move || {
                let dir = fresh_dir(&format!("paper-{scenario}"));
                let output = looplab().args(["plot", "--paper", scenario, "--out"]).arg(&dir).output().unwrap();
                let stdout = String::from_utf8_lossy(&output.stdout);
                assert!(output.status.success(), "{scenario}: {stdout}\n{}", String::from_utf8_lossy(&output.stderr));
                for name in figures {
                    let path = dir.join(name);
                    assert!(stdout.contains(&format!("wrote {}", path.display())), "{name} not reported:\n{stdout}");
                    let (width, height) = png_size(&path);
                    assert!(width >= 800 && height >= 500, "{name}: {width}×{height}");
                }
                std::fs::remove_dir_all(&dir).unwrap();
            });
        }
    });
}
