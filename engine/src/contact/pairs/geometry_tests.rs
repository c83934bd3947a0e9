//! Tests of the narrow phase: analytic values for every pair, unsupported pairs, degenerate
//! configurations and the segment kernel against brute force. The property tests on random
//! poses (invariants, envelope-theorem derivative, swapping) are in `geometry_props.rs`.

use super::kernels::segment_params;
use super::*;
use nalgebra::Rotation3;
use std::f64::consts::{FRAC_PI_2, PI};

const TOL: f64 = 1e-12;

#[path = "geometry_props.rs"]
mod props;

fn pose(pos: [f64; 3], rotvec: [f64; 3]) -> GeomPose {
    GeomPose::new(
        Vector3::from(pos),
        *Rotation3::new(Vector3::from(rotvec)).matrix(),
    )
}

fn at(pos: [f64; 3]) -> GeomPose {
    pose(pos, [0.0; 3])
}

/// Evaluates every candidate of the pair as a caller would, applying `swapped`.
fn eval_pair(a: &Shape, pa: &GeomPose, b: &Shape, pb: &GeomPose) -> Vec<Witness> {
    let (features, swapped) = candidates(a, b).unwrap();
    let run = |f: &Feature| {
        if swapped {
            evaluate(f, b, pb, a, pa)
        } else {
            evaluate(f, a, pa, b, pb)
        }
    };
    features.iter().map(run).collect()
}

fn phis(ws: &[Witness]) -> Vec<f64> {
    ws.iter().map(|w| w.phi).collect()
}

fn sorted(mut v: Vec<f64>) -> Vec<f64> {
    v.sort_by(f64::total_cmp);
    v
}

fn assert_all_close(got: &[f64], want: &[f64], tol: f64) {
    assert_eq!(got.len(), want.len(), "{got:?} vs {want:?}");
    for (g, w) in got.iter().zip(want) {
        assert!((g - w).abs() <= tol, "{got:?} vs {want:?}");
    }
}

fn assert_vec(got: &Vector3<f64>, want: [f64; 3]) {
    assert!(
        (got - Vector3::from(want)).norm() <= 1e-9,
        "{got:?} vs {want:?}"
    );
}

/// `point_a − point_b = φ n`, `|n| = 1`, everything finite.
fn check_invariants(w: &Witness) {
    let finite = w.phi.is_finite()
        && w.point_a
            .iter()
            .chain(w.point_b.iter())
            .chain(w.normal.iter())
            .all(|x| x.is_finite());
    assert!(finite, "{w:?}");
    assert!((w.normal.norm() - 1.0).abs() < 1e-12, "{w:?}");
    let scale = 1.0 + w.point_a.norm() + w.point_b.norm();
    assert!(
        (w.point_a - w.point_b - w.phi * w.normal).norm() < 1e-12 * scale,
        "{w:?}"
    );
}

// ---------------------------------------------------------------- analytic values

#[test]
fn sphere_on_plane_at_known_heights() {
    let sphere = Shape::Sphere { radius: 0.5 };
    for (z, phi) in [(1.0, 0.5), (0.5, 0.0), (0.3, -0.2)] {
        let ws = eval_pair(&sphere, &at([0.2, -0.1, z]), &Shape::Plane, &at([0.0; 3]));
        assert_all_close(&phis(&ws), &[phi], TOL);
        assert_vec(&ws[0].point_a, [0.2, -0.1, z - 0.5]);
        assert_vec(&ws[0].point_b, [0.2, -0.1, 0.0]);
        assert_vec(&ws[0].normal, [0.0, 0.0, 1.0]);
    }
    let ws = eval_pair(
        &Shape::Point,
        &at([1.0, 2.0, -0.25]),
        &Shape::Plane,
        &at([0.0; 3]),
    );
    assert_all_close(&phis(&ws), &[-0.25], TOL);
}

#[test]
fn sphere_on_tilted_plane() {
    let plane = pose([0.3, 0.1, -0.2], [PI / 6.0, 0.0, 0.0]);
    let n = plane.rot.column(2).into_owned();
    let center = plane.pos + 0.7 * n + 0.4 * plane.rot.column(0);
    let ws = eval_pair(
        &Shape::Plane,
        &plane,
        &Shape::Sphere { radius: 0.25 },
        &GeomPose::new(center, Matrix3::identity()),
    );
    assert_all_close(&phis(&ws), &[0.45], TOL);
    assert!((ws[0].normal - n).norm() < TOL);
}

