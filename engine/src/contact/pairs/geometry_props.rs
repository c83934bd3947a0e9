//! Property tests of the narrow phase on random shapes and poses, for every supported pair:
//! the witness invariants, the envelope-theorem derivative of φ under rigid motions of either
//! body (checked against central finite differences), and argument swapping.

use super::*;
use proptest::prelude::*;

/// Shape kinds in the property tests: 0 sphere, 1 point, 2 capsule, 3 box, 4 cylinder,
/// 5 ellipsoid, 6 plane, 7 mesh (the hull of an octahedron's tips and a smaller box's
/// corners, off centre).
fn make_shape(kind: usize, d: [f64; 3]) -> Shape {
    match kind {
        7 => {
            let mut pts = Vec::new();
            for (k, dk) in d.iter().enumerate() {
                for s in [-1.0, 1.0] {
                    pts.push(Vector3::ith(k, s * dk) + Vector3::new(0.05, -0.03, 0.02));
                }
            }
            for i in 0..8 {
                let s = |k: usize| if i >> k & 1 == 1 { 0.45 } else { -0.45 };
                pts.push(Vector3::new(s(0) * d[0], s(1) * d[1], s(2) * d[2]));
            }
            Shape::Mesh {
                hull: std::sync::Arc::new(ConvexHull::new(&pts).unwrap()),
            }
        }
        0 => Shape::Sphere { radius: d[0] },
        1 => Shape::Point,
        2 => Shape::Capsule {
            radius: d[0],
            half_length: d[1],
        },
        3 => Shape::Box {
            half_extents: Vector3::from(d),
        },
        4 => Shape::Cylinder {
            radius: d[0],
            half_length: d[1],
        },
        5 => Shape::Ellipsoid {
            radii: Vector3::from(d),
        },
        _ => Shape::Plane,
    }
}

fn dims() -> impl Strategy<Value = [f64; 3]> {
    prop::array::uniform3(0.1..0.8f64)
}

fn rand_pose() -> impl Strategy<Value = GeomPose> {
    (
        prop::array::uniform3(-1.0..1.0f64),
        prop::array::uniform3(-3.0..3.0f64),
    )
        .prop_map(|(p, r)| pose(p, r))
}

/// Every supported ordered pair of kinds.
fn supported_pair() -> impl Strategy<Value = (usize, usize)> {
    (0..8usize, 0..8usize).prop_filter("supported", |&(a, b)| {
        candidates(&make_shape(a, [0.5; 3]), &make_shape(b, [0.5; 3])).is_ok()
    })
}

/// Rigid motion of a pose: translation `dp` and rotation `dth` about its origin (world).
fn moved(p: &GeomPose, dp: &Vector3<f64>, dth: &Vector3<f64>) -> GeomPose {
    GeomPose::new(p.pos + dp, Rotation3::new(*dth).matrix() * p.rot)
}

/// Whether the feature's witness is locally unique with a margin (no ties, no kinks).
fn unique_witness(f: &Feature, w: &Witness, pa: &GeomPose, pb: &GeomPose) -> bool {
    let margin = 1e-2;
    match f {
        Feature::SpherePlane { .. } | Feature::EllipsoidPlane { .. } => true,
        Feature::DiskPlane { .. } => pa.rot.column(2).dot(&pb.rot.column(2)).abs() < 1.0 - margin,
        Feature::SphereSphere { a, b } => w.phi + a.radius + b.radius > margin,
        Feature::SphereCapsule { a, b } => w.phi + a.radius + b.radius > margin,
        Feature::CapsuleCapsule { a, b } => {
            let sine = pa.rot.column(2).cross(&pb.rot.column(2)).norm();
            w.phi + a.radius + b.radius > margin && sine > 0.1
        }
        Feature::SphereBox { a, half_extents_b } => {
            box_unique(&pa.transform_point(&a.center), half_extents_b, pb)
        }
        Feature::BoxSphere { half_extents_a, b } => {
            box_unique(&pb.transform_point(&b.center), half_extents_a, pa)
        }
        Feature::SphereHull { a, hull_b } => {
            hull_unique(&pa.transform_point(&a.center), hull_b, pb)
        }
        Feature::HullSphere { hull_a, b } => {
            hull_unique(&pb.transform_point(&b.center), hull_a, pa)
        }
        // a minimiser over a segment or rim: smooth where differences of two steps agree (a
        // wrong witness fails the envelope check at every step, so this hides no error)
        // (the core point is the surface witness, or a ball's or segment's centre behind it:
        // a side at its axis' end is measured from its rim, so both must be clear)
        Feature::CoreSolid { a, b } => {
            let (surface, core) = (w.point_a, w.point_a + a.radius() * w.normal);
            solid_unique(&surface, b, pb) && solid_unique(&core, b, pb) && smooth_around(f, pa, pb)
        }
        Feature::SolidCore { a, b } => {
            let (surface, core) = (w.point_b, w.point_b - b.radius() * w.normal);
            solid_unique(&surface, a, pa) && solid_unique(&core, a, pa) && smooth_around(f, pa, pb)
        }
        // (the slot's crossing is found anew at each pose: smooth away from a change of it)
        Feature::BoxEdge { .. } | Feature::CapsuleEdge { .. } | Feature::EdgeCrossing { .. } => {
            smooth_around(f, pa, pb)
        }
    }
}

