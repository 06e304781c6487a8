//! The controllers' design models (assumptions A1–A4): the inner (z, φ, θ, ψ) model with the
//! thrusts' dynamic extension, differentiated in Taylor mode to give b and Δ of (34)–(36), and
//! the outer (x, y, γ₁, γ₂) model that gives A and b of (48).
//!
//! Inner model, nominal parameters with A1 applied:
//! - z̈ = e₃ᵀR_B^F F^B(α, f)/m − g (A1, A2: no coupling to the load or the attitude);
//! - the attitude as one rigid body, J ω̇ + ω × Jω = τ^B + τ_g, ω = W_η η̇, with the constant
//!   J = Σ Jᵢ at α = 0 and at the measured γ, held during the expansion (so τ_α first appears in
//!   the fourth derivative; this equals the Euler–Lagrange form with
//!   M_ηη = W_ηᵀ J W_η, see the tests); τ^B = τ_R f_R + τ_L f_L of (22) verbatim; τ_g the
//!   gravity torque of m₄d₄(γ) (A1: Σ mᵢdᵢ = m₄d₄);
//! - α̈ = τ_α / I_yy (A3: m₂₃ = m₂₄ = 0); no drag on z, η, α (only μ_γ is given);
//! - f_R, f_L double integrators of the new inputs f̈_R, f̈_L.
//!
//! One deviation, inferred: (22)'s lever d_z is the plant's (0.123 m), not A1's 0. A1 is about
//! the mass moments Σ mᵢdᵢ (that H = −S(m₄d₄)); with d_z = 0 in (22) the common tilt makes no
//! pitch torque at α = 0, θ⁽⁴⁾ and z⁽⁴⁾ both depend on f̈_R + f̈_L only, and Δ is singular (a
//! test shows it). The inertia J and the gravity torque keep A1.

use nalgebra::{Matrix2, Matrix4, Vector2, Vector4};

use super::dynamics::{body_rate, l_gamma, load_offset, load_velocity, rotation};
use super::params::Params;
use crate::model::autodiff::{
    Dual, Mat3, Scalar, Vec3, add, cross, identity, mat_add, mat_mul, mat_vec, rot_x, rot_y, skew, transpose,
};
use crate::model::taylor::Taylor;

/// Series order: coefficients of t⁰ … t⁴ (the outputs' relative degree is 4).
pub type Series = Taylor<5>;

/// The inner model's extended state x̄ (16).
pub mod ext {
    pub const Z: usize = 0;
    pub const PHI: usize = 1;
    pub const ALPHA_R: usize = 4;
    pub const ALPHA_L: usize = 5;
    /// ż, φ̇, θ̇, ψ̇, α̇_R, α̇_L.
    pub const RATES: usize = 6;
    pub const F_R: usize = 12;
    pub const F_R_DOT: usize = 13;
    pub const F_L: usize = 14;
    pub const F_L_DOT: usize = 15;
    pub const LEN: usize = 16;
}

/// Outputs z, φ, θ, ψ.
pub const OUTPUTS: usize = 4;

pub fn inverse3(m: &Mat3<f64>) -> Mat3<f64> {
    let cof = |r0: usize, r1: usize, c0: usize, c1: usize| m[r0][c0] * m[r1][c1] - m[r0][c1] * m[r1][c0];
    let adj = [
        [cof(1, 2, 1, 2), -cof(0, 2, 1, 2), cof(0, 1, 1, 2)],
        [-cof(1, 2, 0, 2), cof(0, 2, 0, 2), -cof(0, 1, 0, 2)],
        [cof(1, 2, 0, 1), -cof(0, 2, 0, 1), cof(0, 1, 0, 1)],
    ];
    let det = m[0][0] * adj[0][0] + m[0][1] * adj[1][0] + m[0][2] * adj[2][0];
    adj.map(|row| row.map(|v| v / det))
}

/// Jᵢ = R Iᵢ Rᵀ + mᵢ S(dᵢ)ᵀS(dᵢ) (Steiner, section 2.2).
fn body_inertia(rotation: &Mat3<f64>, inertia: &Mat3<f64>, mass: f64, offset: [f64; 3]) -> Mat3<f64> {
    let s = skew(offset);
    let steiner = mat_mul(&transpose(&s), &s).map(|row| row.map(|v| v * mass));
    mat_add(&mat_mul(&mat_mul(rotation, inertia), &transpose(rotation)), &steiner)
}