#[test]
fn box_resting_on_face_and_on_corner() {
    let cuboid = Shape::Box {
        half_extents: Vector3::new(0.5, 0.3, 0.2),
    };
    let ws = eval_pair(&cuboid, &at([1.0, 2.0, 0.2]), &Shape::Plane, &at([0.0; 3]));
    assert_all_close(
        &sorted(phis(&ws)),
        &[0.0, 0.0, 0.0, 0.0, 0.4, 0.4, 0.4, 0.4],
        TOL,
    );
    // A unit-half cube balanced on corner (−1,−1,−1): the body diagonal is vertical.
    let diagonal = Vector3::new(1.0, 1.0, 1.0).normalize();
    let rot = Rotation3::rotation_between(&diagonal, &Vector3::z()).unwrap();
    let s3 = 3f64.sqrt();
    let cube = Shape::Box {
        half_extents: Vector3::new(1.0, 1.0, 1.0),
    };
    let ws = eval_pair(
        &cube,
        &GeomPose::new(Vector3::new(0.0, 0.0, s3), *rot.matrix()),
        &Shape::Plane,
        &at([0.0; 3]),
    );
    let (lo, hi) = (s3 - 1.0 / s3, s3 + 1.0 / s3);
    assert_all_close(
        &sorted(phis(&ws)),
        &[0.0, lo, lo, lo, hi, hi, hi, 2.0 * s3],
        1e-12,
    );
}

#[test]
fn capsule_lying_flat_and_tilted() {
    let capsule = Shape::Capsule {
        radius: 0.1,
        half_length: 0.5,
    };
    let ws = eval_pair(
        &capsule,
        &pose([0.0, 0.0, 0.1], [FRAC_PI_2, 0.0, 0.0]),
        &Shape::Plane,
        &at([0.0; 3]),
    );
    assert_all_close(&phis(&ws), &[0.0, 0.0], TOL);
    let tilt = 0.3f64;
    let ws = eval_pair(
        &capsule,
        &pose([0.0, 0.0, 1.0], [tilt, 0.0, 0.0]),
        &Shape::Plane,
        &at([0.0; 3]),
    );
    let dz = 0.5 * tilt.cos();
    assert_all_close(&phis(&ws), &[1.0 - dz - 0.1, 1.0 + dz - 0.1], TOL);
}

#[test]
fn cylinder_standing_lying_and_tilted() {
    let cylinder = Shape::Cylinder {
        radius: 0.3,
        half_length: 0.4,
    };
    let ground = at([0.0; 3]);
    let ws = eval_pair(&cylinder, &at([0.0, 0.0, 0.4]), &Shape::Plane, &ground);
    assert_all_close(&phis(&ws), &[0.0, 0.0, 0.0, 0.0, 0.8, 0.8, 0.8, 0.8], TOL);
    assert_vec(&ws[0].point_a, [0.3, 0.0, 0.0]); // axis ∥ normal: rim point on local +x
    let ws = eval_pair(
        &cylinder,
        &pose([0.0, 0.0, 0.3], [FRAC_PI_2, 0.0, 0.0]),
        &Shape::Plane,
        &ground,
    );
    let s = 0.3 * (2.0 * PI / 3.0).sin();
    let disk = [0.0, 0.3, 0.3 + s, 0.3 - s];
    assert_all_close(&phis(&ws), &[disk, disk].concat(), 1e-12);
    let tilt = 0.4f64;
    let ws = eval_pair(
        &cylinder,
        &pose([0.0, 0.0, 1.0], [tilt, 0.0, 0.0]),
        &Shape::Plane,
        &ground,
    );
    let lowest = 1.0 - 0.4 * tilt.cos() - 0.3 * tilt.sin(); // bottom disk, lowest rim point
    assert!((ws[0].phi - lowest).abs() < TOL);
    assert!(ws.iter().all(|w| w.phi >= lowest - TOL));
}

