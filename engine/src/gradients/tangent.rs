//! Tangent spaces of the state: where state perturbations live and how differences of states
//! are measured.
//!
//! * **Minimal** (MuJoCo's `mjd_transitionFD` convention): `(dq, dv)` of size `2 nv`. `dq` adds
//!   to scalar coordinates and rotates ball quaternions in the child frame,
//!   `q ← q ⊗ exp(dq/2)`; `dv` adds to `qvel`.
//! * **Maximal**: per moving body `(δp, δφ, δv, δω)` (12 numbers): world COM displacement,
//!   body-frame rotation `q ← q ⊗ exp(δφ/2)`, world COM velocity and body-frame angular
//!   velocity changes.
use nalgebra::Vector3;

use crate::joints::coordinates::{
    joint_qvel_in_frame, minimal_into, pose_of, qpos_into, qvel_into, set_minimal,
    set_minimal_changed,
};
use crate::joints::geometry::JointFrame;
use crate::math::quat;
use crate::model::Model;
use crate::state::State;

/// Which coordinates Jacobians and adjoints use.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Coordinates {
    /// `(dq, dv)`, size `2 nv` (MuJoCo's convention).
    Minimal,
    /// `(δp, δφ, δv, δω)` per moving body, size `12 (nbody - 1)`.
    Maximal,
}

impl Coordinates {
    /// Size of the state tangent.
    pub fn dim(self, model: &Model) -> usize {
        match self {
            Coordinates::Minimal => 2 * model.nv,
            Coordinates::Maximal => 12 * (model.nbody() - 1),
        }
    }
    /// Parse `"minimal"` / `"maximal"`.
    pub fn from_name(name: &str) -> Option<Coordinates> {
        match name {
            "minimal" => Some(Coordinates::Minimal),
            "maximal" => Some(Coordinates::Maximal),
            _ => None,
        }
    }
}

/// Exponential map of a rotation vector as a unit quaternion.
fn exp_rot(phi: &Vector3<f64>) -> quat::Quat {
    let a = phi.norm();
    if a < 1e-300 {
        return quat::identity();
    }
    quat::axis_angle(&(phi / a), a)
}

/// `qpos ⊕ dq` (MuJoCo's `mj_integratePos` with unit time).
pub fn integrate_qpos(model: &Model, qpos: &mut [f64], dq: &[f64]) {
    for j in model.joints.iter().filter(|j| !j.is_loop) {
        let (qa, va) = (j.qpos_adr, j.qvel_adr);
        if j.rot.nq() == 4 {
            for i in 0..j.ntrans {
                qpos[qa + i] += dq[va + i];
            }
            let a = qa + j.ntrans;
            let d = Vector3::new(
                dq[va + j.ntrans],
                dq[va + j.ntrans + 1],
                dq[va + j.ntrans + 2],
            );
            // an unperturbed quaternion stays bitwise as it is (the partials' row supports
            // are found by comparing perturbed states with the base state)
            if d != Vector3::zeros() {
                let q = (quat::from_wxyz(&qpos[a..a + 4]) * exp_rot(&d)).normalize();
                qpos[a..a + 4].copy_from_slice(quat::wxyz(&q).as_slice());
            }
        } else {
            for i in 0..j.nfree() {
                qpos[qa + i] += dq[va + i];
            }
        }
    }
}

/// `qpos1 ⊖ qpos0`, the `dq` with `qpos0 ⊕ dq = qpos1` (MuJoCo's `mj_differentiatePos`).
pub fn difference_qpos(model: &Model, qpos0: &[f64], qpos1: &[f64], dq: &mut [f64]) {
    for j in model.joints.iter().filter(|j| !j.is_loop) {
        let (qa, va) = (j.qpos_adr, j.qvel_adr);
        let (nq, nf) = (j.nq(), j.nfree());
        joint_difference(
            j,
            &qpos0[qa..qa + nq],
            &qpos1[qa..qa + nq],
            &mut dq[va..va + nf],
        );
    }
}

