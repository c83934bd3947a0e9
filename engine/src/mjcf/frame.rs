//! Poses of MJCF elements: `pos` and one of `quat`, `axisangle`, `euler` (with
//! `compiler/@eulerseq`), `xyaxes`, `zaxis`; and `fromto` for capsules, cylinders, boxes and
//! ellipsoids.
use nalgebra::{Matrix3, Rotation3, UnitQuaternion, Vector3};
use roxmltree::Node;

use super::parse::Ctx;
use crate::Result;
use crate::math::quat::{self, Quat};

/// A rigid transform: `x_parent = pos + R(quat) x_local`.
#[derive(Clone, Copy, Debug)]
pub(super) struct Frame {
    pub pos: Vector3<f64>,
    pub quat: Quat,
}

impl Frame {
    pub fn identity() -> Self {
        Frame {
            pos: Vector3::zeros(),
            quat: quat::identity(),
        }
    }
    /// `self ∘ local`.
    pub fn compose(&self, local: &Frame) -> Frame {
        Frame {
            pos: self.pos + quat::rotation(&self.quat) * local.pos,
            quat: (self.quat * local.quat).normalize(),
        }
    }
    /// `self⁻¹ ∘ other`: `other` expressed in this frame.
    pub fn relative(&self, other: &Frame) -> Frame {
        let rt = quat::rotation(&self.quat).transpose();
        Frame {
            pos: rt * (other.pos - self.pos),
            quat: (quat::conj(&self.quat) * other.quat).normalize(),
        }
    }
    /// A point given in this frame, in the parent frame.
    pub fn point(&self, p: &Vector3<f64>) -> Vector3<f64> {
        self.pos + quat::rotation(&self.quat) * p
    }
    /// A point of the parent frame in this frame.
    pub fn inverse_point(&self, p: &Vector3<f64>) -> Vector3<f64> {
        quat::rotation(&self.quat).transpose() * (p - self.pos)
    }
    pub fn wxyz(&self) -> [f64; 4] {
        let q = quat::wxyz(&self.quat);
        [q[0], q[1], q[2], q[3]]
    }
}

/// Unit quaternion rotating +z onto `v` by the shortest arc (MuJoCo's `z2quat`).
pub(super) fn z_to(v: &Vector3<f64>) -> Quat {
    let n = v.norm();
    let d = v / n;
    let c = d[2];
    if c < -1.0 + 1e-14 {
        return Quat::new(0.0, 1.0, 0.0, 0.0);
    }
    let axis = Vector3::z().cross(&d);
    Quat::new(1.0 + c, axis[0], axis[1], axis[2]).normalize()
}

fn from_matrix(m: &Matrix3<f64>) -> Quat {
    let r = Rotation3::from_matrix_unchecked(*m);
    let q = UnitQuaternion::from_rotation_matrix(&r);
    q.into_inner()
}

/// Orientation of `node` from its orientation attributes (identity if none).
pub(super) fn orientation<'a, 'i>(
    ctx: &Ctx<'a, 'i>,
    node: Node<'a, 'i>,
    class: &str,
) -> Result<Quat> {
    let given: Vec<&str> = ["quat", "axisangle", "euler", "xyaxes", "zaxis"]
        .into_iter()
        .filter(|a| node.attribute(*a).is_some())
        .collect();
    if given.len() > 1 {
        return Err(ctx.err(
            node,
            format!("orientation given more than once ({})", given.join(", ")),
        ));
    }
    // defaults may carry an orientation only for geoms/sites (rare): element attributes first
    let pick = |a: &str| {
        given.first().is_some_and(|g| *g == a)
            || (given.is_empty() && ctx.raw(node, class, a).is_some())
    };
    if pick("quat") {
        let q = ctx.nums(node, class, "quat", 4)?.unwrap_or_default();
        let n = q.iter().map(|x| x * x).sum::<f64>().sqrt();
        if n < 1e-12 {
            return Err(ctx.err(node, format!("attribute `quat` = {q:?}: zero quaternion")));
        }
        return Ok(Quat::new(q[0], q[1], q[2], q[3]) / n);
    }
    if pick("axisangle") {
        let a = ctx.nums(node, class, "axisangle", 4)?.unwrap_or_default();
        let axis = Vector3::new(a[0], a[1], a[2]);
        if axis.norm() < 1e-12 {
            return Err(ctx.err(node, format!("attribute `axisangle` = {a:?}: zero axis")));
        }
        return Ok(quat::axis_angle(&axis.normalize(), ctx.angle(a[3])));
    }
    if pick("euler") {
        let e = ctx.nums(node, class, "euler", 3)?.unwrap_or_default();
        let mut q = quat::identity();
        for (i, &c) in ctx.compiler.eulerseq.iter().enumerate() {
            let axis = match c.to_ascii_lowercase() {
                b'x' => Vector3::x(),
                b'y' => Vector3::y(),
                _ => Vector3::z(),
            };
            let r = quat::axis_angle(&axis, ctx.angle(e[i]));
            // lower case: axes move with the frame (intrinsic, post-multiply)
            q = if c.is_ascii_lowercase() { q * r } else { r * q };
        }
        return Ok(q.normalize());
    }
    if pick("xyaxes") {
        let a = ctx.nums(node, class, "xyaxes", 6)?.unwrap_or_default();
        let x = Vector3::new(a[0], a[1], a[2]);
        let y = Vector3::new(a[3], a[4], a[5]);
        let xn = x.norm();
        let y = y - x * (x.dot(&y) / (xn * xn).max(1e-300));
        if xn < 1e-12 || y.norm() < 1e-12 {
            return Err(ctx.err(node, format!("attribute `xyaxes` = {a:?}: degenerate axes")));
        }
        let (x, y) = (x / xn, y.normalize());
        return Ok(from_matrix(&Matrix3::from_columns(&[x, y, x.cross(&y)])));
    }
    if pick("zaxis") {
        let z = ctx.nums(node, class, "zaxis", 3)?.unwrap_or_default();
        let v = Vector3::new(z[0], z[1], z[2]);
        if v.norm() < 1e-12 {
            return Err(ctx.err(node, format!("attribute `zaxis` = {z:?}: zero vector")));
        }
        return Ok(z_to(&v));
    }
    Ok(quat::identity())
}

/// `pos` and orientation of `node` relative to its parent.
pub(super) fn local_frame<'a, 'i>(
    ctx: &Ctx<'a, 'i>,
    node: Node<'a, 'i>,
    class: &str,
) -> Result<Frame> {
    let pos = ctx.nums(node, class, "pos", 3)?.unwrap_or(vec![0.0; 3]);
    Ok(Frame {
        pos: Vector3::new(pos[0], pos[1], pos[2]),
        quat: orientation(ctx, node, class)?,
    })
}
