//! The truth: the planar vehicle on a rigid link to a ground point (section II), in the
//! frame (z_W up; the thrust points along [sin ϑ, cos ϑ] in the x–z plane; the vehicle at
//! l[cos ϕ, sin ϕ]).
//!
//! The motion comes from Newton–Euler with the joint force as the unknown, which covers both
//! models at once: the ideal one of (1) (massless link at the centre of mass) and the general
//! one of section VI-C (a uniform link of mass m_L, the joint at r_BL in the body frame), where
//! two printed terms are corrected (ḡ₂ has no factor l; the thrust's moment is −r_x f_R).
//! The tests check this against (2), against a first-principles Lagrangian, and against energy.
//!
//! The motors may lag the commands (first order, τ_M, on thrust and torque; section VI-E):
//! within a step the thrust is the exact exponential towards the held command. The plant's
//! mass, length and inertia differ from the nominal ones by the deviations Δ of section VI-B:
//! nominal = (1 + Δ)·real, so Δ > 0 overestimates.

use nalgebra::SVector;
use serde::Deserialize;

use super::params::Model;
use super::{STATE_LEN, state};
use crate::model::integrate::rk4;
use crate::model::scenario::Plant;

/// `[plant]`.
#[derive(Debug, Clone, Copy, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct PlantSection {
    /// RK4 steps per tick.
    pub substeps: u32,
    /// "ideal" (eq. 1) or "general" (section VI-C: link mass and joint offset).
    pub model: ModelKind,
    /// m_L, kg (general model only).
    pub link_mass_kg: f64,
    /// r_BL = [r_x, r_z], m, in the body frame (general model only).
    pub joint_offset_m: [f64; 2],
    /// τ_M, s; 0: the motors follow the commands at once.
    pub motor_time_constant_s: f64,
    /// Δm_R, Δl, ΔJ_R: nominal = (1 + Δ)·real.
    pub mass_deviation: f64,
    pub length_deviation: f64,
    pub inertia_deviation: f64,
    /// [Δϕ, Δϑ], rad: the start, away from the reference's first equilibrium, at rest.
    pub initial_offset_rad: [f64; 2],
}

#[derive(Debug, Clone, Copy, Deserialize, PartialEq, Eq, strum::Display)]
#[serde(rename_all = "lowercase")]
#[strum(serialize_all = "lowercase")]
pub enum ModelKind {
    Ideal,
    General,
}

/// The real vehicle and link.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Body {
    pub mass: f64,
    pub inertia: f64,
    pub length: f64,
    pub g: f64,
    pub link_mass: f64,
    /// r_BL, [x, z] in the body frame.
    pub offset: [f64; 2],
}

impl Body {
    pub fn real(model: &Model, plant: &PlantSection) -> Self {
        let general = plant.model == ModelKind::General;
        Self {
            mass: model.robot_mass_kg / (1.0 + plant.mass_deviation),
            inertia: model.inertia_kg_m2 / (1.0 + plant.inertia_deviation),
            length: model.link_length_m / (1.0 + plant.length_deviation),
            g: model.g_m_s2,
            link_mass: if general { plant.link_mass_kg } else { 0.0 },
            offset: if general { plant.joint_offset_m } else { [0.0, 0.0] },
        }
    }
}

/// Planar vectors are [x, z]. cross(a, b) = a_x b_z − a_z b_x is the moment about y that turns
/// x towards z, the sense in which ϕ grows; ϑ grows the other way (it tilts the thrust from z
/// towards x).
fn cross(a: [f64; 2], b: [f64; 2]) -> f64 {
    a[0] * b[1] - a[1] * b[0]
}

fn dot(a: [f64; 2], b: [f64; 2]) -> f64 {
    a[0] * b[0] + a[1] * b[1]
}

/// The body axes in the world: x_B = [−cos ϑ, sin ϑ], z_B = [−sin ϑ, −cos ϑ] (R = R_y(ϑ + π)).
pub fn body_axes(theta: f64) -> ([f64; 2], [f64; 2]) {
    let (s, c) = theta.sin_cos();
    ([-c, s], [-s, -c])
}

/// What the vehicle does at one instant.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Motion {
    pub phi_ddot: f64,
    pub theta_ddot: f64,
    /// f_L along d, > 0 pulling the vehicle towards the ground point (tension).
    pub link_force: f64,
    /// The specific force at the vehicle's centre of mass in the body frame, [a_x, a_z] (13).
    pub accel: [f64; 2],
}

