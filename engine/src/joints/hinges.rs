//! Rotation charts of hinge sequences: two hinges with possibly non-orthogonal axes
//! (`RotDofs::Universal`) and three hinges (`RotDofs::Hinges3`), as MJCF writes them (a body with
//! several hinge joints about one point).
//!
//! `q_joint = q(a1, θ1) ⊗ q(a2, θ2) [⊗ q(a3, θ3)]`. The relative angular velocity in the child frame
//! is `ω_rel = S(θ) θ̇` with `S = [R₂ᵀ a1, a2]` or `[R₃ᵀR₂ᵀ a1, R₃ᵀ a2, a3]`; the angle rates are
//! `θ̇ = S⁺ ω_rel` (the left inverse, `S⁻¹` for three hinges).
use nalgebra::{Matrix3, Vector3};

use crate::math::quat::{self, Quat};

/// Angle that rotates `from` onto `to` about the unit `axis` (components along `axis` ignored).
pub fn angle_about(axis: &Vector3<f64>, from: &Vector3<f64>, to: &Vector3<f64>) -> f64 {
    let u = from - axis * axis.dot(from);
    let v = to - axis * axis.dot(to);
    axis.dot(&u.cross(&v)).atan2(u.dot(&v))
}

/// Angles `(θ1, θ2)` of two hinges about `a1` then `a2` from the joint rotation `rot_j`:
/// `R a2 = R₁ a2` and `Rᵀ a1 = R₂ᵀ a1` decouple the two angles.
pub fn universal_angles(a1: &Vector3<f64>, a2: &Vector3<f64>, rot_j: &Matrix3<f64>) -> [f64; 2] {
    [
        angle_about(a1, a2, &(rot_j * a2)),
        angle_about(a2, &(rot_j.transpose() * a1), a1),
    ]
}

/// Rotation `q(a1, θ1) ⊗ q(a2, θ2) ⊗ q(a3, θ3)`.
pub fn hinges3_rotation(axes: &[Vector3<f64>; 3], theta: &[f64]) -> Quat {
    quat::axis_angle(&axes[0], theta[0])
        * quat::axis_angle(&axes[1], theta[1])
        * quat::axis_angle(&axes[2], theta[2])
}

/// Motion subspace `S(θ)` (child frame, columns) of three hinges.
pub fn hinges3_subspace(axes: &[Vector3<f64>; 3], theta: &[f64]) -> Matrix3<f64> {
    let r2 = quat::rotation(&quat::axis_angle(&axes[1], theta[1]));
    let r3 = quat::rotation(&quat::axis_angle(&axes[2], theta[2]));
    Matrix3::from_columns(&[
        r3.transpose() * r2.transpose() * axes[0],
        r3.transpose() * axes[1],
        axes[2],
    ])
}

/// Closed-form angles of an orthogonal triad (`a1 ⟂ a2 ⟂ a3`, `a1 ⟂ a3`, `s = a1·(a2×a3) = ±1`),
/// with `θ2 ∈ [-π/2, π/2]`:
/// `sin θ2 = s a1ᵀRa3`, `tan θ1 = -s a2ᵀRa3 / a3ᵀRa3`, `tan θ3 = -s a2ᵀRᵀa1 / a1ᵀRᵀa1`.
/// For other triads it is only a starting guess.
fn triad_guess(axes: &[Vector3<f64>; 3], rot_j: &Matrix3<f64>) -> [f64; 3] {
    let [a1, a2, a3] = axes;
    let s = a1.dot(&a2.cross(a3)).signum();
    let ra3 = rot_j * a3;
    let rta1 = rot_j.transpose() * a1;
    [
        (-s * a2.dot(&ra3)).atan2(a3.dot(&ra3)),
        (s * a1.dot(&ra3)).clamp(-1.0, 1.0).asin(),
        (-s * a2.dot(&rta1)).atan2(a1.dot(&rta1)),
    ]
}

