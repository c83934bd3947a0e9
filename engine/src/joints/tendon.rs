//! Fixed-tendon limits (MuJoCo's limited `<tendon><fixed>`): an inequality on a linear
//! combination of hinge/slide coordinates, solved with the contacts and joint limits in the
//! interior-point step.
//!
//! ```text
//! L = Σ_i coef_i q_i,     lo ≤ L ≤ hi
//! s_lo = L(x⁺) - lo,  s_hi = hi - L(x⁺),  γ_lo s_lo = κ,  γ_hi s_hi = κ
//! ```
//! The slacks hold at the next configuration; the impulse `γ_lo - γ_hi` acts on each term's
//! coordinate as the generalized impulse `coef_i (γ_lo - γ_hi)` through that joint's free
//! Jacobian at the current configuration (the joint-limit rows with `L` in place of `θ`).

/// A compiled tendon limit.
#[derive(Clone, Debug)]
pub struct TendonLimit {
    /// Unique name.
    pub name: String,
    /// Terms `(joint, free dof, coef)`: hinge or slide coordinates of tree joints.
    pub terms: Vec<(usize, usize, f64)>,
    /// Range `(lo, hi)` of the length `L = Σ coef q` (m or rad), `lo < hi`.
    pub range: (f64, f64),
}

impl TendonLimit {
    /// Length `Σ coef_i q_i` from the term coordinates `q(joint, dof)`.
    pub fn length(&self, mut q: impl FnMut(usize, usize) -> f64) -> f64 {
        self.terms.iter().map(|&(j, d, c)| c * q(j, d)).sum()
    }
}

/// A compiled passive fixed tendon (MuJoCo's `<tendon><fixed>` with `stiffness`, `damping` or
/// `frictionloss`): a spring `-k (L - L₀)` at the current configuration, an implicit damper
/// `-d L̇⁺` and dry friction on the length `L = Σ coef q`, each acting on every term's
/// coordinate as `coef ·` the tendon force.
#[derive(Clone, Debug)]
pub struct PassiveTendon {
    /// Unique name.
    pub name: String,
    /// Terms `(joint, free dof, coef)`: hinge or slide coordinates of tree joints.
    pub terms: Vec<(usize, usize, f64)>,
    /// Spring stiffness (N/m or N·m/rad per unit length).
    pub stiffness: f64,
    /// Spring rest length `L₀` (m or rad).
    pub springlength: f64,
    /// Damping (N·s/m or N·m·s/rad per unit length), acting on the next velocities.
    pub damping: f64,
    /// Dry friction on the tendon's length (N or N·m per unit length, MuJoCo's
    /// `frictionloss`), solved as the joints' is (`solver::friction`).
    pub frictionloss: f64,
}