#[test]
fn ellipsoid_rotated_on_plane() {
    let radii = Vector3::new(0.5, 0.2, 0.1);
    let ellipsoid = Shape::Ellipsoid { radii };
    let ws = eval_pair(
        &ellipsoid,
        &pose([0.0, 0.0, 1.0], [0.0, FRAC_PI_2, 0.0]),
        &Shape::Plane,
        &at([0.0; 3]),
    );
    assert_all_close(&phis(&ws), &[0.5], TOL);
    assert_vec(&ws[0].point_a, [0.0, 0.0, 0.5]);
    let tilt = 0.7f64;
    let body = pose([0.1, 0.2, 1.0], [tilt, 0.0, 0.0]);
    let ws = eval_pair(&ellipsoid, &body, &Shape::Plane, &at([0.0; 3]));
    let support = ((0.2 * tilt.sin()).powi(2) + (0.1 * tilt.cos()).powi(2)).sqrt();
    assert_all_close(&phis(&ws), &[1.0 - support], TOL);
    let local = body.rot.transpose() * (ws[0].point_a - body.pos); // witness lies on the ellipsoid
    assert!((local.component_div(&radii).norm() - 1.0).abs() < 1e-12);
}

#[test]
fn sphere_sphere_values_and_coincident_centres() {
    let (a, b) = (Shape::Sphere { radius: 0.3 }, Shape::Sphere { radius: 0.4 });
    let ws = eval_pair(&a, &at([1.0, 0.0, 0.0]), &b, &at([0.0; 3]));
    assert_all_close(&phis(&ws), &[0.3], TOL);
    assert_vec(&ws[0].point_a, [0.7, 0.0, 0.0]);
    assert_vec(&ws[0].point_b, [0.4, 0.0, 0.0]);
    let ws = eval_pair(
        &a,
        &at([0.0; 3]),
        &b,
        &pose([0.0; 3], [FRAC_PI_2, 0.0, 0.0]),
    );
    assert_all_close(&phis(&ws), &[-0.7], TOL);
    assert_vec(&ws[0].normal, [0.0, -1.0, 0.0]); // +z of B
    let ws = eval_pair(&Shape::Point, &at([0.0, 0.5, 0.0]), &b, &at([0.0; 3]));
    assert_all_close(&phis(&ws), &[0.1], TOL);
}

#[test]
fn sphere_capsule_side_and_end() {
    let sphere = Shape::Sphere { radius: 0.3 };
    let capsule = Shape::Capsule {
        radius: 0.2,
        half_length: 1.0,
    };
    let ws = eval_pair(&sphere, &at([1.0, 0.0, 0.5]), &capsule, &at([0.0; 3]));
    assert_all_close(&phis(&ws), &[0.5], TOL);
    assert_vec(&ws[0].point_b, [0.2, 0.0, 0.5]);
    let ws = eval_pair(&capsule, &at([0.0; 3]), &sphere, &at([0.0, 0.0, 2.0]));
    assert_all_close(&phis(&ws), &[0.5], TOL);
    assert_vec(&ws[0].point_a, [0.0, 0.0, 1.7]); // swapped: point_a lies on the sphere
}

#[test]
fn capsule_capsule_crossing_and_parallel() {
    let capsule = Shape::Capsule {
        radius: 0.1,
        half_length: 1.0,
    };
    let along_x = [0.0, FRAC_PI_2, 0.0];
    let along_y = [FRAC_PI_2, 0.0, 0.0];
    let ws = eval_pair(
        &capsule,
        &pose([0.0, 0.0, 0.5], along_x),
        &capsule,
        &pose([0.0; 3], along_y),
    );
    assert!((ws[0].phi - 0.3).abs() < TOL);
    assert_vec(&ws[0].point_a, [0.0, 0.0, 0.4]);
    assert_vec(&ws[0].normal, [0.0, 0.0, 1.0]);
    let end = 1.0f64.hypot(0.5) - 0.2; // A's ends (±1, 0, 0.5) against B's centre
    assert_all_close(&phis(&ws[1..]), &[end, end], TOL);
    // Side by side: all three candidates touch, so the pair is supported at both ends.
    let long = Shape::Capsule {
        radius: 0.1,
        half_length: 2.0,
    };
    let ws = eval_pair(
        &capsule,
        &pose([0.3, 0.5, 0.0], along_x),
        &long,
        &pose([0.0; 3], along_x),
    );
    assert_all_close(&phis(&ws), &[0.3, 0.3, 0.3], TOL);
    assert_vec(&ws[1].point_a, [-0.7, 0.4, 0.0]);
    assert_vec(&ws[2].point_a, [1.3, 0.4, 0.0]);
}