/// The inner design model at one held γ.
#[derive(Debug, Clone)]
pub struct InnerModel {
    mass: f64,
    g: f64,
    beta: f64,
    /// d_y and d_z of (22); d_z is the plant's (see the module doc).
    arm_y: f64,
    arm_z: f64,
    /// kτ/b.
    drag_ratio: f64,
    pub inertia: Mat3<f64>,
    inertia_inv: Mat3<f64>,
    /// I₂yy, I₃yy.
    tilt_inertia: [f64; 2],
    /// m₄d₄^B at the held γ.
    load_moment: Vec3<f64>,
}

impl InnerModel {
    /// `nominal`: the plant's nominal parameters; A1 is applied here.
    pub fn new(nominal: &Params, gamma: [f64; 2]) -> Self {
        let p = nominal.control_model();
        let d4 = load_offset(p.rod_length, gamma);
        let r_e4 = mat_mul(&rot_y(gamma[1]), &rot_x(gamma[0]));
        let bodies = [
            body_inertia(&identity(), &p.inertia[0], p.mass[0], p.offset[0]),
            body_inertia(&rot_x(-p.beta), &p.inertia[1], p.mass[1], p.offset[1]),
            body_inertia(&rot_x(p.beta), &p.inertia[2], p.mass[2], p.offset[2]),
            body_inertia(&r_e4, &p.inertia[3], p.mass[3], d4),
        ];
        let inertia = bodies.iter().skip(1).fold(bodies[0], |acc, j| mat_add(&acc, j));
        InnerModel {
            mass: p.total_mass(),
            g: p.g,
            beta: p.beta,
            arm_y: p.offset[2][1],
            arm_z: nominal.offset[1][2],
            drag_ratio: p.drag_torque_per_thrust,
            inertia,
            inertia_inv: inverse3(&inertia),
            tilt_inertia: [p.inertia[1][1][1], p.inertia[2][1][1]],
            load_moment: d4.map(|v| v * p.mass[3]),
        }
    }

    /// With d_z = 0 in (22) as A1 literally reads (for the test that shows Δ singular then).
    #[cfg(test)]
    fn without_lever_z(mut self) -> Self {
        self.arm_z = 0.0;
        self
    }

    /// F^B = r_R f_R + r_L f_L of (19)–(21).
    pub fn body_force<S: Scalar>(&self, alpha: [S; 2], thrust: [S; 2]) -> Vec3<S> {
        let (sr, cr, sl, cl) = (alpha[0].sin(), alpha[0].cos(), alpha[1].sin(), alpha[1].cos());
        let (sb, cb) = self.beta.sin_cos();
        [
            sr * thrust[0] + sl * thrust[1],
            (cr * thrust[0] - cl * thrust[1]).scale(sb),
            (cr * thrust[0] + cl * thrust[1]).scale(cb),
        ]
    }

    /// τ^B = τ_R f_R + τ_L f_L of (22), verbatim.
    pub fn body_torque<S: Scalar>(&self, alpha: [S; 2], thrust: [S; 2]) -> Vec3<S> {
        let (sr, cr, sl, cl) = (alpha[0].sin(), alpha[0].cos(), alpha[1].sin(), alpha[1].cos());
        let (sb, cb) = self.beta.sin_cos();
        let (dy, dz, k) = (self.arm_y, self.arm_z, self.drag_ratio);
        let tau_r =
            [-cr.scale(cb * dy) - sr.scale(k), sr.scale(dz) + cr.scale(k * sb), sr.scale(dy) + cr.scale(k * cb)];
        let tau_l =
            [cl.scale(cb * dy) + sl.scale(k), sl.scale(dz) + cl.scale(k * sb), -sl.scale(dy) - cl.scale(k * cb)];
        [0, 1, 2].map(|i| tau_r[i] * thrust[0] + tau_l[i] * thrust[1])
    }