/// One joint's `q1 ⊖ q0` (its `nq` coordinates to its `nfree` tangent entries).
fn joint_difference(j: &crate::joints::Joint, q0: &[f64], q1: &[f64], dq: &mut [f64]) {
    if j.rot.nq() == 4 {
        for i in 0..j.ntrans {
            dq[i] = q1[i] - q0[i];
        }
        let a = j.ntrans;
        let (r0, r1) = (
            quat::from_wxyz(&q0[a..a + 4]).normalize(),
            quat::from_wxyz(&q1[a..a + 4]).normalize(),
        );
        let r = quat::rotation_vector(&(quat::conj(&r0) * r1));
        dq[j.ntrans..j.ntrans + 3].copy_from_slice(r.as_slice());
    } else {
        for i in 0..j.nfree() {
            dq[i] = q1[i] - q0[i];
        }
        // a winding hinge's angle measured from poses has no turns: differences are small
        if j.winds() {
            let a = j.ntrans;
            dq[a] = crate::joints::geometry::wrap_angle(q1[a] - q0[a]);
        }
    }
}

/// A state as a point of the chosen coordinates, able to take perturbations and measure
/// differences. Minimal points re-create the maximal state by forward kinematics.
#[derive(Clone, Debug)]
pub(crate) struct Point {
    pub coords: Coordinates,
    pub qpos: Vec<f64>,
    pub qvel: Vec<f64>,
    pub state: State,
}

impl Point {
    /// The point of `state` in `coords`. In minimal coordinates the maximal state is rebuilt
    /// from `(qpos, qvel)` (velocities consistent with the joints at this configuration), so
    /// the linearised map is exactly `x ↦ minimal(step(maximal(x)))`.
    pub fn new(model: &Model, state: &State, coords: Coordinates) -> crate::Result<Point> {
        Point::from_state(model, state.clone(), coords)
    }

    /// [`Point::new`] taking the state (no copy of its inequality variables).
    pub(crate) fn from_state(
        model: &Model,
        mut state: State,
        coords: Coordinates,
    ) -> crate::Result<Point> {
        let mut qpos = vec![0.0; model.nq];
        let mut qvel = vec![0.0; model.nv];
        qpos_into(model, &state, &mut qpos);
        qvel_into(model, &state, &mut qvel);
        if coords == Coordinates::Minimal {
            set_minimal(model, &mut state, &qpos, &qvel)?;
        }
        Ok(Point {
            coords,
            qpos,
            qvel,
            state,
        })
    }

    /// Write the state perturbed by `eps · dir` (a tangent vector) into `out` (which must be
    /// a clone of `self.state`; only poses and velocities are written).
    pub fn perturbed(
        &self,
        model: &Model,
        dir: &[f64],
        eps: f64,
        out: &mut State,
        scratch: &mut [f64],
    ) {
        match self.coords {
            Coordinates::Minimal => {
                let nv = model.nv;
                let (qpos, rest) = scratch.split_at_mut(model.nq);
                let (qvel, dq) = rest.split_at_mut(nv);
                qpos.copy_from_slice(&self.qpos);
                for i in 0..nv {
                    dq[i] = eps * dir[i];
                    qvel[i] = self.qvel[i] + eps * dir[nv + i];
                }
                integrate_qpos(model, qpos, &dq[..nv]);
                // only the joints whose coordinates move, and those below them, are recomputed
                // (`out` holds this point's forward kinematics)
                let changed = |ji: usize| {
                    let j = &model.joints[ji];
                    eps != 0.0
                        && (j.qvel_adr..j.qvel_adr + j.nfree())
                            .any(|i| dir[i] != 0.0 || dir[nv + i] != 0.0)
                };
                // inputs were validated when the point was made; perturbations stay finite
                set_minimal_changed(model, out, qpos, qvel, &changed);
            }
            Coordinates::Maximal => {
                for b in 1..model.nbody() {
                    let d = &dir[12 * (b - 1)..12 * b];
                    if eps == 0.0 || d.iter().all(|&x| x == 0.0) {
                        continue; // unperturbed bodies stay bitwise as they are
                    }
                    let mut pose = self.state.pose(b);
                    let (v, w) = self.state.velocity(b);
                    let dv = |k: usize| Vector3::new(d[k], d[k + 1], d[k + 2]) * eps;
                    pose.pos += dv(0);
                    // (a velocity direction leaves the orientation's bits as they are)
                    if d[3..6].iter().any(|&x| x != 0.0) {
                        pose.quat = (pose.quat * exp_rot(&dv(3))).normalize();
                    }
                    out.set_pose(b, &pose);
                    out.set_velocity(b, &(v + dv(6)), &(w + dv(9)));
                }
            }
        }
    }

