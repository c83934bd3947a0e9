//! Joint couplings (MuJoCo's `equality/joint`): a holonomic scalar constraint between two joint
//! coordinates, solved with the joints in the same Newton step (a loop-style impulse row).
//!
//! ```text
//! k = (y - y₀) - P(x - x₀),   P(t) = c₀ + c₁ t + c₂ t² + c₃ t³ + c₄ t⁴
//! ```
//! `y`, `x` are hinge/slide coordinates (qpos), `y₀`, `x₀` their reference values (MuJoCo's
//! `qpos0`). Without a second joint, `k = y - y₀ - c₀`. The impulse acts through the free
//! Jacobians: `K = J_y - P'(x - x₀) J_x`.

/// A compiled coupling.
#[derive(Clone, Debug)]
pub struct Coupling {
    /// Unique name.
    pub name: String,
    /// Joint index and free dof of the driven coordinate `y`.
    pub joint1: (usize, usize),
    /// Joint index and free dof of the driving coordinate `x`, if any.
    pub joint2: Option<(usize, usize)>,
    /// Polynomial coefficients `c₀..c₄`.
    pub polycoef: [f64; 5],
    /// Reference coordinates `(y₀, x₀)` (m or rad).
    pub reference: (f64, f64),
}

impl Coupling {
    /// Constraint value `k` and `∂k/∂x` (`∂k/∂y = 1`) at coordinates `y`, `x`.
    pub fn value(&self, y: f64, x: f64) -> (f64, f64) {
        let c = &self.polycoef;
        let t = if self.joint2.is_some() {
            x - self.reference.1
        } else {
            0.0
        };
        let p = c[0] + t * (c[1] + t * (c[2] + t * (c[3] + t * c[4])));
        let dp = c[1] + t * (2.0 * c[2] + t * (3.0 * c[3] + t * 4.0 * c[4]));
        let slope = if self.joint2.is_some() { -dp } else { 0.0 };
        (y - self.reference.0 - p, slope)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn slope_is_the_derivative_of_the_value() {
        let c = Coupling {
            name: "c".into(),
            joint1: (0, 0),
            joint2: Some((1, 0)),
            polycoef: [0.1, 0.9, -0.3, 0.2, 0.05],
            reference: (0.2, -0.4),
        };
        let (x, eps) = (0.7, 1e-6);
        let (_, s) = c.value(0.3, x);
        let fd = (c.value(0.3, x + eps).0 - c.value(0.3, x - eps).0) / (2.0 * eps);
        assert!((s - fd).abs() < 1e-8, "{s} vs {fd}");
        // at x = x₀ the coupling holds when y - y₀ = c₀
        assert!(c.value(0.2 + 0.1, -0.4).0.abs() < 1e-15);
    }
}
