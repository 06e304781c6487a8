//! The quadcopter's rigid-body model (21) (paper 001), NED frame (z down):
//!
//!   ṗ = R v,   Ṙ = R S(ω),   v̇ = −S(ω) v + g Rᵀe₃ + m⁻¹ Rᵀ b − m⁻¹ T e₃,
//!   ω̇ = −J⁻¹ S(ω) J ω + J⁻¹ τ
//!
//! with v and ω in the body frame and b a constant force in {I}. RK4 on (p, R, v, ω) with R
//! brought back onto SO(3) after every step (never Euler angles).
//!
//! The actuator is either the torque itself (`torque`, the paper's simulations) or the lab
//! vehicle's on-board rate loop (`rate-loop`): ω follows the commanded rate through a first-order
//! lag, ω̇ = (ω_cmd − ω)/τ_r, whatever torque that takes. A command link that takes a new
//! command only every `command_period_s` (the lab's RF uplink, 45 ms) holds it in between.
//! Optional: process noise on v̇ and ω̇, and a mass that steps at a given time.

use nalgebra::{Matrix3, SVector, Vector3};
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, StandardNormal};
use serde::Deserialize;

use super::params::{Actuation, Model};
use super::{INPUTS, STATE_LEN};
use crate::model::command_link::CommandLink;
use crate::model::integrate::rk4;
use crate::model::scenario::Plant;
use crate::model::so3::{orthonormalise, rotation, skew, write_rotation};

#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PlantSection {
    /// RK4 steps per loop period.
    pub substeps: u32,
    /// Process noise: standard deviation of the accelerations added to v̇ and ω̇, drawn each
    /// tick and held over it (the paper's (58): variances 10⁻³ and 1).
    pub process_noise_std: [f64; 2],
    /// The mass steps by `mass_step_kg` at `mass_step_at_s` (the added mass of §9.2; 0: none).
    pub mass_step_kg: f64,
    pub mass_step_at_s: f64,
    pub initial: Initial,
}

#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Initial {
    pub position_m: [f64; 3],
    pub velocity_m_s: [f64; 3],
    pub rate_rad_s: [f64; 3],
}

impl PlantSection {
    pub fn mass_at(&self, model: &Model, t: f64) -> f64 {
        if self.mass_step_kg != 0.0 && t >= self.mass_step_at_s {
            model.mass_kg + self.mass_step_kg
        } else {
            model.mass_kg
        }
    }
}

type State = SVector<f64, 18>;

pub struct QuadcopterPlant {
    model: Model,
    section: PlantSection,
    /// p, R (row-major), v, ω, m.
    x: [f64; STATE_LEN],
    rng: ChaCha8Rng,
    link: CommandLink<INPUTS>,
    applied: [f64; INPUTS],
}

impl QuadcopterPlant {
    pub fn new(model: Model, section: PlantSection, seed: u64) -> Self {
        let mut x = [0.0; STATE_LEN];
        let i = &section.initial;
        x[0..3].copy_from_slice(&i.position_m);
        write_rotation(&Matrix3::identity(), &mut x[3..12]);
        x[12..15].copy_from_slice(&i.velocity_m_s);
        x[15..18].copy_from_slice(&i.rate_rad_s);
        x[18] = section.mass_at(&model, 0.0);
        let rng = ChaCha8Rng::seed_from_u64(seed ^ crate::config::seed::fnv1a("plant"));
        let link = CommandLink::new(model.command_period_s);
        Self { model, section, x, rng, link, applied: [0.0; INPUTS] }
    }
}

/// ẋ of (p, R, v, ω) for the given mass, thrust, torque (or rate command) and noise.
fn derivative(
    model: &Model,
    mass: f64,
    thrust: f64,
    drive: &Vector3<f64>,
    noise: &(Vector3<f64>, Vector3<f64>),
    x: &State,
) -> State {
    let r = rotation(&x.as_slice()[3..12]);
    let v = Vector3::new(x[12], x[13], x[14]);
    let w = Vector3::new(x[15], x[16], x[17]);
    let j = Vector3::from(model.inertia_kg_m2);
    let e3 = Vector3::z();
    let b = Vector3::from(model.disturbance_n);
    let p_dot = r * v;
    let r_dot = r * skew(&w);
    let v_dot = -w.cross(&v) + model.g * r.transpose() * e3 + r.transpose() * b / mass - e3 * (thrust / mass) + noise.0;
    let w_dot = match model.actuation {
        Actuation::Torque => (-w.cross(&j.component_mul(&w)) + drive).component_div(&j),
        Actuation::RateLoop => (drive - w) / model.rate_loop_time_constant_s,
    } + noise.1;
    let mut dx = State::zeros();
    dx.fixed_rows_mut::<3>(0).copy_from(&p_dot);
    write_rotation(&r_dot, &mut dx.as_mut_slice()[3..12]);
    dx.fixed_rows_mut::<3>(12).copy_from(&v_dot);
    dx.fixed_rows_mut::<3>(15).copy_from(&w_dot);
    dx
}

impl Plant for QuadcopterPlant {
    fn state(&self) -> &[f64] {
        &self.x
    }

