//! The references p_d(t) with their first three time derivatives (the torque law needs p⃛_d),
//! and the excitation γ(t) (paper 001).
//!
//! The derivatives are exact: positions are evaluated on truncated Taylor series in t
//! ([`Jet`]), so the chain rule through ψ(t) is done by arithmetic, not by hand.

use nalgebra::{Matrix3, Vector3};
use serde::Deserialize;

/// p_d and its derivatives at one instant.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Point {
    pub p: Vector3<f64>,
    pub v: Vector3<f64>,
    pub a: Vector3<f64>,
    pub jerk: Vector3<f64>,
}

#[derive(Debug, Clone, Copy, PartialEq, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Kind {
    /// A fixed point (`hover_position`).
    Hover,
    /// The tilted Bernoulli lemniscate flown at the constant speed v_d: the self-consistent
    /// reading of the paper's (65)–(67).
    Lemniscate,
    /// (65)–(67) exactly as printed: t inside the square root and sin² in the y denominator.
    /// Its speed varies between 0.05 and 1.26 m/s instead of the stated 0.8.
    LemniscatePrinted,
}

#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ReferenceSection {
    pub kind: Kind,
    /// Hover: p_d, m ({I}, z down).
    pub hover_position: [f64; 3],
    /// Lemniscate: half-width ℓ_d (also the altitude), m.
    pub lemniscate_size_m: f64,
    /// Lemniscate: the desired speed v_d, m/s.
    pub lemniscate_speed_m_s: f64,
    /// Lemniscate: the tilt φ about x, degrees.
    pub lemniscate_tilt_deg: f64,
    /// γ(t) = amplitude · sin(frequency · t), rad/s: how hard the controller spins the vehicle
    /// about δ to excite the parameters (0 for none).
    pub gamma_amplitude: f64,
    pub gamma_frequency_rad_s: f64,
}

/// Steps of the ψ integration: fixed, so that every process gets the same ψ(t).
const PSI_STEP_S: f64 = 1e-4;

pub struct Reference {
    section: ReferenceSection,
    tilt: Matrix3<f64>,
    /// The lemniscate's phase ψ on the fixed grid: (grid index, ψ there).
    psi_at: (u64, f64),
}

impl Reference {
    pub fn new(section: &ReferenceSection) -> Self {
        let phi = section.lemniscate_tilt_deg.to_radians();
        let (s, c) = phi.sin_cos();
        // R_x(φ) as printed in (67).
        let tilt = Matrix3::new(1.0, 0.0, 0.0, 0.0, c, s, 0.0, -s, c);
        Self { section: section.clone(), tilt, psi_at: (0, 0.0) }
    }

    /// γ(t) and γ̇(t).
    pub fn gamma(&self, t: f64) -> (f64, f64) {
        let (a, w) = (self.section.gamma_amplitude, self.section.gamma_frequency_rad_s);
        (a * (w * t).sin(), a * w * (w * t).cos())
    }

    /// ψ̇ as a function of (t, ψ).
    fn psi_rate(&self, t: f64, psi: f64) -> f64 {
        let c = self.section.lemniscate_speed_m_s / self.section.lemniscate_size_m;
        match self.section.kind {
            Kind::LemniscatePrinted => c * (t.sin().powi(2) + 1.0).sqrt(),
            _ => c * (1.0 + psi.cos().powi(2)).sqrt(),
        }
    }

    fn rk4(&self, t: f64, psi: f64, h: f64) -> f64 {
        let k1 = self.psi_rate(t, psi);
        let k2 = self.psi_rate(t + h / 2.0, psi + h / 2.0 * k1);
        let k3 = self.psi_rate(t + h / 2.0, psi + h / 2.0 * k2);
        let k4 = self.psi_rate(t + h, psi + h * k3);
        psi + h / 6.0 * (k1 + 2.0 * k2 + 2.0 * k3 + k4)
    }

    /// ψ(t) from ψ(0) = 0, by RK4 on a fixed grid (cached: calls come in increasing t).
    fn psi(&mut self, t: f64) -> f64 {
        let n = (t / PSI_STEP_S).floor().max(0.0) as u64;
        if n < self.psi_at.0 {
            self.psi_at = (0, 0.0);
        }
        while self.psi_at.0 < n {
            let (i, psi) = self.psi_at;
            self.psi_at = (i + 1, self.rk4(i as f64 * PSI_STEP_S, psi, PSI_STEP_S));
        }
        let (i, psi) = self.psi_at;
        let rest = t - i as f64 * PSI_STEP_S;
        if rest > 0.0 { self.rk4(i as f64 * PSI_STEP_S, psi, rest) } else { psi }
    }
}

