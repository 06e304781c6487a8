//! The parameter estimator (paper 001): the 16-state Kalman-Bucy filter of §5.1 for
//! ζ = [v, ω, ξ] and the cascaded scalar filters of §5.2 for m = 1/ξ₁ and jᵢ = 1/ξ₄ᵢ.
//!
//! The continuous filter is stiff (its gain reaches 10⁴ s⁻¹), so it is not integrated: the
//! estimator runs its exact discrete-time equivalent at the rate its data come.
//! - A_ζ = [[0, A_ξ(t)], [0, 0]] squares to zero for any two instants, so the transition matrix
//!   over a step is exactly Φ = I + ∫A_ζ; ∫A_ξ is taken by the trapezoid over the step's two
//!   ends (T and τ are held, R and ω are measured at both). The known input integrates the
//!   same way, with the corrected sign of (47): b_ξ = −S(ω)v + g Rᵀe₃.
//! - The process-noise intensity Q_c becomes Q_d = ∫Φ(t,s) Q_c Φ(t,s)ᵀ ds, exact for A_ξ held
//!   over the step: [[Q_x h + A Q_ξ Aᵀ h³/3, A Q_ξ h²/2], [Q_ξ Aᵀ h²/2, Q_ξ h]].
//! - The measurement-noise intensity R_c becomes R_d = R_c/h_m, h_m the time since the last
//!   measurement (a continuous measurement averaged over h_m has that covariance).
//!
//! The scalar filters have closed-form solutions over a step with ξ̂ held, so they are exact
//! at any step: ṗ = q − (ξ²/r) p² and m̂̇ = (ξ²p/r)(1/ξ − m̂).
//!
//! Without velocity and rate sensors (the lab), v and ω come from the motion-capture pose: v
//! by a backward difference of p turned into the body frame, ω from the rotation between two
//! attitudes, ω = log(R_prevᵀ R)^∨ / Δt.

use nalgebra::{Matrix3, SMatrix, SVector, Vector3};
use serde::Deserialize;

use super::layout;
use super::params::Model;
use crate::contract::msg::SensorReading;
use crate::model::scenario::{Estimator, freeze_value, thaw_value};
use crate::model::so3::{log_so3, orthonormalise, rotation};

type Vector16 = SVector<f64, 16>;
type Matrix16 = SMatrix<f64, 16, 16>;
type Matrix6x10 = SMatrix<f64, 6, 10>;

/// Five numbers, one per block of ζ: v, ω, (ξ₁, ξ₂), ξ₃, ξ₄.
pub type Blocks = [f64; 5];

fn expand(blocks: &Blocks) -> Vector16 {
    const SIZES: [usize; 5] = [3, 3, 4, 3, 3];
    let mut out = Vector16::zeros();
    let mut i = 0;
    for (value, size) in blocks.iter().zip(SIZES) {
        for _ in 0..size {
            out[i] = *value;
            i += 1;
        }
    }
    out
}

#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct EstimatorSection {
    /// R_ζ = r · I₆: measurement-noise intensity of v and ω.
    pub r: f64,
    /// Q_ζ per block (v, ω, ξ₁ξ₂, ξ₃, ξ₄): process-noise intensities.
    pub q: Blocks,
    /// Multipliers of R_ζ and Q_ζ (the (R, Q) pairs of Table 2 are multiples of R̄ and Q̄).
    pub r_scale: f64,
    pub q_scale: f64,
    /// P_ζ(0) per block.
    pub p0: Blocks,
    /// ξ̂(0) as multiples of the truth, per parameter block (ξ₁, ξ₂, ξ₃, ξ₄) [paper §7].
    pub initial_xi_factor: [f64; 4],
    /// m̂(0) and ĵ(0) as a multiple of the truth.
    pub initial_mass_inertia_factor: f64,
    /// The cascaded filters' tuning: (r, q) for m and for each j, p(0) = q.
    pub mass_filter: [f64; 2],
    pub inertia_filter: [f64; 2],
}

/// Which readings the estimator uses.
#[derive(Debug, Clone, Copy)]
pub struct Inputs {
    pub pose: usize,
    /// Velocity and angular-rate sensors; None: both come from differencing the pose.
    pub rates: Option<(usize, usize)>,
}

/// A scalar Kalman-Bucy filter for an inverse: x̂ → 1/ξ (§5.2).
#[derive(Debug, Clone, Copy)]
struct InverseFilter {
    estimate: f64,
    p: f64,
    r: f64,
    q: f64,
}

