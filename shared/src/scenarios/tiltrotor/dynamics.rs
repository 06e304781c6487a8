//! The tilt-rotor's 10-DOF Euler–Lagrange model, (2)–(23) of paper 004: four bodies (main
//! body, two thruster groups, the load on a massless rod), q = (ξ, η, α, γ).
//!
//! The inertia matrix (17) and the potential (18) are written once, generic over
//! [`Scalar`]; their partial derivatives come from forward-mode automatic differentiation
//! ([`Dual`]), so C(q, q̇) is assembled from the Christoffel symbols of M and G = ∂P/∂q
//! without a hand-typed term. The input map B(q) implements the torque map (22) verbatim.

use nalgebra::{SMatrix, SVector};

use super::DOF;
use super::params::Params;
use crate::model::autodiff::{
    Dual, Mat3, Scalar, Vec3, add, cross, mat_add, mat_mul, mat_vec, mat3, rot_x, rot_y, rot_z, scale, skew, transpose,
    vec3,
};

/// The coordinates M and P depend on: η, α, γ (not ξ).
const CONFIGURATION: std::ops::Range<usize> = 3..DOF;

/// R_B^F = R_z(ψ) R_y(θ) R_x(φ) (forced by (12), (44), (46)).
pub fn rotation<S: Scalar>(eta: [S; 3]) -> Mat3<S> {
    mat_mul(&rot_z(eta[2]), &mat_mul(&rot_y(eta[1]), &rot_x(eta[0])))
}

/// W_η of (12): ω = W_η η̇ (body rates).
pub fn w_eta<S: Scalar>(phi: S, theta: S) -> Mat3<S> {
    let (sp, cp, st, ct) = (phi.sin(), phi.cos(), theta.sin(), theta.cos());
    let (z, o) = (S::zero(), S::one());
    [[o, z, -st], [z, cp, sp * ct], [z, -sp, cp * ct]]
}

/// d₄ᴮ = R_y(γ₂) R_x(γ₁)(−l k): where the load hangs in B.
pub fn load_offset<S: Scalar>(l: f64, gamma: [S; 2]) -> Vec3<S> {
    let (s1, c1, s2, c2) = (gamma[0].sin(), gamma[0].cos(), gamma[1].sin(), gamma[1].cos());
    [-(c1 * s2).scale(l), s1.scale(l), -(c1 * c2).scale(l)]
}

/// L_γ of (14): ḋ₄ᴮ = L_γ γ̇ (columns γ₁, γ₂).
pub fn l_gamma<S: Scalar>(l: f64, gamma: [S; 2]) -> [[S; 2]; 3] {
    let (s1, c1, s2, c2) = (gamma[0].sin(), gamma[0].cos(), gamma[1].sin(), gamma[1].cos());
    [[(s1 * s2).scale(l), -(c1 * c2).scale(l)], [c1.scale(l), S::zero()], [(s1 * c2).scale(l), (c1 * s2).scale(l)]]
}

/// ω = W_η η̇ (12), the body rates.
pub fn body_rate<S: Scalar>(eta: [S; 3], eta_dot: [S; 3]) -> Vec3<S> {
    mat_vec(&w_eta(eta[0], eta[1]), eta_dot)
}

/// ḋ^F = R_B^F (S(ω) d₄ᴮ + L_γ γ̇): the load's velocity relative to the aircraft, in F (our
/// reading: the paper says only "the load's translational velocity with respect to the
/// aircraft").
pub fn load_velocity(l: f64, eta: [f64; 3], eta_dot: [f64; 3], gamma: [f64; 2], gamma_dot: [f64; 2]) -> [f64; 3] {
    let lg = l_gamma(l, gamma);
    let relative = [0, 1, 2].map(|i| lg[i][0] * gamma_dot[0] + lg[i][1] * gamma_dot[1]);
    mat_vec(&rotation(eta), add(cross(body_rate(eta, eta_dot), load_offset(l, gamma)), relative))
}

