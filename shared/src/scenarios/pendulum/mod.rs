//! Reaction-wheel inverted pendulum with a biased angle sensor (paper 003; see
//! README.md).
//!
//! - `plant`: the nonlinear model;
//! - `sensors`: what the encoder and the motor controller's speed sensor read;
//! - `estimator`: the bias observer and the no-bias observer;
//! - `controller`: the LQR state feedback with the current limit;
//! - `reference`: the upright setpoint the controller, the metrics and the fault reports share.

pub mod controller;
pub mod estimator;
pub mod margin;
mod paper;
pub mod params;
pub mod plant;
pub mod reference;
pub mod sensors;

use std::collections::BTreeMap;

use nalgebra::{RowVector3, Vector3};
use serde::Deserialize;

use self::controller::StateFeedback;
use self::estimator::{Kind, PendulumEstimator};
use self::params::Model;
use self::plant::PendulumPlant;
use self::reference::Upright;
use crate::config::launch::{LaunchConfig, LaunchError};
use crate::config::validate::{positive, positive_as, within, within_si};
use crate::model::mean::max_keeping_nan;
use crate::model::reference::Reference;
use crate::model::scenario::{
    Controller, ErrorMeasure, Estimator, Metrics, Plant, Row, ScenarioEntry, ScenarioParts, TheoreticalMargin,
    check_substeps,
};
use crate::model::vectors::{Component, Vectors};

pub const ENTRY: ScenarioEntry = ScenarioEntry {
    name: "pendulum",
    description: "reaction-wheel inverted pendulum with a biased encoder, LQR and a bias observer (paper 003)",
    file: "launch/pendulum.toml",
    text: include_str!("../../../../launch/pendulum.toml"),
    vectors: &VECTORS,
    build,
    paper: Some(&paper::PAPER),
};

pub static VECTORS: Vectors = Vectors {
    state: &[
        Component::new("theta", "rad"),
        Component::new("theta_dot", "rad/s"),
        Component::new("wheel_speed", "rad/s"),
    ],
    input: &[Component::new("current", "A")],
    estimate: &[
        Component::new("theta", "rad"),
        Component::new("theta_dot", "rad/s"),
        Component::new("wheel_speed", "rad/s"),
        Component::new("bias", "rad"),
    ],
    signals: sensors::SIGNALS,
};

#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
struct PlantSection {
    /// RK4 steps per loop period.
    substeps: u32,
    initial: Initial,
}

#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
struct Initial {
    theta: f64,
    theta_dot: f64,
    wheel_speed: f64,
}

#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
struct EstimatorSection {
    kind: Kind,
    #[serde(rename = "bias-observer")]
    bias_observer: ObserverSection<3>,
    #[serde(rename = "no-bias")]
    no_bias: ObserverSection<2>,
}

#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
struct ObserverSection<const N: usize> {
    /// Error-dynamics poles (real, negative), at cos z = 1 for the bias observer.
    #[serde(with = "serde_arrays")]
    poles: [f64; N],
    /// Explicit gains; when given they are used as they are and `poles` is ignored.
    #[serde(default, with = "serde_arrays::option")]
    gains: Option<[f64; N]>,
}

/// How fault reports judge the pendulum.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
struct LimitsSection {
    /// |θ| beyond which the pendulum has fallen, rad.
    fall_angle_rad: f64,
    /// |θ| within which it counts as recovered, rad.
    recovery_band_rad: f64,
}

#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
struct ControllerSection {
    /// K in I = −K X, X = (θ, θ̇, φ̇).
    gains: [f64; 3],
}

/// Fixed-length arrays from TOML arrays, with a length error that names the expected length.
mod serde_arrays {
    use serde::{Deserialize, Deserializer, de::Error};

    pub fn deserialize<'de, D: Deserializer<'de>, const N: usize>(d: D) -> Result<[f64; N], D::Error> {
        let v = Vec::<f64>::deserialize(d)?;
        let len = v.len();
        v.try_into().map_err(|_| D::Error::custom(format!("expected {N} numbers, got {len}")))
    }

