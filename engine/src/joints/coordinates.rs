//! Minimal ↔ maximal coordinates (MuJoCo's `qpos`/`qvel` conventions).
//!
//! `qpos` of a joint is its free translations (components of the anchor displacement along the
//! free axes, parent joint frame) followed by its rotation coordinates: a hinge angle, two
//! universal angles, or a quaternion `(w, x, y, z)` for ball rotations. A `floating` joint is
//! MuJoCo's free joint: `[x, y, z, qw, qx, qy, qz]` of the child body frame in the parent frame.
//! `qvel` is the free translation rates followed by the relative angular velocity through the
//! motion subspace (child frame for ball rotations, as in MuJoCo). Velocities map linearly
//! through rigid-body kinematics, so min → max → min is exact.
use nalgebra::Vector3;

use super::geometry::{JointFrame, Pose, joint_angvel, joint_rotation};
use super::offsets;
use crate::math::quat;
use crate::model::Model;
use crate::state::State;
use crate::{Error, Result, ensure};

pub(crate) fn pose_of(state: &State, b: usize) -> Pose {
    if b == 0 { Pose::world() } else { state.pose(b) }
}

fn velocity_of(state: &State, b: usize) -> [f64; 6] {
    let (v, w) = if b == 0 {
        (Vector3::zeros(), Vector3::zeros())
    } else {
        state.velocity(b)
    };
    [v[0], v[1], v[2], w[0], w[1], w[2]]
}

/// Add the turns `state` keeps for joint `ji` ([`super::Joint::winds`]) to its coordinates
/// `q`, measured from its bodies' poses (the hinge angle in (-π, π]).
pub(crate) fn wind(model: &Model, state: &State, ji: usize, q: &mut [f64]) {
    if let Some(k) = model.topology.winding_adr[ji] {
        q[model.joints[ji].ntrans] += state.winding[k];
    }
}

/// A winding hinge's angle (without turns) between the poses `parent` and `child`.
fn measured_angle(j: &super::Joint, parent: &Pose, child: &Pose) -> f64 {
    let mut q = [0.0; 7];
    JointFrame::new(j, parent, child).coordinates(j, &mut q[..j.nq()]);
    q[j.ntrans]
}

/// The turns of winding hinge `ji` once its bodies have moved from their poses in `start` to
/// `parent` and `child`: its angle goes on from the wound one of `start` by less than π
/// (`newton::physical_spin_limit` bounds each body's turn in a step by √2 rad).
pub(crate) fn turns_after(
    model: &Model,
    start: &State,
    ji: usize,
    parent: &Pose,
    child: &Pose,
) -> f64 {
    let j = &model.joints[ji];
    let Some(k) = model.topology.winding_adr[ji] else {
        return 0.0;
    };
    let before = measured_angle(j, &pose_of(start, j.parent), &pose_of(start, j.child));
    let wound = before + start.winding[k];
    let after = measured_angle(j, parent, child);
    let next = wound + super::geometry::wrap_angle(after - wound);
    std::f64::consts::TAU * ((next - after) / std::f64::consts::TAU).round()
}

/// Write `qpos` (length `model.nq`) of `state`.
pub fn qpos_into(model: &Model, state: &State, out: &mut [f64]) {
    for (ji, j) in model.joints.iter().enumerate().filter(|(_, j)| !j.is_loop) {
        let frame = JointFrame::new(j, &pose_of(state, j.parent), &pose_of(state, j.child));
        let q = &mut out[j.qpos_adr..j.qpos_adr + j.nq()];
        frame.coordinates(j, q);
        wind(model, state, ji, q);
    }
}

/// Write `qpos` and `qvel` of `state` (one joint frame per joint for both).
pub(crate) fn minimal_into(model: &Model, state: &State, qpos: &mut [f64], qvel: &mut [f64]) {
    for (ji, j) in model.joints.iter().enumerate().filter(|(_, j)| !j.is_loop) {
        let frame = JointFrame::new(j, &pose_of(state, j.parent), &pose_of(state, j.child));
        let q = &mut qpos[j.qpos_adr..j.qpos_adr + j.nq()];
        frame.coordinates(j, q);
        wind(model, state, ji, q);
        joint_qvel_in_frame(
            state,
            j,
            &frame,
            &mut qvel[j.qvel_adr..j.qvel_adr + j.nfree()],
        );
    }
}

