//! Closest-point kernels behind [`super::evaluate`]: each returns the exact witnesses of one
//! small distance problem (point–plane, disk rim–plane, ellipsoid–plane, sphere–sphere,
//! point–segment, segment–segment, point–box) in world coordinates, with
//! `point_a − point_b = phi · normal` and a unit normal from B towards A. Degenerate normals
//! fall back to fixed directions of the geoms, so nothing here can panic or divide by zero.

use nalgebra::Vector3;

use super::{Ball, GeomPose, Segment, Witness};

/// Below this length a vector has no usable direction.
const MIN_NORM: f64 = 1e-100;

/// Below this sine two axes count as parallel (disk axis vs plane normal, segment vs segment).
const PARALLEL_TOL: f64 = 1e-9;

/// `v / |v|`, or `fallback` when `v` is too short to normalise.
fn unit_or(v: &Vector3<f64>, fallback: Vector3<f64>) -> Vector3<f64> {
    let norm = v.norm();
    if norm > MIN_NORM && norm.is_finite() {
        v / norm
    } else {
        fallback
    }
}

/// Clamps `x` to `[-half, half]` without panicking on odd bounds.
fn clamp_sym(x: f64, half: f64) -> f64 {
    x.min(half).max(-half)
}

/// Column `k` of the pose rotation: the world direction of the geom's axis `k`.
fn axis(pose: &GeomPose, k: usize) -> Vector3<f64> {
    pose.rot.column(k).into_owned()
}

/// A's support point `point_a` against plane B: the witness on B is its projection.
fn point_plane(point_a: Vector3<f64>, plane: &GeomPose) -> Witness {
    let normal = axis(plane, 2);
    let phi = normal.dot(&(point_a - plane.pos)); // φ = nᵀ(x − o)
    Witness {
        phi,
        point_a,
        point_b: point_a - phi * normal,
        normal,
    }
}

/// Ball of A against plane B: `φ = nᵀ(c − o) − r`.
pub(super) fn sphere_plane(a: &Ball, pose_a: &GeomPose, plane: &GeomPose) -> Witness {
    let center = pose_a.transform_point(&a.center);
    point_plane(center - a.radius * axis(plane, 2), plane) // support point c − r n
}

/// Lowest rim point of the disk of cylinder A centred at `center_a` (A's frame, normal A's z).
pub(super) fn disk_plane(
    center_a: &Vector3<f64>,
    radius: f64,
    pose_a: &GeomPose,
    plane: &GeomPose,
) -> Witness {
    let center = pose_a.transform_point(center_a);
    let (normal, disk_axis) = (axis(plane, 2), axis(pose_a, 2));
    let in_disk = normal - normal.dot(&disk_axis) * disk_axis; // n projected onto the disk plane
    let norm = in_disk.norm();
    // Lowest rim point: c − r n_∥/|n_∥|; with the axis along n, the rim point on A's local +x.
    let direction = if norm > PARALLEL_TOL {
        -in_disk / norm
    } else {
        axis(pose_a, 0)
    };
    point_plane(center + radius * direction, plane)
}

/// Support point of ellipsoid A against plane B: `φ = nᵀ(c − o) − ‖D Rᵀ n‖`.
pub(super) fn ellipsoid_plane(
    radii: &Vector3<f64>,
    pose_a: &GeomPose,
    plane: &GeomPose,
) -> Witness {
    let scaled = radii.component_mul(&(pose_a.rot.transpose() * axis(plane, 2))); // w = D Rᵀ n
    let support = scaled.norm(); // ‖D Rᵀ n‖
    let offset = if support > MIN_NORM {
        pose_a.rot * radii.component_mul(&scaled) / support // R D² Rᵀ n / ‖D Rᵀ n‖
    } else {
        Vector3::zeros()
    };
    point_plane(pose_a.pos - offset, plane)
}

/// Two spheres (world centres); `fallback` is the normal used when the centres coincide.
fn spheres(
    ca: &Vector3<f64>,
    ra: f64,
    cb: &Vector3<f64>,
    rb: f64,
    fallback: Vector3<f64>,
) -> Witness {
    let gap = ca - cb;
    let normal = unit_or(&gap, fallback);
    let phi = normal.dot(&gap) - ra - rb; // φ = |c_a − c_b| − r_a − r_b
    Witness {
        phi,
        point_a: ca - ra * normal,
        point_b: cb + rb * normal,
        normal,
    }
}

