//! Quadcopter with a Kalman-Bucy parameter estimator and backstepping tracking (paper 001:
//! Zhu et al., "Kalman-Bucy Filter-Based Tracking Controller Design and Experimental Validations
//! for a Quadcopter with Parametric Uncertainties and Disturbances", 2022; see README.md).
//!
//! - `plant`: the rigid body (21) on SO(3), torque or rate-loop actuation, command link;
//! - `sensors`: motion-capture pose, body velocity, body rate;
//! - `estimator`: the 16-state KBF for ξ and the cascaded filters for m and J;
//! - `controller`: the backstepping thrust (56) and torque (57);
//! - `reference`: hover, the lemniscate (as meant and as printed), γ(t); the controller tracks
//!   it, and the metrics and the fault reports measure ‖p − p_d‖ from it.
//!
//! The cases of the paper are launch files in `launch/quadcopter/`.

pub mod controller;
pub mod estimator;
mod paper;
pub mod params;
pub mod plant;
pub mod reference;
pub mod sensors;

use std::collections::BTreeMap;

use serde::Deserialize;

use self::controller::{Backstepping, ControllerSection, Parameters};
use self::estimator::{EstimatorSection, Inputs, ParameterEstimator};
use self::params::{Actuation, Model};
use self::plant::{PlantSection, QuadcopterPlant};
use self::reference::{Reference, ReferenceSection};
use crate::config::launch::{LaunchConfig, LaunchError};
use crate::config::validate::{each, not_negative, period_within_run, positive, within, within_si};
use crate::model::command_link::ActuationAge;
use crate::model::mean::{Mean, max_keeping_nan};
use crate::model::reference::Reference as _;
use crate::model::scenario::{
    Controller, ErrorMeasure, Estimator, Metrics, Plant, PositionLimits, Row, ScenarioEntry, ScenarioParts,
    check_substeps,
};
use crate::model::vectors::{Component, Vectors, concat};

pub const ENTRY: ScenarioEntry = ScenarioEntry {
    name: "quadcopter",
    description: "quadcopter, backstepping tracking with a Kalman-Bucy parameter estimator (paper 001)",
    file: "launch/quadcopter.toml",
    text: include_str!("../../../../launch/quadcopter.toml"),
    vectors: &VECTORS,
    build,
    paper: Some(&paper::PAPER),
};

/// The true state: p, R (row-major), v, ω, m.
pub const STATE_LEN: usize = 19;
/// The command: T, τ, and the body-rate command of a rate-loop vehicle.
pub const INPUTS: usize = 7;

/// Where things are in the estimate vector: the measured motion the controller uses, then
/// the estimator's own output.
pub mod layout {
    use std::ops::Range;
    pub const POSE: Range<usize> = 0..12;
    pub const VELOCITY: Range<usize> = 12..15;
    pub const RATE: Range<usize> = 15..18;
    /// ξ̂ = (ξ₁, ξ₂, ξ₃, ξ₄).
    pub const XI: Range<usize> = 18..28;
    pub const XI2_RATE: Range<usize> = 28..31;
    pub const MASS: usize = 31;
    pub const INERTIA: Range<usize> = 32..35;
    /// (60): the largest singular value of the filter's continuous-time gain.
    pub const SNR: usize = 35;
    pub const LEN: usize = 36;
}

const fn c(name: &'static str, unit: &'static str) -> Component {
    Component::new(name, unit)
}

/// p in {I}, R row-major (the pose the motion capture measures).
const POSE: [Component; 12] = [
    c("p_x", "m"),
    c("p_y", "m"),
    c("p_z", "m"),
    c("R_11", "1"),
    c("R_12", "1"),
    c("R_13", "1"),
    c("R_21", "1"),
    c("R_22", "1"),
    c("R_23", "1"),
    c("R_31", "1"),
    c("R_32", "1"),
    c("R_33", "1"),
];
/// Body-frame linear velocity.
const VELOCITY: [Component; 3] = [c("v_x", "m/s"), c("v_y", "m/s"), c("v_z", "m/s")];
/// Body angular velocity.
const RATE: [Component; 3] = [c("w_x", "rad/s"), c("w_y", "rad/s"), c("w_z", "rad/s")];

const STATE: [Component; STATE_LEN] = concat(&[&POSE, &VELOCITY, &RATE, &[c("mass", "kg")]]);

