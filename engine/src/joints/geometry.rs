//! Joint geometry at one configuration: constraint values and Jacobians (the `k` of Dojo eq. 13
//! and its map `K`), and the free-coordinate Jacobian used by springs, dampers and inputs.
//!
//! Perturbations of a body are `(δp, δφ)`: world-frame translation of its COM and body-frame
//! rotation `q ⊗ [1, δφ/2]`. Jacobians have 12 columns: parent `(δp, δφ)`, child `(δp, δφ)`.
use nalgebra::{Matrix3, Matrix3x4, SMatrix, Vector3};

use super::{Joint, RotDofs, hinges, offsets};
use crate::math::quat::{self, Quat};
use crate::math::spatial::skew;

/// Pose of a body's centre of mass: world position and orientation.
#[derive(Clone, Copy, Debug)]
pub struct Pose {
    /// COM position, world frame (m).
    pub pos: Vector3<f64>,
    /// Orientation, body to world.
    pub quat: Quat,
}

impl Pose {
    /// The world frame.
    pub fn world() -> Self {
        Pose {
            pos: Vector3::zeros(),
            quat: quat::identity(),
        }
    }
}

/// Row-major `rows × 12` Jacobian block writer.
type Row12 = SMatrix<f64, 1, 12>;

/// Everything a joint needs at one configuration of its two bodies.
pub struct JointFrame {
    rot_p: Matrix3<f64>,
    rot_c: Matrix3<f64>,
    rot_off: Matrix3<f64>,
    /// Parent joint frame to world: `R(q_parent ⊗ offset)`.
    rot_pj: Matrix3<f64>,
    /// Relative rotation `q_joint = offset† ⊗ q_parent† ⊗ q_child`.
    qj: Quat,
    rot_j: Matrix3<f64>,
    /// Anchor displacement in the parent joint frame, `Δ = R_pjᵀ (a_child - a_parent)`.
    delta_raw: Vector3<f64>,
    /// `Δ - g(q_joint)`: the displacement left after hinges about offset anchors ([`offsets`]).
    delta: Vector3<f64>,
    /// `∂g/∂δφ_c` (zero without hinge offsets).
    offset_jac: Matrix3<f64>,
    /// The angles of a three-hinge joint, found on first use (an iterative chart: the
    /// coordinates and the motion subspace both need them).
    angles3: std::cell::OnceCell<[f64; 3]>,
}

impl JointFrame {
    /// Evaluate at the given parent and child COM poses.
    pub fn new(joint: &Joint, parent: &Pose, child: &Pose) -> Self {
        let rot_p = quat::rotation(&parent.quat);
        let rot_c = quat::rotation(&child.quat);
        // most joints have no offset: skip the products with the identity (bit for bit the same)
        let plain = joint.offset == Quat::identity();
        let (rot_off, rot_pj, qj) = if plain {
            (
                Matrix3::identity(),
                rot_p,
                quat::conj(&parent.quat) * child.quat,
            )
        } else {
            let rot_off = quat::rotation(&joint.offset);
            let qj = quat::conj(&joint.offset) * quat::conj(&parent.quat) * child.quat;
            (rot_off, rot_p * rot_off, qj)
        };
        let a_p = parent.pos + rot_p * joint.parent_anchor;
        let a_c = child.pos + rot_c * joint.child_anchor;
        let delta_raw = rot_pj.transpose() * (a_c - a_p);
        let rot_j = quat::rotation(&qj);
        let (g, offset_jac) = if joint.hinge_offsets.is_empty() {
            (Vector3::zeros(), Matrix3::zeros())
        } else {
            offsets::displacement(&joint.rot, &joint.hinge_offsets, &qj, &rot_j)
        };
        JointFrame {
            rot_p,
            rot_c,
            rot_off,
            rot_pj,
            rot_j,
            qj,
            delta_raw,
            delta: delta_raw - g,
            offset_jac,
            angles3: std::cell::OnceCell::new(),
        }
    }