impl crate::model::reference::Reference for Reference {
    type Point = Point;

    fn at(&mut self, t: f64) -> Point {
        if self.section.kind == Kind::Hover {
            let zero = Vector3::zeros();
            return Point { p: Vector3::from(self.section.hover_position), v: zero, a: zero, jerk: zero };
        }
        let psi = self.psi(t);
        let s = &self.section;
        let c = s.lemniscate_speed_m_s / s.lemniscate_size_m;
        // ψ as a series in t: ψ̇ from its ODE, ψ̈ and ψ⃛ by differentiating it along ψ̇.
        let psi_jet = match s.kind {
            Kind::LemniscatePrinted => {
                let time = Jet([t, 1.0, 0.0, 0.0]);
                let rate = ((time.sin() * time.sin()) + 1.0).sqrt() * c;
                rate.integrate(psi)
            }
            _ => {
                // ψ̇ = c√(1 + cos²ψ): ψ̈ = −c² sinψ cosψ, ψ⃛ = −c² cos 2ψ · ψ̇.
                let rate = c * (1.0 + psi.cos().powi(2)).sqrt();
                let accel = -c * c * psi.sin() * psi.cos();
                let jerk = -c * c * (2.0 * psi).cos() * rate;
                Jet([psi, rate, accel / 2.0, jerk / 6.0])
            }
        };
        let l = s.lemniscate_size_m;
        let (sin, cos) = (psi_jet.sin(), psi_jet.cos());
        let (x, y) = match s.kind {
            Kind::LemniscatePrinted => ((sin * cos * l).div(&((cos * cos) + 1.0)), (sin * l).div(&((sin * sin) + 1.0))),
            _ => {
                let denominator = (cos * cos) + 1.0;
                ((sin * cos * l).div(&denominator), (sin * l).div(&denominator))
            }
        };
        let z = Jet([-l, 0.0, 0.0, 0.0]);
        let derivative = |order: usize| {
            let factorial = [1.0, 1.0, 2.0, 6.0][order];
            self.tilt * Vector3::new(x.0[order], y.0[order], z.0[order]) * factorial
        };
        Point { p: derivative(0), v: derivative(1), a: derivative(2), jerk: derivative(3) }
    }

    /// ‖z₁‖ = ‖p − p_d‖, m.
    fn error(&mut self, t: f64, x: &[f64]) -> f64 {
        (Vector3::from_column_slice(&x[..3]) - self.at(t).p).norm()
    }
}

/// A truncated Taylor series f(t₀ + s) = Σ cᵢ sⁱ, i ≤ 3: arithmetic on it carries the first
/// three derivatives through any formula (cᵢ = f⁽ⁱ⁾/i!).
#[derive(Debug, Clone, Copy, PartialEq)]
struct Jet([f64; 4]);

impl std::ops::Add<f64> for Jet {
    type Output = Jet;
    fn add(mut self, rhs: f64) -> Jet {
        self.0[0] += rhs;
        self
    }
}

impl std::ops::Mul<f64> for Jet {
    type Output = Jet;
    fn mul(self, rhs: f64) -> Jet {
        Jet(self.0.map(|c| c * rhs))
    }
}

impl std::ops::Mul for Jet {
    type Output = Jet;
    fn mul(self, rhs: Jet) -> Jet {
        let (a, b) = (self.0, rhs.0);
        Jet(std::array::from_fn(|n| (0..=n).map(|i| a[i] * b[n - i]).sum()))
    }
}

impl Jet {
    fn div(&self, rhs: &Jet) -> Jet {
        // q = a / b: a = q b, so qₙ = (aₙ − Σ_{i<n} qᵢ b_{n−i}) / b₀.
        let (a, b) = (self.0, rhs.0);
        let mut q = [0.0; 4];
        for n in 0..4 {
            q[n] = (a[n] - (0..n).map(|i| q[i] * b[n - i]).sum::<f64>()) / b[0];
        }
        Jet(q)
    }