const INPUT: [Component; INPUTS] = [
    c("thrust", "N"),
    c("tau_x", "N·m"),
    c("tau_y", "N·m"),
    c("tau_z", "N·m"),
    c("rate_cmd_x", "rad/s"),
    c("rate_cmd_y", "rad/s"),
    c("rate_cmd_z", "rad/s"),
];

/// The estimate, in the order of [`layout`]: ξ = (1/m, b/m, the inertia ratios, 1/J).
const ESTIMATE: [Component; layout::LEN] = concat(&[
    &POSE,
    &VELOCITY,
    &RATE,
    &[
        c("xi_1", "1/kg"),
        c("xi_2x", "m/s²"),
        c("xi_2y", "m/s²"),
        c("xi_2z", "m/s²"),
        c("xi_3x", "1"),
        c("xi_3y", "1"),
        c("xi_3z", "1"),
        c("xi_4x", "1/(kg·m²)"),
        c("xi_4y", "1/(kg·m²)"),
        c("xi_4z", "1/(kg·m²)"),
        c("xi_2x_rate", "m/s³"),
        c("xi_2y_rate", "m/s³"),
        c("xi_2z_rate", "m/s³"),
        c("mass", "kg"),
        c("j_x", "kg·m²"),
        c("j_y", "kg·m²"),
        c("j_z", "kg·m²"),
        c("snr", "1"),
    ],
]);

pub static VECTORS: Vectors = Vectors { state: &STATE, input: &INPUT, estimate: &ESTIMATE, signals: sensors::SIGNALS };

#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
struct MetricsSection {
    /// Steady state starts here: `z1_rms_m` and `snr_mean` are taken from this time on.
    steady_from_s: f64,
}

pub struct Quadcopter {
    model: Model,
    plant: PlantSection,
    estimator: EstimatorSection,
    controller: ControllerSection,
    reference: ReferenceSection,
    limits: PositionLimits,
    metrics: MetricsSection,
    inputs: Inputs,
    seed: u64,
}

fn build(c: &LaunchConfig) -> Result<Box<dyn ScenarioParts>, LaunchError> {
    Ok(Box::new(Quadcopter::from_config(c)?))
}

