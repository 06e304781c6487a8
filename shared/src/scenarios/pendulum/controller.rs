//! The pendulum's control law (paper 003 §2): I = −K (X − X_d) with X = (θ, θ̇, φ̇) and X_d the
//! upright setpoint, saturated to the motor controller's current limit.

use nalgebra::{RowVector3, Vector3};

use super::reference::Upright;
use crate::model::reference::Reference;
use crate::model::scenario::Controller;

pub struct StateFeedback {
    pub gains: RowVector3<f64>,
    pub current_limit: f64,
    pub reference: Upright,
}

impl Controller for StateFeedback {
    fn update(&mut self, t: f64, estimate: &[f64], command: &mut [f64]) {
        let x = Vector3::new(estimate[0], estimate[1], estimate[2]) - self.reference.at(t);
        let current = -(self.gains * x)[0];
        command[0] = current.clamp(-self.current_limit, self.current_limit);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn law_and_saturation() {
        let mut c =
            StateFeedback { gains: RowVector3::new(-378.0, -55.0, -1.0), current_limit: 5.0, reference: Upright };
        let mut u = [0.0];
        c.update(0.0, &[0.001, 0.01, 2.0, 0.0], &mut u);
        assert!((u[0] - (0.378 + 0.55 + 2.0)).abs() < 1e-12);
        c.update(0.0, &[0.1, 0.0, 0.0, 0.0], &mut u);
        assert_eq!(u[0], 5.0);
        c.update(0.0, &[-0.1, 0.0, 0.0, 0.0], &mut u);
        assert_eq!(u[0], -5.0);
    }
}
