//! Rows of the fixed-tendon limits in the interior-point step ([`crate::joints::tendon`]).
//! Node layout `[γ_lo, s_lo, γ_hi, s_hi]`, as one limited joint dof:
//!
//! ```text
//! r₀ = s_lo - (L(x⁺) - lo)    r₁ = γ_lo s_lo - κ
//! r₂ = s_hi - (hi - L(x⁺))    r₃ = γ_hi s_hi - κ
//! body rows of each term's joint:  -coef_i J_f,iᵀ (γ_lo - γ_hi)   (current configuration)
//! ```
use super::coupling::coordinate;
use super::inequality::chain_row;
use crate::joints::geometry::Pose;
use crate::model::Model;
use crate::model::topology_body_node as body_node;
use crate::state::Workspace;

fn next(ws: &Workspace, b: usize) -> Pose {
    if b == 0 {
        Pose::world()
    } else {
        ws.next_pose[b]
    }
}

/// Length of tendon limit `t` at the next configuration (`ws.next_pose`).
pub(crate) fn next_length(model: &Model, ws: &Workspace, t: usize) -> f64 {
    model.tendon_limits[t].length(|ji, dof| {
        let j = &model.joints[ji];
        coordinate(
            model,
            ws,
            (ji, dof),
            &next(ws, j.parent),
            &next(ws, j.child),
        )
        .0
    })
}

/// Slack and complementarity rows of every tendon limit at the iterate `w`, and their impulses
/// on the body rows (needs `ws.next_pose` and the current free Jacobians).
pub(crate) fn add_rows(model: &Model, ws: &Workspace, w: &[f64], residual: &mut [f64]) {
    let t = &model.topology;
    let first = model.ncontact() + model.njoint();
    for (k, tendon) in model.tendon_limits.iter().enumerate() {
        let o = t.pattern.offset(t.tendon_node[k]);
        if !ws.active[first + k] {
            // an inactive limit: no impulse, its variables fixed (rows `w - w₀ = 0`)
            residual[o..o + 4].fill(0.0);
            continue;
        }
        let (lo, hi) = tendon.range;
        let len = next_length(model, ws, k);
        let x = &w[o..o + 4];
        let r = &mut residual[o..o + 4];
        r[0] = x[1] - (len - lo);
        r[1] = x[0] * x[1];
        r[2] = x[3] - (hi - len);
        r[3] = x[2] * x[3];
        let imp = x[0] - x[2];
        for &(ji, dof, coef) in &tendon.terms {
            let joint = &model.joints[ji];
            let fa = ws.free_adr[ji] + 12 * dof;
            for (side, b) in [(0, joint.parent), (1, joint.child)] {
                if let Some(n) = body_node(b) {
                    let ob = t.pattern.offset(n);
                    for i in 0..6 {
                        residual[ob + i] -= coef * ws.free_jac[fa + 6 * side + i] * imp;
                    }
                }
            }
        }
    }
}

/// Newton-matrix blocks of the tendon-limit nodes at the iterate `w`: the diagonal block, the
/// slack rows' `∂L(x⁺)/∂w_b` (chain rule through the step map) and the body rows' `∓coef J_fᵀ`.
pub(crate) fn assemble(model: &Model, ws: &mut Workspace, w: &[f64], h: f64) {
    let t = &model.topology;
    let first = model.ncontact() + model.njoint();
    for (k, tendon) in model.tendon_limits.iter().enumerate() {
        let n = t.tendon_node[k];
        // an inactive limit's node keeps the identity row and column
        let active = ws.active[first + k];
        if ws.matrix.is_skipped(n) == active {
            ws.matrix.set_skipped(&t.pattern, n, !active);
        }
        if !active {
            continue;
        }
        let o = t.pattern.offset(n);
        let x = &w[o..o + 4];
        if let Some(diag) = t.pattern.block(n, n) {
            let d = &mut ws.matrix.values[diag..diag + 16];
            d.fill(0.0);
            d[1] = 1.0; // s_lo
            d[4] = x[1];
            d[5] = x[0];
            d[2 * 4 + 3] = 1.0; // s_hi
            d[3 * 4 + 2] = x[3];
            d[3 * 4 + 3] = x[2];
        }
        for &(ji, dof, coef) in &tendon.terms {
            let joint = &model.joints[ji];
            let (_, dq) = coordinate(
                model,
                ws,
                (ji, dof),
                &next(ws, joint.parent),
                &next(ws, joint.child),
            );
            let fa = ws.free_adr[ji] + 12 * dof;
            for (side, b) in [(0, joint.parent), (1, joint.child)] {
                let Some(&(_, (row_n, row_b))) = t.tendon_blocks[k].iter().find(|e| e.0 == b)
                else {
                    continue;
                };
                let chain = chain_row(&dq[6 * side..6 * side + 6], h, &ws.dphi[b]);
                let vals = &mut ws.matrix.values;
                for i in 0..6 {
                    let jf = coef * ws.free_jac[fa + 6 * side + i];
                    vals[row_n + i] -= coef * chain[i]; // s_lo - (L - lo)
                    vals[row_n + 12 + i] += coef * chain[i]; // s_hi - (hi - L)
                    vals[row_b + 4 * i] -= jf; // -coef J_fᵀ γ_lo
                    vals[row_b + 4 * i + 2] += jf; // +coef J_fᵀ γ_hi
                }
            }
        }
    }
}
