//! Narrow-phase collision geometry: a fixed list of point-like contact candidates per pair of
//! collision shapes, and the evaluation of each candidate to a signed distance, two witness
//! points and a normal.
//!
//! ## Fixed candidates
//! The interior-point contact solver (Dojo-style NCP) needs the set of complementarity
//! constraints to stay fixed while it iterates, so the contacts between two geoms are not found
//! anew each step. Instead [`candidates`] decides once, when the model is compiled, a list of
//! [`Feature`]s (which feature of A may touch which feature of B), and each step [`evaluate`]
//! turns every candidate into a [`Witness`]: the signed distance φ (metres, negative =
//! penetration), a point on each surface and the unit normal pointing from B towards A, with
//! `point_a − point_b = φ · normal`. Several candidates may sit at the same place (a cylinder's
//! lowest rim point may coincide with one of its fixed rim points); the solver handles
//! duplicates.
//!
//! ## Envelope theorem
//! Each candidate is a small distance problem: φ is the minimum over the candidate's feature
//! pair of the distance between the two surfaces (or minus the penetration depth). Where its
//! minimiser is locally unique, φ is a smooth function of the two poses, and by the envelope
//! theorem its first variation under rigid motions of the bodies only needs the witnesses:
//! `δφ = nᵀ δx_a(point_a) − nᵀ δx_b(point_b)`, where `δx(p) = δp + δθ × (p − o)` is the
//! displacement of the material point at `p` of a body moving by `(δp, δθ)` about `o`. The
//! solver relies on this, so every kernel returns the *exact* closest (or deepest) points of its
//! feature, never an approximation, and ties (e.g. parallel segments, a point equidistant from
//! two box faces) are broken deterministically.
//!
//! ## Candidate lists
//! | pair | candidates |
//! |---|---|
//! | sphere / point – plane | 1: the centre, `φ = nᵀ(c − o) − r` |
//! | capsule – plane | 2: the end spheres |
//! | box – plane | 8: the corners |
//! | cylinder – plane | 8: per end disk, its exact lowest rim point plus rim points at 0°, 120°, 240° |
//! | ellipsoid – plane | 1: the exact support point, `φ = nᵀ(c − o) − ‖D Rᵀ n‖` |
//! | sphere – sphere | 1 |
//! | sphere – capsule | 1: closest point on the segment |
//! | capsule – capsule | 3: segment–segment closest points, each end of A against B's segment |
//! | sphere / point – box | 1: signed distance of the centre to the box, minus the radius |
//! | capsule – box | 5: end spheres and the midpoint sphere against the box, and two slots for where the segment crosses the box's edges (`pairs/box_edges.rs`) |
//! | box – box | 24: each corner of A against B, each corner of B against A, and eight slots for the points where an edge of A crosses an edge of B (`pairs/box_edges.rs`) |
//! | mesh – plane | one per hull vertex |
//! | sphere / point – mesh | 1: signed distance of the centre to the hull, minus the radius |
//! | capsule – mesh | 5: end spheres and the midpoint sphere against the hull, and two slots for where the segment crosses the hull's edges (hulls of up to 255 edges) |
//! | box – mesh | each corner of the box against the hull, each hull vertex against the box, and eight slots for edge crossings (`pairs/box_edges.rs`) |
//! | mesh – mesh | each hull vertex of A against B's hull, and of B against A's, and eight slots for edge crossings (hulls of up to 255 edges, 4096 edge pairs) |
//! | sphere / point – cylinder | 1: signed distance of the centre to the cylinder, minus the radius |
//! | capsule – cylinder | 3: the segment's point nearest the cylinder, and the end spheres |
//! | box – cylinder | A's corners and A's twelve edges' nearest points against the cylinder; per end disk, the rim's point nearest A and three fixed rim points against A |
//! | mesh – cylinder | A's hull vertices and edges' nearest points against the cylinder; per end disk, the rim's point nearest A and three fixed rim points against A |
//! | cylinder – cylinder | per end disk of each, the rim's nearest point and three fixed rim points, and each side, against the other |
//!
//! The cylinder pairs are a *core* (ball, segment, rim, side) against a convex *solid* (box,
//! cylinder, hull) measured by its exact signed distance; the core's point nearest the solid
//! is found to round-off (`pairs/convex.rs`). A near-flat rim, segment or side (a disk lying on
//! a face, a capsule or cylinder lying along one) is held at its nearest point at the step's
//! predicted pose, as the disk–plane rim is ([`super::disk_rim_for_step`]).
//!
//! A mesh is the convex hull of its vertices ([`ConvexHull`], as MuJoCo collides it); the
//! signed distance to it is exact outside (closest point on the hull's triangles) and the
//! depth below the nearest face plane inside, as for a box.
//!
//! A point is a sphere of radius 0. The plane is always B; in pairs of different kinds the
//! "smaller" kind (sphere/point < capsule < box < mesh < cylinder < ellipsoid < plane) is A, and
//! [`candidates`] reports when it had to exchange the two geoms.
//!
//! ## Limitations
//! Ellipsoids only collide with planes; plane–plane is unsupported. A box's or hull's edge
//! across a cylinder's rim is not detected; deep inside a solid (a rim or segment crossing it)
//! the nearest point ties two faces and the witness normal is one face's. Box–mesh,
//! capsule–mesh and mesh–mesh pairs of hulls with
//! more than 255 edges or 4096 edge pairs only test vertices, so edge–edge contact between
//! detailed meshes is not detected. Capsule–capsule tests the ends of A only,
//! so parallel capsules are supported at two points only where A's ends lie alongside B's
//! segment.
//!
//! ## Degenerate configurations
//! `evaluate` never panics and returns finite values for finite poses and shapes. Where the
//! normal is undefined it picks a fixed direction: coincident sphere centres → +z of B; a
//! sphere centre on a capsule's segment → +x of B; intersecting segments → `axis_a × axis_b`
//! (or +x of B when they are also parallel); a point exactly at a box centre → the outward
//! normal of the face with the smallest half-extent (+ side, lowest axis on ties); a cylinder
//! axis parallel to the plane normal → the rim point along the disk's local +x.

