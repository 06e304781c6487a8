//! Rotations (SO(3)) on nalgebra's `f64` matrices, written once for every scenario: the skew
//! matrix, exp and log, the projection back onto SO(3), and R stored row-major in a state
//! slice. The generic (dual-number) rotations of the tiltrotor's model are in `autodiff`.

use nalgebra::{Matrix3, Vector3};

/// Skew-symmetric matrix: S(x) y = x × y.
pub fn skew(x: &Vector3<f64>) -> Matrix3<f64> {
    x.cross_matrix()
}

/// exp(S(w)) by Rodrigues' formula.
pub fn exp_so3(w: &Vector3<f64>) -> Matrix3<f64> {
    let angle = w.norm();
    let s = w.cross_matrix();
    if angle < 1e-9 {
        return Matrix3::identity() + s + s * s * 0.5;
    }
    Matrix3::identity() + s * (angle.sin() / angle) + s * s * ((1.0 - angle.cos()) / (angle * angle))
}

/// The SO(3) logarithm as a rotation vector: log(R)^∨.
pub fn log_so3(r: &Matrix3<f64>) -> Vector3<f64> {
    let vee = Vector3::new(r[(2, 1)] - r[(1, 2)], r[(0, 2)] - r[(2, 0)], r[(1, 0)] - r[(0, 1)]);
    let cos = ((r.trace() - 1.0) / 2.0).clamp(-1.0, 1.0);
    let angle = cos.acos();
    if angle < 1e-8 { vee / 2.0 } else { vee * (angle / (2.0 * angle.sin())) }
}

/// The nearest rotation to an almost-orthonormal matrix (polar factor by Newton iteration,
/// which converges in one or two steps this close to SO(3)).
pub fn orthonormalise(r: &Matrix3<f64>) -> Matrix3<f64> {
    let mut q = *r;
    for _ in 0..3 {
        let inverse_t = q.try_inverse().map_or(q, |i| i.transpose());
        q = (q + inverse_t) * 0.5;
    }
    q
}

/// Row-major R from a state slice of nine, and back.
pub fn rotation(x: &[f64]) -> Matrix3<f64> {
    Matrix3::from_row_slice(x)
}

pub fn write_rotation(r: &Matrix3<f64>, out: &mut [f64]) {
    for i in 0..3 {
        for j in 0..3 {
            out[3 * i + j] = r[(i, j)];
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const VECTORS: [[f64; 3]; 4] = [[0.3, -0.2, 0.5], [1e-10, 0.0, 0.0], [0.0, 2.5, 1.0], [-1.0, 0.4, -2.0]];

    fn is_rotation(r: &Matrix3<f64>, tolerance: f64) -> bool {
        (r * r.transpose() - Matrix3::identity()).norm() < tolerance && (r.determinant() - 1.0).abs() < tolerance
    }

    #[test]
    fn skew_is_the_cross_product() {
        let (a, b) = (Vector3::new(1.0, -2.0, 0.5), Vector3::new(0.3, 0.1, -4.0));
        assert_eq!(skew(&a) * b, a.cross(&b));
        assert_eq!(skew(&a).transpose(), -skew(&a));
    }

    #[test]
    fn exp_is_nalgebras_rotation_and_log_inverts_it() {
        for w in VECTORS.map(Vector3::from) {
            let r = exp_so3(&w);
            let expected = nalgebra::Rotation3::from_scaled_axis(w).into_inner();
            assert!((r - expected).abs().max() < 1e-13, "{w}");
            assert!(is_rotation(&r, 1e-13), "{r}");
            assert!((log_so3(&r) - w).norm() < 1e-9, "{w}");
        }
    }

    #[test]
    fn exp_of_log_is_the_identity_map() {
        for w in VECTORS.map(Vector3::from) {
            let r = nalgebra::Rotation3::from_scaled_axis(w).into_inner();
            assert!((exp_so3(&log_so3(&r)) - r).abs().max() < 1e-12, "{r}");
        }
    }

    #[test]
    fn orthonormalise_projects_back_onto_so3() {
        let r = exp_so3(&Vector3::new(0.3, -0.2, 0.5));
        let perturbed = r + Matrix3::new(1e-4, -2e-4, 0.0, 3e-4, 0.0, 1e-4, 0.0, -1e-4, 2e-4);
        assert!(!is_rotation(&perturbed, 1e-6));
        let q = orthonormalise(&perturbed);
        assert!(is_rotation(&q, 1e-14), "{q}");
        assert!((q - r).abs().max() < 1e-3);
        // A rotation is a fixed point.
        assert!((orthonormalise(&r) - r).abs().max() < 1e-15);
    }

    #[test]
    fn rotation_is_row_major_and_write_rotation_inverts_it() {
        let x = [1.0, 2.0, 3.0, 4.0, 5.0, 6.0, 7.0, 8.0, 9.0];
        let r = rotation(&x);
        assert_eq!((r[(0, 1)], r[(1, 0)], r[(2, 2)]), (2.0, 4.0, 9.0));
        let mut out = [0.0; 9];
        write_rotation(&r, &mut out);
        assert_eq!(out, x);
    }
}