/// Whether φ of a point against a solid is smooth around it (one nearest face or region, with
/// a margin): deep inside, a core's nearest point ties two faces and φ's gradient mixes their
/// normals, which a single witness normal cannot give (a solve keeps contacts shallow).
fn solid_unique(point: &Vector3<f64>, solid: &Solid, pose: &GeomPose) -> bool {
    match solid {
        Solid::Box { half_extents } => {
            // (and not on a mid-plane, where the two faces of the nearest axis tie)
            let q = pose.rot.transpose() * (point - pose.pos);
            let depth = |k: usize| half_extents[k] - q[k].abs();
            let k = (1..3).fold(0, |best, k| if depth(k) < depth(best) { k } else { best });
            box_unique(point, half_extents, pose) && (depth(k) < 0.0 || q[k].abs() > 1e-2)
        }
        Solid::Hull(hull) => hull_unique(point, hull, pose),
        Solid::Cylinder {
            radius,
            half_length,
        } => {
            let margin = 1e-2;
            let q = pose.rot.transpose() * (point - pose.pos);
            let (dr, dz) = (q.x.hypot(q.y) - radius, q.z.abs() - half_length);
            q.x.hypot(q.y) > margin
                && if dr < 0.0 && dz < 0.0 {
                    // (nearer a cap: not on the mid-plane, where the two caps tie)
                    (dr - dz).abs() > margin && (dr > dz || q.z.abs() > margin)
                } else {
                    dr.abs() > margin && dz.abs() > margin
                }
        }
    }
}

/// Whether central differences of φ with steps 1e-4 and 1e-6 agree to 1e-5 under each of the
/// 12 unit rigid motions of A and B (no kink of φ within 1e-4 of the poses).
fn smooth_around(f: &Feature, pa: &GeomPose, pb: &GeomPose) -> bool {
    let phi = |qa: &GeomPose, qb: &GeomPose| evaluate(f, &Shape::Point, qa, &Shape::Point, qb).phi;
    (0..12).all(|k| {
        let unit = Vector3::ith(k % 3, 1.0);
        let (dp, dth) = if k % 6 < 3 {
            (unit, Vector3::zeros())
        } else {
            (Vector3::zeros(), unit)
        };
        let diff = |h: f64| {
            let (mut qa, mut qb) = (*pa, *pb);
            let (mut ra, mut rb) = (*pa, *pb);
            if k < 6 {
                qa = moved(pa, &(h * dp), &(h * dth));
                ra = moved(pa, &(-h * dp), &(-h * dth));
            } else {
                qb = moved(pb, &(h * dp), &(h * dth));
                rb = moved(pb, &(-h * dp), &(-h * dth));
            }
            (phi(&qa, &qb) - phi(&ra, &rb)) / (2.0 * h)
        };
        (diff(1e-4) - diff(1e-6)).abs() < 1e-5
    })
}

/// Whether φ of a point against a hull is smooth around the point, with a margin: inside, one
/// nearest face plane; outside, one plane facing the point, its projection on that plane well
/// inside every other (the closest point inside a face, away from its edges).
fn hull_unique(point: &Vector3<f64>, hull: &ConvexHull, pose: &GeomPose) -> bool {
    let margin = 1e-2;
    let q = pose.rot.transpose() * (point - pose.pos);
    // distinct planes (coplanar triangles share one)
    let mut planes: Vec<(Vector3<f64>, f64)> = Vec::new();
    for (n, d) in hull.planes() {
        if !planes
            .iter()
            .any(|(m, e)| (m - n).amax() < 1e-9 && (e - d).abs() < 1e-9)
        {
            planes.push((n, d));
        }
    }
    let mut s: Vec<(f64, usize)> = (planes.iter().enumerate())
        .map(|(i, (n, d))| (n.dot(&q) - d, i))
        .collect();
    s.sort_by(|x, y| y.0.total_cmp(&x.0));
    if s[0].0 <= 0.0 {
        return s[0].0 - s[1].0 > margin;
    }
    let (n, _) = planes[s[0].1];
    let foot = q - s[0].0 * n;
    s[0].0 > margin
        && (planes.iter().enumerate())
            .filter(|&(i, _)| i != s[0].1)
            .all(|(_, (m, e))| m.dot(&foot) - e < -margin)
}

/// Whether φ of a point against a box is smooth around the point, with a margin.
///
/// Inside, φ = −(least depth) is piecewise linear: the nearest face must be unique. Outside, the
/// witness is unique but the distance `d` to the clamped point is only C¹: its Hessian is zero
/// in the face regions, of norm 1/d in the edge and corner regions, and jumps where `|q_k| = h_k`
/// on some axis. The envelope-theorem derivative holds there too, but a central difference of
/// step ε that straddles such a boundary is off by up to ~ε/(2d) (2e-6 against the check's 1e-6
/// tolerance for d ≈ 2 mm, as seen on box–box corners), so every axis must be clear of its
/// region boundary by the margin, which also keeps d above the margin (as the sphere features
/// require of their centre distances).
fn box_unique(point: &Vector3<f64>, half: &Vector3<f64>, pose_box: &GeomPose) -> bool {
    let margin = 1e-2;
    let q = pose_box.rot.transpose() * (point - pose_box.pos);
    let mut depths: Vec<f64> = (0..3).map(|k| half[k] - q[k].abs()).collect();
    if depths.iter().any(|d| *d < 0.0) {
        return depths.iter().all(|d| d.abs() > margin);
    }
    depths.sort_by(f64::total_cmp);
    depths[1] - depths[0] > margin
}

