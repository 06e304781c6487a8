//! The LTV Kalman–Bucy filter of section 4 for x = [q, ω, b/(m_Qℓ)] (6), with the input
//! u = −T r₃/(m_Qℓ) (9) from the applied thrust and the measured attitude, and the output
//! y = [q; 0] (7), whose last row is the virtual measurement of the constraint qᵀω = 0.
//! A(t), B(t) and C(t) of (10)–(12) use the measured q: q = (p_L − p_Q)/‖·‖
//! from the motion capture.
//!
//! The filter runs as its exact discrete-time equivalent (the quadcopter's estimator does the
//! same), with q and u held over each tick, as the plant holds its inputs:
//! - A is nilpotent (A³ = 0), so Φ = I + Ah + A²h²/2 exactly, and the input enters through
//!   Γ = [S²(q)h²/2; −S(q)h; 0]·u.
//! - The process-noise intensity Q becomes Q_d = ∫Φ(s)QΦ(s)ᵀds, which with Φ a polynomial in
//!   s is Σ_{i,j≤2} h^(i+j+1)/((i+j+1) i! j!) AⁱQ(Aʲ)ᵀ, exact.
//! - The measurement-noise intensity R becomes R_d = R/h_m at each new motion-capture sample,
//!   h_m the time since the last one (a continuous measurement averaged over h_m has that
//!   covariance). Between samples the filter only predicts. The update is in Joseph form and P
//!   is kept symmetric.
//!
//! It publishes q̂, ω̂, b̂ = m_Qℓ·x̂₇:₉ and v̂_L = v_Q − ℓS(q)ω̂ (28), and passes the measured p_L,
//! q, R and v_Q on to the controller.

use nalgebra::{Matrix3, SMatrix, SVector, Vector3};
use serde::Deserialize;

use super::layout;
use super::params::Model;
use crate::contract::msg::SensorReading;
use crate::model::scenario::{Estimator, freeze_value, thaw_value};
use crate::model::so3::{rotation, skew};

type Vector9 = SVector<f64, 9>;
type Matrix9 = SMatrix<f64, 9, 9>;
type Matrix4x9 = SMatrix<f64, 4, 9>;

/// `[estimator]`: the paper's tuning, Q = diag(q_q I₃, q_ω I₃, diag(q_b)), R = r I₄.
#[derive(Debug, Clone, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct EstimatorSection {
    /// Process-noise intensity of q, 1/s.
    pub q_direction: f64,
    /// Of ω, rad²/s³.
    pub q_rate: f64,
    /// Of b/(m_Qℓ) per axis, 1/s⁵.
    pub q_disturbance: [f64; 3],
    /// R: the measurement-noise intensity of each of the four outputs, s.
    pub r: f64,
    /// P(0) per block: q, ω, b/(m_Qℓ).
    pub p0: [f64; 3],
    /// q̂(0); ω̂(0) = 0 and b̂(0) = 0 (the paper: e₃, pointing down, opposite to the truth).
    pub initial_direction: [f64; 3],
}

impl EstimatorSection {
    fn q_intensity(&self) -> Matrix9 {
        let mut d = [0.0; 9];
        d[..3].fill(self.q_direction);
        d[3..6].fill(self.q_rate);
        d[6..].copy_from_slice(&self.q_disturbance);
        Matrix9::from_diagonal(&Vector9::from(d))
    }
}

/// Where its inputs are among the readings.
#[derive(Debug, Clone, Copy)]
pub struct Inputs {
    pub load_position: usize,
    pub uav_position: usize,
    pub attitude: usize,
    pub uav_velocity: usize,
}

pub struct KalmanBucy {
    model: Model,
    inputs: Inputs,
    q_intensity: Matrix9,
    r: f64,
    x: Vector9,
    p: Matrix9,
    /// Time of the last prediction and of the last sample assimilated.
    last_t: Option<f64>,
    last_sample: Option<f64>,
    /// The measured q and r₃ the last tick held: the model over the tick that follows.
    held_direction: Vector3<f64>,
    held_r3: Vector3<f64>,
}