impl InverseFilter {
    /// Advances by h with ξ̂ held: the exact solutions of the scalar Riccati equation and of
    /// the linear estimate equation.
    fn step(&mut self, xi: f64, h: f64) {
        let a = xi * xi / self.r;
        if a * self.q <= 0.0 {
            self.p += self.q * h;
            return;
        }
        let lambda = (self.q * a).sqrt();
        let s = (self.q / a).sqrt();
        let tanh = (lambda * h).tanh();
        // ∫ a p ds over the step = ln y(h), y = cosh λh + (p₀/s) sinh λh.
        let log_y = (lambda * h).cosh().ln() + (1.0 + self.p / s * tanh).ln();
        self.p = s * (self.p + s * tanh) / (s + self.p * tanh);
        self.estimate = 1.0 / xi + (self.estimate - 1.0 / xi) * (-log_y).exp();
    }
}

/// The measured quantities at one instant, for A_ξ and b_ξ.
#[derive(Debug, Clone, Copy)]
struct Sample {
    r: Matrix3<f64>,
    v: Vector3<f64>,
    w: Vector3<f64>,
}

/// A_ξ(t) of (46) for the applied thrust and torque.
fn a_xi(s: &Sample, thrust: f64, torque: &Vector3<f64>) -> Matrix6x10 {
    let mut a = Matrix6x10::zeros();
    a[(2, 0)] = -thrust;
    a.fixed_view_mut::<3, 3>(0, 1).copy_from(&s.r.transpose());
    let w = s.w;
    for i in 0..3 {
        // Ω(ω) = diag(ω₂ω₃, ω₁ω₃, ω₁ω₂), U(τ) = diag(τ).
        a[(3 + i, 4 + i)] = w[(i + 1) % 3] * w[(i + 2) % 3];
        a[(3 + i, 7 + i)] = torque[i];
    }
    a
}

/// b_ξ(t) with the sign of (47) corrected: −S(ω)v + g Rᵀe₃ (the printed +S(ω)v biases ξ̂).
fn b_xi(s: &Sample, g: f64) -> SVector<f64, 6> {
    let dv = -s.w.cross(&s.v) + g * s.r.transpose() * Vector3::z();
    SVector::<f64, 6>::from_fn(|i, _| if i < 3 { dv[i] } else { 0.0 })
}

pub struct ParameterEstimator {
    inputs: Inputs,
    g: f64,
    q_c: Vector16,
    r_c: f64,
    zeta: Vector16,
    p: Matrix16,
    mass: InverseFilter,
    inertia: [InverseFilter; 3],
    /// Simulation time and measured quantities of the last step.
    last: Option<(f64, Sample)>,
    /// When the last measurement update was (with velocity and rate sensors).
    last_corrected: Option<f64>,
    /// The last motion-capture frame: sample time, p, R (without them).
    last_pose: Option<(f64, Vector3<f64>, Matrix3<f64>)>,
    xi2_rate: Vector3<f64>,
    snr: f64,
}

impl ParameterEstimator {
    pub fn new(section: &EstimatorSection, model: &Model, inputs: Inputs) -> Self {
        let truth = model.xi(model.mass_kg);
        let f = section.initial_xi_factor;
        let factor = [f[0], f[1], f[1], f[1], f[2], f[2], f[2], f[3], f[3], f[3]];
        let mut zeta = Vector16::zeros();
        for i in 0..10 {
            zeta[6 + i] = truth[i] * factor[i];
        }
        let scalar = |estimate: f64, [r, q]: [f64; 2]| InverseFilter { estimate, p: q, r, q };
        let k = section.initial_mass_inertia_factor;
        Self {
            inputs,
            g: model.g,
            q_c: expand(&section.q) * section.q_scale,
            r_c: section.r * section.r_scale,
            zeta,
            p: Matrix16::from_diagonal(&expand(&section.p0)),
            mass: scalar(model.mass_kg * k, section.mass_filter),
            inertia: model.inertia_kg_m2.map(|j| scalar(j * k, section.inertia_filter)),
            last: None,
            last_corrected: None,
            last_pose: None,
            xi2_rate: Vector3::zeros(),
            snr: 0.0,
        }
    }

    /// The continuous-time gain P Cᵀ R_c⁻¹ of (60) has the largest singular value of the
    /// filter's covariance columns over R_c.
    fn snr(&self) -> f64 {
        let columns = self.p.fixed_columns::<6>(0) / self.r_c;
        (columns.transpose() * columns).symmetric_eigenvalues().max().sqrt()
    }

