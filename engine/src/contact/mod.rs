//! Hard contact (Dojo §IV-A): collision geometry, contact candidates and their models.
//!
//! Each pair of geoms that may touch yields a fixed list of point candidates at compile time
//! ([`geometry::candidates`]). A candidate is a node of the mechanism graph with its own
//! interior-point variables, sized by its [`ContactModel`]:
//!
//! | model | variables | rows |
//! |---|---|---|
//! | `Impact` | γ, s | `s - φ(x⁺)`, `γ s - κ` |
//! | `Nonlinear` | γ, s, ξ ∈ Q³, η ∈ Q³ | `s - φ`, `γ s - κ`, `ξ₁ - μγ`, `ξ ∘ η - κe`, `η₂:₃ - v_t` (eqs. 20-24) |
//! | `Linear` | γ, s, ψ, s_ψ, β ∈ R⁴, η ∈ R⁴ | `s - φ`, `s_ψ - (μγ - Σβ)`, `η - (Dᵀv + ψ)`, complementarities (eqs. 5-10) |
//!
//! `φ` is evaluated at the next configuration; the contact impulse acts along the contact frame
//! of the current configuration (like joint impulses), and `v_t` is the tangential slip at the
//! next midpoint velocities, measured consistently with rolling ([`slip`]: the exact
//! displacement of the feature's core point over the step plus the arc rolled about the
//! contact; to first order the contact point's velocity). Impacts are perfectly inelastic (no
//! restitution), as in the paper.
pub mod cone;
pub mod geometry;
pub mod hull;
pub mod slide_pair;
pub mod slip;
pub mod wrench;

use nalgebra::{Matrix3, Vector3};

use crate::joints::geometry::Pose;
use crate::math::quat;
use crate::math::spatial::basis_from_axis;
use geometry::box_edges::{self, Crossings};
use geometry::{Feature, GeomPose, Shape, Witness};

/// How a contact pair resolves friction.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ContactModel {
    /// Exact Coulomb cone as a second-order cone program (default).
    Nonlinear,
    /// Pyramid with four directions (the LCP form).
    Linear,
    /// Frictionless impact only.
    Impact,
}

impl ContactModel {
    /// Interior-point variables of one candidate.
    pub fn dim(self) -> usize {
        match self {
            ContactModel::Impact => 2,
            ContactModel::Nonlinear => 8,
            ContactModel::Linear => 12,
        }
    }
    /// Name used in Python.
    pub fn name(self) -> &'static str {
        match self {
            ContactModel::Nonlinear => "nonlinear",
            ContactModel::Linear => "linear",
            ContactModel::Impact => "impact",
        }
    }
    /// Parse a name.
    pub fn from_name(name: &str) -> Option<ContactModel> {
        match name {
            "nonlinear" => Some(ContactModel::Nonlinear),
            "linear" => Some(ContactModel::Linear),
            "impact" => Some(ContactModel::Impact),
            _ => None,
        }
    }
    /// Number of (orthant pairs, second-order cones) of one candidate.
    pub fn cones(self) -> (usize, usize) {
        match self {
            ContactModel::Impact => (1, 0),
            ContactModel::Nonlinear => (1, 1),
            ContactModel::Linear => (6, 0),
        }
    }
}

/// A compiled collision geometry attached to a body.
#[derive(Clone, Debug)]
pub struct Geom {
    /// Unique name.
    pub name: String,
    /// Body index (0 = world).
    pub body: usize,
    /// Shape in the geom frame.
    pub shape: Shape,
    /// Geom frame origin in the body's COM frame (m).
    pub pos: Vector3<f64>,
    /// Geom frame orientation relative to the body frame.
    pub rot: Matrix3<f64>,
    /// Coulomb friction coefficient.
    pub friction: f64,
    /// Contact model, or `None` for a geom that never collides.
    pub model: Option<ContactModel>,
    /// Collision type bits (MuJoCo's `contype`).
    pub contype: u32,
    /// Collision affinity bits (MuJoCo's `conaffinity`).
    pub conaffinity: u32,
}

impl Geom {
    /// World pose of the geom given its body's COM pose.
    pub fn world_pose(&self, body: &Pose) -> GeomPose {
        let r = quat::rotation(&body.quat);
        GeomPose {
            pos: body.pos + r * self.pos,
            rot: r * self.rot,
        }
    }
}