fn vector(reading: &SensorReading) -> Vector3<f64> {
    Vector3::from_column_slice(&reading.value[..3])
}

impl KalmanBucy {
    pub fn new(section: &EstimatorSection, model: Model, inputs: Inputs) -> Self {
        let mut x = Vector9::zeros();
        x.fixed_rows_mut::<3>(0).copy_from(&Vector3::from(section.initial_direction));
        let [p_q, p_w, p_b] = section.p0;
        let mut p0 = [p_q; 9];
        p0[3..6].fill(p_w);
        p0[6..].fill(p_b);
        Self {
            model,
            inputs,
            q_intensity: section.q_intensity(),
            r: section.r,
            x,
            p: Matrix9::from_diagonal(&Vector9::from(p0)),
            last_t: None,
            last_sample: None,
            held_direction: Vector3::new(0.0, 0.0, -1.0),
            held_r3: Vector3::z(),
        }
    }

    /// A(q) of (10).
    fn a(q: &Vector3<f64>) -> Matrix9 {
        let mut a = Matrix9::zeros();
        a.fixed_view_mut::<3, 3>(0, 3).copy_from(&-skew(q));
        a.fixed_view_mut::<3, 3>(3, 6).copy_from(&-skew(q));
        a
    }

    /// x and P over h with q and u held.
    fn predict(&mut self, h: f64, thrust: f64) {
        let q = self.held_direction;
        let u = -self.held_r3 * (thrust / self.model.uav_mass_times_rod());
        let a = Self::a(&q);
        let a2 = a * a;
        let phi = Matrix9::identity() + a * h + a2 * (h * h / 2.0);
        let s = skew(&q);
        let mut gamma_u = Vector9::zeros();
        gamma_u.fixed_rows_mut::<3>(0).copy_from(&(s * s * u * (h * h / 2.0)));
        gamma_u.fixed_rows_mut::<3>(3).copy_from(&(-s * u * h));
        self.x = phi * self.x + gamma_u;

        let powers = [Matrix9::identity(), a, a2];
        let factorial = [1.0, 1.0, 2.0];
        let mut q_d = Matrix9::zeros();
        for (i, ai) in powers.iter().enumerate() {
            for (j, aj) in powers.iter().enumerate() {
                let n = (i + j + 1) as f64;
                q_d += ai
                    * self.q_intensity
                    * aj.transpose()
                    * (h.powi(i as i32 + j as i32 + 1) / (n * factorial[i] * factorial[j]));
            }
        }
        self.p = phi * self.p * phi.transpose() + q_d;
        self.p = (self.p + self.p.transpose()) * 0.5;
    }

    /// Assimilates y = [q; 0] with R_d = R/h_m.
    fn correct(&mut self, q: &Vector3<f64>, h_m: f64) {
        let mut c = Matrix4x9::zeros();
        c.fixed_view_mut::<3, 3>(0, 0).copy_from(&Matrix3::identity());
        c.fixed_view_mut::<1, 3>(3, 3).copy_from(&q.transpose());
        let r_d = SMatrix::<f64, 4, 4>::identity() * (self.r / h_m);
        let mut y = SVector::<f64, 4>::zeros();
        y.fixed_rows_mut::<3>(0).copy_from(q);
        let innovation = y - c * self.x;
        let s = c * self.p * c.transpose() + r_d;
        let Some(s_inv) = s.try_inverse() else { return };
        let k = self.p * c.transpose() * s_inv;
        self.x += k * innovation;
        let i_kc = Matrix9::identity() - k * c;
        self.p = i_kc * self.p * i_kc.transpose() + k * r_d * k.transpose();
        self.p = (self.p + self.p.transpose()) * 0.5;
    }
}

