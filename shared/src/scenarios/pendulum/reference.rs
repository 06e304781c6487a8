//! The pendulum's reference: upright and still, X_d = (θ, θ̇, φ̇) = 0. The controller feeds back
//! X − X_d, and the metrics and the fault reports measure |θ − θ_d|.

use nalgebra::Vector3;

use crate::model::reference::Reference;

/// The upright equilibrium, a constant setpoint.
#[derive(Debug, Clone, Copy, Default)]
pub struct Upright;

impl Reference for Upright {
    /// X_d = (θ, θ̇, φ̇).
    type Point = Vector3<f64>;

    fn at(&mut self, _t: f64) -> Vector3<f64> {
        Vector3::zeros()
    }

    /// |θ − θ_d|, rad.
    fn error(&mut self, t: f64, x: &[f64]) -> f64 {
        (x[0] - self.at(t)[0]).abs()
    }
}
