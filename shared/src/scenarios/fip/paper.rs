//! Paper 000, Fig. 2 (the estimated load speed and the thrust in the three disturbance cases)
//! and Fig. 4 (b̂ against the stochastic b), from the cases' launch files (120 s each).

use anyhow::Context as _;

use crate::model::figure::{
    Colour, Curve, Figure, Line, NamedFigure, Panel, PaperCase, PaperFigures, PaperTarget, RunColumns, series,
};

pub static PAPER: PaperFigures = PaperFigures {
    cases: &[
        PaperCase {
            name: "2-no-disturbance",
            target: PaperTarget::File(
                "2-no-disturbance.toml",
                include_str!("../../../../launch/fip/2-no-disturbance.toml"),
            ),
            overrides: &[],
        },
        PaperCase {
            name: "3-constant-disturbance",
            target: PaperTarget::File(
                "3-constant-disturbance.toml",
                include_str!("../../../../launch/fip/3-constant-disturbance.toml"),
            ),
            overrides: &[],
        },
        PaperCase {
            name: "4-stochastic-disturbance",
            target: PaperTarget::File(
                "4-stochastic-disturbance.toml",
                include_str!("../../../../launch/fip/4-stochastic-disturbance.toml"),
            ),
            overrides: &[],
        },
    ],
    draw,
};

/// The norm of three columns, row by row.
fn norms(columns: [&[f64]; 3]) -> Vec<f64> {
    (0..columns[0].len()).map(|i| columns.iter().map(|c| c[i] * c[i]).sum::<f64>().sqrt()).collect()
}

fn draw(runs: &[&dyn RunColumns]) -> anyhow::Result<Vec<NamedFigure>> {
    let span = runs[0].span();
    let labels = ["(i) no disturbance", "(ii) constant", "(iii) stochastic"];
    let (mut speed, mut thrust) = (Vec::new(), Vec::new());
    for (i, (run, label)) in runs.iter().zip(labels).enumerate() {
        let column = |name: &str| run.estimate(name).with_context(|| format!("no estimate {name}"));
        let v = norms([column("load_vx_hat")?, column("load_vy_hat")?, column("load_vz_hat")?]);
        speed.push(Curve::new(label, series(run.t(), &v), Colour::Series(i), Line::Solid(1)));
        let t = run.command("thrust").context("no thrust command")?;
        thrust.push(Curve::new(label, series(run.t(), t), Colour::Series(i), Line::Solid(1)));
    }
    speed.push(Curve::level("0.5 m/s, the reference's speed", 0.5, &span, Colour::Truth));
    let fig2 = Figure {
        title: "Paper 000, Fig. 2, reproduced: the estimated load speed and the thrust (lockstep)".into(),
        panels: vec![Panel::new("", "estimated load speed, m/s", speed), Panel::new("", "T, N", thrust)],
        x: span.clone(),
        x_desc: "t, s",
        faults: vec![],
        faults_label: "",
        caption: Some("Figure 2. Estimated load linear speed and thrust, cases (i)–(iii).".into()),
    };

    let stochastic = runs[2];
    let mut panels = Vec::new();
    for axis in ["x", "y", "z"] {
        let truth = stochastic.state(&format!("b_{axis}")).context("no true b")?;
        let estimate = stochastic.estimate(&format!("b_hat_{axis}")).context("no b̂")?;
        let curves = vec![
            Curve::new(
                format!("b_{axis} estimate"),
                series(stochastic.t(), estimate),
                Colour::Series(0),
                Line::Solid(2),
            ),
            Curve::new(format!("b_{axis} (true)"), series(stochastic.t(), truth), Colour::Truth, Line::Solid(1)),
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