    /// Propagates ζ̂ and P from the last step to `now` with the thrust and torque held.
    fn predict(&mut self, from: &Sample, to: &Sample, h: f64, thrust: f64, torque: &Vector3<f64>) {
        let a = (a_xi(from, thrust, torque) + a_xi(to, thrust, torque)) * 0.5;
        let b = (b_xi(from, self.g) + b_xi(to, self.g)) * 0.5;
        let xi = self.zeta.fixed_rows::<10>(6).into_owned();
        let dx = (a * xi + b) * h;
        for i in 0..6 {
            self.zeta[i] += dx[i];
        }
        let mut phi = Matrix16::identity();
        phi.fixed_view_mut::<6, 10>(0, 6).copy_from(&(a * h));
        let q_x = SMatrix::<f64, 6, 6>::from_diagonal(&self.q_c.fixed_rows::<6>(0).into_owned());
        let q_xi = SMatrix::<f64, 10, 10>::from_diagonal(&self.q_c.fixed_rows::<10>(6).into_owned());
        let mut q_d = Matrix16::zeros();
        q_d.fixed_view_mut::<6, 6>(0, 0).copy_from(&(q_x * h + a * q_xi * a.transpose() * (h * h * h / 3.0)));
        let cross = a * q_xi * (h * h / 2.0);
        q_d.fixed_view_mut::<6, 10>(0, 6).copy_from(&cross);
        q_d.fixed_view_mut::<10, 6>(6, 0).copy_from(&cross.transpose());
        q_d.fixed_view_mut::<10, 10>(6, 6).copy_from(&(q_xi * h));
        self.p = phi * self.p * phi.transpose() + q_d;
    }

    /// The Kalman update with y = [v, ω] measured over `interval` seconds.
    fn correct(&mut self, y: &SVector<f64, 6>, interval: f64) {
        let r_d = SMatrix::<f64, 6, 6>::identity() * (self.r_c / interval);
        let s = self.p.fixed_view::<6, 6>(0, 0) + r_d;
        let Some(s_inverse) = s.try_inverse() else { return };
        let gain = self.p.fixed_columns::<6>(0) * s_inverse;
        let innovation = y - self.zeta.fixed_rows::<6>(0);
        self.zeta += gain * innovation;
        self.p -= gain * s * gain.transpose();
        self.p = (self.p + self.p.transpose()) * 0.5;
    }

    /// v and ω now, whether they are new, and the time they were measured over: from their
    /// sensors, or by differencing the pose against the last motion-capture frame. None until
    /// there is something to measure.
    fn measure(&mut self, readings: &[SensorReading], t: f64) -> Option<(Sample, bool, f64)> {
        let pose = &readings[self.inputs.pose];
        if pose.valid == 0 {
            return None;
        }
        let r = orthonormalise(&rotation(&pose.value[3..12]));
        if let Some((velocity, rate)) = self.inputs.rates {
            let (v, w) = (&readings[velocity], &readings[rate]);
            if v.valid == 0 || w.valid == 0 {
                return None;
            }
            let sample = Sample {
                r,
                v: Vector3::from_column_slice(&v.value[..3]),
                w: Vector3::from_column_slice(&w.value[..3]),
            };
            let fresh = v.fresh != 0 || w.fresh != 0;
            let interval = t - self.last_corrected.unwrap_or(t);
            if fresh {
                self.last_corrected = Some(t);
            }
            return Some((sample, fresh, interval));
        }
        let p = Vector3::from_column_slice(&pose.value[..3]);
        if pose.fresh == 0 {
            // Held between motion-capture frames.
            return self.last.map(|(_, s)| (s, false, 0.0));
        }
        let previous = self.last_pose.replace((pose.sample_time, p, r));
        let (since, p_prev, r_prev) = previous?;
        let interval = pose.sample_time - since;
        if interval <= 0.0 {
            return self.last.map(|(_, s)| (s, false, 0.0));
        }
        let v = r.transpose() * (p - p_prev) / interval;
        let w = log_so3(&(r_prev.transpose() * r)) / interval;
        Some((Sample { r, v, w }, true, interval))
    }
}

