//! Variational integrator residual of one rigid body, Dojo eqs. (16)-(18), in impulse units.
//!
//! Unknowns are the next midpoint velocities `v⁺ = (p⁺ - p)/h` (world, COM) and `ω⁺` (body
//! frame, `q⁺ = q ⊗ f(ω⁺)`, eq. 18). The previous midpoint velocities `v⁻, ω⁻` are the state.
//! With `c(ω) = sqrt(1 - |hω/2|²)`, eq. (16) divided by 1 and eq. (17) multiplied by `2/h`:
//!
//! ```text
//! r_lin = m (v⁺ - v⁻)                                                       - h (m g + f) - Aᵀ j
//! r_rot = c(ω⁺) J ω⁺ + (h/2) ω⁺ × J ω⁺ - c(ω⁻) J ω⁻ + (h/2) ω⁻ × J ω⁻       - h τ_b      - Bᵀ j
//! ```
//! The applied impulses (gravity, external wrenches, springs, inputs) are evaluated at the
//! current configuration, which is what the discrete Euler-Lagrange equations of the trapezoidal
//! discrete Lagrangian give; constraint impulses act through the constraint Jacobian at the
//! current configuration while the constraint itself holds at the next one.
use nalgebra::{Matrix3, Vector3};

use crate::math::spatial::skew;

/// `c(ω) = sqrt(1 - |hω/2|²)`, the scalar part of the step map.
pub fn step_scalar(omega: &Vector3<f64>, h: f64) -> f64 {
    (1.0 - (omega * (0.5 * h)).norm_squared()).max(0.0).sqrt()
}

/// Forward discrete angular momentum (body frame at the start of the step):
/// `c(ω) J ω + (h/2) ω × J ω`.
pub fn angular_momentum_forward(
    inertia: &Matrix3<f64>,
    omega: &Vector3<f64>,
    h: f64,
) -> Vector3<f64> {
    let jw = inertia * omega;
    jw * step_scalar(omega, h) + omega.cross(&jw) * (0.5 * h)
}

/// Backward discrete angular momentum (body frame at the end of the step):
/// `c(ω) J ω - (h/2) ω × J ω`. Equal to the forward momentum rotated by the step (Noether).
pub fn angular_momentum_backward(
    inertia: &Matrix3<f64>,
    omega: &Vector3<f64>,
    h: f64,
) -> Vector3<f64> {
    let jw = inertia * omega;
    jw * step_scalar(omega, h) - omega.cross(&jw) * (0.5 * h)
}

/// Momentum part of the body residual (no applied or constraint impulses): `[r_lin; r_rot]`.
/// `h_prev` is the length of the previous interval (the one `v⁻, ω⁻` are the midpoint
/// velocities of), `h` that of the step: the discrete Euler-Lagrange equations of a variable
/// step equate the backward momentum of the one with the forward momentum of the other (the
/// applied impulses then act over `(h_prev + h) / 2`).
pub fn momentum_residual(
    mass: f64,
    inertia: &Matrix3<f64>,
    (h_prev, h): (f64, f64),
    (linvel_prev, angvel_prev): (&Vector3<f64>, &Vector3<f64>),
    (linvel, angvel): (&Vector3<f64>, &Vector3<f64>),
) -> (Vector3<f64>, Vector3<f64>) {
    let lin = (linvel - linvel_prev) * mass;
    let rot = angular_momentum_forward(inertia, angvel, h)
        - angular_momentum_backward(inertia, angvel_prev, h_prev);
    (lin, rot)
}

/// `∂r_rot/∂ω⁺ = c J - (h²/4c) J ω ωᵀ + (h/2)(skew(ω) J - skew(J ω))`; `∂r_lin/∂v⁺ = m I`.
pub fn rot_jacobian(inertia: &Matrix3<f64>, angvel: &Vector3<f64>, h: f64) -> Matrix3<f64> {
    let c = step_scalar(angvel, h).max(1e-12);
    let jw = inertia * angvel;
    inertia * c - jw * angvel.transpose() * (0.25 * h * h / c)
        + (skew(angvel) * inertia - skew(&jw)) * (0.5 * h)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::math::quat;

    fn inertia() -> Matrix3<f64> {
        Matrix3::new(2.0, 0.3, -0.1, 0.3, 1.0, 0.2, -0.1, 0.2, 0.5)
    }

    #[test]
    fn rot_jacobian_matches_finite_differences() {
        let (j, h) = (inertia(), 0.02);
        let w = Vector3::new(4.0, -7.0, 11.0);
        let jac = rot_jacobian(&j, &w, h);
        for i in 0..3 {
            let e = Vector3::ith(i, 1e-6);
            let fd = (angular_momentum_forward(&j, &(w + e), h)
                - angular_momentum_forward(&j, &(w - e), h))
                / 2e-6;
            assert!((fd - jac.column(i)).norm() < 1e-7, "{i}");
        }
    }

    #[test]
    fn step_rotates_backward_momentum_into_forward_momentum() {
        // R(f(ω)) (c Jω - h/2 ω×Jω) = c Jω + h/2 ω×Jω: the identity behind exact angular momentum
        // conservation of the free rigid body.
        let (j, h) = (inertia(), 0.05);
        let w = Vector3::new(3.0, -2.0, 9.0);
        let r = quat::rotation(&quat::step_map(&w, h));
        let lhs = r * angular_momentum_backward(&j, &w, h);
        assert!((lhs - angular_momentum_forward(&j, &w, h)).norm() < 1e-13);
    }
}