/// W_γ of (13): the load's angular velocity relative to B, in E₄.
fn w_gamma<S: Scalar>(g1: S) -> [[S; 2]; 3] {
    let (z, o) = (S::zero(), S::one());
    [[o, z], [z, g1.cos()], [z, -g1.sin()]]
}

/// Each body's frame in B: R_E1 = I, R_E2 = R_x(−β)R_y(α_R), R_E3 = R_x(β)R_y(α_L),
/// R_E4 = R_y(γ₂)R_x(γ₁).
fn body_frames<S: Scalar>(p: &Params, q: &[S; DOF]) -> [Mat3<S>; 4] {
    let beta = S::c(p.beta);
    [
        mat3([[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]]),
        mat_mul(&rot_x(-beta), &rot_y(q[6])),
        mat_mul(&rot_x(beta), &rot_y(q[7])),
        mat_mul(&rot_y(q[9]), &rot_x(q[8])),
    ]
}

/// A 3×2 block as columns, for products with 3×3 matrices.
fn mat_vec2<S: Scalar>(m: &Mat3<S>, b: &[[S; 2]; 3]) -> [[S; 2]; 3] {
    let column = |j: usize| mat_vec(m, [b[0][j], b[1][j], b[2][j]]);
    let (c0, c1) = (column(0), column(1));
    [[c0[0], c1[0]], [c0[1], c1[1]], [c0[2], c1[2]]]
}

/// (17) the inertia matrix and (18) the potential energy, at q.
pub fn mass_and_potential<S: Scalar>(p: &Params, q: &[S; DOF]) -> ([[S; DOF]; DOF], S) {
    let (phi, theta, psi) = (q[3], q[4], q[5]);
    let (g1, g2) = (q[8], q[9]);
    let l = p.rod_length;
    let r = rotation([phi, theta, psi]);
    let w = w_eta(phi, theta);
    let wt = transpose(&w);
    let frames = body_frames(p, q);
    let d4 = load_offset(l, [g1, g2]);
    let offsets = [vec3(p.offset[0]), vec3(p.offset[1]), vec3(p.offset[2]), d4];
    let lg = l_gamma(l, [g1, g2]);
    let wg = w_gamma(g1);
    let m4 = p.mass[3];

    let total = p.total_mass();
    // s = Σ mᵢdᵢ; J = Σ R_Ei Iᵢ R_Eiᵀ + mᵢ S(dᵢ)ᵀS(dᵢ).
    let mut s = [S::zero(); 3];
    let mut j = [[S::zero(); 3]; 3];
    for i in 0..4 {
        s = add(s, scale(offsets[i], S::c(p.mass[i])));
        let rotated = mat_mul(&frames[i], &mat_mul(&mat3(p.inertia[i]), &transpose(&frames[i])));
        let sd = skew(offsets[i]);
        let steiner = mat_mul(&transpose(&sd), &sd).map(|row| row.map(|v| v.scale(p.mass[i])));
        j = mat_add(&j, &mat_add(&rotated, &steiner));
    }

    let mut m = [[S::zero(); DOF]; DOF];
    for (i, row) in m.iter_mut().enumerate().take(3) {
        row[i] = S::c(total);
    }
    // M₁₂ = R_B^F H W_η, H = −S(s).
    let m12 = mat_mul(&r, &mat_mul(&skew(s).map(|row| row.map(|v| -v)), &w));
    // M₁₅ = m₄ R_B^F L_γ.
    let m15 = mat_vec2(&r, &lg);
    // M₂₂ = W_ηᵀ J W_η.
    let m22 = mat_mul(&wt, &mat_mul(&j, &w));
    // M₂₃, M₂₄ = W_ηᵀ R_Ei Iᵢ j.
    let tilt_column = |i: usize| {
        let inertia = mat3(p.inertia[i]);
        mat_vec(&wt, mat_vec(&frames[i], [inertia[0][1], inertia[1][1], inertia[2][1]]))
    };
    let (m23, m24) = (tilt_column(1), tilt_column(2));
    // M₂₅ = W_ηᵀ R_E4 I₄ W_γ + m₄ W_ηᵀ S(d₄) L_γ.
    let rot_part = mat_vec2(&mat_mul(&wt, &mat_mul(&frames[3], &mat3(p.inertia[3]))), &wg);
    let trans_part = mat_vec2(&mat_mul(&wt, &skew(d4)), &lg);
    // M₅₅ = m₄ L_γᵀ L_γ + W_γᵀ I₄ W_γ.
    let i4 = mat3(p.inertia[3]);
    let i4wg = mat_vec2(&i4, &wg);
    for a in 0..3 {
        for b in 0..3 {
            m[a][3 + b] = m12[a][b];
            m[3 + b][a] = m12[a][b];
            // W_ηᵀJW_η is symmetric; take one triangle so that rounding keeps M exactly so.
            m[3 + a][3 + b] = if a <= b { m22[a][b] } else { m22[b][a] };
        }
        for k in 0..2 {
            let v = m15[a][k].scale(m4);
            m[a][8 + k] = v;
            m[8 + k][a] = v;
            let v = rot_part[a][k] + trans_part[a][k].scale(m4);
            m[3 + a][8 + k] = v;
            m[8 + k][3 + a] = v;
        }
        m[3 + a][6] = m23[a];
        m[6][3 + a] = m23[a];
        m[3 + a][7] = m24[a];
        m[7][3 + a] = m24[a];
    }
    m[6][6] = S::c(p.inertia[1][1][1]);
    m[7][7] = S::c(p.inertia[2][1][1]);
    for a in 0..2 {
        for b in 0..2 {
            let mut v = S::zero();
            for row in 0..3 {
                v = v + (lg[row][a] * lg[row][b]).scale(m4) + wg[row][a] * i4wg[row][b];
            }
            m[8 + a][8 + b] = v;
        }
    }
    // (18): P = g kᵀ(R_B^F s + m ξ).
    let potential = (mat_vec(&r, s)[2] + q[2].scale(total)).scale(p.g);
    (m, potential)
}

