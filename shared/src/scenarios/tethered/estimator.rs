//! The high-gain observer of section V, from the IMU alone, run twice to resolve the sign of η.
//!
//! With the gyro as an input (u₃ = ω), z = [ϕ + ϑ, ϕ̇, ϕ̈] has the triangular form (18),
//! ż₁ = z₂ + u₃, ż₂ = z₃, ż₃ = σ, and the accelerometer gives z₁ up to π: with
//! η = ‖[a_x, a_z + f_R/m_R]‖ = |f_L|/m_R, w = atan2((a_z + f_R/m_R)/η_s, a_x/η_s) for
//! η_s = ±η (20)–(21). The corrected forms are used: the thrust's specific force is f_R/m_R
//! (the printed a₂u₁ is off by a factor l), σ's first term is −a₁z₂ sin x₁, and atan2 takes
//! (sin, cos). With (22) substituted, σ = z₂³ − (η_s/l)z₂ + a₂(cos z₁ u̇₁ − sin z₁ u₁u₃).
//!
//! Each branch runs (23), ż = Az + Bσ + λ + H·wrap(w − z₁) with H = [α₁/ε, α₂/ε², α₃/ε³],
//! by RK4 over each tick with u₁, u̇₁ held and ω, η, w interpolated between samples, its rate and acceleration saturated against
//! peaking (section V-E.2); (24) takes it back to x̂. The selector of section V-D filters each
//! branch's accelerometer prediction error, ẽ̇ = λ(‖a − â‖ − ẽ), and takes the smaller, with
//! a hysteresis and, optionally, a prior that the vehicle is above the ground
//! (x̂₁ ∈ (0, π)). u₁ and u̇₁ are the controller's compensator states, which reach the estimator
//! through the command.

use std::f64::consts::PI;

use nalgebra::{Vector3, Vector4};
use serde::{Deserialize, Serialize};

use super::layout;
use super::params::Model;
use crate::contract::msg::SensorReading;
use crate::model::integrate::rk4;
use crate::model::poly::{coefficients_of_roots, wrap};
use crate::model::scenario::{Estimator, freeze_value, thaw_value};

/// `[estimator]`.
#[derive(Debug, Clone, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct EstimatorSection {
    /// ε of H.
    pub epsilon: f64,
    /// The roots of s³ + α₁s² + α₂s + α₃ (the observer's poles are these over ε).
    pub roots: [f64; 3],
    pub selector: Selector,
    /// λ, the prediction errors' discount rate, 1/s.
    pub selector_rate_per_s: f64,
    /// The other branch takes over only when its filtered error is this much smaller, m/s².
    pub selector_hysteresis_m_s2: f64,
    /// Never select a branch that puts the vehicle below the ground (x̂₁ ∉ (0, π)) while the
    /// other does not.
    pub ground_prior: bool,
    /// The branch the prediction-error selector starts from.
    pub initial_branch: Branch,
    /// |ẑ₂| ≤ this, rad/s, and |ẑ₃| ≤ acceleration bound, rad/s²: against peaking.
    pub rate_bound_rad_s: f64,
    pub acceleration_bound_rad_s2: f64,
}

#[derive(Debug, Clone, Copy, Deserialize, PartialEq, Eq, strum::Display)]
#[serde(rename_all = "kebab-case")]
#[strum(serialize_all = "kebab-case")]
pub enum Selector {
    /// Section V-D: the branch with the smaller filtered prediction error.
    PredictionError,
    /// Always the branch η_s = +η (f_L > 0, a taut cable).
    Plus,
    Minus,
}

/// One sign of η.
#[derive(Debug, Clone, Copy, Deserialize, PartialEq, Eq, strum::Display)]
#[serde(rename_all = "lowercase")]
#[strum(serialize_all = "lowercase")]
pub enum Branch {
    Plus,
    Minus,
}

/// Where the estimator finds its sensors among the readings.
#[derive(Debug, Clone, Copy)]
pub struct Inputs {
    pub accelerometer: usize,
    pub gyro: usize,
}

/// One sign's observer.
#[derive(Debug, Clone, Copy)]
struct BranchObserver {
    sign: f64,
    z: Vector3<f64>,
    /// x̂₁, x̂₂, x̂₃ from (24).
    x: [f64; 3],
    /// ẽ, m/s².
    prediction_error: f64,
}

/// What the IMU gave at one tick.
#[derive(Debug, Clone, Copy, Serialize, Deserialize)]
struct Sample {
    t: f64,
    u3: f64,
    eta: f64,
    /// w for η_s = +η.
    w: f64,
}

