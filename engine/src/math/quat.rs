//! Quaternion algebra of Dojo's Appendix A, `(w, x, y, z)` order at every boundary.
//!
//! `L(q)` and `R(q)` are the left and right multiplication matrices (eqs. 59-61):
//! `a ⊗ b = L(a) b = R(b) a`. A body-frame attitude perturbation `δφ` acts as `q ⊗ [1, δφ/2]`.
//! The integrator's step map (eq. 18) is `q_next = q ⊗ [sqrt(1 - |hω/2|²), hω/2]`.
use nalgebra::{Matrix3, Matrix3x4, Matrix4, Matrix4x3, Quaternion, Vector3, Vector4};

use super::spatial::skew;

/// A quaternion; nalgebra stores it as `[i, j, k, w]`, convert with [`wxyz`] / [`from_wxyz`].
pub type Quat = Quaternion<f64>;

/// Coordinates in `(w, x, y, z)` order.
pub fn wxyz(q: &Quat) -> Vector4<f64> {
    Vector4::new(q.w, q.i, q.j, q.k)
}

/// Quaternion from `(w, x, y, z)` coordinates.
pub fn from_wxyz(v: &[f64]) -> Quat {
    Quaternion::new(v[0], v[1], v[2], v[3])
}

/// Identity rotation.
pub fn identity() -> Quat {
    Quaternion::new(1.0, 0.0, 0.0, 0.0)
}

/// Vector part `V q` (eq. 64).
pub fn vec(q: &Quat) -> Vector3<f64> {
    Vector3::new(q.i, q.j, q.k)
}

/// Conjugate `q†` (eq. 66); the inverse of a unit quaternion.
pub fn conj(q: &Quat) -> Quat {
    Quaternion::new(q.w, -q.i, -q.j, -q.k)
}

/// `L(q)`, eq. (60): `q ⊗ p = L(q) p`.
pub fn lmat(q: &Quat) -> Matrix4<f64> {
    let (s, v) = (q.w, vec(q));
    let b = Matrix3::identity() * s + skew(&v);
    lr_matrix(s, &v, &b)
}

/// `R(q)`, eq. (61): `p ⊗ q = R(q) p`.
pub fn rmat(q: &Quat) -> Matrix4<f64> {
    let (s, v) = (q.w, vec(q));
    let b = Matrix3::identity() * s - skew(&v);
    lr_matrix(s, &v, &b)
}

fn lr_matrix(s: f64, v: &Vector3<f64>, b: &Matrix3<f64>) -> Matrix4<f64> {
    let mut m = Matrix4::zeros();
    m[(0, 0)] = s;
    for i in 0..3 {
        m[(0, i + 1)] = -v[i];
        m[(i + 1, 0)] = v[i];
        for j in 0..3 {
            m[(i + 1, j + 1)] = b[(i, j)];
        }
    }
    m
}

/// `Vᵀ`: embeds a 3-vector as a pure quaternion (eq. 65).
pub fn vt() -> Matrix4x3<f64> {
    let mut m = Matrix4x3::zeros();
    m[(1, 0)] = 1.0;
    m[(2, 1)] = 1.0;
    m[(3, 2)] = 1.0;
    m
}

/// `V`: extracts the vector part (eq. 65).
pub fn v() -> Matrix3x4<f64> {
    vt().transpose()
}

/// Rotation matrix of a unit quaternion (body to world).
pub fn rotation(q: &Quat) -> Matrix3<f64> {
    let (w, x, y, z) = (q.w, q.i, q.j, q.k);
    Matrix3::new(
        1.0 - 2.0 * (y * y + z * z),
        2.0 * (x * y - w * z),
        2.0 * (x * z + w * y),
        2.0 * (x * y + w * z),
        1.0 - 2.0 * (x * x + z * z),
        2.0 * (y * z - w * x),
        2.0 * (x * z - w * y),
        2.0 * (y * z + w * x),
        1.0 - 2.0 * (x * x + y * y),
    )
}

/// Rotation by `angle` (rad) about the unit `axis`.
pub fn axis_angle(axis: &Vector3<f64>, angle: f64) -> Quat {
    let (s, c) = (0.5 * angle).sin_cos();
    Quaternion::new(c, s * axis[0], s * axis[1], s * axis[2])
}