/// Angles of three hinges from `q_joint`: Newton's method on `rotvec(q(θ)† ⊗ q_joint) = 0`
/// (`δθ = S⁻¹ e`) from the orthogonal-triad formula and from zero; of the converged solutions the
/// one nearest zero is kept (a triad has two branches; non-orthogonal axes may have more). Never
/// panics; at a singular `S` it stops.
pub fn hinges3_angles(axes: &[Vector3<f64>; 3], qj: &Quat) -> [f64; 3] {
    let guess = triad_guess(axes, &quat::rotation(qj));
    let flipped = [
        guess[0] + std::f64::consts::PI,
        std::f64::consts::PI - guess[1],
        guess[2] + std::f64::consts::PI,
    ];
    exact_triad(axes, qj, guess, flipped)
        .unwrap_or_else(|| newton_branches(axes, qj, guess, flipped))
}

/// [`hinges3_angles`] by Newton's method from `guess`, zero and `flipped`.
fn newton_branches(
    axes: &[Vector3<f64>; 3],
    qj: &Quat,
    guess: [f64; 3],
    flipped: [f64; 3],
) -> [f64; 3] {
    let mut best: Option<([f64; 3], f64)> = None;
    for start in [guess, [0.0; 3], flipped] {
        if start.iter().any(|t| !t.is_finite()) {
            continue;
        }
        let (theta, err) = newton(axes, qj, start);
        let theta = theta.map(super::geometry::wrap_angle);
        let size: f64 = theta.iter().map(|t| t * t).sum();
        let better = match best {
            None => true,
            Some((b, e)) => {
                let bsize: f64 = b.iter().map(|t| t * t).sum();
                (err < 1e-10 && (e >= 1e-10 || size < bsize - 1e-12)) || (e >= 1e-10 && err < e)
            }
        };
        if better {
            best = Some((theta, err));
        }
    }
    best.map_or([0.0; 3], |(t, _)| t)
}

/// The branch of an orthonormal triad nearest zero, when the closed form is exact at `qj`.
///
/// Why: an orthonormal triad has exactly the two branches `guess` and `flipped`, where Newton's
/// method from any start ends, so [`hinges3_angles`] would pick the same one after three
/// Newton runs; the humanoid's hips and abdomen spent ~10% of a step there. Near gimbal lock
/// (`θ2 → ±π/2`, where `asin` loses accuracy and the branches merge) the check fails and the
/// Newton path decides.
fn exact_triad(
    axes: &[Vector3<f64>; 3],
    qj: &Quat,
    guess: [f64; 3],
    flipped: [f64; 3],
) -> Option<[f64; 3]> {
    const ORTHONORMAL: f64 = 1e-12;
    let [a1, a2, a3] = axes;
    let unit = |a: &Vector3<f64>| (a.norm_squared() - 1.0).abs() < ORTHONORMAL;
    let orthogonal = a1.dot(a2).abs() < ORTHONORMAL
        && a2.dot(a3).abs() < ORTHONORMAL
        && a1.dot(a3).abs() < ORTHONORMAL;
    if !(unit(a1) && unit(a2) && unit(a3) && orthogonal) || guess.iter().any(|t| !t.is_finite()) {
        return None;
    }
    let err = quat::rotation_vector(&(quat::conj(&hinges3_rotation(axes, &guess)) * qj)).norm();
    if err >= 1e-13 || (guess[1].abs() - std::f64::consts::FRAC_PI_2).abs() < 1e-6 {
        return None;
    }
    let (g, f) = (
        guess.map(super::geometry::wrap_angle),
        flipped.map(super::geometry::wrap_angle),
    );
    let size = |t: &[f64; 3]| t.iter().map(|t| t * t).sum::<f64>();
    // the tie rule of `hinges3_angles`: a later solution must be smaller by 1e-12
    Some(if size(&f) < size(&g) - 1e-12 { f } else { g })
}

