//! NLLS-2L and NLPT-2L (paper 004, section 3): two loops of feedback linearisation.
//!
//! Inner loop (z, φ, θ, ψ; section 3.1): the thrusts are the controller's own
//! double integrators (the dynamic extension), the new inputs are Γ̄ = (f̈_R, f̈_L, τ_αR, τ_αL),
//! every output has relative degree 4 and Γ̄ = Δ⁻¹(v − b) (36), with
//! vᵢ = iRef⁽⁴⁾ + K_ddd e⃛ + K_dd ë + K_d ė + K_p e + K_I ∫e, e = i − iRef.
//! b, Δ and e's derivatives come exactly from the design model's Taylor series
//! (`control_model`), from the estimated ż and the measured angles and rates: no
//! numerical differentiation.
//!
//! Outer loop (x, y and the load; section 3.2): Υ = A⁻¹(v − b) of (48) from M_q2 of
//! the design model, then φ_Ref, θ_Ref by (46) with σ saturation and f_z^B from the thrust
//! states; f_x^B, f_y^B are compensated as known disturbances (n_x, n_y of (43)). NLLS-2L adds
//! K_pd ḋ^F + K_Id ∫ḋ^F (49)–(50), NLPT-2L leaves them out (72)–(73).
//!
//! Choices the paper does not make (stand-ins, see README.md):
//! - φ_Ref and θ_Ref pass through a 4th-order critically damped prefilter, (s + ω)⁴, whose
//!   state gives their derivatives to the 4th order; it starts at the measured φ, θ.
//! - The thrust states start at the nominal hover thrust, ḟ = 0, and are integrated
//!   exactly over the tick; the command is their value at the tick's midpoint,
//!   f + τḟ/2 + τ²f̈/8: the plant holds the command over the whole tick, and the midpoint value
//!   matches the model's thrust profile over it with no mean lag (the start value would lag
//!   by half a tick, 5 ms, inside a loop that feeds back the thrust's 2nd derivative).
//! - Limits: f in [0, thrust_max] with ḟ zeroed at a bound, τ_α within ±torque_max;
//!   every integrator is frozen while an actuator saturates (and the outer ones also while σ
//!   of (46) saturates).
//! - The gains are the launch file's, from the H₂/H∞ synthesis of `gains` (the
//!   services/tiltrotor-gains tool).
//! - ψ's error is not wrapped (the stand-in reference stays within ±π/4).
//!
//! Measured on the full plant (the launch file's gains, ±30 % draws): both kinds fly the
//! stand-in and keep the load bounded; why the prefilter stays slow is in `gains`.

use nalgebra::Vector2;
use serde::{Deserialize, Serialize};

use super::control_model::{InnerModel, OUTPUTS, OuterModel, ext};
use super::dynamics::rotation;
use super::gains::chain_poles;
use super::layout;
use super::params::Params;
use super::reference::TiltReference;
use crate::config::launch::{LaunchConfig, LaunchError};
use crate::model::scenario::{Controller, freeze_value, thaw_value};

#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize, strum::Display)]
pub enum Kind {
    /// The proposed controller, with load-swing damping.
    #[serde(rename = "nlls-2l")]
    #[strum(serialize = "nlls-2l")]
    Nlls2l,
    /// The same without the swing terms: the load is a disturbance.
    #[serde(rename = "nlpt-2l")]
    #[strum(serialize = "nlpt-2l")]
    Nlpt2l,
}

/// `[controller]`: the kind and each loop's gains K = [K_I, K_p, K_d, …] of (49)–(50) and
/// (38)–(41) (see `gains` for their synthesis and the Table 2 region of each loop).
#[derive(Debug, Clone, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct ControllerSection {
    pub kind: Kind,
    /// x and y: [K_I, K_p, K_d] on (∫e, e, ė).
    pub xy_gains: [f64; 3],
    /// The swing terms of NLLS-2L: [K_Id, K_pd] on (∫ḋ, ḋ).
    pub swing_gains: [f64; 2],
    /// z: [K_I, K_p, K_d, K_dd, K_ddd] on (∫e, e, ė, ë, e⃛).
    pub z_gains: [f64; 5],
    /// φ and θ.
    pub attitude_gains: [f64; 5],
    pub yaw_gains: [f64; 5],
    /// ω of the (s + ω)⁴ prefilter on φ_Ref, θ_Ref, rad/s.
    pub prefilter_rad_s: f64,
}

