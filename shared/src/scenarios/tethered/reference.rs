//! The references of section VI: smooth steps from one constant to another over a transition of
//! D seconds (7, 5 or 3 s in the paper), in three phases: constant (the observer converges),
//! the transition, constant again. The paper gives no formula; these are our
//! polynomials, with exactly as many continuous derivatives as each output needs (Table I):
//!
//! - C²: s(τ) = 10τ³ − 15τ⁴ + 6τ⁵ (ϑ_d of Γa′, f_Ld of Γb);
//! - C³: 35τ⁴ − 84τ⁵ + 70τ⁶ − 20τ⁷ (ϕ_d of Γa′);
//! - C⁴: 126τ⁵ − 420τ⁶ + 540τ⁷ − 315τ⁸ + 70τ⁹ (ϕ_d of Γb).
//!
//! The error of section VI-B, e_track = |y₁d − y₁|/|y₁d| + |y₂d − y₂|/|y₂d|, is computed here
//! too, so that the metrics and the fault reports judge exactly what the controller tracks.

use serde::Deserialize;

use super::law::Law;
use super::state;
use crate::model::reference::Reference;

/// `[reference]`.
#[derive(Debug, Clone, Copy, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct ReferenceSection {
    /// Phase 1, constant reference, s.
    pub phase1_s: f64,
    /// D, the transition (phase 2), s. Phase 3 is the rest of the run.
    pub transition_s: f64,
    pub gamma_a: GammaAReference,
    pub gamma_b: GammaBReference,
}

/// Γa′ tracks ϕ and ϑ.
#[derive(Debug, Clone, Copy, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct GammaAReference {
    /// ϕ_d from, to, degrees.
    pub phi_deg: [f64; 2],
    /// ϑ_d from, to, degrees.
    pub theta_deg: [f64; 2],
}

/// Γb tracks ϕ and the link force f_L.
#[derive(Debug, Clone, Copy, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct GammaBReference {
    pub phi_deg: [f64; 2],
    /// f_Ld from, to, N.
    pub link_force_n: [f64; 2],
}

/// y(t) = y₀ + (y_f − y₀)·s((t − t₀)/D), s a polynomial in τ ∈ [0, 1], constant outside.
#[derive(Debug, Clone, Copy)]
pub struct SmoothStep {
    from: f64,
    to: f64,
    start: f64,
    duration: f64,
    /// s(τ) = Σ cₖ τᵏ.
    coefficients: [f64; 10],
}

impl SmoothStep {
    /// A step whose first `continuity` derivatives are continuous (2, 3 or 4).
    pub fn new(from: f64, to: f64, start: f64, duration: f64, continuity: usize) -> Self {
        let coefficients = match continuity {
            2 => [0.0, 0.0, 0.0, 10.0, -15.0, 6.0, 0.0, 0.0, 0.0, 0.0],
            3 => [0.0, 0.0, 0.0, 0.0, 35.0, -84.0, 70.0, -20.0, 0.0, 0.0],
            4 => [0.0, 0.0, 0.0, 0.0, 0.0, 126.0, -420.0, 540.0, -315.0, 70.0],
            _ => panic!("no smooth step of continuity {continuity}"),
        };
        Self { from, to, start, duration, coefficients }
    }

    /// y and its first N − 1 time derivatives at t.
    pub fn at<const N: usize>(&self, t: f64) -> [f64; N] {
        let tau = (t - self.start) / self.duration;
        let mut out = [0.0; N];
        if tau <= 0.0 || tau >= 1.0 {
            out[0] = if tau <= 0.0 { self.from } else { self.to };
            return out;
        }
        let scale = self.to - self.from;
        for (n, value) in out.iter_mut().enumerate() {
            // dⁿs/dτⁿ = Σ cₖ k!/(k − n)! τ^(k−n), and each d/dt brings 1/D.
            let mut ds = 0.0;
            for (k, c) in self.coefficients.iter().enumerate().skip(n) {
                let falling: f64 = (k - n + 1..=k).map(|i| i as f64).product();
                ds += c * falling * tau.powi((k - n) as i32);
            }
            *value = scale * ds / self.duration.powi(n as i32);
        }
        out[0] += self.from;
        out
    }
}

