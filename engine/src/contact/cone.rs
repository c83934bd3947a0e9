//! Cone algebra of the interior-point solver (Dojo §IV-B, eqs. 33-46): positive orthant and
//! second-order cone products, identities, and the analytic step-length search.
use nalgebra::{Matrix3, Vector3};

/// Second-order-cone product `a ∘ b = (aᵀb, a₁ b₂:₃ + b₁ a₂:₃)` (eq. 24/37) in 3-D.
pub fn soc_product(a: &Vector3<f64>, b: &Vector3<f64>) -> Vector3<f64> {
    Vector3::new(
        a.dot(b),
        a[0] * b[1] + b[0] * a[1],
        a[0] * b[2] + b[0] * a[2],
    )
}

/// Largest `α ∈ (0, 1]` with `y + α Δ ≥ (1 - τ) y` componentwise (eq. 41 with fraction τ).
pub fn orthant_step(y: &[f64], dy: &[f64], tau: f64) -> f64 {
    let mut alpha: f64 = 1.0;
    for (yi, di) in y.iter().zip(dy) {
        if *di < 0.0 {
            alpha = alpha.min(-tau * yi / di);
        }
    }
    alpha
}

/// Largest `α ∈ (0, 1]` keeping `y + α Δ` inside the second-order cone, scaled by `τ`
/// (eqs. 42-46). `y` must be strictly inside the cone.
pub fn soc_step(y: &Vector3<f64>, dy: &Vector3<f64>, tau: f64) -> f64 {
    // NOTE: the unfactored y₁² - |y₂:₃|² on purpose: with `soc_det` here the 1000:1
    // heavy-on-light stack (tests/stress) went from 0 to 25 of 100 steps unconverged.
    let nu = y[0] * y[0] - y[1] * y[1] - y[2] * y[2];
    if nu <= 0.0 {
        return 0.0;
    }
    let sq = nu.sqrt();
    let zeta = y[0] * dy[0] - y[1] * dy[1] - y[2] * dy[2];
    let rho1 = zeta / nu;
    let c = (zeta / sq + dy[0]) / (y[0] * sq + nu);
    let rho2 = (dy[1] / sq - c * y[1], dy[2] / sq - c * y[2]);
    let norm = (rho2.0 * rho2.0 + rho2.1 * rho2.1).sqrt();
    if norm > rho1 {
        (tau / (norm - rho1)).min(1.0)
    } else {
        1.0
    }
}

/// `y₁² - |y₂:₃|²`, factored so that points near the boundary keep their relative accuracy.
pub fn soc_det(y: &Vector3<f64>) -> f64 {
    let n = (y[1] * y[1] + y[2] * y[2]).sqrt();
    (y[0] - n) * (y[0] + n)
}

/// Arrow matrix `Arw(y)`, the linear map `z ↦ y ∘ z`.
pub fn arrow(y: &Vector3<f64>) -> Matrix3<f64> {
    Matrix3::new(y[0], y[1], y[2], y[1], y[0], 0.0, y[2], 0.0, y[0])
}

/// Nesterov–Todd scaling of a pair `(x, s)` strictly inside the second-order cone: the cone
/// automorphism `W` (symmetric positive definite) with `W x = W⁻¹ s = λ`.
///
/// Linearising `x ∘ s = κe` directly (the "unscaled" Newton step) gives directions that leave
/// the central path's neighbourhood when `x` and `s` differ in scale or direction (a sliding
/// contact: large friction impulse, tiny tangential slack), so the cone line search cuts every
/// step short. Linearising the equivalent `(W x) ∘ (W⁻¹ s) = κe` at the current `W` treats `x` and
/// `s` symmetrically (Nesterov–Todd 1997; the SOC formulas as in Vandenberghe's CVXOPT notes).
#[derive(Clone, Copy, Debug)]
pub struct NtScaling {
    /// `W`.
    pub w: Matrix3<f64>,
    /// `W⁻¹`.
    pub w_inv: Matrix3<f64>,
    /// `λ = W x = W⁻¹ s`.
    pub lambda: Vector3<f64>,
}

impl NtScaling {
    /// The identity scaling (`x = s`).
    pub fn identity() -> Self {
        NtScaling {
            w: Matrix3::identity(),
            w_inv: Matrix3::identity(),
            lambda: Vector3::new(1.0, 0.0, 0.0),
        }
    }

    /// Scaling of the interior pair `(x, s)`; `None` if either is not strictly inside.
    pub fn new(x: &Vector3<f64>, s: &Vector3<f64>) -> Option<Self> {
        let (dx, ds) = (soc_det(x), soc_det(s));
        if !(dx > 0.0 && ds > 0.0) {
            return None;
        }
        let xb = x / dx.sqrt();
        let sb = s / ds.sqrt();
        let gamma = (0.5 * (1.0 + xb.dot(&sb))).sqrt();
        // normalised scaling point w̄ = (s̄ + J x̄) / 2γ, w̄ᵀ J w̄ = 1
        let wb = Vector3::new(sb[0] + xb[0], sb[1] - xb[1], sb[2] - xb[2]) / (2.0 * gamma);
        let eta = (ds / dx).sqrt().sqrt();
        let t = nalgebra::Vector2::new(wb[1], wb[2]);
        let lower = nalgebra::Matrix2::identity() + t * t.transpose() / (1.0 + wb[0]);
        let mut w = Matrix3::zeros();
        let mut w_inv = Matrix3::zeros();
        w[(0, 0)] = wb[0];
        w_inv[(0, 0)] = wb[0];
        for i in 0..2 {
            w[(0, 1 + i)] = t[i];
            w[(1 + i, 0)] = t[i];
            w_inv[(0, 1 + i)] = -t[i];
            w_inv[(1 + i, 0)] = -t[i];
            for k in 0..2 {
                w[(1 + i, 1 + k)] = lower[(i, k)];
                w_inv[(1 + i, 1 + k)] = lower[(i, k)];
            }
        }
        w *= eta;
        w_inv /= eta;
        let lambda = w * x;
        Some(NtScaling { w, w_inv, lambda })
    }
}

