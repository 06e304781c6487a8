//! Tilt-rotor UAV carrying a suspended load (paper 004: G. V. Raffo and
//! M. M. de Almeida, "A Load Transportation Nonlinear Control Strategy Using a Tilt-Rotor UAV",
//! Journal of Advanced Transportation, 2018; see README.md).
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
mod paper;
pub mod params;
pub mod plant;
pub mod reference;
pub mod sensors;

use serde::Deserialize;

use self::controller::{ControllerSection, TwoLoop};
use self::disturbance::DisturbanceSection;
use self::estimator::{EstimatorSection, Inputs, Lkfui};
use self::metrics::{MetricsSection, TiltrotorMetrics};
use self::params::Params;
use self::plant::{PlantSection, TiltrotorPlant};
use self::reference::{ReferenceSection, TiltReference};
use crate::config::launch::{LaunchConfig, LaunchError};
use crate::config::validate::{MAX_SI, in_range, not_negative, positive, within, within_si};
use crate::model::scenario::{
    Controller, ErrorMeasure, Estimator, Metrics, Plant, PositionLimits, ScenarioEntry, ScenarioParts, check_substeps,
};
use crate::model::vectors::{Component, Vectors, concat};

pub const ENTRY: ScenarioEntry = ScenarioEntry {
    name: "tiltrotor",
    description: "tilt-rotor UAV with a suspended load, LKFUI and NLLS-2L / NLPT-2L (paper 004)",
    file: "launch/tiltrotor.toml",
    text: include_str!("../../../../launch/tiltrotor.toml"),
    vectors: &VECTORS,
    build,
    paper: Some(&paper::PAPER),
};

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

/// `[model]`: what is not Table 1 (which is built in, `params.rs`).
#[derive(Debug, Clone, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
struct ModelSection {
    /// The plant's masses and inertia tensors are each scaled by a factor drawn from
    /// U[1 − this, 1 + this].
    uncertainty_fraction: f64,
    uncertainty_seed: u64,
    thrust_max_n: f64,
    tilt_torque_max_nm: f64,
}

pub struct Tiltrotor {
    model: ModelSection,
    plant: PlantSection,
    disturbance: DisturbanceSection,
    estimator: EstimatorSection,
    controller: ControllerSection,
    reference: ReferenceSection,
    limits: PositionLimits,
    metrics: MetricsSection,
    inputs: Inputs,
    tick_s: f64,
    fix_period_ticks: u32,
}

fn build(c: &LaunchConfig) -> Result<Box<dyn ScenarioParts>, LaunchError> {
    Ok(Box::new(Tiltrotor::from_config(c)?))
}