/// Write `qvel` (length `model.nv`) of `state`.
pub fn qvel_into(model: &Model, state: &State, out: &mut [f64]) {
    for j in model.joints.iter().filter(|j| !j.is_loop) {
        joint_qvel_into(state, j, &mut out[j.qvel_adr..j.qvel_adr + j.nfree()]);
    }
}

/// Write the `nfree` velocity coordinates of joint `j` in `state` (no allocation).
pub(crate) fn joint_qvel_into(state: &State, j: &super::Joint, out: &mut [f64]) {
    let frame = JointFrame::new(j, &pose_of(state, j.parent), &pose_of(state, j.child));
    joint_qvel_in_frame(state, j, &frame, out);
}

/// [`joint_qvel_into`] with the joint's frame at `state` already built.
pub(crate) fn joint_qvel_in_frame(
    state: &State,
    j: &super::Joint,
    frame: &JointFrame,
    out: &mut [f64],
) {
    let mut jac = [0.0; 6 * 12];
    let nf = j.nfree();
    frame.free_jacobian(j, &mut jac[..12 * nf]);
    let (vp, vc) = (velocity_of(state, j.parent), velocity_of(state, j.child));
    for (r, o) in out.iter_mut().enumerate().take(nf) {
        let row = &jac[12 * r..12 * r + 12];
        *o = (0..6).map(|i| row[i] * vp[i] + row[6 + i] * vc[i]).sum();
    }
}

/// `qpos` of `state`.
pub fn qpos(model: &Model, state: &State) -> Vec<f64> {
    let mut q = vec![0.0; model.nq];
    qpos_into(model, state, &mut q);
    q
}

/// `qvel` of `state`.
pub fn qvel(model: &Model, state: &State) -> Vec<f64> {
    let mut v = vec![0.0; model.nv];
    qvel_into(model, state, &mut v);
    v
}

/// Check `qpos`/`qvel` lengths, finiteness and quaternion norms.
pub fn validate_minimal(model: &Model, qpos: &[f64], qvel: &[f64]) -> Result<()> {
    ensure!(
        qpos.len() == model.nq,
        Error::shape("qpos", &[model.nq], &[qpos.len()])
    );
    ensure!(
        qvel.len() == model.nv,
        Error::shape("qvel", &[model.nv], &[qvel.len()])
    );
    Error::check_finite("qpos", qpos)?;
    Error::check_finite("qvel", qvel)?;
    for j in model
        .joints
        .iter()
        .filter(|j| !j.is_loop && j.rot.nq() == 4)
    {
        let a = j.qpos_adr + j.ntrans;
        let n = qpos[a..a + 4].iter().map(|x| x * x).sum::<f64>().sqrt();
        ensure!(
            n > 1e-9,
            Error::input(
                format!("qpos[{a}..{}] (joint {})", a + 4, j.name),
                &qpos[a..a + 4],
                "quaternion must be non-zero"
            )
        );
    }
    Ok(())
}

/// Set body poses and velocities of `state` from minimal coordinates by forward kinematics.
/// Quaternions in `qpos` are normalised. Loop joints are not enforced here: `qpos` must be
/// consistent with them (the solver then keeps them closed).
pub fn set_minimal(model: &Model, state: &mut State, qpos: &[f64], qvel: &[f64]) -> Result<()> {
    validate_minimal(model, qpos, qvel)?;
    forward_kinematics(model, state, qpos, qvel, None);
    Ok(())
}

/// [`set_minimal`] for a `state` that already holds the forward kinematics of coordinates that
/// differ from `(qpos, qvel)` only at the joints `changed(j)`: only those joints and the joints
/// below them are recomputed (bitwise what [`set_minimal`] computes for them; the rest is left
/// as it is). Not validated: for coordinates near ones [`validate_minimal`] accepted (the
/// gradients' partials perturb a few coordinates at a time, ~30 times per linearisation).
pub(crate) fn set_minimal_changed(
    model: &Model,
    state: &mut State,
    qpos: &[f64],
    qvel: &[f64],
    changed: &dyn Fn(usize) -> bool,
) {
    forward_kinematics(model, state, qpos, qvel, Some(changed));
}

