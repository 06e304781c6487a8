//! The flatness-based controllers of section IV with the observer's estimate (section V-C):
//!
//! - Γa′ (9): outputs ϕ and ϑ, thrust extended once. [ϕ⁽³⁾, ϑ̈] = b̄ᵃ + Eᵃ[u̇₁, τ_R] with
//!   b̄ᵃ = [−a₁ sin x₁ x₂ − a₂ sin ψ ψ̇ u₁, 0], Eᵃ = diag(a₂ cos ψ, a₃), ψ = x₁ + x₃; singular at
//!   ψ = π/2 + kπ.
//! - Γb (10)–(11): outputs ϕ and f_L, thrust extended twice. [ϕ⁽⁴⁾, f̈_L] = bᵇ + Eᵇ[ü₁, τ_R]
//!   with a re-derived bᵇ and Eᵇ = [[a₂ cos ψ, −a₂a₃ sin ψ u₁], [sin ψ, a₃ cos ψ u₁]]; singular at
//!   u₁ = 0.
//!
//! Each output's error follows the linear dynamics of its poles. u₁ (and u̇₁ for Γb) are the
//! compensator's states, integrated here exactly over each tick; the command carries them to
//! the plant and to the estimator: [f_R, τ_R, ḟ_R]. The derivatives of ϕ come from the model
//! at the estimated state (the design is a state feedback), so they carry the nominal
//! parameters' error.

use serde::Deserialize;

use super::law::Law;
use super::layout;
use super::params::Model;
use super::reference::{Point, TetheredReference};
use crate::model::poly::coefficients_of_roots;
use crate::model::reference::Reference;
use crate::model::scenario::{Controller, freeze_value, thaw_value};

/// `[controller]`.
#[derive(Debug, Clone, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct ControllerSection {
    pub law: Law,
    pub gamma_a: GammaAPoles,
    pub gamma_b: GammaBPoles,
}

#[derive(Debug, Clone, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct GammaAPoles {
    pub phi_poles: [f64; 3],
    pub theta_poles: [f64; 2],
}

#[derive(Debug, Clone, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct GammaBPoles {
    pub phi_poles: [f64; 4],
    pub link_force_poles: [f64; 2],
}

/// The state and the derivatives both laws use, at x̂ and the compensator's u₁, u̇₁.
struct Derivatives {
    psi: f64,
    psi_dot: f64,
    /// ϕ̈ = a₁ cos x₁ + a₂ cos ψ u₁.
    phi_ddot: f64,
}

/// Σ cᵢ (y_d⁽ⁱ⁾ − y⁽ⁱ⁾) + y_d⁽ⁿ⁾: the new input that gives the error the poles' dynamics.
fn linear_input(coefficients: &[f64], desired: &[f64], actual: &[f64]) -> f64 {
    let n = coefficients.len();
    desired[n] + coefficients.iter().enumerate().map(|(i, c)| c * (desired[i] - actual[i])).sum::<f64>()
}

pub struct FlatnessController {
    law: Law,
    model: Model,
    phi_gains: Vec<f64>,
    second_gains: Vec<f64>,
    reference: TetheredReference,
    /// The compensator: u₁ = f_R, u̇₁, and the last ü₁ (Γb).
    u1: f64,
    u1_dot: f64,
    u1_ddot: f64,
    last_t: Option<f64>,
}

impl FlatnessController {
    pub fn new(section: &ControllerSection, model: Model, reference: TetheredReference, initial_thrust: f64) -> Self {
        let (phi, second) = match section.law {
            Law::GammaA => (section.gamma_a.phi_poles.to_vec(), section.gamma_a.theta_poles.to_vec()),
            Law::GammaB => (section.gamma_b.phi_poles.to_vec(), section.gamma_b.link_force_poles.to_vec()),
        };
        Self {
            law: section.law,
            model,
            phi_gains: coefficients_of_roots(&phi),
            second_gains: coefficients_of_roots(&second),
            reference,
            u1: initial_thrust,
            u1_dot: 0.0,
            u1_ddot: 0.0,
            last_t: None,
        }
    }

    fn derivatives(&self, x: &[f64]) -> Derivatives {
        let m = &self.model;
        let psi = x[0] + x[2];
        Derivatives { psi, psi_dot: x[1] + x[3], phi_ddot: m.a1() * x[0].cos() + m.a2() * psi.cos() * self.u1 }
    }

    /// Γa′: [u̇₁, τ_R].
    fn gamma_a(&self, point: &Point, x: &[f64]) -> [f64; 2] {
        let (m, d) = (&self.model, self.derivatives(x));
        let v1 = linear_input(&self.phi_gains, &point.phi, &[x[0], x[1], d.phi_ddot]);
        let v2 = linear_input(&self.second_gains, &point.second, &[x[2], x[3]]);
        let b1 = -m.a1() * x[0].sin() * x[1] - m.a2() * d.psi.sin() * d.psi_dot * self.u1;
        [(v1 - b1) / (m.a2() * d.psi.cos()), v2 / m.a3()]
    }