/// The accelerations at state (ϕ, ϕ̇, ϑ, ϑ̇) with thrust f and torque τ. Unknowns ϕ̈, ϑ̈ and the
/// joint's force F on the vehicle:
/// - vehicle: m(p̈_B + g e₃) = F + f t, p_B = l d − w with w = R r_BL;
/// - vehicle about its centre of mass: J ϑ̈ = τ − cross(w, F);
/// - link about the ground point: (m_L l²/3) ϕ̈ = −cross(l d, F) − m_L g (l/2) cos ϕ.
///
/// p̈_B is linear in ϕ̈ and ϑ̈, so F is too; the two moment equations give a 2×2 system.
pub fn motion(b: &Body, phi: f64, phi_dot: f64, theta: f64, theta_dot: f64, thrust: f64, torque: f64) -> Motion {
    let (sp, cp) = phi.sin_cos();
    let d = [cp, sp];
    let d_perp = [-sp, cp];
    let t = [theta.sin(), theta.cos()];
    let (x_b, z_b) = body_axes(theta);
    let w = [b.offset[0] * x_b[0] + b.offset[1] * z_b[0], b.offset[0] * x_b[1] + b.offset[1] * z_b[1]];
    // dw/dϑ; d²w/dϑ² = −w.
    let w_prime = [w[1], -w[0]];
    let l = b.length;
    let m = b.mass;
    // F = F_phi ϕ̈ + F_theta ϑ̈ + F_0.
    let f_phi = [m * l * d_perp[0], m * l * d_perp[1]];
    let f_theta = [-m * w_prime[0], -m * w_prime[1]];
    let f_0: [f64; 2] = std::array::from_fn(|i| {
        let gravity = if i == 1 { b.g } else { 0.0 };
        m * (-l * d[i] * phi_dot * phi_dot + w[i] * theta_dot * theta_dot + gravity) - thrust * t[i]
    });
    let ld = [l * d[0], l * d[1]];
    let a11 = b.link_mass * l * l / 3.0 + cross(ld, f_phi);
    let a12 = cross(ld, f_theta);
    let r1 = -cross(ld, f_0) - b.link_mass * b.g * 0.5 * l * cp;
    let a21 = cross(w, f_phi);
    let a22 = b.inertia + cross(w, f_theta);
    let r2 = torque - cross(w, f_0);
    let det = a11 * a22 - a12 * a21;
    let phi_ddot = (r1 * a22 - a12 * r2) / det;
    let theta_ddot = (a11 * r2 - a21 * r1) / det;
    let force: [f64; 2] = std::array::from_fn(|i| f_phi[i] * phi_ddot + f_theta[i] * theta_ddot + f_0[i]);
    let specific = [(force[0] + thrust * t[0]) / m, (force[1] + thrust * t[1]) / m];
    Motion { phi_ddot, theta_ddot, link_force: -dot(d, force), accel: [dot(x_b, specific), dot(z_b, specific)] }
}

pub struct TetheredPlant {
    body: Body,
    substeps: u32,
    time_constant: f64,
    x: [f64; STATE_LEN],
    /// The motors' start: [f_R, 0, 0], held until the first command arrives.
    initial_input: [f64; 3],
}

impl TetheredPlant {
    /// At rest at (ϕ, ϑ) with the motors at `thrust` and no torque, held until the first
    /// command.
    pub fn new(body: Body, section: &PlantSection, phi: f64, theta: f64, thrust: f64) -> Self {
        let mut x = [0.0; STATE_LEN];
        x[state::PHI] = phi;
        x[state::THETA] = theta;
        x[state::THRUST] = thrust;
        let mut plant = Self {
            body,
            substeps: section.substeps,
            time_constant: section.motor_time_constant_s,
            x,
            initial_input: [thrust, 0.0, 0.0],
        };
        plant.write_outputs();
        plant
    }

    /// The link force and the specific force at the current state and motor outputs.
    fn write_outputs(&mut self) {
        let x = &self.x;
        let m = motion(
            &self.body,
            x[state::PHI],
            x[state::PHI_DOT],
            x[state::THETA],
            x[state::THETA_DOT],
            x[state::THRUST],
            x[state::TORQUE],
        );
        self.x[state::LINK_FORCE] = m.link_force;
        self.x[state::ACCEL].copy_from_slice(&m.accel);
    }

    /// The motors' output s seconds into a step from `from` towards the held `command`.
    fn motor(&self, from: f64, command: f64, s: f64) -> f64 {
        if self.time_constant > 0.0 { command + (from - command) * (-s / self.time_constant).exp() } else { command }
    }
}

impl Plant for TetheredPlant {
    fn state(&self) -> &[f64] {
        &self.x
    }