/// Newton iterations from `theta`; returns the angles and the final rotation error (rad).
fn newton(axes: &[Vector3<f64>; 3], qj: &Quat, mut theta: [f64; 3]) -> ([f64; 3], f64) {
    let residual =
        |t: &[f64; 3]| quat::rotation_vector(&(quat::conj(&hinges3_rotation(axes, t)) * qj));
    let mut err = residual(&theta);
    for _ in 0..30 {
        if err.norm() < 1e-15 {
            break;
        }
        let Some(inv) = hinges3_subspace(axes, &theta).try_inverse() else {
            break;
        };
        let d = inv * err;
        if !d.iter().all(|x| x.is_finite()) {
            break;
        }
        // backtracking: accept the first step length that reduces the error
        let mut accepted = false;
        let mut alpha = 1.0;
        for _ in 0..12 {
            let mut trial = theta;
            for (t, dt) in trial.iter_mut().zip(d.iter()) {
                *t += alpha * dt;
            }
            let e = residual(&trial);
            if e.norm() < err.norm() {
                theta = trial;
                err = e;
                accepted = true;
                break;
            }
            alpha *= 0.5;
        }
        if !accepted {
            break;
        }
    }
    (theta, err.norm())
}

/// Rows of the left inverse `(SᵀS)⁻¹Sᵀ` of the columns `s` (1-3 of them), written to `out`.
/// Falls back to `Sᵀ` where `SᵀS` is singular (a gimbal lock), so it never fails.
pub fn left_inverse_rows(s: &[Vector3<f64>], out: &mut [Vector3<f64>]) {
    // (fixed sizes for the two- and three-hinge joints: no allocation in a residual evaluation;
    // nalgebra inverts 2×2 and 3×3 matrices in closed form at either size, so the bits agree)
    match s.len() {
        2 => left_inverse_sized::<2>(s, out),
        3 => left_inverse_sized::<3>(s, out),
        n => {
            let gram = nalgebra::DMatrix::<f64>::from_fn(n, n, |i, k| s[i].dot(&s[k]));
            rows_from_inverse(s, gram.try_inverse(), out);
        }
    }
}

fn left_inverse_sized<const N: usize>(s: &[Vector3<f64>], out: &mut [Vector3<f64>]) {
    let gram = nalgebra::SMatrix::<f64, N, N>::from_fn(|i, k| s[i].dot(&s[k]));
    rows_from_inverse(s, gram.try_inverse(), out);
}

