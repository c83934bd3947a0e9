//! Spatial helpers: the skew map (Dojo eq. 62) and orthonormal frames built from an axis.
use nalgebra::{Matrix3, Vector3};

/// `skew(x) y = x × y` (Dojo eq. 62-63).
pub fn skew(x: &Vector3<f64>) -> Matrix3<f64> {
    Matrix3::new(0.0, -x[2], x[1], x[2], 0.0, -x[0], -x[1], x[0], 0.0)
}

/// Orthonormal basis `[a, b, c]` (columns) whose first column is the unit vector `a`.
///
/// `b` is the projection, orthogonal to `a`, of the coordinate axis least aligned with `a`
/// (x first on ties), and `c = a × b`. For `a = z` this gives `b = x`, `c = y`; for `a = x`,
/// `b = y`, `c = z`. Deterministic, so the planar and orbital coordinates it defines are stable.
pub fn basis_from_axis(a: &Vector3<f64>) -> Matrix3<f64> {
    let mut k = 0;
    for i in 1..3 {
        if a[i].abs() < a[k].abs() - 1e-12 {
            k = i;
        }
    }
    let e = Vector3::ith(k, 1.0);
    let b = (e - a * a.dot(&e)).normalize();
    let c = a.cross(&b);
    Matrix3::from_columns(&[*a, b, c])
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn skew_is_cross_product() {
        let x = Vector3::new(0.3, -1.2, 2.0);
        let y = Vector3::new(-0.7, 0.1, 0.5);
        assert!((skew(&x) * y - x.cross(&y)).norm() < 1e-15);
    }

    #[test]
    fn basis_is_orthonormal_and_right_handed() {
        for a in [
            Vector3::z(),
            Vector3::x(),
            Vector3::y(),
            Vector3::new(1.0, 2.0, -0.5).normalize(),
        ] {
            let m = basis_from_axis(&a);
            assert!((m.transpose() * m - Matrix3::identity()).norm() < 1e-14);
            assert!((m.determinant() - 1.0).abs() < 1e-14);
            assert!((m.column(0) - a).norm() < 1e-15);
        }
        let m = basis_from_axis(&Vector3::z());
        assert!((m.column(1) - Vector3::x()).norm() < 1e-15);
        assert!((m.column(2) - Vector3::y()).norm() < 1e-15);
    }
}
