//! Hinges about different anchors (MuJoCo composes the joints of one body in sequence, each
//! rotating the body about its own anchor `p_i`, body frame).
//!
//! With the joint anchored at the first hinge on the parent and at the last hinge on the child,
//! the anchor displacement in the joint frame is no longer zero but a function of the rotation:
//! ```text
//! g = Σ_{i≥2} Q₁…Q_{i-1} (p_i - p_{i-1}),   Q_i = rotation about a_i by θ_i
//! ```
//! and the translational constraint is `Δ - g(q_joint) = 0` (Δ: measured anchor displacement).
//! Two hinges use an exact polynomial form in `R_j` (no angles): with
//! `d = c₀ a1 + c₁ a2 + c₂ a1×a2`, `Q₁ d = c₀ a1 + c₁ u + c₂ a1×u`, `u = R_j a2 = Q₁ a2`.
//! Three hinges go through the angle chart ([`super::hinges::hinges3_angles`]).
use nalgebra::{Matrix3, Vector3};

use super::{RotDofs, hinges};
use crate::math::quat::{self, Quat};
use crate::math::spatial::skew;

/// Coefficients `c` of `d` in the basis `[a1, a2, a1×a2]` (a1, a2 not parallel).
fn coefficients(a1: &Vector3<f64>, a2: &Vector3<f64>, d: &Vector3<f64>) -> Vector3<f64> {
    let m = Matrix3::from_columns(&[*a1, *a2, a1.cross(a2)]);
    m.try_inverse().map_or(Vector3::zeros(), |inv| inv * d)
}

/// `g(q_joint)` and `∂g/∂δφ_c` (child-frame rotation perturbation), joint frame. The parent's
/// is `-∂g/∂δφ_c R_jᵀ R_offᵀ` (g depends on the relative rotation only).
pub fn displacement(
    rot: &RotDofs,
    offsets: &[Vector3<f64>],
    qj: &Quat,
    rot_j: &Matrix3<f64>,
) -> (Vector3<f64>, Matrix3<f64>) {
    match (rot, offsets) {
        (RotDofs::Universal { a1, a2 }, [d]) => {
            let c = coefficients(a1, a2, d);
            let u = rot_j * a2;
            let g = a1 * c[0] + u * c[1] + a1.cross(&u) * c[2];
            // du = -R_j skew(a2) δφ_c
            let dg_du = Matrix3::identity() * c[1] + skew(a1) * c[2];
            (g, -dg_du * rot_j * skew(a2))
        }
        (RotDofs::Hinges3 { axes }, [_, _]) => {
            let theta = hinges::hinges3_angles(axes, qj);
            let (g, dg_dtheta) = displacement_at_angles(rot, offsets, &theta);
            let s = hinges::hinges3_subspace(axes, &theta);
            let s_inv = s.try_inverse().unwrap_or_else(|| s.transpose());
            (g, Matrix3::from_columns(&dg_dtheta) * s_inv)
        }
        _ => (Vector3::zeros(), Matrix3::zeros()),
    }
}

/// `g(θ)` and `∂g/∂θ_i` (columns) from the hinge angles (forward kinematics).
pub fn displacement_at_angles(
    rot: &RotDofs,
    offsets: &[Vector3<f64>],
    theta: &[f64],
) -> (Vector3<f64>, [Vector3<f64>; 3]) {
    let zero = Vector3::zeros();
    match (rot, offsets) {
        (RotDofs::Universal { a1, .. }, [d]) => {
            let g = quat::rotation(&quat::axis_angle(a1, theta[0])) * d;
            (g, [a1.cross(&g), zero, zero])
        }
        (RotDofs::Hinges3 { axes }, [d12, d23]) => {
            let q1 = quat::rotation(&quat::axis_angle(&axes[0], theta[0]));
            let q2 = quat::rotation(&quat::axis_angle(&axes[1], theta[1]));
            let g = q1 * d12 + q1 * q2 * d23;
            (
                g,
                [axes[0].cross(&g), q1 * axes[1].cross(&(q2 * d23)), zero],
            )
        }
        _ => (zero, [zero; 3]),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn dofs() -> Vec<(RotDofs, Vec<Vector3<f64>>)> {
        let n = |x: f64, y: f64, z: f64| Vector3::new(x, y, z).normalize();
        vec![
            (
                RotDofs::Universal {
                    a1: Vector3::y(),
                    a2: n(1.0, 0.0, 0.5),
                },
                vec![Vector3::new(0.0, 0.0, -0.04)],
            ),
            (
                RotDofs::Hinges3 {
                    axes: [n(2.0, 1.0, 1.0), n(0.0, -1.0, 1.0), n(1.0, 0.3, -0.2)],
                },
                vec![Vector3::new(0.1, -0.2, 0.05), Vector3::new(-0.03, 0.0, 0.2)],
            ),
        ]
    }

    fn rotation_of(rot: &RotDofs, theta: &[f64]) -> Quat {
        super::super::geometry::joint_rotation(rot, theta)
    }

    #[test]
    fn rotation_form_equals_angle_form() {
        for (rot, off) in dofs() {
            let theta = [0.4, -0.9, 1.1];
            let qj = rotation_of(&rot, &theta);
            let (g, _) = displacement(&rot, &off, &qj, &quat::rotation(&qj));
            let (g2, _) = displacement_at_angles(&rot, &off, &theta);
            assert!((g - g2).norm() < 1e-12, "{g} vs {g2}");
        }
    }

    #[test]
    fn child_jacobian_matches_central_differences() {
        for (rot, off) in dofs() {
            let qj = rotation_of(&rot, &[0.3, 0.7, -0.5]);
            let (_, jac) = displacement(&rot, &off, &qj, &quat::rotation(&qj));
            let eps = 1e-6;
            for i in 0..3 {
                let dir = Vector3::ith(i, 1.0);
                let f = |s: f64| {
                    let q = qj * quat::step_map(&(dir * s), 1.0);
                    displacement(&rot, &off, &q, &quat::rotation(&q)).0
                };
                let fd = (f(eps) - f(-eps)) / (2.0 * eps);
                assert!((fd - jac * dir).norm() < 1e-7, "{i}: {fd} vs {}", jac * dir);
            }
        }
    }
}