    /// The gravity torque on the body of the load's mass moment: (m₄d₄) × (R^T(−g e₃)).
    pub fn gravity_torque<S: Scalar>(&self, eta: [S; 3]) -> Vec3<S> {
        let (sp, cp, st, ct) = (eta[0].sin(), eta[0].cos(), eta[1].sin(), eta[1].cos());
        let up_in_body = [-st, ct * sp, ct * cp];
        cross(self.load_moment.map(S::c), up_in_body).map(|v| v.scale(-self.g))
    }

    /// η̈ of the rigid body for a body torque τ.
    pub fn attitude_acceleration<S: Scalar>(&self, eta: [S; 3], eta_dot: [S; 3], torque: Vec3<S>) -> Vec3<S> {
        let j = self.inertia.map(|row| row.map(S::c));
        let omega = body_rate(eta, eta_dot);
        let gyro = cross(omega, mat_vec(&j, omega));
        let net = [0, 1, 2].map(|i| torque[i] - gyro[i]);
        let omega_dot = mat_vec(&self.inertia_inv.map(|row| row.map(S::c)), net);
        // Ẇ_η η̇, by hand.
        let (sp, cp, st, ct) = (eta[0].sin(), eta[0].cos(), eta[1].sin(), eta[1].cos());
        let [pd, td, yd] = eta_dot;
        let w_dot_eta_dot = [
            -ct * td * yd,
            -sp * pd * td + (cp * ct * pd - sp * st * td) * yd,
            -cp * pd * td - (sp * ct * pd + cp * st * td) * yd,
        ];
        let a = [0, 1, 2].map(|i| omega_dot[i] - w_dot_eta_dot[i]);
        // W_η⁻¹.
        let tt = st / ct;
        [a[0] + sp * tt * a[1] + cp * tt * a[2], cp * a[1] - sp * a[2], (sp * a[1] + cp * a[2]) / ct]
    }

    /// x̄̇ for the new inputs Γ̄ = (f̈_R, f̈_L, τ_αR, τ_αL).
    pub fn derivative<S: Scalar>(&self, x: &[S; ext::LEN], input: &[S; 4]) -> [S; ext::LEN] {
        let eta = [x[1], x[2], x[3]];
        let eta_dot = [x[7], x[8], x[9]];
        let alpha = [x[ext::ALPHA_R], x[ext::ALPHA_L]];
        let thrust = [x[ext::F_R], x[ext::F_L]];
        let force = mat_vec(&rotation(eta), self.body_force(alpha, thrust));
        let z_acc = force[2].scale(1.0 / self.mass) - S::c(self.g);
        let torque = add(self.body_torque(alpha, thrust), self.gravity_torque(eta));
        let eta_acc = self.attitude_acceleration(eta, eta_dot, torque);
        let mut out = [S::zero(); ext::LEN];
        out[..6].copy_from_slice(&x[ext::RATES..ext::RATES + 6]);
        out[6] = z_acc;
        out[7..10].copy_from_slice(&eta_acc);
        out[10] = input[2].scale(1.0 / self.tilt_inertia[0]);
        out[11] = input[3].scale(1.0 / self.tilt_inertia[1]);
        out[ext::F_R] = x[ext::F_R_DOT];
        out[ext::F_R_DOT] = input[0];
        out[ext::F_L] = x[ext::F_L_DOT];
        out[ext::F_L_DOT] = input[1];
        out
    }

    /// The Taylor series of the extended state from x̄₀ with Γ̄ held: xₖ₊₁ = (x̄̇)ₖ/(k + 1), each
    /// coefficient of x̄̇ needing only the state's coefficients up to its own order.
    pub fn expand(&self, x0: &[f64; ext::LEN], input: [f64; 4]) -> [Series; ext::LEN] {
        let mut x = x0.map(Series::c);
        let u = input.map(Series::c);
        for k in 0..4 {
            let dx = self.derivative(&x, &u);
            for (xi, dxi) in x.iter_mut().zip(&dx) {
                xi.c[k + 1] = dxi.c[k] / (k + 1) as f64;
            }
        }
        x
    }

