//! Numbers that carry derivatives, for models written once and differentiated exactly: a
//! [`Scalar`] is `f64` or a [`Dual`] (one directional derivative, forward mode). Code generic
//! over `Scalar` gives the value with `f64`, and ∂/∂qᵢ by seeding qᵢ's dual part with 1.
//! Also small generic 3-vector and 3×3 helpers, since nalgebra's types need `RealField`.

use std::fmt::Debug;
use std::ops::{Add, Div, Mul, Neg, Sub};

/// A real number a model can be evaluated with.
pub trait Scalar:
    Copy + Debug + Add<Output = Self> + Sub<Output = Self> + Mul<Output = Self> + Div<Output = Self> + Neg<Output = Self>
{
    /// A constant (no derivative).
    fn c(value: f64) -> Self;
    /// The value without its derivatives.
    fn value(self) -> f64;
    fn sin(self) -> Self;
    fn cos(self) -> Self;
    fn sqrt(self) -> Self;
    fn zero() -> Self {
        Self::c(0.0)
    }
    fn one() -> Self {
        Self::c(1.0)
    }
    /// `self · k` for a constant k.
    fn scale(self, k: f64) -> Self {
        self * Self::c(k)
    }
}

impl Scalar for f64 {
    fn c(value: f64) -> Self {
        value
    }
    fn value(self) -> f64 {
        self
    }
    fn sin(self) -> Self {
        f64::sin(self)
    }
    fn cos(self) -> Self {
        f64::cos(self)
    }
    fn sqrt(self) -> Self {
        f64::sqrt(self)
    }
    fn scale(self, k: f64) -> Self {
        self * k
    }
}

/// A value and its derivative along one direction: f(x + εv) = f(x) + ε f'(x)v.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Dual {
    pub v: f64,
    pub d: f64,
}

impl Dual {
    /// A variable: derivative 1 along itself.
    pub fn var(v: f64) -> Self {
        Dual { v, d: 1.0 }
    }
}

impl Add for Dual {
    type Output = Dual;
    fn add(self, o: Dual) -> Dual {
        Dual { v: self.v + o.v, d: self.d + o.d }
    }
}
impl Sub for Dual {
    type Output = Dual;
    fn sub(self, o: Dual) -> Dual {
        Dual { v: self.v - o.v, d: self.d - o.d }
    }
}
impl Mul for Dual {
    type Output = Dual;
    fn mul(self, o: Dual) -> Dual {
        Dual { v: self.v * o.v, d: self.d * o.v + self.v * o.d }
    }
}
impl Div for Dual {
    type Output = Dual;
    fn div(self, o: Dual) -> Dual {
        Dual { v: self.v / o.v, d: (self.d * o.v - self.v * o.d) / (o.v * o.v) }
    }
}
impl Neg for Dual {
    type Output = Dual;
    fn neg(self) -> Dual {
        Dual { v: -self.v, d: -self.d }
    }
}

impl Scalar for Dual {
    fn c(value: f64) -> Self {
        Dual { v: value, d: 0.0 }
    }
    fn value(self) -> f64 {
        self.v
    }
    fn sin(self) -> Self {
        Dual { v: self.v.sin(), d: self.d * self.v.cos() }
    }
    fn cos(self) -> Self {
        Dual { v: self.v.cos(), d: -self.d * self.v.sin() }
    }
    fn sqrt(self) -> Self {
        let r = self.v.sqrt();
        Dual { v: r, d: self.d / (2.0 * r) }
    }
    fn scale(self, k: f64) -> Self {
        Dual { v: self.v * k, d: self.d * k }
    }
}

pub type Vec3<S> = [S; 3];
/// Row-major: `m[row][column]`.
pub type Mat3<S> = [[S; 3]; 3];

pub fn vec3<S: Scalar>(v: [f64; 3]) -> Vec3<S> {
    v.map(S::c)
}

pub fn mat3<S: Scalar>(m: [[f64; 3]; 3]) -> Mat3<S> {
    m.map(|row| row.map(S::c))
}

pub fn identity<S: Scalar>() -> Mat3<S> {
    mat3([[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]])
}

pub fn add<S: Scalar>(a: Vec3<S>, b: Vec3<S>) -> Vec3<S> {
    [a[0] + b[0], a[1] + b[1], a[2] + b[2]]
}

