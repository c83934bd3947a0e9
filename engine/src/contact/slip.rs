//! The no-slip measure of a contact candidate for one step: the tangential velocity that the
//! friction cone's rows `η₂:₃ = v_t` hold at zero when the contact sticks.
//!
//! **Rolling-consistent.** Each side of a candidate is a *core* point fixed in its body (a
//! ball's centre, a capsule's axis point, a box corner) and a rounding radius `r` (the ball's;
//! 0 for a corner or a rim point), the contact point lying `r` from the core along the normal.
//! The side's velocity over the step is the core's exact displacement to the next pose over
//! `h` plus the arc rolled about the contact, `ω × (p − c)`:
//!
//! ```text
//! V = (c⁺ − c) / h + ω × (p − c) = v + R [ c_h (ω × ρ) + (h/2) ω × (ω × ρ) + ω × e ]
//! ```
//!
//! (`ρ`, `e` the core and the contact point's offset from it in the body frame, `c_h =
//! sqrt(1 − |hω/2|²)`: `q⁺ = q ⊗ (c_h, hω/2)`), and `v_t` is the tangential part of
//! `V_a − V_b` along the current contact frame.
//!
//! Why not the contact point's velocity `v + ω × (p − x)` at the current pose: its normal
//! part is only the first-order rate of the gap, which the step enforces exactly at the next
//! pose. Sticking (`v_t = 0`) and the gap (`φ⁺ = 0`) then are three independent conditions
//! where the continuous ones, `ω × (p − a) = 0` for a ball on a ball joint at `a`, are two:
//! they leave the spin about the line from `a` to the contact free (a cone rolling on its
//! tip). A capsule wedged against the floor and spinning about that line could then neither
//! stick nor slide (no contact impulse has a moment about the line) and the step had no
//! solution (random stress scene 701). Here the normal part of `V` is exactly the core's
//! height change, so a rolling ball that keeps its gap sticks along a one-parameter family, as
//! in continuous time; to first order in `h` both measures are the contact point's velocity.
use nalgebra::Vector3;

use super::geometry::Witness;
use crate::joints::geometry::Pose;
use crate::math::quat;
use crate::math::spatial::basis_from_axis;

/// One body's side of a candidate (see the module docs).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
struct Side {
    /// Core point in the body frame, relative to the centre of mass.
    core: Vector3<f64>,
    /// Contact point minus core, body frame.
    offset: Vector3<f64>,
    /// The two tangents in the body frame (`Rᵀ t_k`, current pose).
    tangents: [Vector3<f64>; 2],
}

impl Side {
    fn new(body: &Pose, point: &Vector3<f64>, offset: Vector3<f64>, t: &[Vector3<f64>; 2]) -> Self {
        let rt = quat::rotation(&body.quat).transpose();
        Side {
            core: rt * (point - offset - body.pos),
            offset: rt * offset,
            tangents: [rt * t[0], rt * t[1]],
        }
    }

    /// The body-frame motion of the contact relative to the centre of mass, `f = c_h (ω × ρ) +
    /// (h/2) ω × (ω × ρ) + ω × e` (`t_k · V = t_k · v + (Rᵀt_k) · f`), at body angular velocity
    /// `w`.
    fn turning(&self, h: f64, w: &Vector3<f64>) -> Vector3<f64> {
        let (rho, e) = (&self.core, &self.offset);
        let c = (1.0 - (w * (0.5 * h)).norm_squared()).max(1e-300).sqrt();
        let wr = w.cross(rho);
        c * wr + (0.5 * h) * w.cross(&wr) + w.cross(e)
    }

    /// `∂((Rᵀt_k) · f)/∂w` (see [`Side::turning`]).
    fn turning_gradient(&self, h: f64, w: &Vector3<f64>, k: usize) -> Vector3<f64> {
        let (rho, e, u) = (&self.core, &self.offset, &self.tangents[k]);
        let c = (1.0 - (w * (0.5 * h)).norm_squared()).max(1e-300).sqrt();
        let wr = w.cross(rho);
        c * rho.cross(u)
            - (h * h / (4.0 * c)) * u.dot(&wr) * w
            - (0.5 * h) * (u.cross(&wr) + u.cross(w).cross(rho))
            - u.cross(e)
    }
}

/// The no-slip measure of one candidate for one step, built at the step's current pose.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Slip {
    /// Tangents `t₁`, `t₂` of the current contact frame (world).
    tangents: [Vector3<f64>; 2],
    /// Body a's and body b's sides.
    sides: [Side; 2],
}

impl Slip {
    /// From the candidate's witness at the current poses of its bodies and its rounding radii
    /// `(r_a, r_b)` ([`super::Contact::radii`]).
    pub fn new(w: &Witness, radii: (f64, f64), body_a: &Pose, body_b: &Pose) -> Self {
        let basis = basis_from_axis(&w.normal);
        let t = [basis.column(1).into_owned(), basis.column(2).into_owned()];
        // the normal points from b to a: a's contact point lies r_a below its core, b's above
        Slip {
            tangents: t,
            sides: [
                Side::new(body_a, &w.point_a, -radii.0 * w.normal, &t),
                Side::new(body_b, &w.point_b, radii.1 * w.normal, &t),
            ],
        }
    }

    /// Tangential slip `t_k · (V_a − V_b)`, `k` = 0, 1, at the next midpoint velocities
    /// `(v, ω_body)` of body a and body b.
    pub fn tangential(&self, h: f64, motion: &[(Vector3<f64>, Vector3<f64>); 2]) -> [f64; 2] {
        let mut slip = [0.0; 2];
        for (side, sign) in [(0, 1.0), (1, -1.0)] {
            let (v, w) = &motion[side];
            let f = self.sides[side].turning(h, w);
            for (k, s) in slip.iter_mut().enumerate() {
                *s += sign * (self.tangents[k].dot(v) + self.sides[side].tangents[k].dot(&f));
            }
        }
        slip
    }