/// The inputs µ of one tick.
#[derive(Debug, Clone, Copy)]
struct Mu {
    u1: f64,
    u1_dot: f64,
    u3: f64,
    /// The thrust's specific force, m/s².
    thrust_accel: f64,
}

pub struct HighGainObserver {
    model: Model,
    section: EstimatorSection,
    inputs: Inputs,
    gains: [f64; 3],
    branches: [BranchObserver; 2],
    active: usize,
    /// The longest RK4 step, s: the reciprocal of the fastest observer pole.
    max_step: f64,
    last: Option<Sample>,
    /// The printed (15): a_z's thrust term a₂u₁ instead of u₁/m_R (tests only).
    printed_thrust_term: bool,
}

impl HighGainObserver {
    pub fn new(model: Model, section: EstimatorSection, inputs: Inputs) -> Self {
        let a = coefficients_of_roots(&section.roots);
        let e = section.epsilon;
        let gains = [a[2] / e, a[1] / (e * e), a[0] / (e * e * e)];
        let branch = |sign| BranchObserver { sign, z: Vector3::zeros(), x: [0.0; 3], prediction_error: 0.0 };
        let minus = section.selector == Selector::Minus
            || (section.selector == Selector::PredictionError && section.initial_branch == Branch::Minus);
        let active = usize::from(minus);
        let fastest = section.roots.iter().map(|r| r.abs()).fold(0.0, f64::max) / e;
        Self {
            max_step: 1.0 / fastest,
            model,
            section,
            inputs,
            gains,
            branches: [branch(1.0), branch(-1.0)],
            active,
            last: None,
            printed_thrust_term: false,
        }
    }

    /// The observer with the paper's printed a_z (a₂u₁ for the thrust), for the test that
    /// shows it makes the loop diverge.
    #[cfg(test)]
    pub fn with_printed_thrust_term(mut self) -> Self {
        self.printed_thrust_term = true;
        self
    }

    /// σ(z, µ) for η_s.
    fn sigma(&self, z: &Vector3<f64>, mu: &Mu, eta_s: f64) -> f64 {
        let (s1, c1) = z[0].sin_cos();
        z[1].powi(3) - eta_s / self.model.link_length_m * z[1] + self.model.a2() * (c1 * mu.u1_dot - s1 * mu.u1 * mu.u3)
    }

    /// (24): x̂ from ẑ.
    fn back_transform(&self, z: &Vector3<f64>, mu: &Mu, eta_s: f64) -> [f64; 3] {
        let m = &self.model;
        let (s1, c1) = z[0].sin_cos();
        let cos_x1 = (z[2] - m.a2() * c1 * mu.u1) / m.a1();
        let sin_x1 = (eta_s / m.link_length_m - z[1] * z[1] - m.a2() * s1 * mu.u1) / m.a1();
        let x1 = sin_x1.atan2(cos_x1);
        [x1, z[1], wrap(z[0] - x1)]
    }

    /// (26): the accelerometer reading the branch predicts.
    fn predicted_accel(&self, x: &[f64; 3], mu: &Mu) -> [f64; 2] {
        let m = &self.model;
        let psi = x[0] + x[2];
        let along_link = m.link_length_m * (x[1] * x[1] + m.a1() * x[0].sin() + m.a2() * psi.sin() * mu.u1);
        [psi.cos() * along_link, psi.sin() * along_link - mu.thrust_accel]
    }

    fn saturate(&self, z: &mut Vector3<f64>) {
        z[0] = wrap(z[0]);
        let (rate, accel) = (self.section.rate_bound_rad_s, self.section.acceleration_bound_rad_s2);
        z[1] = z[1].clamp(-rate, rate);
        z[2] = z[2].clamp(-accel, accel);
    }

    fn select(&mut self) {
        if self.section.selector != Selector::PredictionError {
            return;
        }
        let other = 1 - self.active;
        let above_ground = |b: &BranchObserver| b.x[0] > 0.0 && b.x[0] < PI;
        let (a, o) = (&self.branches[self.active], &self.branches[other]);
        if self.section.ground_prior && above_ground(a) != above_ground(o) {
            if above_ground(o) {
                self.active = other;
            }
            return;
        }
        if o.prediction_error + self.section.selector_hysteresis_m_s2 < a.prediction_error {
            self.active = other;
        }
    }
}