    /// `∂(Δ - g)/∂(δp_p, δφ_p, δp_c, δφ_c)`, 3 × 12.
    fn delta_jacobian(&self, joint: &Joint) -> SMatrix<f64, 3, 12> {
        let t = self.rot_pj.transpose();
        let mut m = SMatrix::<f64, 3, 12>::zeros();
        m.fixed_view_mut::<3, 3>(0, 0).copy_from(&(-t));
        // δΔ = R_pjᵀ R_p skew(r_p) δφ_p + skew(Δ) R_offᵀ δφ_p   (anchor arm and frame rotation)
        // δg = -∂g/∂δφ_c R_jᵀ R_offᵀ δφ_p + ∂g/∂δφ_c δφ_c   (g depends on q_joint only)
        let dg_dc = self.offset_jac;
        let dg_dp = -dg_dc * self.rot_j.transpose() * self.rot_off.transpose();
        let dp = t * self.rot_p * skew(&joint.parent_anchor)
            + skew(&self.delta_raw) * self.rot_off.transpose()
            - dg_dp;
        m.fixed_view_mut::<3, 3>(0, 3).copy_from(&dp);
        m.fixed_view_mut::<3, 3>(0, 6).copy_from(&t);
        m.fixed_view_mut::<3, 3>(0, 9)
            .copy_from(&(-t * self.rot_c * skew(&joint.child_anchor) - dg_dc));
        m
    }

    /// `∂q_joint/∂δφ` for the parent and child (4 × 3 each, wxyz rows).
    fn qj_jacobians(&self) -> (nalgebra::Matrix4x3<f64>, nalgebra::Matrix4x3<f64>) {
        // child: q_j ⊗ [0, δφ/2];  parent: [0, -R_offᵀ δφ/2] ⊗ q_j
        let g_c = quat::lmat(&self.qj) * quat::vt() * 0.5;
        let g_p = -quat::rmat(&self.qj) * quat::vt() * self.rot_off.transpose() * 0.5;
        (g_p, g_c)
    }

    /// Constraint values `k` (length `joint.ncon()`): constrained translations, then rotations.
    pub fn constraint(&self, joint: &Joint, out: &mut [f64]) {
        let t = joint.trans_dual.transpose() * self.delta;
        let mut r = 0;
        for i in joint.ntrans..3 {
            out[r] = t[i];
            r += 1;
        }
        let v = quat::vec(&self.qj);
        match &joint.rot {
            RotDofs::Locked => out[r..r + 3].copy_from_slice(v.as_slice()),
            RotDofs::Hinge { perp, .. } => {
                out[r] = perp[0].dot(&v);
                out[r + 1] = perp[1].dot(&v);
            }
            RotDofs::Universal { a1, a2 } => out[r] = a1.dot(&(self.rot_j * a2)) - a1.dot(a2),
            RotDofs::Ball | RotDofs::Hinges3 { .. } => {}
        }
    }

    /// Constraint Jacobian `∂k/∂(δp_p, δφ_p, δp_c, δφ_c)`, row-major `ncon × 12`.
    pub fn constraint_jacobian(&self, joint: &Joint, out: &mut [f64]) {
        let dt = joint.trans_dual.transpose() * self.delta_jacobian(joint);
        let mut r = 0;
        for i in joint.ntrans..3 {
            out[12 * r..12 * r + 12].copy_from_slice(dt.row(i).transpose().as_slice());
            r += 1;
        }
        let (g_p, g_c) = self.qj_jacobians();
        let vmat: Matrix3x4<f64> = quat::v();
        let mut put = |r: usize, p: Vector3<f64>, c: Vector3<f64>| {
            let row = &mut out[12 * r..12 * r + 12];
            row.fill(0.0);
            row[3..6].copy_from_slice(p.as_slice());
            row[9..12].copy_from_slice(c.as_slice());
        };
        match &joint.rot {
            RotDofs::Locked => {
                let (jp, jc) = (vmat * g_p, vmat * g_c);
                for i in 0..3 {
                    put(r + i, jp.row(i).transpose(), jc.row(i).transpose());
                }
            }
            RotDofs::Hinge { perp, .. } => {
                let (jp, jc) = (vmat * g_p, vmat * g_c);
                for (i, e) in perp.iter().enumerate() {
                    put(r + i, jp.transpose() * e, jc.transpose() * e);
                }
            }
            RotDofs::Universal { a1, a2 } => {
                // k = a1ᵀ R_j a2: child δk = -a1ᵀ R_j skew(a2) δφ_c; parent δk = (a1 × R_j a2)ᵀ R_offᵀ δφ_p
                let c = -(self.rot_j.transpose() * a1).transpose() * skew(a2);
                let p = self.rot_off * a1.cross(&(self.rot_j * a2));
                put(r, p, c.transpose());
            }
            RotDofs::Ball | RotDofs::Hinges3 { .. } => {}
        }
    }