/// One contact candidate: a feature of geom `a` against geom `b`.
#[derive(Clone, Debug)]
pub struct Contact {
    /// First geom (the normal points from `b` to `a`).
    pub geom_a: usize,
    /// Second geom.
    pub geom_b: usize,
    /// Which features touch.
    pub feature: Feature,
    /// Friction model of the pair.
    pub model: ContactModel,
    /// Friction coefficient of the pair (max of the two geoms, as MuJoCo).
    pub friction: f64,
    /// When the two geoms' bodies can only slide along one axis relative to each other (a
    /// parallel gripper's fingers, [`slide_pair`]): that axis in geom a's and geom b's frames.
    /// A candidate whose normal is this axis cannot slip, and the solver holds its friction at
    /// zero.
    pub slide_axes: Option<[Vector3<f64>; 2]>,
    /// Of a slide pair whose slides are all limited: the limits bounding its relative travel
    /// (`slide_pair::slide_limits`), shared by the pair's candidates.
    pub slide_limits: Option<std::sync::Arc<[(usize, usize, f64)]>>,
}

impl Contact {
    /// Whether this candidate, with its feature frozen for the step as `frozen`, has its normal
    /// along the pair's slide axis, so that its two sides cannot slip (see [`slide_pair`]):
    /// a box corner measured against the face of a box that faces along the axis. Other
    /// features' normals turn as the pair slides, and keep their friction.
    pub fn cannot_slip(&self, frozen: Option<Frozen>) -> bool {
        self.normal_along_slide(frozen).is_some()
    }

    /// `n · a` (±1) for a candidate that [cannot slip](Self::cannot_slip): its normal `n` (from
    /// B to A) against the pair's slide axis `a`, both in either geom's frame.
    pub fn normal_along_slide(&self, frozen: Option<Frozen>) -> Option<f64> {
        let (Some(axes), Some(Frozen::Face { axis, sign })) = (self.slide_axes, frozen) else {
            return None;
        };
        // the measuring box: B for a corner of A (or a ball) on B, whose face's outward normal
        // is n; A for a ball of B on A, whose face's outward normal is -n
        let along = match self.feature {
            Feature::SphereBox { .. } => sign * axes[1][axis],
            Feature::BoxSphere { .. } => -sign * axes[0][axis],
            _ => return None,
        };
        (along.abs() >= 1.0 - 1e-12).then_some(along.signum())
    }
}

impl Contact {
    /// Rounding radii `(r_a, r_b)` of the two sides: how far each witness point lies from the
    /// core point fixed in its body along the normal (a ball's or capsule's radius; 0 for a box
    /// corner, a rim point, an ellipsoid's support point or a plane), see [`slip`].
    pub fn radii(&self) -> (f64, f64) {
        match &self.feature {
            Feature::SpherePlane { a }
            | Feature::SphereBox { a, .. }
            | Feature::SphereHull { a, .. } => (a.radius, 0.0),
            Feature::SphereSphere { a, b } => (a.radius, b.radius),
            Feature::SphereCapsule { a, b } => (a.radius, b.radius),
            Feature::CapsuleCapsule { a, b } => (a.radius, b.radius),
            Feature::BoxSphere { b, .. } | Feature::HullSphere { b, .. } => (0.0, b.radius),
            Feature::DiskPlane { .. } | Feature::EllipsoidPlane { .. } => (0.0, 0.0),
            Feature::CoreSolid { a, .. } => (a.radius(), 0.0),
            Feature::SolidCore { b, .. } => (0.0, b.radius()),
            Feature::BoxEdge { .. } => (0.0, 0.0),
            Feature::CapsuleEdge { a, .. } => (a.radius, 0.0),
            Feature::EdgeCrossing { .. } => (0.0, 0.0),
        }
    }
}

/// Contact frame at one configuration: world normal and tangents, witness arms, and the
/// Jacobian of the contact-point relative velocity `[n t1 t2]ᵀ (v_a(w_a) - v_b(w_b))` with
/// respect to `(v, ω_body)` of body a (columns 0..6) and body b (6..12).
#[derive(Clone, Copy, Debug)]
pub struct ContactFrame {
    /// Signed distance (m).
    pub phi: f64,
    /// Rows n, t1, t2 of the 3 × 12 Jacobian.
    pub jac: [[f64; 12]; 3],
}

impl ContactFrame {
    /// From a witness and the two bodies' COM poses.
    pub fn new(w: &Witness, body_a: &Pose, body_b: &Pose) -> Self {
        let basis = basis_from_axis(&w.normal);
        let arms = Arms::new(w, body_a, body_b);
        let mut jac = [[0.0; 12]; 3];
        for (k, row) in jac.iter_mut().enumerate() {
            *row = arms.velocity_row(&basis.column(k).into_owned());
        }
        ContactFrame { phi: w.phi, jac }
    }