/// Rows `Σ_k inv_ik s_k` of the left inverse, or `s` itself when the Gram matrix is singular.
fn rows_from_inverse<R, C, S>(
    s: &[Vector3<f64>],
    inv: Option<nalgebra::Matrix<f64, R, C, S>>,
    out: &mut [Vector3<f64>],
) where
    R: nalgebra::Dim,
    C: nalgebra::Dim,
    S: nalgebra::RawStorage<f64, R, C>,
{
    let n = s.len();
    match inv {
        Some(inv) => {
            for i in 0..n {
                out[i] = (0..n).map(|k| s[k] * inv[(i, k)]).sum();
            }
        }
        None => out[..n].copy_from_slice(s),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn axes() -> Vec<[Vector3<f64>; 3]> {
        let n = |x: f64, y: f64, z: f64| Vector3::new(x, y, z).normalize();
        vec![
            [Vector3::z(), Vector3::y(), Vector3::x()],
            [Vector3::x(), Vector3::z(), Vector3::y()],
            [-Vector3::x(), Vector3::z(), -Vector3::y()],
            [n(2.0, 1.0, 1.0), n(0.0, -1.0, 1.0), n(1.0, 0.3, -0.2)],
        ]
    }

    #[test]
    fn angles_invert_the_rotation() {
        for ax in axes() {
            for theta in [
                [0.3, -0.7, 1.2],
                [-2.5, 0.4, 3.0],
                [0.0, 0.0, 0.0],
                [1.0, 1.4, -0.1],
            ] {
                let q = hinges3_rotation(&ax, &theta);
                let back = hinges3_angles(&ax, &q);
                let q2 = hinges3_rotation(&ax, &back);
                // same rotation (possibly the other Euler branch)
                let e = quat::rotation_vector(&(quat::conj(&q2) * q)).norm();
                assert!(e < 1e-12, "{ax:?} {theta:?} -> {back:?}");
                if theta[1].abs() < 1.0 && theta.iter().all(|t| t.abs() < 1.3) {
                    for i in 0..3 {
                        assert!(
                            (back[i] - theta[i]).abs() < 1e-10,
                            "{ax:?} {theta:?} {back:?}"
                        );
                    }
                }
            }
        }
    }

    #[test]
    fn subspace_is_the_derivative_of_the_rotation() {
        for ax in axes() {
            let theta = [0.3, -0.5, 0.8];
            let s = hinges3_subspace(&ax, &theta);
            let q = hinges3_rotation(&ax, &theta);
            let eps = 1e-6;
            for i in 0..3 {
                let (mut tp, mut tm) = (theta, theta);
                tp[i] += eps;
                tm[i] -= eps;
                let dp = quat::rotation_vector(&(quat::conj(&q) * hinges3_rotation(&ax, &tp)));
                let dm = quat::rotation_vector(&(quat::conj(&q) * hinges3_rotation(&ax, &tm)));
                let fd = (dp - dm) / (2.0 * eps);
                assert!(
                    (fd - s.column(i)).norm() < 1e-8,
                    "{i}: {fd} vs {}",
                    s.column(i)
                );
            }
        }
    }

    #[test]
    fn universal_angles_invert_non_orthogonal_hinges() {
        let a1 = Vector3::new(2.0, 1.0, 1.0).normalize();
        let a2 = Vector3::new(0.0, -1.0, 1.0).normalize();
        for (t1, t2) in [(0.4, -1.1), (-2.9, 2.0), (0.0, 0.0)] {
            let q = quat::axis_angle(&a1, t1) * quat::axis_angle(&a2, t2);
            let [b1, b2] = universal_angles(&a1, &a2, &quat::rotation(&q));
            assert!(
                (b1 - t1).abs() < 1e-12 && (b2 - t2).abs() < 1e-12,
                "{b1} {b2}"
            );
        }
    }

    #[test]
    fn closed_form_triads_pick_the_branch_newton_picks() {
        // orthonormal triads in several orders and handednesses, rotations over the whole
        // range (both branches, near and far from gimbal lock)
        let (x, y, z) = (Vector3::x(), Vector3::y(), Vector3::z());
        let tilt = quat::rotation(&quat::axis_angle(
            &Vector3::new(1.0, 2.0, 2.0).normalize(),
            0.7,
        ));
        let triads = [
            [x, y, z],
            [z, x, y],
            [y, z, x],
            [x, z, y],
            [tilt * x, tilt * z, tilt * y],
        ];
        let mut fast = 0;
        for ax in triads {
            for k in 0..400 {
                let t = k as f64;
                let theta = [
                    3.1 * (0.37 * t).sin(),
                    1.6 * (0.71 * t).cos(),
                    3.1 * (1.13 * t).sin(),
                ];
                let q = hinges3_rotation(&ax, &theta);
                let guess = triad_guess(&ax, &quat::rotation(&q));
                let flipped = [
                    guess[0] + std::f64::consts::PI,
                    std::f64::consts::PI - guess[1],
                    guess[2] + std::f64::consts::PI,
                ];
                let reference = newton_branches(&ax, &q, guess, flipped);
                if exact_triad(&ax, &q, guess, flipped).is_some() {
                    fast += 1;
                }
                let got = hinges3_angles(&ax, &q);
                for i in 0..3 {
                    assert!(
                        (got[i] - reference[i]).abs() < 1e-12,
                        "{ax:?} {theta:?}: {got:?} vs {reference:?}"
                    );
                }
            }
        }
        // the closed form is taken away from gimbal lock, i.e. almost always
        assert!(fast > 1900, "closed form taken {fast} of 2000 times");
    }
}