pub fn mass_matrix<S: Scalar>(p: &Params, q: &[S; DOF]) -> [[S; DOF]; DOF] {
    mass_and_potential(p, q).0
}

pub fn potential<S: Scalar>(p: &Params, q: &[S; DOF]) -> S {
    mass_and_potential(p, q).1
}

/// M(q), ∂M/∂qₖ and ∂P/∂qₖ for every k (zero for ξ but G_z = m g), by forward mode.
pub struct Partials {
    pub m: [[f64; DOF]; DOF],
    pub dm: [[[f64; DOF]; DOF]; DOF],
    pub gravity: [f64; DOF],
}

pub fn partials(p: &Params, q: &[f64; DOF]) -> Partials {
    let mut out = Partials { m: [[0.0; DOF]; DOF], dm: [[[0.0; DOF]; DOF]; DOF], gravity: [0.0; DOF] };
    out.gravity[2] = p.total_mass() * p.g;
    for k in CONFIGURATION {
        let mut qd = q.map(Dual::c);
        qd[k].d = 1.0;
        let (m, potential) = mass_and_potential(p, &qd);
        if k == CONFIGURATION.start {
            out.m = m.map(|row| row.map(|v| v.v));
        }
        out.dm[k] = m.map(|row| row.map(|v| v.d));
        out.gravity[k] = potential.d;
    }
    out
}

impl Partials {
    /// C(q, q̇) from the Christoffel symbols of the first kind:
    /// C_kj = Σᵢ ½(∂ᵢM_kj + ∂ⱼM_ki − ∂ₖM_ij) q̇ᵢ.
    pub fn coriolis(&self, qdot: &[f64; DOF]) -> [[f64; DOF]; DOF] {
        let mut c = [[0.0; DOF]; DOF];
        for (k, row) in c.iter_mut().enumerate() {
            for (j, cell) in row.iter_mut().enumerate() {
                *cell =
                    (0..DOF).map(|i| 0.5 * (self.dm[i][k][j] + self.dm[j][k][i] - self.dm[k][i][j]) * qdot[i]).sum();
            }
        }
        c
    }