    /// Γb: [ü₁, τ_R].
    fn gamma_b(&self, point: &Point, x: &[f64]) -> [f64; 2] {
        let (m, d) = (&self.model, self.derivatives(x));
        let (a1, a2, a3) = (m.a1(), m.a2(), m.a3());
        let (u1, u1_dot) = (self.u1, self.u1_dot);
        let (x1, x2) = (x[0], x[1]);
        let (s1, c1) = x1.sin_cos();
        let (sp, cp) = d.psi.sin_cos();
        let (psi_dot, x2_dot) = (d.psi_dot, d.phi_ddot);
        let x2_ddot = -a1 * s1 * x2 - a2 * sp * psi_dot * u1 + a2 * cp * u1_dot;
        let b1 = -a1 * c1 * x2 * x2
            - a1 * s1 * x2_dot
            - a2 * cp * psi_dot * psi_dot * u1
            - a2 * sp * u1 * x2_dot
            - 2.0 * a2 * sp * psi_dot * u1_dot;
        let link_force = x2 * x2 / a2 + a1 / a2 * s1 + sp * u1;
        let link_force_dot = 2.0 / a2 * x2 * x2_dot + a1 / a2 * c1 * x2 + cp * psi_dot * u1 + sp * u1_dot;
        let b2 = 2.0 / a2 * (x2_dot * x2_dot + x2 * x2_ddot) + a1 / a2 * (-s1 * x2 * x2 + c1 * x2_dot)
            - sp * psi_dot * psi_dot * u1
            + cp * u1 * x2_dot
            + 2.0 * cp * psi_dot * u1_dot;
        let v1 = linear_input(&self.phi_gains, &point.phi, &[x1, x2, x2_dot, x2_ddot]);
        let v2 = linear_input(&self.second_gains, &point.second, &[link_force, link_force_dot]);
        // E = [[a₂ cψ, −a₂a₃ sψ u₁], [sψ, a₃ cψ u₁]], det = a₂a₃u₁.
        let (r1, r2) = (v1 - b1, v2 - b2);
        let det = a2 * a3 * u1;
        [(a3 * cp * u1 * r1 + a2 * a3 * sp * u1 * r2) / det, (-sp * r1 + a2 * cp * r2) / det]
    }

    /// The compensator over the `dt` since the last command, with the last derivative held.
    fn advance(&mut self, dt: f64) {
        match self.law {
            Law::GammaA => self.u1 += self.u1_dot * dt,
            Law::GammaB => {
                self.u1 += self.u1_dot * dt + 0.5 * self.u1_ddot * dt * dt;
                self.u1_dot += self.u1_ddot * dt;
            }
        }
        self.u1 = self.u1.clamp(0.0, self.model.thrust_max_n);
        let rate = self.model.thrust_rate_max_n_s;
        self.u1_dot = self.u1_dot.clamp(-rate, rate);
    }
}

impl Controller for FlatnessController {
    fn update(&mut self, t: f64, estimate: &[f64], command: &mut [f64]) {
        if let Some(last) = self.last_t {
            self.advance(t - last);
        }
        self.last_t = Some(t);
        let x =
            [estimate[layout::PHI], estimate[layout::PHI_DOT], estimate[layout::THETA], estimate[layout::THETA_DOT]];
        let point = self.reference.at(t);
        let torque = match self.law {
            Law::GammaA => {
                let [u1_dot, torque] = self.gamma_a(&point, &x);
                let rate = self.model.thrust_rate_max_n_s;
                self.u1_dot = if u1_dot.is_finite() { u1_dot.clamp(-rate, rate) } else { 0.0 };
                torque
            }
            Law::GammaB => {
                let [u1_ddot, torque] = self.gamma_b(&point, &x);
                self.u1_ddot = if u1_ddot.is_finite() { u1_ddot } else { 0.0 };
                torque
            }
        };
        let torque_max = self.model.torque_max_n_m;
        command[0] = self.u1;
        command[1] = if torque.is_finite() { torque.clamp(-torque_max, torque_max) } else { 0.0 };
        command[2] = self.u1_dot;
    }

    /// The compensator and when it last ran: [u₁, u̇₁, ü₁, 1, t], or [u₁, u̇₁, ü₁, 0, 0] before
    /// the first update.
    /// The thrust chain u₁, u̇₁, ü₁ and the time of the last update.
    fn freeze(&self) -> Option<Vec<u8>> {
        Some(freeze_value(&(self.u1, self.u1_dot, self.u1_ddot, self.last_t)))
    }

    fn thaw(&mut self, frozen: &[u8]) -> anyhow::Result<()> {
        (self.u1, self.u1_dot, self.u1_ddot, self.last_t) = thaw_value(frozen)?;
        Ok(())
    }
}