/// The reference at one instant: ϕ_d to its fourth derivative, and the second output (ϑ_d in
/// rad for Γa′, f_Ld in N for Γb) to its second.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Point {
    pub phi: [f64; 5],
    pub second: [f64; 3],
}

#[derive(Debug, Clone, Copy)]
pub struct TetheredReference {
    law: Law,
    phi: SmoothStep,
    second: SmoothStep,
}

impl TetheredReference {
    pub fn new(section: &ReferenceSection, law: Law) -> Self {
        let (start, d) = (section.phase1_s, section.transition_s);
        let (phi, second) = match law {
            Law::GammaA => {
                let r = section.gamma_a;
                let [p0, p1] = r.phi_deg.map(f64::to_radians);
                let [t0, t1] = r.theta_deg.map(f64::to_radians);
                (SmoothStep::new(p0, p1, start, d, 3), SmoothStep::new(t0, t1, start, d, 2))
            }
            Law::GammaB => {
                let r = section.gamma_b;
                let [p0, p1] = r.phi_deg.map(f64::to_radians);
                let [f0, f1] = r.link_force_n;
                (SmoothStep::new(p0, p1, start, d, 4), SmoothStep::new(f0, f1, start, d, 2))
            }
        };
        Self { law, phi, second }
    }

    /// The second output of true state x: ϑ, or the link force f_L.
    pub fn second_output(&self, x: &[f64]) -> f64 {
        match self.law {
            Law::GammaA => x[state::THETA],
            Law::GammaB => x[state::LINK_FORCE],
        }
    }
}

impl Reference for TetheredReference {
    type Point = Point;

    fn at(&mut self, t: f64) -> Point {
        Point { phi: self.phi.at(t), second: self.second.at(t) }
    }

    /// e_track of section VI-B (relative, so dimensionless).
    fn error(&mut self, t: f64, x: &[f64]) -> f64 {
        let d = self.at(t);
        let relative = |want: f64, got: f64| (want - got).abs() / want.abs();
        relative(d.phi[0], x[state::PHI]) + relative(d.second[0], self.second_output(x))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Each step reaches its end, and its derivatives up to its continuity are continuous at
    /// both ends (zero there), the next one is not: exactly the smoothness Table I asks for.
    /// The derivatives match central differences of the step itself.
    #[test]
    fn the_steps_have_their_continuity_and_exact_derivatives() {
        for continuity in [2, 3, 4] {
            let s = SmoothStep::new(1.0, 3.0, 2.0, 5.0, continuity);
            assert_eq!(s.at::<1>(0.0), [1.0]);
            assert_eq!(s.at::<1>(7.5), [3.0]);
            let just_inside = s.at::<6>(2.0 + 1e-9);
            let mid = s.at::<6>(4.5);
            assert!((mid[0] - 2.0).abs() < 1e-12, "{mid:?}");
            for (n, derivative) in just_inside.iter().enumerate().take(continuity + 1).skip(1) {
                assert!(derivative.abs() < 1e-6, "C{continuity}: derivative {n} = {derivative} at the start");
            }
            let jump = just_inside[continuity + 1];
            assert!(jump.abs() > 1e-3, "C{continuity}: derivative {} is continuous too", continuity + 1);
            let h = 1e-4;
            for t in [2.3, 3.7, 5.1, 6.6] {
                let (lo, at, hi) = (s.at::<6>(t - h), s.at::<6>(t), s.at::<6>(t + h));
                for n in 0..5 {
                    let numeric = (hi[n] - lo[n]) / (2.0 * h);
                    assert!((numeric - at[n + 1]).abs() < 1e-5 * (1.0 + at[n + 1].abs()), "C{continuity} d{n} at {t}");
                }
            }
        }
    }
}
