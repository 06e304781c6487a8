//! The flying inverted pendulum's plant, (3) and (5) in NED:
//!
//!   ṗ_L = v_L,  v̇_L = (1/m_T)(f + b)∥ − (m_Qℓ/m_T)‖ω‖² q + g e₃,
//!   q̇ = S(ω) q,  ω̇ = −(1/(m_Qℓ)) S(q)(f + b),  Ṙ = R S(Ω),  f = −T R e₃,
//!
//! with (·)∥ = q qᵀ(·). The body rate Ω is a kinematic input (the paper models no attitude
//! dynamics), so over a tick with Ω held R(s) = R(t)·exp(S(Ω)s) exactly (Rodrigues), and the
//! thrust direction inside each RK4 stage is taken from it. The translational and pendulum
//! states go by RK4 on `substeps` steps per tick; after each, q is brought back onto the unit
//! sphere and ω projected onto q's normal plane, so qᵀω = 0 holds to rounding. No Euler
//! angles anywhere. b comes from `disturbance` (exact between its noise draws). A command link
//! (`command_period_s`, the experiment's 45 Hz radio) holds T and Ω between its slots.

use nalgebra::{Matrix3, SVector, Vector3};
use serde::Deserialize;

use super::disturbance::{Disturbance, DisturbanceSection, OverTick};
use super::params::Model;
use super::{INPUTS, STATE_LEN, state};
use crate::model::command_link::CommandLink;
use crate::model::scenario::Plant;
use crate::model::so3::{exp_so3, orthonormalise, rotation, write_rotation};

/// `[plant]`.
#[derive(Debug, Clone, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct PlantSection {
    /// RK4 steps per loop period.
    pub substeps: u32,
    /// The command link takes a new command every this many seconds and holds it (0: every tick).
    pub command_period_s: f64,
    pub initial: Initial,
}

/// `[plant.initial]`: (70), at rest, R = I.
#[derive(Debug, Clone, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct Initial {
    pub load_position_m: [f64; 3],
    /// The rod's angle from upright, degrees (the paper: 5°).
    pub tilt_deg: f64,
    /// The direction it leans to, from x towards y, degrees (the paper: 45°).
    pub tilt_azimuth_deg: f64,
}

impl Initial {
    /// q(0) = [sin θ cos φ, sin θ sin φ, −cos θ]: the paper's [sin5°/√2, sin5°/√2, −cos5°].
    pub fn direction(&self) -> [f64; 3] {
        let (theta, phi) = (self.tilt_deg.to_radians(), self.tilt_azimuth_deg.to_radians());
        [theta.sin() * phi.cos(), theta.sin() * phi.sin(), -theta.cos()]
    }
}

/// (p_L, v_L, q, ω).
type Motion = SVector<f64, 12>;

pub struct FipPlant {
    model: Model,
    substeps: u32,
    x: [f64; STATE_LEN],
    disturbance: Disturbance,
    link: CommandLink<INPUTS>,
    applied: [f64; INPUTS],
}

impl FipPlant {
    pub fn new(model: Model, section: &PlantSection, disturbance: DisturbanceSection, seed: u64) -> Self {
        let mut x = [0.0; STATE_LEN];
        x[state::LOAD_POSITION].copy_from_slice(&section.initial.load_position_m);
        x[state::DIRECTION].copy_from_slice(&section.initial.direction());
        write_rotation(&Matrix3::identity(), &mut x[state::ROTATION]);
        x[state::DISTURBANCE].copy_from_slice(&disturbance.initial());
        let mut plant = Self {
            model,
            substeps: section.substeps,
            x,
            disturbance: Disturbance::new(disturbance, seed),
            link: CommandLink::new(section.command_period_s),
            applied: [0.0; INPUTS],
        };
        plant.write_uav();
        plant
    }

    /// p_Q = p_L − ℓq and v_Q = v_L − ℓq̇ = v_L + ℓ S(q) ω, from the rest of the state.
    fn write_uav(&mut self) {
        let l = self.model.rod_length_m;
        let v3 = |r: std::ops::Range<usize>| Vector3::from_column_slice(&self.x[r]);
        let (p, v, q, w) = (v3(state::LOAD_POSITION), v3(state::LOAD_VELOCITY), v3(state::DIRECTION), v3(state::RATE));
        let p_uav = p - q * l;
        let v_uav = v + q.cross(&w) * l;
        self.x[state::UAV_POSITION].copy_from_slice(p_uav.as_slice());
        self.x[state::UAV_VELOCITY].copy_from_slice(v_uav.as_slice());
    }
}