    /// Ṁ = Σᵢ ∂ᵢM q̇ᵢ.
    pub fn m_dot(&self, qdot: &[f64; DOF]) -> [[f64; DOF]; DOF] {
        let mut out = [[0.0; DOF]; DOF];
        for (i, dm) in self.dm.iter().enumerate() {
            for (row, dm_row) in out.iter_mut().zip(dm) {
                for (cell, v) in row.iter_mut().zip(dm_row) {
                    *cell += v * qdot[i];
                }
            }
        }
        out
    }
}

pub fn coriolis(p: &Params, q: &[f64; DOF], qdot: &[f64; DOF]) -> [[f64; DOF]; DOF] {
    partials(p, q).coriolis(qdot)
}

/// G(q) = ∂P/∂q.
pub fn gravity(p: &Params, q: &[f64; DOF]) -> [f64; DOF] {
    partials(p, q).gravity
}

/// The propeller drag torque to thrust ratio of the control law is that of the plant.
/// The thrust directions in B, r_R and r_L of (19)–(20).
pub fn thrust_directions(beta: f64, alpha_r: f64, alpha_l: f64) -> [[f64; 3]; 2] {
    let (sb, cb) = beta.sin_cos();
    [[alpha_r.sin(), alpha_r.cos() * sb, alpha_r.cos() * cb], [alpha_l.sin(), -alpha_l.cos() * sb, alpha_l.cos() * cb]]
}

/// τ_R and τ_L of (22), verbatim: the torque on the main body per newton of each thrust.
pub fn thrust_torques(p: &Params, alpha_r: f64, alpha_l: f64) -> [[f64; 3]; 2] {
    let (sb, cb) = p.beta.sin_cos();
    let (dy, dz, k) = (p.offset[2][1].abs(), p.offset[1][2], p.drag_torque_per_thrust);
    let (sr, cr, sl, cl) = (alpha_r.sin(), alpha_r.cos(), alpha_l.sin(), alpha_l.cos());
    [
        [-cr * cb * dy - k * sr, sr * dz + k * cr * sb, sr * dy + k * cr * cb],
        [cl * cb * dy + k * sl, sl * dz + k * cl * sb, -sl * dy - k * cl * cb],
    ]
}

/// B(q) of (23): columns f_R, f_L, τ_αR, τ_αL.
pub fn input_map(p: &Params, q: &[f64; DOF]) -> [[f64; 4]; DOF] {
    let r = rotation([q[3], q[4], q[5]]);
    let wt = transpose(&w_eta(q[3], q[4]));
    let directions = thrust_directions(p.beta, q[6], q[7]);
    let torques = thrust_torques(p, q[6], q[7]);
    let mut b = [[0.0; 4]; DOF];
    for j in 0..2 {
        let force = mat_vec(&r, directions[j]);
        let torque = mat_vec(&wt, torques[j]);
        for a in 0..3 {
            b[a][j] = force[a];
            b[3 + a][j] = torque[a];
        }
    }
    b[6][2] = 1.0;
    b[7][3] = 1.0;
    b
}