    /// Rows `∂/∂(v_a, ω_a, v_b, ω_b)` of [`Slip::tangential`].
    pub fn rows(&self, h: f64, motion: &[(Vector3<f64>, Vector3<f64>); 2]) -> [[f64; 12]; 2] {
        let mut rows = [[0.0; 12]; 2];
        for (k, row) in rows.iter_mut().enumerate() {
            let t = &self.tangents[k];
            for (side, sign) in [(0, 1.0), (1, -1.0)] {
                let grad = self.sides[side].turning_gradient(h, &motion[side].1, k);
                for i in 0..3 {
                    row[6 * side + i] = sign * t[i];
                    row[6 * side + 3 + i] = sign * grad[i];
                }
            }
        }
        rows
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::math::quat::step_map;
    use nalgebra::UnitQuaternion;

    fn pose(p: [f64; 3], axis: [f64; 3], angle: f64) -> Pose {
        let q = UnitQuaternion::from_axis_angle(
            &nalgebra::Unit::new_normalize(Vector3::from(axis)),
            angle,
        );
        Pose {
            pos: Vector3::from(p),
            quat: *q.quaternion(),
        }
    }

    fn witness(pa: [f64; 3], pb: [f64; 3], n: [f64; 3]) -> Witness {
        let normal = Vector3::from(n).normalize();
        Witness {
            phi: (Vector3::from(pa) - Vector3::from(pb)).dot(&normal),
            point_a: Vector3::from(pa),
            point_b: Vector3::from(pb),
            normal,
        }
    }

    /// Two tilted bodies, a witness between them, radii (0.05, 0.02).
    fn scene() -> (Pose, Pose, Witness, (f64, f64)) {
        (
            pose([0.1, -0.2, 0.4], [1.0, 2.0, 0.5], 0.7),
            pose([0.0, 0.3, -0.1], [0.0, 1.0, 1.0], -0.4),
            witness([0.05, 0.0, 0.02], [0.05, 0.01, -0.01], [0.2, 0.1, 1.0]),
            (0.05, 0.02),
        )
    }

    /// Velocities `(v_a, ω_a, v_b, ω_b)` of the test bodies.
    const MOTION: [f64; 12] = [
        0.3, -1.0, 0.2, 4.0, -7.0, 2.0, -0.5, 0.1, 0.7, -3.0, 1.0, 9.0,
    ];

    fn motion(x: &[f64; 12]) -> [(Vector3<f64>, Vector3<f64>); 2] {
        let v = |i: usize| Vector3::new(x[i], x[i + 1], x[i + 2]);
        [(v(0), v(3)), (v(6), v(9))]
    }

    #[test]
    fn slip_is_the_core_displacement_plus_the_rolled_arc() {
        // V_a = (c⁺ − c)/h + ω × (p − c) with c⁺ from the integrator's own pose update
        let h = 0.01;
        let (a, b, w, (ra, rb)) = scene();
        let slip = Slip::new(&w, (ra, rb), &a, &b);
        let motion = motion(&MOTION);
        let side_velocity = |body: &Pose,
                             (v, om): &(Vector3<f64>, Vector3<f64>),
                             point: Vector3<f64>,
                             off: Vector3<f64>| {
            let core = point - off;
            let next = Pose {
                pos: body.pos + h * v,
                quat: body.quat * step_map(om, h),
            };
            let rho = quat::rotation(&body.quat).transpose() * (core - body.pos);
            let core_next = next.pos + quat::rotation(&next.quat) * rho;
            (core_next - core) / h + (quat::rotation(&body.quat) * om).cross(&off)
        };
        let va = side_velocity(&a, &motion[0], w.point_a, -ra * w.normal);
        let vb = side_velocity(&b, &motion[1], w.point_b, rb * w.normal);
        let basis = basis_from_axis(&w.normal);
        for k in 0..2 {
            let want = basis.column(k + 1).dot(&(va - vb));
            let got = slip.tangential(h, &motion)[k];
            assert!(
                (got - want).abs() < 1e-12 * want.abs().max(1.0),
                "k {k}: {got} vs {want}"
            );
        }
    }

    #[test]
    fn slip_rows_are_its_derivatives() {
        let h = 0.02;
        let (a, b, w, radii) = scene();
        let slip = Slip::new(&w, radii, &a, &b);
        let x0 = MOTION;
        for k in 0..2 {
            let row = slip.rows(h, &motion(&x0))[k];
            for i in 0..12 {
                let eps = 1e-6;
                let (mut xp, mut xm) = (x0, x0);
                xp[i] += eps;
                xm[i] -= eps;
                let fd = (slip.tangential(h, &motion(&xp))[k]
                    - slip.tangential(h, &motion(&xm))[k])
                    / (2.0 * eps);
                assert!(
                    (row[i] - fd).abs() < 1e-8,
                    "k {k} col {i}: {} vs {fd}",
                    row[i]
                );
            }
        }
    }

    #[test]
    fn to_first_order_slip_is_the_contact_point_velocity() {
        // h → 0: t · (v + ω × (p − x)) on each side, the classical rows (ContactFrame)
        let (a, b, w, radii) = scene();
        let slip = Slip::new(&w, radii, &a, &b);
        let frame = super::super::ContactFrame::new(&w, &a, &b);
        let motion = motion(&MOTION);
        for k in 0..2 {
            let row = slip.rows(0.0, &motion)[k];
            for (i, (got, want)) in row.iter().zip(frame.jac[k + 1]).enumerate() {
                assert!((got - want).abs() < 1e-12, "k {k} col {i}: {got} vs {want}");
            }
        }
    }
}