    /// sin and cos together: s' = c u', c' = −s u'.
    fn sin_cos(&self) -> (Jet, Jet) {
        let u = self.0;
        let (mut s, mut c) = ([0.0; 4], [0.0; 4]);
        (s[0], c[0]) = u[0].sin_cos();
        for n in 1..4 {
            // n sₙ = Σ_{k=1..n} k u_k c_{n−k}, and likewise for c with −s.
            let nf = n as f64;
            s[n] = (1..=n).map(|k| k as f64 * u[k] * c[n - k]).sum::<f64>() / nf;
            c[n] = -(1..=n).map(|k| k as f64 * u[k] * s[n - k]).sum::<f64>() / nf;
        }
        (Jet(s), Jet(c))
    }

    fn sin(&self) -> Jet {
        self.sin_cos().0
    }

    fn cos(&self) -> Jet {
        self.sin_cos().1
    }

    fn sqrt(&self) -> Jet {
        // r² = u: 2 r₀ rₙ = uₙ − Σ_{0<i<n} rᵢ r_{n−i}.
        let u = self.0;
        let mut r = [0.0; 4];
        r[0] = u[0].sqrt();
        for n in 1..4 {
            r[n] = (u[n] - (1..n).map(|i| r[i] * r[n - i]).sum::<f64>()) / (2.0 * r[0]);
        }
        Jet(r)
    }

    /// The series of ∫ with the given value at s = 0 (drops the last term).
    fn integrate(&self, value: f64) -> Jet {
        let c = self.0;
        Jet([value, c[0], c[1] / 2.0, c[2] / 3.0])
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::model::reference::Reference as _;

    pub(crate) fn section(kind: Kind) -> ReferenceSection {
        ReferenceSection {
            kind,
            hover_position: [0.0, 0.0, -0.8],
            lemniscate_size_m: 1.2,
            lemniscate_speed_m_s: 0.8,
            lemniscate_tilt_deg: -10.0,
            gamma_amplitude: 30.0,
            gamma_frequency_rad_s: 1.0,
        }
    }

    /// Each derivative against a central difference of the one below it.
    #[test]
    fn derivatives_match_finite_differences() {
        for kind in [Kind::Lemniscate, Kind::LemniscatePrinted] {
            let mut r = Reference::new(&section(kind));
            let h = 1e-4;
            for t in [0.3, 2.0, 5.55, 9.1] {
                let (before, now, after) = (r.at(t - h), r.at(t), r.at(t + h));
                let d = |f: fn(&Point) -> Vector3<f64>| (f(&after) - f(&before)) / (2.0 * h);
                assert!((d(|p| p.p) - now.v).norm() < 1e-6, "{kind:?} velocity at {t}");
                assert!((d(|p| p.v) - now.a).norm() < 1e-6, "{kind:?} acceleration at {t}");
                assert!((d(|p| p.a) - now.jerk).norm() < 1e-5, "{kind:?} jerk at {t}");
            }
        }
    }

    /// The Bernoulli lemniscate is flown at exactly v_d, within |x| ≤ ℓ/(2√2) and |y| ≤ ℓ
    /// (before the tilt), and starts at R_x(φ)(0, 0, −ℓ). The printed one's speed varies.
    #[test]
    fn lemniscate_speed_and_extent() {
        let mut r = Reference::new(&section(Kind::Lemniscate));
        let start = r.at(0.0).p;
        let phi = (-10f64).to_radians();
        assert!((start - Vector3::new(0.0, -1.2 * phi.sin(), -1.2 * phi.cos())).norm() < 1e-12);
        let untilt = r.tilt.transpose();
        let (mut x_max, mut y_max) = (0.0f64, 0.0f64);
        for i in 0..2000 {
            let point = r.at(i as f64 * 0.005);
            assert!((point.v.norm() - 0.8).abs() < 1e-9, "speed {}", point.v.norm());
            let flat = untilt * point.p;
            x_max = x_max.max(flat.x.abs());
            y_max = y_max.max(flat.y.abs());
        }
        assert!((x_max - 1.2 / 8f64.sqrt()).abs() < 1e-4 && (y_max - 1.2).abs() < 1e-4, "{x_max}, {y_max}");

        let mut printed = Reference::new(&section(Kind::LemniscatePrinted));
        let speeds: Vec<f64> = (0..2000).map(|i| printed.at(i as f64 * 0.005).v.norm()).collect();
        let (lo, hi) = speeds.iter().fold((f64::MAX, 0.0f64), |(lo, hi), s| (lo.min(*s), hi.max(*s)));
        assert!(lo < 0.1 && hi > 1.2, "printed lemniscate speed {lo}..{hi}");
    }
}