    /// Tangent coordinates of `state` relative to this point: `state ⊖ self`, written to `out`
    /// (length `coords.dim(model)`).
    pub fn difference(&self, model: &Model, state: &State, out: &mut [f64], scratch: &mut [f64]) {
        match self.coords {
            Coordinates::Minimal => {
                let nv = model.nv;
                let qpos = &mut scratch[..model.nq];
                let (dq, dv) = out.split_at_mut(nv);
                minimal_into(model, state, qpos, dv);
                difference_qpos(model, &self.qpos, qpos, dq);
                for (d, v0) in dv.iter_mut().zip(&self.qvel) {
                    *d -= v0;
                }
            }
            Coordinates::Maximal => {
                for b in 1..model.nbody() {
                    let o = &mut out[12 * (b - 1)..12 * b];
                    let (p0, p1) = (self.state.pose(b), state.pose(b));
                    let (v0, w0) = self.state.velocity(b);
                    let (v1, w1) = state.velocity(b);
                    let dp = p1.pos - p0.pos;
                    let dphi = quat::rotation_vector(&(quat::conj(&p0.quat) * p1.quat));
                    for (k, x) in [dp, dphi, v1 - v0, w1 - w0].iter().enumerate() {
                        o[3 * k..3 * k + 3].copy_from_slice(x.as_slice());
                    }
                }
            }
        }
    }

    /// [`Point::difference`] on the rows of the joints flagged in `joints` only (minimal
    /// coordinates; in maximal ones every row is written). The other rows of `out` are left as
    /// they are.
    pub fn difference_joints(
        &self,
        model: &Model,
        state: &State,
        joints: &[bool],
        out: &mut [f64],
        scratch: &mut [f64],
    ) {
        if self.coords == Coordinates::Maximal {
            return self.difference(model, state, out, scratch);
        }
        let nv = model.nv;
        let (dq, dv) = out.split_at_mut(nv);
        for (ji, j) in model.joints.iter().enumerate() {
            if j.is_loop || !joints[ji] {
                continue;
            }
            let (qa, va, nq, nf) = (j.qpos_adr, j.qvel_adr, j.nq(), j.nfree());
            let parent = pose_of(state, j.parent);
            let child = pose_of(state, j.child);
            let q1 = &mut scratch[qa..qa + nq];
            let frame = JointFrame::new(j, &parent, &child);
            frame.coordinates(j, q1);
            joint_difference(j, &self.qpos[qa..qa + nq], q1, &mut dq[va..va + nf]);
            joint_qvel_in_frame(state, j, &frame, &mut dv[va..va + nf]);
            for (d, v0) in dv[va..va + nf].iter_mut().zip(&self.qvel[va..va + nf]) {
                *d -= v0;
            }
        }
    }

    /// Scratch length needed by [`Point::perturbed`] and [`Point::difference`].
    pub fn scratch_len(model: &Model) -> usize {
        model.nq + 2 * model.nv
    }
}

/// `state ⊕ eps · dir` in `coords` (for minimal coordinates the result is rebuilt from the
/// perturbed `(qpos, qvel)` by forward kinematics).
pub fn perturb(
    model: &Model,
    state: &State,
    coords: Coordinates,
    dir: &[f64],
    eps: f64,
) -> crate::Result<State> {
    crate::ensure!(
        dir.len() == coords.dim(model),
        crate::Error::shape("dir", &[coords.dim(model)], &[dir.len()])
    );
    let p = Point::new(model, state, coords)?;
    let mut out = p.state.clone();
    let mut scratch = vec![0.0; Point::scratch_len(model)];
    p.perturbed(model, dir, eps, &mut out, &mut scratch);
    Ok(out)
}