    /// The outputs' derivatives 0…3 (the model's h, L_f h, L_f² h, L_f³ h), b and Δ.
    pub fn linearise(&self, x0: &[f64; ext::LEN]) -> Linearisation {
        let free = self.expand(x0, [0.0; 4]);
        let mut derivatives = [[0.0; 4]; OUTPUTS];
        let mut b = [0.0; OUTPUTS];
        for i in 0..OUTPUTS {
            derivatives[i] = [0, 1, 2, 3].map(|n| free[i].derivative(n));
            b[i] = free[i].derivative(4);
        }
        let mut delta = [[0.0; 4]; OUTPUTS];
        for j in 0..4 {
            let mut unit = [0.0; 4];
            unit[j] = 1.0;
            let pushed = self.expand(x0, unit);
            for i in 0..OUTPUTS {
                delta[i][j] = pushed[i].derivative(4) - b[i];
            }
        }
        Linearisation { derivatives, b, delta }
    }
}

/// h⁽⁴⁾ = b + Δ Γ̄ at one state, and the lower derivatives.
#[derive(Debug, Clone, Copy)]
pub struct Linearisation {
    /// `derivatives[output][order]`, order 0…3.
    pub derivatives: [[f64; 4]; OUTPUTS],
    pub b: [f64; OUTPUTS],
    pub delta: [[f64; 4]; OUTPUTS],
}

impl Linearisation {
    /// Γ̄ = Δ⁻¹(v − b) of (36); None where Δ is singular.
    pub fn solve(&self, v: [f64; OUTPUTS]) -> Option<[f64; 4]> {
        let delta = Matrix4::from_fn(|i, j| self.delta[i][j]);
        let rhs = Vector4::from_fn(|i, _| v[i] - self.b[i]);
        delta.lu().solve(&rhs).map(|s| [s[0], s[1], s[2], s[3]])
    }
}

/// The outer design model (x, y, γ₁, γ₂) of (26), (47)–(48): M_q2 from (17) with the control
/// parameters (m·I₂, m₄(R_B^F L_γ) rows x, y, m₅₅), η a time-varying parameter.
#[derive(Debug, Clone)]
pub struct OuterModel {
    mass: f64,
    load_mass: f64,
    rod_length: f64,
    g: f64,
    load_inertia: Mat3<f64>,
    load_drag: f64,
}

/// What (45)–(48) need at one instant.
#[derive(Debug, Clone, Copy)]
pub struct OuterTerms {
    /// A = [I 0] M_q2⁻¹ [I; 0].
    pub a: Matrix2<f64>,
    /// b = −[I 0] M_q2⁻¹ n̄, n̄ = [0, 0, n_γ].
    pub b: Vector2<f64>,
    /// The x, y rows of the velocity terms (C_q2 q̇₂ of the design model).
    pub velocity_xy: [f64; 2],
}

impl OuterModel {
    pub fn new(nominal: &Params) -> Self {
        let p = nominal.control_model();
        OuterModel {
            mass: p.total_mass(),
            load_mass: p.mass[3],
            rod_length: p.rod_length,
            g: p.g,
            load_inertia: p.inertia[3],
            load_drag: p.load_drag,
        }
    }

    /// M_q2(η, γ).
    pub fn mass_matrix<S: Scalar>(&self, eta: [S; 3], gamma: [S; 2]) -> [[S; 4]; 4] {
        let l_gamma = l_gamma(self.rod_length, gamma);
        let r = rotation(eta);
        let (s1, c1) = (gamma[0].sin(), gamma[0].cos());
        let w_gamma = [[S::one(), S::zero()], [S::zero(), c1], [S::zero(), -s1]];
        let i4 = self.load_inertia.map(|row| row.map(S::c));
        let mut m = [[S::zero(); 4]; 4];
        m[0][0] = S::c(self.mass);
        m[1][1] = S::c(self.mass);
        for row in 0..2 {
            for col in 0..2 {
                let coupling = (0..3).fold(S::zero(), |acc, k| acc + r[row][k] * l_gamma[k][col]).scale(self.load_mass);
                m[row][2 + col] = coupling;
                m[2 + col][row] = coupling;
            }
        }
        for a in 0..2 {
            for b in 0..2 {
                let translational = (0..3).fold(S::zero(), |acc, k| acc + l_gamma[k][a] * l_gamma[k][b]);
                let iw = (0..3).map(|k| (0..3).fold(S::zero(), |acc, n| acc + i4[k][n] * w_gamma[n][b]));
                let rotational = iw.zip(0..3).fold(S::zero(), |acc, (v, k)| acc + w_gamma[k][a] * v);
                m[2 + a][2 + b] = translational.scale(self.load_mass) + rotational;
            }
        }
        m
    }