impl Estimator for KalmanBucy {
    fn update(&mut self, t: f64, readings: &[SensorReading], u_applied: &[f64], estimate: &mut [f64]) {
        let i = self.inputs;
        let (load, uav) = (&readings[i.load_position], &readings[i.uav_position]);
        let (p_load, p_uav) = (vector(load), vector(uav));
        let q = (p_load - p_uav).try_normalize(1e-9).unwrap_or(self.held_direction);
        let r = rotation(&readings[i.attitude].value[..9]);
        let v_uav = vector(&readings[i.uav_velocity]);

        if let Some(last) = self.last_t
            && t > last
        {
            self.predict(t - last, u_applied[0]);
        }
        self.last_t = Some(t);
        let sampled = load.valid != 0 && uav.valid != 0;
        if sampled && load.sample_time > self.last_sample.unwrap_or(f64::NEG_INFINITY) {
            // The first sample is weighted as if averaged over one tick-length interval of 1 ms.
            let h_m = self.last_sample.map_or(1e-3, |s| load.sample_time - s).max(1e-6);
            self.correct(&q, h_m);
            self.last_sample = Some(load.sample_time);
        }
        self.held_direction = q;
        self.held_r3 = r.column(2).into_owned();

        let l = self.model.rod_length_m;
        let w_hat = self.x.fixed_rows::<3>(3).into_owned();
        let v_load_hat = v_uav - q.cross(&w_hat) * l;
        estimate[layout::DIRECTION_HAT].copy_from_slice(self.x.fixed_rows::<3>(0).as_slice());
        estimate[layout::RATE_HAT].copy_from_slice(w_hat.as_slice());
        let b_hat = self.x.fixed_rows::<3>(6) * self.model.uav_mass_times_rod();
        estimate[layout::DISTURBANCE_HAT].copy_from_slice(b_hat.as_slice());
        estimate[layout::LOAD_VELOCITY_HAT].copy_from_slice(v_load_hat.as_slice());
        estimate[layout::LOAD_POSITION].copy_from_slice(p_load.as_slice());
        estimate[layout::DIRECTION].copy_from_slice(q.as_slice());
        estimate[layout::ROTATION].copy_from_slice(&readings[i.attitude].value[..9]);
        estimate[layout::UAV_VELOCITY].copy_from_slice(v_uav.as_slice());
    }

    /// b̂ is the slow state worth keeping across a restart.
    fn freeze(&self) -> Option<Vec<u8>> {
        Some(freeze_value(&<[f64; 3]>::try_from(self.x.fixed_rows::<3>(6).as_slice()).expect("3 rows")))
    }

    fn thaw(&mut self, frozen: &[u8]) -> anyhow::Result<()> {
        let bias: [f64; 3] = thaw_value(frozen)?;
        self.x.fixed_rows_mut::<3>(6).copy_from_slice(&bias);
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Q_d by the closed form equals the integral of Φ(s)QΦ(s)ᵀ by three-point Gauss–Legendre
    /// quadrature (exact up to degree 5; the integrand is of degree 4).
    #[test]
    fn the_discrete_process_noise_is_the_integral() {
        let q = Vector3::new(0.1, -0.2, -0.97).normalize();
        let a = KalmanBucy::a(&q);
        assert_eq!(a * a * a, Matrix9::zeros(), "A is nilpotent of index 3");
        let section = EstimatorSection {
            q_direction: 1e-7,
            q_rate: 1e-4,
            q_disturbance: [10.0, 10.0, 0.1],
            r: 3e-5,
            p0: [0.0; 3],
            initial_direction: [0.0, 0.0, 1.0],
        };
        let model = super::super::params::tests::simulation();
        let inputs = Inputs { load_position: 0, uav_position: 1, attitude: 2, uav_velocity: 3 };
        let mut f = KalmanBucy::new(&section, model, inputs);
        f.held_direction = q;
        let h = 0.01;
        f.predict(h, 0.0);
        let qc = section.q_intensity();
        let phi = |s: f64| Matrix9::identity() + a * s + a * a * (s * s / 2.0);
        let g = |s: f64| phi(s) * qc * phi(s).transpose();
        let offset = h / 2.0 * (3.0f64 / 5.0).sqrt();
        let gauss = (g(h / 2.0 - offset) * 5.0 + g(h / 2.0) * 8.0 + g(h / 2.0 + offset) * 5.0) * (h / 18.0);
        let error = (f.p - gauss).abs().max();
        assert!(error < 1e-12 * gauss.abs().max(), "{error}");
    }
}
