//! Paper 004, Fig. 4: the x-position a-priori estimation error e_x(i|k) over the first 10 s for
//! each controller, against the paper's ±3.81 cm (99.8 %) bound. Chosen over Fig. 7 (the load's
//! swing) because the text gives this one a number to check against.

use anyhow::Context as _;

use crate::model::figure::{
    Colour, Curve, Figure, Line, NamedFigure, Panel, PaperCase, PaperFigures, PaperTarget, RunColumns, series,
};

/// The paper's bound on the a-priori x error, m: ±3.81 cm with 99.8 % confidence.
const X_ERROR_BOUND_M: f64 = 0.0381;

pub static PAPER: PaperFigures = PaperFigures {
    cases: &[
        PaperCase {
            name: "1-nlls-2l",
            target: PaperTarget::File("1-nlls-2l.toml", include_str!("../../../../launch/tiltrotor/1-nlls-2l.toml")),
            overrides: &["duration_s=10"],
        },
        PaperCase {
            name: "2-nlpt-2l",
            target: PaperTarget::File("2-nlpt-2l.toml", include_str!("../../../../launch/tiltrotor/2-nlpt-2l.toml")),
            overrides: &["duration_s=10"],
        },
    ],
    draw,
};

fn draw(runs: &[&dyn RunColumns]) -> anyhow::Result<Vec<NamedFigure>> {
    let span = runs[0].span();
    let bound = X_ERROR_BOUND_M * 100.0;
    let mut panels = Vec::new();
    let mut within = Vec::new();
    for (i, (run, label)) in runs.iter().zip(["NLLS-2L", "NLPT-2L"]).enumerate() {
        let (x, prior) = (run.state("x").context("no true x")?, run.estimate("x_prior").context("no a-priori x")?);
        let error_cm: Vec<f64> = x.iter().zip(prior).map(|(x, p)| (x - p) * 100.0).collect();
        let points = series(run.t(), &error_cm);
        let inside = points.iter().filter(|p| p.1.abs() <= X_ERROR_BOUND_M * 100.0).count();
        within.push(format!("{label} {:.1} %", 100.0 * inside as f64 / points.len().max(1) as f64));
        // One panel each: the two errors differ by little and would hide each other.
        let curves = vec![
            Curve::new(format!("e_x, {label}"), points, Colour::Series(i), Line::Solid(1)),
            Curve::level("±3.81 cm (99.8 %, the paper)", bound, &span, Colour::Truth),
            Curve::level("±3.81 cm (99.8 %, the paper)", -bound, &span, Colour::Truth),
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