use std::sync::Arc;

use nalgebra::{Matrix3, Vector3};

pub use super::hull::ConvexHull;

#[path = "pairs/kernels.rs"]
mod kernels;

#[path = "pairs/convex.rs"]
mod convex;

#[path = "pairs/box_edges.rs"]
pub mod box_edges;

pub use convex::{Core, Solid, cylinder_distance};

#[cfg(test)]
#[path = "pairs/geometry_tests.rs"]
mod tests;

/// Collision shape in its geom frame (MuJoCo conventions).
#[derive(Clone, Debug, PartialEq)]
pub enum Shape {
    /// Infinite plane through the geom origin with normal +z of the geom frame (solid below).
    Plane,
    /// Sphere centred at the geom origin.
    Sphere {
        /// Radius (m).
        radius: f64,
    },
    /// Segment along geom z from -half_length to +half_length, swept by a sphere of `radius`.
    Capsule {
        /// Radius of the swept sphere (m).
        radius: f64,
        /// Half the length of the segment (m).
        half_length: f64,
    },
    /// Box centred at the geom origin, aligned with the geom axes.
    Box {
        /// Half the side lengths along geom x, y, z (m).
        half_extents: Vector3<f64>,
    },
    /// Axis along geom z, total height 2·half_length.
    Cylinder {
        /// Radius of the end disks (m).
        radius: f64,
        /// Half the height (m).
        half_length: f64,
    },
    /// Ellipsoid centred at the geom origin with semi-axes along the geom axes.
    Ellipsoid {
        /// Semi-axes along geom x, y, z (m).
        radii: Vector3<f64>,
    },
    /// A point (a sphere of radius 0).
    Point,
    /// The convex hull of a mesh, in the geom frame (MuJoCo collides a mesh as its hull).
    Mesh {
        /// The hull (shared by every geom of one mesh).
        hull: Arc<ConvexHull>,
    },
}

impl Shape {
    /// Human-readable kind name, for error messages.
    fn kind(&self) -> &'static str {
        match self {
            Shape::Plane => "plane",
            Shape::Sphere { .. } => "sphere",
            Shape::Capsule { .. } => "capsule",
            Shape::Box { .. } => "box",
            Shape::Cylinder { .. } => "cylinder",
            Shape::Ellipsoid { .. } => "ellipsoid",
            Shape::Point => "point",
            Shape::Mesh { .. } => "mesh",
        }
    }

    /// Order of kinds: in a pair, the lower rank is A and the higher is B.
    fn rank(&self) -> u8 {
        match self {
            Shape::Sphere { .. } | Shape::Point => 0,
            Shape::Capsule { .. } => 1,
            Shape::Box { .. } => 2,
            Shape::Mesh { .. } => 3,
            Shape::Cylinder { .. } => 4,
            Shape::Ellipsoid { .. } => 5,
            Shape::Plane => 6,
        }
    }

    /// Radius of a sphere-like shape (a point has radius 0), `None` for the other kinds.
    fn ball_radius(&self) -> Option<f64> {
        match *self {
            Shape::Sphere { radius } => Some(radius),
            Shape::Point => Some(0.0),
            _ => None,
        }
    }

    /// The segment along z (its half length) and the radius about it of a shape that lies
    /// within that capsule: a sphere or point (length 0), a capsule, a cylinder.
    pub fn core_segment(&self) -> Option<(f64, f64)> {
        match *self {
            Shape::Sphere { radius } => Some((0.0, radius)),
            Shape::Point => Some((0.0, 0.0)),
            Shape::Capsule {
                radius,
                half_length,
            }
            | Shape::Cylinder {
                radius,
                half_length,
            } => Some((half_length, radius)),
            _ => None,
        }
    }

    /// The shape's sizes in the order MJCF's `geom size` lists them (m): a sphere's radius; a
    /// capsule's or cylinder's radius and half length; a box's half extents; an ellipsoid's
    /// radii; none for a plane, a point or a mesh (its hull is its shape).
    pub fn sizes(&self) -> Vec<f64> {
        match self {
            Shape::Plane | Shape::Point | Shape::Mesh { .. } => Vec::new(),
            Shape::Sphere { radius } => vec![*radius],
            Shape::Capsule {
                radius,
                half_length,
            }
            | Shape::Cylinder {
                radius,
                half_length,
            } => vec![*radius, *half_length],
            Shape::Box { half_extents: v } | Shape::Ellipsoid { radii: v } => {
                v.iter().copied().collect()
            }
        }
    }

    /// Checks that every dimension is finite and non-negative.
    fn validate(&self) -> Result<(), String> {
        let dims = self.sizes();
        if dims.iter().all(|d| d.is_finite() && *d >= 0.0) {
            Ok(())
        } else {
            Err(format!(
                "{} has a negative or non-finite dimension: {self:?}",
                self.kind()
            ))
        }
    }
}