/// (ṗ_L, v̇_L, q̇, ω̇) under total force `force` = f + b at the UAV.
fn motion_rate(model: &Model, y: &Motion, force: &Vector3<f64>) -> Motion {
    let v = y.fixed_rows::<3>(3).into_owned();
    let q = y.fixed_rows::<3>(6).into_owned();
    let w = y.fixed_rows::<3>(9).into_owned();
    let (m_t, m_ql) = (model.total_mass(), model.uav_mass_times_rod());
    let v_dot = q * (q.dot(force) / m_t) - q * (m_ql / m_t * w.norm_squared()) + Vector3::z() * model.g_m_s2;
    let w_dot = -q.cross(force) / m_ql;
    let q_dot = w.cross(&q);
    let mut dy = Motion::zeros();
    dy.fixed_rows_mut::<3>(0).copy_from(&v);
    dy.fixed_rows_mut::<3>(3).copy_from(&v_dot);
    dy.fixed_rows_mut::<3>(6).copy_from(&q_dot);
    dy.fixed_rows_mut::<3>(9).copy_from(&w_dot);
    dy
}

/// One RK4 step from `s` into the tick, the thrust direction and b taken at each stage's time.
fn rk4_step(
    model: &Model,
    y: &Motion,
    s: f64,
    h: f64,
    thrust_force: &impl Fn(f64) -> Vector3<f64>,
    b: &OverTick,
) -> Motion {
    let f = |s: f64, y: &Motion| motion_rate(model, y, &(thrust_force(s) + Vector3::from(b.at(s))));
    let k1 = f(s, y);
    let k2 = f(s + h / 2.0, &(y + k1 * (h / 2.0)));
    let k3 = f(s + h / 2.0, &(y + k2 * (h / 2.0)));
    let k4 = f(s + h, &(y + k3 * h));
    y + (k1 + k2 * 2.0 + k3 * 2.0 + k4) * (h / 6.0)
}

impl Plant for FipPlant {
    fn state(&self) -> &[f64] {
        &self.x
    }

    fn step(&mut self, t: f64, u: &[f64], dt: f64) -> anyhow::Result<()> {
        let command = self.link.through(t, u);
        self.applied = command;
        let thrust = command[0];
        let rate = Vector3::new(command[1], command[2], command[3]);
        let r0 = rotation(&self.x[state::ROTATION]);
        let thrust_force = |s: f64| -(r0 * exp_so3(&(rate * s))).column(2) * thrust;
        let mut b = [0.0; 3];
        b.copy_from_slice(&self.x[state::DISTURBANCE]);
        let b = self.disturbance.over_tick(t, b);

        let mut y = Motion::from_column_slice(&self.x[..12]);
        let h = dt / f64::from(self.substeps);
        for i in 0..self.substeps {
            y = rk4_step(&self.model, &y, f64::from(i) * h, h, &thrust_force, &b);
            let q = y.fixed_rows::<3>(6).normalize();
            let w = y.fixed_rows::<3>(9).into_owned();
            y.fixed_rows_mut::<3>(6).copy_from(&q);
            y.fixed_rows_mut::<3>(9).copy_from(&(w - q * q.dot(&w)));
        }
        self.x[..12].copy_from_slice(y.as_slice());
        write_rotation(&orthonormalise(&(r0 * exp_so3(&(rate * dt)))), &mut self.x[state::ROTATION]);
        self.x[state::DISTURBANCE].copy_from_slice(&b.at(dt));
        self.write_uav();
        Ok(())
    }

    fn restore(&mut self, state: &[f64]) {
        self.x.copy_from_slice(&state[..STATE_LEN]);
        self.link.reset();
    }

    fn applied_input(&self) -> Option<&[f64]> {
        Some(&self.applied)
    }
}