/// q̈ of (3): M⁻¹(BΓ + F_ext − [C + μ]q̇ − G), with μ only on γ̇.
pub fn acceleration(p: &Params, q: &[f64; DOF], qdot: &[f64; DOF], input: &[f64; 4], f_ext: &[f64; 3]) -> [f64; DOF] {
    let parts = partials(p, q);
    let b = input_map(p, q);
    // C q̇ = Ṁq̇ − ½ q̇ᵀ(∂ₖM)q̇, cheaper than forming C.
    let m_dot = parts.m_dot(qdot);
    let quad = |dm: &[[f64; DOF]; DOF]| -> f64 {
        (0..DOF).map(|i| qdot[i] * (0..DOF).map(|j| dm[i][j] * qdot[j]).sum::<f64>()).sum()
    };
    let mut rhs = SVector::<f64, DOF>::zeros();
    for k in 0..DOF {
        let c_qdot = (0..DOF).map(|j| m_dot[k][j] * qdot[j]).sum::<f64>() - 0.5 * quad(&parts.dm[k]);
        let forcing = (0..4).map(|j| b[k][j] * input[j]).sum::<f64>();
        let drag = if k >= 8 { p.load_drag * qdot[k] } else { 0.0 };
        let external = if k < 3 { f_ext[k] } else { 0.0 };
        rhs[k] = forcing + external - c_qdot - drag - parts.gravity[k];
    }
    let m = SMatrix::<f64, DOF, DOF>::from_fn(|i, j| parts.m[i][j]);
    // M is positive definite except where the Euler angles are singular (θ = ±90°, W_η loses
    // rank): the paper's model cannot describe a vehicle that has flipped over.
    let qdd = m
        .cholesky()
        .unwrap_or_else(|| {
            panic!("tiltrotor plant: the vehicle reached θ = {:.3} rad (Euler-angle singularity at ±π/2)", q[4])
        })
        .solve(&rhs);
    qdd.into()
}

