//! Dry joint friction (MuJoCo's `frictionloss`) in the interior-point step: the joint resists its
//! motion with an impulse `τ`, `|τ| ≤ f h`, that dissipates the most, `τ θ̇⁺` largest (maximal
//! dissipation along one dof: a one-dimensional friction cone with a fixed bound). Its optimality
//! conditions split the dof's displacement over the step `h θ̇⁺ = h J_f w⁺` into a forward part
//! `δ_fw` and a backward part `δ_bw`, each complementary to the room `s` left on its side of the
//! bound:
//!
//! ```text
//! node layout per dof with friction: [δ_fw, s_fw, δ_bw, s_bw]
//! r₀ = s_fw + s_bw - 2 f h        (so τ = (s_bw - s_fw) / 2 lies in [-f h, f h])
//! r₁ = δ_fw s_fw - κ              (moving forward, δ_fw > 0: τ = f h)
//! r₂ = δ_fw - δ_bw - h J_f w⁺
//! r₃ = δ_bw s_bw - κ              (moving backward: τ = -f h)
//! body rows of the joint's bodies: + J_fᵀ τ  (as a damper's impulse, current configuration)
//! ```
//!
//! Each pair is an impulse and a distance, as a contact's `(γ, gap)` is, so the solver's
//! centring and warm-start widening treat them alike. Scaled otherwise the iterations grew:
//! the A1 (`frictionloss` 0.2 on its twelve joints, `step_bench a1.xml 1000 1 SEED`, seeds
//! 1-2) took 10.7 and 10.5 iterations a step like this (10.0 and 10.2 without friction),
//! 18.1 and 17.4 with rates `θ̇` for `δ`, and 61 and 62 with the room in units of the bound.
//!
//! A passive tendon's friction (MuJoCo's tendon `frictionloss`) is the same node on the tendon's
//! length `L = Σ coef q`: its displacement `h Σ coef J_f w⁺`, its impulse acting on every term
//! as `coef τ`.
//!
//! A sticking joint has `δ_fw = δ_bw = 0` and `|τ| < f h`: it holds any load below its
//! friction, exactly, with no creep (MuJoCo's frictionloss is a soft constraint and creeps).
//! The pairs are always active: a joint with friction may start or stop in any step.
use crate::model::Model;
use crate::model::topology_body_node as body_node;
use crate::state::Workspace;

/// The rows `(band, displacement)` of every dof with friction, their complementarity products (the
/// κ shift is `inequality::violations`'), and the impulses on the body rows, at the iterate `w`
/// (needs the current free Jacobians `ws.free_jac`).
pub(crate) fn add_rows(model: &Model, ws: &Workspace, w: &[f64], residual: &mut [f64]) {
    let t = &model.topology;
    let h = model.options.timestep;
    for (j, joint) in model.joints.iter().enumerate() {
        let Some(n) = t.friction_node[j] else {
            continue;
        };
        let o = t.pattern.offset(n);
        for (i, (dof, f)) in joint.friction_dofs().enumerate() {
            let jf = &ws.free_jac[ws.free_adr[j] + 12 * dof..ws.free_adr[j] + 12 * dof + 12];
            let rate = free_rate(model, joint.parent, joint.child, jf, w);
            let r = &mut residual[o + 4 * i..o + 4 * i + 4];
            let tau = pair_rows(r, &w[o + 4 * i..o + 4 * i + 4], f * h, h * rate);
            add_impulse(model, joint, jf, tau, residual);
        }
    }
    // a tendon's: its length's rate `Σ coef J_f w⁺`, its impulse on every term as `coef τ`
    for (k, tendon) in model.passive_tendons.iter().enumerate() {
        let Some(n) = t.tendon_friction_node[k] else {
            continue;
        };
        let o = t.pattern.offset(n);
        let jf = |j: usize, d: usize| &ws.free_jac[ws.free_adr[j] + 12 * d..][..12];
        let rate: f64 = (tendon.terms.iter())
            .map(|&(j, d, c)| {
                let joint = &model.joints[j];
                c * free_rate(model, joint.parent, joint.child, jf(j, d), w)
            })
            .sum();
        let r = &mut residual[o..o + 4];
        let tau = pair_rows(r, &w[o..o + 4], tendon.frictionloss * h, h * rate);
        for &(j, d, c) in &tendon.terms {
            add_impulse(model, &model.joints[j], jf(j, d), c * tau, residual);
        }
    }
}

/// The rows of one dof's friction variables `x` with bound `f h` and displacement `h θ̇⁺`
/// (products only: `inequality::violations` shifts them by κ); returns its impulse `τ`.
fn pair_rows(r: &mut [f64], x: &[f64], bound: f64, displacement: f64) -> f64 {
    r[0] = x[1] + x[3] - 2.0 * bound;
    r[1] = x[0] * x[1];
    r[2] = x[0] - x[2] - displacement;
    r[3] = x[2] * x[3];
    0.5 * (x[3] - x[1])
}

