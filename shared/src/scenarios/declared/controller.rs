//! The built-in `[controller]` of a declared system: static state feedback u = −K x̂, clamped
//! to the input's limits. For a first run; a controller of the user's own is a stage
//! (`[stages.controller]`).

use crate::model::scenario::Controller;

pub struct StateFeedback {
    /// One row per input, one column per estimate component.
    pub gains: Vec<Vec<f64>>,
    pub limits: Vec<(f64, f64)>,
}

impl Controller for StateFeedback {
    fn update(&mut self, _t: f64, estimate: &[f64], command: &mut [f64]) {
        for ((u, row), (min, max)) in command.iter_mut().zip(&self.gains).zip(&self.limits) {
            let mut sum = 0.0;
            for (k, x) in row.iter().zip(estimate) {
                sum += k * x;
            }
            *u = (-sum).clamp(*min, *max);
        }
    }
}

/// No built-in controller runs: `[stages.controller]` runs the user's in its place.
pub struct NoController;

impl Controller for NoController {
    fn update(&mut self, _t: f64, _estimate: &[f64], command: &mut [f64]) {
        command.fill(0.0);
    }
}