    /// Free-coordinate Jacobian `∂qvel/∂(v_p, ω_p, v_c, ω_c)`, row-major `nfree × 12`
    /// (velocities as perturbation rates: world COM velocity, body-frame angular velocity).
    ///
    /// Translations are exact derivatives of the free components of `Δ`. Rotations map the relative
    /// angular velocity in the child frame, `ω_rel = ω_c - R_jᵀ R_offᵀ ω_p`, through the pseudo-inverse
    /// of the joint's motion subspace `S` (`ω_rel = S qvel_rot`).
    pub fn free_jacobian(&self, joint: &Joint, out: &mut [f64]) {
        if joint.ntrans > 0 {
            let dt = joint.trans_dual.transpose() * self.delta_jacobian(joint);
            for i in 0..joint.ntrans {
                out[12 * i..12 * i + 12].copy_from_slice(dt.row(i).transpose().as_slice());
            }
        }
        let to_child = self.rot_j.transpose() * self.rot_off.transpose();
        let mut r = joint.ntrans;
        let mut put = |s: Vector3<f64>| {
            let mut row = Row12::zeros();
            let p = -(to_child.transpose() * s);
            row.fixed_view_mut::<1, 3>(0, 3).copy_from(&p.transpose());
            row.fixed_view_mut::<1, 3>(0, 9).copy_from(&s.transpose());
            out[12 * r..12 * r + 12].copy_from_slice(row.as_slice());
            r += 1;
        };
        let cols = self.motion_subspace(&joint.rot);
        let n = joint.rot.nfree();
        if Self::orthonormal_subspace(&joint.rot) {
            for s in cols.iter().flatten() {
                put(*s);
            }
        } else {
            // non-orthogonal hinge axes: θ̇ = S⁺ ω_rel (left inverse, not Sᵀ)
            let mut s = [Vector3::zeros(); 3];
            for (k, c) in cols.iter().flatten().enumerate() {
                s[k] = *c;
            }
            let mut rows = [Vector3::zeros(); 3];
            hinges::left_inverse_rows(&s[..n], &mut rows[..n]);
            for row in &rows[..n] {
                put(*row);
            }
        }
    }

    /// [`hinges::hinges3_angles`] of this frame's relative rotation, computed once.
    fn hinges3_angles(&self, axes: &[Vector3<f64>; 3]) -> &[f64; 3] {
        self.angles3
            .get_or_init(|| hinges::hinges3_angles(axes, &self.qj))
    }

    /// Whether the motion subspace has orthonormal columns (then `S⁺ = Sᵀ`).
    fn orthonormal_subspace(rot: &RotDofs) -> bool {
        match rot {
            RotDofs::Universal { a1, a2 } => a1.dot(a2) == 0.0,
            RotDofs::Hinges3 { .. } => false,
            _ => true,
        }
    }

    /// Columns of the rotational motion subspace `S` (child frame), at most three.
    fn motion_subspace(&self, rot: &RotDofs) -> [Option<Vector3<f64>>; 3] {
        match rot {
            RotDofs::Locked => [None, None, None],
            RotDofs::Hinge { axis, .. } => [Some(*axis), None, None],
            RotDofs::Universal { a1, a2 } => [Some(self.rot_j.transpose() * a1), Some(*a2), None],
            RotDofs::Ball => [Some(Vector3::x()), Some(Vector3::y()), Some(Vector3::z())],
            RotDofs::Hinges3 { axes } => {
                let s = hinges::hinges3_subspace(axes, self.hinges3_angles(axes));
                [
                    Some(s.column(0).into()),
                    Some(s.column(1).into()),
                    Some(s.column(2).into()),
                ]
            }
        }
    }

    /// Minimal position coordinates (length `joint.nq()`): free translations, then rotation
    /// coordinates (angles in (-π, π] — or, for a limited angle, within π of its range's
    /// midpoint — or the quaternion `q_joint` for a ball).
    pub fn coordinates(&self, joint: &Joint, out: &mut [f64]) {
        let t = joint.trans_dual.transpose() * self.delta;
        out[..joint.ntrans].copy_from_slice(&t.as_slice()[..joint.ntrans]);
        let r = &mut out[joint.ntrans..];
        match &joint.rot {
            RotDofs::Locked => {}
            RotDofs::Hinge { axis, .. } => {
                let (w, s) = (self.qj.w, axis.dot(&quat::vec(&self.qj)));
                let (w, s) = if w < 0.0 { (-w, -s) } else { (w, s) };
                r[0] = 2.0 * s.atan2(w);
            }
            RotDofs::Universal { a1, a2 } if a1.dot(a2) == 0.0 => {
                let a3 = a1.cross(a2);
                let ra2 = self.rot_j * a2;
                let rta1 = self.rot_j.transpose() * a1;
                r[0] = a3.dot(&ra2).atan2(a2.dot(&ra2));
                r[1] = a3.dot(&rta1).atan2(a1.dot(&rta1));
            }
            RotDofs::Universal { a1, a2 } => {
                r[..2].copy_from_slice(&hinges::universal_angles(a1, a2, &self.rot_j));
            }
            RotDofs::Hinges3 { axes } => {
                r[..3].copy_from_slice(self.hinges3_angles(axes));
            }
            RotDofs::Ball => r[..4].copy_from_slice(quat::wxyz(&self.qj).as_slice()),
        }
        // MuJoCo's `ref`: the reference configuration has qpos = qpos_ref (0 on quaternions)
        for (c, off) in out.iter_mut().zip(&joint.qpos_ref) {
            *c += off;
        }
        // A limited angle is reported on the branch centred on its range, not in (-π, π]: a
        // range wider than π (the A1's hips, -60°..240°) must not see the angle jump by 2π
        // inside it, which the limit rows and position servos would read as a 2π violation
        // (measured: a hip crossing 180° snapped back with +370 J in one step).
        if !matches!(joint.rot, RotDofs::Ball) {
            for &(dof, lo, hi) in &joint.limits {
                if dof >= joint.ntrans && hi - lo < std::f64::consts::TAU {
                    let mid = 0.5 * (lo + hi);
                    out[dof] = mid + wrap_angle(out[dof] - mid);
                }
            }
        }
    }