/// Ball of A against ball of B; coincident centres use B's +z.
pub(super) fn sphere_sphere(a: &Ball, pose_a: &GeomPose, b: &Ball, pose_b: &GeomPose) -> Witness {
    let (ca, cb) = (
        pose_a.transform_point(&a.center),
        pose_b.transform_point(&b.center),
    );
    spheres(&ca, a.radius, &cb, b.radius, axis(pose_b, 2))
}

/// Ball of A against capsule B; a centre on B's segment uses B's +x.
pub(super) fn sphere_capsule(
    a: &Ball,
    pose_a: &GeomPose,
    b: &Segment,
    pose_b: &GeomPose,
) -> Witness {
    let center = pose_a.transform_point(&a.center);
    let axis_b = axis(pose_b, 2);
    let t = clamp_sym(axis_b.dot(&(center - pose_b.pos)), b.half_length); // projection on the segment
    spheres(
        &center,
        a.radius,
        &(pose_b.pos + t * axis_b),
        b.radius,
        axis(pose_b, 0),
    )
}

/// Closest points of the segments of capsules A and B.
pub(super) fn capsule_capsule(
    a: &Segment,
    pose_a: &GeomPose,
    b: &Segment,
    pose_b: &GeomPose,
) -> Witness {
    let (axis_a, axis_b) = (axis(pose_a, 2), axis(pose_b, 2));
    let r = pose_a.pos - pose_b.pos;
    let (s, t) = segment_params(&r, &axis_a, a.half_length, &axis_b, b.half_length);
    let (pa, pb) = (pose_a.pos + s * axis_a, pose_b.pos + t * axis_b);
    let fallback = unit_or(&axis_a.cross(&axis_b), axis(pose_b, 0)); // crossing segments
    spheres(&pa, a.radius, &pb, b.radius, fallback)
}

/// Parameters `(s, t)` minimising `|r + s·d1 − t·d2|` over `|s| ≤ h1`, `|t| ≤ h2`, for unit
/// directions `d1`, `d2` and `r = c1 − c2` (Ericson, Real-Time Collision Detection, §5.1.9).
/// Parallel segments take `s = 0` before the clamping passes.
pub(super) fn segment_params(
    r: &Vector3<f64>,
    d1: &Vector3<f64>,
    h1: f64,
    d2: &Vector3<f64>,
    h2: f64,
) -> (f64, f64) {
    let (b, e, f) = (d1.dot(d2), d1.dot(r), d2.dot(r));
    let denom = 1.0 - b * b; // |d1 × d2|²
    let free = if denom > PARALLEL_TOL * PARALLEL_TOL {
        (b * f - e) / denom
    } else {
        0.0
    }; // unconstrained s
    let s = clamp_sym(free, h1);
    let t = clamp_sym(f + b * s, h2); // best t for this s
    let s = clamp_sym(b * t - e, h1); // best s for that t
    (s, t)
}

/// Signed distance from `q` to the surface of the box of half extents `half` (box frame):
/// `(distance, surface point, outward normal)`. Inside, the nearest face wins (lowest axis on
/// ties, + side when `q` is on the mid-plane).
pub(super) fn box_distance(
    q: &Vector3<f64>,
    half: &Vector3<f64>,
) -> (f64, Vector3<f64>, Vector3<f64>) {
    let closest = q.zip_map(half, clamp_sym);
    let gap = q - closest;
    let dist = gap.norm();
    if dist > MIN_NORM && dist.is_finite() {
        return (dist, closest, gap / dist); // outside: distance to the closest point
    }
    let depth = |k: usize| half[k] - q[k].abs(); // depth below face k
    let face = (1..3).fold(0, |best, k| if depth(k) < depth(best) { k } else { best });
    let sign = if q[face] >= 0.0 { 1.0 } else { -1.0 };
    let mut normal = Vector3::zeros();
    normal[face] = sign;
    let mut point = *q;
    point[face] = sign * half[face]; // projection onto the nearest face
    (-depth(face), point, normal)
}

