//! A declared system's plant over the built-in pendulum's derivative (`model::declared_plant`).

use nalgebra::Vector3;

use crate::model::declared_plant::*;
use crate::model::plant_model::{PlantModel, Stepping};
use crate::model::scenario::Plant;
use crate::scenarios::pendulum::params::Model;
use crate::scenarios::pendulum::plant::PendulumPlant;
use anyhow::Result;

/// The built-in pendulum's derivative as a plant model of the user's own.
struct PendulumModel(Model);

impl PlantModel for PendulumModel {
    fn describe(&self) -> String {
        "pendulum".into()
    }
    fn stepping(&self) -> Stepping {
        Stepping::Derivative
    }
    fn initial_state(&mut self) -> Result<Vec<f64>> {
        Ok(vec![0.05, 0.0, 0.0])
    }
    fn derivative(&mut self, _t: f64, x: &[f64], u: &[f64], dx: &mut [f64]) -> Result<()> {
        dx.copy_from_slice(self.0.derivative(&Vector3::from_column_slice(x), u[0]).as_slice());
        Ok(())
    }
    fn do_step(&mut self, _t: f64, _dt: f64, _u: &[f64], _x: &mut [f64]) -> Result<()> {
        unreachable!()
    }
    fn outputs(&mut self, _t: f64, x: &[f64], _u: &[f64], y: &mut [f64]) -> Result<()> {
        y[0] = x[0].cos();
        Ok(())
    }
    fn set_state(&mut self, _x: &[f64]) -> Result<()> {
        Ok(())
    }
}

fn model() -> Model {
    let (config, _) = crate::scenarios::resolve("pendulum", &[]).unwrap();
    config.section("model").unwrap()
}

/// The declared plant's RK4 does the built-in one's arithmetic in the same order: a model
/// with the same derivative gives the same bits (what an FMU of the pendulum relies on).
#[test]
fn the_declared_rk4_is_the_builtin_rk4_bit_for_bit() {
    let mut builtin = PendulumPlant::new(model(), 10, Vector3::new(0.05, 0.0, 0.0));
    let mut declared = DeclaredPlant::new(Box::new(PendulumModel(model())), 1, 1, 10).unwrap();
    for k in 0..2000 {
        let u = [((k % 97) as f64 - 48.0) / 10.0];
        builtin.step(k as f64 * 1e-3, &u, 1e-3).unwrap();
        declared.step(k as f64 * 1e-3, &u, 1e-3).unwrap();
        assert_eq!(&declared.state()[..3], builtin.state(), "tick {k}");
        assert_eq!(declared.state()[3], declared.state()[0].cos(), "the output after the state");
    }
}

/// A model error ends the step with its line; a state that is no longer finite too.
#[test]
fn a_failing_or_diverging_model_is_an_error() {
    struct Exploding;
    impl PlantModel for Exploding {
        fn describe(&self) -> String {
            "exploding".into()
        }
        fn stepping(&self) -> Stepping {
            Stepping::Derivative
        }
        fn initial_state(&mut self) -> Result<Vec<f64>> {
            Ok(vec![1.0])
        }
        fn derivative(&mut self, t: f64, x: &[f64], _u: &[f64], dx: &mut [f64]) -> Result<()> {
            if t > 0.5 {
                anyhow::bail!("exploding: no derivative at t = {t}");
            }
            dx[0] = x[0] * 1e308;
            Ok(())
        }
        fn do_step(&mut self, _t: f64, _dt: f64, _u: &[f64], _x: &mut [f64]) -> Result<()> {
            unreachable!()
        }
        fn outputs(&mut self, _t: f64, _x: &[f64], _u: &[f64], _y: &mut [f64]) -> Result<()> {
            Ok(())
        }
        fn set_state(&mut self, _x: &[f64]) -> Result<()> {
            Ok(())
        }
    }
    let mut plant = DeclaredPlant::new(Box::new(Exploding), 0, 1, 1).unwrap();
    let e = plant.step(0.0, &[0.0], 0.1).unwrap_err().to_string();
    assert!(e.contains("not finite"), "{e}");
    let mut plant = DeclaredPlant::new(Box::new(Exploding), 0, 1, 1).unwrap();
    plant.restore(&[0.0]);
    let e = plant.step(0.6, &[0.0], 0.1).unwrap_err().to_string();
    assert_eq!(e, "exploding: no derivative at t = 0.6");
}
