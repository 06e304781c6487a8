//! The built-in `[plant.linear]` model: ẋ = A x + B u, y = C x + D u, a [`PlantModel`] that
//! LoopLab integrates with its RK4 (a declared system's first plant, and its tests').

use anyhow::{Result, bail};

use crate::config::launch::declared::LinearSection;
use crate::model::plant_model::{ModelSpec, PlantModel, Stepping};

pub struct LinearModel {
    m: LinearSection,
    initial: Vec<f64>,
}

impl LinearModel {
    /// The matrices' shapes were checked when the launch file was read.
    pub fn new(m: LinearSection, spec: &ModelSpec) -> Self {
        Self { m, initial: spec.initial.iter().map(|x| x.unwrap_or(0.0)).collect() }
    }
}

/// `out = M v + N w`, row by row, in index order (so the result is the same on every machine).
fn affine(m: &[Vec<f64>], v: &[f64], n: &[Vec<f64>], w: &[f64], out: &mut [f64]) {
    for (i, out) in out.iter_mut().enumerate() {
        let mut sum = 0.0;
        for (a, x) in m[i].iter().zip(v) {
            sum += a * x;
        }
        if let Some(row) = n.get(i) {
            for (b, u) in row.iter().zip(w) {
                sum += b * u;
            }
        }
        *out = sum;
    }
}

impl PlantModel for LinearModel {
    fn describe(&self) -> String {
        let (n, m, p) = (self.m.a.len(), self.m.b.first().map_or(0, Vec::len), self.m.c.len());
        format!("linear state-space model, {n} states, {m} inputs, {p} outputs")
    }

    fn stepping(&self) -> Stepping {
        Stepping::Derivative
    }

    fn initial_state(&mut self) -> Result<Vec<f64>> {
        Ok(self.initial.clone())
    }

    fn derivative(&mut self, _t: f64, x: &[f64], u: &[f64], dx: &mut [f64]) -> Result<()> {
        affine(&self.m.a, x, &self.m.b, u, dx);
        Ok(())
    }

    fn do_step(&mut self, _t: f64, _dt: f64, _u: &[f64], _x: &mut [f64]) -> Result<()> {
        bail!("a linear model is integrated by LoopLab, not stepped by itself")
    }

    fn outputs(&mut self, _t: f64, x: &[f64], u: &[f64], y: &mut [f64]) -> Result<()> {
        affine(&self.m.c, x, &self.m.d, u, y);
        Ok(())
    }

    /// The whole state is the vector: nothing else to restore.
    fn set_state(&mut self, _x: &[f64]) -> Result<()> {
        Ok(())
    }
}