/// `state ⊖ base` in `coords` (length `coords.dim(model)`).
pub fn difference(
    model: &Model,
    base: &State,
    state: &State,
    coords: Coordinates,
) -> crate::Result<Vec<f64>> {
    state.check_model(model)?;
    let mut p = Point::new(model, base, Coordinates::Maximal)?;
    p.coords = coords;
    p.state = base.clone();
    let mut out = vec![0.0; coords.dim(model)];
    let mut scratch = vec![0.0; Point::scratch_len(model)];
    p.difference(model, state, &mut out, &mut scratch);
    Ok(out)
}

/// Chain an adjoint from the tangent `dq` (length nv) to raw `qpos` (length nq): scalar
/// coordinates copy; a quaternion `q` (used normalised, `q̂ = q/|q|`, perturbed as
/// `q̂ ⊗ exp(δ/2)`) gets `(2/|q|) L(q̂) Vᵀ adj_δ`, since `δ = (2/|q|) V L(q̂)ᵀ dq`.
pub fn qpos_adjoint_from_tangent(model: &Model, qpos: &[f64], adj_dq: &[f64], out: &mut [f64]) {
    for j in model.joints.iter().filter(|j| !j.is_loop) {
        let (qa, va) = (j.qpos_adr, j.qvel_adr);
        if j.rot.nq() == 4 {
            out[qa..qa + j.ntrans].copy_from_slice(&adj_dq[va..va + j.ntrans]);
            let (a, v) = (qa + j.ntrans, va + j.ntrans);
            let q = quat::from_wxyz(&qpos[a..a + 4]);
            let n = q.norm().max(1e-300);
            let g = quat::lmat(&(q / n)) * quat::vt() * (2.0 / n);
            let r = g * Vector3::new(adj_dq[v], adj_dq[v + 1], adj_dq[v + 2]);
            out[a..a + 4].copy_from_slice(r.as_slice());
        } else {
            out[qa..qa + j.nfree()].copy_from_slice(&adj_dq[va..va + j.nfree()]);
        }
    }
}

/// Chain an adjoint from raw `qpos` (length nq, at a unit-quaternion configuration) to the
/// tangent `dq` (length nv): a quaternion gives `½ V L(q)ᵀ adj_q` (`dq_raw = ½ L(q) Vᵀ δ`).
pub fn tangent_adjoint_from_qpos(model: &Model, qpos: &[f64], adj_qpos: &[f64], out: &mut [f64]) {
    for j in model.joints.iter().filter(|j| !j.is_loop) {
        let (qa, va) = (j.qpos_adr, j.qvel_adr);
        if j.rot.nq() == 4 {
            out[va..va + j.ntrans].copy_from_slice(&adj_qpos[qa..qa + j.ntrans]);
            let (a, v) = (qa + j.ntrans, va + j.ntrans);
            let q = quat::from_wxyz(&qpos[a..a + 4]);
            let g = quat::v() * quat::lmat(&q).transpose() * 0.5;
            let r = g * nalgebra::Vector4::new(
                adj_qpos[a],
                adj_qpos[a + 1],
                adj_qpos[a + 2],
                adj_qpos[a + 3],
            );
            out[v..v + 3].copy_from_slice(r.as_slice());
        } else {
            out[va..va + j.nfree()].copy_from_slice(&adj_qpos[qa..qa + j.nfree()]);
        }
    }
}

/// Map a tangent `dq` (length nv) at `qpos` to a raw `qpos` change (length nq): quaternions
/// move by `½ L(q) Vᵀ δ` (`q ⊗ exp(δ/2)` to first order), scalar coordinates copy.
pub fn qpos_raw_from_tangent(model: &Model, qpos: &[f64], dq: &[f64], out: &mut [f64]) {
    for j in model.joints.iter().filter(|j| !j.is_loop) {
        let (qa, va) = (j.qpos_adr, j.qvel_adr);
        if j.rot.nq() == 4 {
            out[qa..qa + j.ntrans].copy_from_slice(&dq[va..va + j.ntrans]);
            let (a, v) = (qa + j.ntrans, va + j.ntrans);
            let q = quat::from_wxyz(&qpos[a..a + 4]);
            let r = quat::lmat(&q) * quat::vt() * Vector3::new(dq[v], dq[v + 1], dq[v + 2]) * 0.5;
            out[a..a + 4].copy_from_slice(r.as_slice());
        } else {
            out[qa..qa + j.nfree()].copy_from_slice(&dq[va..va + j.nfree()]);
        }
    }
}