    /// The normal row of [`ContactFrame::new`]'s Jacobian alone (the gap's gradient).
    pub fn normal_row(w: &Witness, body_a: &Pose, body_b: &Pose) -> [f64; 12] {
        Arms::new(w, body_a, body_b).velocity_row(&w.normal)
    }
}

/// The witness points' arms from the two bodies' COMs and the bodies' rotations (body to
/// world), shared by a frame's three rows.
struct Arms {
    arm_a: Vector3<f64>,
    arm_b: Vector3<f64>,
    rot_a: nalgebra::Matrix3<f64>,
    rot_b: nalgebra::Matrix3<f64>,
}

impl Arms {
    fn new(w: &Witness, body_a: &Pose, body_b: &Pose) -> Self {
        Arms {
            arm_a: w.point_a - body_a.pos,
            arm_b: w.point_b - body_b.pos,
            rot_a: quat::rotation(&body_a.quat),
            rot_b: quat::rotation(&body_b.quat),
        }
    }

    /// `d · (v_a(w_a) − v_b(w_b))` at the witness points as a row in `(v, ω_body)` of a and b.
    fn velocity_row(&self, d: &Vector3<f64>) -> [f64; 12] {
        // d · (v + R ω_b × r) = dᵀ v + (Rᵀ (r × d))ᵀ ω_b
        let (ja, jb) = (
            self.rot_a.transpose() * self.arm_a.cross(d),
            self.rot_b.transpose() * self.arm_b.cross(d),
        );
        let mut row = [0.0; 12];
        for i in 0..3 {
            row[i] = d[i];
            row[3 + i] = ja[i];
            row[6 + i] = -d[i];
            row[9 + i] = -jb[i];
        }
        row
    }
}

/// A candidate's rows for one step at its current poses, built on first use: the impulse
/// directions (the Jacobian of [`ContactFrame`]) and the no-slip measure ([`slip::Slip`]).
/// `prepare` visits every candidate of a model each step (1024 on the A1), but only the active
/// few are ever evaluated.
#[derive(Clone, Copy, Debug, Default)]
pub struct StepRows {
    /// The witness and body poses to build from, until built.
    source: Option<(Witness, Pose, Pose)>,
    jac: [[f64; 12]; 3],
    slip: slip::Slip,
}

impl StepRows {
    /// To be built from the candidate's witness at the current poses of its bodies.
    pub fn new(w: Witness, body_a: Pose, body_b: Pose) -> Self {
        StepRows {
            source: Some((w, body_a, body_b)),
            ..Default::default()
        }
    }

    /// The impulse rows (n, t1, t2 of [`ContactFrame::jac`]) and the slip measure, built now if
    /// they were not yet (`radii` as for [`slip::Slip::new`]).
    pub fn get(&mut self, radii: (f64, f64)) -> (&[[f64; 12]; 3], &slip::Slip) {
        if let Some((w, a, b)) = self.source.take() {
            self.jac = ContactFrame::new(&w, &a, &b).jac;
            self.slip = slip::Slip::new(&w, radii, &a, &b);
        }
        (&self.jac, &self.slip)
    }

    /// The normal row of the impulse rows: the gap rate's gradient in the twists.
    pub fn normal_row(&self) -> [f64; 12] {
        match &self.source {
            Some((w, a, b)) => ContactFrame::normal_row(w, a, b),
            None => self.jac[0],
        }
    }
}

/// A candidate's feature held fixed for one step, chosen at the step's predicted poses
/// ([`freeze_for_step`]): the step's constraint is then a smooth function of the poses.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Frozen {
    /// A cylinder rim against a plane or another solid: the material rim point (in the
    /// cylinder's geom frame), see [`disk_rim_for_step`].
    Rim(Vector3<f64>),
    /// A disk's rim point against a plane re-frozen after a solve more than a quarter turn
    /// round the rim from the point its contact frame was built at (an impulse there could not
    /// lift it): the gap is measured at `point`, the impulse acts at `frame` (both material
    /// points of the rim, in the cylinder's geom frame), see `activation::refreeze_disks`.
    RimFramed {
        /// The rim point the gap is measured at.
        point: Vector3<f64>,
        /// The rim point the contact frame is built at.
        frame: Vector3<f64>,
    },
    /// Box corner against a box: the corner is measured against the plane of this face of the
    /// box (axis of the box's geom frame, outward side ±1), see [`box_face_for_step`].
    Face {
        /// Axis of the box's geom frame normal to the face.
        axis: usize,
        /// Outward side of the face along `axis` (±1).
        sign: f64,
    },
    /// A box pair's edge-crossing slot: the lines of A's edge `a` and B's edge `b`, measured
    /// along their common normal of orientation `sign` ([`geometry::box_edges`]).
    Crossing {
        /// A's edge ([`geometry::box_edges::box_edge`] index).
        a: u8,
        /// B's edge.
        b: u8,
        /// Orientation of the normal `sign (d_a × d_b)/|d_a × d_b|` (from B towards A).
        sign: f64,
    },
    /// A box pair's edge-crossing slot that holds no crossing this step: measured as
    /// [`geometry::box_edges::apart`], out of every step's reach.
    NoCrossing,
}