impl Estimator for ParameterEstimator {
    fn update(&mut self, t: f64, readings: &[SensorReading], u_applied: &[f64], estimate: &mut [f64]) {
        estimate[layout::POSE].copy_from_slice(&readings[self.inputs.pose].value[..12]);
        let Some((sample, fresh, interval)) = self.measure(readings, t) else {
            self.write(estimate, None);
            return;
        };
        let y = SVector::<f64, 6>::from_fn(|i, _| if i < 3 { sample.v[i] } else { sample.w[i - 3] });
        match self.last {
            None => {
                // v̂(0) = v(0), ω̂(0) = ω(0) [paper §7].
                self.zeta.fixed_rows_mut::<6>(0).copy_from(&y);
            }
            Some((t_last, from)) => {
                let h = t - t_last;
                let xi2_before = self.zeta.fixed_rows::<3>(7).into_owned();
                if h > 0.0 {
                    let torque = Vector3::new(u_applied[1], u_applied[2], u_applied[3]);
                    self.predict(&from, &sample, h, u_applied[0], &torque);
                    self.mass.step(self.zeta[6], h);
                    for (i, filter) in self.inertia.iter_mut().enumerate() {
                        filter.step(self.zeta[13 + i], h);
                    }
                }
                // ξ̂ has no drift term (the ξ rows of A_ζ are zero): its rate is the gain times
                // the innovation, which the controller's ω̇_d needs. A correction takes in what
                // was measured over `interval`, so that is the time the change is spread over;
                // between measurements the rate is held.
                if fresh && interval > 0.0 {
                    self.correct(&y, interval);
                    self.xi2_rate = (self.zeta.fixed_rows::<3>(7) - xi2_before) / interval;
                }
            }
        }
        self.snr = self.snr();
        self.last = Some((t, sample));
        self.write(estimate, Some(&sample));
    }

    /// The parameter estimates are what took the filter seconds of excitation to learn: they
    /// outlive a restart, with their variances (ξ̂ and the diagonal of its covariance block, m̂,
    /// ĵ and their filters' p). The fast states start again from the measurements.
    fn freeze(&self) -> Option<Vec<u8>> {
        self.last?;
        let xi: [f64; 10] = std::array::from_fn(|i| self.zeta[6 + i]);
        let variances: [f64; 10] = std::array::from_fn(|i| self.p[(6 + i, 6 + i)]);
        let filters: Vec<(f64, f64)> =
            std::iter::once(&self.mass).chain(&self.inertia).map(|f| (f.estimate, f.p)).collect();
        Some(freeze_value(&(xi, variances, filters)))
    }

    fn thaw(&mut self, frozen: &[u8]) -> anyhow::Result<()> {
        let (xi, variances, filters): ([f64; 10], [f64; 10], Vec<(f64, f64)>) = thaw_value(frozen)?;
        for i in 0..10 {
            self.zeta[6 + i] = xi[i];
            self.p[(6 + i, 6 + i)] = variances[i];
        }
        for (filter, (estimate, p)) in std::iter::once(&mut self.mass).chain(&mut self.inertia).zip(filters) {
            (filter.estimate, filter.p) = (estimate, p);
        }
        Ok(())
    }
}

impl ParameterEstimator {
    fn write(&self, estimate: &mut [f64], sample: Option<&Sample>) {
        if let Some(s) = sample {
            estimate[layout::VELOCITY].copy_from_slice(s.v.as_slice());
            estimate[layout::RATE].copy_from_slice(s.w.as_slice());
        }
        estimate[layout::XI].copy_from_slice(self.zeta.fixed_rows::<10>(6).as_slice());
        estimate[layout::XI2_RATE].copy_from_slice(self.xi2_rate.as_slice());
        estimate[layout::MASS] = self.mass.estimate;
        for i in 0..3 {
            estimate[layout::INERTIA.start + i] = self.inertia[i].estimate;
        }
        estimate[layout::SNR] = self.snr;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The closed-form step against a fine RK4 integration of ṗ = q − (ξ²/r)p² and
    /// m̂̇ = (ξp/r)(1 − ξm̂), over one long step with p(0) far from its steady state.
    #[test]
    fn inverse_filter_step_is_the_exact_solution() {
        let (xi, r, q) = (5.0, 1.0, 1.0);
        let mut exact = InverseFilter { estimate: 0.1, p: 1.0, r, q };
        exact.step(xi, 0.3);
        let f = |s: &nalgebra::Vector2<f64>| {
            nalgebra::Vector2::new(xi * s[1] / r * (1.0 - xi * s[0]), q - xi * xi / r * s[1] * s[1])
        };
        let fine = crate::model::integrate::rk4(&f, &nalgebra::Vector2::new(0.1, 1.0), 0.3, 30_000);
        assert!((exact.estimate - fine[0]).abs() < 1e-12 && (exact.p - fine[1]).abs() < 1e-12, "{exact:?} vs {fine}");
        // It settles at m = 1/ξ with p = √(qr)/ξ.
        for _ in 0..100 {
            exact.step(xi, 0.1);
        }
        assert!((exact.estimate - 0.2).abs() < 1e-12 && (exact.p - 0.2).abs() < 1e-12);
    }
}
