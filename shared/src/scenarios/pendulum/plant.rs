//! The reaction-wheel pendulum's plant: the nonlinear model of `params.rs` (paper 003 §2) by RK4.
//!
//! State x = (θ, θ̇, φ̇): pendulum angle from the upward vertical, its rate, and the wheel's
//! speed relative to the pendulum. Input: motor current I, torque τ = k·I on the wheel.

use nalgebra::Vector3;

use super::params::Model;
use crate::model::integrate::rk4;
use crate::model::scenario::Plant;

pub struct PendulumPlant {
    pub model: Model,
    pub substeps: u32,
    x: Vector3<f64>,
}

impl PendulumPlant {
    pub fn new(model: Model, substeps: u32, initial: Vector3<f64>) -> Self {
        Self { model, substeps, x: initial }
    }
}

impl Plant for PendulumPlant {
    fn state(&self) -> &[f64] {
        self.x.as_slice()
    }

    fn restore(&mut self, state: &[f64]) {
        self.x = Vector3::from_column_slice(state);
    }

    fn step(&mut self, _t: f64, u: &[f64], dt: f64) -> anyhow::Result<()> {
        let current = u[0];
        self.x = rk4(&|x: &Vector3<f64>| self.model.derivative(x, current), &self.x, dt, self.substeps);
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::super::params::tests::paper_model;
    use super::*;

    #[test]
    fn unforced_motion_conserves_energy() {
        // A large swing (0.3 rad from upright, falling) over 1 s with no torque.
        let m = paper_model();
        let mut plant = PendulumPlant::new(m.clone(), 10, Vector3::new(0.3, 0.0, 5.0));
        let e0 = m.energy(&Vector3::from_column_slice(plant.state()));
        let mut worst: f64 = 0.0;
        for _ in 0..1000 {
            plant.step(0.0, &[0.0], 1e-3).unwrap();
            let e = m.energy(&Vector3::from_column_slice(plant.state()));
            worst = worst.max((e - e0).abs() / e0.abs());
        }
        // The pendulum swings through the bottom (θ passes π), so energy is well exercised.
        assert!(plant.state()[0] > 1.5, "the pendulum should have fallen: θ = {}", plant.state()[0]);
        assert!(worst < 1e-9, "relative energy drift {worst:e}");
    }

    #[test]
    fn rk4_error_falls_with_the_fourth_power_of_the_step() {
        // Forced motion over 0.5 s against a reference with 100× finer steps; halving the step
        // must cut the error by about 2⁴ = 16.
        let m = paper_model();
        let x0 = Vector3::new(0.2, -1.0, 3.0);
        let f = |x: &Vector3<f64>| m.derivative(x, 2.0);
        let reference = rk4(&f, &x0, 0.5, 20_000);
        let error = |steps: u32| (rk4(&f, &x0, 0.5, steps) - reference).norm();
        for steps in [25, 50, 100] {
            let ratio = error(steps) / error(2 * steps);
            assert!((ratio - 16.0).abs() < 1.5, "error ratio {ratio} at {steps} steps");
        }
    }
}
