//! The flying inverted pendulum's metrics (names are a contract, issue 14). "Steady" is
//! t ≥ 20 s, after the initial transient (the paper starts 1.54 m from the path).
//!
//! - `zp_mean_m`, `zp_max_after_20s_m`: ‖z_p‖ = ‖p_L − p_Ld‖ of the true load, steady;
//! - `zp_z_mean_m`: its vertical part (NED: positive is below the path), steady;
//! - `vl_hat_speed_mean_m_s`: ‖v̂_L‖, steady;
//! - `b_hat_err_rms_n_{x,y,z}`: RMS of b̂ − b, steady; `b_hat_mean_n_*`, `b_mean_n_*` and
//!   `b_std_n_*` (b's own spread), steady;
//! - `thrust_mean_n`: the applied T, steady; `thrust_max_n`, `rate_max_rad_s`: whole run;
//! - `theta_pendulum_max_rad`: the largest angle of q from upright, whole run (and steady);
//! - `omega_err_rms_rad_s`, `vl_err_rms_m_s`, `q_hat_err_rms`: the filter's errors, steady;
//! - `lap_period_s`: when the reference's ϑ first reaches 2π (interpolated between ticks);
//!   `reference_speed_err_max_m_s`: the largest |‖ṗ_Ld‖ − V|;
//! - the command link's hold and the data age at the actuator (`model::command_link`).

use std::collections::BTreeMap;

use super::reference::EllipseReference;
use super::{INPUTS, layout, state};
use crate::model::command_link::ActuationAge;
use crate::model::mean::{Mean, max_keeping_nan};
use crate::model::reference::Reference;
use crate::model::scenario::{Metrics, Row};

pub const STEADY_FROM_S: f64 = 20.0;

fn norm(v: &[f64]) -> f64 {
    v.iter().map(|x| x * x).sum::<f64>().sqrt()
}

fn difference_norm(a: &[f64], b: &[f64]) -> f64 {
    a.iter().zip(b).map(|(x, y)| (x - y).powi(2)).sum::<f64>().sqrt()
}

pub struct FipMetrics {
    reference: EllipseReference,
    speed: f64,
    zp: Mean,
    zp_max: Option<f64>,
    zp_z: Mean,
    vl_hat_speed: Mean,
    b_err: [Mean; 3],
    b_hat: [Mean; 3],
    b: [Mean; 3],
    thrust: Mean,
    thrust_max: f64,
    rate_max: f64,
    theta_max: f64,
    /// When the largest angle was reached.
    theta_max_at: f64,
    theta_max_steady: Option<f64>,
    omega_err: Mean,
    vl_err: Mean,
    q_hat_err: Mean,
    previous_theta: Option<(f64, f64)>,
    lap_period: Option<f64>,
    speed_err_max: f64,
    actuation: ActuationAge,
}

impl FipMetrics {
    pub fn new(reference: EllipseReference, speed: f64) -> Self {
        Self {
            reference,
            speed,
            zp: Mean::default(),
            zp_max: None,
            zp_z: Mean::default(),
            vl_hat_speed: Mean::default(),
            b_err: [Mean::default(); 3],
            b_hat: [Mean::default(); 3],
            b: [Mean::default(); 3],
            thrust: Mean::default(),
            thrust_max: 0.0,
            rate_max: 0.0,
            theta_max: 0.0,
            theta_max_at: 0.0,
            theta_max_steady: None,
            omega_err: Mean::default(),
            vl_err: Mean::default(),
            q_hat_err: Mean::default(),
            previous_theta: None,
            lap_period: None,
            speed_err_max: 0.0,
            actuation: ActuationAge::default(),
        }
    }
}

impl Metrics for FipMetrics {
    frozen_fields!(
        zp,
        zp_max,
        zp_z,
        vl_hat_speed,
        b_err,
        b_hat,
        b,
        thrust,
        thrust_max,
        rate_max,
        theta_max,
        theta_max_at,
        theta_max_steady,
        omega_err,
        vl_err,
        q_hat_err,
        previous_theta,
        lap_period,
        speed_err_max,
        actuation
    );