/// Evaluate candidate `c` of `geoms` at the given body poses (`pose(b)` for body `b`).
pub fn witness(c: &Contact, geoms: &[Geom], pose: impl Fn(usize) -> Pose) -> (Witness, Pose, Pose) {
    witness_frozen(c, geoms, pose, None)
}

/// [`witness`], with the candidate's feature optionally frozen for the step ([`Frozen`]).
pub fn witness_frozen(
    c: &Contact,
    geoms: &[Geom],
    pose: impl Fn(usize) -> Pose,
    frozen: Option<Frozen>,
) -> (Witness, Pose, Pose) {
    let (ga, gb) = (&geoms[c.geom_a], &geoms[c.geom_b]);
    let (pa, pb) = (pose(ga.body), pose(gb.body));
    let (wa, wb) = (ga.world_pose(&pa), gb.world_pose(&pb));
    (witness_frozen_at(c, geoms, (&wa, &wb), frozen), pa, pb)
}

/// [`witness_frozen`] at the geoms' world poses `wa`, `wb` (already composed with their bodies'
/// poses).
pub fn witness_frozen_at(
    c: &Contact,
    geoms: &[Geom],
    (wa, wb): (&GeomPose, &GeomPose),
    frozen: Option<Frozen>,
) -> Witness {
    let (ga, gb) = (&geoms[c.geom_a], &geoms[c.geom_b]);
    match (frozen, &c.feature) {
        (Some(Frozen::Rim(point)), Feature::CoreSolid { .. } | Feature::SolidCore { .. }) => {
            geometry::frozen_rim(&c.feature, point, wa, wb)
                .unwrap_or_else(|| geometry::evaluate(&c.feature, &ga.shape, wa, &gb.shape, wb))
        }
        (Some(Frozen::Rim(center) | Frozen::RimFramed { point: center, .. }), _) => {
            let a = geometry::Ball {
                center,
                radius: 0.0,
            };
            geometry::evaluate(&Feature::SpherePlane { a }, &ga.shape, wa, &gb.shape, wb)
        }
        (Some(Frozen::Face { axis, sign }), Feature::SphereBox { a, half_extents_b }) => {
            geometry::ball_box_face(a, wa, half_extents_b, wb, axis, sign)
        }
        (Some(Frozen::Face { axis, sign }), Feature::BoxSphere { half_extents_a, b }) => {
            geometry::box_face_ball(half_extents_a, wa, b, wb, axis, sign)
        }
        (
            Some(Frozen::Crossing { a, b, sign }),
            Feature::BoxEdge {
                half_extents_a,
                half_extents_b,
                ..
            },
        ) => box_edges::edge_edge(half_extents_a, wa, half_extents_b, wb, (a, b, sign)),
        (
            Some(Frozen::NoCrossing),
            Feature::BoxEdge {
                half_extents_a,
                half_extents_b,
                ..
            },
        ) => box_edges::apart(half_extents_a, wa, half_extents_b, wb),
        (
            Some(frozen @ (Frozen::Crossing { .. } | Frozen::NoCrossing)),
            Feature::CapsuleEdge { a, b, .. },
        ) => {
            let capsule = (a.half_length, a.radius);
            match (geometry::polytope(b), frozen) {
                (Some(pb), Frozen::Crossing { b, sign, .. }) => {
                    box_edges::capsule_edge(capsule, wa, pb, wb, (b, sign))
                }
                (Some(pb), _) => box_edges::capsule_apart(capsule, wa, pb, wb),
                _ => box_edges::centres_apart(wa, wb),
            }
        }
        (
            Some(frozen @ (Frozen::Crossing { .. } | Frozen::NoCrossing)),
            Feature::EdgeCrossing { a, b, .. },
        ) => match (geometry::polytope(a), geometry::polytope(b), frozen) {
            (Some(pa), Some(pb), Frozen::Crossing { a, b, sign }) => {
                box_edges::polytope_edge_edge(pa, wa, pb, wb, (a, b, sign))
            }
            (Some(pa), Some(pb), _) => box_edges::polytope_apart(pa, wa, pb, wb),
            _ => box_edges::centres_apart(wa, wb),
        },
        _ => geometry::evaluate(&c.feature, &ga.shape, wa, &gb.shape, wb),
    }
}