    pub mod option {
        use super::*;
        pub fn deserialize<'de, D: Deserializer<'de>, const N: usize>(d: D) -> Result<Option<[f64; N]>, D::Error> {
            super::deserialize(d).map(Some)
        }
    }
}

pub struct Pendulum {
    model: Model,
    plant: PlantSection,
    estimator: EstimatorSection,
    bias_gains: Vector3<f64>,
    no_bias_gains: nalgebra::Vector2<f64>,
    controller: ControllerSection,
    limits: LimitsSection,
    encoder: usize,
    wheel_speed: usize,
    bias_true: f64,
    /// The encoder's count, rad (0: not quantised).
    encoder_quantum: f64,
    dt: f64,
}

fn build(c: &LaunchConfig) -> Result<Box<dyn ScenarioParts>, LaunchError> {
    Ok(Box::new(Pendulum::from_config(c)?))
}

impl Pendulum {
    pub fn from_config(c: &LaunchConfig) -> Result<Self, LaunchError> {
        let model: Model = c.section("model")?;
        for (key, value) in [
            ("m_p", model.m_p),
            ("l_p", model.l_p),
            ("j_p", model.j_p),
            ("m_r", model.m_r),
            ("l_r", model.l_r),
            ("j_r", model.j_r),
            ("g", model.g),
            ("torque_constant", model.torque_constant),
            ("current_limit_a", model.current_limit_a),
        ] {
            positive(c, &format!("model.{key}"), value)?;
        }
        // Positive parameters can still overflow (1e300 kg): the linear model must be finite.
        let (a, b) = (model.a(), model.b());
        if !(a.is_finite() && a != 0.0 && b.is_finite() && b != 0.0) {
            return Err(c.error(
                "model",
                format!(
                    "these parameters give a = m·l·g/J₀ = {a} and b = −k/J₀ = {b}; both must be finite and \
                     non-zero (keep the parameters within physical ranges)"
                ),
            ));
        }
        let plant: PlantSection = c.section("plant")?;
        check_substeps(c, "plant.substeps", plant.substeps)?;
        // Larger initial motion is no pendulum experiment, and a rate near f64's limit
        // overflows within a step.
        within(c, "plant.initial.theta", plant.initial.theta, std::f64::consts::PI, "rad")?;
        within_si(c, "plant.initial.theta_dot", plant.initial.theta_dot)?;
        within_si(c, "plant.initial.wheel_speed", plant.initial.wheel_speed)?;
        let estimator: EstimatorSection = c.section("estimator")?;
        let poles_key = |kind: &str| format!("estimator.{kind}.poles");
        if estimator.bias_observer.poles.iter().any(|p| !(p.is_finite() && *p < 0.0)) {
            return Err(c.error(&poles_key("bias-observer"), "every pole must be a negative number (a stable error)"));
        }
        if estimator.no_bias.poles.iter().any(|p| !(p.is_finite() && *p < 0.0)) {
            return Err(c.error(&poles_key("no-bias"), "every pole must be a negative number (a stable error)"));
        }
        let bias_gains = match estimator.bias_observer.gains {
            Some(g) => Vector3::from(g),
            None => estimator::bias_observer_gains(model.a(), estimator.bias_observer.poles),
        };
        let no_bias_gains = match estimator.no_bias.gains {
            Some(g) => nalgebra::Vector2::from(g),
            None => estimator::no_bias_gains(estimator.no_bias.poles),
        };
        // Extreme poles give gains that overflow.
        if !bias_gains.iter().all(|g| g.is_finite()) {
            return Err(
                c.error(&poles_key("bias-observer"), format!("give gains too large to compute: {bias_gains:?}"))
            );
        }
        if !no_bias_gains.iter().all(|g| g.is_finite()) {
            return Err(c.error(&poles_key("no-bias"), format!("give gains too large to compute: {no_bias_gains:?}")));
        }
        let controller: ControllerSection = c.section("controller")?;
        let limits: LimitsSection = c.section("limits")?;
        for (key, value) in [("fall_angle_rad", limits.fall_angle_rad), ("recovery_band_rad", limits.recovery_band_rad)]
        {
            positive_as(c, &format!("limits.{key}"), value, "angle")?;
        }
        let (encoder, _, encoder_spec) = c.sensor_for("theta")?;
        let (wheel_speed, _, _) = c.sensor_for("wheel_speed")?;
        let bias_true = encoder_spec.bias.expand(1)[0];
        Ok(Pendulum {
            model,
            plant,
            estimator,
            bias_gains,
            no_bias_gains,
            controller,
            limits,
            encoder,
            wheel_speed,
            bias_true,
            encoder_quantum: encoder_spec.quantum,
            dt: c.dt(),
        })
    }
}