#[test]
fn sphere_box_outside_inside_edge_corner() {
    let cuboid = Shape::Box {
        half_extents: Vector3::new(1.0, 0.5, 0.25),
    };
    let sphere = Shape::Sphere { radius: 0.1 };
    let b = pose([0.0; 3], [0.0; 3]);
    let cases = [
        ([1.5, 0.0, 0.0], 0.4, [1.0, 0.0, 0.0], [1.0, 0.0, 0.0]), // face
        ([0.0, 0.0, 0.2], -0.15, [0.0, 0.0, 0.25], [0.0, 0.0, 1.0]), // inside, nearest face z
        ([0.9, -0.1, 0.0], -0.2, [1.0, -0.1, 0.0], [1.0, 0.0, 0.0]), // inside, nearest face x
        ([1.3, 0.9, 0.0], 0.4, [1.0, 0.5, 0.0], [0.6, 0.8, 0.0]), // edge
        (
            [1.2, -0.7, -0.45],
            0.2 * 3f64.sqrt() - 0.1,
            [1.0, -0.5, -0.25],
            [1.0, -1.0, -1.0],
        ), // corner
    ];
    for (center, phi, point_b, normal) in cases {
        let ws = eval_pair(&sphere, &at(center), &cuboid, &b);
        assert_all_close(&phis(&ws), &[phi], 1e-12);
        assert_vec(&ws[0].point_b, point_b);
        assert_vec(&ws[0].normal, Vector3::from(normal).normalize().into());
    }
    // A point at the box centre: the face of the smallest half-extent (z), + side.
    let ws = eval_pair(&Shape::Point, &at([0.0; 3]), &cuboid, &b);
    assert_all_close(&phis(&ws), &[-0.25], TOL);
    assert_vec(&ws[0].normal, [0.0, 0.0, 1.0]);
}

#[test]
fn capsule_box_three_spheres() {
    let capsule = Shape::Capsule {
        radius: 0.1,
        half_length: 0.5,
    };
    let cuboid = Shape::Box {
        half_extents: Vector3::new(1.0, 1.0, 0.5),
    };
    let tilt = 0.2f64;
    let ws = eval_pair(
        &capsule,
        &pose([0.0, 0.0, 1.0], [0.0, FRAC_PI_2 + tilt, 0.0]),
        &cuboid,
        &at([0.0; 3]),
    );
    let dz = 0.5 * tilt.sin();
    assert_all_close(&phis(&ws[..3]), &[0.4 + dz, 0.4, 0.4 - dz], TOL);
    // the segment lies over the face, crossing no edge: its two crossing slots are empty
    assert!(ws[3..].iter().all(|w| w.phi > 1.0), "{:?}", &ws[3..]);
}

#[test]
fn box_box_stacked() {
    let base = Shape::Box {
        half_extents: Vector3::new(1.0, 1.0, 0.5),
    };
    let cube = Shape::Box {
        half_extents: Vector3::new(0.5, 0.5, 0.5),
    };
    let ws = eval_pair(&cube, &at([0.0, 0.0, 1.0]), &base, &at([0.0; 3]));
    let (a_on_b, rest) = ws.split_at(8);
    let (b_on_a, crossings) = rest.split_at(8);
    // aligned boxes: no edge crosses another (the eight slots are empty, far out of reach)
    assert!(crossings.iter().all(|w| w.phi > 2.0));
    assert_all_close(
        &sorted(phis(a_on_b)),
        &[0.0, 0.0, 0.0, 0.0, 1.0, 1.0, 1.0, 1.0],
        TOL,
    );
    let (top, bottom) = (0.5f64.sqrt(), 1.5f64.sqrt());
    assert_all_close(
        &sorted(phis(b_on_a)),
        &[top, top, top, top, bottom, bottom, bottom, bottom],
        TOL,
    );
    assert!(b_on_a.iter().all(|w| w.normal.z >= 0.0)); // from the base's corners up towards the cube
    ws.iter().for_each(check_invariants);
}