/// `r_b += J_f,bᵀ τ` on the body rows of `joint`'s parent and child (`jf` a free dof's row).
fn add_impulse(model: &Model, joint: &crate::joints::Joint, jf: &[f64], tau: f64, r: &mut [f64]) {
    for (side, b) in [(0, joint.parent), (1, joint.child)] {
        if let Some(bn) = body_node(b) {
            let ob = model.topology.pattern.offset(bn);
            for k in 0..6 {
                r[ob + k] += jf[6 * side + k] * tau;
            }
        }
    }
}

/// `J_f w⁺`: a free dof's rate at the iterate (the world's velocities are zero).
fn free_rate(model: &Model, parent: usize, child: usize, jf: &[f64], w: &[f64]) -> f64 {
    let mut rate = 0.0;
    for (side, b) in [(0, parent), (1, child)] {
        if let Some(bn) = body_node(b) {
            let ob = model.topology.pattern.offset(bn);
            rate += (0..6).map(|k| jf[6 * side + k] * w[ob + k]).sum::<f64>();
        }
    }
    rate
}

/// Newton-matrix blocks of the friction nodes at the iterate `w`: the diagonal block, the
/// displacement rows' `-h J_f` and the body rows' `∓J_fᵀ / 2`.
pub(crate) fn assemble(model: &Model, ws: &mut Workspace, w: &[f64]) {
    let t = &model.topology;
    let h = model.options.timestep;
    for (j, joint) in model.joints.iter().enumerate() {
        let Some(n) = t.friction_node[j] else {
            continue;
        };
        let (o, dim) = (t.pattern.offset(n), t.pattern.dim(n));
        if let Some(diag) = t.pattern.block(n, n) {
            diagonal(
                &mut ws.matrix.values[diag..diag + dim * dim],
                &w[o..o + dim],
            );
        }
        for (side, blk) in t.friction_blocks[j].iter().enumerate() {
            let Some((row_n, row_b)) = *blk else { continue };
            for (i, (dof, _)) in joint.friction_dofs().enumerate() {
                let fa = ws.free_adr[j] + 12 * dof + 6 * side;
                let vals = &mut ws.matrix.values;
                for k in 0..6 {
                    let jf = ws.free_jac[fa + k];
                    vals[row_n + (4 * i + 2) * 6 + k] = -h * jf; // r₂ = … - h J_f w⁺
                    vals[row_b + k * dim + 4 * i + 1] = -0.5 * jf; // τ = (s_bw - s_fw) / 2
                    vals[row_b + k * dim + 4 * i + 3] = 0.5 * jf;
                }
            }
        }
    }
    for (k, tendon) in model.passive_tendons.iter().enumerate() {
        let Some(n) = t.tendon_friction_node[k] else {
            continue;
        };
        let o = t.pattern.offset(n);
        if let Some(diag) = t.pattern.block(n, n) {
            diagonal(&mut ws.matrix.values[diag..diag + 16], &w[o..o + 4]);
        }
        // terms may share a body: each adds its share (the blocks start at zero)
        for &(b, (row_n, row_b)) in &t.tendon_friction_blocks[k] {
            for &(j, dof, c) in &tendon.terms {
                let joint = &model.joints[j];
                for (side, jb) in [(0, joint.parent), (1, joint.child)] {
                    if jb != b {
                        continue;
                    }
                    let fa = ws.free_adr[j] + 12 * dof + 6 * side;
                    let vals = &mut ws.matrix.values;
                    for i in 0..6 {
                        let jf = c * ws.free_jac[fa + i];
                        vals[row_n + 2 * 6 + i] -= h * jf; // r₂ = … - h Σ coef J_f w⁺
                        vals[row_b + 4 * i + 1] -= 0.5 * jf; // τ = (s_bw - s_fw) / 2
                        vals[row_b + 4 * i + 3] += 0.5 * jf;
                    }
                }
            }
        }
    }
}

/// The diagonal block `d` of a friction node with variables `x` (4 per dof, `dim = x.len()`):
/// per dof the band row `[0, 1, 0, 1]`, the complementarity rows and the displacement row
/// `[1, 0, -1, 0]`.
fn diagonal(d: &mut [f64], x: &[f64]) {
    let dim = x.len();
    d.fill(0.0);
    for (i, x) in x.chunks_exact(4).enumerate() {
        let at = |r: usize, c: usize| (4 * i + r) * dim + 4 * i + c;
        (d[at(0, 1)], d[at(0, 3)]) = (1.0, 1.0);
        (d[at(1, 0)], d[at(1, 1)]) = (x[1], x[0]);
        (d[at(2, 0)], d[at(2, 2)]) = (1.0, -1.0);
        (d[at(3, 2)], d[at(3, 3)]) = (x[3], x[2]);
    }
}

/// The impulse `τ = (s_bw - s_fw) / 2` of each dof with friction whose node variables are in
/// `x` (N·s or N·m·s, resisting the dof's motion: positive opposes a positive rate).
pub(crate) fn impulses(x: &[f64]) -> impl Iterator<Item = f64> + '_ {
    x.chunks_exact(4).map(|x| 0.5 * (x[3] - x[1]))
}
