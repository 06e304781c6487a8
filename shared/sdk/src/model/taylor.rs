//! Truncated power series in t, for Taylor-mode differentiation: a [`Taylor`] holds the
//! coefficients of t⁰ … t^(N−1) of a function of time, and arithmetic on series gives the
//! series of the result exactly (to that order). Propagating an ODE's state as series gives its
//! time derivatives at t = 0 without numerical differentiation: x⁽ⁿ⁾(0) = n!·xₙ.

use std::ops::{Add, Div, Mul, Neg, Sub};

use super::autodiff::Scalar;

/// a₀ + a₁t + … + a_(N−1)t^(N−1), higher powers dropped.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Taylor<const N: usize> {
    pub c: [f64; N],
}

impl<const N: usize> Taylor<N> {
    pub fn new(c: [f64; N]) -> Self {
        Taylor { c }
    }

    /// a + b·t.
    pub fn line(a: f64, b: f64) -> Self {
        let mut c = [0.0; N];
        c[0] = a;
        if N > 1 {
            c[1] = b;
        }
        Taylor { c }
    }

    /// The n-th time derivative at t = 0: n!·aₙ.
    pub fn derivative(&self, n: usize) -> f64 {
        self.c[n] * (1..=n).map(|k| k as f64).product::<f64>()
    }
}

impl<const N: usize> Add for Taylor<N> {
    type Output = Self;
    fn add(self, o: Self) -> Self {
        Taylor { c: std::array::from_fn(|k| self.c[k] + o.c[k]) }
    }
}

impl<const N: usize> Sub for Taylor<N> {
    type Output = Self;
    fn sub(self, o: Self) -> Self {
        Taylor { c: std::array::from_fn(|k| self.c[k] - o.c[k]) }
    }
}

impl<const N: usize> Neg for Taylor<N> {
    type Output = Self;
    fn neg(self) -> Self {
        Taylor { c: self.c.map(|v| -v) }
    }
}

/// The Cauchy product, truncated.
impl<const N: usize> Mul for Taylor<N> {
    type Output = Self;
    fn mul(self, o: Self) -> Self {
        Taylor { c: std::array::from_fn(|k| (0..=k).map(|j| self.c[j] * o.c[k - j]).sum()) }
    }
}

/// q = a/b from a = q·b: qₖ = (aₖ − Σ_{j=1..k} bⱼ q_(k−j)) / b₀.
impl<const N: usize> Div for Taylor<N> {
    type Output = Self;
    fn div(self, o: Self) -> Self {
        let mut q = [0.0; N];
        for k in 0..N {
            let known: f64 = (1..=k).map(|j| o.c[j] * q[k - j]).sum();
            q[k] = (self.c[k] - known) / o.c[0];
        }
        Taylor { c: q }
    }
}

impl<const N: usize> Taylor<N> {
    /// sin u and cos u together, from s′ = c·u′ and c′ = −s·u′:
    /// k·sₖ = Σ_{j=1..k} j·uⱼ·c_(k−j), k·cₖ = −Σ_{j=1..k} j·uⱼ·s_(k−j).
    pub fn sin_cos(self) -> (Self, Self) {
        let (mut s, mut c) = ([0.0; N], [0.0; N]);
        s[0] = self.c[0].sin();
        c[0] = self.c[0].cos();
        for k in 1..N {
            let (mut ds, mut dc) = (0.0, 0.0);
            for j in 1..=k {
                let ju = j as f64 * self.c[j];
                ds += ju * c[k - j];
                dc -= ju * s[k - j];
            }
            s[k] = ds / k as f64;
            c[k] = dc / k as f64;
        }
        (Taylor { c: s }, Taylor { c })
    }
}

impl<const N: usize> Scalar for Taylor<N> {
    fn c(value: f64) -> Self {
        let mut c = [0.0; N];
        c[0] = value;
        Taylor { c }
    }
    fn value(self) -> f64 {
        self.c[0]
    }
    fn sin(self) -> Self {
        self.sin_cos().0
    }
    fn cos(self) -> Self {
        self.sin_cos().1
    }
    /// r = √a from r·r = a: rₖ = (aₖ − Σ_{j=1..k−1} rⱼ r_(k−j)) / (2r₀).
    fn sqrt(self) -> Self {
        let mut r = [0.0; N];
        r[0] = self.c[0].sqrt();
        for k in 1..N {
            let known: f64 = (1..k).map(|j| r[j] * r[k - j]).sum();
            r[k] = (self.c[k] - known) / (2.0 * r[0]);
        }
        Taylor { c: r }
    }
    fn scale(self, k: f64) -> Self {
        Taylor { c: self.c.map(|v| v * k) }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    type T5 = Taylor<5>;

    fn close(a: &[f64], b: &[f64], tol: f64) {
        for (k, (x, y)) in a.iter().zip(b).enumerate() {
            assert!((x - y).abs() < tol, "coefficient {k}: {x} vs {y}");
        }
    }

    #[test]
    fn sin_and_cos_of_a_line_are_the_known_series() {
        // sin(a + bt) = Σ sin(a + kπ/2) bᵏ tᵏ / k!.
        let (a, b) = (0.7, -1.3);
        let (s, c) = T5::line(a, b).sin_cos();
        let fact = [1.0, 1.0, 2.0, 6.0, 24.0];
        let half_pi = std::f64::consts::FRAC_PI_2;
        let sin_expected: Vec<f64> =
            (0..5).map(|k| (a + k as f64 * half_pi).sin() * b.powi(k) / fact[k as usize]).collect();
        let cos_expected: Vec<f64> =
            (0..5).map(|k| (a + k as f64 * half_pi).cos() * b.powi(k) / fact[k as usize]).collect();
        close(&s.c, &sin_expected, 1e-15);
        close(&c.c, &cos_expected, 1e-15);
    }

    #[test]
    fn division_and_square_root_are_the_binomial_series() {
        // 1/(1 + t) = 1 − t + t² − t³ + t⁴.
        let q = T5::c(1.0) / T5::line(1.0, 1.0);
        close(&q.c, &[1.0, -1.0, 1.0, -1.0, 1.0], 1e-15);
        // √(1 + t) = 1 + t/2 − t²/8 + t³/16 − 5t⁴/128.
        let r = T5::line(1.0, 1.0).sqrt();
        close(&r.c, &[1.0, 0.5, -0.125, 0.0625, -5.0 / 128.0], 1e-15);
        // (1 + t)·(1 − t + t² − t³ + t⁴) = 1 + t⁵, truncated: 1.
        close(&(q * T5::line(1.0, 1.0)).c, &[1.0, 0.0, 0.0, 0.0, 0.0], 1e-15);
    }

    #[test]
    fn a_composition_matches_its_analytic_derivatives() {
        // f(t) = sin(t)²/(2 + t) at t = 0.4 (series in s = t − 0.4): compare f′ and f″ with
        // the hand derivatives.
        let t0 = 0.4;
        let u = T5::line(t0, 1.0);
        let f = u.sin() * u.sin() / (T5::c(2.0) + u);
        let (s, c, d) = (t0.sin(), t0.cos(), 2.0 + t0);
        let g = s * s;
        let g1 = 2.0 * s * c;
        let g2 = 2.0 * (c * c - s * s);
        let f1 = g1 / d - g / (d * d);
        let f2 = g2 / d - 2.0 * g1 / (d * d) + 2.0 * g / (d * d * d);
        assert!((f.derivative(0) - g / d).abs() < 1e-15);
        assert!((f.derivative(1) - f1).abs() < 1e-14);
        assert!((f.derivative(2) - f2).abs() < 1e-14);
    }
}
