//! The KF-aided backstepping controller of section 5 (29)–(56), evaluated with the filter's
//! pseudo-estimates: v̂_L, ω̂, b̂, and the measured p_L, q, R.
//!
//! The chain position → pendulum direction → pendulum rate → thrust direction needs time
//! derivatives the paper does not print ("pseudo-derivatives" along the flow with f = f∥d):
//! ξ̇ (η), η̇, q̇_d, ω̇_d and ż_ω are written out by hand in
//! [`desired`]. Everything the thrust direction needs beyond that comes exactly from dual numbers
//! (`model::autodiff`) through the same code:
//! - ṙ₃d: [`desired`] evaluated on duals seeded with the model's flow under the applied
//!   f = −T r₃ and ḃ̂ = 0, the reference's derivatives one order up (p_Ld⁽⁵⁾ enters here);
//! - ∂z_ω/∂v_L: the same, seeded with each axis of v_L.
//!
//! δ in (56) is δ′ = m_T·(50): with (50)'s leading 1/m_T the third term
//! of Ω would not cancel its cross term in V̇₄. γ (the yaw rate, free in the paper) is set in the
//! launch file.

use serde::Deserialize;

use super::layout;
use super::params::Model;
use super::reference::{EllipseReference, ORDERS};
use crate::model::autodiff::{Dual, Scalar, Vec3, add, cross, dot, scale};
use crate::model::reference::Reference;
use crate::model::scenario::{Controller, freeze_value, thaw_value};

/// `[controller]`: K_p = k_p I and K_v = k_v I (the paper's gains are scalar).
#[derive(Debug, Clone, Copy, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct Gains {
    pub k_p: f64,
    pub k_v: f64,
    pub beta: f64,
    pub k_q: f64,
    pub k_omega: f64,
    pub k_r: f64,
    pub h_q: f64,
    pub h_omega: f64,
    pub h_r: f64,
    /// γ: the commanded yaw rate Ω₃ = −γ, rad/s.
    pub yaw_rate_rad_s: f64,
}

/// What the control law reads: the load's position and velocity, the pendulum direction and
/// rate, the disturbance estimate, and the reference's value and first four derivatives.
#[derive(Debug, Clone, Copy)]
pub struct Inputs<S> {
    pub p: Vec3<S>,
    pub v: Vec3<S>,
    pub q: Vec3<S>,
    pub w: Vec3<S>,
    pub b: Vec3<S>,
    pub reference: [Vec3<S>; 5],
}

/// The steps of the chain the thrust direction and Ω need.
#[derive(Debug, Clone, Copy)]
pub struct Desired<S> {
    pub z_p: Vec3<S>,
    pub z_v: Vec3<S>,
    /// ξ (34), N.
    pub xi: Vec3<S>,
    /// ‖ξ‖, N.
    pub xi_norm: S,
    /// f∥d (33), N.
    pub f_par: Vec3<S>,
    pub q_d: Vec3<S>,
    pub omega_d: Vec3<S>,
    /// ω̇_d along f = f∥d.
    pub omega_d_dot: Vec3<S>,
    pub z_omega: Vec3<S>,
    /// f_d = f∥d + f⊥d (53), N.
    pub f_d: Vec3<S>,
}

fn sub<S: Scalar>(a: Vec3<S>, b: Vec3<S>) -> Vec3<S> {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}

fn times<S: Scalar>(a: Vec3<S>, k: f64) -> Vec3<S> {
    a.map(|x| x.scale(k))
}

/// The part of `a` normal to the unit vector q: (I − qqᵀ)a.
fn normal<S: Scalar>(q: Vec3<S>, a: Vec3<S>) -> Vec3<S> {
    sub(a, scale(q, dot(q, a)))
}

/// ‖ξ‖ is kept away from 0 by this (it never comes close in the paper's runs).
const XI_FLOOR: f64 = 1e-6;