    fn observe(&mut self, row: &Row) {
        let (t, x, est) = (row.t, row.state, row.estimate);
        let point = self.reference.at(t);
        self.speed_err_max = max_keeping_nan(self.speed_err_max, (norm(&point.p[1]) - self.speed).abs());
        if self.lap_period.is_none() {
            let lap = std::f64::consts::TAU;
            if let Some((t0, theta0)) = self.previous_theta
                && point.theta >= lap
            {
                self.lap_period = Some(t0 + (t - t0) * (lap - theta0) / (point.theta - theta0));
            }
            self.previous_theta = Some((t, point.theta));
        }
        // The angle from upright, −e₃.
        let theta = (-x[state::DIRECTION][2]).clamp(-1.0, 1.0).acos();
        if theta > self.theta_max {
            (self.theta_max, self.theta_max_at) = (theta, t);
        }
        self.thrust_max = max_keeping_nan(self.thrust_max, row.applied[0]);
        self.rate_max = row.applied[1..INPUTS].iter().fold(self.rate_max, |m, r| max_keeping_nan(m, r.abs()));
        self.actuation.observe(row, INPUTS);
        if t < STEADY_FROM_S {
            return;
        }
        let z_p: Vec<f64> = (0..3).map(|i| x[state::LOAD_POSITION][i] - point.p[0][i]).collect();
        let zp = norm(&z_p);
        self.zp.add(zp);
        self.zp_max = Some(max_keeping_nan(self.zp_max.unwrap_or(0.0), zp));
        self.zp_z.add(z_p[2]);
        self.vl_hat_speed.add(norm(&est[layout::LOAD_VELOCITY_HAT]));
        for i in 0..3 {
            let (b_hat, b) = (est[layout::DISTURBANCE_HAT][i], x[state::DISTURBANCE][i]);
            self.b_err[i].add(b_hat - b);
            self.b_hat[i].add(b_hat);
            self.b[i].add(b);
        }
        self.thrust.add(row.applied[0]);
        self.theta_max_steady = Some(max_keeping_nan(self.theta_max_steady.unwrap_or(0.0), theta));
        self.omega_err.add(difference_norm(&est[layout::RATE_HAT], &x[state::RATE]));
        self.vl_err.add(difference_norm(&est[layout::LOAD_VELOCITY_HAT], &x[state::LOAD_VELOCITY]));
        self.q_hat_err.add(difference_norm(&est[layout::DIRECTION_HAT], &x[state::DIRECTION]));
    }

    fn finish(&self) -> BTreeMap<String, f64> {
        let mut m = BTreeMap::new();
        let mut put = |name: &str, value: Option<f64>| {
            if let Some(v) = value {
                m.insert(name.to_string(), v);
            }
        };
        put("zp_mean_m", self.zp.mean());
        put("zp_max_after_20s_m", self.zp_max);
        put("zp_z_mean_m", self.zp_z.mean());
        put("vl_hat_speed_mean_m_s", self.vl_hat_speed.mean());
        for (i, axis) in ["x", "y", "z"].iter().enumerate() {
            put(&format!("b_hat_err_rms_n_{axis}"), self.b_err[i].rms());
            put(&format!("b_hat_mean_n_{axis}"), self.b_hat[i].mean());
            put(&format!("b_mean_n_{axis}"), self.b[i].mean());
            put(&format!("b_std_n_{axis}"), self.b[i].std());
        }
        put("thrust_mean_n", self.thrust.mean());
        put("thrust_max_n", Some(self.thrust_max));
        put("rate_max_rad_s", Some(self.rate_max));
        put("theta_pendulum_max_rad", Some(self.theta_max));
        put("theta_pendulum_max_after_20s_rad", self.theta_max_steady);
        put("omega_err_rms_rad_s", self.omega_err.rms());
        put("vl_err_rms_m_s", self.vl_err.rms());
        put("q_hat_err_rms", self.q_hat_err.rms());
        put("lap_period_s", self.lap_period);
        put("reference_speed_err_max_m_s", Some(self.speed_err_max));
        for (name, value) in self.actuation.metrics() {
            put(name, Some(value));
        }
        m
    }

    /// A rod that swung far from upright is worth saying in words: the paper's start (1.54 m
    /// from the path, the filter's q̂ pointing down) makes a violent first second.
    fn notes(&self) -> Vec<String> {
        if self.theta_max < 30f64.to_radians() {
            return Vec::new();
        }
        let past = if self.theta_max > std::f64::consts::FRAC_PI_2 { " (past horizontal)" } else { "" };
        let after = self
            .theta_max_steady
            .map(|a| format!("; after {STEADY_FROM_S} s it stayed within {:.1}°", a.to_degrees()))
            .unwrap_or_default();
        vec![format!(
            "the rod swung to {:.0}° from upright{past} at t = {:.2} s{after}",
            self.theta_max.to_degrees(),
            self.theta_max_at
        )]
    }
}