/// Push `y` strictly inside the second-order cone: `y₁ ≥ |y₂:₃| + margin`.
pub fn soc_interior(y: &mut Vector3<f64>, margin: f64) {
    let n = (y[1] * y[1] + y[2] * y[2]).sqrt();
    if y[0] < n + margin {
        y[0] = n + margin;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn in_cone(y: &Vector3<f64>) -> f64 {
        y[0] - (y[1] * y[1] + y[2] * y[2]).sqrt()
    }

    #[test]
    fn soc_step_stops_exactly_at_the_boundary() {
        let y = Vector3::new(2.0, 0.5, -0.3);
        for dy in [
            Vector3::new(-3.0, 1.0, 0.5),
            Vector3::new(0.0, 4.0, 0.0),
            Vector3::new(-1.0, -2.0, 3.0),
        ] {
            let a = soc_step(&y, &dy, 1.0);
            assert!(a > 0.0 && a <= 1.0);
            if a < 1.0 {
                assert!(in_cone(&(y + dy * a)).abs() < 1e-12, "boundary at α = {a}");
            }
            let inner = soc_step(&y, &dy, 0.95);
            assert!(in_cone(&(y + dy * inner)) > 0.0);
        }
        // a direction into the cone allows the full step
        assert_eq!(soc_step(&y, &Vector3::new(1.0, 0.0, 0.0), 0.99), 1.0);
    }

    #[test]
    fn nt_scaling_maps_both_to_lambda() {
        let pairs = [
            (Vector3::new(2.0, 0.5, -0.3), Vector3::new(1.0, -0.2, 0.7)),
            (
                Vector3::new(1e3, 999.9, 0.0),
                Vector3::new(1e-6, -0.5e-6, 0.1e-6),
            ),
            (Vector3::new(1.0, 0.0, 0.0), Vector3::new(1.0, 0.0, 0.0)),
        ];
        for (x, s) in pairs {
            let nt = NtScaling::new(&x, &s).unwrap();
            let (wx, ws) = (nt.w * x, nt.w_inv * s);
            let scale = nt.lambda.norm();
            assert!((wx - ws).norm() < 1e-9 * scale, "W x {wx} vs W⁻¹ s {ws}");
            assert!((nt.w * nt.w_inv - Matrix3::identity()).norm() < 1e-9);
            assert!((nt.w - nt.w.transpose()).norm() < 1e-12 * nt.w.norm());
            // λᵀλ = xᵀs, and λ is inside the cone
            assert!(
                (nt.lambda.dot(&nt.lambda) - x.dot(&s)).abs() < 1e-9 * x.dot(&s).abs().max(1e-12)
            );
            assert!(soc_det(&nt.lambda) > 0.0);
        }
        assert!(
            NtScaling::new(&Vector3::new(1.0, 1.0, 0.0), &Vector3::new(1.0, 0.0, 0.0)).is_none()
        );
    }

    #[test]
    fn scaled_central_path_is_the_central_path() {
        // x ∘ s = κe  ⟺  (W x) ∘ (W⁻¹ s) = κe for a fixed automorphism W
        let x = Vector3::new(2.0, 0.6, -0.8);
        let ev = soc_det(&x);
        // s = κ x⁻¹ with the Jordan inverse x⁻¹ = J x / det(x)
        let kappa = 0.3;
        let s = Vector3::new(x[0], -x[1], -x[2]) * (kappa / ev);
        assert!((soc_product(&x, &s) - Vector3::new(kappa, 0.0, 0.0)).norm() < 1e-12);
        let other =
            NtScaling::new(&Vector3::new(3.0, 1.0, 0.5), &Vector3::new(1.0, 0.1, -0.3)).unwrap();
        let scaled = soc_product(&(other.w * x), &(other.w_inv * s));
        assert!(
            (scaled - Vector3::new(kappa, 0.0, 0.0)).norm() < 1e-12,
            "{scaled}"
        );
    }

    #[test]
    fn orthant_step_keeps_a_fraction() {
        let a = orthant_step(&[1.0, 2.0], &[-4.0, 1.0], 0.9);
        assert!((a - 0.225).abs() < 1e-15);
    }

    #[test]
    fn soc_product_identity() {
        let e = Vector3::new(1.0, 0.0, 0.0);
        let y = Vector3::new(2.0, 0.3, -0.4);
        assert!((soc_product(&e, &y) - y).norm() < 1e-15);
    }
}