    /// u = [f_R, τ_R, ḟ_R]: the plant takes the first two (the rate is for the estimator).
    fn step(&mut self, _t: f64, u: &[f64], dt: f64) -> anyhow::Result<()> {
        let (thrust0, torque0) = (self.x[state::THRUST], self.x[state::TORQUE]);
        // y = [ϕ, ϕ̇, ϑ, ϑ̇, s]: s, the time into the step, gives the motors' exact lag.
        let f = |y: &SVector<f64, 5>| {
            let thrust = self.motor(thrust0, u[0], y[4]);
            let torque = self.motor(torque0, u[1], y[4]);
            let m = motion(&self.body, y[0], y[1], y[2], y[3], thrust, torque);
            SVector::<f64, 5>::new(y[1], m.phi_ddot, y[3], m.theta_ddot, 1.0)
        };
        let x = &self.x;
        let y0 = SVector::<f64, 5>::new(x[state::PHI], x[state::PHI_DOT], x[state::THETA], x[state::THETA_DOT], 0.0);
        let y = rk4(&f, &y0, dt, self.substeps);
        let thrust = self.motor(thrust0, u[0], dt);
        let torque = self.motor(torque0, u[1], dt);
        self.x[..4].copy_from_slice(&y.as_slice()[..4]);
        self.x[state::THRUST] = thrust;
        self.x[state::TORQUE] = torque;
        self.write_outputs();
        Ok(())
    }

    fn restore(&mut self, state: &[f64]) {
        self.x.copy_from_slice(&state[..STATE_LEN]);
    }

    /// The vehicle starts in flight: its motors keep the start's thrust until the controller's
    /// first command (in real time the plant ticks before it arrives).
    fn initial_input(&self) -> Option<&[f64]> {
        Some(&self.initial_input)
    }
}

#[cfg(test)]
mod tests {
    use super::super::params::tests::paper;
    use super::*;

    fn ideal() -> Body {
        Body { mass: 1.0, inertia: 0.25, length: 2.0, g: 9.81, link_mass: 0.0, offset: [0.0, 0.0] }
    }

    fn general() -> Body {
        Body { link_mass: 0.2, offset: [0.03, 0.03], ..ideal() }
    }

    const STATES: [[f64; 6]; 4] = [
        [0.3, 0.2, 0.5, -0.4, 12.0, 0.3],
        [1.2, -1.1, -0.2, 0.9, 9.0, -1.0],
        [2.5, 0.4, 1.9, 2.0, 15.0, 0.0],
        [0.8, 0.0, 0.0, 0.0, 0.0, 0.0],
    ];

    /// The ideal model is (2) and (5), and the accelerometer is (15) corrected:
    /// a_x = (f_L/m_R) cos(ϕ+ϑ), a_z = (f_L/m_R) sin(ϕ+ϑ) − f_R/m_R.
    #[test]
    fn the_ideal_model_is_the_papers_state_space_form() {
        let m = paper();
        for [phi, phi_dot, theta, theta_dot, f, tau] in STATES {
            let got = motion(&ideal(), phi, phi_dot, theta, theta_dot, f, tau);
            let psi = phi + theta;
            let phi_ddot = m.a1() * phi.cos() + m.a2() * psi.cos() * f;
            let link_force = phi_dot * phi_dot / m.a2() + m.a1() / m.a2() * phi.sin() + psi.sin() * f;
            assert!((got.phi_ddot - phi_ddot).abs() < 1e-12);
            assert!((got.theta_ddot - m.a3() * tau).abs() < 1e-12);
            assert!((got.link_force - link_force).abs() < 1e-12);
            assert!((got.accel[0] - link_force * psi.cos()).abs() < 1e-12);
            assert!((got.accel[1] - (link_force * psi.sin() - f)).abs() < 1e-12);
        }
    }

    /// The general model satisfies a first-principles Lagrangian, thrust and
    /// torque included: (m_R l² + m_L l²/3)ϕ̈ + m₁₂ϑ̈ + c₀ϑ̇² + (m_R + m_L/2) g l cos ϕ = l cos ψ f_R
    /// and m₁₂ϕ̈ + (J_R + m_R‖r‖²)ϑ̈ + c₀ϕ̇² − m_R g (R̄r)·e₃ = τ_R − r_x f_R.
    #[test]
    fn the_general_model_satisfies_the_notes_lagrangian() {
        let b = general();
        let (m, l) = (b.mass, b.length);
        for [phi, phi_dot, theta, theta_dot, f, tau] in STATES {
            let got = motion(&b, phi, phi_dot, theta, theta_dot, f, tau);
            let (x_b, z_b) = body_axes(theta);
            let w: [f64; 2] = std::array::from_fn(|i| b.offset[0] * x_b[i] + b.offset[1] * z_b[i]);
            let w_bar = [w[1], -w[0]];
            let d = [phi.cos(), phi.sin()];
            let d_perp = [-phi.sin(), phi.cos()];
            let m12 = -m * l * dot(d_perp, w_bar);
            let c0 = m * l * dot(d, w_bar);
            let r2 = b.offset[0] * b.offset[0] + b.offset[1] * b.offset[1];
            let first = (m * l * l + b.link_mass * l * l / 3.0) * got.phi_ddot
                + m12 * got.theta_ddot
                + c0 * theta_dot * theta_dot
                + (m + b.link_mass / 2.0) * b.g * l * phi.cos()
                - l * (phi + theta).cos() * f;
            let second = m12 * got.phi_ddot + (b.inertia + m * r2) * got.theta_ddot + c0 * phi_dot * phi_dot
                - m * b.g * w_bar[1]
                - (tau - b.offset[0] * f);
            assert!(first.abs() < 1e-10 && second.abs() < 1e-10, "residuals {first}, {second}");
        }
    }

