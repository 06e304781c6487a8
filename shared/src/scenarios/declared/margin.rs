//! The theoretical delay margin of a declared linear loop: the plant ẋ = A x + B u integrated as
//! LoopLab integrates it (RK4, `substeps` per period, the input held), each estimate component a
//! state component sensed every loop (each sensor's `delay_ticks` late), the built-in
//! pass-through estimator and u = −K (x̂ − r). A reference does not change stability.
//!
//! With one input the loop gain is L(z) = Σ_j K_j z^(−s_j) [(zI − Φ)⁻¹ Γ]_(i_j), and an extra
//! controller delay of d ticks multiplies it by z^(−d): the loop, stable at d = 0, goes unstable
//! at the smallest d at which a crossover's phase margin is used up, d* = min over crossovers
//! ω_c (rad per tick, |L| = 1) of the phase margin over ω_c. The margin is the first whole d ≥ d*,
//! confirmed by the spectral radius of the loop with its delays as state (below 1 one tick
//! before, at least 1 at it). Unknown (None) where the loop is not that, or the check fails.

use nalgebra::{Complex, DMatrix, DVector};

use crate::config::launch::LaunchConfig;
use crate::config::launch::declared::Source;
use crate::model::scenario::TheoreticalMargin;

use super::system::{PlantSource, System};

/// Frequencies sampled for the crossovers, over (0, π] rad per tick.
const GRID: usize = 20_000;
/// The check's matrix is n·(d + 1) square: larger loops are not confirmed, so not reported.
const MAX_CHECKED_DIM: usize = 1500;

/// The margin of `system`'s loop as `config` runs it, or None (see the module).
pub fn delay_margin(system: &System, config: &LaunchConfig) -> Option<TheoreticalMargin> {
    let PlantSource::Linear(linear) = &system.source else { return None };
    let (gains, picks) = (system.gains.as_ref()?, system.pass_through.as_ref()?);
    let [gains] = gains.as_slice() else { return None };
    let n = linear.a.len();
    // Each estimate component: the state component it is and how late its sensor reads it.
    let sensors: Vec<_> = config.sensors.values().collect();
    let mut sensed = Vec::new();
    for &(sensor, component) in picks {
        let spec = sensors.get(sensor)?;
        if (spec.period_s * config.rate_hz).round() as i64 != 1 {
            return None;
        }
        let (source, index, _) = system.vectors.find(spec.reads.get(component)?).ok()?;
        (source == Source::State).then_some(())?;
        sensed.push((index, spec.delay_ticks as usize));
    }
    let (phi, gamma) = sampled_plant(&linear.a, &linear.b, config.dt(), system.substeps);
    let loop_gain = |omega: f64| -> Option<Complex<f64>> {
        let z = Complex::from_polar(1.0, omega);
        let zi_phi = DMatrix::<Complex<f64>>::identity(n, n) * z - phi.map(Complex::from);
        let v = zi_phi.lu().solve(&gamma.map(Complex::from))?;
        Some(gains.iter().zip(&sensed).map(|(k, &(i, s))| v[i] * *k * z.powi(-(s as i32))).sum())
    };
    let radius = |d: usize| spectral_radius(&closed_loop(&phi, &gamma, gains, &sensed, d));
    if n * (sensed.iter().map(|s| s.1).max().unwrap_or(0) + 1) > MAX_CHECKED_DIM || radius(0)? >= 1.0 {
        return None;
    }
    // Crossovers: where |L| passes 1 between two grid points, refined by bisection.
    let excess = |omega: f64| loop_gain(omega).map(|l| l.norm() - 1.0);
    let mut best: Option<(f64, f64, f64)> = None; // (d*, ω_c, phase margin)
    let step = std::f64::consts::PI / GRID as f64;
    let mut before = excess(step)?;
    for i in 2..=GRID {
        let omega = step * i as f64;
        let now = excess(omega)?;
        if before.signum() != now.signum() {
            let (mut lo, mut hi) = (omega - step, omega);
            for _ in 0..60 {
                let mid = 0.5 * (lo + hi);
                if excess(mid)?.signum() == before.signum() { lo = mid } else { hi = mid }
            }
            let crossing = 0.5 * (lo + hi);
            let phase_margin =
                (std::f64::consts::PI + loop_gain(crossing)?.arg()).rem_euclid(2.0 * std::f64::consts::PI);
            let ticks = phase_margin / crossing;
            if best.is_none_or(|(b, ..)| ticks < b) {
                best = Some((ticks, crossing, phase_margin));
            }
        }
        before = now;
    }
    let (exact, crossover, phase_margin) = best?;
    let ticks = exact.ceil().max(1.0) as usize;
    if n * (ticks + sensed.iter().map(|s| s.1).max().unwrap_or(0) + 1) > MAX_CHECKED_DIM {
        return None;
    }
    let (radius_before, radius_at_margin) = (radius(ticks - 1)?, radius(ticks)?);
    (radius_before < 1.0 && radius_at_margin >= 1.0).then_some(TheoreticalMargin {
        ticks: ticks as u32,
        continuous_ticks: f64::NAN,
        lagged_ticks: exact,
        crossover_rad_s: crossover * config.rate_hz,
        phase_margin_deg: phase_margin.to_degrees(),
        radius_before,
        radius_at_margin,
    })
}