/// Central finite differences of φ under the 12 unit rigid motions against the envelope
/// theorem: `dφ = nᵀ(δp + δθ × (point_a − pos_a))` for A, the negative for B.
fn check_derivative(f: &Feature, sa: &Shape, pa: &GeomPose, sb: &Shape, pb: &GeomPose) {
    let w = evaluate(f, sa, pa, sb, pb);
    let eps = 1e-6;
    for (body, sign) in [(0, 1.0), (1, -1.0)] {
        let (p, witness) = if body == 0 {
            (pa, w.point_a)
        } else {
            (pb, w.point_b)
        };
        for k in 0..6 {
            let unit = Vector3::ith(k % 3, 1.0);
            let (dp, dth) = if k < 3 {
                (unit, Vector3::zeros())
            } else {
                (Vector3::zeros(), unit)
            };
            let phi = |h: f64| {
                let q = moved(p, &(h * dp), &(h * dth));
                let (qa, qb) = if body == 0 { (q, *pb) } else { (*pa, q) };
                evaluate(f, sa, &qa, sb, &qb).phi
            };
            let fd = (phi(eps) - phi(-eps)) / (2.0 * eps);
            let analytic = sign * w.normal.dot(&(dp + dth.cross(&(witness - p.pos))));
            assert!(
                (fd - analytic).abs() <= 1e-6 * (1.0 + analytic.abs()),
                "{f:?} body {body} dir {k}: fd {fd} vs {analytic}, {w:?}"
            );
        }
    }
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(256))]

    #[test]
    fn witnesses_are_consistent((ka, kb) in supported_pair(), da in dims(), db in dims(), pa in rand_pose(), pb in rand_pose(), target in -0.1..0.3f64) {
        let (a, b) = (make_shape(ka, da), make_shape(kb, db));
        let (features, swapped) = candidates(&a, &b).unwrap();
        let ((sa, pa), (sb, pb)) = if swapped { ((&b, pb), (&a, pa)) } else { ((&a, pa), (&b, pb)) };
        for f in &features {
            let w = evaluate(f, sa, &pa, sb, &pb);
            check_invariants(&w);
            // Move A along the normal so that this candidate is near `target` (both signs).
            let shifted = moved(&pa, &((target - w.phi) * w.normal), &Vector3::zeros());
            check_invariants(&evaluate(f, sa, &shifted, sb, &pb));
        }
    }

    #[test]
    fn phi_derivative_follows_envelope_theorem((ka, kb) in supported_pair(), da in dims(), db in dims(), pa in rand_pose(), pb in rand_pose(), target in -0.05..0.2f64) {
        let (a, b) = (make_shape(ka, da), make_shape(kb, db));
        let (features, swapped) = candidates(&a, &b).unwrap();
        let ((sa, pa), (sb, pb)) = if swapped { ((&b, pb), (&a, pa)) } else { ((&a, pa), (&b, pb)) };
        for f in &features {
            let w = evaluate(f, sa, &pa, sb, &pb);
            let shifted = moved(&pa, &((target - w.phi) * w.normal), &Vector3::zeros());
            for pose_a in [pa, shifted] {
                let w = evaluate(f, sa, &pose_a, sb, &pb);
                if unique_witness(f, &w, &pose_a, &pb) {
                    check_derivative(f, sa, &pose_a, sb, &pb);
                }
            }
        }
    }

    #[test]
    fn swapping_arguments_gives_the_same_contacts((ka, kb) in supported_pair(), da in dims(), db in dims(), pa in rand_pose(), pb in rand_pose()) {
        let (a, b) = (make_shape(ka, da), make_shape(kb, db));
        let (fab, sab) = candidates(&a, &b).unwrap();
        let (fba, sba) = candidates(&b, &a).unwrap();
        let (ab, ba) = (eval_pair(&a, &pa, &b, &pb), eval_pair(&b, &pb, &a, &pa));
        if a.rank() == b.rank() {
            prop_assert!(!sab && !sba);
            let min = |ws: &[Witness]| ws.iter().map(|w| w.phi).fold(f64::INFINITY, f64::min);
            prop_assert!((min(&ab) - min(&ba)).abs() < 1e-12);
            if ka == 3 {
                prop_assert!(sorted(phis(&ab)).iter().zip(sorted(phis(&ba))).all(|(x, y)| (x - y).abs() < 1e-12));
            }
        } else {
            prop_assert!(sab != sba && fab == fba);
            prop_assert_eq!(phis(&ab), phis(&ba));
        }
    }
}