/// The feature of candidate `c` to hold fixed for a step from the bodies' current poses
/// `now_a`, `now_b`, predicted at `predicted_a`, `predicted_b` (the current poses advanced by
/// the current velocities): a near-flat disk's rim point or a box corner's face
/// ([`disk_rim_for_step`], [`box_face_for_step`]); `None` to evaluate the candidate exactly.
pub fn freeze_for_step(
    c: &Contact,
    geoms: &[Geom],
    now: (&Pose, &Pose),
    predicted: (&Pose, &Pose),
) -> Option<Frozen> {
    let disk = matches!(
        c.feature,
        Feature::DiskPlane { .. } | Feature::CoreSolid { .. } | Feature::SolidCore { .. }
    );
    if !disk && !box_pair(c, geoms) && !c.feature.is_crossing_slot() {
        return None;
    }
    let [na, nb, pa, pb] = pair_world_poses(c, geoms, now, predicted);
    freeze_for_step_at(
        c,
        geoms,
        (&na, &nb),
        (&pa, &pb),
        f64::INFINITY,
        &mut BoxPairMemo::default(),
    )
}

/// Whether candidate `c` is between two boxes.
fn box_pair(c: &Contact, geoms: &[Geom]) -> bool {
    matches!(
        (&geoms[c.geom_a].shape, &geoms[c.geom_b].shape),
        (Shape::Box { .. }, Shape::Box { .. })
    )
}

/// World poses of candidate `c`'s geoms `[A now, B now, A predicted, B predicted]` from their
/// bodies' poses.
fn pair_world_poses(
    c: &Contact,
    geoms: &[Geom],
    (now_a, now_b): (&Pose, &Pose),
    (predicted_a, predicted_b): (&Pose, &Pose),
) -> [GeomPose; 4] {
    let (ga, gb) = (&geoms[c.geom_a], &geoms[c.geom_b]);
    [
        ga.world_pose(now_a),
        gb.world_pose(now_b),
        ga.world_pose(predicted_a),
        gb.world_pose(predicted_b),
    ]
}

/// [`freeze_for_step`] at the geoms' world poses, current (`now`) and predicted (`ahead`),
/// reusing `memo` for the candidates of one box pair (see [`BoxPairMemo`]); a box pair farther
/// apart than `margin` at both holds no edge crossing for the step (`box_crossing_at`).
pub fn freeze_for_step_at(
    c: &Contact,
    geoms: &[Geom],
    now: (&GeomPose, &GeomPose),
    ahead: (&GeomPose, &GeomPose),
    margin: f64,
    memo: &mut BoxPairMemo,
) -> Option<Frozen> {
    disk_rim_at(c, ahead, false)
        .map(Frozen::Rim)
        .or_else(|| box_face_at(c, geoms, now, ahead, memo))
        .or_else(|| box_crossing_at(c, now, ahead, margin, memo))
}

/// The separating axis [`box_face_for_step`] found for the last box pair it measured, `(geom a,
/// geom b)` with the geom poses it used and the axis (from B towards A), reused by that pair's
/// other corner candidates (sixteen share it). Valid only while the bodies' poses and
/// velocities do not change: one memo per pass over the candidates of one state. Why: the
/// Panda's finger pads make 400 corner candidates, and the axis test, repeated for each, was
/// 4.8% of its step Jacobians' instructions.
#[derive(Clone, Copy, Debug, Default)]
pub struct BoxPairMemo {
    last: Option<((usize, usize), BoxAxis)>,
    /// The last pair's edge crossings ([`box_crossing_at`]), shared by its eight slots.
    crossings: Option<((usize, usize), Crossings)>,
}

/// The geom poses of a box pair and the axis that separates them (from B towards A).
/// (`None`: the boxes meet edge on edge, and no face measures their corners.)
type BoxAxis = (GeomPose, GeomPose, Option<Vector3<f64>>);

/// The pose of body `b` (0 = world) one step of length `h` ahead at its current velocities.
pub fn predicted_pose(state: &crate::State, b: usize, h: f64) -> Pose {
    if b == 0 {
        return Pose::world();
    }
    let (p, (v, w)) = (state.pose(b), state.velocity(b));
    Pose {
        pos: p.pos + h * v,
        quat: p.quat * quat::step_map(&w, h),
    }
}

/// How much better (m) an edge-crossing axis must separate two boxes than every face normal for
/// [`box_face_for_step`] to leave their corners unfrozen (faces flush to round-off tie).
const EDGE_ON_EDGE_TOL: f64 = 1e-9;

