//! The linear gains of NLLS-2L and NLPT-2L: the paper's mixed H₂/H∞ synthesis with the
//! pole-placement LMIs (52)–(57), Table 2's regions and Table 3's weights, solved by the
//! standalone tool `services/tiltrotor-gains` (clarabel's SDP cone; BLAS stays out of the
//! workspace) and kept in launch/tiltrotor.toml with the command that reproduces them.
//! This module holds what checks them without a solver: the design models, Table 2 and the
//! closed-loop poles and H∞ norm of each loop (the tests below).
//!
//! Table 2, read as Re s < α, |s − c| < |r|, |Im s| < tan φ·|Re s| (the printed signs clash
//! with (55)–(56)):
//!
//! | loop  | design model (51)                          | Table 2 region                      |
//! |-------|--------------------------------------------|-------------------------------------|
//! | x, y  | (∫e, e, ė), ë = ũ + π                       | Re < −1, |s| < 3, cone π/36         |
//! | swing | (∫ḋ, ḋ), see below                          | Re < −1.5, |s| < 2, cone π/20       |
//! | z     | (∫e, e, ė, ë, e⃛), e⁽⁴⁾ = ũ + π              | Re < −1.1, |s| < 80, cone π/36      |
//! | φ, θ  | the same                                   | Re < −7, |s + 7| < 110, cone π/4    |
//! | ψ     | the same                                   | Re < −3, |s + 3| < 20, cone π/10    |
//!
//! Each chain's v = Σ Kⱼ e⁽ʲ⁻¹⁾ (∫e first) closes sⁿ⁺¹ − K_last sⁿ − … − K_I (e = i − i_Ref:
//! the gains come out negative). The swing terms (49)–(50) drive ḋ with −v (the aircraft's
//! acceleration enters the pendulum with a minus sign), so K_pd > 0 damps.
//!
//! Each loop is designed on its own model as (51) lists them, the swing on ë = −ũ (x's
//! acceleration drives the load's relative velocity with a minus sign) with gravity left out as
//! in the integrator chains. Together, on the linearised pendulum (`x_and_pendulum`), the x and
//! swing loops leave the pendulum at −0.31 ± 3.36j (the pole-placement stand-ins before them:
//! −0.18 ± 3.39j), −0.14 … −0.51 over the ±30 % polytope (the tests). We also tried x and the
//! swing as one loop on that model (`tiltrotor-gains --combined`, all five poles in Re < −1,
//! |s| < 3, cone π/20): it damps the swing far more (NLPT/NLLS ratios 3.7, 3.2, medians over 60
//! runs), but NLLS-2L then tracks x about 5× worse (RMSE 0.18 m at draw 4) and the ψ and IAVU
//! ratios hold less often (15/60, 3/60), so the separate design stays.
//!
//! The ±30 % polytope: after feedback linearisation with Table 1's parameters, a drawn plant
//! sees e⁽ⁿ⁾ = ρv + … with ρ = nominal/true mass or inertia in [1/1.3, 1/0.7]. Imposing the
//! LMIs at both vertices of ρ with one Q, Y (quadratic D-stability, `--polytope`) is infeasible
//! for every loop: Table 2's cones of π/36–π/10 cannot hold a ±30 % loop gain (φ, θ's π/4 can
//! with Table 2's α = −7, but a pole then reaches 115 rad/s, beyond the 100 Hz loop). So each
//! loop is designed on its nominal model (ρ = 1); 60 runs over 20 draws show the result robust.
//!
//! Speeds (the synthesis, not chosen): x −1.01, −1.51, −2.99; swing −1.74 ± 0.13j; z −1.17 ±
//! 0.07j … −79.9 (|s|τ = 0.8 at τ = 0.01 s, the edge of its disk); ψ −3.2 ± 0.8j … −20.1;
//! φ, θ −17.5 ± 11.7j … −46.5 with α = −15 and a disk of radius 60 (the launch file says why not
//! Table 2's −7 and 110). The φ_Ref, θ_Ref
//! prefilter (25 rad/s) must stay slow: it also low-passes the path α → f_x^B → θ_Ref (the tilt
//! that pitches the body also pushes it, and (46) compensates that push); at 40 rad/s the
//! vehicle was lost (measured with the pole-placement stand-ins).
//!
//! NLLS-3L (the three-loop cascade of the paper's ref. [22]) is not here: the paper gives
//! neither its structure nor its gains.

use nalgebra::{Complex, DMatrix};

/// A Table 2 row: Re s < α, |s − centre| < radius, |Im s| < tan(cone)·|Re s|.
#[derive(Debug, Clone, Copy)]
pub struct Region {
    pub alpha: f64,
    pub centre: f64,
    pub radius: f64,
    pub cone: f64,
}

impl Region {
    pub fn holds(&self, s: Complex<f64>) -> bool {
        s.re < self.alpha && (s - self.centre).norm() < self.radius && s.im.abs() < self.cone.tan() * s.re.abs()
    }
}

const PI: f64 = std::f64::consts::PI;
pub const X_REGION: Region = Region { alpha: -1.0, centre: 0.0, radius: 3.0, cone: PI / 36.0 };
pub const SWING_REGION: Region = Region { alpha: -1.5, centre: 0.0, radius: 2.0, cone: PI / 20.0 };
pub const Z_REGION: Region = Region { alpha: -1.1, centre: 0.0, radius: 80.0, cone: PI / 36.0 };
pub const ATTITUDE_REGION: Region = Region { alpha: -7.0, centre: -7.0, radius: 110.0, cone: PI / 4.0 };
pub const YAW_REGION: Region = Region { alpha: -3.0, centre: -3.0, radius: 20.0, cone: PI / 10.0 };

/// The chain ė = shift·e + eₙ(ũ + π) of n = gains.len() states, and B.
pub fn chain(n: usize) -> (DMatrix<f64>, DMatrix<f64>) {
    let mut a = DMatrix::zeros(n, n);
    for i in 0..n - 1 {
        a[(i, i + 1)] = 1.0;
    }
    let mut b = DMatrix::zeros(n, 1);
    b[(n - 1, 0)] = 1.0;
    (a, b)
}

/// The x + pendulum design model: (∫e_x, e_x, ė_x, ∫ḋ, ḋ), ẍ = ρũ + κd, d̈ = −ẍ − (g/l)d.
pub fn x_and_pendulum(g_over_l: f64, rho: f64, kappa: f64) -> (DMatrix<f64>, DMatrix<f64>) {
    let mut a = DMatrix::zeros(5, 5);
    a[(0, 1)] = 1.0;
    a[(1, 2)] = 1.0;
    a[(2, 3)] = kappa;
    a[(3, 4)] = 1.0;
    a[(4, 3)] = -(g_over_l + kappa);
    (a, DMatrix::from_column_slice(5, 1, &[0.0, 0.0, rho, 0.0, -rho]))
}

/// The eigenvalues of A + BK.
pub fn closed_loop_poles(a: &DMatrix<f64>, b: &DMatrix<f64>, k: &[f64]) -> Vec<Complex<f64>> {
    let k = DMatrix::from_row_slice(1, k.len(), k);
    (a + b * k).complex_eigenvalues().iter().copied().collect()
}

/// A chain's closed-loop poles (its design model, e⁽ⁿ⁾ = Ke).
pub fn chain_poles(gains: &[f64]) -> Vec<Complex<f64>> {
    let (a, b) = chain(gains.len());
    closed_loop_poles(&a, &b, gains)
}

#[cfg(test)]
mod tests;