/// One period of the plant as LoopLab integrates it: x⁺ = Φ x + Γ u, from `substeps` RK4 steps
/// of ẋ = A x + B u with u held.
fn sampled_plant(a: &[Vec<f64>], b: &[Vec<f64>], dt: f64, substeps: u32) -> (DMatrix<f64>, DVector<f64>) {
    let n = a.len();
    let a = DMatrix::from_fn(n, n, |i, j| a[i][j]);
    let b = DVector::from_fn(n, |i, _| b[i][0]);
    let h = dt / f64::from(substeps.max(1));
    let ha = &a * h;
    let identity = DMatrix::<f64>::identity(n, n);
    let ha2 = &ha * &ha;
    let ha3 = &ha2 * &ha;
    // RK4 on a linear system: x⁺ = (I + hA + (hA)²/2 + (hA)³/6 + (hA)⁴/24) x + h (I + hA/2 + (hA)²/6 + (hA)³/24) B u.
    let m = &identity + &ha + &ha2 / 2.0 + &ha3 / 6.0 + &ha3 * &ha / 24.0;
    let g = (&identity + &ha / 2.0 + &ha2 / 6.0 + &ha3 / 24.0) * &b * h;
    let (mut phi, mut gamma) = (identity.clone(), DVector::zeros(n));
    for _ in 0..substeps.max(1) {
        gamma = &m * gamma + &g;
        phi = &m * phi;
    }
    (phi, gamma)
}

/// The loop with `d` ticks of extra controller delay, its past states as state:
/// x_{k+1} = Φ x_k − Γ Σ_j K_j x_{i_j, k − d − s_j}, over (x_k, x_{k−1}, …, x_{k−D}).
fn closed_loop(
    phi: &DMatrix<f64>,
    gamma: &DVector<f64>,
    gains: &[f64],
    sensed: &[(usize, usize)],
    d: usize,
) -> DMatrix<f64> {
    let n = phi.nrows();
    let depth = d + sensed.iter().map(|s| s.1).max().unwrap_or(0);
    let dim = n * (depth + 1);
    let mut m = DMatrix::zeros(dim, dim);
    m.view_mut((0, 0), (n, n)).copy_from(phi);
    for (k, &(i, s)) in gains.iter().zip(sensed) {
        let column = n * (d + s) + i;
        for row in 0..n {
            m[(row, column)] -= gamma[row] * k;
        }
    }
    for lag in 1..=depth {
        m.view_mut((n * lag, n * (lag - 1)), (n, n)).copy_from(&DMatrix::identity(n, n));
    }
    m
}

fn spectral_radius(m: &DMatrix<f64>) -> Option<f64> {
    let schur = nalgebra::linalg::Schur::try_new(m.clone(), f64::EPSILON, 1_000_000)?;
    Some(schur.complex_eigenvalues().iter().map(|z| z.norm()).fold(0.0, f64::max))
}