#[cfg(test)]
mod tests {
    use super::super::disturbance::Kind;
    use super::super::disturbance::tests::paper as disturbance;
    use super::super::params::tests::simulation;
    use super::*;

    fn paper_plant(kind: Kind) -> FipPlant {
        let section = PlantSection {
            substeps: 1,
            command_period_s: 0.0,
            initial: Initial { load_position_m: [0.0, 0.2, -0.3], tilt_deg: 5.0, tilt_azimuth_deg: 45.0 },
        };
        FipPlant::new(simulation(), &section, disturbance(kind), 1)
    }

    /// (70): q(0) = [0.061628, 0.061628, −0.996195], the UAV 0.7 m below the load.
    #[test]
    fn the_initial_state_is_the_papers() {
        let p = paper_plant(Kind::None);
        let x = p.state();
        for (got, want) in x[state::DIRECTION].iter().zip([0.061628, 0.061628, -0.996195]) {
            assert!((got - want).abs() < 1e-6, "{got} vs {want}");
        }
        // Derived by hand: p_Q(0) = [−0.043, 0.157, 0.397].
        for (got, want) in x[state::UAV_POSITION].iter().zip([-0.043, 0.157, 0.397]) {
            assert!((got - want).abs() < 1e-3, "{got} vs {want}");
        }
    }

    /// The equilibrium of section 2: with f + b = −m_T g e₃ and q upright, nothing moves; the
    /// constant b is cancelled by tilting the thrust.
    #[test]
    fn the_static_equilibrium_holds() {
        let model = simulation();
        let mut p = paper_plant(Kind::Constant);
        let mut x = [0.0; STATE_LEN];
        x[state::DIRECTION].copy_from_slice(&[0.0, 0.0, -1.0]);
        x[state::DISTURBANCE].copy_from_slice(&[-0.5, 0.5, -0.8]);
        // −T r₃ = −m_T g e₃ − b: r₃ along m_T g e₃ + b.
        let f = Vector3::new(0.5, -0.5, -model.hover_thrust() + 0.8);
        let r3 = -f.normalize();
        let axis = Vector3::z().cross(&r3);
        let r = exp_so3(&(axis.normalize() * Vector3::z().dot(&r3).acos()));
        write_rotation(&r, &mut x[state::ROTATION]);
        p.restore(&x);
        for k in 0..1000 {
            p.step(k as f64 * 1e-3, &[f.norm(), 0.0, 0.0, 0.0], 1e-3).unwrap();
        }
        let s = p.state();
        for (i, v) in s[..12].iter().enumerate() {
            let at_rest = if i == 8 { v + 1.0 } else { *v };
            assert!(at_rest.abs() < 1e-12, "state {i} = {v}");
        }
    }

    /// A free pendulum (no thrust, no gravity effect on q) keeps |q| = 1 and qᵀω = 0, and the
    /// body rate turns R exactly: after π/2 s at 1 rad/s about z, R is a quarter turn.
    #[test]
    fn the_manifolds_are_kept_and_rates_integrate_exactly() {
        let mut p = paper_plant(Kind::None);
        let mut x = p.state().to_vec();
        x[state::RATE].copy_from_slice(&[0.3, -0.2, 0.0]);
        // Make ω ⊥ q.
        let q = Vector3::from_column_slice(&x[state::DIRECTION]);
        let w = Vector3::new(0.3, -0.2, 0.0);
        x[state::RATE].copy_from_slice((w - q * q.dot(&w)).as_slice());
        p.restore(&x);
        let n = 1571;
        let dt = std::f64::consts::FRAC_PI_2 / n as f64;
        for k in 0..n {
            p.step(k as f64 * dt, &[1.0, 0.0, 0.0, 1.0], dt).unwrap();
        }
        let s = p.state();
        let q = Vector3::from_column_slice(&s[state::DIRECTION]);
        let w = Vector3::from_column_slice(&s[state::RATE]);
        assert!((q.norm() - 1.0).abs() < 1e-14 && q.dot(&w).abs() < 1e-14);
        let r = rotation(&s[state::ROTATION]);
        let quarter = Matrix3::new(0.0, -1.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 1.0);
        assert!((r - quarter).abs().max() < 1e-12, "{r}");
    }
}