/// World pose of a geom: position and rotation (geom frame -> world).
#[derive(Clone, Copy, Debug)]
pub struct GeomPose {
    /// World position of the geom origin (m).
    pub pos: Vector3<f64>,
    /// Rotation matrix taking geom-frame vectors to world vectors.
    pub rot: Matrix3<f64>,
}

impl Default for GeomPose {
    /// The world frame.
    fn default() -> Self {
        Self::new(Vector3::zeros(), Matrix3::identity())
    }
}

impl GeomPose {
    /// Pose from a position and a rotation matrix.
    pub fn new(pos: Vector3<f64>, rot: Matrix3<f64>) -> Self {
        Self { pos, rot }
    }

    /// World position of a point given in the geom frame.
    pub fn transform_point(&self, local: &Vector3<f64>) -> Vector3<f64> {
        self.pos + self.rot * local // x = p + R x_local
    }
}

/// A sphere fixed in one body of a pair: a sphere of a sphere geom, an end of a capsule, or a
/// point (radius 0) such as a box corner or a cylinder rim point.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Ball {
    /// Centre in the geom frame of the body it belongs to.
    pub center: Vector3<f64>,
    /// Radius (m), 0 for a point.
    pub radius: f64,
}

/// A capsule core: the segment along geom z from -half_length to +half_length, swept by a
/// sphere of `radius`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Segment {
    /// Half the length of the segment (m).
    pub half_length: f64,
    /// Radius of the swept sphere (m).
    pub radius: f64,
}

/// One candidate of a pair: which feature of A touches which feature of B.
///
/// Every variant stores the dimensions it needs (copied by [`candidates`]); positions are in
/// the geom frame of the body they belong to.
#[derive(Clone, Debug, PartialEq)]
pub enum Feature {
    /// A ball of A against plane B: `φ = nᵀ(c − o) − r`.
    SpherePlane {
        /// The ball of A.
        a: Ball,
    },
    /// The lowest rim point of an end disk of cylinder A (disk normal = A's z) against plane B.
    DiskPlane {
        /// Disk centre in A's geom frame (on A's z axis).
        center_a: Vector3<f64>,
        /// Disk radius.
        radius_a: f64,
    },
    /// The support point of ellipsoid A (centred at A's origin) against plane B.
    EllipsoidPlane {
        /// Semi-axes of A along its geom axes.
        radii_a: Vector3<f64>,
    },
    /// A ball of A against a ball of B.
    SphereSphere {
        /// The ball of A.
        a: Ball,
        /// The ball of B.
        b: Ball,
    },
    /// A ball of A against capsule B (closest point on B's segment).
    SphereCapsule {
        /// The ball of A.
        a: Ball,
        /// The capsule core of B.
        b: Segment,
    },
    /// Closest points of the segments of capsules A and B.
    CapsuleCapsule {
        /// The capsule core of A.
        a: Segment,
        /// The capsule core of B.
        b: Segment,
    },
    /// A ball of A against box B (centred at B's origin).
    SphereBox {
        /// The ball of A.
        a: Ball,
        /// Half extents of box B.
        half_extents_b: Vector3<f64>,
    },
    /// Box A (centred at A's origin) against a ball of B.
    BoxSphere {
        /// Half extents of box A.
        half_extents_a: Vector3<f64>,
        /// The ball of B.
        b: Ball,
    },
    /// A ball of A against the convex hull of mesh B.
    SphereHull {
        /// The ball of A.
        a: Ball,
        /// The hull of B.
        hull_b: Arc<ConvexHull>,
    },
    /// The convex hull of mesh A against a ball of B (a vertex of B's hull, a box corner).
    HullSphere {
        /// The hull of A.
        hull_a: Arc<ConvexHull>,
        /// The ball of B.
        b: Ball,
    },
    /// The point of a core of A (ball, segment, cylinder side or rim) nearest the convex solid
    /// of B (the pairs with a cylinder, see [`Core`]).
    CoreSolid {
        /// The core of A.
        a: Core,
        /// The solid of B.
        b: Solid,
    },
    /// The convex solid of A against the point of a core of B nearest it.
    SolidCore {
        /// The solid of A.
        a: Solid,
        /// The core of B.
        b: Core,
    },
    /// One of the [`box_edges::EDGE_SLOTS`] edge crossings of a box and a mesh's hull, or of
    /// two hulls: an edge of A across an edge of B ([`box_edges::polytope_crossings`]).
    EdgeCrossing {
        /// Which of the pair's crossings (ordered by their edges).
        slot: u8,
        /// The box or hull of A.
        a: Solid,
        /// The box or hull of B.
        b: Solid,
    },
    /// One of a capsule–box or capsule–mesh pair's [`box_edges::CAPSULE_SLOTS`] crossings:
    /// capsule A's segment across an edge of B ([`box_edges::capsule_crossings`]).
    CapsuleEdge {
        /// Which of the pair's crossings (ordered by their edges).
        slot: u8,
        /// The capsule core of A.
        a: Segment,
        /// The box or hull of B.
        b: Solid,
    },
    /// One of a box pair's [`box_edges::EDGE_SLOTS`] edge crossings: an edge of box A across
    /// an edge of box B ([`box_edges`]).
    BoxEdge {
        /// Which of the pair's crossings (ordered by their edges).
        slot: u8,
        /// Half extents of box A.
        half_extents_a: Vector3<f64>,
        /// Half extents of box B.
        half_extents_b: Vector3<f64>,
    },
}