impl Quadcopter {
    pub fn from_config(c: &LaunchConfig) -> Result<Self, LaunchError> {
        let model: Model = c.section("model")?;
        positive(c, "model.mass_kg", model.mass_kg)?;
        for (i, j) in model.inertia_kg_m2.iter().enumerate() {
            positive(c, &format!("model.inertia_kg_m2.{i}"), *j)?;
        }
        positive(c, "model.g", model.g)?;
        positive(c, "model.rate_loop_time_constant_s", model.rate_loop_time_constant_s)?;
        period_within_run(c, "model.command_period_s", model.command_period_s, true)?;
        positive(c, "model.thrust_max_n", model.thrust_max_n)?;
        positive(c, "model.torque_max_nm", model.torque_max_nm)?;
        positive(c, "model.rate_max_rad_s", model.rate_max_rad_s)?;

        let plant: PlantSection = c.section("plant")?;
        check_substeps(c, "plant.substeps", plant.substeps)?;
        for (i, std) in plant.process_noise_std.iter().enumerate() {
            not_negative(c, &format!("plant.process_noise_std.{i}"), *std)?;
            within_si(c, &format!("plant.process_noise_std.{i}"), *std)?;
        }
        // Larger initial motion overflows the rigid body's products (ω × Jω) within a step.
        let initial = &plant.initial;
        for (name, values) in [
            ("position_m", initial.position_m),
            ("velocity_m_s", initial.velocity_m_s),
            ("rate_rad_s", initial.rate_rad_s),
        ] {
            for (i, value) in values.iter().enumerate() {
                within_si(c, &format!("plant.initial.{name}.{i}"), *value)?;
            }
        }
        if plant.mass_step_kg <= -model.mass_kg {
            return Err(c.error("plant.mass_step_kg", "must leave a positive mass"));
        }
        not_negative(c, "plant.mass_step_at_s", plant.mass_step_at_s)?;
        // Positive parameters can still overflow (a mass of 1e-300 kg): ξ = (1/m, b/m, ...) of
        // the vehicle before and after the mass step must be finite.
        for (key, mass) in
            [("model.mass_kg", model.mass_kg), ("plant.mass_step_kg", model.mass_kg + plant.mass_step_kg)]
        {
            let xi = model.xi(mass);
            if !xi.iter().all(|x| x.is_finite()) {
                return Err(c.error(
                    key,
                    format!(
                        "with these mass, inertia and disturbance values ξ = (1/m, b/m, ...) is not finite: {xi:?}; \
                         keep them within physical ranges"
                    ),
                ));
            }
        }

        let estimator: EstimatorSection = c.section("estimator")?;
        positive(c, "estimator.r", estimator.r)?;
        positive(c, "estimator.r_scale", estimator.r_scale)?;
        positive(c, "estimator.q_scale", estimator.q_scale)?;
        for (name, blocks) in [("q", estimator.q), ("p0", estimator.p0)] {
            for (i, value) in blocks.iter().enumerate() {
                positive(c, &format!("estimator.{name}.{i}"), *value)?;
            }
        }
        for (name, [r, q]) in [("mass_filter", estimator.mass_filter), ("inertia_filter", estimator.inertia_filter)] {
            positive(c, &format!("estimator.{name}.0"), r)?;
            positive(c, &format!("estimator.{name}.1"), q)?;
        }
        positive(c, "estimator.initial_mass_inertia_factor", estimator.initial_mass_inertia_factor)?;
        // ξ̂₁(0) = factor · 1/m: the mass filter divides by it.
        positive(c, "estimator.initial_xi_factor.0", estimator.initial_xi_factor[0])?;

        let controller: ControllerSection = c.section("controller")?;
        for (i, k) in controller.gains.iter().enumerate() {
            positive(c, &format!("controller.gains.{i}"), *k)?;
        }
        positive(c, "controller.beta", controller.beta)?;
        if !(controller.delta[2].is_finite() && controller.delta[2] != 0.0) {
            return Err(c.error("controller.delta", "δ₃ (the third component) must not be 0 (Lemma 4.1)"));
        }

        let reference: ReferenceSection = c.section("reference")?;
        each(c, "reference.hover_position", &reference.hover_position, within_si)?;
        positive(c, "reference.lemniscate_size_m", reference.lemniscate_size_m)?;
        within_si(c, "reference.lemniscate_size_m", reference.lemniscate_size_m)?;
        not_negative(c, "reference.lemniscate_speed_m_s", reference.lemniscate_speed_m_s)?;
        within_si(c, "reference.lemniscate_speed_m_s", reference.lemniscate_speed_m_s)?;
        within(c, "reference.lemniscate_tilt_deg", reference.lemniscate_tilt_deg, 360.0, "degrees")?;
        within_si(c, "reference.gamma_amplitude", reference.gamma_amplitude)?;
        within_si(c, "reference.gamma_frequency_rad_s", reference.gamma_frequency_rad_s)?;
        let limits = PositionLimits::load(c)?;
        let metrics: MetricsSection = c.section("metrics")?;
        not_negative(c, "metrics.steady_from_s", metrics.steady_from_s)?;

        let (pose, _, _) = c.sensor_for("pose")?;
        let has = |signal: &str| c.sensors.values().any(|s| s.signal == signal);
        let rates = match (has("velocity"), has("angular_rate")) {
            (true, true) => Some((c.sensor_for("velocity")?.0, c.sensor_for("angular_rate")?.0)),
            (false, false) => None,
            _ => {
                return Err(c.error(
                    "sensors",
                    "the quadcopter needs both a velocity and an angular_rate sensor, or neither \
                     (then both come from differencing the pose)",
                ));
            }
        };
        Ok(Self {
            model,
            plant,
            estimator,
            controller,
            reference,
            limits,
            metrics,
            inputs: Inputs { pose, rates },
            seed: c.seed,
        })
    }

    /// The reference the controller tracks and the metrics and fault reports measure from.
    fn reference(&self) -> Reference {
        Reference::new(&self.reference)
    }
}

impl ScenarioParts for Quadcopter {
    fn title(&self) -> String {
        let parameters = match self.controller.parameters {
            Parameters::Nominal => "true parameters",
            Parameters::Estimated => "estimated parameters",
        };
        let actuation = match self.model.actuation {
            Actuation::Torque => "torque",
            Actuation::RateLoop => "rate loop",
        };
        let sensing = if self.inputs.rates.is_some() { "full state" } else { "pose only" };
        format!("quadcopter, {:?} reference, {parameters}, {actuation}, {sensing}", self.reference.kind)
    }

    fn input_limits(&self) -> Vec<(f64, f64)> {
        let m = &self.model;
        let mut limits = vec![(0.0, m.thrust_max_n)];
        limits.extend([(-m.torque_max_nm, m.torque_max_nm); 3]);
        limits.extend([(-m.rate_max_rad_s, m.rate_max_rad_s); 3]);
        limits
    }