impl ControllerSection {
    /// The chains' gains by key, for the checks.
    pub fn chains(&self) -> [(&'static str, &[f64]); 4] {
        [
            ("xy_gains", &self.xy_gains),
            ("z_gains", &self.z_gains),
            ("attitude_gains", &self.attitude_gains),
            ("yaw_gains", &self.yaw_gains),
        ]
    }
}

/// The fastest pole or prefilter the 100 Hz loop is allowed: |s|τ ≤ 1.
const MAX_POLE_TICKS: f64 = 1.0;

/// Each chain's closed loop on its design model (e⁽ⁿ⁾ = Ke) stable, no pole faster than 1/τ; the
/// swing gains positive (the swing loop on ë = −u is then stable); the prefilter positive and
/// no faster.
pub fn check(c: &LaunchConfig, s: &ControllerSection) -> Result<(), LaunchError> {
    let fastest = MAX_POLE_TICKS / c.dt();
    for (name, gains) in s.chains() {
        let poles = chain_poles(gains);
        let finite = gains.iter().all(|g| g.is_finite());
        if !finite || poles.iter().any(|p| p.re >= 0.0 || p.norm() > fastest) {
            let shown: Vec<String> = poles.iter().map(|p| format!("{:.3}{:+.3}i", p.re, p.im)).collect();
            return Err(c.error(
                &format!("controller.{name}"),
                format!(
                    "must be finite gains whose closed-loop poles have Re s < 0 and |s| ≤ 1/τ = {fastest} rad/s, got {gains:?} (poles {})",
                    shown.join(", ")
                ),
            ));
        }
    }
    for (i, g) in s.swing_gains.iter().enumerate() {
        if !(g.is_finite() && *g > 0.0) {
            return Err(c.error(
                &format!("controller.swing_gains.{i}"),
                format!("must be a positive gain (K_Id, K_pd > 0 damp the swing), got {g}"),
            ));
        }
    }
    crate::config::validate::in_range(c, "controller.prefilter_rad_s", s.prefilter_rad_s, 1e-3..=fastest, "rad/s")
}

/// (s + ω)⁴ driven by u: y⁗ = ω⁴(u − y) − 4ω³y′ − 6ω²y″ − 4ωy‴.
#[derive(Debug, Clone, Copy)]
struct Prefilter {
    omega: f64,
    /// y, y′, y″, y‴.
    y: [f64; 4],
}

impl Prefilter {
    fn fourth(&self, y: &[f64; 4], u: f64) -> f64 {
        let w = self.omega;
        w.powi(4) * (u - y[0]) - 4.0 * w.powi(3) * y[1] - 6.0 * w * w * y[2] - 4.0 * w * y[3]
    }

    /// y … y⁗ for the input u.
    fn derivatives(&self, u: f64) -> [f64; 5] {
        [self.y[0], self.y[1], self.y[2], self.y[3], self.fourth(&self.y, u)]
    }

    /// Over `dt` with u held: RK4 on four sub-steps (ω·dt/4 ≤ 0.25 at the allowed ω).
    fn advance(&mut self, u: f64, dt: f64) {
        let f = |y: &[f64; 4]| [y[1], y[2], y[3], self.fourth(y, u)];
        let h = dt / 4.0;
        let mut y = self.y;
        for _ in 0..4 {
            let axpy = |k: &[f64; 4], s: f64| std::array::from_fn(|i| y[i] + s * k[i]);
            let k1 = f(&y);
            let k2 = f(&axpy(&k1, h / 2.0));
            let k3 = f(&axpy(&k2, h / 2.0));
            let k4 = f(&axpy(&k3, h));
            y = std::array::from_fn(|i| y[i] + h / 6.0 * (k1[i] + 2.0 * k2[i] + 2.0 * k3[i] + k4[i]));
        }
        self.y = y;
    }
}

/// What the last update computed, for tests and debugging.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct Internals {
    pub attitude_reference: [f64; 2],
    /// ḋ^F x, y.
    pub swing_velocity: [f64; 2],
    /// f_R, ḟ_R, f_L, ḟ_L at the tick's end.
    pub thrust_state: [f64; 4],
    pub saturated: bool,
}

/// NLLS-2L or NLPT-2L.
pub struct TwoLoop {
    nominal: Params,
    outer: OuterModel,
    reference: TiltReference,
    tick_s: f64,
    thrust_max: f64,
    torque_max: f64,
    /// [K_I, K_p, K_d, K_dd, K_ddd] for z, φ, θ, ψ.
    inner_gains: [[f64; 5]; OUTPUTS],
    /// [K_I, K_p, K_d].
    xy_gains: [f64; 3],
    /// [K_Id, K_pd]; zero for NLPT-2L.
    swing_gains: [f64; 2],
    prefilter_rad_s: f64,
    /// f_R, ḟ_R, f_L, ḟ_L.
    thrust: [f64; 4],
    inner_integral: [f64; OUTPUTS],
    xy_integral: [f64; 2],
    swing_integral: [f64; 2],
    /// φ_Ref and θ_Ref filters, from the first update.
    prefilter: Option<[Prefilter; 2]>,
    internals: Internals,
}

