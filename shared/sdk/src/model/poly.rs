//! Small scalar helpers the scenarios share: the monic polynomial with given roots (pole
//! placement's coefficients) and angle wrapping.

use std::f64::consts::{PI, TAU};

/// Π(s − rᵢ) = sᴺ + c_(N−1)s^(N−1) + … + c₀ (any degree N): the coefficients [c₀ … c_(N−1)],
/// lowest first, without the leading 1.
pub fn coefficients_of_roots(roots: &[f64]) -> Vec<f64> {
    // Multiply out with the highest power last: p = [1] then p ← p·(s − r).
    let mut p = vec![1.0];
    for r in roots {
        let mut next = vec![0.0; p.len() + 1];
        for (i, c) in p.iter().enumerate() {
            next[i + 1] += c;
            next[i] -= r * c;
        }
        p = next;
    }
    p.pop();
    p
}

/// The angle in [0, 2π).
pub fn wrap_to_turn(angle: f64) -> f64 {
    angle.rem_euclid(TAU)
}

/// The angle in (−π, π].
pub fn wrap(angle: f64) -> f64 {
    let a = wrap_to_turn(angle + PI) - PI;
    if a == -PI { PI } else { a }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn coefficients_multiply_out_the_roots() {
        // (s + 6)(s + 4.5)(s + 3) = s³ + 13.5s² + 58.5s + 81.
        assert_eq!(coefficients_of_roots(&[-6.0, -4.5, -3.0]), [81.0, 58.5, 13.5]);
        assert_eq!(coefficients_of_roots(&[-1.0, -1.5, -2.0, -2.5]), [7.5, 19.25, 17.75, 7.0]);
        // (s − 2)(s + 3) = s² + s − 6; no roots is the constant 1.
        assert_eq!(coefficients_of_roots(&[2.0, -3.0]), [-6.0, 1.0]);
        assert!(coefficients_of_roots(&[]).is_empty());
    }

    #[test]
    fn angles_wrap_into_minus_pi_to_pi() {
        for (a, w) in [(0.5, 0.5), (PI, PI), (-PI, PI), (3.0 * PI / 2.0, -PI / 2.0), (-7.0, -7.0 + 2.0 * PI)] {
            assert!((wrap(a) - w).abs() < 1e-12, "{a} → {}", wrap(a));
        }
    }

    #[test]
    fn angles_wrap_into_one_turn() {
        for (a, w) in [(0.5, 0.5), (TAU, 0.0), (-PI / 2.0, 3.0 * PI / 2.0), (7.0, 7.0 - TAU), (0.0, 0.0)] {
            assert!((wrap_to_turn(a) - w).abs() < 1e-12, "{a} → {}", wrap_to_turn(a));
        }
    }
}
