//! The reference x, y, z, ψ with derivatives to the fourth order. The paper publishes none
//! so this stand-in is a start point plus smooth moves, each a ninth-degree
//! polynomial step whose first four derivatives vanish at both ends, so the reference is C⁴
//! (the inner loop feeds forward z⁽⁴⁾ and ψ⁽⁴⁾).

use serde::Deserialize;

use crate::model::reference::Reference as ReferenceTrait;

/// x, y, z, ψ.
pub const AXES: usize = 4;
/// The value and four derivatives.
pub const ORDERS: usize = 5;

/// `[reference]`: where it starts and the moves on each axis, each `[at_s, duration_s, by]`.
#[derive(Debug, Clone, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct ReferenceSection {
    /// x, y, z in m and ψ in rad at t = 0.
    pub start: [f64; AXES],
    pub x_moves: Vec<[f64; 3]>,
    pub y_moves: Vec<[f64; 3]>,
    pub z_moves: Vec<[f64; 3]>,
    pub psi_moves: Vec<[f64; 3]>,
}

impl ReferenceSection {
    pub fn moves(&self) -> [(&'static str, &[[f64; 3]]); AXES] {
        [
            ("x_moves", &self.x_moves),
            ("y_moves", &self.y_moves),
            ("z_moves", &self.z_moves),
            ("psi_moves", &self.psi_moves),
        ]
    }
}

/// The reference at one instant: `p[axis][order]`, axis x, y, z, ψ; order 0 is the value.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Point {
    pub p: [[f64; ORDERS]; AXES],
}

#[derive(Debug, Clone)]
pub struct TiltReference {
    section: ReferenceSection,
}

/// s(τ) = 126τ⁵ − 420τ⁶ + 540τ⁷ − 315τ⁸ + 70τ⁹ on [0, 1] and its derivatives in τ: 0 → 1 with
/// s′ … s⁗ = 0 at both ends.
fn smooth_step(tau: f64) -> [f64; ORDERS] {
    if tau <= 0.0 {
        return [0.0; ORDERS];
    }
    if tau >= 1.0 {
        return [1.0, 0.0, 0.0, 0.0, 0.0];
    }
    // Coefficients of τ⁵..τ⁹, differentiated term by term.
    let coefficients = [126.0, -420.0, 540.0, -315.0, 70.0];
    let mut out = [0.0; ORDERS];
    for (i, c) in coefficients.iter().enumerate() {
        let power = 5 + i as i32;
        let mut factor = *c;
        for (order, value) in out.iter_mut().enumerate() {
            *value += factor * tau.powi(power - order as i32);
            factor *= f64::from(power - order as i32);
        }
    }
    out
}

impl TiltReference {
    pub fn new(section: &ReferenceSection) -> Self {
        Self { section: section.clone() }
    }

    pub fn point(&self, t: f64) -> Point {
        let mut p = [[0.0; ORDERS]; AXES];
        for (axis, (_, moves)) in self.section.moves().iter().enumerate() {
            p[axis][0] = self.section.start[axis];
            for &[at, duration, by] in moves.iter() {
                let s = smooth_step((t - at) / duration);
                for (order, value) in s.iter().enumerate() {
                    p[axis][order] += by * value / duration.powi(order as i32);
                }
            }
        }
        Point { p }
    }
}

impl ReferenceTrait for TiltReference {
    type Point = Point;

    fn at(&mut self, t: f64) -> Point {
        self.point(t)
    }

    /// ‖ξ − ξ_ref‖, m.
    fn error(&mut self, t: f64, x: &[f64]) -> f64 {
        let p = self.point(t).p;
        ((x[0] - p[0][0]).powi(2) + (x[1] - p[1][0]).powi(2) + (x[2] - p[2][0]).powi(2)).sqrt()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn section() -> ReferenceSection {
        ReferenceSection {
            start: [0.0, 0.0, 1.0, 0.0],
            x_moves: vec![[1.0, 4.0, 3.0], [8.0, 2.0, -1.0]],
            y_moves: vec![],
            z_moves: vec![[0.5, 3.0, 1.0]],
            psi_moves: vec![[2.0, 5.0, 0.785]],
        }
    }

    #[test]
    fn each_derivative_is_the_slope_of_the_one_before() {
        let r = TiltReference::new(&section());
        let h = 1e-5;
        for t in [0.7, 1.3, 2.9, 4.2, 8.5, 9.9] {
            let (a, b, mid) = (r.point(t - h).p, r.point(t + h).p, r.point(t).p);
            for axis in 0..AXES {
                for order in 0..ORDERS - 1 {
                    let slope = (b[axis][order] - a[axis][order]) / (2.0 * h);
                    let scale = 1.0 + mid[axis][order + 1].abs();
                    assert!((slope - mid[axis][order + 1]).abs() < 1e-5 * scale, "t {t} axis {axis} order {order}");
                }
            }
        }
    }

    #[test]
    fn moves_start_and_end_at_rest_and_add_up() {
        let r = TiltReference::new(&section());
        let end = r.point(20.0).p;
        assert_eq!(end[0], [2.0, 0.0, 0.0, 0.0, 0.0]);
        assert_eq!(end[2], [2.0, 0.0, 0.0, 0.0, 0.0]);
        // C⁴: every derivative is continuous at the ends of a move, and zero there.
        for t in [1.0, 5.0] {
            for order in 1..ORDERS {
                assert!(r.point(t + 1e-9).p[0][order].abs() < 1e-6, "t {t} order {order}");
            }
        }
        assert_eq!(r.point(0.0).p[3][0], 0.0);
    }
}