/// Relative lateral tolerance of [`box_face_for_step`]: a corner this far outside a face's
/// edges (relative to the half extent) still counts as over the face, so that the corners of
/// equal boxes stacked flush (exactly on each other's side planes) are measured by the face.
const FACE_EDGE_TOL: f64 = 1e-6;

/// The face of box B that measures a corner of box A for the step (or, for a `BoxSphere`
/// candidate, the face of A that measures B's corner).
///
/// Why: a corner's exact distance to a box is measured to the box's nearest face. When two
/// boxes of equal size stand flush on each other, every touching corner lies on a side plane
/// of the other box, so its nearest face is a side face at distance 0 whatever the vertical
/// overlap: the stack sank into itself held only by friction (1000 kg on 1 kg: 0.12 mm of
/// overlap with every distance reported as 0). Instead the pair's contact normal is the
/// separating axis of least overlap among the six face normals (SAT), and a corner that lies
/// over the face of the other box most aligned with that normal (within its edges, in the
/// front half of the box) is measured against that face's plane: a smooth constraint whose
/// normal is the pair's normal, as MuJoCo's box–box contacts share one normal. Other corners
/// (beside the box, or behind it) keep the exact distance.
///
/// Which poses: boxes that overlap or touch at the start of the step (`now_a`, `now_b`) are
/// judged at the step's predicted poses (`predicted_a`, `predicted_b`), where the step ends.
/// Boxes that are apart at the start are judged at the current poses, along the axis that
/// separates them now: a fast thin box's predicted pose can lie past the other box (the
/// Panda's 4–8 mm finger pads closing at 1.2 m/s each predict 23 mm of travel in a 10 ms
/// step), and the face selected there is the far face, whose plane the corner is already
/// behind (−2.4e-2 m while the pads were 1.6e-2 m apart): a constraint that contradicted
/// the fingers' joint limits, and every solve of the step failed.
pub fn box_face_for_step(
    c: &Contact,
    geoms: &[Geom],
    now: (&Pose, &Pose),
    predicted: (&Pose, &Pose),
) -> Option<Frozen> {
    if !box_pair(c, geoms) {
        return None;
    }
    let [na, nb, pa, pb] = pair_world_poses(c, geoms, now, predicted);
    box_face_at(
        c,
        geoms,
        (&na, &nb),
        (&pa, &pb),
        &mut BoxPairMemo::default(),
    )
}

/// [`box_face_for_step`] at the geoms' world poses, current (`now`) and predicted (`ahead`),
/// reusing `memo` for the candidates of one box pair.
fn box_face_at(
    c: &Contact,
    geoms: &[Geom],
    (na, nb): (&GeomPose, &GeomPose),
    (pa, pb): (&GeomPose, &GeomPose),
    memo: &mut BoxPairMemo,
) -> Option<Frozen> {
    let (ga, gb) = (&geoms[c.geom_a], &geoms[c.geom_b]);
    let (Shape::Box { half_extents: ha }, Shape::Box { half_extents: hb }) = (&ga.shape, &gb.shape)
    else {
        return None;
    };
    let key = (c.geom_a, c.geom_b);
    let (pa, pb, normal) = match memo.last {
        Some((k, axis)) if k == key => axis,
        _ => {
            let (separation, normal_now) = geometry::box_box_axis(ha, na, hb, nb);
            let (pa, pb, separation, normal) = if separation > 0.0 {
                (*na, *nb, separation, normal_now)
            } else {
                let (separation, normal) = geometry::box_box_axis(ha, pa, hb, pb); // B to A
                (*pa, *pb, separation, normal)
            };
            // edge on edge: an edge-crossing axis separates the boxes better than every face
            // normal, and the face of least overlap is not where they meet (random box pile
            // 18: a corner resting on a box's bottom face, 1.3 cm from its side, was measured
            // against the side's plane, 1.3 cm deep)
            // (apart along a face normal, a face plane bounds each corner's distance from below
            // anyway: the check is for boxes that touch)
            let edge_on_edge = separation <= 0.0
                && box_edges::cross_separation(ha, &pa, hb, &pb) > separation + EDGE_ON_EDGE_TOL;
            let axis = (pa, pb, (!edge_on_edge).then_some(normal));
            memo.last = Some((key, axis));
            axis
        }
    };
    let normal = normal?;
    // (corner in world, the measuring box, its pose, the outward direction its face should face)
    let (corner, half, pose, outward) = match &c.feature {
        Feature::SphereBox { a, .. } => (pa.transform_point(&a.center), hb, &pb, normal),
        Feature::BoxSphere { b, .. } => (pb.transform_point(&b.center), ha, &pa, -normal),
        _ => return None,
    };
    let q = pose.rot.transpose() * (corner - pose.pos);
    let n_local = pose.rot.transpose() * outward;
    let axis = n_local.iamax();
    let sign = if n_local[axis] >= 0.0 { 1.0 } else { -1.0 };
    let over_face = (0..3)
        .filter(|&k| k != axis)
        .all(|k| q[k].abs() <= half[k] * (1.0 + FACE_EDGE_TOL));
    (over_face && sign * q[axis] >= 0.0).then_some(Frozen::Face { axis, sign })
}