/// (29)–(53): the errors, the desired pendulum direction and rate, and the desired force.
pub fn desired<S: Scalar>(g: &Gains, m: &Model, x: &Inputs<S>) -> Desired<S> {
    let (m_t, m_ql) = (m.total_mass(), m.uav_mass_times_rod());
    let [r0, r1, r2, r3, r4] = x.reference;
    let q = x.q;
    let gravity = [S::zero(), S::zero(), S::c(m.g_m_s2)];
    let z_p = sub(x.p, r0);
    let z_v = sub(x.v, r1);
    let a_ref = sub(gravity, r2);
    // (34) ξ = m_T(K_p z_p + K_v z_v + g e₃ − p̈_Ld).
    let xi = times(add(add(times(z_p, g.k_p), times(z_v, g.k_v)), a_ref), m_t);
    let xi_norm = (dot(xi, xi) + S::c(XI_FLOOR * XI_FLOOR)).sqrt();
    let xi_par = scale(q, dot(q, xi));
    // (33) f∥d = −ξ∥ − b̂∥ + m_Qℓ‖ω‖²q.
    let f_par = add(sub(times(xi_par, -1.0), scale(q, dot(q, x.b))), scale(q, dot(x.w, x.w).scale(m_ql)));
    // (40) q_d = −ξ/‖ξ‖.
    let q_d = scale(xi, -S::one() / xi_norm);
    // ż_v along f = f∥d, and η = ξ̇ along it.
    let z_v_dot = add(times(xi_par, -1.0 / m_t), a_ref);
    let eta = sub(add(sub(times(z_v, m_t * g.k_p), times(xi_par, g.k_v)), times(a_ref, m_t * g.k_v)), times(r3, m_t));
    let q_dot = cross(x.w, q);
    // q̇_d = S²(q_d)η/‖ξ‖ = (q_d q_dᵀ − I)η/‖ξ‖.
    let q_d_dot = scale(sub(scale(q_d, dot(q_d, eta)), eta), S::one() / xi_norm);
    // η̇ = m_T K_p ż_v − K_v(q̇qᵀξ + qq̇ᵀξ + qqᵀη) − m_T K_v p⃛_Ld − m_T p_Ld⁽⁴⁾.
    let xi_par_dot = add(add(scale(q_dot, dot(q, xi)), scale(q, dot(q_dot, xi))), scale(q, dot(q, eta)));
    let eta_dot =
        sub(sub(sub(times(z_v_dot, m_t * g.k_p), times(xi_par_dot, g.k_v)), times(r3, m_t * g.k_v)), times(r4, m_t));
    // (47) ω_d = (k_q/h_q)S(q)q_d − S(q_d)η/‖ξ‖, and its rate.
    let kq = g.k_q / g.h_q;
    let omega_d = sub(times(cross(q, q_d), kq), scale(cross(q_d, eta), S::one() / xi_norm));
    let omega_d_dot = sub(
        sub(
            times(add(cross(q_dot, q_d), cross(q, q_d_dot)), kq),
            scale(cross(q_d, eta), dot(q_d, eta) / (xi_norm * xi_norm)),
        ),
        scale(add(cross(q_d_dot, eta), cross(q_d, eta_dot)), S::one() / xi_norm),
    );
    // (46) z_ω = S(q)(ω − ω_d), and ż_ω along f = f∥d without the S(q)ω̇ part.
    let z_omega = cross(q, sub(x.w, omega_d));
    let z_omega_dot = sub(cross(q_dot, sub(x.w, omega_d)), cross(q, omega_d_dot));
    // (51) f⊥d = −m_Qℓ(ż_ω + (h_q/h_ω)q_d + (k_ω/h_ω)z_ω + b̂/(m_Qℓ))⊥.
    let inner = add(
        add(add(z_omega_dot, times(q_d, g.h_q / g.h_omega)), times(z_omega, g.k_omega / g.h_omega)),
        times(x.b, 1.0 / m_ql),
    );
    let f_perp = times(normal(q, inner), -m_ql);
    Desired { z_p, z_v, xi, xi_norm, f_par, q_d, omega_d, omega_d_dot, z_omega, f_d: add(f_par, f_perp) }
}

/// Ṫ and Ω of (54) and (56) from the estimates: the command [T, Ω₁, Ω₂, Ω₃].
pub struct Backstepping {
    gains: Gains,
    model: Model,
    reference: EllipseReference,
}

fn lift(v: [f64; 3], d: [f64; 3]) -> Vec3<Dual> {
    std::array::from_fn(|i| Dual { v: v[i], d: d[i] })
}

fn derivative(v: Vec3<Dual>) -> [f64; 3] {
    v.map(|x| x.d)
}

fn slice3(x: &[f64]) -> [f64; 3] {
    [x[0], x[1], x[2]]
}

/// Rᵀa for R row-major.
fn transpose_times(r: &[f64], a: [f64; 3]) -> [f64; 3] {
    std::array::from_fn(|j| (0..3).map(|i| r[3 * i + j] * a[i]).sum())
}

/// e₃ × a.
fn e3_cross(a: [f64; 3]) -> [f64; 3] {
    [-a[1], a[0], 0.0]
}

impl Backstepping {
    pub fn new(gains: Gains, model: Model, reference: EllipseReference) -> Self {
        Self { gains, model, reference }
    }