    /// A, b and the x, y velocity terms at q₂, q̇₂ (x, y velocities `xy_dot`) and η, η̇.
    pub fn terms(
        &self,
        eta: [f64; 3],
        eta_dot: [f64; 3],
        gamma: [f64; 2],
        gamma_dot: [f64; 2],
        xy_dot: [f64; 2],
    ) -> OuterTerms {
        let m = Matrix4::from_fn(|i, j| self.mass_matrix(eta, gamma)[i][j]);
        let q_dot = [xy_dot[0], xy_dot[1], gamma_dot[0], gamma_dot[1]];
        // ∂M/∂c for c = φ, θ, ψ, γ₁, γ₂, by forward mode.
        let rates = [eta_dot[0], eta_dot[1], eta_dot[2], gamma_dot[0], gamma_dot[1]];
        let mut m_dot = [[0.0; 4]; 4];
        let mut d_gamma = [[[0.0; 4]; 4]; 2];
        for c in 0..5 {
            let seed = |i: usize, v: f64| if i == c { Dual::var(v) } else { Dual::c(v) };
            let eta_d = [0, 1, 2].map(|i| seed(i, eta[i]));
            let gamma_d = [0, 1].map(|i| seed(3 + i, gamma[i]));
            let dm = self.mass_matrix(eta_d, gamma_d).map(|row| row.map(|v| v.d));
            for (row, drow) in m_dot.iter_mut().zip(&dm) {
                for (cell, d) in row.iter_mut().zip(drow) {
                    *cell += d * rates[c];
                }
            }
            if c >= 3 {
                d_gamma[c - 3] = dm;
            }
        }
        // Velocity terms: Ṁ q̇₂ − ½ ∂(q̇₂ᵀ M q̇₂)/∂q₂ (only γ appears in M among q₂).
        let mut velocity = [0.0; 4];
        for (i, v) in velocity.iter_mut().enumerate() {
            *v = (0..4).map(|j| m_dot[i][j] * q_dot[j]).sum();
        }
        for (k, dm) in d_gamma.iter().enumerate() {
            let quad: f64 =
                (0..4).flat_map(|i| (0..4).map(move |j| (i, j))).map(|(i, j)| q_dot[i] * dm[i][j] * q_dot[j]).sum();
            velocity[2 + k] -= 0.5 * quad;
        }
        // G_γ = m₄ g L_γᵀ Rᵀ k and the drag μ_γ γ̇.
        let l_gamma = l_gamma(self.rod_length, gamma);
        let r = rotation(eta);
        let up_in_body = [r[2][0], r[2][1], r[2][2]];
        let mut n_bar = Vector4::zeros();
        for k in 0..2 {
            let g_k = self.load_mass * self.g * (0..3).map(|i| l_gamma[i][k] * up_in_body[i]).sum::<f64>();
            n_bar[2 + k] = velocity[2 + k] + g_k + self.load_drag * gamma_dot[k];
        }
        let m_inv = m.try_inverse().expect("M_q2 is positive definite");
        let a = m_inv.fixed_view::<2, 2>(0, 0).into_owned();
        let b = -(m_inv * n_bar).fixed_rows::<2>(0).into_owned();
        OuterTerms { a, b, velocity_xy: [velocity[0], velocity[1]] }
    }

