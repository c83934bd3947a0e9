//! Rotor inertia of joint dofs (MuJoCo's `armature`) in the discrete Euler-Lagrange equations.
//!
//! A dof with armature `a` adds the kinetic energy `½ a θ̇²`, where `θ̇ = J_f w` is the dof rate
//! of the body velocities `w = (v_p, ω_p, v_c, ω_c)` through the free Jacobian `J_f` at the
//! current configuration. Its discrete Euler-Lagrange term is the momentum difference
//!
//! ```text
//! r_b += J_bᵀ a (J_f w⁺ − J_f w⁻)           (impulse, like m (v⁺ − v⁻) of a body)
//! ∂r_a/∂w_b⁺ = J_aᵀ a J_b                    (a, b ∈ {parent, child})
//! ```
//! with the same block pattern as the implicit damper `h J_fᵀ D J_f w⁺`.
use nalgebra::Vector3;

use crate::joints::Joint;
use crate::model::Model;
use crate::model::topology_body_node as body_node;
use crate::state::State;

fn slot(model: &Model, b: usize) -> usize {
    body_node(b).map_or(0, |n| model.topology.pattern.offset(n))
}

/// `(v, ω)` of body `b` in the iterate `w` (zeros for the world).
fn iterate_velocity(model: &Model, w: &[f64], b: usize) -> [f64; 6] {
    if b == 0 {
        return [0.0; 6];
    }
    let o = slot(model, b);
    [w[o], w[o + 1], w[o + 2], w[o + 3], w[o + 4], w[o + 5]]
}

/// `(v, ω)` of body `b` in the state (the previous midpoint velocities).
fn state_velocity(state: &State, b: usize) -> [f64; 6] {
    if b == 0 {
        return [0.0; 6];
    }
    let (v, w): (Vector3<f64>, Vector3<f64>) = state.velocity(b);
    [v[0], v[1], v[2], w[0], w[1], w[2]]
}

/// `r_b += J_bᵀ a (J_f w⁺ − J_f w⁻)` on the joint's parent and child body rows.
pub(crate) fn add_armature_residual(
    model: &Model,
    state: &State,
    joint: &Joint,
    jf: &[f64],
    w: &[f64],
    residual: &mut [f64],
) {
    let next = [
        iterate_velocity(model, w, joint.parent),
        iterate_velocity(model, w, joint.child),
    ];
    let prev = [
        state_velocity(state, joint.parent),
        state_velocity(state, joint.child),
    ];
    for (r, &a) in joint.armature.iter().enumerate() {
        if a == 0.0 {
            continue;
        }
        let row = &jf[12 * r..12 * r + 12];
        let rate =
            |x: &[[f64; 6]; 2]| -> f64 { (0..12).map(|i| row[i] * x[i / 6][i % 6]).sum::<f64>() };
        let f = a * (rate(&next) - rate(&prev));
        for (side, b) in [(0, joint.parent), (1, joint.child)] {
            if b > 0 {
                let ob = slot(model, b);
                for i in 0..6 {
                    residual[ob + i] += row[6 * side + i] * f;
                }
            }
        }
    }
}