impl TwoLoop {
    /// `nominal`: the parameters the controller believes (Table 1); A1 is applied inside.
    pub fn new(
        section: &ControllerSection,
        nominal: &Params,
        reference: TiltReference,
        tick_s: f64,
        thrust_max: f64,
        torque_max: f64,
    ) -> Self {
        let attitude = section.attitude_gains;
        let hover = nominal.hover_thrust();
        TwoLoop {
            nominal: nominal.clone(),
            outer: OuterModel::new(nominal),
            reference,
            tick_s,
            thrust_max,
            torque_max,
            inner_gains: [section.z_gains, attitude, attitude, section.yaw_gains],
            xy_gains: section.xy_gains,
            swing_gains: match section.kind {
                Kind::Nlls2l => section.swing_gains,
                Kind::Nlpt2l => [0.0; 2],
            },
            prefilter_rad_s: section.prefilter_rad_s,
            thrust: [hover, 0.0, hover, 0.0],
            inner_integral: [0.0; OUTPUTS],
            xy_integral: [0.0; 2],
            swing_integral: [0.0; 2],
            prefilter: None,
            internals: Internals::default(),
        }
    }

    pub fn internals(&self) -> Internals {
        self.internals
    }
}

impl Controller for TwoLoop {
    fn update(&mut self, t: f64, estimate: &[f64], command: &mut [f64]) {
        let position = &estimate[layout::POSITION];
        let velocity = &estimate[layout::VELOCITY];
        let angles = &estimate[layout::ANGLES];
        let rates = &estimate[layout::ANGLE_RATES];
        let eta = [angles[0], angles[1], angles[2]];
        let eta_dot = [rates[0], rates[1], rates[2]];
        let alpha = [angles[3], angles[4]];
        let gamma = [angles[5], angles[6]];
        let gamma_dot = [rates[5], rates[6]];
        let reference = self.reference.point(t).p;
        let inner = InnerModel::new(&self.nominal, gamma);
        let [f_r, _, f_l, _] = self.thrust;

        // Outer loop: (49)–(50), (48), (46).
        let terms = self.outer.terms(eta, eta_dot, gamma, gamma_dot, [velocity[0], velocity[1]]);
        let body_force = inner.body_force(alpha, [f_r, f_l]);
        let r = rotation(eta);
        let swing = self.outer.swing_velocity(eta, eta_dot, gamma, gamma_dot);
        let [ki, kp, kd] = self.xy_gains;
        let [kid, kpd] = self.swing_gains;
        let mut v = Vector2::zeros();
        let mut xy_error = [0.0; 2];
        let mut n = [0.0; 2];
        for axis in 0..2 {
            let e = position[axis] - reference[axis][0];
            let e_dot = velocity[axis] - reference[axis][1];
            xy_error[axis] = e;
            v[axis] = reference[axis][2]
                + kd * e_dot
                + kp * e
                + ki * self.xy_integral[axis]
                + kpd * swing[axis]
                + kid * self.swing_integral[axis];
            // n of (43): the velocity terms less the known f_x^B, f_y^B projections.
            n[axis] = terms.velocity_xy[axis] - (r[axis][0] * body_force[0] + r[axis][1] * body_force[1]);
        }
        let upsilon = terms.a.try_inverse().map_or(Vector2::zeros(), |a_inv| a_inv * (v - terms.b));
        let f_z = body_force[2].max(1e-3);
        let (sy, cy) = eta[2].sin_cos();
        let (px, py) = (upsilon[0] + n[0], upsilon[1] + n[1]);
        let sigma = |p: f64| p.clamp(-1.0, 1.0);
        let roll_arg = (sy * px - cy * py) / f_z;
        let phi_ref = sigma(roll_arg).asin();
        let pitch_arg = (cy * px + sy * py) / (f_z * phi_ref.cos());
        let theta_ref = sigma(pitch_arg).asin();
        let sigma_saturated = roll_arg.abs() > 1.0 || pitch_arg.abs() > 1.0;

        // Inner loop: (36) with the prefiltered φ_Ref, θ_Ref.
        let omega = self.prefilter_rad_s;
        let filters = self.prefilter.get_or_insert([
            Prefilter { omega, y: [eta[0], 0.0, 0.0, 0.0] },
            Prefilter { omega, y: [eta[1], 0.0, 0.0, 0.0] },
        ]);
        let refs = [reference[2], filters[0].derivatives(phi_ref), filters[1].derivatives(theta_ref), reference[3]];
        let mut x0 = [0.0; ext::LEN];
        x0[ext::Z] = position[2];
        x0[ext::PHI..ext::PHI + 3].copy_from_slice(&eta);
        x0[ext::ALPHA_R] = alpha[0];
        x0[ext::ALPHA_L] = alpha[1];
        x0[ext::RATES] = velocity[2];
        x0[ext::RATES + 1..ext::RATES + 6].copy_from_slice(&rates[..5]);
        x0[ext::F_R..=ext::F_L_DOT].copy_from_slice(&self.thrust);
        let lin = inner.linearise(&x0);
        let mut v_inner = [0.0; OUTPUTS];
        let mut inner_error = [0.0; OUTPUTS];
        for i in 0..OUTPUTS {
            let e: [f64; 4] = std::array::from_fn(|k| lin.derivatives[i][k] - refs[i][k]);
            let [k_i, k_p, k_d, k_dd, k_ddd] = self.inner_gains[i];
            inner_error[i] = e[0];
            v_inner[i] =
                refs[i][4] + k_ddd * e[3] + k_dd * e[2] + k_d * e[1] + k_p * e[0] + k_i * self.inner_integral[i];
        }
        let new_inputs = lin.solve(v_inner).unwrap_or([0.0; 4]);

        // Actuators: the thrust double integrators over the tick, then the limits.
        let tau = self.tick_s;
        let mut saturated = false;
        let mut thrust_command = [0.0; 2];
        for (side, f_ddot) in [new_inputs[0], new_inputs[1]].into_iter().enumerate() {
            let (f, f_dot) = (self.thrust[2 * side], self.thrust[2 * side + 1]);
            let midpoint = f + tau * f_dot / 2.0 + tau * tau * f_ddot / 8.0;
            thrust_command[side] = midpoint.clamp(0.0, self.thrust_max);
            let mut end = f + tau * f_dot + tau * tau * f_ddot / 2.0;
            let mut end_rate = f_dot + tau * f_ddot;
            if !(0.0..=self.thrust_max).contains(&end) || thrust_command[side] != midpoint {
                saturated = true;
            }
            if !(0.0..=self.thrust_max).contains(&end) {
                end = end.clamp(0.0, self.thrust_max);
                end_rate = 0.0;
            }
            self.thrust[2 * side] = end;
            self.thrust[2 * side + 1] = end_rate;
        }
        let torques = [new_inputs[2], new_inputs[3]].map(|tq| {
            let clamped = tq.clamp(-self.torque_max, self.torque_max);
            saturated |= clamped != tq;
            clamped
        });
        command[0] = thrust_command[0];
        command[1] = thrust_command[1];
        command[2] = torques[0];
        command[3] = torques[1];

        // Integrators, frozen while saturated (anti-windup).
        if !saturated {
            for (integral, e) in self.inner_integral.iter_mut().zip(inner_error) {
                *integral += tau * e;
            }
            if !sigma_saturated {
                for axis in 0..2 {
                    self.xy_integral[axis] += tau * xy_error[axis];
                    self.swing_integral[axis] += tau * swing[axis];
                }
            }
        }
        filters[0].advance(phi_ref, tau);
        filters[1].advance(theta_ref, tau);
        self.internals = Internals {
            attitude_reference: [phi_ref, theta_ref],
            swing_velocity: [swing[0], swing[1]],
            thrust_state: self.thrust,
            saturated,
        };
    }

