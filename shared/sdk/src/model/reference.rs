//! The reference: where a scenario's system should be at each instant. It is computed in one
//! place per scenario, so that what the controller tracks is exactly what the metrics and the
//! fault reports' error measure judge against.

/// A scenario's reference trajectory (a setpoint is a constant one).
pub trait Reference: Send {
    /// What the controller tracks at one instant: a setpoint, or a point with its derivatives.
    type Point;
    /// The reference at simulation time `t`.
    fn at(&mut self, t: f64) -> Self::Point;
    /// How far true state `x` is from the reference at `t`, in the units of the scenario's
    /// error measure.
    fn error(&mut self, t: f64, x: &[f64]) -> f64;
}