    /// Generalized spring force per free dof, `-k (θ - θ_ref)` (ball: `-k ⊙ rotvec(q_ref† ⊗ q_j)`).
    pub fn spring_force(&self, joint: &Joint, coords: &[f64], out: &mut [f64]) {
        let nt = joint.ntrans;
        for i in 0..nt {
            out[i] = -joint.stiffness[i] * (coords[i] - joint.spring_ref[i]);
        }
        match &joint.rot {
            RotDofs::Ball => {
                let qref = quat::from_wxyz(&joint.spring_ref[nt..nt + 4]);
                let rv = quat::rotation_vector(&(quat::conj(&qref) * self.qj));
                for i in 0..3 {
                    out[nt + i] = -joint.stiffness[nt + i] * rv[i];
                }
            }
            // a winding hinge's spring sees its turns (coordinates wound by the caller, as
            // MuJoCo's `qpos`); two or three hinges' angles are in (-π, π]
            RotDofs::Hinge { .. } => {
                out[nt] = -joint.stiffness[nt] * (coords[nt] - joint.spring_ref[nt]);
            }
            rot => {
                for i in nt..nt + rot.nfree() {
                    out[i] = -joint.stiffness[i] * wrap_angle(coords[i] - joint.spring_ref[i]);
                }
            }
        }
    }

    /// Parent joint frame to world rotation.
    pub fn rot_pj(&self) -> &Matrix3<f64> {
        &self.rot_pj
    }
}

/// Wrap an angle difference to (-π, π].
pub fn wrap_angle(a: f64) -> f64 {
    let two_pi = std::f64::consts::TAU;
    let w = a - two_pi * (a / two_pi).round();
    if w <= -std::f64::consts::PI {
        w + two_pi
    } else {
        w
    }
}

/// Joint rotation `q_joint` from rotational coordinates (inverse of [`JointFrame::coordinates`]).
pub fn joint_rotation(rot: &RotDofs, q: &[f64]) -> Quat {
    match rot {
        RotDofs::Locked => quat::identity(),
        RotDofs::Hinge { axis, .. } => quat::axis_angle(axis, q[0]),
        RotDofs::Universal { a1, a2 } => quat::axis_angle(a1, q[0]) * quat::axis_angle(a2, q[1]),
        RotDofs::Hinges3 { axes } => hinges::hinges3_rotation(axes, q),
        RotDofs::Ball => quat::from_wxyz(&q[..4]).normalize(),
    }
}

/// Relative angular velocity of the child in its own frame from rotational velocity coordinates,
/// at the rotation coordinates `angles` (those `qj` was made from: a three-hinge joint's motion
/// subspace is taken at them rather than at angles recovered from `qj`).
pub fn joint_angvel(rot: &RotDofs, qj: &Quat, angles: &[f64], qd: &[f64]) -> Vector3<f64> {
    match rot {
        RotDofs::Locked => Vector3::zeros(),
        RotDofs::Hinge { axis, .. } => axis * qd[0],
        RotDofs::Universal { a1, a2 } => quat::rotation(qj).transpose() * a1 * qd[0] + a2 * qd[1],
        RotDofs::Hinges3 { axes } => {
            hinges::hinges3_subspace(axes, angles) * Vector3::new(qd[0], qd[1], qd[2])
        }
        RotDofs::Ball => Vector3::new(qd[0], qd[1], qd[2]),
    }
}