    fn plant(&self) -> Box<dyn Plant> {
        Box::new(QuadcopterPlant::new(self.model.clone(), self.plant.clone(), self.seed))
    }

    fn estimator(&self) -> Box<dyn Estimator> {
        Box::new(ParameterEstimator::new(&self.estimator, &self.model, self.inputs))
    }

    fn controller(&self) -> Box<dyn Controller> {
        Box::new(Backstepping::new(&self.controller, &self.model, self.reference()))
    }

    fn error_measure(&self) -> ErrorMeasure {
        self.limits.error_measure("|p - p_d| m", self.reference())
    }

    fn metrics(&self) -> Box<dyn Metrics> {
        Box::new(QuadcopterMetrics {
            reference: Some(self.reference()),
            model: Some(self.model.clone()),
            plant: Some(self.plant.clone()),
            steady_from_s: self.metrics.steady_from_s,
            ..Default::default()
        })
    }
}

/// Seconds before the mass step, and at the end of the run, over which the mass estimate is
/// averaged.
const MASS_WINDOW_S: f64 = 5.0;

#[derive(Default)]
struct QuadcopterMetrics {
    reference: Option<Reference>,
    model: Option<Model>,
    plant: Option<PlantSection>,
    steady_from_s: f64,
    z1_steady: Mean,
    z1_max_after_5s: f64,
    z1_last: f64,
    snr_steady: Mean,
    t_last: f64,
    xi_initial: Option<[f64; 10]>,
    /// Largest relative change of ξ̂₃ and ξ̂₄ from their initial estimates.
    xi3_change: f64,
    xi4_change: f64,
    xi_last: [f64; 10],
    xi_true_last: [f64; 10],
    mass_last: f64,
    mass_true_last: f64,
    /// Around the mass step: m̂ before it, m̂ over the last seconds (t, m̂), ‖z₁‖ before and after.
    mass_before: Mean,
    mass_recent: std::collections::VecDeque<(f64, f64)>,
    z1_before_step: Mean,
    z1_after_step: Mean,
    z1_max_after_step: f64,
    actuation: ActuationAge,
}

impl QuadcopterMetrics {
    fn step_at(&self) -> Option<f64> {
        self.plant.as_ref().filter(|p| p.mass_step_kg != 0.0).map(|p| p.mass_step_at_s)
    }
}

/// |x̂ − x|/|x|, or |x̂ − x| where x = 0.
fn relative_error(estimate: f64, truth: f64) -> f64 {
    let error = (estimate - truth).abs();
    if truth == 0.0 { error } else { error / truth.abs() }
}

fn block_change(now: &[f64], initial: &[f64]) -> f64 {
    let norm = |v: &[f64]| v.iter().map(|x| x * x).sum::<f64>().sqrt();
    let diff: Vec<f64> = now.iter().zip(initial).map(|(a, b)| a - b).collect();
    norm(&diff) / norm(initial).max(f64::MIN_POSITIVE)
}

impl Metrics for QuadcopterMetrics {
    frozen_fields!(
        z1_steady,
        z1_max_after_5s,
        z1_last,
        snr_steady,
        t_last,
        xi_initial,
        xi3_change,
        xi4_change,
        xi_last,
        xi_true_last,
        mass_last,
        mass_true_last,
        mass_before,
        mass_recent,
        z1_before_step,
        z1_after_step,
        z1_max_after_step,
        actuation
    );

    fn observe(&mut self, row: &Row) {
        let t = row.t;
        let z1 = self.reference.as_mut().expect("built with a reference").error(t, row.state);
        if t >= self.steady_from_s {
            self.z1_steady.add(z1);
            self.snr_steady.add(row.estimate[layout::SNR]);
        }
        if t >= 5.0 {
            self.z1_max_after_5s = max_keeping_nan(self.z1_max_after_5s, z1);
        }
        self.z1_last = z1;
        self.t_last = t;

        let mut xi = [0.0; 10];
        xi.copy_from_slice(&row.estimate[layout::XI]);
        let initial = *self.xi_initial.get_or_insert(xi);
        self.xi3_change = max_keeping_nan(self.xi3_change, block_change(&xi[4..7], &initial[4..7]));
        self.xi4_change = max_keeping_nan(self.xi4_change, block_change(&xi[7..10], &initial[7..10]));
        self.xi_last = xi;
        let mass_true = row.state[18];
        self.xi_true_last = self.model.as_ref().expect("built with a model").xi(mass_true);
        self.mass_last = row.estimate[layout::MASS];
        self.mass_true_last = mass_true;

        if let Some(at) = self.step_at() {
            if t < at {
                self.z1_before_step.add(z1);
                if t >= at - MASS_WINDOW_S {
                    self.mass_before.add(self.mass_last);
                }
            } else {
                self.z1_after_step.add(z1);
                self.z1_max_after_step = max_keeping_nan(self.z1_max_after_step, z1);
            }
        }
        self.actuation.observe(row, INPUTS);
        self.mass_recent.push_back((t, self.mass_last));
        while self.mass_recent.front().is_some_and(|(s, _)| *s <= t - MASS_WINDOW_S) {
            self.mass_recent.pop_front();
        }
    }

