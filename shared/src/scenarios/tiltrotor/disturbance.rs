//! The external force F_ext on x, y, z (N, in F), rows 1–3 of (24). The paper shows its
//! profiles only in Fig. 3, with no numbers, so this is a stand-in: steps,
//! which exercise the LKFUI's unknown input, plus smooth sin² pulses.

use std::f64::consts::PI;

use serde::Deserialize;

/// `[disturbance]`: the steps and pulses, summed.
#[derive(Debug, Clone, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct DisturbanceSection {
    /// Each [at_s, fx, fy, fz]: a step that adds this force (N, in F) from at_s on.
    pub steps: Vec<[f64; 4]>,
    /// Each [at_s, duration_s, fx, fy, fz]: a smooth pulse (sin² shape, so C¹) peaking at this
    /// force at at_s + duration_s/2, zero outside [at_s, at_s + duration_s].
    pub pulses: Vec<[f64; 5]>,
}

/// sin²(π s) on [0, 1], else 0: 0 with zero slope at both ends, 1 at s = ½.
fn pulse_shape(s: f64) -> f64 {
    if s <= 0.0 || s >= 1.0 {
        return 0.0;
    }
    let sine = (PI * s).sin();
    sine * sine
}

fn is_zero(force: &[f64]) -> bool {
    force.iter().all(|f| *f == 0.0)
}

impl DisturbanceSection {
    /// The summed force at time t. A step is on from its at_s (inclusive). A pulse with a
    /// duration of 0 or less adds nothing (the launch file's check should refuse one).
    pub fn force(&self, t: f64) -> [f64; 3] {
        let mut out = [0.0; 3];
        for [at, fx, fy, fz] in &self.steps {
            if t >= *at {
                out = [out[0] + fx, out[1] + fy, out[2] + fz];
            }
        }
        for [at, duration, fx, fy, fz] in &self.pulses {
            if *duration > 0.0 {
                let shape = pulse_shape((t - at) / duration);
                out = [out[0] + shape * fx, out[1] + shape * fy, out[2] + shape * fz];
            }
        }
        out
    }

    /// True when the force on every axis is the same at every instant of [from, to]: no step
    /// with a nonzero force starts in (from, to] and no nonzero pulse is nonzero anywhere
    /// inside. Conservative: steps that cancel each other at the same instant still count as a
    /// change. An empty interval (to < from) is constant.
    pub fn is_constant_over(&self, from: f64, to: f64) -> bool {
        if to <= from {
            return true;
        }
        let step_inside = self.steps.iter().any(|[at, force @ ..]| *at > from && *at <= to && !is_zero(force));
        // A pulse is nonzero exactly on the open (at, at + duration).
        let pulse_inside = self
            .pulses
            .iter()
            .any(|[at, duration, force @ ..]| *duration > 0.0 && *at < to && at + duration > from && !is_zero(force));
        !step_inside && !pulse_inside
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn section() -> DisturbanceSection {
        DisturbanceSection {
            steps: vec![[2.0, 1.0, 0.0, -0.5], [5.0, 0.0, 0.25, 1.5]],
            pulses: vec![[10.0, 4.0, 0.0, 2.0, 0.0]],
        }
    }

    #[test]
    fn steps_add_from_their_instant_on() {
        let d = section();
        assert_eq!(d.force(0.0), [0.0, 0.0, 0.0]);
        assert_eq!(d.force(1.999), [0.0, 0.0, 0.0]);
        assert_eq!(d.force(2.0), [1.0, 0.0, -0.5]);
        assert_eq!(d.force(4.5), [1.0, 0.0, -0.5]);
        assert_eq!(d.force(5.0), [1.0, 0.25, 1.0]);
        assert_eq!(d.force(9.0), [1.0, 0.25, 1.0]);
    }

    #[test]
    fn pulse_peaks_midway_and_vanishes_outside_its_support() {
        let d = DisturbanceSection { steps: vec![], pulses: vec![[10.0, 4.0, 0.0, 2.0, -1.0]] };
        assert_eq!(d.force(12.0), [0.0, 2.0, -1.0]);
        for t in [0.0, 9.0, 10.0, 14.0, 14.5, 100.0] {
            assert_eq!(d.force(t), [0.0, 0.0, 0.0], "t = {t}");
        }
        // sin²(π/4) = ½ a quarter of the way in; symmetric about the peak.
        let quarter = d.force(11.0);
        assert!((quarter[1] - 1.0).abs() < 1e-15 && (quarter[2] + 0.5).abs() < 1e-15);
        let (before, after) = (d.force(11.0), d.force(13.0));
        assert!((0..3).all(|i| (before[i] - after[i]).abs() < 1e-15));
        // Strictly inside, it is nonzero; the peak is the largest value.
        for i in 1..400 {
            let f = d.force(10.0 + 0.01 * f64::from(i))[1];
            assert!(f > 0.0 && f <= 2.0);
        }
    }

    #[test]
    fn pulse_is_smooth_at_its_ends() {
        // sin² leaves its ends with zero slope: the force one small h inside is O(h²).
        let d = DisturbanceSection { steps: vec![], pulses: vec![[1.0, 2.0, 3.0, 0.0, 0.0]] };
        let h = 1e-4;
        let expected = 3.0 * (PI * h / 2.0).sin().powi(2);
        assert!((d.force(1.0 + h)[0] - expected).abs() < 1e-15);
        assert!((d.force(3.0 - h)[0] - expected).abs() < 1e-12);
        assert!(d.force(1.0 + h)[0] < 1e-7);
    }

    #[test]
    fn steps_and_pulses_sum() {
        let d = section();
        assert_eq!(d.force(12.0), [1.0, 2.25, 1.0]);
        assert_eq!(d.force(20.0), [1.0, 0.25, 1.0]);
    }

    #[test]
    fn constant_between_changes() {
        let d = section();
        assert!(d.is_constant_over(0.0, 1.9));
        assert!(d.is_constant_over(2.0, 4.9));
        // The force at `from` is already the stepped one, so a step at `from` changes nothing.
        assert!(d.is_constant_over(5.0, 10.0));
        assert!(d.is_constant_over(14.0, 60.0));
        assert!(d.is_constant_over(3.0, 3.0));
    }

    #[test]
    fn not_constant_across_a_step_or_a_pulse() {
        let d = section();
        assert!(!d.is_constant_over(0.0, 2.0));
        assert!(!d.is_constant_over(4.0, 6.0));
        assert!(!d.is_constant_over(9.0, 10.5));
        assert!(!d.is_constant_over(13.9, 20.0));
        assert!(!d.is_constant_over(11.0, 12.0));
        assert!(!d.is_constant_over(0.0, 60.0));
    }

    #[test]
    fn zero_forces_do_not_count_as_changes() {
        let d = DisturbanceSection { steps: vec![[2.0, 0.0, 0.0, 0.0]], pulses: vec![[3.0, 1.0, 0.0, 0.0, 0.0]] };
        assert!(d.is_constant_over(0.0, 10.0));
        assert_eq!(d.force(3.5), [0.0, 0.0, 0.0]);
    }
}