#[test]
fn unsupported_pairs_and_bad_dimensions() {
    let cylinder = Shape::Cylinder {
        radius: 0.1,
        half_length: 0.2,
    };
    let ellipsoid = Shape::Ellipsoid {
        radii: Vector3::new(0.1, 0.2, 0.3),
    };
    assert!(candidates(&Shape::Plane, &Shape::Plane).is_err());
    assert!(
        candidates(&ellipsoid, &Shape::Sphere { radius: 1.0 })
            .unwrap_err()
            .contains("not supported")
    );
    assert!(
        candidates(&Shape::Point, &ellipsoid)
            .unwrap_err()
            .contains("not supported")
    );
    assert!(candidates(&cylinder, &ellipsoid).is_err());
    assert!(candidates(&Shape::Sphere { radius: -1.0 }, &Shape::Plane).is_err());
    assert!(
        candidates(
            &Shape::Box {
                half_extents: Vector3::new(1.0, f64::NAN, 1.0)
            },
            &Shape::Plane
        )
        .is_err()
    );
    let counts = [
        (Shape::Sphere { radius: 1.0 }, 1),
        (cylinder, 8),
        (ellipsoid, 1),
        (Shape::Point, 1),
    ];
    for (shape, n) in counts {
        let (features, swapped) = candidates(&Shape::Plane, &shape).unwrap();
        assert!(swapped && features.len() == n);
    }
}

#[test]
fn segment_params_match_brute_force() {
    let mut seed = 12345u64;
    let mut rand = || {
        seed = seed
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        (seed >> 11) as f64 / (1u64 << 53) as f64 * 2.0 - 1.0
    };
    for _ in 0..200 {
        let r = Vector3::new(rand(), rand(), rand());
        let d1 = Vector3::new(rand(), rand(), rand()).normalize();
        let d2 = Vector3::new(rand(), rand(), rand()).normalize();
        let (h1, h2) = (rand().abs() + 0.1, rand().abs() + 0.1);
        let dist = |s: f64, t: f64| (r + s * d1 - t * d2).norm();
        let (s, t) = segment_params(&r, &d1, h1, &d2, h2);
        assert!(s.abs() <= h1 && t.abs() <= h2);
        let n = 200;
        let grid = (0..=n).flat_map(|i| (0..=n).map(move |j| (i, j)));
        let best = grid
            .map(|(i, j)| {
                dist(
                    h1 * (2.0 * i as f64 / n as f64 - 1.0),
                    h2 * (2.0 * j as f64 / n as f64 - 1.0),
                )
            })
            .fold(f64::INFINITY, f64::min);
        assert!(dist(s, t) <= best + 1e-12, "{} > {best}", dist(s, t));
    }
}

#[test]
fn degenerate_configurations_stay_finite() {
    let shapes = [
        Shape::Sphere { radius: 0.0 },
        Shape::Point,
        Shape::Capsule {
            radius: 0.0,
            half_length: 0.0,
        },
        Shape::Box {
            half_extents: Vector3::zeros(),
        },
        Shape::Cylinder {
            radius: 0.0,
            half_length: 0.0,
        },
        Shape::Ellipsoid {
            radii: Vector3::zeros(),
        },
        Shape::Plane,
        Shape::Capsule {
            radius: 0.2,
            half_length: 0.5,
        },
        Shape::Box {
            half_extents: Vector3::new(0.5, 0.5, 0.5),
        },
        Shape::Cylinder {
            radius: 0.2,
            half_length: 0.5,
        },
    ];
    let same = at([0.0; 3]);
    for a in &shapes {
        for b in &shapes {
            if candidates(a, b).is_ok() {
                eval_pair(a, &same, b, &same)
                    .iter()
                    .for_each(check_invariants);
            }
        }
    }
    // Coaxial parallel capsules, and a capsule whose axis is crossing B's exactly.
    let capsule = Shape::Capsule {
        radius: 0.1,
        half_length: 1.0,
    };
    let crossing = pose([0.0; 3], [FRAC_PI_2, 0.0, 0.0]);
    let ws = eval_pair(&capsule, &crossing, &capsule, &same);
    ws.iter().for_each(check_invariants);
    assert_vec(&ws[0].normal, [-1.0, 0.0, 0.0]); // axis_a × axis_b = (0, −1, 0) × (0, 0, 1)
}

