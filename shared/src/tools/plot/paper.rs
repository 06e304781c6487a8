//! `looplab plot --paper SCENARIO`: a figure of the paper behind a scenario, reproduced. Runs
//! the paper's launch files in lockstep in this process (a run folder each, under the output
//! folder), then draws what the paper's figure shows, with its curves numbered and its caption
//! as the paper words them.

use std::path::{Path, PathBuf};

use anyhow::Context as _;

use crate::config::launch::Override;
use crate::launcher::create_run_dir;
use crate::launcher::in_process::run_in_process;
use crate::model::reference::Reference as _;
use crate::scenarios;
use crate::tools::ToolError;
use crate::tools::plot::colour;
use crate::tools::plot::run::{Curve, FaultMark, Figure, Line, Panel, RunData, TRUTH, series};

/// The scenarios with a paper figure.
pub const SCENARIOS: [&str; 5] = ["pendulum", "quadcopter", "tiltrotor", "fip", "tethered"];

/// Where a run's launch file comes from.
enum Target {
    /// The scenario's built-in defaults.
    Scenario(&'static str),
    /// A launch file of the repository, compiled in so that the command works anywhere: (its
    /// name, its text).
    File(&'static str, &'static str),
}

/// One run of a paper's experiment.
struct Case {
    /// Its run folder's name under the output folder.
    name: &'static str,
    target: Target,
    /// Overrides on top of the launch file (every case runs in lockstep).
    overrides: &'static [&'static str],
}

impl Case {
    /// Runs the case in this process into `out/<name>` and reads the run folder back.
    fn run(&self, out: &Path) -> anyhow::Result<RunData> {
        let overrides = std::iter::once(&"mode=lockstep")
            .chain(self.overrides)
            .map(|text| Override::parse(text))
            .collect::<Result<Vec<_>, _>>()?;
        let resolved = match self.target {
            Target::Scenario(name) => scenarios::resolve(name, &overrides),
            Target::File(file, text) => {
                let path = out.join(file);
                std::fs::write(&path, text).with_context(|| format!("write {}", path.display()))?;
                scenarios::resolve(&path.to_string_lossy(), &overrides)
            }
        };
        let (config, scenario) = resolved?;
        let dir = create_run_dir(Some(&out.join(self.name)), &config.scenario)?;
        println!("running {} ({}, {} s in lockstep) ...", self.name, scenario.title(), config.duration_s);
        run_in_process(&config, scenario.as_ref(), &dir)?;
        RunData::read(&dir).map_err(|e| match e {
            ToolError::BadInput(why) => anyhow::anyhow!(why),
            ToolError::Failed(e) => e,
        })
    }
}

/// Runs the experiments behind `scenario`'s paper figure into `out` (a new or empty folder; by
/// default `runs/<time>-paper-<scenario>`) and draws the figures there. Returns their paths.
pub fn paper_figures(scenario: &str, out: Option<&Path>) -> Result<Vec<PathBuf>, ToolError> {
    if !SCENARIOS.contains(&scenario) {
        return Err(ToolError::BadInput(format!(
            "--paper {scenario}: no paper figure for it; allowed: {}",
            SCENARIOS.join(", ")
        )));
    }
    let out = match out {
        Some(dir) => {
            if dir.exists() && std::fs::read_dir(dir).map(|mut d| d.next().is_some()).unwrap_or(true) {
                return Err(ToolError::BadInput(format!(
                    "--out {}: exists and is not an empty folder; give a new or empty folder",
                    dir.display()
                )));
            }
            dir.to_path_buf()
        }
        None => {
            PathBuf::from("runs").join(format!("{}-paper-{scenario}", chrono::Local::now().format("%Y%m%d-%H%M%S")))
        }
    };
    std::fs::create_dir_all(&out).with_context(|| format!("create {}", out.display()))?;
    let figures = match scenario {
        "pendulum" => pendulum(&out)?,
        "quadcopter" => quadcopter(&out)?,
        "tiltrotor" => tiltrotor(&out)?,
        "fip" => fip(&out)?,
        _ => tethered(&out)?,
    };
    let mut written = Vec::new();
    for (name, figure) in figures {
        let path = out.join(name);
        figure.draw(&path)?;
        written.push(path);
    }
    Ok(written)
}