    fn step(&mut self, t: f64, u: &[f64], dt: f64) -> anyhow::Result<()> {
        let command = self.link.through(t, u);
        self.applied = command;
        let thrust = command[0];
        let drive = match self.model.actuation {
            Actuation::Torque => Vector3::new(command[1], command[2], command[3]),
            Actuation::RateLoop => Vector3::new(command[4], command[5], command[6]),
        };
        let [std_v, std_w] = self.section.process_noise_std;
        let mut draw = |std: f64| {
            Vector3::from_fn(|_, _| {
                if std > 0.0 { std * Distribution::<f64>::sample(&StandardNormal, &mut self.rng) } else { 0.0 }
            })
        };
        let noise = (draw(std_v), draw(std_w));
        // The mass in effect over the tick is the one at its start; a step lands on a tick.
        let mass = self.section.mass_at(&self.model, t);
        let f = |x: &State| derivative(&self.model, mass, thrust, &drive, &noise, x);
        let substeps = self.section.substeps;
        let h = dt / f64::from(substeps);
        let mut x = State::from_column_slice(&self.x[..18]);
        for _ in 0..substeps {
            x = rk4(&f, &x, h, 1);
            let r = orthonormalise(&rotation(&x.as_slice()[3..12]));
            write_rotation(&r, &mut x.as_mut_slice()[3..12]);
        }
        self.x[..18].copy_from_slice(x.as_slice());
        self.x[18] = self.section.mass_at(&self.model, t + dt);
        Ok(())
    }

    fn restore(&mut self, state: &[f64]) {
        self.x.copy_from_slice(state);
        self.link.reset();
    }

    fn applied_input(&self) -> Option<&[f64]> {
        Some(&self.applied)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    pub(crate) fn model(actuation: Actuation) -> Model {
        Model {
            mass_kg: 0.2,
            inertia_kg_m2: [6e-3, 4e-3, 1e-3],
            g: 9.8,
            disturbance_n: [0.0; 3],
            actuation,
            rate_loop_time_constant_s: 0.05,
            command_period_s: 0.0,
            thrust_max_n: 20.0,
            torque_max_nm: 1.0,
            rate_max_rad_s: 50.0,
        }
    }

    fn section() -> PlantSection {
        PlantSection {
            substeps: 4,
            process_noise_std: [0.0, 0.0],
            mass_step_kg: 0.0,
            mass_step_at_s: 0.0,
            initial: Initial { position_m: [0.0; 3], velocity_m_s: [0.0; 3], rate_rad_s: [0.0; 3] },
        }
    }

    /// Torque-free spin: angular momentum in {I} and rotational energy are conserved, and R
    /// stays a rotation.
    #[test]
    fn torque_free_rigid_body_conserves_momentum_and_energy() {
        let mut section = section();
        section.initial.rate_rad_s = [0.3, 4.0, 0.2]; // near the unstable middle axis: a hard case
        let model = model(Actuation::Torque);
        let j = Vector3::from(model.inertia_kg_m2);
        let mut plant = QuadcopterPlant::new(model, section, 1);
        let momentum = |x: &[f64]| rotation(&x[3..12]) * j.component_mul(&Vector3::new(x[15], x[16], x[17]));
        let energy = |x: &[f64]| {
            0.5 * Vector3::new(x[15], x[16], x[17]).dot(&j.component_mul(&Vector3::new(x[15], x[16], x[17])))
        };
        let (l0, e0) = (momentum(plant.state()), energy(plant.state()));
        // Hover thrust so that the translational part stays tame.
        let u = [0.2 * 9.8, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0];
        for k in 0..5000 {
            plant.step(k as f64 * 1e-3, &u, 1e-3).unwrap();
        }
        let x = plant.state();
        assert!((momentum(x) - l0).norm() < 1e-8 * l0.norm(), "momentum drifted to {}", momentum(x));
        assert!((energy(x) - e0).abs() < 1e-8 * e0, "energy drifted");
        let r = rotation(&x[3..12]);
        assert!((r.transpose() * r - Matrix3::identity()).norm() < 1e-12 && (r.determinant() - 1.0).abs() < 1e-12);
    }

    #[test]
    fn command_link_holds_between_slots_and_the_rate_loop_is_a_first_order_lag() {
        let mut model = model(Actuation::RateLoop);
        model.command_period_s = 0.045;
        let mut plant = QuadcopterPlant::new(model, section(), 1);
        let dt = 1.0 / 1200.0;
        let mut taken = Vec::new();
        for k in 0..200u64 {
            let u = [1.96, 0.0, 0.0, 0.0, 0.0, 0.0, k as f64];
            plant.step(k as f64 * dt, &u, dt).unwrap();
            taken.push(plant.applied_input().unwrap()[6]);
        }
        // 45 ms is 54 ticks at 1200 Hz: the link takes the commands of ticks 0, 54, 108, 162.
        for (k, value) in taken.iter().enumerate() {
            assert_eq!(*value, (k / 54 * 54) as f64, "tick {k}");
        }
        // ω_z after 54 ticks of a held zero command, then a step to 54 rad/s for 54 ticks:
        // 54(1 − e^{−0.045/0.05}).
        let mut plant = QuadcopterPlant::new(self::model(Actuation::RateLoop), section(), 1);
        for k in 0..54u64 {
            plant.step(k as f64 * dt, &[1.96, 0.0, 0.0, 0.0, 0.0, 0.0, 54.0], dt).unwrap();
        }
        let expected = 54.0 * (1.0 - (-0.045f64 / 0.05).exp());
        assert!((plant.state()[17] - expected).abs() < 1e-8, "{} vs {expected}", plant.state()[17]);
    }
}
