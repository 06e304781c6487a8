//! Classical fourth-order Runge–Kutta on fixed-size nalgebra vectors.

use nalgebra::SVector;

/// One RK4 step of size `h` for the autonomous system ẋ = f(x) (inputs held constant by the
/// caller's closure).
pub fn rk4_step<const N: usize>(
    f: &impl Fn(&SVector<f64, N>) -> SVector<f64, N>,
    x: &SVector<f64, N>,
    h: f64,
) -> SVector<f64, N> {
    let k1 = f(x);
    let k2 = f(&(x + k1 * (h / 2.0)));
    let k3 = f(&(x + k2 * (h / 2.0)));
    let k4 = f(&(x + k3 * h));
    x + (k1 + k2 * 2.0 + k3 * 2.0 + k4) * (h / 6.0)
}

/// Integrates over `duration` in `substeps` equal RK4 steps.
pub fn rk4<const N: usize>(
    f: &impl Fn(&SVector<f64, N>) -> SVector<f64, N>,
    x: &SVector<f64, N>,
    duration: f64,
    substeps: u32,
) -> SVector<f64, N> {
    let h = duration / f64::from(substeps.max(1));
    (0..substeps.max(1)).fold(*x, |x, _| rk4_step(f, &x, h))
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::Vector2;

    #[test]
    fn harmonic_oscillator_matches_the_analytic_solution() {
        // ẍ = −x from (1, 0): x = cos t.
        let f = |x: &Vector2<f64>| Vector2::new(x[1], -x[0]);
        let x = rk4(&f, &Vector2::new(1.0, 0.0), 10.0, 1000);
        assert!((x[0] - 10f64.cos()).abs() < 1e-9);
        assert!((x[1] + 10f64.sin()).abs() < 1e-9);
    }
}