    /// [T, Ω] at time t from the estimate vector.
    pub fn command(&mut self, t: f64, estimate: &[f64]) -> [f64; 4] {
        let (g, m) = (self.gains, self.model);
        let (m_t, m_ql) = (m.total_mass(), m.uav_mass_times_rod());
        let point = self.reference.at(t).p;
        let x = Inputs {
            p: slice3(&estimate[layout::LOAD_POSITION]),
            v: slice3(&estimate[layout::LOAD_VELOCITY_HAT]),
            q: slice3(&estimate[layout::DIRECTION]),
            w: slice3(&estimate[layout::RATE_HAT]),
            b: slice3(&estimate[layout::DISTURBANCE_HAT]),
            reference: std::array::from_fn(|n| point[n]),
        };
        let rotation = &estimate[layout::ROTATION];
        let d = desired(&g, &m, &x);
        let t_d = dot(d.f_d, d.f_d).sqrt().max(XI_FLOOR);
        let r3d = times(d.f_d, -1.0 / t_d);
        let r3 = [rotation[2], rotation[5], rotation[8]];
        // (54) T = T_d r₃dᵀr₃, within what the actuator takes.
        let thrust = (t_d * dot(r3d, r3)).clamp(0.0, m.thrust_max_n);

        // The model's flow under the applied thrust, for ḟ_d.
        let force = add(times(r3, -thrust), x.b);
        let v_dot =
            add(sub(times(x.q, dot(x.q, force) / m_t), times(x.q, m_ql / m_t * dot(x.w, x.w))), [0.0, 0.0, m.g_m_s2]);
        let flow = Inputs {
            p: lift(x.p, x.v),
            v: lift(x.v, v_dot),
            q: lift(x.q, cross(x.w, x.q)),
            w: lift(x.w, times(cross(x.q, force), -1.0 / m_ql)),
            b: lift(x.b, [0.0; 3]),
            reference: std::array::from_fn(|n| lift(point[n], point[n + 1])),
        };
        let f_d_dot = derivative(desired(&g, &m, &flow).f_d);
        // ṙ₃d = −(I − r₃d r₃dᵀ)ḟ_d/T_d.
        let r3d_dot = times(normal(r3d, f_d_dot), -1.0 / t_d);

        // (∂z_ω/∂v_L)ᵀ z_ω, column by column.
        let constant = |v: [f64; 3]| lift(v, [0.0; 3]);
        let mut dz_dv_z = [0.0; 3];
        for (axis, out) in dz_dv_z.iter_mut().enumerate() {
            let mut seed = [0.0; 3];
            seed[axis] = 1.0;
            let along = Inputs {
                p: constant(x.p),
                v: lift(x.v, seed),
                q: constant(x.q),
                w: constant(x.w),
                b: constant(x.b),
                reference: x.reference.map(constant),
            };
            *out = dot(derivative(desired(&g, &m, &along).z_omega), d.z_omega);
        }
        // δ′ = βz_p + z_v − (h_q/‖ξ‖) m_T K_v S²(q_d) q + h_ω (∂z_ω/∂v_L)ᵀ z_ω.
        let s2_qd_q = sub(times(d.q_d, dot(d.q_d, x.q)), x.q);
        let delta = add(
            sub(add(times(d.z_p, g.beta), d.z_v), times(s2_qd_q, g.h_q * m_t * g.k_v / d.xi_norm)),
            times(dz_dv_z, g.h_omega),
        );
        let delta_par = times(x.q, dot(x.q, delta));

        // (56), with −S²(e₃) = diag(1, 1, 0).
        let terms = [
            transpose_times(rotation, cross(r3d, r3d_dot)),
            times(e3_cross(transpose_times(rotation, r3d)), g.k_r / g.h_r),
            times(e3_cross(transpose_times(rotation, delta_par)), t_d / (g.h_r * m_t)),
            times(e3_cross(transpose_times(rotation, d.z_omega)), g.h_omega / g.h_r * t_d / m_ql),
        ];
        let sum = terms.iter().fold([0.0; 3], |acc, term| add(acc, *term));
        let limit = m.rate_max_rad_s;
        [thrust, sum[0].clamp(-limit, limit), sum[1].clamp(-limit, limit), (-g.yaw_rate_rad_s).clamp(-limit, limit)]
    }
}

impl Controller for Backstepping {
    fn update(&mut self, t: f64, estimate: &[f64], command: &mut [f64]) {
        command[..4].copy_from_slice(&self.command(t, estimate));
    }

