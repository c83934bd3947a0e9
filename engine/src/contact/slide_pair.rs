//! Pairs of bodies that can only slide along one axis relative to each other, like the two
//! fingers of a parallel gripper: friction between them cannot act on the motion.
//!
//! When every joint on the tree paths from two bodies to their common ancestor is rotationally
//! locked and all their free translations are parallel, the bodies keep their relative
//! orientation and move apart only along that axis `a`. A contact between them whose normal is
//! `a` (a box corner on the box face facing the other finger) has no tangential slip: two
//! touching points of the pair move apart along `a` only. Its friction impulses then just trade
//! places with the joints' reaction impulses — a whole family of solutions with the same
//! motion — and the Newton matrix of the interior-point solve is singular in that family but
//! for the barrier terms, which vanish as κ → 0. The Panda's pressed finger pads (32 sticking
//! cones) jammed its solves for hundreds of iterations there; so the solver holds such a
//! contact's friction at zero ([`crate::solver`]'s `Hold::Frictionless`), which leaves the
//! motion unchanged, and of such contacts between the same bodies along the same normal keeps
//! only the tightest: their gaps are one relative coordinate shifted by constants. The axes are
//! found here, once, when the model is compiled.
use nalgebra::{Matrix3, Vector3};

use crate::joints::Joint;
use crate::math::quat;

/// The axis along which bodies `a` and `b` can move relative to each other, in `a`'s and `b`'s
/// COM frames, when that is their only relative motion (see the module docs); `None` when they
/// can also rotate relative to each other, translate along two axes, or not move at all.
pub fn slide_axis(joints: &[Joint], a: usize, b: usize) -> Option<[Vector3<f64>; 2]> {
    let (slides, frames) = locked_paths(joints, a, b)?;
    let mut axis: Option<Vector3<f64>> = None;
    for s in &slides {
        for t in &s.axes {
            let t = t.try_normalize(1e-12)?;
            match axis {
                None => axis = Some(t),
                Some(a) if a.cross(&t).norm() <= PARALLEL => {}
                Some(_) => return None,
            }
        }
    }
    let axis = axis?;
    Some([frames[0].transpose() * axis, frames[1].transpose() * axis])
}

/// The joint limits that bound how far the bodies `a` and `b` of a slide pair ([`slide_axis`])
/// can move along their axis: `(joint, limit, coef)` per slide on the two tree paths, such that
/// `b` moves relative to `a` along the axis by `Σ coef Δq` (`q` the slide's limited
/// coordinate, `joint.limits[limit]`); `None` when a translation on the paths is unlimited or
/// the bodies are not a slide pair. (A parallel gripper's closing fingers stop at their
/// limits: the activation bounds how far a candidate between them can close in a step by the
/// travel left, `solver::activation::activate`.)
pub fn slide_limits(joints: &[Joint], a: usize, b: usize) -> Option<Vec<(usize, usize, f64)>> {
    slide_axis(joints, a, b)?;
    let (slides, _) = locked_paths(joints, a, b)?;
    let axis = slides.first()?.axes.first()?.normalize();
    slides
        .iter()
        .map(|s| {
            // one slide, limited (its free dof 0 is its only coordinate)
            let joint = &joints[s.joint];
            if s.axes.len() > 1 || joint.nq() != 1 {
                return None;
            }
            let limit = joint.limits.iter().position(|&(dof, _, _)| dof == 0)?;
            Some((s.joint, limit, s.sign * s.axes[0].dot(&axis)))
        })
        .collect()
}

/// A joint with free translations on the tree path from a slide pair's body to the bodies'
/// common ancestor ([`locked_paths`]).
struct PathSlide {
    /// The joint's index.
    joint: usize,
    /// -1 on `a`'s path (it moves `a`), +1 on `b`'s.
    sign: f64,
    /// Its free translation axes in the common ancestor's frame.
    axes: Vec<Vector3<f64>>,
}

/// The joints with free translations on the tree paths from `a` and `b` to their common
/// ancestor, `a`'s path first, and each body's orientation relative to the ancestor; `None`
/// when a joint on the paths turns (or a body has no tree joint).
fn locked_paths(
    joints: &[Joint],
    a: usize,
    b: usize,
) -> Option<(Vec<PathSlide>, [Matrix3<f64>; 2])> {
    let (path_a, path_b) = (tree_path(joints, a)?, tree_path(joints, b)?);
    // the common ancestor: the first body of a's path (a, its parent, …, 0) on b's
    let common = *path_a.iter().find(|x| path_b.contains(x))?;
    let mut slides = Vec::new();
    let mut frames = [Matrix3::identity(); 2];
    for (side, path) in [&path_a, &path_b].into_iter().enumerate() {
        // orientation relative to the common ancestor, from the ancestor down
        let below: Vec<usize> = path.iter().take_while(|&&x| x != common).copied().collect();
        let mut rot = Matrix3::identity();
        for &child in below.iter().rev() {
            let ji = joints.iter().position(|j| j.child == child && !j.is_loop)?;
            let joint = &joints[ji];
            if joint.rot.nfree() > 0 {
                return None;
            }
            // a rotationally locked joint holds the child at its offset from the parent
            rot *= quat::rotation(&joint.offset);
            if joint.ntrans > 0 {
                slides.push(PathSlide {
                    joint: ji,
                    sign: if side == 0 { -1.0 } else { 1.0 },
                    axes: (0..joint.ntrans)
                        .map(|k| rot * joint.trans_basis.column(k).into_owned())
                        .collect(),
                });
            }
        }
        frames[side] = rot;
    }
    Some((slides, frames))
}