/// Evaluated candidate.
#[derive(Clone, Copy, Debug)]
pub struct Witness {
    /// Signed distance (m), negative when penetrating: `point_a − point_b = phi · normal`.
    pub phi: f64,
    /// Witness point on A's surface (world).
    pub point_a: Vector3<f64>,
    /// Witness point on B's surface (world).
    pub point_b: Vector3<f64>,
    /// Unit normal (world), pointing from B towards A.
    pub normal: Vector3<f64>,
}

impl Witness {
    /// The same witness seen with the two geoms exchanged (B's candidate evaluated as A's).
    pub fn swapped(self) -> Witness {
        Witness {
            phi: self.phi,
            point_a: self.point_b,
            point_b: self.point_a,
            normal: -self.normal,
        }
    }
}

/// Candidates for shape A against shape B, or `Err(message)` if the pair is unsupported or a
/// dimension is negative or not finite.
///
/// Returns `(features, swapped)`: when `swapped` is true the features are for the pair
/// `(b, a)`, and the caller must call [`evaluate`] with the two geoms exchanged (the normal then
/// points from the caller's A towards its B).
pub fn candidates(a: &Shape, b: &Shape) -> Result<(Vec<Feature>, bool), String> {
    a.validate()?;
    b.validate()?;
    let swapped = a.rank() > b.rank();
    let (first, second) = if swapped { (b, a) } else { (a, b) };
    let features = match second {
        Shape::Plane => against_plane(first)?,
        _ => between_solids(first, second)?,
    };
    Ok((features, swapped))
}

/// Evaluates one candidate: `shape_a` at `pose_a`, `shape_b` at `pose_b` (after the caller
/// applied `swapped`).
///
/// The features store the dimensions they use, so the shapes are not read by the current
/// features; they are part of the signature so that callers pass the pair as compiled.
pub fn evaluate(
    feature: &Feature,
    shape_a: &Shape,
    pose_a: &GeomPose,
    shape_b: &Shape,
    pose_b: &GeomPose,
) -> Witness {
    let _ = (shape_a, shape_b);
    match feature {
        Feature::SpherePlane { a } => kernels::sphere_plane(a, pose_a, pose_b),
        Feature::DiskPlane { center_a, radius_a } => {
            kernels::disk_plane(center_a, *radius_a, pose_a, pose_b)
        }
        Feature::EllipsoidPlane { radii_a } => kernels::ellipsoid_plane(radii_a, pose_a, pose_b),
        Feature::SphereSphere { a, b } => kernels::sphere_sphere(a, pose_a, b, pose_b),
        Feature::SphereCapsule { a, b } => kernels::sphere_capsule(a, pose_a, b, pose_b),
        Feature::CapsuleCapsule { a, b } => kernels::capsule_capsule(a, pose_a, b, pose_b),
        Feature::SphereBox { a, half_extents_b } => {
            kernels::sphere_box(a, pose_a, half_extents_b, pose_b)
        }
        Feature::BoxSphere { half_extents_a, b } => {
            kernels::box_sphere(half_extents_a, pose_a, b, pose_b)
        }
        Feature::SphereHull { a, hull_b } => kernels::sphere_hull(a, pose_a, hull_b, pose_b),
        Feature::HullSphere { hull_a, b } => {
            kernels::sphere_hull(b, pose_b, hull_a, pose_a).swapped()
        }
        Feature::CoreSolid { a, b } => convex::core_solid(a, pose_a, b, pose_b),
        Feature::SolidCore { a, b } => convex::core_solid(b, pose_b, a, pose_a).swapped(),
        Feature::EdgeCrossing { slot, a, b } => match (polytope(a), polytope(b)) {
            (Some(pa), Some(pb)) => {
                box_edges::polytope_slot_witness(usize::from(*slot), pa, pose_a, pb, pose_b)
            }
            // (slots are made for boxes and hulls only)
            _ => box_edges::centres_apart(pose_a, pose_b),
        },
        Feature::CapsuleEdge { slot, a, b } => match polytope(b) {
            Some(pb) => box_edges::capsule_slot_witness(
                usize::from(*slot),
                (a.half_length, a.radius),
                pose_a,
                pb,
                pose_b,
            ),
            None => box_edges::centres_apart(pose_a, pose_b),
        },
        Feature::BoxEdge {
            slot,
            half_extents_a,
            half_extents_b,
        } => box_edges::slot_witness(
            usize::from(*slot),
            half_extents_a,
            pose_a,
            half_extents_b,
            pose_b,
        ),
    }
}

impl Feature {
    /// Whether this is an edge-crossing slot ([`Feature::BoxEdge`], [`Feature::CapsuleEdge`]):
    /// most hold nothing at any step, and they are not pairs of the problem's degree.
    pub fn is_crossing_slot(&self) -> bool {
        matches!(
            self,
            Feature::BoxEdge { .. } | Feature::CapsuleEdge { .. } | Feature::EdgeCrossing { .. }
        )
    }
}

