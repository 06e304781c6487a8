//! Paper 002, Fig. 8: Γb with a noisy IMU and reduced gains (launch/tethered/6-noise.toml):
//! the outputs ϕ and f_L against their references and the observer's estimates, and the
//! uncontrolled attitude ϑ.

use anyhow::Context as _;

use super::Tethered;
use crate::model::figure::{
    Colour, Curve, Figure, Line, NamedFigure, Panel, PaperCase, PaperFigures, PaperTarget, RunColumns, series,
};
use crate::model::reference::Reference as _;

pub static PAPER: PaperFigures = PaperFigures {
    cases: &[PaperCase {
        name: "6-noise",
        target: PaperTarget::File("6-noise.toml", include_str!("../../../../launch/tethered/6-noise.toml")),
        overrides: &[],
    }],
    draw,
};

fn draw(runs: &[&dyn RunColumns]) -> anyhow::Result<Vec<NamedFigure>> {
    let run = runs[0];
    let mut reference = Tethered::from_config(run.config())?.reference();
    let t = run.t();
    let desired: Vec<_> = t.iter().map(|&t| reference.at(t)).collect();
    let state = |name: &str| run.state(name).with_context(|| format!("no state {name}"));
    let estimate = |name: &str| run.estimate(name).with_context(|| format!("no estimate {name}"));
    let degrees = |values: &[f64]| values.iter().map(|v| v.to_degrees()).collect::<Vec<_>>();
    let phi_desired: Vec<f64> = desired.iter().map(|d| d.phi[0].to_degrees()).collect();
    let force_desired: Vec<f64> = desired.iter().map(|d| d.second[0]).collect();
    let panel = |y_desc: &str, truth: Vec<f64>, estimate: Vec<f64>, wanted: Option<Vec<f64>>| {
        let mut curves = vec![
            Curve::new("estimate", series(t, &estimate), Colour::Series(0), Line::Solid(1)),
            Curve::new("true", series(t, &truth), Colour::Truth, Line::Solid(2)),
        ];
        if let Some(wanted) = wanted {
            curves.push(Curve::new("reference", series(t, &wanted), Colour::Series(1), Line::Dashed));
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