pub fn scale<S: Scalar>(a: Vec3<S>, k: S) -> Vec3<S> {
    [a[0] * k, a[1] * k, a[2] * k]
}

pub fn dot<S: Scalar>(a: Vec3<S>, b: Vec3<S>) -> S {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

pub fn cross<S: Scalar>(a: Vec3<S>, b: Vec3<S>) -> Vec3<S> {
    [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]]
}

pub fn mat_vec<S: Scalar>(m: &Mat3<S>, v: Vec3<S>) -> Vec3<S> {
    [dot(m[0], v), dot(m[1], v), dot(m[2], v)]
}

pub fn transpose<S: Scalar>(m: &Mat3<S>) -> Mat3<S> {
    [[m[0][0], m[1][0], m[2][0]], [m[0][1], m[1][1], m[2][1]], [m[0][2], m[1][2], m[2][2]]]
}

pub fn mat_mul<S: Scalar>(a: &Mat3<S>, b: &Mat3<S>) -> Mat3<S> {
    let mut out = [[S::zero(); 3]; 3];
    for (i, row) in out.iter_mut().enumerate() {
        for (j, cell) in row.iter_mut().enumerate() {
            *cell = a[i][0] * b[0][j] + a[i][1] * b[1][j] + a[i][2] * b[2][j];
        }
    }
    out
}

pub fn mat_add<S: Scalar>(a: &Mat3<S>, b: &Mat3<S>) -> Mat3<S> {
    let mut out = *a;
    for (row, brow) in out.iter_mut().zip(b) {
        for (cell, bc) in row.iter_mut().zip(brow) {
            *cell = *cell + *bc;
        }
    }
    out
}

/// S(v): S(v)·w = v × w.
pub fn skew<S: Scalar>(v: Vec3<S>) -> Mat3<S> {
    let z = S::zero();
    [[z, -v[2], v[1]], [v[2], z, -v[0]], [-v[1], v[0], z]]
}

/// Rotation about x by `a`.
pub fn rot_x<S: Scalar>(a: S) -> Mat3<S> {
    let (s, c, z, o) = (a.sin(), a.cos(), S::zero(), S::one());
    [[o, z, z], [z, c, -s], [z, s, c]]
}

/// Rotation about y by `a`.
pub fn rot_y<S: Scalar>(a: S) -> Mat3<S> {
    let (s, c, z, o) = (a.sin(), a.cos(), S::zero(), S::one());
    [[c, z, s], [z, o, z], [-s, z, c]]
}

/// Rotation about z by `a`.
pub fn rot_z<S: Scalar>(a: S) -> Mat3<S> {
    let (s, c, z, o) = (a.sin(), a.cos(), S::zero(), S::one());
    [[c, -s, z], [s, c, z], [z, z, o]]
}

#[cfg(test)]
mod tests {
    use super::*;

    /// f(x) = sin(x)·cos(x)/√x + x², written once.
    fn f<S: Scalar>(x: S) -> S {
        x.sin() * x.cos() / x.sqrt() + x * x
    }

    #[test]
    fn the_dual_part_is_the_analytic_derivative() {
        let x = 0.7_f64;
        let analytic = (x.cos().powi(2) - x.sin().powi(2)) / x.sqrt() - 0.5 * x.sin() * x.cos() / x.powf(1.5) + 2.0 * x;
        let d = f(Dual::var(x));
        assert_eq!(d.v, f(x));
        assert!((d.d - analytic).abs() < 1e-14, "{} vs {analytic}", d.d);
    }

    #[test]
    fn rotations_compose_and_skew_is_the_cross_product() {
        let r = mat_mul(&rot_z(0.3), &mat_mul(&rot_y(-0.2), &rot_x(0.5)));
        let rrt = mat_mul(&r, &transpose(&r));
        for (i, row) in rrt.iter().enumerate() {
            for (j, v) in row.iter().enumerate() {
                assert!((v - if i == j { 1.0 } else { 0.0 }).abs() < 1e-15);
            }
        }
        let (a, b) = ([1.0, -2.0, 0.5], [0.3, 0.1, -4.0]);
        assert_eq!(mat_vec(&skew(a), b), cross(a, b));
    }
}