impl ScenarioParts for Pendulum {
    fn title(&self) -> String {
        let kind = match self.estimator.kind {
            Kind::BiasObserver => "bias-observer",
            Kind::NoBias => "no-bias",
        };
        format!("reaction-wheel pendulum, {kind}")
    }

    fn input_limits(&self) -> Vec<(f64, f64)> {
        vec![(-self.model.current_limit_a, self.model.current_limit_a)]
    }

    fn plant(&self) -> Box<dyn Plant> {
        let i = &self.plant.initial;
        Box::new(PendulumPlant::new(
            self.model.clone(),
            self.plant.substeps,
            Vector3::new(i.theta, i.theta_dot, i.wheel_speed),
        ))
    }

    fn estimator(&self) -> Box<dyn Estimator> {
        Box::new(PendulumEstimator::new(
            self.estimator.kind,
            &self.model,
            self.bias_gains,
            self.no_bias_gains,
            self.encoder,
            self.wheel_speed,
        ))
    }

    fn controller(&self) -> Box<dyn Controller> {
        Box::new(StateFeedback {
            gains: RowVector3::from(self.controller.gains),
            current_limit: self.model.current_limit_a,
            reference: Upright,
        })
    }

    fn error_measure(&self) -> ErrorMeasure {
        ErrorMeasure::of_reference("|theta| rad", Upright, self.limits.recovery_band_rad, self.limits.fall_angle_rad)
            .keyed("limits.fall_angle_rad")
            // Past the horizontal, gravity's torque is many times what the wheel's current limit
            // gives: it has fallen (or swung over), and nothing brings it back up.
            .lost_beyond(std::f64::consts::FRAC_PI_2, "fallen past the horizontal")
    }

    fn delay_margin(&self, config: &LaunchConfig) -> Option<TheoreticalMargin> {
        let m = margin::delay_margin(self, config)?;
        Some(TheoreticalMargin {
            ticks: m.ticks,
            continuous_ticks: m.continuous_ticks,
            lagged_ticks: m.lagged_ticks,
            crossover_rad_s: m.crossover_rad_s,
            phase_margin_deg: m.phase_margin_deg,
            radius_before: m.radius_before,
            radius_at_margin: m.radius_at_margin,
        })
    }

    fn metrics(&self) -> Box<dyn Metrics> {
        Box::new(PendulumMetrics {
            bias_true: self.bias_true,
            bias_band: settling_band(self.bias_true, self.encoder_quantum),
            current_limit: self.model.current_limit_a,
            observer: self.estimator.kind == Kind::BiasObserver,
            dt: self.dt,
            ..Default::default()
        })
    }
}

/// The band the bias estimate settles into: 2 % of the bias, but never narrower than two encoder
/// counts. The estimate cannot resolve less than a count, and the rounded angle's limit cycle
/// keeps it wandering by up to about 1.4 counts for good (δ = 0.03 rad, 20 s): a 2 % band there
/// (0.0006 rad, under one 0.000628 rad count) called it unsettled until 12-20 s.
fn settling_band(bias: f64, encoder_quantum: f64) -> f64 {
    (0.02 * bias.abs()).max(2.0 * encoder_quantum)
}