/// The box or hull of a solid as the crossing search sees it (`None` for a cylinder).
pub fn polytope(solid: &Solid) -> Option<box_edges::Polytope<'_>> {
    match solid {
        Solid::Box { half_extents } => Some(box_edges::Polytope::Box(half_extents)),
        Solid::Hull(hull) => Some(box_edges::Polytope::Hull(hull)),
        Solid::Cylinder { .. } => None,
    }
}

/// The rim point (in the cylinder's geom frame) nearest the other geom of a cylinder-rim
/// candidate (a [`Core::Rim`], or a [`Core::Side`] whose nearest axis point is an end), and the
/// sine of the angle between that disk and the contact plane (0: the disk lies flat on the
/// other solid); `None` for other candidates.
pub fn rim_point(
    feature: &Feature,
    pose_a: &GeomPose,
    pose_b: &GeomPose,
) -> Option<(Vector3<f64>, f64)> {
    match feature {
        Feature::CoreSolid { a, b } => convex::nearest_rim(a, pose_a, b, pose_b),
        Feature::SolidCore { a, b } => convex::nearest_rim(b, pose_b, a, pose_a),
        _ => None,
    }
}

/// A point of the cylinder (its geom frame, from [`rim_point`]) held for the step in place of a
/// rim or side candidate's moving nearest point: a rim point is a ball of radius 0, a point on
/// the axis (a side's) a ball of the cylinder's radius, against the other solid.
pub fn frozen_rim(
    feature: &Feature,
    point: Vector3<f64>,
    pose_a: &GeomPose,
    pose_b: &GeomPose,
) -> Option<Witness> {
    let core = match feature {
        Feature::CoreSolid { a, .. } => a,
        Feature::SolidCore { b, .. } => b,
        _ => return None,
    };
    let radius = match core {
        Core::Side(s) | Core::Segment(s) if point.x == 0.0 && point.y == 0.0 => s.radius,
        _ => 0.0,
    };
    let ball = Core::Ball(Ball {
        center: point,
        radius,
    });
    match feature {
        Feature::CoreSolid { b, .. } => Some(convex::core_solid(&ball, pose_a, b, pose_b)),
        Feature::SolidCore { a, .. } => {
            Some(convex::core_solid(&ball, pose_b, a, pose_a).swapped())
        }
        _ => None,
    }
}

/// A ball of A against the plane of face `(axis, sign)` of box B (a frozen box–box corner,
/// [`super::Frozen::Face`]): `φ = ± q_axis − half_axis − r` with `q` the centre in B's frame.
pub fn ball_box_face(
    a: &Ball,
    pose_a: &GeomPose,
    half_b: &Vector3<f64>,
    pose_b: &GeomPose,
    axis: usize,
    sign: f64,
) -> Witness {
    kernels::ball_box_face(a, pose_a, half_b, pose_b, axis, sign)
}

/// Box A's face `(axis, sign)` against a ball of B: [`ball_box_face`] with the roles exchanged.
pub fn box_face_ball(
    half_a: &Vector3<f64>,
    pose_a: &GeomPose,
    b: &Ball,
    pose_b: &GeomPose,
    axis: usize,
    sign: f64,
) -> Witness {
    kernels::ball_box_face(b, pose_b, half_a, pose_a, axis, sign).swapped()
}

/// The separating axis of least overlap (or largest separation) of boxes A and B among their
/// six face normals (unit, world, pointing from B towards A) and the separation along it
/// (positive: the boxes are apart); ties go to B's axes, then the lower axis.
pub fn box_box_axis(
    half_a: &Vector3<f64>,
    pose_a: &GeomPose,
    half_b: &Vector3<f64>,
    pose_b: &GeomPose,
) -> (f64, Vector3<f64>) {
    kernels::box_box_axis(half_a, pose_a, half_b, pose_b)
}

/// Distance between the segments `c1 ± h1 d1` and `c2 ± h2 d2` (unit directions, world).
pub fn segment_distance(
    (c1, d1, h1): (&Vector3<f64>, &Vector3<f64>, f64),
    (c2, d2, h2): (&Vector3<f64>, &Vector3<f64>, f64),
) -> f64 {
    let (s, t) = kernels::segment_params(&(c1 - c2), d1, h1, d2, h2);
    (c1 + s * d1 - c2 - t * d2).norm()
}

/// Ball of the given centre and radius.
fn ball(center: Vector3<f64>, radius: f64) -> Ball {
    Ball { center, radius }
}

/// Candidates of shape A against plane B.
fn against_plane(a: &Shape) -> Result<Vec<Feature>, String> {
    let sphere = |center: Vector3<f64>, radius: f64| Feature::SpherePlane {
        a: ball(center, radius),
    };
    Ok(match *a {
        Shape::Sphere { radius } => vec![sphere(Vector3::zeros(), radius)],
        Shape::Point => vec![sphere(Vector3::zeros(), 0.0)],
        Shape::Capsule {
            radius,
            half_length,
        } => capsule_ends(half_length)
            .map(|c| sphere(c, radius))
            .to_vec(),
        Shape::Box { half_extents } => box_corners(&half_extents).map(|c| sphere(c, 0.0)).to_vec(),
        Shape::Cylinder {
            radius,
            half_length,
        } => cylinder_plane(radius, half_length),
        Shape::Ellipsoid { radii } => vec![Feature::EllipsoidPlane { radii_a: radii }],
        Shape::Mesh { ref hull } => hull.vertices.iter().map(|&v| sphere(v, 0.0)).collect(),
        Shape::Plane => return Err("plane-plane collision is not supported".to_string()),
    })
}