    /// Without thrust or torque the general model keeps its energy: ½(m_L l²/3)ϕ̈² + ½m_R|ṗ_B|²
    /// + ½J_R ϑ̇² + m_R g z_B + m_L g (l/2) sin ϕ, over 3 s of swinging, to 1e-9 of its swing.
    #[test]
    fn without_inputs_the_general_model_keeps_its_energy() {
        let b = general();
        let section = PlantSection {
            substeps: 10,
            model: ModelKind::General,
            link_mass_kg: b.link_mass,
            joint_offset_m: b.offset,
            motor_time_constant_s: 0.0,
            mass_deviation: 0.0,
            length_deviation: 0.0,
            inertia_deviation: 0.0,
            initial_offset_rad: [0.0, 0.0],
        };
        let mut plant = TetheredPlant::new(b, &section, 1.0, 0.4, 0.0);
        let mut x = plant.state().to_vec();
        x[state::PHI_DOT] = 0.7;
        x[state::THETA_DOT] = -1.3;
        plant.restore(&x);
        let energy = |x: &[f64]| {
            let (phi, phi_dot, theta, theta_dot) = (x[0], x[1], x[2], x[3]);
            let (x_b, z_b) = body_axes(theta);
            let w: [f64; 2] = std::array::from_fn(|i| b.offset[0] * x_b[i] + b.offset[1] * z_b[i]);
            let w_prime = [w[1], -w[0]];
            let velocity: [f64; 2] =
                std::array::from_fn(|i| b.length * [-phi.sin(), phi.cos()][i] * phi_dot - w_prime[i] * theta_dot);
            let height = b.length * phi.sin() - w[1];
            0.5 * b.link_mass * b.length.powi(2) / 3.0 * phi_dot * phi_dot
                + 0.5 * b.mass * dot(velocity, velocity)
                + 0.5 * b.inertia * theta_dot * theta_dot
                + b.mass * b.g * height
                + b.link_mass * b.g * 0.5 * b.length * phi.sin()
        };
        let start = energy(plant.state());
        let mut swing: f64 = 0.0;
        for k in 0..3000 {
            plant.step(k as f64 * 1e-3, &[0.0, 0.0, 0.0], 1e-3).unwrap();
            swing = swing.max((plant.state()[state::PHI] - 1.0).abs());
        }
        assert!(swing > 0.5, "it hardly moved ({swing} rad)");
        let drift = energy(plant.state()) - start;
        assert!(drift.abs() < 1e-9 * b.mass * b.g * b.length, "energy drifted by {drift} J");
    }

    /// With a motor lag τ_M the thrust follows a step in the command as 1 − e^(−t/τ_M) exactly.
    #[test]
    fn the_motors_lag_the_commands_by_their_time_constant() {
        let section = PlantSection {
            substeps: 1,
            model: ModelKind::Ideal,
            link_mass_kg: 0.0,
            joint_offset_m: [0.0, 0.0],
            motor_time_constant_s: 0.05,
            mass_deviation: 0.0,
            length_deviation: 0.0,
            inertia_deviation: 0.0,
            initial_offset_rad: [0.0, 0.0],
        };
        let mut plant = TetheredPlant::new(ideal(), &section, 0.5, 0.0, 10.0);
        for k in 0..50 {
            plant.step(k as f64 * 1e-3, &[12.0, 1.0, 0.0], 1e-3).unwrap();
        }
        let x = plant.state();
        let lagged = 1.0 - (-1.0f64).exp();
        assert!((x[state::THRUST] - (10.0 + 2.0 * lagged)).abs() < 1e-12, "{}", x[state::THRUST]);
        assert!((x[state::TORQUE] - lagged).abs() < 1e-12);
    }
}