/// Sphere (world centre) against box B: signed distance of the centre minus the radius.
fn sphere_box_world(
    center: &Vector3<f64>,
    radius: f64,
    half_b: &Vector3<f64>,
    pose_b: &GeomPose,
) -> Witness {
    let q = pose_b.rot.transpose() * (center - pose_b.pos); // centre in B's frame
    let (dist, point, normal_local) = box_distance(&q, half_b);
    let normal = pose_b.rot * normal_local;
    let point_b = pose_b.transform_point(&point);
    Witness {
        phi: dist - radius,
        point_a: center - radius * normal,
        point_b,
        normal,
    } // φ = d(c) − r
}

/// Ball of A against box B.
pub(super) fn sphere_box(
    a: &Ball,
    pose_a: &GeomPose,
    half_b: &Vector3<f64>,
    pose_b: &GeomPose,
) -> Witness {
    sphere_box_world(&pose_a.transform_point(&a.center), a.radius, half_b, pose_b)
}

/// Ball of A against the convex hull of mesh B: the signed distance of the centre to the hull
/// minus the radius.
pub(super) fn sphere_hull(
    a: &Ball,
    pose_a: &GeomPose,
    hull_b: &super::ConvexHull,
    pose_b: &GeomPose,
) -> Witness {
    let center = pose_a.transform_point(&a.center);
    let q = pose_b.rot.transpose() * (center - pose_b.pos); // centre in B's frame
    let (dist, point, normal_local) = hull_b.signed_distance(&q);
    let normal = pose_b.rot * normal_local;
    Witness {
        phi: dist - a.radius,
        point_a: center - a.radius * normal,
        point_b: pose_b.transform_point(&point),
        normal,
    }
}

/// Box A against a ball of B: the ball against the box with the roles exchanged.
pub(super) fn box_sphere(
    half_a: &Vector3<f64>,
    pose_a: &GeomPose,
    b: &Ball,
    pose_b: &GeomPose,
) -> Witness {
    sphere_box_world(&pose_b.transform_point(&b.center), b.radius, half_a, pose_a).swapped()
}

/// Ball of A against the plane of face `(axis, sign)` of box B, whatever side of the face's
/// edges the centre lies: the witness on B is the centre's projection onto the face plane.
pub(super) fn ball_box_face(
    a: &Ball,
    pose_a: &GeomPose,
    half_b: &Vector3<f64>,
    pose_b: &GeomPose,
    axis: usize,
    sign: f64,
) -> Witness {
    let center = pose_a.transform_point(&a.center);
    let q = pose_b.rot.transpose() * (center - pose_b.pos); // centre in B's frame
    let normal = sign * self::axis(pose_b, axis);
    let mut on_face = q;
    on_face[axis] = sign * half_b[axis];
    Witness {
        phi: sign * q[axis] - half_b[axis] - a.radius, // φ = ±q_k − h_k − r
        point_a: center - a.radius * normal,
        point_b: pose_b.transform_point(&on_face),
        normal,
    }
}

/// The face normal of A or B along which the two boxes overlap least (or are separated most):
/// separation `|uᵀ(c_a − c_b)| − Σ_k h_k |uᵀ e_k|` over both boxes' axes `e_k`, oriented
/// from B towards A, and that separation (positive: the boxes are apart along it).
pub(super) fn box_box_axis(
    half_a: &Vector3<f64>,
    pose_a: &GeomPose,
    half_b: &Vector3<f64>,
    pose_b: &GeomPose,
) -> (f64, Vector3<f64>) {
    let d = pose_a.pos - pose_b.pos;
    let radius = |half: &Vector3<f64>, pose: &GeomPose, u: &Vector3<f64>| -> f64 {
        (0..3).map(|k| half[k] * u.dot(&axis(pose, k)).abs()).sum()
    };
    let mut best = (f64::NEG_INFINITY, axis(pose_b, 2));
    for pose in [pose_b, pose_a] {
        for k in 0..3 {
            let u = axis(pose, k);
            let sep = u.dot(&d).abs() - radius(half_a, pose_a, &u) - radius(half_b, pose_b, &u);
            if sep > best.0 {
                best = (sep, u);
            }
        }
    }
    let u = best.1;
    (best.0, if u.dot(&d) < 0.0 { -u } else { u })
}