    /// The thrust integrators, the integrals of the inner loop, of x, y and of the swing, and
    /// the φ_Ref and θ_Ref prefilters once they exist.
    fn freeze(&self) -> Option<Vec<u8>> {
        Some(freeze_value(&Frozen {
            thrust: self.thrust,
            inner_integral: self.inner_integral,
            xy_integral: self.xy_integral,
            swing_integral: self.swing_integral,
            prefilter: self.prefilter.as_ref().map(|[phi, theta]| [phi.y, theta.y]),
        }))
    }

    fn thaw(&mut self, frozen: &[u8]) -> anyhow::Result<()> {
        let frozen: Frozen = thaw_value(frozen)?;
        (self.thrust, self.inner_integral) = (frozen.thrust, frozen.inner_integral);
        (self.xy_integral, self.swing_integral) = (frozen.xy_integral, frozen.swing_integral);
        let omega = self.prefilter_rad_s;
        self.prefilter = frozen.prefilter.map(|ys| ys.map(|y| Prefilter { omega, y }));
        Ok(())
    }
}

/// What [`TwoLoop`] keeps across a restart.
#[derive(Serialize, Deserialize)]
struct Frozen {
    thrust: [f64; 4],
    inner_integral: [f64; OUTPUTS],
    xy_integral: [f64; 2],
    swing_integral: [f64; 2],
    /// The φ_Ref and θ_Ref prefilters' y, y′, y″, y‴.
    prefilter: Option<[[f64; 4]; 2]>,
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scenarios::tiltrotor::reference::ReferenceSection;
    use crate::scenarios::tiltrotor::{STATE_LEN, state};

