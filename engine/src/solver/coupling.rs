//! Rows of the joint couplings in the Newton step ([`crate::joints::coupling`]): the impulse
//! `λ` acts on the bodies through `K = J_y - P' J_x` at the current configuration, and the row
//! is `k(x⁺) = 0` at the next one (like a loop joint's).
use crate::joints::geometry::{JointFrame, Pose};
use crate::model::Model;
use crate::model::topology_body_node as body_node;
use crate::state::{State, Workspace};

fn pose_in(poses: &[Pose], b: usize) -> Pose {
    if b == 0 { Pose::world() } else { poses[b] }
}

fn pose_of(state: &State, b: usize) -> Pose {
    if b == 0 { Pose::world() } else { state.pose(b) }
}

/// Coordinate `dof` of joint `ji` with its free-Jacobian row, at the given poses; a winding
/// hinge's angle with the turns that keep it within π of the step's start (`ws.joint_q`, wound
/// by `newton::prepare_smooth_forces`), so a coupling or tendon over a wheel does not jump by
/// 2π where the wheel's measured angle wraps.
pub(super) fn coordinate(
    model: &Model,
    ws: &Workspace,
    (ji, dof): (usize, usize),
    parent: &Pose,
    child: &Pose,
) -> (f64, [f64; 12]) {
    let joint = &model.joints[ji];
    let frame = JointFrame::new(joint, parent, child);
    let mut q = [0.0; 7];
    frame.coordinates(joint, &mut q[..joint.nq()]);
    if joint.winds() && dof == joint.ntrans {
        let start = ws.joint_q[ji][dof];
        q[dof] = start + crate::joints::geometry::wrap_angle(q[dof] - start);
    }
    let mut jf = [0.0; 6 * 12];
    frame.free_jacobian(joint, &mut jf[..12 * joint.nfree()]);
    let mut row = [0.0; 12];
    row.copy_from_slice(&jf[12 * dof..12 * dof + 12]);
    (q[dof], row)
}

/// Value and slope `∂k/∂x` of coupling `c` at the given poses.
fn value_at(
    model: &Model,
    ws: &Workspace,
    c: usize,
    poses: &dyn Fn(usize) -> Pose,
) -> (f64, f64, [[f64; 12]; 2]) {
    let cp = &model.couplings[c];
    let at = |(ji, dof): (usize, usize)| {
        let j = &model.joints[ji];
        coordinate(model, ws, (ji, dof), &poses(j.parent), &poses(j.child))
    };
    let (y, jy) = at(cp.joint1);
    let (x, jx) = cp.joint2.map_or((0.0, [0.0; 12]), at);
    let (k, slope) = cp.value(y, x);
    (k, slope, [jy, jx])
}

/// The coupling's terms: (joint, dof) with the coefficient of its free-Jacobian row in `K`.
fn terms(model: &Model, c: usize, slope: f64) -> impl Iterator<Item = (usize, usize, f64)> {
    let cp = &model.couplings[c];
    std::iter::once((cp.joint1.0, cp.joint1.1, 1.0)).chain(cp.joint2.map(|(j, d)| (j, d, slope)))
}

/// Slopes at the current configuration (they fix `K` for the step).
pub(crate) fn prepare(model: &Model, state: &State, ws: &mut Workspace) {
    for c in 0..model.couplings.len() {
        let (_, slope, _) = value_at(model, ws, c, &|b| pose_of(state, b));
        ws.coupling_slope[c] = slope;
    }
}

/// Body rows `-Kᵀ λ` and the coupling rows `k(x⁺)` (needs `ws.next_pose`).
pub(crate) fn add_rows(model: &Model, ws: &Workspace, w: &[f64], residual: &mut [f64]) {
    let t = &model.topology;
    for c in 0..model.couplings.len() {
        let o = t.pattern.offset(t.coupling_node[c]);
        let lam = w[o];
        for (ji, dof, coef) in terms(model, c, ws.coupling_slope[c]) {
            let joint = &model.joints[ji];
            let row = &ws.free_jac[ws.free_adr[ji] + 12 * dof..ws.free_adr[ji] + 12 * dof + 12];
            for (side, b) in [(0, joint.parent), (1, joint.child)] {
                if let Some(n) = body_node(b) {
                    let ob = t.pattern.offset(n);
                    for i in 0..6 {
                        residual[ob + i] -= coef * row[6 * side + i] * lam;
                    }
                }
            }
        }
        let (k, _, _) = value_at(model, ws, c, &|b| pose_in(&ws.next_pose, b));
        residual[o] = k;
    }
}

/// Newton-matrix blocks: `∂k(x⁺)/∂w_b` (node row) and `-K_bᵀ` (body rows).
pub(crate) fn assemble(model: &Model, ws: &mut Workspace, h: f64) {
    let t = &model.topology;
    for c in 0..model.couplings.len() {
        let n = t.coupling_node[c];
        if let Some(d) = t.pattern.block(n, n) {
            ws.matrix.values[d] = -model.options.regularization;
        }
        let (_, slope_next, rows_next) = value_at(model, ws, c, &|b| pose_in(&ws.next_pose, b));
        let slope_now = ws.coupling_slope[c];
        let coefs_next = [1.0, slope_next];
        for (i_term, (ji, dof, coef_now)) in terms(model, c, slope_now).enumerate() {
            let joint = &model.joints[ji];
            let jnext = rows_next[i_term];
            let fa = ws.free_adr[ji] + 12 * dof;
            for (side, b) in [(0, joint.parent), (1, joint.child)] {
                let Some(&(_, (row_n, row_b))) = t.coupling_blocks[c].iter().find(|e| e.0 == b)
                else {
                    continue;
                };
                let dphi = ws.dphi[b];
                let cn = coefs_next[i_term];
                for i in 0..3 {
                    // ∂k/∂v⁺ = h ∂k/∂δp ;  ∂k/∂ω⁺ = ∂k/∂δφ · ∂φ/∂ω
                    ws.matrix.values[row_n + i] += cn * h * jnext[6 * side + i];
                    let rot: f64 = (0..3).map(|k| jnext[6 * side + 3 + k] * dphi[(k, i)]).sum();
                    ws.matrix.values[row_n + 3 + i] += cn * rot;
                }
                for i in 0..6 {
                    ws.matrix.values[row_b + i] -= coef_now * ws.free_jac[fa + 6 * side + i];
                }
            }
        }
    }
}