/// A figure and its file's name.
type Named = (&'static str, Figure);

/// Paper 003, Figs. 3 and 4: the pendulum's angle and the flywheel speed, 1 – without bias
/// estimation, 2 – with it. At the paper's δ = 0.1 rad the loop without bias estimation does
/// not settle here (the wheel runs away), so δ = 0.05 rad, where the paper's law
/// φ̇ = −k₁δ/k₃ holds (tests/pendulum.rs).
fn pendulum(out: &Path) -> anyhow::Result<Vec<Named>> {
    const BIAS: &str = "sensors.encoder.bias=0.05";
    let cases = [
        Case {
            name: "1-no-bias",
            target: Target::Scenario("pendulum"),
            overrides: &["estimator.kind=no-bias", BIAS, "duration_s=12"],
        },
        Case {
            name: "2-bias-observer",
            target: Target::Scenario("pendulum"),
            overrides: &["estimator.kind=bias-observer", BIAS, "duration_s=12"],
        },
    ];
    let runs = cases.iter().map(|c| c.run(out)).collect::<anyhow::Result<Vec<_>>>()?;
    let labels = ["1 – without bias estimation", "2 – with bias estimation"];
    let bias = runs[0].config.sensors.get("encoder").map(|s| s.bias.expand(1)[0]).unwrap_or_default();
    let figure = |state: &str, y_desc: &str, title: &str, caption: &str| {
        let curves = runs
            .iter()
            .zip(labels)
            .enumerate()
            .map(|(i, (run, label))| {
                let points = series(run.t(), run.state(state).expect("the pendulum's state"));
                Curve::new(label, points, if i == 0 { TRUTH } else { colour(0) }, Line::Solid(2))
            })
            .collect();
        Figure {
            title: format!("Paper 003, {title}, reproduced: encoder bias δ = {bias} rad (the paper: 0.1), lockstep"),
            panels: vec![Panel::new("", y_desc, curves)],
            x: runs[0].span(),
            x_desc: "t, s",
            faults: vec![],
            faults_label: "",
            caption: Some(caption.into()),
        }
    };
    Ok(vec![
        (
            "paper-003-fig3-angle.png",
            figure(
                "theta",
                "pendulum angle, rad",
                "Fig. 3",
                "Figure 3. The angle of the pendulum in two experiments: 1 – without bias estimation, 2 – with bias estimation.",
            ),
        ),
        (
            "paper-003-fig4-flywheel-speed.png",
            figure(
                "wheel_speed",
                "flywheel speed, rad/s",
                "Fig. 4",
                "Figure 4. The flywheel speed in two experiments: 1 – without bias estimation, 2 – with bias estimation.",
            ),
        ),
    ])
}

/// Paper 001, Fig. 17: the mass estimate m̂ as 0.045 kg is added in hover (case 7).
fn quadcopter(out: &Path) -> anyhow::Result<Vec<Named>> {
    let case = Case {
        name: "7-hover-mass-step",
        target: Target::File(
            "7-hover-mass-step.toml",
            include_str!("../../../../launch/quadcopter/7-hover-mass-step.toml"),
        ),
        overrides: &[],
    };
    let run = case.run(out)?;
    let plant = run.config.document.get("plant");
    let number = |key: &str| plant.and_then(|p| p.get(key)).and_then(|v| v.as_float());
    let step = match (number("mass_step_at_s"), number("mass_step_kg")) {
        (Some(t), Some(kg)) => vec![FaultMark { t, label: format!("+{kg} kg") }],
        _ => vec![],
    };
    let curves = vec![
        Curve::new(
            "estimate of m",
            series(run.t(), run.estimate("mass").expect("a mass estimate")),
            colour(0),
            Line::Solid(2),
        ),
        Curve::new("m (true)", series(run.t(), run.state("mass").expect("a true mass")), TRUTH, Line::Solid(1)),
    ];
    let figure = Figure {
        title: "Paper 001, Fig. 17, reproduced: the mass estimate as weight is added in hover (case 7, lockstep)"
            .into(),
        panels: vec![Panel::new("", "mass, kg", curves)],
        x: run.span(),
        x_desc: "t, s",
        faults: step,
        faults_label: "weight added",
        caption: Some("Figure 17. Time evolution of the estimate of m (m-hat).".into()),
    };
    Ok(vec![("paper-001-fig17-mass-estimate.png", figure)])
}

/// The paper's bound on the a-priori x error, m: ±3.81 cm with 99.8 % confidence.
const X_ERROR_BOUND_M: f64 = 0.0381;

/// Paper 004, Fig. 4: the x-position a-priori estimation error e_x(i|k) over the first 10 s for
/// each controller, against the paper's ±3.81 cm (99.8 %) bound. Chosen over Fig. 7 (the load's
/// swing) because the text gives this one a number to check against.
fn tiltrotor(out: &Path) -> anyhow::Result<Vec<Named>> {
    let cases = [
        Case {
            name: "1-nlls-2l",
            target: Target::File("1-nlls-2l.toml", include_str!("../../../../launch/tiltrotor/1-nlls-2l.toml")),
            overrides: &["duration_s=10"],
        },
        Case {
            name: "2-nlpt-2l",
            target: Target::File("2-nlpt-2l.toml", include_str!("../../../../launch/tiltrotor/2-nlpt-2l.toml")),
            overrides: &["duration_s=10"],
        },
    ];
    let runs = cases.iter().map(|c| c.run(out)).collect::<anyhow::Result<Vec<_>>>()?;
    let span = runs[0].span();
    let bound = X_ERROR_BOUND_M * 100.0;
    let mut panels = Vec::new();
    let mut within = Vec::new();
    for (i, (run, label)) in runs.iter().zip(["NLLS-2L", "NLPT-2L"]).enumerate() {
        let (x, prior) = (run.state("x").expect("a true x"), run.estimate("x_prior").expect("an a-priori x"));
        let error_cm: Vec<f64> = x.iter().zip(prior).map(|(x, p)| (x - p) * 100.0).collect();
        let points = series(run.t(), &error_cm);
        let inside = points.iter().filter(|p| p.1.abs() <= X_ERROR_BOUND_M * 100.0).count();
        within.push(format!("{label} {:.1} %", 100.0 * inside as f64 / points.len().max(1) as f64));
        // One panel each: the two errors differ by little and would hide each other.
        let curves = vec![
            Curve::new(format!("e_x, {label}"), points, colour(i), Line::Solid(1)),
            Curve::level("±3.81 cm (99.8 %, the paper)", bound, &span, TRUTH),
            Curve::level("±3.81 cm (99.8 %, the paper)", -bound, &span, TRUTH),
        ];
        panels.push(Panel::new(label, "e_x = x − x_prior, cm", curves));
    }
    let figure = Figure {
        title: format!("Paper 004, Fig. 4, reproduced: within ±3.81 cm: {} (lockstep)", within.join(", ")),
        panels,
        x: span,
        x_desc: "t, s",
        faults: vec![],
        faults_label: "",
        caption: Some("Figure 4. Position estimation error in x (a priori), the first ten seconds.".into()),
    };
    Ok(vec![("paper-004-fig4-x-prior-error.png", figure)])
}

/// The norm of three columns, row by row.
fn norms(columns: [&[f64]; 3]) -> Vec<f64> {
    (0..columns[0].len()).map(|i| columns.iter().map(|c| c[i] * c[i]).sum::<f64>().sqrt()).collect()
}

/// Paper 000, Fig. 2 (the estimated load speed and the thrust in the three disturbance cases)
/// and Fig. 4 (b̂ against the stochastic b), from the cases' launch files (120 s each).
fn fip(out: &Path) -> anyhow::Result<Vec<Named>> {
    let cases = [
        Case {
            name: "2-no-disturbance",
            target: Target::File("2-no-disturbance.toml", include_str!("../../../../launch/fip/2-no-disturbance.toml")),
            overrides: &[],
        },
        Case {
            name: "3-constant-disturbance",
            target: Target::File(
                "3-constant-disturbance.toml",
                include_str!("../../../../launch/fip/3-constant-disturbance.toml"),
            ),
            overrides: &[],
        },
        Case {
            name: "4-stochastic-disturbance",
            target: Target::File(
                "4-stochastic-disturbance.toml",
                include_str!("../../../../launch/fip/4-stochastic-disturbance.toml"),
            ),
            overrides: &[],
        },
    ];
    let runs = cases.iter().map(|c| c.run(out)).collect::<anyhow::Result<Vec<_>>>()?;
    let span = runs[0].span();
    let labels = ["(i) no disturbance", "(ii) constant", "(iii) stochastic"];
    let (mut speed, mut thrust) = (Vec::new(), Vec::new());
    for (i, (run, label)) in runs.iter().zip(labels).enumerate() {
        let column = |name: &str| run.estimate(name).with_context(|| format!("no estimate {name}"));
        let v = norms([column("load_vx_hat")?, column("load_vy_hat")?, column("load_vz_hat")?]);
        speed.push(Curve::new(label, series(run.t(), &v), colour(i), Line::Solid(1)));
        let t = run.command("thrust").context("no thrust command")?;
        thrust.push(Curve::new(label, series(run.t(), t), colour(i), Line::Solid(1)));
    }
    speed.push(Curve::level("0.5 m/s, the reference's speed", 0.5, &span, TRUTH));
    let fig2 = Figure {
        title: "Paper 000, Fig. 2, reproduced: the estimated load speed and the thrust (lockstep)".into(),
        panels: vec![Panel::new("", "estimated load speed, m/s", speed), Panel::new("", "T, N", thrust)],
        x: span.clone(),
        x_desc: "t, s",
        faults: vec![],
        faults_label: "",
        caption: Some("Figure 2. Estimated load linear speed and thrust, cases (i)–(iii).".into()),
    };

    let stochastic = &runs[2];
    let mut panels = Vec::new();
    for axis in ["x", "y", "z"] {
        let truth = stochastic.state(&format!("b_{axis}")).context("no true b")?;
        let estimate = stochastic.estimate(&format!("b_hat_{axis}")).context("no b̂")?;
        let curves = vec![
            Curve::new(format!("b_{axis} estimate"), series(stochastic.t(), estimate), colour(0), Line::Solid(2)),
            Curve::new(format!("b_{axis} (true)"), series(stochastic.t(), truth), TRUTH, Line::Solid(1)),
        ];
        panels.push(Panel::new("", format!("b_{axis}, N"), curves));
    }
    let fig4 = Figure {
        title: "Paper 000, Fig. 4, reproduced: the estimate of b against the stochastic b, case (iii) (lockstep)"
            .into(),
        panels,
        x: span,
        x_desc: "t, s",
        faults: vec![],
        faults_label: "",
        caption: Some("Figure 4. The disturbance estimate under the stochastic disturbance (71).".into()),
    };
    Ok(vec![("paper-000-fig2-speed-thrust.png", fig2), ("paper-000-fig4-disturbance-estimate.png", fig4)])
}

/// Paper 002, Fig. 8: Γb with a noisy IMU and reduced gains (launch/tethered/6-noise.toml):
/// the outputs ϕ and f_L against their references and the observer's estimates, and the
/// uncontrolled attitude ϑ.
fn tethered(out: &Path) -> anyhow::Result<Vec<Named>> {
    let case = Case {
        name: "6-noise",
        target: Target::File("6-noise.toml", include_str!("../../../../launch/tethered/6-noise.toml")),
        overrides: &[],
    };
    let run = case.run(out)?;
    let mut reference = crate::scenarios::tethered::Tethered::from_config(&run.config)?.reference();
    let t = run.t();
    let desired: Vec<_> = t.iter().map(|&t| reference.at(t)).collect();
    let state = |name: &str| run.state(name).with_context(|| format!("no state {name}"));
    let estimate = |name: &str| run.estimate(name).with_context(|| format!("no estimate {name}"));
    let degrees = |values: &[f64]| values.iter().map(|v| v.to_degrees()).collect::<Vec<_>>();
    let phi_desired: Vec<f64> = desired.iter().map(|d| d.phi[0].to_degrees()).collect();
    let force_desired: Vec<f64> = desired.iter().map(|d| d.second[0]).collect();
    let panel = |y_desc: &str, truth: Vec<f64>, estimate: Vec<f64>, wanted: Option<Vec<f64>>| {
        let mut curves = vec![
            Curve::new("estimate", series(t, &estimate), colour(0), Line::Solid(1)),
            Curve::new("true", series(t, &truth), TRUTH, Line::Solid(2)),
        ];
        if let Some(wanted) = wanted {
            curves.push(Curve::new("reference", series(t, &wanted), colour(1), Line::Dashed));
        }
        Panel::new("", y_desc, curves)
    };
    let panels = vec![
        panel("ϕ, degrees", degrees(state("phi")?), degrees(estimate("phi")?), Some(phi_desired)),
        panel("f_L, N", state("link_force")?.to_vec(), estimate("link_force")?.to_vec(), Some(force_desired)),
        panel("ϑ, degrees", degrees(state("theta")?), degrees(estimate("theta")?), None),
    ];
    let fig8 = Figure {
        title: "Paper 002, Fig. 8, reproduced: Γb with a noisy IMU, ε = 0.5 and halved poles (lockstep)".into(),
        panels,
        x: run.span(),
        x_desc: "t, s",
        faults: vec![],
        faults_label: "",
        caption: Some("Figure 8. Controller Γb: noisy measurements.".into()),
    };
    Ok(vec![("paper-002-fig8-noise.png", fig8)])
}