/// Cylinder against plane: per end disk, its lowest rim point and three fixed rim points.
fn cylinder_plane(radius: f64, half_length: f64) -> Vec<Feature> {
    let mut features = Vec::with_capacity(8);
    for z in [-half_length, half_length] {
        let center_a = Vector3::new(0.0, 0.0, z);
        features.push(Feature::DiskPlane {
            center_a,
            radius_a: radius,
        });
        for k in 0..3 {
            let angle = f64::from(k) * 2.0 * std::f64::consts::PI / 3.0; // 0°, 120°, 240°
            let rim = Vector3::new(radius * angle.cos(), radius * angle.sin(), z);
            features.push(Feature::SpherePlane { a: ball(rim, 0.0) });
        }
    }
    features
}

/// Candidates between two non-plane shapes with `a.rank() <= b.rank()`.
fn between_solids(a: &Shape, b: &Shape) -> Result<Vec<Feature>, String> {
    let features = match (a.ball_radius(), a, b) {
        (Some(radius), _, _) => ball_against(ball(Vector3::zeros(), radius), b),
        (
            None,
            Shape::Capsule {
                radius,
                half_length,
            },
            _,
        ) => capsule_against(
            Segment {
                half_length: *half_length,
                radius: *radius,
            },
            b,
        ),
        (None, Shape::Box { half_extents: ha }, Shape::Box { half_extents: hb }) => {
            Some(box_box(ha, hb))
        }
        (None, Shape::Box { half_extents }, Shape::Mesh { hull }) => {
            Some(box_hull(half_extents, hull))
        }
        (None, Shape::Mesh { hull: ha }, Shape::Mesh { hull: hb }) => Some(hull_hull(ha, hb)),
        (None, _, Shape::Cylinder { .. }) => solid_cylinder(a, b),
        _ => None,
    };
    features.ok_or_else(|| {
        let (ka, kb) = (a.kind(), b.kind());
        format!("collision between a {ka} and a {kb} is not supported (ellipsoids collide only with planes)")
    })
}

/// A sphere or point A against a sphere, point, capsule or box B.
fn ball_against(a: Ball, b: &Shape) -> Option<Vec<Feature>> {
    let feature = match *b {
        Shape::Sphere { radius } => Feature::SphereSphere {
            a,
            b: ball(Vector3::zeros(), radius),
        },
        Shape::Point => Feature::SphereSphere {
            a,
            b: ball(Vector3::zeros(), 0.0),
        },
        Shape::Capsule {
            radius,
            half_length,
        } => Feature::SphereCapsule {
            a,
            b: Segment {
                half_length,
                radius,
            },
        },
        Shape::Box { half_extents } => Feature::SphereBox {
            a,
            half_extents_b: half_extents,
        },
        Shape::Mesh { ref hull } => Feature::SphereHull {
            a,
            hull_b: hull.clone(),
        },
        Shape::Cylinder { .. } => Feature::CoreSolid {
            a: Core::Ball(a),
            b: solid(b)?,
        },
        _ => return None,
    };
    Some(vec![feature])
}

/// The convex solid of a box, cylinder or mesh.
fn solid(shape: &Shape) -> Option<Solid> {
    Some(match *shape {
        Shape::Box { half_extents } => Solid::Box { half_extents },
        Shape::Cylinder {
            radius,
            half_length,
        } => Solid::Cylinder {
            radius,
            half_length,
        },
        Shape::Mesh { ref hull } => Solid::Hull(hull.clone()),
        _ => return None,
    })
}

/// The cores of a cylinder against another solid: per end disk its rim's nearest point and
/// three fixed rim points (0°, 120°, 240°: a disk lying flat on a face rests on them, as on a
/// plane), then, against another cylinder, its side (crossed cylinders touch side on side) and
/// each rim's second point ([`Core::Rim`]).
/// Against a box or a hull the side is left out: a face holds a lying cylinder at its rims'
/// nearest points, or where the face's edges cross it (a box's edges are its candidates), and
/// the corners meet the side as points. With the side, a cylinder lying on a face had its
/// side's nearest point jump between the middle and the ends as it tilted by round-off (its
/// solves took ten times the iterations), and a box on a roller jammed: a single point cannot
/// hold a line contact whose ends swap as it tilts.
fn cylinder_cores(radius: f64, half_length: f64, side: bool) -> Vec<Core> {
    let mut cores = Vec::with_capacity(11);
    let rim = |z: f64, second: bool| Core::Rim { z, radius, second };
    for z in [-half_length, half_length] {
        cores.push(rim(z, false));
        for k in 0..3 {
            let angle = f64::from(k) * 2.0 * std::f64::consts::PI / 3.0;
            let rim = Vector3::new(radius * angle.cos(), radius * angle.sin(), z);
            cores.push(Core::Ball(ball(rim, 0.0)));
        }
    }
    if side {
        cores.push(Core::Side(Segment {
            half_length,
            radius,
        }));
        // each rim's second point: a cylinder lying across another's end disk touches its rim
        // at a chord's two ends; one held point swapped between them every check round (the
        // lying cylinder rocked without rest, 11 iterations a step; random pile 159 was left
        // 1.7 cm deep)
        cores.extend([rim(-half_length, true), rim(half_length, true)]);
    }
    cores
}