/// Seconds at the end of the run over which the settled values are averaged (the encoder's
/// quantisation leaves a small limit cycle, so one sample is a noisy final value).
const FINAL_WINDOW_S: f64 = 1.0;

#[derive(Default)]
struct PendulumMetrics {
    reference: Upright,
    bias_true: f64,
    current_limit: f64,
    /// Loops whose command was at the current limit.
    saturated: u64,
    /// Σ I² over the loops and their count: the run's RMS current, which the drive's continuous
    /// rating bounds (launch/pendulum.toml, `current_limit_a`).
    current_square_sum: f64,
    loops: u64,
    observer: bool,
    dt: f64,
    last: Option<(f64, f64, f64, f64)>,
    theta_max_abs: f64,
    /// Half-width of the band the bias estimate settles into, rad.
    bias_band: f64,
    /// Last time the bias estimate was outside the band (None: never).
    bias_last_outside: Option<f64>,
    /// (t, θ, φ̇) of the rows in the final window.
    recent: std::collections::VecDeque<(f64, f64, f64)>,
}

impl Metrics for PendulumMetrics {
    frozen_fields!(saturated, current_square_sum, loops, last, theta_max_abs, bias_last_outside, recent);

    fn observe(&mut self, row: &Row) {
        let (theta, wheel_speed, bias_estimate) = (row.state[0], row.state[2], row.estimate[3]);
        if row.command[0].abs() >= self.current_limit {
            self.saturated += 1;
        }
        self.current_square_sum += row.command[0] * row.command[0];
        self.loops += 1;
        self.last = Some((row.t, theta, wheel_speed, bias_estimate));
        self.theta_max_abs = max_keeping_nan(self.theta_max_abs, self.reference.error(row.t, row.state));
        if (bias_estimate - self.bias_true).abs() >= self.bias_band {
            self.bias_last_outside = Some(row.t);
        }
        self.recent.push_back((row.t, theta, wheel_speed));
        while self.recent.front().is_some_and(|(t, _, _)| *t <= row.t - FINAL_WINDOW_S) {
            self.recent.pop_front();
        }
    }

    fn finish(&self) -> BTreeMap<String, f64> {
        let mut m = BTreeMap::new();
        let Some((t_final, theta, wheel_speed, bias_estimate)) = self.last else {
            return m;
        };
        m.insert("theta_final_rad".into(), theta);
        m.insert("theta_max_abs_rad".into(), self.theta_max_abs);
        m.insert("wheel_speed_final_rad_s".into(), wheel_speed);
        let n = self.recent.len() as f64;
        m.insert("theta_mean_last_1s_rad".into(), self.recent.iter().map(|r| r.1).sum::<f64>() / n);
        m.insert("wheel_speed_mean_last_1s_rad_s".into(), self.recent.iter().map(|r| r.2).sum::<f64>() / n);
        m.insert("current_at_limit_s".into(), self.saturated as f64 * self.dt);
        m.insert("current_rms_a".into(), (self.current_square_sum / self.loops.max(1) as f64).sqrt());
        m.insert("bias_true_rad".into(), self.bias_true);
        m.insert("bias_estimate_final_rad".into(), bias_estimate);
        // Settled means inside the band from some time on; a run that ends outside it (or a
        // zero bias, which has nothing to settle to) has no settling time.
        if self.observer && self.bias_true != 0.0 {
            match self.bias_last_outside {
                None => {
                    m.insert("observer_settling_s".into(), 0.0);
                }
                Some(t) if t < t_final => {
                    m.insert("observer_settling_s".into(), t + self.dt);
                }
                Some(_) => {}
            }
        }
        m
    }
}