/// Largest `|a × t|` of two unit axes that count as parallel.
const PARALLEL: f64 = 1e-9;

/// The joint holding body `x` to its parent in the kinematic tree (loop joints do not count).
fn tree_joint(joints: &[Joint], x: usize) -> Option<&Joint> {
    joints.iter().find(|j| j.child == x && !j.is_loop)
}

/// `x`, its parent, …, up to the world (body 0); `None` if a body has no tree joint.
fn tree_path(joints: &[Joint], mut x: usize) -> Option<Vec<usize>> {
    let mut path = vec![x];
    while x != 0 {
        x = tree_joint(joints, x)?.parent;
        if path.contains(&x) {
            return None;
        }
        path.push(x);
    }
    Some(path)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::{BodySpec, JointKind, JointSpec, ModelBuilder};

    /// [`gripper`] with the fingers' slides limited to `range` (`None`: the second unlimited).
    fn limited_gripper(range: (f64, f64), second: Option<(f64, f64)>) -> crate::Model {
        let mut b = ModelBuilder::new();
        b.add_body(BodySpec::new("hand", 1.0, [0.1; 3]));
        b.add_body(BodySpec::new("f1", 0.1, [0.01; 3]));
        b.add_body(BodySpec::new("f2", 0.1, [0.01; 3]).quat([0.0, 0.0, 0.0, 1.0]));
        b.add_joint(JointSpec::new(
            "wrist",
            JointKind::Revolute,
            "world",
            "hand",
        ));
        for (f, r) in [("f1", Some(range)), ("f2", second)] {
            let mut j = JointSpec::new(&format!("s{f}"), JointKind::Prismatic, "hand", f)
                .axis([0.0, 1.0, 0.0]);
            j.range = r.map(|r| vec![r]);
            b.add_joint(j);
        }
        b.compile().unwrap()
    }

    /// The second finger, turned half a turn, slides along the hand's -y as its coordinate
    /// grows, the first along +y: each coordinate's growth moves the second finger relative to
    /// the first by -1 along the first's axis. An unlimited slide leaves the travel unbounded,
    /// and a turning joint on the way has no slide axis at all.
    #[test]
    fn a_limited_gripper_bounds_its_fingers_relative_travel() {
        let m = limited_gripper((0.0, 0.04), Some((0.0, 0.04)));
        let limits = slide_limits(&m.joints, 2, 3).expect("both slides limited");
        assert_eq!(limits.len(), 2);
        for (&(j, limit, coef), name) in limits.iter().zip(["sf1", "sf2"]) {
            assert_eq!(m.joints[j].name, name);
            assert_eq!(limit, 0);
            assert!((coef + 1.0).abs() < 1e-12, "{name}: {coef}");
        }
        // the first finger against its hand: +1
        let hand = slide_limits(&m.joints, 1, 2).expect("one limited slide");
        assert_eq!(hand.len(), 1);
        assert!((hand[0].2 - 1.0).abs() < 1e-12, "{hand:?}");
        let m = limited_gripper((0.0, 0.04), None);
        assert!(slide_limits(&m.joints, 2, 3).is_none());
        assert!(slide_limits(&m.joints, 0, 2).is_none(), "the wrist turns");
    }

    /// A hand hinged to the world with two fingers sliding on it; `axes` are the fingers'
    /// slide axes (in their own frames) and `quat` the second finger's orientation.
    fn gripper(axes: [[f64; 3]; 2], quat: [f64; 4]) -> crate::Model {
        let mut b = ModelBuilder::new();
        b.add_body(BodySpec::new("hand", 1.0, [0.1; 3]));
        b.add_body(BodySpec::new("f1", 0.1, [0.01; 3]));
        b.add_body(BodySpec::new("f2", 0.1, [0.01; 3]).quat(quat));
        b.add_joint(JointSpec::new(
            "wrist",
            JointKind::Revolute,
            "world",
            "hand",
        ));
        for (i, a) in axes.iter().enumerate() {
            let f = format!("f{}", i + 1);
            b.add_joint(
                JointSpec::new(&format!("s{}", i + 1), JointKind::Prismatic, "hand", &f).axis(*a),
            );
        }
        b.compile().unwrap()
    }

    #[test]
    fn fingers_sliding_on_one_axis_have_it_as_their_axis() {
        // the second finger turned half a turn about z on the hand, sliding along its own y:
        // the hand's -y axis
        let m = gripper([[0.0, 1.0, 0.0], [0.0, 1.0, 0.0]], [0.0, 0.0, 0.0, 1.0]);
        let [a, b] = slide_axis(&m.joints, 2, 3).expect("parallel slides");
        assert!(a.cross(&Vector3::y()).norm() < 1e-12, "{a}");
        assert!(b.cross(&Vector3::y()).norm() < 1e-12, "{b}");
        // a finger and its hand: one slide
        assert!(slide_axis(&m.joints, 1, 2).is_some());
    }

    #[test]
    fn other_relative_motions_have_no_axis() {
        let id = [1.0, 0.0, 0.0, 0.0];
        // slides along two axes
        let m = gripper([[0.0, 1.0, 0.0], [1.0, 0.0, 0.0]], id);
        assert!(slide_axis(&m.joints, 2, 3).is_none());
        // a finger and the world: the wrist turns
        let m = gripper([[0.0, 1.0, 0.0], [0.0, 1.0, 0.0]], id);
        assert!(slide_axis(&m.joints, 0, 2).is_none());
        assert!(slide_axis(&m.joints, 1, 0).is_none());
    }
}
