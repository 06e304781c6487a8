//! Tilt-rotor UAV carrying a suspended load (paper 004: Raffo & de Almeida 2018; note
//! `../shared/papers/004-tiltrotor-suspended-load.md`).
//!
//! - `params`: Table 1, the seeded ±30 % draw, the control-design model (A1);
//! - `dynamics`: the 10-DOF Euler–Lagrange model (17)–(23), differentiated exactly;
//! - `plant`: RK4 with the input held, the external forces on x, y, z;
//! - `sensors`: the 10 Hz position and velocity fix, the angles and rates every tick, the
//!   known translational force;
//! - `estimator`: the LKFUI (Kalman filter with unknown inputs) of section 4;
//! - `controller`: NLLS-2L and NLPT-2L (feedback linearisation, two loops);
//! - `reference`, `disturbance`: the stand-ins for what the paper does not publish;
//! - `metrics`: the paper's RMSE and IAVU, the filter's error percentiles.

pub mod control_model;
pub mod controller;
pub mod disturbance;
pub mod dynamics;
pub mod estimator;
pub mod gains;
pub mod metrics;
pub mod params;
pub mod plant;
pub mod reference;
pub mod sensors;

use crate::model::vectors::{Component, Vectors};

/// q = (x, y, z, φ, θ, ψ, α_R, α_L, γ₁, γ₂) and q̇.
pub const DOF: usize = 10;
pub const STATE_LEN: usize = 2 * DOF;
/// Γ = (f_R, f_L, τ_αR, τ_αL).
pub const INPUTS: usize = 4;

/// Where things are in the state vector.
pub mod state {
    use std::ops::Range;
    pub const POSITION: Range<usize> = 0..3;
    /// φ, θ, ψ.
    pub const ATTITUDE: Range<usize> = 3..6;
    /// α_R, α_L.
    pub const TILT: Range<usize> = 6..8;
    /// γ₁, γ₂.
    pub const LOAD: Range<usize> = 8..10;
    pub const VELOCITY: Range<usize> = 10..13;
    /// The angles' rates (φ̇ … γ̇₂): the `attitude` signal reads q[3..10] then q̇[3..10].
    pub const ANGLES: Range<usize> = 3..10;
    pub const ANGLE_RATES: Range<usize> = 13..20;
}

/// Where things are in the estimate vector: the LKFUI's output, then the measured angles and
/// rates passed through for the controller.
pub mod layout {
    use std::ops::Range;
    /// x̂(i|k): the estimate the controller uses (a posteriori at a correction tick).
    pub const POSITION: Range<usize> = 0..3;
    pub const VELOCITY: Range<usize> = 3..6;
    /// d̂: the unknown translational force, N, held between corrections.
    pub const DISTURBANCE: Range<usize> = 6..9;
    /// The position predicted for this tick before any correction (the a-priori estimate).
    pub const PRIOR_POSITION: Range<usize> = 9..12;
    /// 1 at a tick where a new fix was assimilated, else 0.
    pub const CORRECTED: usize = 12;
    /// How old the newest fix is, s (t − its sample time).
    pub const FIX_AGE: usize = 13;
    /// φ, θ, ψ, α_R, α_L, γ₁, γ₂ then their rates, as the `attitude` signal reads them.
    pub const ANGLES: Range<usize> = 14..21;
    pub const ANGLE_RATES: Range<usize> = 21..28;
    pub const LEN: usize = 28;
}

const fn c(name: &'static str, unit: &'static str) -> Component {
    Component::new(name, unit)
}

/// Concatenates component tables at compile time.
const fn concat<const N: usize>(parts: &[&[Component]]) -> [Component; N] {
    let mut out = [c("", ""); N];
    let (mut i, mut n) = (0, 0);
    while i < parts.len() {
        let mut j = 0;
        while j < parts[i].len() {
            out[n] = parts[i][j];
            (j, n) = (j + 1, n + 1);
        }
        i += 1;
    }
    assert!(n == N, "the parts do not add up to the vector's length");
    out
}

const POSITION: [Component; 3] = [c("x", "m"), c("y", "m"), c("z", "m")];
const VELOCITY: [Component; 3] = [c("vx", "m/s"), c("vy", "m/s"), c("vz", "m/s")];
const ANGLES: [Component; 7] = [
    c("phi", "rad"),
    c("theta", "rad"),
    c("psi", "rad"),
    c("alpha_r", "rad"),
    c("alpha_l", "rad"),
    c("gamma_1", "rad"),
    c("gamma_2", "rad"),
];
const ANGLE_RATES: [Component; 7] = [
    c("phi_dot", "rad/s"),
    c("theta_dot", "rad/s"),
    c("psi_dot", "rad/s"),
    c("alpha_r_dot", "rad/s"),
    c("alpha_l_dot", "rad/s"),
    c("gamma_1_dot", "rad/s"),
    c("gamma_2_dot", "rad/s"),
];
const ATTITUDE_SIGNAL: [Component; 14] = concat(&[&ANGLES, &ANGLE_RATES]);
const FORCE: [Component; 3] = [c("thrust_force_x", "N"), c("thrust_force_y", "N"), c("thrust_force_z", "N")];

const STATE: [Component; STATE_LEN] = concat(&[&POSITION, &ANGLES, &VELOCITY, &ANGLE_RATES]);
const INPUT: [Component; INPUTS] = [c("f_r", "N"), c("f_l", "N"), c("tau_alpha_r", "N·m"), c("tau_alpha_l", "N·m")];
const ESTIMATE: [Component; layout::LEN] = concat(&[
    &[c("x_hat", "m"), c("y_hat", "m"), c("z_hat", "m")],
    &[c("vx_hat", "m/s"), c("vy_hat", "m/s"), c("vz_hat", "m/s")],
    &[c("d_hat_x", "N"), c("d_hat_y", "N"), c("d_hat_z", "N")],
    &[c("x_prior", "m"), c("y_prior", "m"), c("z_prior", "m")],
    &[c("corrected", "1"), c("fix_age", "s")],
    &ANGLES,
    &ANGLE_RATES,
]);

pub static VECTORS: Vectors = Vectors { state: &STATE, input: &INPUT, estimate: &ESTIMATE, signals: sensors::SIGNALS };

