//! The built-in `[controller]` of a declared system: static state feedback u = −K (x̂ − r),
//! clamped to the input's limits, r each estimate component's reference (`[reference]` of the
//! state or output component of its name; zero without one). For a first run; a controller of
//! the user's own is a stage (`[stages.controller]`).

use crate::model::reference::Signal;
use crate::model::scenario::Controller;

pub struct StateFeedback {
    /// One row per input, one column per estimate component.
    pub gains: Vec<Vec<f64>>,
    pub limits: Vec<(f64, f64)>,
    /// Per estimate component, its reference (None: zero).
    pub setpoints: Vec<Option<Signal>>,
}

impl Controller for StateFeedback {
    fn update(&mut self, t: f64, estimate: &[f64], command: &mut [f64]) {
        let error: Vec<f64> =
            (estimate.iter().zip(&self.setpoints)).map(|(x, r)| x - r.as_ref().map_or(0.0, |r| r.at(t))).collect();
        for ((u, row), (min, max)) in command.iter_mut().zip(&self.gains).zip(&self.limits) {
            let mut sum = 0.0;
            for (k, e) in row.iter().zip(&error) {
                sum += k * e;
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
