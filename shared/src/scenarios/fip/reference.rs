//! The reference of (68)–(69): the load flies the tilted ellipse
//!
//!   p_Ld(ϑ) = [r sin(ϑ + π/2), r sin ϑ, c sin ϑ + z₀]   (paper: r = 0.8, c = 0.5, z₀ = −1.6 m)
//!
//! at constant speed V along the path: ϑ̇ = V/‖∂p_Ld/∂ϑ‖ = V/√(r² + c² cos²ϑ), ϑ(0) = 0.
//! ϑ(t) is integrated by Taylor steps of that ODE (series to the tenth order, steps of at most
//! 10 ms, so the truncation error is far below rounding), and the derivatives of p_Ld to the
//! sixth order come exactly from the series of p_Ld(ϑ(t + s)): the controller needs p_Ld⁽⁵⁾.

use serde::Deserialize;

use crate::model::autodiff::Scalar;
use crate::model::reference::Reference;
use crate::model::taylor::Taylor;

/// The value and the derivatives to the sixth order.
pub const ORDERS: usize = 7;
/// Coefficients of ϑ's series in one integration step.
const STEP_ORDER: usize = 11;
/// The longest integration step, s.
const MAX_STEP_S: f64 = 0.01;

/// `[reference]`.
#[derive(Debug, Clone, Copy, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct ReferenceSection {
    /// r: the radius of the path's projection on the x–y plane, m.
    pub radius_m: f64,
    /// c: how far z swings either side of its centre, m.
    pub z_amplitude_m: f64,
    /// z₀ (NED: negative is up), m.
    pub z_centre_m: f64,
    /// V, the speed along the path, m/s.
    pub speed_m_s: f64,
}

/// The reference at one instant: `p[n]` is the n-th time derivative of p_Ld; ϑ is the path
/// parameter (one lap per 2π).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Point {
    pub p: [[f64; 3]; ORDERS],
    pub theta: f64,
}

#[derive(Debug, Clone)]
pub struct EllipseReference {
    section: ReferenceSection,
    /// The last (t, ϑ(t)) computed: the loop asks for t in order, so each call integrates
    /// one tick on from it.
    cached: (f64, f64),
}

impl EllipseReference {
    pub fn new(section: ReferenceSection) -> Self {
        Self { section, cached: (0.0, 0.0) }
    }

    /// p_Ld as a function of ϑ, on any scalar.
    fn path<S: Scalar>(&self, theta: S) -> [S; 3] {
        let s = self.section;
        [
            theta.cos().scale(s.radius_m),
            theta.sin().scale(s.radius_m),
            theta.sin().scale(s.z_amplitude_m) + S::c(s.z_centre_m),
        ]
    }

    /// ϑ̇ = V/√(r² + c² cos²ϑ), on any scalar.
    fn theta_rate<S: Scalar>(&self, theta: S) -> S {
        let s = self.section;
        let c = theta.cos();
        S::c(s.speed_m_s) / (c * c.scale(s.z_amplitude_m * s.z_amplitude_m) + S::c(s.radius_m * s.radius_m)).sqrt()
    }

    /// The series of ϑ(t + s) from ϑ(t), order by order: ϑₖ₊₁ = (ϑ̇)ₖ/(k + 1).
    fn theta_series<const N: usize>(&self, theta: f64) -> Taylor<N> {
        let mut series = Taylor::<N>::c(theta);
        for k in 0..N - 1 {
            let rate = self.theta_rate(series);
            series.c[k + 1] = rate.c[k] / (k + 1) as f64;
        }
        series
    }

    /// The last (t, ϑ(t)) computed, from which the next call integrates on.
    pub fn phase(&self) -> (f64, f64) {
        self.cached
    }

    /// Goes on from a phase that [`EllipseReference::phase`] gave (a restarted controller).
    pub fn resume_phase(&mut self, phase: (f64, f64)) {
        self.cached = phase;
    }

    /// ϑ(t), integrated from the last instant asked for (from 0 if t is earlier).
    pub fn theta(&mut self, t: f64) -> f64 {
        let (mut at, mut theta) = if t >= self.cached.0 { self.cached } else { (0.0, 0.0) };
        while at < t {
            let h = (t - at).min(MAX_STEP_S);
            let series = self.theta_series::<STEP_ORDER>(theta);
            theta = series.c.iter().rev().fold(0.0, |sum, c| sum * h + c);
            at = if t - at <= MAX_STEP_S { t } else { at + h };
        }
        self.cached = (t, theta);
        theta
    }