    /// ḋ^F = R_B^F (S(ω) d₄^B + L_γ γ̇): the load's velocity relative to the aircraft.
    pub fn swing_velocity(&self, eta: [f64; 3], eta_dot: [f64; 3], gamma: [f64; 2], gamma_dot: [f64; 2]) -> [f64; 3] {
        load_velocity(self.rod_length, eta, eta_dot, gamma, gamma_dot)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn state() -> [f64; ext::LEN] {
        let mut x = [0.0; ext::LEN];
        let values = [1.2, 0.1, -0.15, 0.4, 0.05, -0.08, 0.3, 0.5, -0.4, 0.2, 0.6, -0.3, 8.9, 1.5, 8.4, -2.0];
        x.copy_from_slice(&values);
        x
    }

    fn rk4(model: &InnerModel, x: &[f64; ext::LEN], u: &[f64; 4], h: f64) -> [f64; ext::LEN] {
        let f = |x: &[f64; ext::LEN]| model.derivative(x, u);
        let axpy = |a: &[f64; ext::LEN], k: &[f64; ext::LEN], s: f64| std::array::from_fn(|i| a[i] + s * k[i]);
        let k1 = f(x);
        let k2 = f(&axpy(x, &k1, h / 2.0));
        let k3 = f(&axpy(x, &k2, h / 2.0));
        let k4 = f(&axpy(x, &k3, h));
        std::array::from_fn(|i| x[i] + h / 6.0 * (k1[i] + 2.0 * k2[i] + 2.0 * k3[i] + k4[i]))
    }

    /// The series' coefficients are the trajectory's derivatives: against a fine RK4
    /// trajectory, the truncation error |x(t) − Σₖ xₖtᵏ| shrinks as t⁵ (halving t divides it by
    /// 32; a wrong 4th coefficient would leave t⁴, a ratio of 16).
    #[test]
    fn the_series_matches_an_integrated_trajectory() {
        let model = InnerModel::new(&Params::table1(), [0.3, -0.2]);
        let u = [3.0, -2.0, 0.02, -0.03];
        let x0 = state();
        let series = model.expand(&x0, u);
        let error = |t: f64| {
            let steps = 400;
            let mut x = x0;
            for _ in 0..steps {
                x = rk4(&model, &x, &u, t / steps as f64);
            }
            (0..OUTPUTS)
                .map(|i| (x[i] - series[i].c.iter().rev().fold(0.0, |acc, c| acc * t + c)).abs())
                .fold(0.0, f64::max)
        };
        for t in [4e-3, -4e-3] {
            let (coarse, fine) = (error(t), error(t / 2.0));
            let ratio = coarse / fine;
            assert!((27.0..40.0).contains(&ratio), "t {t}: {coarse:e} / {fine:e} = {ratio}");
        }
    }

    /// b and Δ: h⁽⁴⁾ for any Γ̄ equals b + ΔΓ̄, and τ_α does not reach the 3rd derivative.
    #[test]
    fn h4_is_affine_in_the_new_inputs_and_the_relative_degree_is_four() {
        let model = InnerModel::new(&Params::table1(), [0.3, -0.2]);
        let x0 = state();
        let lin = model.linearise(&x0);
        let u = [2.5, -1.0, 0.3, -0.7];
        let direct = model.expand(&x0, u);
        for (i, series) in direct.iter().take(OUTPUTS).enumerate() {
            let predicted = lin.b[i] + (0..4).map(|j| lin.delta[i][j] * u[j]).sum::<f64>();
            assert!((series.derivative(4) - predicted).abs() < 1e-9 * (1.0 + predicted.abs()));
            for n in 0..4 {
                assert_eq!(series.derivative(n), lin.derivatives[i][n], "output {i} order {n} moved with Γ̄");
            }
        }
        let solved = lin.solve([1.0, -2.0, 0.5, 3.0]).expect("Δ invertible");
        let back = model.expand(&x0, solved);
        for (i, want) in [1.0, -2.0, 0.5, 3.0].iter().enumerate() {
            assert!((back[i].derivative(4) - want).abs() < 1e-8, "{i}");
        }
    }

    /// At hover, with A1's d_z = 0 also in (22), Δ is singular; with the plant's d_z it is not.
    #[test]
    fn the_pitch_lever_makes_delta_invertible_at_hover() {
        let p = Params::table1();
        let mut x0 = [0.0; ext::LEN];
        x0[ext::F_R] = p.hover_thrust();
        x0[ext::F_L] = p.hover_thrust();
        let det = |m: &InnerModel| Matrix4::from_fn(|i, j| m.linearise(&x0).delta[i][j]).determinant();
        let with_lever = det(&InnerModel::new(&p, [0.0, 0.0]));
        let without = det(&InnerModel::new(&p, [0.0, 0.0]).without_lever_z());
        assert!(with_lever.abs() > 1e6, "{with_lever}");
        assert!(without.abs() < 1e-9 * with_lever.abs(), "{without} vs {with_lever}");
    }

    /// The rigid-body attitude equation equals Euler–Lagrange with M_ηη = W_ηᵀ J W_η and the
    /// potential of m₄d₄: W_ηᵀ(J ω̇ + ω×Jω − τ_g) = M η̈ + C η̇ + G_η, checked by evaluating the
    /// Lagrangian's terms with forward-mode derivatives at a random state.
    #[test]
    fn the_rigid_body_form_is_the_euler_lagrange_form() {
        let p = Params::table1();
        let model = InnerModel::new(&p, [0.25, -0.35]);
        let eta = [0.2, -0.3, 0.7];
        let eta_dot = [0.4, -0.6, 0.9];
        let torque = [0.05, -0.02, 0.01];
        let eta_acc = model.attitude_acceleration(eta, eta_dot, add(torque, model.gravity_torque(eta)));
        let w = |e: [Dual; 3]| {
            let (sp, cp, st, ct) = (e[0].sin(), e[0].cos(), e[1].sin(), e[1].cos());
            let (z, o) = (Dual::zero(), Dual::one());
            [[o, z, -st], [z, cp, sp * ct], [z, -sp, cp * ct]]
        };
        let m_of = |e: [Dual; 3]| {
            let wm = w(e);
            let j = model.inertia.map(|row| row.map(Dual::c));
            mat_mul(&transpose(&wm), &mat_mul(&j, &wm))
        };
        let potential = |e: [Dual; 3]| {
            // P = g kᵀ R (m₄d₄).
            let r = rotation(e);
            let s = model.load_moment.map(Dual::c);
            (r[2][0] * s[0] + r[2][1] * s[1] + r[2][2] * s[2]).scale(p.g)
        };
        let partial = |k: usize| [0, 1, 2].map(|i| if i == k { Dual::var(eta[i]) } else { Dual::c(eta[i]) });
        let m0 = m_of(eta.map(Dual::c)).map(|row| row.map(|v| v.v));
        let dm: Vec<[[f64; 3]; 3]> = (0..3).map(|k| m_of(partial(k)).map(|row| row.map(|v| v.d))).collect();
        for k in 0..3 {
            // (M η̈)ₖ + Σ (∂Mₖⱼ/∂ηᵢ − ½ ∂Mᵢⱼ/∂ηₖ) η̇ᵢ η̇ⱼ + ∂P/∂ηₖ = (W_ηᵀ τ)ₖ.
            let mut lhs: f64 = (0..3).map(|j| m0[k][j] * eta_acc[j]).sum();
            for i in 0..3 {
                for j in 0..3 {
                    lhs += (dm[i][k][j] - 0.5 * dm[k][i][j]) * eta_dot[i] * eta_dot[j];
                }
            }
            lhs += potential(partial(k)).d;
            let wm = w(eta.map(Dual::c)).map(|row| row.map(|v| v.v));
            let rhs: f64 = (0..3).map(|i| wm[i][k] * torque[i]).sum();
            assert!((lhs - rhs).abs() < 1e-12, "row {k}: {lhs} vs {rhs}");
        }
    }

    /// The outer model's A is [I 0]M⁻¹[I; 0]: at a hanging load (γ = 0, level) M couples x with
    /// γ₂ and y with γ₁, and A is the inverse of the Schur complement.
    #[test]
    fn outer_a_is_the_schur_complement_inverse() {
        let p = Params::table1();
        let model = OuterModel::new(&p);
        let terms = model.terms([0.0; 3], [0.0; 3], [0.0, 0.0], [0.0, 0.0], [0.0, 0.0]);
        let c = p.control_model();
        let (m, m4, l, i4) = (c.total_mass(), c.mass[3], c.rod_length, c.inertia[3][0][0]);
        // x row couples with γ₂ by −m₄l, m₅₅ = m₄l² + I₄.
        let schur = m - (m4 * l).powi(2) / (m4 * l * l + i4);
        assert!((terms.a[(0, 0)] - 1.0 / schur).abs() < 1e-12, "{}", terms.a[(0, 0)]);
        assert!((terms.a[(1, 1)] - 1.0 / schur).abs() < 1e-12);
        assert!(terms.b.norm() < 1e-15);
    }
}