    /// The law is static, but the reference's phase ϑ is integrated on from the last update:
    /// [t, ϑ(t)], so that a restarted controller computes the very same ϑ, not one integrated
    /// afresh from 0 (equal only to rounding).
    /// The reference's phase (t, θ): where on the ellipse the vehicle was sent.
    fn freeze(&self) -> Option<Vec<u8>> {
        Some(freeze_value(&self.reference.phase()))
    }

    fn thaw(&mut self, frozen: &[u8]) -> anyhow::Result<()> {
        self.reference.resume_phase(thaw_value(frozen)?);
        Ok(())
    }
}

const _: () = assert!(ORDERS >= 6, "ṙ₃d needs p_Ld⁽⁵⁾");

#[cfg(test)]
mod tests {
    use super::super::params::tests::simulation;
    use super::super::reference::tests::paper as paper_reference;
    use super::*;
    use crate::scenarios::fip::closed_loop_tests::paper_gains;

    fn at_start() -> Inputs<f64> {
        let point = EllipseReference::new(paper_reference()).at(0.0).p;
        let tilt = 5f64.to_radians();
        Inputs {
            p: [0.0, 0.2, -0.3],
            v: [0.0; 3],
            q: [tilt.sin() / 2f64.sqrt(), tilt.sin() / 2f64.sqrt(), -tilt.cos()],
            w: [0.0; 3],
            b: [0.0; 3],
            reference: std::array::from_fn(|n| point[n]),
        }
    }

    /// Numbers derived by hand at t₀: ξ̂(0) = [−2.7188, 0.5116, 7.2536] N (‖ξ̂‖ = 7.763),
    /// q_d(0) = [0.3502, −0.0659, −0.9343], f∥d(0) = [0.454, 0.454, −7.334] N.
    #[test]
    fn the_first_step_matches_the_note() {
        let d = desired(&paper_gains(), &simulation(), &at_start());
        let close = |a: [f64; 3], b: [f64; 3], tol: f64| (0..3).all(|i| (a[i] - b[i]).abs() < tol);
        assert!(close(d.xi, [-2.7188, 0.5116, 7.2536], 1e-4), "{:?}", d.xi);
        assert!((d.xi_norm - 7.763).abs() < 1e-3, "{}", d.xi_norm);
        assert!(close(d.q_d, [0.3502, -0.0659, -0.9343], 1e-4), "{:?}", d.q_d);
        assert!(close(d.f_par, [0.454, 0.454, -7.334], 1e-3), "{:?}", d.f_par);
    }

    /// The hand-expanded ω̇_d (η, η̇, q̇_d) is the time derivative of ω_d along the
    /// model's flow with f = f∥d and ḃ̂ = 0, which dual numbers give exactly through the same code.
    #[test]
    fn the_derived_pseudo_derivatives_are_the_flows_derivatives() {
        let (g, m) = (paper_gains(), simulation());
        let (m_t, m_ql) = (m.total_mass(), m.uav_mass_times_rod());
        let mut reference = EllipseReference::new(paper_reference());
        for (i, t) in [0.0, 1.3, 4.7, 9.1].into_iter().enumerate() {
            let point = reference.at(t).p;
            let s = i as f64;
            let q = {
                let raw = [0.1 + 0.05 * s, -0.2 + 0.1 * s, -1.0];
                let n = dot(raw, raw).sqrt();
                raw.map(|x| x / n)
            };
            let x = Inputs {
                p: [0.3 - 0.1 * s, 0.1, -1.2],
                v: [0.2, -0.1 * s, 0.3],
                q,
                w: normal(q, [0.4, -0.3 + 0.2 * s, 0.1]),
                b: [-0.5, 0.5 * s, -0.8],
                reference: std::array::from_fn(|n| point[n]),
            };
            let d = desired(&g, &m, &x);
            let force = add(d.f_par, x.b);
            let v_dot =
                add(sub(times(q, dot(q, force) / m_t), times(q, m_ql / m_t * dot(x.w, x.w))), [0.0, 0.0, m.g_m_s2]);
            let flow = Inputs {
                p: lift(x.p, x.v),
                v: lift(x.v, v_dot),
                q: lift(q, cross(x.w, q)),
                // ω̇ does not enter ω_d; any value shows it.
                w: lift(x.w, [7.0, -3.0, 2.0]),
                b: lift(x.b, [0.0; 3]),
                reference: std::array::from_fn(|n| lift(point[n], point[n + 1])),
            };
            let exact = derivative(desired(&g, &m, &flow).omega_d);
            for (axis, (dual, hand)) in exact.iter().zip(d.omega_d_dot).enumerate() {
                assert!(
                    (dual - hand).abs() < 1e-10 * (1.0 + dual.abs()),
                    "t {t} axis {axis}: dual {dual} vs hand {hand}"
                );
            }
        }
    }
}
