//! The quadcopter's vehicle and actuation (`[model]`): the plant flies it, and the estimator and
//! controller take their nominal values from it, so neither imports the plant.

use serde::Deserialize;

#[derive(Debug, Clone, Copy, PartialEq, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Actuation {
    /// Thrust and body torque act directly (the paper's simulations).
    Torque,
    /// Thrust and a body-rate command; the vehicle's own rate loop tracks it (the lab).
    RateLoop,
}

/// The true vehicle [paper Table 1; §8 for the lab's BLADE 200QX].
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Model {
    pub mass_kg: f64,
    /// Principal moments of inertia j, kg·m² (Assumption 1: J = diag(j)).
    pub inertia_kg_m2: [f64; 3],
    pub g: f64,
    /// Constant external force b in {I}, N.
    pub disturbance_n: [f64; 3],
    pub actuation: Actuation,
    /// Rate loop: time constant τ_r of the first-order lag, s.
    pub rate_loop_time_constant_s: f64,
    /// The command link takes a new command every this many seconds and holds it (0: every tick).
    pub command_period_s: f64,
    /// Accepted command ranges: 0 ≤ T ≤ thrust_max, |τᵢ| ≤ torque_max, |ω_cmd,ᵢ| ≤ rate_max.
    pub thrust_max_n: f64,
    pub torque_max_nm: f64,
    pub rate_max_rad_s: f64,
}

impl Model {
    /// The true parameter vector ξ = (1/m, b/m, ξ₃, 1/j) of (22) for mass m.
    pub fn xi(&self, mass: f64) -> [f64; 10] {
        let [j1, j2, j3] = self.inertia_kg_m2;
        let b = self.disturbance_n;
        [
            1.0 / mass,
            b[0] / mass,
            b[1] / mass,
            b[2] / mass,
            (j2 - j3) / j1,
            (j3 - j1) / j2,
            (j1 - j2) / j3,
            1.0 / j1,
            1.0 / j2,
            1.0 / j3,
        ]
    }
}