/// The total mechanical energy ½q̇ᵀMq̇ + P.
pub fn energy(p: &Params, q: &[f64; DOF], qdot: &[f64; DOF]) -> f64 {
    let (m, potential) = mass_and_potential(p, q);
    let kinetic: f64 = (0..DOF).map(|i| qdot[i] * (0..DOF).map(|j| m[i][j] * qdot[j]).sum::<f64>()).sum();
    0.5 * kinetic + potential
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::SymmetricEigen;

    fn state_at(t: f64) -> ([f64; DOF], [f64; DOF]) {
        // A made-up smooth motion through large angles.
        let q = [
            0.3 * t,
            -0.2,
            1.0 + t,
            0.4 * (2.0 * t).sin(),
            -0.3 * t.cos(),
            2.0 * t,
            0.5 * t.sin(),
            -0.4,
            1.1 * t.cos(),
            0.7 * (0.5 * t).sin(),
        ];
        let qdot = [
            0.3,
            0.0,
            1.0,
            0.8 * (2.0 * t).cos(),
            0.3 * t.sin(),
            2.0,
            0.5 * t.cos(),
            0.0,
            -1.1 * t.sin(),
            0.35 * (0.5 * t).cos(),
        ];
        (q, qdot)
    }

    #[test]
    fn the_inertia_matrix_is_symmetric_positive_definite_along_a_trajectory() {
        let p = Params::table1().perturbed(0.3, 3);
        for i in 0..50 {
            let (q, _) = state_at(0.37 * i as f64);
            let m = mass_matrix(&p, &q);
            let m = SMatrix::<f64, DOF, DOF>::from_fn(|i, j| m[i][j]);
            assert_eq!(m, m.transpose(), "symmetric");
            let smallest = SymmetricEigen::new(m).eigenvalues.min();
            assert!(smallest > 0.0, "λ_min {smallest} at sample {i}");
        }
    }

    #[test]
    fn m_dot_minus_two_c_is_skew_symmetric() {
        let p = Params::table1();
        for i in 0..20 {
            let (q, qdot) = state_at(0.53 * i as f64);
            let parts = partials(&p, &q);
            let (c, m_dot) = (parts.coriolis(&qdot), parts.m_dot(&qdot));
            for a in 0..DOF {
                for b in 0..DOF {
                    let n_ab = m_dot[a][b] - 2.0 * c[a][b];
                    let n_ba = m_dot[b][a] - 2.0 * c[b][a];
                    assert!((n_ab + n_ba).abs() < 1e-12, "({a},{b}): {n_ab} vs {n_ba}");
                }
            }
        }
    }

    #[test]
    fn dual_partials_match_central_differences() {
        let p = Params::table1();
        let (q, _) = state_at(1.3);
        let parts = partials(&p, &q);
        let h = 1e-6;
        for k in CONFIGURATION {
            let (mut a, mut b) = (q, q);
            a[k] -= h;
            b[k] += h;
            let (ma, pa) = mass_and_potential(&p, &a);
            let (mb, pb) = mass_and_potential(&p, &b);
            assert!(((pb - pa) / (2.0 * h) - parts.gravity[k]).abs() < 1e-6);
            for i in 0..DOF {
                for j in 0..DOF {
                    let fd = (mb[i][j] - ma[i][j]) / (2.0 * h);
                    assert!((fd - parts.dm[k][i][j]).abs() < 1e-7, "∂M[{i}][{j}]/∂q{k}");
                }
            }
        }
    }

    #[test]
    fn the_hover_needs_the_papers_thrust() {
        // Level, α = 0, load straight down, the control model's geometry (A1: d₁ = 0,
        // d_z = 0): m·g/(2 cos β) = 8.691 N per rotor (total mass 1.7652 kg) holds every
        // coordinate still once the propellers' drag torque of (22) is taken out; with it, only
        // the vertical balance is exact (the drag torque pitches the body).
        let mut p = Params::table1().control_model();
        let f = p.hover_thrust();
        assert!((f - 8.691).abs() < 5e-4 && (p.total_mass() - 1.7652).abs() < 1e-12);
        let at_rest = |p: &Params, f: f64| acceleration(p, &[0.0; DOF], &[0.0; DOF], &[f, f, 0.0, 0.0], &[0.0; 3]);
        assert!(at_rest(&p, f)[2].abs() < 1e-12);
        let climb = at_rest(&p, f + 0.01)[2];
        assert!((climb - 2.0 * 0.01 * p.beta.cos() / p.total_mass()).abs() < 1e-12, "{climb}");
        p.drag_torque_per_thrust = 0.0;
        for (k, a) in at_rest(&p, f).iter().enumerate() {
            assert!(a.abs() < 1e-12, "q̈[{k}] = {a}");
        }
    }

    /// The largest |E(t) − E(0)| over `seconds` of RK4 at step `h`, and the kinetic energy.
    fn energy_drift(h: f64, seconds: f64) -> (f64, f64) {
        let mut p = Params::table1().perturbed(0.3, 5);
        p.load_drag = 0.0;
        let split = |x: &SVector<f64, 20>| -> ([f64; DOF], [f64; DOF]) {
            (std::array::from_fn(|i| x[i]), std::array::from_fn(|i| x[DOF + i]))
        };
        let f = |x: &SVector<f64, 20>| {
            let (q, qdot) = split(x);
            let qdd = acceleration(&p, &q, &qdot, &[0.0; 4], &[0.0; 3]);
            SVector::<f64, 20>::from_fn(|i, _| if i < DOF { qdot[i] } else { qdd[i - DOF] })
        };
        let (q0, qdot0) = state_at(0.0);
        let e0 = energy(&p, &q0, &qdot0);
        let mut x = SVector::<f64, 20>::from_fn(|i, _| if i < DOF { q0[i] } else { qdot0[i - DOF] });
        let mut drift: f64 = 0.0;
        for _ in 0..(seconds / h).round() as usize {
            x = crate::model::integrate::rk4_step(&f, &x, h);
            let (q, qdot) = split(&x);
            drift = drift.max((energy(&p, &q, &qdot) - e0).abs());
        }
        (drift, e0 - potential(&p, &q0))
    }

    #[test]
    fn energy_is_conserved_without_drag_or_inputs() {
        // μ = 0, Γ = 0, no external force, from a tumbling start (tilt rates on the 4e-5 kg·m²
        // thrusters, a swinging load): E = ½q̇ᵀMq̇ + P is constant. RK4 at the plant's 1 ms
        // step keeps it within 1e-5 of the kinetic energy over 3 s, and the drift falls like
        // h⁴ (at least 10× for half the step), so it is the integrator's, not the model's.
        let (drift, kinetic) = energy_drift(1e-3, 3.0);
        let (half, _) = energy_drift(5e-4, 3.0);
        assert!(drift < 1e-5 * kinetic, "drift {drift} J of {kinetic} J kinetic");
        assert!(half < drift / 10.0, "{half} J at 0.5 ms against {drift} J at 1 ms");
    }
}
