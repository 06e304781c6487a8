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

    fn freeze(&mut self) -> Result<Option<Vec<u8>>> {
        self.model.freeze()
    }

    /// The model's own frozen state: what a co-simulation FMU, which cannot be set from the
    /// state vector, goes on from. A model that cannot fails its first step with the reason.
    fn thaw(&mut self, frozen: &[u8]) -> Result<()> {
        self.failed = match self.model.thaw(frozen) {
            Ok(()) => None,
            Err(e) => Some(e.context("the restarted plant cannot go on from its model's saved state")),
        };
        Ok(())
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