fn hull_shape(points: &[Vector3<f64>]) -> Shape {
    Shape::Mesh {
        hull: std::sync::Arc::new(crate::contact::hull::ConvexHull::new(points).unwrap()),
    }
}

fn is_edge_core(f: &Feature) -> bool {
    matches!(
        f,
        Feature::CoreSolid {
            a: Core::Edge { .. },
            ..
        } | Feature::SolidCore {
            b: Core::Edge { .. },
            ..
        }
    )
}

#[test]
fn a_hull_edge_through_another_hull_with_both_ends_outside_is_measured_by_its_edge_core() {
    // a 1 m triangular rod whose lowest edge runs 1 cm below the top face of a 20 cm cube,
    // across it (turned 0.3 rad about z), both of its ends 0.4 m outside the cube: every
    // vertex of either hull is outside the other, and the rod's lowest edge, as a core against
    // the cube, finds the 1 cm overlap
    let mut rod = Vec::new();
    for x in [-0.5, 0.5] {
        for (y, z) in [(0.0, 0.0), (-0.01, 0.02), (0.01, 0.02)] {
            rod.push(Vector3::new(x, y, z));
        }
    }
    let cube: Vec<Vector3<f64>> = (0..8)
        .map(|k| {
            Vector3::new(1.0, 1.0, 1.0) * 0.1
                - Vector3::new(
                    0.2 * f64::from(k & 1),
                    0.2 * f64::from((k >> 1) & 1),
                    0.2 * f64::from((k >> 2) & 1),
                )
        })
        .collect();
    let (a, b) = (hull_shape(&rod), hull_shape(&cube));
    let (pa, pb) = (pose([0.0, 0.0, 0.09], [0.0, 0.0, 0.3]), at([0.0; 3]));
    let (features, swapped) = candidates(&a, &b).unwrap();
    assert!(!swapped);
    let ws = eval_pair(&a, &pa, &b, &pb);
    let edges: Vec<f64> = (features.iter().zip(&ws))
        .filter(|(f, _)| is_edge_core(f))
        .map(|(_, w)| w.phi)
        .collect();
    // 9 rod edges and 12 cube edges
    assert_eq!(edges.len(), 9 + 12);
    let vertices = (features.iter().zip(&ws))
        .filter(|(f, _)| matches!(f, Feature::SphereHull { .. } | Feature::HullSphere { .. }))
        .map(|(_, w)| w.phi)
        .fold(f64::INFINITY, f64::min);
    assert!(vertices > 0.05, "a vertex within reach: {vertices}");
    let deepest = edges.iter().copied().fold(f64::INFINITY, f64::min);
    assert!((deepest + 0.01).abs() < 1e-9, "deepest edge {deepest}");
}

#[test]
fn detailed_hulls_meet_at_their_vertices_only() {
    // 200 points on a sphere: a hull of ~600 edges has no crossing slots, and no edge cores
    let sphere: Vec<Vector3<f64>> = (0..200)
        .map(|k| {
            let z = 1.0 - 2.0 * (f64::from(k) + 0.5) / 200.0;
            let phi = f64::from(k) * 2.399_963_229_728_653; // golden angle
            let r = (1.0 - z * z).sqrt();
            Vector3::new(r * phi.cos(), r * phi.sin(), z) * 0.1
        })
        .collect();
    let cube: Vec<Vector3<f64>> = (0..8)
        .map(|k| Vector3::new(f64::from(k & 1), f64::from((k >> 1) & 1), f64::from(k >> 2)))
        .collect();
    let (features, _) = candidates(&hull_shape(&sphere), &hull_shape(&cube)).unwrap();
    assert!(!features.iter().any(is_edge_core));
    assert!(!features.iter().any(|f| f.is_crossing_slot()));
    assert_eq!(features.len(), 200 + 8);
}
