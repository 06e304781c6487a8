//! The backstepping tracking law (paper 001): thrust (56) and torque (57), with the
//! parameters either true (the nominal controller of §4) or the estimator's (certainty
//! equivalence, §6).
//!
//!   z₁ = p − p_d,   z₂ = v + k₁Rᵀz₁ − Rᵀṗ_d − δ
//!   h  = −k₁²Rᵀz₁ + k₁(z₂+δ) + gRᵀe₃ − Rᵀp̈_d + Rᵀξ̂₂,   h_D = −h − k₂z₂
//!   T  = −m̂ δᵀh_D / δ₃,   ω_d = M h_D + γδ,   M = −S(δ)(I − e₃δᵀ/δ₃)/‖δ‖²
//!   τ  = Ĵ(−k₃z₃ − Ω(ω)ξ̂₃ + ω̇_d + β⁻¹S(δ)z₂),   z₃ = ω − ω_d
//!
//! ω̇_d is analytic (the paper does not write it out): ω̇_d = M ḣ_D + γ̇δ, with ż₁, ż₂ and ḣ
//! from the model at the estimates, p_d up to its third derivative and ξ̂̇₂ from the filter.
//!
//! With a rate-loop vehicle the command also carries a body-rate command: the integral of the
//! angular acceleration the computed torque asks for, Ω(ω)ξ̂₃ + Ĵ⁻¹τ = ω̇_d − k₃z₃ + β⁻¹S(δ)z₂
//! (paper §9.1). Its ω̇_d part integrates exactly to ω_d, so only the rest is summed:
//! ω_cmd = ω_d + ∫(−k₃z₃ + β⁻¹S(δ)z₂), starting from ω_cmd(0) = ω(0). Summing ω̇_d numerically
//! instead fails: it holds a term of about M S(g e₃) ω (a gain near 50 s⁻¹ here) that only
//! cancels in continuous time, and behind a 45 ms command link it drives a fast oscillation.

use nalgebra::{Matrix3, Vector3};
use serde::Deserialize;

use super::layout;
use super::params::Model;
use super::reference::Reference;
use crate::model::reference::Reference as _;
use crate::model::scenario::{Controller, freeze_value, thaw_value};
use crate::model::so3::{rotation, skew};

#[derive(Debug, Clone, Copy, PartialEq, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Parameters {
    /// The nominal controller: true m, J, b (the open-loop estimation studies of §7.1–7.2).
    Nominal,
    /// Certainty equivalence: m̂, ĵ, ξ̂ from the estimator (§6).
    Estimated,
}

#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ControllerSection {
    /// k₁, k₂, k₃ [Table 1].
    pub gains: [f64; 3],
    pub beta: f64,
    /// δ of (29): δ₃ ≠ 0 (Lemma 4.1).
    pub delta: [f64; 3],
    pub parameters: Parameters,
}

/// M with ω_d = M h_D + γδ: the ω rows of the right inverse Dᵀ(DDᵀ)⁻¹ of D = [−ξ₁e₃, S(δ)],
/// which do not depend on ξ₁.
pub fn rate_map(delta: &Vector3<f64>) -> Matrix3<f64> {
    -skew(delta) * (Matrix3::identity() - Vector3::z() * delta.transpose() / delta.z) / delta.norm_squared()
}

pub struct Backstepping {
    k: [f64; 3],
    beta: f64,
    delta: Vector3<f64>,
    rate_map: Matrix3<f64>,
    parameters: Parameters,
    model: Model,
    reference: Reference,
    /// ∫(−k₃z₃ + β⁻¹S(δ)z₂) of the rate command, and when it was last advanced.
    rate_integral: Option<(f64, Vector3<f64>)>,
}

/// What the law needs of the vehicle: measured motion and the parameters it believes.
struct Belief {
    p: Vector3<f64>,
    r: Matrix3<f64>,
    v: Vector3<f64>,
    w: Vector3<f64>,
    xi1: f64,
    xi2: Vector3<f64>,
    xi3: Vector3<f64>,
    xi2_rate: Vector3<f64>,
    mass: f64,
    inertia: Vector3<f64>,
}

impl Backstepping {
    pub fn new(section: &ControllerSection, model: &Model, reference: Reference) -> Self {
        let delta = Vector3::from(section.delta);
        Self {
            k: section.gains,
            beta: section.beta,
            delta,
            rate_map: rate_map(&delta),
            parameters: section.parameters,
            model: model.clone(),
            reference,
            rate_integral: None,
        }
    }

    fn belief(&self, e: &[f64]) -> Belief {
        let v3 = |range: std::ops::Range<usize>| Vector3::from_column_slice(&e[range]);
        let pose = &e[layout::POSE];
        let (p, r, v, w) =
            (Vector3::from_column_slice(&pose[..3]), rotation(&pose[3..12]), v3(layout::VELOCITY), v3(layout::RATE));
        match self.parameters {
            Parameters::Nominal => {
                let xi = self.model.xi(self.model.mass_kg);
                Belief {
                    p,
                    r,
                    v,
                    w,
                    xi1: xi[0],
                    xi2: Vector3::new(xi[1], xi[2], xi[3]),
                    xi3: Vector3::new(xi[4], xi[5], xi[6]),
                    xi2_rate: Vector3::zeros(),
                    mass: self.model.mass_kg,
                    inertia: Vector3::from(self.model.inertia_kg_m2),
                }
            }
            Parameters::Estimated => {
                let xi = &e[layout::XI];
                Belief {
                    p,
                    r,
                    v,
                    w,
                    xi1: xi[0],
                    xi2: Vector3::from_column_slice(&xi[1..4]),
                    xi3: Vector3::from_column_slice(&xi[4..7]),
                    xi2_rate: v3(layout::XI2_RATE),
                    mass: e[layout::MASS],
                    inertia: v3(layout::INERTIA),
                }
            }
        }
    }