/// The crossing that edge slot `c` of a box pair holds for the step ([`Frozen::Crossing`], or
/// [`Frozen::NoCrossing`]), `None` for other candidates. The crossings are found at the
/// current poses; one the step brings in is held after the solve ([`crate::solver::activation`]'s
/// re-freezing). Why not at the predicted poses, as the corners' faces: boxes meeting edge on
/// edge at speed are predicted deep in each other, where the edges that support each box
/// along a crossing's normal are not the ones that touch (random box pile 37, step 34: a pair
/// chosen 9.7 cm deep at the predicted poses was held from the start, and the solve threw the
/// boxes apart, +54 J).
///
/// Boxes apart by more than `margin` along a face normal, now and at the predicted poses,
/// hold none: a crossing's distance is then above `margin` too (it is the distance of two
/// edge points whose lines' closest points lie on both edges, and no two points of the boxes
/// are nearer than their separation), so it would not take part in the step. Why: the
/// Panda's 25 finger-pad pairs are always near enough for the activation's bounding spheres,
/// and searching their crossings every step cost it 23% (`step_bench panda.xml 1000 3 1`,
/// 0.229 → 0.281 ms a step).
fn box_crossing_at(
    c: &Contact,
    (na, nb): (&GeomPose, &GeomPose),
    (pa, pb): (&GeomPose, &GeomPose),
    margin: f64,
    memo: &mut BoxPairMemo,
) -> Option<Frozen> {
    let slot = match &c.feature {
        Feature::BoxEdge { slot, .. }
        | Feature::CapsuleEdge { slot, .. }
        | Feature::EdgeCrossing { slot, .. } => *slot,
        _ => return None,
    };
    let key = (c.geom_a, c.geom_b);
    let found = match memo.crossings {
        Some((k, found)) if k == key => found,
        _ => {
            let apart = |poses| crossing_pair_gap(&c.feature, poses);
            let found = if apart((na, nb)) > margin && apart((pa, pb)) > margin {
                Crossings::default()
            } else {
                crossings_at(&c.feature, (na, nb))
            };
            memo.crossings = Some((key, found));
            found
        }
    };
    Some(crossing_frozen(found.slot(usize::from(slot))))
}

/// The crossings of an edge slot's pair at these geom poses (none for other candidates).
pub fn crossings_at(feature: &Feature, (wa, wb): (&GeomPose, &GeomPose)) -> Crossings {
    match feature {
        Feature::BoxEdge {
            half_extents_a: ha,
            half_extents_b: hb,
            ..
        } => box_edges::crossings(ha, wa, hb, wb),
        Feature::CapsuleEdge { a, b, .. } => match geometry::polytope(b) {
            Some(pb) => box_edges::capsule_crossings((a.half_length, a.radius), wa, pb, wb),
            None => Crossings::default(),
        },
        Feature::EdgeCrossing { a, b, .. } => {
            match (geometry::polytope(a), geometry::polytope(b)) {
                (Some(pa), Some(pb)) => box_edges::polytope_crossings(pa, wa, pb, wb),
                _ => Crossings::default(),
            }
        }
        _ => Crossings::default(),
    }
}

/// A lower bound on the distance of an edge slot's two geoms at these geom poses: a box
/// pair's separation along the face normals; a capsule's and a box's bounding spheres' gap.
pub fn crossing_pair_gap(feature: &Feature, (wa, wb): (&GeomPose, &GeomPose)) -> f64 {
    match feature {
        Feature::BoxEdge {
            half_extents_a: ha,
            half_extents_b: hb,
            ..
        } => geometry::box_box_axis(ha, wa, hb, wb).0,
        Feature::CapsuleEdge { a, b, .. } => {
            (wa.pos - wb.pos).norm() - a.half_length - a.radius - solid_radius(b)
        }
        Feature::EdgeCrossing { a, b, .. } => {
            (wa.pos - wb.pos).norm() - solid_radius(a) - solid_radius(b)
        }
        _ => f64::NEG_INFINITY,
    }
}

