//! The built-in pass-through estimator: each estimate component is the held reading of the
//! first sensor that reads a component of its name (`[sensors.<name>] reads`). With exact
//! sensors (no noise, bias, quantum or delay, every loop) that is the true state, for a
//! declared system's first run before an estimator of the user's own. The estimator sees only
//! the sensors, as every estimator does.

use crate::contract::msg::SensorReading;
use crate::model::scenario::Estimator;

pub struct PassThrough {
    /// Each estimate component's (sensor, component) in the readings.
    pub picks: Vec<(usize, usize)>,
}

impl Estimator for PassThrough {
    fn update(&mut self, _t: f64, readings: &[SensorReading], _u_applied: &[f64], estimate: &mut [f64]) {
        for (e, &(sensor, component)) in estimate.iter_mut().zip(&self.picks) {
            *e = readings[sensor].value[component];
        }
    }
}
