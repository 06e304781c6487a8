//! Paper 001, Fig. 17: the mass estimate m̂ as 0.045 kg is added in hover (case 7).

use anyhow::Context as _;

use crate::model::figure::{
    Colour, Curve, FaultMark, Figure, Line, NamedFigure, Panel, PaperCase, PaperFigures, PaperTarget, RunColumns,
    series,
};

pub static PAPER: PaperFigures = PaperFigures {
    cases: &[PaperCase {
        name: "7-hover-mass-step",
        target: PaperTarget::File(
            "7-hover-mass-step.toml",
            include_str!("../../../../launch/quadcopter/7-hover-mass-step.toml"),
        ),
        overrides: &[],
    }],
    draw,
};

fn draw(runs: &[&dyn RunColumns]) -> anyhow::Result<Vec<NamedFigure>> {
    let run = runs[0];
    let plant = run.config().document.get("plant");
    let number = |key: &str| plant.and_then(|p| p.get(key)).and_then(|v| v.as_float());
    let step = match (number("mass_step_at_s"), number("mass_step_kg")) {
        (Some(t), Some(kg)) => vec![FaultMark { t, label: format!("+{kg} kg") }],
        _ => vec![],
    };
    let curves = vec![
        Curve::new(
            "estimate of m",
            series(run.t(), run.estimate("mass").context("no mass estimate")?),
            Colour::Series(0),
            Line::Solid(2),
        ),
        Curve::new(
            "m (true)",
            series(run.t(), run.state("mass").context("no true mass")?),
            Colour::Truth,
            Line::Solid(1),
        ),
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