impl Tiltrotor {
    pub fn from_config(c: &LaunchConfig) -> Result<Self, LaunchError> {
        let model: ModelSection = c.section("model")?;
        if !(0.0..1.0).contains(&model.uncertainty_fraction) {
            return Err(c.error(
                "model.uncertainty_fraction",
                format!("must be 0 or more and below 1 (a fraction of each mass), got {}", model.uncertainty_fraction),
            ));
        }
        positive(c, "model.thrust_max_n", model.thrust_max_n)?;
        within_si(c, "model.thrust_max_n", model.thrust_max_n)?;
        positive(c, "model.tilt_torque_max_nm", model.tilt_torque_max_nm)?;
        within_si(c, "model.tilt_torque_max_nm", model.tilt_torque_max_nm)?;

        let plant: PlantSection = c.section("plant")?;
        check_substeps(c, "plant.substeps", plant.substeps)?;
        for (i, v) in plant.initial.position_m.iter().enumerate() {
            within_si(c, &format!("plant.initial.position_m.{i}"), *v)?;
        }
        within(c, "plant.initial.yaw_rad", plant.initial.yaw_rad, std::f64::consts::PI, "rad")?;
        for (i, v) in plant.initial.load_rad.iter().enumerate() {
            // The rod must hang below the body: beyond ±π/2 the load is above it.
            within(c, &format!("plant.initial.load_rad.{i}"), *v, 1.5, "rad")?;
        }

        let disturbance: DisturbanceSection = c.section("disturbance")?;
        for (i, step) in disturbance.steps.iter().enumerate() {
            not_negative(c, &format!("disturbance.steps.{i}.0"), step[0])?;
            for (j, v) in step.iter().enumerate() {
                within_si(c, &format!("disturbance.steps.{i}.{j}"), *v)?;
            }
        }
        for (i, pulse) in disturbance.pulses.iter().enumerate() {
            not_negative(c, &format!("disturbance.pulses.{i}.0"), pulse[0])?;
            positive(c, &format!("disturbance.pulses.{i}.1"), pulse[1])?;
            for (j, v) in pulse.iter().enumerate() {
                within_si(c, &format!("disturbance.pulses.{i}.{j}"), *v)?;
            }
        }

        let reference: ReferenceSection = c.section("reference")?;
        for (i, v) in reference.start.iter().enumerate() {
            within_si(c, &format!("reference.start.{i}"), *v)?;
        }
        for (name, moves) in reference.moves() {
            for (i, [at, duration, by]) in moves.iter().enumerate() {
                not_negative(c, &format!("reference.{name}.{i}.0"), *at)?;
                within_si(c, &format!("reference.{name}.{i}.0"), *at)?;
                // A C⁴ step's fourth derivative grows as 1/duration⁴.
                in_range(c, &format!("reference.{name}.{i}.1"), *duration, 0.5..=MAX_SI, "s")?;
                within_si(c, &format!("reference.{name}.{i}.2"), *by)?;
            }
        }

        let estimator: EstimatorSection = c.section("estimator")?;
        // R must be positive definite; P₀ and Q may be singular.
        positive(c, "estimator.r_position_m", estimator.r_position_m)?;
        positive(c, "estimator.r_velocity_m_s", estimator.r_velocity_m_s)?;
        for (key, value) in [
            ("estimator.q_scale", estimator.q_scale),
            ("estimator.p0_position_m", estimator.p0_position_m),
            ("estimator.p0_velocity_m_s", estimator.p0_velocity_m_s),
        ] {
            not_negative(c, key, value)?;
            within_si(c, key, value)?;
        }
        for (key, value) in
            [("estimator.r_position_m", estimator.r_position_m), ("estimator.r_velocity_m_s", estimator.r_velocity_m_s)]
        {
            within_si(c, key, value)?;
        }
        let controller: ControllerSection = c.section("controller")?;
        controller::check(c, &controller)?;

        let limits = PositionLimits::load(c)?;

        let metrics: MetricsSection = c.section("metrics")?;
        let [from, to] = metrics.d_hat_window_s;
        if !(from.is_finite() && to.is_finite() && 0.0 <= from && from < to) {
            return Err(
                c.error("metrics.d_hat_window_s", format!("must be [from, to] with 0 ≤ from < to, got {from}, {to}"))
            );
        }
        if !disturbance.is_constant_over(from, to) {
            return Err(c.error(
                "metrics.d_hat_window_s",
                format!(
                    "must be a window where the disturbance is constant; a step or pulse falls in [{from}, {to}] s"
                ),
            ));
        }

        // The LKFUI needs the fix (position and velocity together, every h ticks), the
        // angles, and the known force.
        let (position, _, position_spec) = c.sensor_for("position")?;
        let (velocity, velocity_name, velocity_spec) = c.sensor_for("velocity")?;
        let (attitude, _, _) = c.sensor_for("attitude")?;
        let (force, _, _) = c.sensor_for("thrust_force")?;
        let fix_period_ticks = c.period_ticks(position_spec);
        if c.period_ticks(velocity_spec) != fix_period_ticks {
            return Err(c.error(
                &format!("sensors.{velocity_name}.period_s"),
                format!(
                    "must equal the position sensor's period ({} s): the LKFUI corrects with both at once",
                    position_spec.period_s
                ),
            ));
        }
        let fix_period_ticks = u32::try_from(fix_period_ticks.max(1)).unwrap_or(u32::MAX);
        Ok(Self {
            model,
            plant,
            disturbance,
            estimator,
            controller,
            reference,
            limits,
            metrics,
            inputs: Inputs { position, velocity, attitude, force },
            tick_s: c.dt(),
            fix_period_ticks,
        })
    }

    /// The vehicle as flown: Table 1 with the seeded draw.
    pub fn true_params(&self) -> Params {
        Params::table1().perturbed(self.model.uncertainty_fraction, self.model.uncertainty_seed)
    }

    fn reference(&self) -> TiltReference {
        TiltReference::new(&self.reference)
    }
}

impl ScenarioParts for Tiltrotor {
    fn title(&self) -> String {
        format!("tilt-rotor with a suspended load, {}, LKFUI", self.controller.kind)
    }

    fn input_limits(&self) -> Vec<(f64, f64)> {
        let (f, tau) = (self.model.thrust_max_n, self.model.tilt_torque_max_nm);
        vec![(0.0, f), (0.0, f), (-tau, tau), (-tau, tau)]
    }

    fn plant(&self) -> Box<dyn Plant> {
        Box::new(TiltrotorPlant::new(self.true_params(), &self.plant, self.disturbance.clone()))
    }

    fn estimator(&self) -> Box<dyn Estimator> {
        let nominal = Params::table1();
        Box::new(Lkfui::new(
            &self.estimator,
            nominal.total_mass(),
            nominal.g,
            self.tick_s,
            self.fix_period_ticks,
            self.inputs,
            self.plant.initial.position_m,
        ))
    }

    fn controller(&self) -> Box<dyn Controller> {
        Box::new(TwoLoop::new(
            &self.controller,
            &Params::table1(),
            self.reference(),
            self.tick_s,
            self.model.thrust_max_n,
            self.model.tilt_torque_max_nm,
        ))
    }

    fn metrics(&self) -> Box<dyn Metrics> {
        Box::new(TiltrotorMetrics::new(
            &self.metrics,
            self.reference(),
            Params::table1().rod_length,
            self.model.thrust_max_n,
        ))
    }

    fn error_measure(&self) -> ErrorMeasure {
        self.limits.error_measure("|xi - xi_ref| m", self.reference())
    }
}