impl Estimator for HighGainObserver {
    fn update(&mut self, t: f64, readings: &[SensorReading], u_applied: &[f64], estimate: &mut [f64]) {
        let accel = [readings[self.inputs.accelerometer].value[0], readings[self.inputs.accelerometer].value[1]];
        let u3 = readings[self.inputs.gyro].value[0];
        let u1 = u_applied[0];
        let thrust_accel = if self.printed_thrust_term { self.model.a2() * u1 } else { u1 / self.model.robot_mass_kg };
        let eta = accel[0].hypot(accel[1] + thrust_accel);
        let now = Sample { t, u3, eta, w: (accel[1] + thrust_accel).atan2(accel[0]) };
        let mu = Mu { u1, u1_dot: u_applied[2], u3, thrust_accel };
        let previous = self.last.replace(now);
        let discount = previous.map_or(0.0, |p| 1.0 - (-self.section.selector_rate_per_s * (t - p.t)).exp());
        for i in 0..2 {
            let mut b = self.branches[i];
            // w of branch −η is w of +η turned by π.
            let turn = if b.sign > 0.0 { 0.0 } else { PI };
            match previous {
                // ẑ(0) = [w, 0, 0].
                None => b.z = Vector3::new(wrap(now.w + turn), 0.0, 0.0),
                // The same instant again: nothing to integrate.
                Some(p) if t <= p.t => {}
                Some(p) => {
                    // Over the tick, ω, η and w go linearly from the last sample to this one;
                    // y = [z, s], s the fraction of the tick.
                    let dt = t - p.t;
                    let h = self.gains;
                    let dw = wrap(now.w - p.w);
                    let f = |y: &Vector4<f64>| {
                        let s = y[3];
                        let z = y.fixed_rows::<3>(0).into_owned();
                        let eta_s = b.sign * (p.eta + s * (now.eta - p.eta));
                        let mu = Mu { u3: p.u3 + s * (now.u3 - p.u3), ..mu };
                        // At f_L = 0, w is undefined: no correction (section V-E.1).
                        let e = if eta_s != 0.0 { wrap(p.w + s * dw + turn - z[0]) } else { 0.0 };
                        Vector4::new(
                            z[1] + mu.u3 + h[0] * e,
                            z[2] + h[1] * e,
                            self.sigma(&z, &mu, eta_s) + h[2] * e,
                            1.0 / dt,
                        )
                    };
                    // Steps of at most 1/(the fastest pole): a gap after skipped ticks or a
                    // restart is crossed as accurately as a tick (RK4 diverges beyond 2.8/pole).
                    let steps = (dt / self.max_step - 1e-9).ceil().max(1.0) as u32;
                    let y = rk4(&f, &Vector4::new(b.z[0], b.z[1], b.z[2], 0.0), dt, steps);
                    b.z = y.fixed_rows::<3>(0).into_owned();
                }
            }
            self.saturate(&mut b.z);
            b.x = self.back_transform(&b.z, &mu, b.sign * eta);
            let predicted = self.predicted_accel(&b.x, &mu);
            let error = (accel[0] - predicted[0]).hypot(accel[1] - predicted[1]);
            b.prediction_error += discount * (error - b.prediction_error);
            self.branches[i] = b;
        }
        self.select();

        let a = &self.branches[self.active];
        estimate[layout::PHI] = a.x[0];
        estimate[layout::PHI_DOT] = a.x[1];
        estimate[layout::THETA] = a.x[2];
        estimate[layout::THETA_DOT] = u3;
        estimate[layout::LINK_FORCE] = a.sign * eta * self.model.robot_mass_kg;
        estimate[layout::ACTIVE_BRANCH] = a.sign;
        for (b, range) in self.branches.iter().zip([layout::PLUS, layout::MINUS]) {
            estimate[range].copy_from_slice(&[b.x[0], b.x[1], b.x[2], b.prediction_error]);
        }
    }

    /// The whole observer, not only slow states: a high-gain observer started afresh in flight
    /// (ẑ₂ = ẑ₃ = 0 while the vehicle moves) peaks, and the loop loses the vehicle (measured with
    /// a kill at 5 s of the nominal run). A restarted estimator goes on from its predecessor's
    /// last update across the outage instead.
    fn freeze(&self) -> Option<Vec<u8>> {
        let last = self.last?;
        let branches: Vec<([f64; 3], f64)> = self.branches.iter().map(|b| (b.z.into(), b.prediction_error)).collect();
        Some(freeze_value(&(branches, self.active, last)))
    }

    fn thaw(&mut self, frozen: &[u8]) -> anyhow::Result<()> {
        let (branches, active, last): (Vec<([f64; 3], f64)>, usize, Sample) = thaw_value(frozen)?;
        for (b, (z, prediction_error)) in self.branches.iter_mut().zip(branches) {
            (b.z, b.prediction_error) = (Vector3::from(z), prediction_error);
        }
        (self.active, self.last) = (active, Some(last));
        Ok(())
    }
}