fn forward_kinematics(
    model: &Model,
    state: &mut State,
    qpos: &[f64],
    qvel: &[f64],
    changed: Option<&dyn Fn(usize) -> bool>,
) {
    // bodies recomputed so far (their child joints must follow)
    let mut moved = changed.map(|_| vec![false; model.nbody()]);
    for &ji in &model.topology.fk_order {
        let j = &model.joints[ji];
        if let (Some(changed), Some(moved)) = (changed, moved.as_mut()) {
            if !changed(ji) && !moved[j.parent] {
                continue;
            }
            moved[j.child] = true;
        }
        let parent = pose_of(state, j.parent);
        // measured displacement = qpos - qpos_ref (MuJoCo's `ref`)
        let mut q = [0.0; 7];
        for (i, qi) in q[..j.nq()].iter_mut().enumerate() {
            *qi = qpos[j.qpos_adr + i] - j.qpos_ref_at(i);
        }
        let q = &q[..j.nq()];
        let qd = &qvel[j.qvel_adr..j.qvel_adr + j.nfree()];
        let qj = joint_rotation(&j.rot, &q[j.ntrans..]);
        let rot_p = quat::rotation(&parent.quat);
        let rot_pj = rot_p * quat::rotation(&j.offset);
        let child_quat = (parent.quat * j.offset * qj).normalize();
        let rot_c = quat::rotation(&child_quat);
        // Σ_i basis_i q_i over the free translations (no allocation)
        let along = |x: &[f64]| -> Vector3<f64> {
            (0..j.ntrans)
                .map(|i| j.trans_basis.column(i) * x[i])
                .fold(Vector3::zeros(), |a, b| a + b)
        };
        // hinges about offset anchors displace the child anchor by g(θ) (joints::offsets)
        let (g, dg_dtheta) =
            offsets::displacement_at_angles(&j.rot, &j.hinge_offsets, &q[j.ntrans..]);
        let delta = along(q) + g;
        let a_p = parent.pos + rot_p * j.parent_anchor;
        let a_c = a_p + rot_pj * delta;
        let child = Pose {
            pos: a_c - rot_c * j.child_anchor,
            quat: child_quat,
        };
        state.set_pose(j.child, &child);
        // a winding hinge keeps the turns of its qpos beyond the angle its poses give
        if let Some(k) = model.topology.winding_adr[ji] {
            let angle = qpos[j.qpos_adr + j.ntrans];
            let measured = measured_angle(j, &parent, &child);
            let turns = ((angle - measured) / std::f64::consts::TAU).round();
            state.winding[k] = std::f64::consts::TAU * turns;
        }
        // velocities: ω_c = R_jᵀ R_offᵀ ω_p + S qvel_rot;  ȧ_c = ȧ_p + R_pj Δ̇ + ω_p × (R_pj Δ)
        let vp = velocity_of(state, j.parent);
        let (v_p, w_p) = (
            Vector3::new(vp[0], vp[1], vp[2]),
            Vector3::new(vp[3], vp[4], vp[5]),
        );
        let rot_j = quat::rotation(&qj);
        let w_c = rot_j.transpose() * quat::rotation(&j.offset).transpose() * w_p
            + joint_angvel(&j.rot, &qj, &q[j.ntrans..], &qd[j.ntrans..]);
        let ddelta = along(qd)
            + (0..j.rot.nfree().min(3))
                .map(|i| dg_dtheta[i] * qd[j.ntrans + i])
                .sum::<Vector3<f64>>();
        let w_pw = rot_p * w_p;
        let adot_p = v_p + w_pw.cross(&(rot_p * j.parent_anchor));
        let adot_c = adot_p + rot_pj * ddelta + w_pw.cross(&(rot_pj * delta));
        let v_c = adot_c - (rot_c * w_c).cross(&(rot_c * j.child_anchor));
        state.set_velocity(j.child, &v_c, &w_c);
    }
}