/// Radius of a sphere about a solid's geom origin that holds it (infinite for a cylinder:
/// edge slots are made for boxes and hulls only).
fn solid_radius(solid: &geometry::Solid) -> f64 {
    match solid {
        geometry::Solid::Box { half_extents } => half_extents.norm(),
        geometry::Solid::Hull(h) => h.radius(),
        geometry::Solid::Cylinder { .. } => f64::INFINITY,
    }
}

/// The frozen feature of an edge slot holding `crossing`.
pub fn crossing_frozen(crossing: Option<box_edges::Crossing>) -> Frozen {
    match crossing {
        Some(x) => Frozen::Crossing {
            a: x.a,
            b: x.b,
            sign: x.sign,
        },
        None => Frozen::NoCrossing,
    }
}

/// Below this sine of the angle between a cylinder's end disk and the plane, the disk's
/// lowest-rim-point candidate is frozen for the step (see [`disk_rim_for_step`]). About 11°.
pub const DISK_FREEZE_SINE: f64 = 0.2;

/// The material rim point (A's geom frame) at which a disk–plane candidate is held for one step,
/// or `None` to track the lowest rim point exactly.
///
/// Why: the disk's distance `nᵀc − r |n_∥|` is the minimum over its rim, kinked where the disk
/// lies flat (`n_∥ = 0`). Tracked exactly, the lowest point can jump across the disk within a
/// step, and the solve then found spurious solutions where the tilt flips and energy grows
/// (+59% in one step for a cylinder landing flat). Near flat, the candidate is instead the rim
/// point that is lowest at the predicted next pose (`predicted_a`, `predicted_b`: the
/// current poses advanced by the current velocities): a fixed material point, a smooth
/// constraint, exact for constant velocity; the disk's three fixed rim points support it
/// where it is flat. Tilted disks (rolling on the rim) keep the exact moving point.
/// With `force`, the rim point lowest at the given poses is returned at any tilt.
pub fn disk_rim_for_step(
    c: &Contact,
    geoms: &[Geom],
    predicted_a: &Pose,
    predicted_b: &Pose,
    force: bool,
) -> Option<Vector3<f64>> {
    if !matches!(
        c.feature,
        Feature::DiskPlane { .. } | Feature::CoreSolid { .. } | Feature::SolidCore { .. }
    ) {
        return None;
    }
    let (ga, gb) = (&geoms[c.geom_a], &geoms[c.geom_b]);
    let (pa, pb) = (ga.world_pose(predicted_a), gb.world_pose(predicted_b));
    disk_rim_at(c, (&pa, &pb), force)
}

/// [`disk_rim_for_step`] at the geoms' world poses `pa`, `pb`.
fn disk_rim_at(c: &Contact, (pa, pb): (&GeomPose, &GeomPose), force: bool) -> Option<Vector3<f64>> {
    let Feature::DiskPlane { center_a, radius_a } = &c.feature else {
        // a cylinder's rim against another solid: its nearest rim point, held when near flat
        let (point, sine) = geometry::rim_point(&c.feature, pa, pb)?;
        return (force || sine < DISK_FREEZE_SINE).then_some(point);
    };
    // plane normal in A's geom frame; its x, y part is the in-disk direction
    let n_local = pa.rot.transpose() * pb.rot.column(2);
    let in_disk = Vector3::new(n_local[0], n_local[1], 0.0);
    let sine = in_disk.norm();
    if sine >= DISK_FREEZE_SINE && !force {
        return None;
    }
    let direction = if sine > 1e-12 {
        -in_disk / sine
    } else {
        Vector3::x()
    };
    Some(center_a + direction * *radius_a)
}

/// Signed distance of every contact candidate at `state` (m, negative = penetration). A box
/// corner over the face of another box is measured by the face the pair's separating axis
/// selects at `state` ([`box_face_for_step`]), so flush boxes report their overlap.
pub fn signed_distances(model: &crate::Model, state: &crate::State) -> Vec<f64> {
    let pose = |b: usize| if b == 0 { Pose::world() } else { state.pose(b) };
    signed_distances_at(model, pose).collect()
}

/// [`signed_distances`] at the body poses `pose(b)` (the world frame for body 0).
pub(crate) fn signed_distances_at(
    model: &crate::Model,
    pose: impl Fn(usize) -> Pose + Copy,
) -> impl Iterator<Item = f64> {
    model.contacts.iter().map(move |c| {
        let (ga, gb) = (&model.geoms[c.geom_a], &model.geoms[c.geom_b]);
        let (pa, pb) = (pose(ga.body), pose(gb.body));
        let face = box_face_for_step(c, &model.geoms, (&pa, &pb), (&pa, &pb));
        witness_frozen(c, &model.geoms, pose, face).0.phi
    })
}