    /// The time one lap takes: the integral of 1/ϑ̇ over one period of ϑ, by Simpson's rule on
    /// 2000 panels (the integrand is smooth and periodic, so this is exact to rounding).
    pub fn lap_period_s(&self) -> f64 {
        let n = 2000;
        let h = std::f64::consts::TAU / n as f64;
        let f = |i: usize| 1.0 / self.theta_rate(i as f64 * h);
        let inner: f64 = (1..n).map(|i| if i % 2 == 1 { 4.0 } else { 2.0 } * f(i)).sum();
        (f(0) + inner + f(n)) * h / 3.0
    }
}

impl Reference for EllipseReference {
    type Point = Point;

    fn at(&mut self, t: f64) -> Point {
        let theta = self.theta(t);
        let series = self.theta_series::<ORDERS>(theta);
        let p = self.path(series);
        Point { p: std::array::from_fn(|n| [p[0].derivative(n), p[1].derivative(n), p[2].derivative(n)]), theta }
    }

    /// ‖p_L − p_Ld‖, m.
    fn error(&mut self, t: f64, x: &[f64]) -> f64 {
        let d = self.at(t).p[0];
        (0..3).map(|i| (x[i] - d[i]).powi(2)).sum::<f64>().sqrt()
    }
}

#[cfg(test)]
pub mod tests {
    use super::*;

    pub fn paper() -> ReferenceSection {
        ReferenceSection { radius_m: 0.8, z_amplitude_m: 0.5, z_centre_m: -1.6, speed_m_s: 0.5 }
    }

    fn norm(v: [f64; 3]) -> f64 {
        v.iter().map(|x| x * x).sum::<f64>().sqrt()
    }

    /// Numbers derived by hand: p_Ld(0) = [0.8, 0, −1.6], ṗ_Ld(0) = [0, 0.4240, 0.2650],
    /// p̈_Ld(0) = [−0.2247, 0, 0]; one lap takes 10.9726 s (arc 5.48631 m at 0.5 m/s).
    #[test]
    fn the_start_and_the_lap_match_the_note() {
        let mut r = EllipseReference::new(paper());
        let p = r.at(0.0).p;
        let close = |a: [f64; 3], b: [f64; 3], tol: f64| (0..3).all(|i| (a[i] - b[i]).abs() < tol);
        assert!(close(p[0], [0.8, 0.0, -1.6], 1e-15), "{:?}", p[0]);
        assert!(close(p[1], [0.0, 0.4240, 0.2650], 5e-5), "{:?}", p[1]);
        assert!(close(p[2], [-0.2247, 0.0, 0.0], 5e-5), "{:?}", p[2]);
        let lap = r.lap_period_s();
        assert!((lap - 10.9726).abs() < 5e-4, "{lap}");
        // Integrating ϑ to the lap's end gives 2π.
        let theta = r.theta(lap);
        assert!((theta - std::f64::consts::TAU).abs() < 1e-10, "{theta}");
    }

    /// The speed along the path is V at every instant, and each derivative is the time
    /// derivative of the one before (central differences, which the exact series must match).
    #[test]
    fn the_speed_is_constant_and_the_derivatives_are_consistent() {
        let mut r = EllipseReference::new(paper());
        let h = 1e-4;
        for i in 0..200 {
            let t = 0.1 * i as f64 + 0.01;
            let here = r.at(t);
            assert!((norm(here.p[1]) - 0.5).abs() < 1e-12, "speed at {t}: {}", norm(here.p[1]));
            let (before, after) = (r.at(t - h).p, r.at(t + h).p);
            for n in 0..ORDERS - 1 {
                for axis in 0..3 {
                    let numeric = (after[n][axis] - before[n][axis]) / (2.0 * h);
                    let scale = 1.0 + here.p[n + 1][axis].abs();
                    assert!(
                        (numeric - here.p[n + 1][axis]).abs() < 1e-5 * scale,
                        "order {} axis {axis} at {t}: {numeric} vs {}",
                        n + 1,
                        here.p[n + 1][axis]
                    );
                }
            }
        }
    }

    /// Asking for an earlier time integrates again from 0 and gives the same ϑ.
    #[test]
    fn theta_does_not_depend_on_the_order_of_calls() {
        let mut a = EllipseReference::new(paper());
        let mut b = EllipseReference::new(paper());
        let late = a.theta(7.3);
        a.theta(30.0);
        assert_eq!(a.theta(7.3).to_bits(), late.to_bits());
        for k in 0..=7300 {
            b.theta(k as f64 * 1e-3);
        }
        assert!((b.theta(7.3) - late).abs() < 1e-12);
    }
}