    const TICK: f64 = 0.01;

    /// The launch file's controller with this kind.
    fn section(kind: Kind) -> ControllerSection {
        let section: ControllerSection = launch_file()["controller"].clone().try_into().expect("[controller]");
        ControllerSection { kind, ..section }
    }

    fn launch_file() -> toml::Table {
        toml::from_str(include_str!("../../../../launch/tiltrotor.toml")).expect("launch/tiltrotor.toml parses")
    }

    fn hover_reference() -> ReferenceSection {
        ReferenceSection {
            start: [0.0, 0.0, 1.0, 0.0],
            x_moves: vec![],
            y_moves: vec![],
            z_moves: vec![],
            psi_moves: vec![],
        }
    }

    /// The estimate vector from a true state: x̂ = truth, angles and rates = truth.
    fn estimate_of(x: &[f64]) -> [f64; layout::LEN] {
        let mut e = [0.0; layout::LEN];
        e[layout::POSITION].copy_from_slice(&x[state::POSITION]);
        e[layout::VELOCITY].copy_from_slice(&x[state::VELOCITY]);
        e[layout::ANGLES].copy_from_slice(&x[state::ANGLES]);
        e[layout::ANGLE_RATES].copy_from_slice(&x[state::ANGLE_RATES]);
        e
    }

    /// The inner loop on its own design model: the reduced model (RK4 at 1 ms, the command held
    /// over each 10 ms tick) from z, φ, θ, ψ off their references converges to them.
    #[test]
    fn the_inner_loop_converges_on_its_design_model() {
        let nominal = Params::table1();
        let model = InnerModel::new(&nominal, [0.0, 0.0]);
        let mut c =
            TwoLoop::new(&section(Kind::Nlpt2l), &nominal, TiltReference::new(&hover_reference()), TICK, 17.0, 1.0);
        // z, φ, θ, ψ, α_R, α_L and rates; x, y held at the reference (the model has none).
        let mut q = [0.7, 0.15, -0.12, 0.3, 0.05, -0.05, 0.2, -0.3, 0.2, 0.1, 0.0, 0.0];
        let mut command = [0.0; 4];
        for k in 0..800 {
            let mut truth = [0.0; STATE_LEN];
            truth[2] = q[0];
            truth[3..8].copy_from_slice(&q[1..6]);
            truth[12] = q[6];
            truth[13..18].copy_from_slice(&q[7..12]);
            c.update(k as f64 * TICK, &estimate_of(&truth), &mut command);
            let f = |q: &[f64; 12]| {
                let mut x = [0.0; ext::LEN];
                x[..12].copy_from_slice(q);
                x[ext::F_R] = command[0];
                x[ext::F_L] = command[1];
                let d = model.derivative(&x, &[0.0, 0.0, command[2], command[3]]);
                std::array::from_fn::<f64, 12, _>(|i| d[i])
            };
            for _ in 0..10 {
                let h = TICK / 10.0;
                let axpy = |k: &[f64; 12], s: f64| std::array::from_fn(|i| q[i] + s * k[i]);
                let k1 = f(&q);
                let k2 = f(&axpy(&k1, h / 2.0));
                let k3 = f(&axpy(&k2, h / 2.0));
                let k4 = f(&axpy(&k3, h));
                q = std::array::from_fn(|i| q[i] + h / 6.0 * (k1[i] + 2.0 * k2[i] + 2.0 * k3[i] + k4[i]));
            }
        }
        let attitude_reference = c.internals().attitude_reference;
        assert!((q[0] - 1.0).abs() < 1e-3, "z {}", q[0]);
        assert!((q[1] - attitude_reference[0]).abs() < 1e-3, "φ {} vs {}", q[1], attitude_reference[0]);
        assert!((q[2] - attitude_reference[1]).abs() < 1e-3, "θ {} vs {}", q[2], attitude_reference[1]);
        assert!(q[3].abs() < 1e-3, "ψ {}", q[3]);
        assert!(q[6..].iter().all(|r| r.abs() < 1e-2), "rates {:?}", &q[6..]);
    }
}
