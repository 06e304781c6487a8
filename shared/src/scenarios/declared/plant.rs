//! A declared system's plant: a [`Plant`] over a [`PlantModel`] (built in, an FMU, a Python
//! class). LoopLab integrates a model's derivative with RK4, the input held, `substeps` per
//! period ([`Stepping::Derivative`]), or lets it step itself ([`Stepping::OwnStep`]). Its state
//! message is the state, then the declared outputs, computed after each step with the held
//! input. A model error ends the plant's incarnation with its one line.

use anyhow::{Result, anyhow};

use crate::model::plant_model::{PlantModel, Stepping};
use crate::model::scenario::Plant;

pub struct DeclaredPlant {
    model: Box<dyn PlantModel>,
    /// State components; `x[n..]` are the outputs.
    n: usize,
    substeps: u32,
    /// The state message: the state, then the outputs.
    x: Vec<f64>,
    /// RK4's stages and trial point, kept to step without allocating.
    k: [Vec<f64>; 4],
    trial: Vec<f64>,
    /// A restore the model refused, reported by the next step.
    failed: Option<anyhow::Error>,
}

impl DeclaredPlant {
    /// The model from its initial state, with the outputs at t = 0 under a zero input.
    pub fn new(mut model: Box<dyn PlantModel>, outputs: usize, inputs: usize, substeps: u32) -> Result<Self> {
        let state = model.initial_state()?;
        let n = state.len();
        let mut x = state;
        x.resize(n + outputs, 0.0);
        let (xs, ys) = x.split_at_mut(n);
        model.outputs(0.0, xs, &vec![0.0; inputs], ys)?;
        Ok(Self {
            model,
            n,
            substeps: substeps.max(1),
            x,
            k: std::array::from_fn(|_| vec![0.0; n]),
            trial: vec![0.0; n],
            failed: None,
        })
    }

    /// What the model says it is, for reports.
    pub fn describe(&self) -> String {
        self.model.describe()
    }

    /// RK4 over `dt` in `substeps` steps, the same arithmetic in the same order as
    /// `model::integrate::rk4` (so a model with the built-in pendulum's derivative gives its
    /// trajectory bit for bit).
    fn integrate(&mut self, t: f64, u: &[f64], dt: f64) -> Result<()> {
        let h = dt / f64::from(self.substeps);
        let n = self.n;
        let [k1, k2, k3, k4] = &mut self.k;
        let (x, trial) = (&mut self.x[..n], &mut self.trial);
        for i in 0..self.substeps {
            let s = t + f64::from(i) * h;
            self.model.derivative(s, x, u, k1)?;
            for j in 0..n {
                trial[j] = x[j] + k1[j] * (h / 2.0);
            }
            self.model.derivative(s + h / 2.0, trial, u, k2)?;
            for j in 0..n {
                trial[j] = x[j] + k2[j] * (h / 2.0);
            }
            self.model.derivative(s + h / 2.0, trial, u, k3)?;
            for j in 0..n {
                trial[j] = x[j] + k3[j] * h;
            }
            self.model.derivative(s + h, trial, u, k4)?;
            for j in 0..n {
                x[j] += (k1[j] + k2[j] * 2.0 + k3[j] * 2.0 + k4[j]) * (h / 6.0);
            }
        }
        Ok(())
    }
}

impl Plant for DeclaredPlant {
    fn state(&self) -> &[f64] {
        &self.x
    }

    fn step(&mut self, t: f64, u: &[f64], dt: f64) -> Result<()> {
        if let Some(e) = self.failed.take() {
            return Err(e);
        }
        match self.model.stepping() {
            Stepping::Derivative => self.integrate(t, u, dt)?,
            Stepping::OwnStep => self.model.do_step(t, dt, u, &mut self.x[..self.n])?,
        }
        if let Some(bad) = self.x[..self.n].iter().position(|v| !v.is_finite()) {
            return Err(anyhow!("the state is not finite after the step: component {bad} is {}", self.x[bad]));
        }
        let (x, y) = self.x.split_at_mut(self.n);
        self.model.outputs(t + dt, x, u, y)
    }

    /// From the snapshot's state message: the state goes back into the model (the outputs
    /// were computed from it).
    fn restore(&mut self, state: &[f64]) {
        let len = self.x.len();
        self.x.copy_from_slice(&state[..len]);
        if let Err(e) = self.model.set_state(&self.x[..self.n]) {
            self.failed = Some(e.context("the restarted plant cannot go on from its snapshot"));
        }
    }
}

/// A plant whose model could not be built in this process: it has the declared size and fails
/// its first step with the reason (the launcher found no error building it at resolve time).
pub struct FailedPlant {
    pub x: Vec<f64>,
    pub error: String,
}

impl Plant for FailedPlant {
    fn state(&self) -> &[f64] {
        &self.x
    }

    fn step(&mut self, _t: f64, _u: &[f64], _dt: f64) -> Result<()> {
        Err(anyhow!("{}", self.error))
    }

    fn restore(&mut self, state: &[f64]) {
        let len = self.x.len();
        self.x.copy_from_slice(&state[..len]);
    }
}

#[cfg(test)]
mod tests {
    use nalgebra::Vector3;

    use super::*;
    use crate::scenarios::pendulum::params::Model;
    use crate::scenarios::pendulum::plant::PendulumPlant;

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
}