/// Box, mesh or cylinder A against cylinder B: A's corners (a box's, a hull's vertices) or
/// cylinder cores against B, then B's cylinder cores against A's solid. Edge–edge contact of a
/// box or hull with a disk's rim is not detected (as box–box).
fn solid_cylinder(a: &Shape, b: &Shape) -> Option<Vec<Feature>> {
    let (solid_a, solid_b) = (solid(a)?, solid(b)?);
    let Shape::Cylinder {
        radius,
        half_length,
    } = *b
    else {
        return None;
    };
    let cores_a: Vec<Core> = match *a {
        Shape::Box { half_extents } => (box_corners(&half_extents)
            .map(|c| Core::Ball(ball(c, 0.0))))
        .into_iter()
        .chain(box_edge_cores(&half_extents))
        .collect(),
        Shape::Mesh { ref hull } => (hull.vertices.iter())
            .map(|&v| Core::Ball(ball(v, 0.0)))
            .chain(hull_edges(hull))
            .collect(),
        Shape::Cylinder {
            radius,
            half_length,
        } => cylinder_cores(radius, half_length, true),
        _ => return None,
    };
    let a_on_b = cores_a.into_iter().map(|core| Feature::CoreSolid {
        a: core,
        b: solid_b.clone(),
    });
    let both_cylinders = matches!(a, Shape::Cylinder { .. });
    let b_on_a = cylinder_cores(radius, half_length, both_cylinders)
        .into_iter()
        .map(|core| Feature::SolidCore {
            a: solid_a.clone(),
            b: core,
        });
    Some(a_on_b.chain(b_on_a).collect())
}

/// Capsule A against capsule B (segments' closest points, then each end of A against B) or
/// against box B (end spheres and the midpoint sphere).
fn capsule_against(a: Segment, b: &Shape) -> Option<Vec<Feature>> {
    let ends = capsule_ends(a.half_length).map(|c| ball(c, a.radius));
    match *b {
        Shape::Capsule {
            radius,
            half_length,
        } => {
            let b = Segment {
                half_length,
                radius,
            };
            let first = Feature::CapsuleCapsule { a, b };
            let rest = ends.map(|end| Feature::SphereCapsule { a: end, b });
            Some([first].into_iter().chain(rest).collect())
        }
        // the end spheres and the midpoint sphere, then the segment's crossings of the box's
        // edges
        Shape::Box { half_extents } => {
            let middle = ball(Vector3::zeros(), a.radius);
            let balls = [ends[0], middle, ends[1]].map(|ball| Feature::SphereBox {
                a: ball,
                half_extents_b: half_extents,
            });
            let crossings = capsule_slots(a, Solid::Box { half_extents });
            Some(balls.into_iter().chain(crossings).collect())
        }
        // the segment's point nearest the cylinder, then the end spheres
        Shape::Cylinder { .. } => {
            let b = solid(b)?;
            let first = Feature::CoreSolid {
                a: Core::Segment(a),
                b: b.clone(),
            };
            let rest = ends.map(|end| Feature::CoreSolid {
                a: Core::Ball(end),
                b: b.clone(),
            });
            Some([first].into_iter().chain(rest).collect())
        }
        // as against a box: the end spheres and the midpoint sphere, then the segment's
        // crossings of the hull's edges (hulls of up to 255 edges)
        Shape::Mesh { ref hull } => {
            let middle = ball(Vector3::zeros(), a.radius);
            let balls = [ends[0], middle, ends[1]].map(|ball| Feature::SphereHull {
                a: ball,
                hull_b: hull.clone(),
            });
            let crossings = if hull.edge_faces().len() <= usize::from(u8::MAX) {
                capsule_slots(a, Solid::Hull(hull.clone()))
            } else {
                Vec::new()
            };
            Some(balls.into_iter().chain(crossings).collect())
        }
        _ => None,
    }
}

/// The crossing slots of capsule core `a` against box or hull `b`.
fn capsule_slots(a: Segment, b: Solid) -> Vec<Feature> {
    (0..box_edges::CAPSULE_SLOTS as u8)
        .map(|slot| Feature::CapsuleEdge {
            slot,
            a,
            b: b.clone(),
        })
        .collect()
}

/// Box A against mesh B: the corners of A against B's hull, the hull's vertices against A,
/// then the slots of the edge crossings ([`crossing_slots`]).
fn box_hull(half_a: &Vector3<f64>, hull_b: &Arc<ConvexHull>) -> Vec<Feature> {
    let a_in_b = box_corners(half_a).map(|c| Feature::SphereHull {
        a: ball(c, 0.0),
        hull_b: hull_b.clone(),
    });
    let b_in_a = hull_b.vertices.iter().map(|&v| Feature::BoxSphere {
        half_extents_a: *half_a,
        b: ball(v, 0.0),
    });
    let a = Solid::Box {
        half_extents: *half_a,
    };
    (a_in_b.into_iter().chain(b_in_a))
        .chain(crossing_slots(&a, &Solid::Hull(hull_b.clone())))
        .collect()
}