/// Rotation vector (log map) of a unit quaternion, with `w ≥ 0` chosen so the angle is in [0, π].
pub fn rotation_vector(q: &Quat) -> Vector3<f64> {
    let (w, v) = if q.w < 0.0 {
        (-q.w, -vec(q))
    } else {
        (q.w, vec(q))
    };
    let s = v.norm();
    if s < 1e-12 {
        // angle ≈ 2 s, direction v / s: first-order series of 2 atan2(s, w) v / s
        return v * (2.0 / w.max(1e-300));
    }
    v * (2.0 * s.atan2(w) / s)
}

/// Largest angular speed the step map (eq. 18) can represent at time step `h`: `|ω| < 2/h`.
pub fn max_angular_speed(h: f64) -> f64 {
    2.0 / h
}

/// Step map `f(ω) = [sqrt(1 - |hω/2|²), hω/2]` of eq. (18); `q_next = q ⊗ f(ω)`.
///
/// The caller keeps `|ω| < 2/h` (the solver clamps); outside it the scalar part is clamped at 0.
pub fn step_map(omega: &Vector3<f64>, h: f64) -> Quat {
    let half = omega * (0.5 * h);
    let c = (1.0 - half.norm_squared()).max(0.0).sqrt();
    Quaternion::new(c, half[0], half[1], half[2])
}

/// `∂φ/∂ω`: the body-frame attitude perturbation of `q_next = q ⊗ f(ω)` per change of `ω`.
///
/// `q_next ⊗ [1, δφ/2] = q ⊗ f(ω + δω)` gives `δφ = 2 V L(f)ᵀ (∂f/∂ω) δω`, which equals
/// `c h I - (h²/2) skew(ω) + (h³/4c) ω ωᵀ` with `c = sqrt(1 - |hω/2|²)`.
pub fn step_map_dphi_domega(omega: &Vector3<f64>, h: f64) -> Matrix3<f64> {
    let c = (1.0 - (omega * (0.5 * h)).norm_squared())
        .max(1e-300)
        .sqrt();
    Matrix3::identity() * (c * h) - skew(omega) * (0.5 * h * h)
        + omega * omega.transpose() * (h * h * h / (4.0 * c))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn q(w: f64, x: f64, y: f64, z: f64) -> Quat {
        Quaternion::new(w, x, y, z).normalize()
    }

    #[test]
    fn l_and_r_matrices_multiply() {
        let a = q(0.3, -0.2, 0.9, 0.1);
        let b = q(-0.5, 0.4, 0.2, 0.7);
        let ab = wxyz(&(a * b));
        assert!((lmat(&a) * wxyz(&b) - ab).norm() < 1e-15);
        assert!((rmat(&b) * wxyz(&a) - ab).norm() < 1e-15);
    }

    #[test]
    fn rotation_matches_nalgebra() {
        let a = q(0.3, -0.2, 0.9, 0.1);
        let u = nalgebra::UnitQuaternion::from_quaternion(a);
        assert!((rotation(&a) - u.to_rotation_matrix().into_inner()).norm() < 1e-14);
        let p = Vector3::new(0.1, 2.0, -1.0);
        // R(q) p = V (q ⊗ [0, p] ⊗ q†)
        let pq = Quaternion::new(0.0, p[0], p[1], p[2]);
        assert!((rotation(&a) * p - vec(&(a * pq * conj(&a)))).norm() < 1e-14);
    }

    #[test]
    fn rotation_vector_inverts_axis_angle() {
        let axis = Vector3::new(1.0, -2.0, 0.5).normalize();
        for angle in [1e-9, 0.3, 2.0, 3.1] {
            let r = rotation_vector(&axis_angle(&axis, angle));
            assert!((r - axis * angle).norm() < 1e-12, "{angle}");
        }
    }

    #[test]
    fn step_map_is_unit_and_derivative_matches_fd() {
        let h = 0.05;
        let w = Vector3::new(3.0, -5.0, 12.0);
        let f = step_map(&w, h);
        assert!((f.norm() - 1.0).abs() < 1e-15);
        let base = q(0.2, 0.5, -0.3, 0.8);
        let qn = base * f;
        let d = step_map_dphi_domega(&w, h);
        let eps = 1e-6;
        for i in 0..3 {
            let mut wp = w;
            wp[i] += eps;
            let mut wm = w;
            wm[i] -= eps;
            let dp = conj(&qn) * (base * step_map(&wp, h));
            let dm = conj(&qn) * (base * step_map(&wm, h));
            let fd = (vec(&dp) - vec(&dm)) * (2.0 / (2.0 * eps));
            assert!(
                (fd - d.column(i)).norm() < 1e-8,
                "column {i}: {fd} vs {}",
                d.column(i)
            );
        }
    }
}