/// Map a raw `qpos` change (length nq) at `qpos` to the tangent `dq` (length nv) of the
/// normalised configuration: quaternions give `(2/|q|) V L(q̂)ᵀ dq_raw`.
pub fn qpos_tangent_from_raw(model: &Model, qpos: &[f64], dq_raw: &[f64], out: &mut [f64]) {
    for j in model.joints.iter().filter(|j| !j.is_loop) {
        let (qa, va) = (j.qpos_adr, j.qvel_adr);
        if j.rot.nq() == 4 {
            out[va..va + j.ntrans].copy_from_slice(&dq_raw[qa..qa + j.ntrans]);
            let (a, v) = (qa + j.ntrans, va + j.ntrans);
            let q = quat::from_wxyz(&qpos[a..a + 4]);
            let n = q.norm().max(1e-300);
            let g = quat::v() * quat::lmat(&(q / n)).transpose() * (2.0 / n);
            let r =
                g * nalgebra::Vector4::new(dq_raw[a], dq_raw[a + 1], dq_raw[a + 2], dq_raw[a + 3]);
            out[v..v + 3].copy_from_slice(r.as_slice());
        } else {
            out[va..va + j.nfree()].copy_from_slice(&dq_raw[qa..qa + j.nfree()]);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::{BodySpec, JointKind, JointSpec, ModelBuilder};

    #[test]
    fn integrate_and_difference_are_inverse() {
        let model = ModelBuilder::new()
            .body(BodySpec::new("a", 1.0, [0.1, 0.2, 0.3]).pos([0.0, 0.0, 1.0]))
            .body(BodySpec::new("b", 1.0, [0.1, 0.2, 0.3]).pos([0.0, 0.0, 0.5]))
            .joint(JointSpec::new("free", JointKind::Floating, "world", "a"))
            .joint(
                JointSpec::new("hinge", JointKind::Revolute, "a", "b")
                    .axis([0.0, 1.0, 0.0])
                    .anchors([0.0, 0.0, -0.25], [0.0, 0.0, 0.25]),
            )
            .compile()
            .unwrap();
        let mut q = model.qpos0.clone();
        let dq = [0.1, -0.2, 0.3, 0.4, -0.5, 0.6, 0.7];
        integrate_qpos(&model, &mut q, &dq);
        let mut back = [0.0; 7];
        difference_qpos(&model, &model.qpos0, &q, &mut back);
        for i in 0..7 {
            assert!((back[i] - dq[i]).abs() < 1e-12, "{i}: {back:?}");
        }
    }

    /// A wound hinge (two turns on) measured against its own point: the rows that measure the
    /// joint from poses alone (`difference_joints`) see no difference, not -2 turns.
    #[test]
    fn differences_of_a_wound_hinge_have_no_turns() {
        let model = ModelBuilder::new()
            .body(BodySpec::new("b", 1.0, [0.1, 0.2, 0.3]))
            .joint(JointSpec::new("hinge", JointKind::Revolute, "world", "b"))
            .compile()
            .unwrap();
        let mut state = State::reference(&model);
        set_minimal(
            &model,
            &mut state,
            &[0.5 + 2.0 * std::f64::consts::TAU],
            &[1.0],
        )
        .unwrap();
        let point = Point::new(&model, &state, Coordinates::Minimal).unwrap();
        let mut out = vec![1.0; 2];
        let mut scratch = vec![0.0; Point::scratch_len(&model)];
        point.difference_joints(&model, &state, &[true], &mut out, &mut scratch);
        assert!(out.iter().all(|d| d.abs() < 1e-12), "{out:?}");
        point.difference(&model, &state, &mut out, &mut scratch);
        assert!(out.iter().all(|d| d.abs() < 1e-12), "{out:?}");
    }
}