    /// Thrust, torque, ω_d, and the part of the angular acceleration the torque asks for that
    /// is not ω̇_d.
    fn law(&mut self, t: f64, b: &Belief) -> (f64, Vector3<f64>, Vector3<f64>, Vector3<f64>) {
        let [k1, k2, k3] = self.k;
        let (delta, m) = (self.delta, self.rate_map);
        let e3 = Vector3::z();
        let g = self.model.g;
        let d = self.reference.at(t);
        let (gamma, gamma_rate) = self.reference.gamma(t);
        let rt = b.r.transpose();

        let z1 = b.p - d.p;
        let z2 = b.v + k1 * rt * z1 - rt * d.v - delta;
        // h = −k₁²Rᵀz₁ + k₁(z₂+δ) + gRᵀe₃ − Rᵀp̈_d + Rᵀξ̂₂ (32); `outer` is the part Rᵀ(·) of it.
        let outer = -k1 * k1 * rt * z1 + g * rt * e3 - rt * d.a + rt * b.xi2;
        let h = outer + k1 * (z2 + delta);
        let h_d = -h - k2 * z2;
        let thrust = -b.mass * delta.dot(&h_d) / delta.z;
        let w_d = m * h_d + gamma * delta;
        let z3 = b.w - w_d;

        // Derivatives along the model at the estimates (certainty equivalence).
        let z1_dot = b.r * b.v - d.v;
        let z2_dot = (z2 + delta).cross(&b.w) - b.xi1 * thrust * e3 + h;
        let h_dot = -b.w.cross(&outer) - k1 * k1 * rt * z1_dot + k1 * z2_dot - rt * d.jerk + rt * b.xi2_rate;
        let h_d_dot = -h_dot - k2 * z2_dot;
        let w_d_dot = m * h_d_dot + gamma_rate * delta;

        let omega = Vector3::new(b.w.y * b.w.z, b.w.x * b.w.z, b.w.x * b.w.y);
        let wanted = -k3 * z3 - omega.component_mul(&b.xi3) + w_d_dot + skew(&delta) * z2 / self.beta;
        let torque = b.inertia.component_mul(&wanted);
        let feedback = -k3 * z3 + skew(&delta) * z2 / self.beta;
        (thrust, torque, w_d, feedback)
    }
}

impl Controller for Backstepping {
    fn update(&mut self, t: f64, estimate: &[f64], command: &mut [f64]) {
        let belief = self.belief(estimate);
        let (thrust, torque, w_d, feedback) = self.law(t, &belief);
        let integral = match self.rate_integral {
            Some((t_last, integral)) => integral + feedback * (t - t_last),
            None => belief.w - w_d,
        };
        self.rate_integral = Some((t, integral));
        let rate = w_d + integral;
        let model = &self.model;
        command[0] = thrust.clamp(0.0, model.thrust_max_n);
        for i in 0..3 {
            command[1 + i] = torque[i].clamp(-model.torque_max_nm, model.torque_max_nm);
            command[4 + i] = rate[i].clamp(-model.rate_max_rad_s, model.rate_max_rad_s);
        }
        // A non-finite estimate must not become a command (the plant would reject it anyway).
        if command[..7].iter().any(|u| !u.is_finite()) {
            command[..7].fill(0.0);
        }
    }

    /// The rate command's integral and when it was last advanced: [1, t, ∫x, ∫y, ∫z], or all
    /// zero before the first update.
    /// The rate integral and the time it was last advanced, once it exists.
    fn freeze(&self) -> Option<Vec<u8>> {
        Some(freeze_value(&self.rate_integral.map(|(t, integral)| (t, <[f64; 3]>::from(integral)))))
    }

    fn thaw(&mut self, frozen: &[u8]) -> anyhow::Result<()> {
        let rate_integral: Option<(f64, [f64; 3])> = thaw_value(frozen)?;
        self.rate_integral = rate_integral.map(|(t, integral)| (t, Vector3::from(integral)));
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::{Matrix3x4, Vector4};

    /// M h equals the ω rows of the right inverse Dᵀ(DDᵀ)⁻¹ h for any ξ₁, and D μ_d = h.
    #[test]
    fn rate_map_is_the_right_inverse_rows() {
        let delta = Vector3::new(0.15, -0.05, 0.1);
        let h = Vector3::new(0.7, -1.3, 2.1);
        for xi1 in [5.0, 0.3, 12.0] {
            let mut d = Matrix3x4::zeros();
            d.set_column(0, &(-xi1 * Vector3::z()));
            d.fixed_view_mut::<3, 3>(0, 1).copy_from(&skew(&delta));
            let right_inverse = d.transpose() * (d * d.transpose()).try_inverse().unwrap();
            let mu: Vector4<f64> = right_inverse * h;
            assert!((d * mu - h).norm() < 1e-12);
            let w = Vector3::new(mu[1], mu[2], mu[3]);
            assert!((rate_map(&delta) * h - w).norm() < 1e-12, "ξ₁ = {xi1}");
            // T = μ₁ = −δᵀh/(ξ₁δ₃) (38).
            assert!((mu[0] + delta.dot(&h) / (xi1 * delta.z)).abs() < 1e-12);
        }
    }
}
