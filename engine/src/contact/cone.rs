//! Cone algebra of the interior-point solver (Dojo §IV-B, eqs. 33-46): positive orthant and
//! second-order cone products, identities, and the analytic step-length search.
use nalgebra::Vector3;

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
