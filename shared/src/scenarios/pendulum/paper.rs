//! Paper 003, Figs. 3 and 4: the pendulum's angle and the flywheel speed, 1 – without bias
//! estimation, 2 – with it, at the paper's δ = 0.1 rad. (Held to the drive's continuous ±5 A the
//! loop without bias estimation did not settle there and the figures used δ = 0.05; at its
//! ±10 A peak it settles at φ̇ = −k₁δ/k₃, tests/pendulum.rs.)

use anyhow::Context as _;

use crate::model::figure::{
    Colour, Curve, Figure, Line, NamedFigure, Panel, PaperCase, PaperFigures, PaperTarget, RunColumns, series,
};

const BIAS: &str = "sensors.encoder.bias=0.1";

pub static PAPER: PaperFigures = PaperFigures {
    cases: &[
        PaperCase {
            name: "1-no-bias",
            target: PaperTarget::Scenario("pendulum"),
            overrides: &["estimator.kind=no-bias", BIAS, "duration_s=12"],
        },
        PaperCase {
            name: "2-bias-observer",
            target: PaperTarget::Scenario("pendulum"),
            overrides: &["estimator.kind=bias-observer", BIAS, "duration_s=12"],
        },
    ],
    draw,
};

fn draw(runs: &[&dyn RunColumns]) -> anyhow::Result<Vec<NamedFigure>> {
    let labels = ["1 – without bias estimation", "2 – with bias estimation"];
    let bias = runs[0].config().sensors.get("encoder").map(|s| s.bias.expand(1)[0]).unwrap_or_default();
    let figure = |state: &str, y_desc: &str, title: &str, caption: &str| -> anyhow::Result<Figure> {
        let curves = runs
            .iter()
            .zip(labels)
            .enumerate()
            .map(|(i, (run, label))| {
                let points = series(run.t(), run.state(state).with_context(|| format!("no state {state}"))?);
                let colour = if i == 0 { Colour::Truth } else { Colour::Series(0) };
                Ok(Curve::new(label, points, colour, Line::Solid(2)))
            })
            .collect::<anyhow::Result<_>>()?;
        Ok(Figure {
            title: format!("Paper 003, {title}, reproduced: encoder bias δ = {bias} rad (the paper: 0.1), lockstep"),
            panels: vec![Panel::new("", y_desc, curves)],
            x: runs[0].span(),
            x_desc: "t, s",
            faults: vec![],
            faults_label: "",
            caption: Some(caption.into()),
        })
    };
    Ok(vec![
        (
            "paper-003-fig3-angle.png",
            figure(
                "theta",
                "pendulum angle, rad",
                "Fig. 3",
                "Figure 3. The angle of the pendulum in two experiments: 1 – without bias estimation, 2 – with bias estimation.",
            )?,
        ),
        (
            "paper-003-fig4-flywheel-speed.png",
            figure(
                "wheel_speed",
                "flywheel speed, rad/s",
                "Fig. 4",
                "Figure 4. The flywheel speed in two experiments: 1 – without bias estimation, 2 – with bias estimation.",
            )?,
        ),
    ])
}