    fn finish(&self) -> BTreeMap<String, f64> {
        let mut m = BTreeMap::new();
        if self.xi_initial.is_none() {
            return m;
        }
        let mut put = |name: &str, value: Option<f64>| {
            if let Some(v) = value {
                m.insert(name.to_string(), v);
            }
        };
        put("z1_rms_m", self.z1_steady.rms());
        put("z1_max_after_5s_m", (self.t_last >= 5.0).then_some(self.z1_max_after_5s));
        put("z1_final_m", Some(self.z1_last));
        put("mass_estimate_final_kg", Some(self.mass_last));
        put("mass_true_kg", Some(self.mass_true_last));
        let (xi, truth) = (&self.xi_last, &self.xi_true_last);
        let errors: Vec<f64> = xi.iter().zip(truth).map(|(e, t)| relative_error(*e, *t)).collect();
        put("param_rel_error_max_final", errors.iter().copied().reduce(max_keeping_nan));
        put("xi1_rel_error_final", Some(errors[0]));
        put("xi2_error_final_m_s2", errors[1..4].iter().copied().reduce(max_keeping_nan));
        put("xi3_rel_error_max_final", errors[4..7].iter().copied().reduce(max_keeping_nan));
        put("xi4_rel_error_max_final", errors[7..10].iter().copied().reduce(max_keeping_nan));
        put("xi3_change_max_rel", Some(self.xi3_change));
        put("xi4_change_max_rel", Some(self.xi4_change));
        // b = ξ₂/ξ₁.
        for (i, axis) in ["x", "y", "z"].iter().enumerate() {
            put(&format!("disturbance_estimate_{axis}_n"), Some(xi[1 + i] / xi[0]));
        }
        let b_true = self.model.as_ref().map(|m| m.disturbance_n).unwrap_or_default();
        let b_error = (0..3).map(|i| (xi[1 + i] / xi[0] - b_true[i]).powi(2)).sum::<f64>().sqrt();
        put("disturbance_error_n", Some(b_error));
        put("snr_mean", self.snr_steady.mean());
        for (name, value) in self.actuation.metrics() {
            put(name, Some(value));
        }
        if self.step_at().is_some() {
            let before = self.mass_before.mean();
            let n = self.mass_recent.len() as f64;
            let after = (n > 0.0).then(|| self.mass_recent.iter().map(|(_, m)| m).sum::<f64>() / n);
            put("mass_estimate_before_step_kg", before);
            put("mass_estimate_after_step_kg", after);
            put("mass_estimate_rise_kg", before.zip(after).map(|(b, a)| a - b));
            let (lo, hi) =
                self.mass_recent.iter().fold((f64::MAX, f64::MIN), |(lo, hi), (_, m)| (lo.min(*m), hi.max(*m)));
            put("mass_estimate_spread_last_5s_kg", (n > 0.0).then_some(hi - lo));
            put("z1_rms_before_step_m", self.z1_before_step.rms());
            put("z1_rms_after_step_m", self.z1_after_step.rms());
            put("z1_max_after_step_m", (self.z1_after_step.n > 0).then_some(self.z1_max_after_step));
        }
        m
    }

    fn notes(&self) -> Vec<String> {
        // A block that never moved from its initial estimate was not identified: nothing in
        // the run excited it (with γ = 0, ω and τ stay 0, so Ω(ω) and U(τ) of A_ξ are 0).
        let mut notes = Vec::new();
        for (name, change) in [("xi_3", self.xi3_change), ("xi_4", self.xi4_change)] {
            if self.xi_initial.is_some() && change < 1e-9 {
                notes.push(format!(
                    "{name} stayed at its initial estimate (relative change {change:.1e}): it is unobservable \
                     in this run, nothing excited it"
                ));
            }
        }
        notes
    }
}