/// Mesh A against mesh B: the vertices of each hull against the other (as boxes' corners),
/// each hull's edges as cores against the other, then the slots of the edge crossings
/// ([`crossing_slots`]; hulls with too many edges for those meet at their vertices only).
///
/// Why the edges: an edge of one hull can pass through the other with both ends outside, where
/// no vertex measures it, and the crossing tests do not always keep the crossing that would:
/// 29 of 250 hull piles (`python -m tests.stress.measure`) sank into each other by up to
/// 4.7 cm, seen by the stress suite's separating-axis oracle. With the edges, 1 (pile 200: an
/// unconverged step, no overlap); the piles take about three times as long (BENCHMARKS.md,
/// session 45).
fn hull_hull(hull_a: &Arc<ConvexHull>, hull_b: &Arc<ConvexHull>) -> Vec<Feature> {
    let a_in_b = hull_a.vertices.iter().map(|&v| Feature::SphereHull {
        a: ball(v, 0.0),
        hull_b: hull_b.clone(),
    });
    let b_in_a = hull_b.vertices.iter().map(|&v| Feature::HullSphere {
        hull_a: hull_a.clone(),
        b: ball(v, 0.0),
    });
    let (a, b) = (Solid::Hull(hull_a.clone()), Solid::Hull(hull_b.clone()));
    let crossings = crossing_slots(&a, &b);
    let mut features: Vec<Feature> = a_in_b.chain(b_in_a).collect();
    if !crossings.is_empty() {
        let edges_a = hull_edges(hull_a).map(|core| Feature::CoreSolid {
            a: core,
            b: b.clone(),
        });
        let edges_b = hull_edges(hull_b).map(|core| Feature::SolidCore {
            a: a.clone(),
            b: core,
        });
        features.extend(edges_a.chain(edges_b));
    }
    features.extend(crossings);
    features
}

/// The edge-crossing slots of a box or hull A against a box or hull B: none when their edges
/// make more than [`box_edges::MAX_EDGE_PAIRS`] pairs or one has more than 255 edges
/// (detailed meshes meet at vertices only).
fn crossing_slots(a: &Solid, b: &Solid) -> Vec<Feature> {
    let count = |s: &Solid| polytope(s).map_or(0, |p| p.edge_count());
    let (na, nb) = (count(a), count(b));
    if na * nb > box_edges::MAX_EDGE_PAIRS || na.max(nb) > 255 || na * nb == 0 {
        return Vec::new();
    }
    (0..box_edges::EDGE_SLOTS as u8)
        .map(|slot| Feature::EdgeCrossing {
            slot,
            a: a.clone(),
            b: b.clone(),
        })
        .collect()
}

/// Box against box: the corners of A against B, the corners of B against A, then the slots of
/// the edge crossings ([`box_edges`]).
fn box_box(half_a: &Vector3<f64>, half_b: &Vector3<f64>) -> Vec<Feature> {
    let a_in_b = box_corners(half_a).map(|c| Feature::SphereBox {
        a: ball(c, 0.0),
        half_extents_b: *half_b,
    });
    let b_in_a = box_corners(half_b).map(|c| Feature::BoxSphere {
        half_extents_a: *half_a,
        b: ball(c, 0.0),
    });
    let crossings = (0..box_edges::EDGE_SLOTS as u8).map(|slot| Feature::BoxEdge {
        slot,
        half_extents_a: *half_a,
        half_extents_b: *half_b,
    });
    (a_in_b.into_iter().chain(b_in_a).chain(crossings)).collect()
}

/// The twelve edges of a box as segment cores ([`box_edges::box_edge`]'s order).
fn box_edge_cores(half: &Vector3<f64>) -> impl Iterator<Item = Core> + '_ {
    (0..12).map(move |e| {
        let (centre, direction, half_length) = box_edges::box_edge(half, e);
        Core::Edge {
            centre,
            direction,
            half_length,
        }
    })
}

/// The edges of a hull as segment cores (as a box's edges: a slab lying on a roller rests
/// where its edges cross the roller's top).
fn hull_edges(hull: &ConvexHull) -> impl Iterator<Item = Core> + '_ {
    hull.edges().into_iter().map(|(i, j)| {
        let (a, b) = (hull.vertices[i], hull.vertices[j]);
        let half = 0.5 * (b - a).norm();
        Core::Edge {
            centre: 0.5 * (a + b),
            direction: (b - a) / (2.0 * half).max(1e-300),
            half_length: half,
        }
    })
}

/// The two ends of a segment along z: `(0, 0, ∓half_length)`.
fn capsule_ends(half_length: f64) -> [Vector3<f64>; 2] {
    [
        Vector3::new(0.0, 0.0, -half_length),
        Vector3::new(0.0, 0.0, half_length),
    ]
}

/// The eight corners of a box, bit k of the index selecting the sign of axis k.
fn box_corners(half: &Vector3<f64>) -> [Vector3<f64>; 8] {
    std::array::from_fn(|i| {
        Vector3::from_fn(|k, _| if i >> k & 1 == 1 { half[k] } else { -half[k] })
    })
}
