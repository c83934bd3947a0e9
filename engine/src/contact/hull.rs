//! Convex hulls of meshes. MuJoCo collides a mesh geom as the convex hull of its vertices; so
//! does ukemi: a hull's vertices are contact points against other shapes, and the signed
//! distance of a point to the hull ([`ConvexHull::signed_distance`]) is the kernel of every
//! candidate against it. Its mass properties ([`ConvexHull::mass_properties`]) are those of
//! the solid hull (MuJoCo's mesh `inertia="convex"`).
use nalgebra::{Matrix3, Vector3};

/// Below this length a vector has no usable direction (as in the other kernels).
const MIN_NORM: f64 = 1e-100;

/// A convex polytope: its vertices and outward triangles, in the geom frame.
#[derive(Clone, Debug, PartialEq)]
pub struct ConvexHull {
    /// The hull's vertices (m, geom frame): the mesh points on the hull.
    pub vertices: Vec<Vector3<f64>>,
    /// Triangles as vertex indices, counter-clockwise seen from outside.
    pub triangles: Vec<[usize; 3]>,
    /// Outward unit normal of each triangle's plane.
    normals: Vec<Vector3<f64>>,
    /// Offset of each triangle's plane: `n · x = d` on it, `< d` inside.
    offsets: Vec<f64>,
    /// The largest distance of a vertex from the origin (kept: the activation asks for it per
    /// candidate, and a mesh has one candidate per vertex).
    radius: f64,
    /// The hull's edges with their two faces' normals ([`Self::edges`]' order), for the edge
    /// crossings of [`super::geometry::box_edges`].
    edge_faces: Vec<HullEdge>,
    /// The mean of the vertices: a point inside the hull.
    interior: Vector3<f64>,
}

/// An edge of a hull (its geom frame) with the outward normals of its two faces.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct HullEdge {
    /// Midpoint.
    pub centre: Vector3<f64>,
    /// Unit direction.
    pub direction: Vector3<f64>,
    /// Half the length (m).
    pub half_length: f64,
    /// Outward unit normals of the two faces that meet at the edge.
    pub faces: [Vector3<f64>; 2],
}

impl ConvexHull {
    /// The convex hull of `points` (at least four, not all in one plane, all finite).
    pub fn new(points: &[Vector3<f64>]) -> Result<ConvexHull, String> {
        if let Some(p) = points.iter().find(|p| !p.iter().all(|x| x.is_finite())) {
            return Err(format!("mesh vertex {p:?} is not finite"));
        }
        let center = points
            .iter()
            .fold(Vector3::zeros(), |s: Vector3<f64>, p| s + p)
            / points.len().max(1) as f64;
        let scale = points
            .iter()
            .map(|p| (p - center).amax())
            .fold(0.0, f64::max);
        if points.len() < 4 || scale <= 0.0 {
            return Err(format!(
                "a mesh needs at least 4 points spanning a volume, got {}",
                points.len()
            ));
        }
        // (the hull is found at unit scale: the library's tolerance is absolute)
        let unit: Vec<Vec<f64>> = points
            .iter()
            .map(|p| ((p - center) / scale).iter().copied().collect())
            .collect();
        // In exact integer arithmetic (the points as multiples of f64::EPSILON at unit scale):
        // its floating-point hull, on CAD meshes of float32 vertices (pybullet_data's laikago
        // legs), left input points up to 3 cm outside a 13 cm hull. (The library indexes and
        // unwraps inside: a panic on a degenerate cloud is an error here, never a crash.)
        let built = std::panic::catch_unwind(|| chull::ConvexHullWrapper::try_new(&unit, None));
        let hull = match built {
            Ok(Ok(h)) => h,
            Ok(Err(e)) => {
                return Err(format!(
                    "no convex hull of the mesh's {} points: {e:?}",
                    points.len()
                ));
            }
            Err(_) => {
                return Err(format!(
                    "no convex hull of the mesh's {} points (degenerate)",
                    points.len()
                ));
            }
        };
        let (pts, flat) = hull.vertices_indices();
        // each hull point is an input point on the integer grid: back to its index
        let grid = |x: f64| (x / f64::EPSILON).round() as i64;
        let key = |p: &[f64]| [grid(p[0]), grid(p[1]), grid(p[2])];
        let truncated = |x: f64| (x / f64::EPSILON).trunc() as i64;
        let input: std::collections::HashMap<[i64; 3], usize> = (unit.iter().enumerate())
            .map(|(i, p)| ([truncated(p[0]), truncated(p[1]), truncated(p[2])], i))
            .collect();
        let index: Vec<usize> = pts
            .iter()
            .map(|p| input.get(&key(p)).copied())
            .collect::<Option<_>>()
            .ok_or("the hull library returned a point that is not an input point")?;
        let triangles: Vec<[usize; 3]> = flat
            .chunks_exact(3)
            .map(|t| [index[t[0]], index[t[1]], index[t[2]]])
            .collect();
        let (vertices, triangles) = canonical(points, &triangles, scale);
        if triangles.len() < 4 {
            return Err(format!(
                "the hull of the mesh's {} points has no volume",
                points.len()
            ));
        }
        let mut out = ConvexHull {
            vertices,
            triangles,
            normals: Vec::new(),
            offsets: Vec::new(),
            radius: 0.0,
            edge_faces: Vec::new(),
            interior: Vector3::zeros(),
        };
        out.refresh_planes();
        // (every face a sliver, or no volume: no inside test and no mass would hold)
        let volume = out.mass_properties().0;
        if volume.is_nan()
            || volume <= 1e-12 * scale.powi(3)
            || out.offsets.iter().all(|d| d.is_nan())
        {
            return Err(format!(
                "the hull of the mesh's {} points has no volume",
                points.len()
            ));
        }
        Ok(out)
    }

    fn refresh_planes(&mut self) {
        self.radius = self.vertices.iter().map(|v| v.norm()).fold(0.0, f64::max);
        self.normals.clear();
        self.offsets.clear();
        for t in &self.triangles {
            let (a, b, c) = (
                self.vertices[t[0]],
                self.vertices[t[1]],
                self.vertices[t[2]],
            );
            let n = (b - a).cross(&(c - a));
            // a sliver's normal is round-off: its plane would cut through the hull, so it
            // takes no part in the inside test (NaN offset; its neighbours bound the hull)
            let sliver = n.norm() <= 1e-9 * (b - a).norm() * (c - a).norm();
            let n = n.normalize();
            self.normals.push(n);
            self.offsets.push(if sliver { f64::NAN } else { n.dot(&a) });
        }
        self.interior = self.vertices.iter().sum::<Vector3<f64>>() / self.vertices.len() as f64;
        let sliver = |f: usize| self.offsets[f].is_nan();
        self.edge_faces = (self.sides().into_iter())
            .filter(|&(_, f, g)| !sliver(f) && !g.is_some_and(sliver))
            .map(|((i, j), f, g)| {
                let (a, b) = (self.vertices[i], self.vertices[j]);
                let half_length = 0.5 * (b - a).norm();
                HullEdge {
                    centre: 0.5 * (a + b),
                    direction: (b - a) / (2.0 * half_length).max(1e-300),
                    half_length,
                    faces: [self.normals[f], self.normals[g.unwrap_or(f)]],
                }
            })
            .collect();
    }

    /// The hull in a new frame: `x' = rot (x - origin)` for every vertex.
    pub fn transformed(&self, rot: &Matrix3<f64>, origin: &Vector3<f64>) -> ConvexHull {
        let mut out = self.clone();
        for v in &mut out.vertices {
            *v = rot * (*v - origin);
        }
        out.refresh_planes();
        out
    }

    /// The triangles' planes: outward unit normal and offset (`n · x = d` on the plane).
    pub fn planes(&self) -> impl Iterator<Item = (Vector3<f64>, f64)> + '_ {
        self.normals
            .iter()
            .copied()
            .zip(self.offsets.iter().copied())
            .filter(|(_, d)| d.is_finite())
    }

    /// The hull's edges as vertex index pairs `(i, j)`, `i < j`, in order: the sides of its
    /// triangles between two different planes (a diagonal between coplanar triangles of one
    /// face is not an edge).
    pub fn edges(&self) -> Vec<(usize, usize)> {
        self.sides().into_iter().map(|(e, _, _)| e).collect()
    }

    /// The hull's edges with their triangles: `((i, j), f, g)`, [`Self::edges`]' order (`g`
    /// `None` for a side with one triangle).
    fn sides(&self) -> Vec<((usize, usize), usize, Option<usize>)> {
        let mut sides: Vec<((usize, usize), usize)> = Vec::new();
        for (f, t) in self.triangles.iter().enumerate() {
            for k in 0..3 {
                let (a, b) = (t[k], t[(k + 1) % 3]);
                sides.push(((a.min(b), a.max(b)), f));
            }
        }
        sides.sort_unstable();
        let coplanar = |f: usize, g: usize| {
            (self.normals[f] - self.normals[g]).amax() < 1e-9
                && (self.offsets[f] - self.offsets[g]).abs() < 1e-9
        };
        let mut edges: Vec<((usize, usize), usize, Option<usize>)> = Vec::new();
        for pair in sides.chunks(2) {
            // (a closed hull has two triangles on each side; a lone side is kept)
            match pair {
                [(e, f), (e2, g)] if e == e2 => {
                    if !coplanar(*f, *g) {
                        edges.push((*e, *f, Some(*g)));
                    }
                }
                _ => edges.push((pair[0].0, pair[0].1, None)),
            }
        }
        edges.dedup_by_key(|e| e.0);
        edges
    }

    /// The hull's edges with the normals of their two faces.
    pub fn edge_faces(&self) -> &[HullEdge] {
        &self.edge_faces
    }

    /// A point inside the hull (the mean of its vertices; geom frame).
    pub fn interior(&self) -> Vector3<f64> {
        self.interior
    }

    /// The support function along `u` (geom frame): the largest `v · u` over the vertices.
    pub fn support(&self, u: &Vector3<f64>) -> f64 {
        (self.vertices.iter())
            .map(|v| v.dot(u))
            .fold(f64::NEG_INFINITY, f64::max)
    }

    /// The largest distance of a vertex from the geom origin (m).
    pub fn radius(&self) -> f64 {
        self.radius
    }

    /// Volume (m³), centre of volume (geom frame) and inertia about that centre per unit
    /// density (geom axes) of the solid hull, by the divergence theorem over tetrahedra from
    /// the origin to each triangle.
    pub fn mass_properties(&self) -> (f64, Vector3<f64>, Matrix3<f64>) {
        let (mut volume, mut first, mut second) = (0.0, Vector3::zeros(), Matrix3::zeros());
        for t in &self.triangles {
            let (a, b, c) = (
                self.vertices[t[0]],
                self.vertices[t[1]],
                self.vertices[t[2]],
            );
            let v = a.dot(&b.cross(&c)) / 6.0;
            let s = a + b + c;
            volume += v;
            first += v * s / 4.0;
            // ∫ x xᵀ over the tetrahedron (0, a, b, c)
            second += v / 20.0
                * (a * a.transpose() + b * b.transpose() + c * c.transpose() + s * s.transpose());
        }
        let com = first / volume;
        let about_com = second - volume * com * com.transpose();
        let inertia = Matrix3::identity() * about_com.trace() - about_com;
        (volume, com, inertia)
    }

    /// Signed distance of point `q` (geom frame) to the hull's surface, negative inside:
    /// `(distance, the closest surface point, outward unit normal)`. Outside, the exact closest
    /// point (over the triangles whose planes face `q`: the closest point lies on one of them);
    /// inside, the projection onto the nearest face plane (first such face on ties).
    pub fn signed_distance(&self, q: &Vector3<f64>) -> (f64, Vector3<f64>, Vector3<f64>) {
        let mut nearest = 0;
        let mut best = f64::NEG_INFINITY;
        for (f, (n, d)) in self.normals.iter().zip(&self.offsets).enumerate() {
            let s = n.dot(q) - d;
            // (NaN for a sliver: never the best)
            if s > best {
                (best, nearest) = (s, f);
            }
        }
        if best > 0.0 {
            let mut closest = (f64::INFINITY, *q);
            for (f, t) in self.triangles.iter().enumerate() {
                if self.normals[f].dot(q) - self.offsets[f] <= 0.0 {
                    continue;
                }
                let p = closest_on_triangle(
                    q,
                    &self.vertices[t[0]],
                    &self.vertices[t[1]],
                    &self.vertices[t[2]],
                );
                let d2 = (q - p).norm_squared();
                if d2 < closest.0 {
                    closest = (d2, p);
                }
            }
            let gap = q - closest.1;
            let dist = gap.norm();
            if dist > MIN_NORM && dist.is_finite() {
                return (dist, closest.1, gap / dist);
            }
        }
        let n = self.normals[nearest];
        (best, q - best * n, n)
    }
}

/// The hull's vertices and triangles made independent of the order the hull library found its
/// facets in (it iterates hash sets, so its order changes from process to process, and with it
/// the candidates' order and a chaotic pile's trajectory): coplanar triangles are merged into
/// faces; the corners of the polytope are kept (a point inside a face or on an edge is not a
/// vertex: it lies on fewer than three independent face planes); each face's corners are
/// ordered counter-clockwise seen from outside, from the lowest input index, and fanned into
/// triangles; vertices come in input order and faces by their corners.
fn canonical(
    points: &[Vector3<f64>],
    triangles: &[[usize; 3]],
    scale: f64,
) -> (Vec<Vector3<f64>>, Vec<[usize; 3]>) {
    let mut used: Vec<usize> = triangles.iter().flatten().copied().collect();
    used.sort_unstable();
    used.dedup();
    let inside = used
        .iter()
        .fold(Vector3::zeros(), |s: Vector3<f64>, &i| s + points[i])
        / used.len().max(1) as f64;
    // faces: outward unit normal, offset, the points on it
    let mut faces: Vec<(Vector3<f64>, f64, Vec<usize>)> = Vec::new();
    for t in triangles {
        let (a, b, c) = (points[t[0]], points[t[1]], points[t[2]]);
        let n = (b - a).cross(&(c - a));
        // (slivers of coplanar points carry no face)
        if n.norm() <= 1e-14 * scale * scale {
            continue;
        }
        let n = if n.dot(&(a - inside)) >= 0.0 { n } else { -n }.normalize();
        let d = n.dot(&a);
        match (faces.iter_mut()).find(|f| (f.0 - n).amax() < 1e-9 && (f.1 - d).abs() < 1e-9 * scale)
        {
            Some(f) => f.2.extend_from_slice(t),
            None => faces.push((n, d, t.to_vec())),
        }
    }
    // a corner lies on three faces whose normals span space
    let on = |i: usize| faces.iter().filter(move |f| f.2.contains(&i)).map(|f| f.0);
    let corner = |i: usize| {
        let normals: Vec<Vector3<f64>> = on(i).collect();
        (0..normals.len()).any(|x| {
            (x + 1..normals.len()).any(|y| {
                (y + 1..normals.len())
                    .any(|z| normals[x].dot(&normals[y].cross(&normals[z])).abs() > 1e-9)
            })
        })
    };
    let corners: Vec<usize> = used.iter().copied().filter(|&i| corner(i)).collect();
    let mut polygons: Vec<Vec<usize>> = Vec::new();
    for (n, _, members) in &faces {
        let mut ring: Vec<usize> = corners
            .iter()
            .copied()
            .filter(|i| members.contains(i))
            .collect();
        if ring.len() < 3 {
            continue;
        }
        let c = ring
            .iter()
            .fold(Vector3::zeros(), |s: Vector3<f64>, &i| s + points[i])
            / ring.len() as f64;
        let u = (points[ring[0]] - c).normalize();
        let v = n.cross(&u);
        let angle = |i: usize| {
            let r = points[i] - c;
            r.dot(&v).atan2(r.dot(&u))
        };
        ring.sort_by(|&a, &b| angle(a).total_cmp(&angle(b)).then(a.cmp(&b)));
        let first = (0..ring.len()).min_by_key(|&k| ring[k]).unwrap_or(0);
        ring.rotate_left(first);
        polygons.push(ring);
    }
    polygons.sort();
    let position = |i: usize| corners.binary_search(&i).unwrap_or(0);
    let vertices = corners.iter().map(|&i| points[i]).collect();
    let triangles = polygons
        .iter()
        .flat_map(|ring| {
            (1..ring.len() - 1)
                .map(move |k| [position(ring[0]), position(ring[k]), position(ring[k + 1])])
        })
        .collect();
    (vertices, triangles)
}

/// The point of triangle `(a, b, c)` closest to `p` (Ericson, Real-Time Collision Detection,
/// §5.1.5: by the Voronoi region of `p`).
fn closest_on_triangle(
    p: &Vector3<f64>,
    a: &Vector3<f64>,
    b: &Vector3<f64>,
    c: &Vector3<f64>,
) -> Vector3<f64> {
    let (ab, ac, ap) = (b - a, c - a, p - a);
    let (d1, d2) = (ab.dot(&ap), ac.dot(&ap));
    if d1 <= 0.0 && d2 <= 0.0 {
        return *a;
    }
    let bp = p - b;
    let (d3, d4) = (ab.dot(&bp), ac.dot(&bp));
    if d3 >= 0.0 && d4 <= d3 {
        return *b;
    }
    let vc = d1 * d4 - d3 * d2;
    if vc <= 0.0 && d1 >= 0.0 && d3 <= 0.0 {
        return a + ab * (d1 / (d1 - d3));
    }
    let cp = p - c;
    let (d5, d6) = (ab.dot(&cp), ac.dot(&cp));
    if d6 >= 0.0 && d5 <= d6 {
        return *c;
    }
    let vb = d5 * d2 - d1 * d6;
    if vb <= 0.0 && d2 >= 0.0 && d6 <= 0.0 {
        return a + ac * (d2 / (d2 - d6));
    }
    let va = d3 * d6 - d5 * d4;
    if va <= 0.0 && (d4 - d3) >= 0.0 && (d5 - d6) >= 0.0 {
        return b + (c - b) * ((d4 - d3) / ((d4 - d3) + (d5 - d6)));
    }
    let denom = 1.0 / (va + vb + vc);
    a + ab * (vb * denom) + ac * (vc * denom)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::contact::geometry::{Ball, Feature, GeomPose, Shape, evaluate};
    use crate::solver::test_rng::Rng;

    /// The box kernel's signed distance of point `q` to the box `half` (its frame).
    fn box_distance(q: &Vector3<f64>, half: &Vector3<f64>) -> (f64, Vector3<f64>, Vector3<f64>) {
        let feature = Feature::SphereBox {
            a: Ball {
                center: *q,
                radius: 0.0,
            },
            half_extents_b: *half,
        };
        let b = Shape::Box {
            half_extents: *half,
        };
        let w = evaluate(
            &feature,
            &Shape::Point,
            &GeomPose::default(),
            &b,
            &GeomPose::default(),
        );
        (w.phi, w.point_b, w.normal)
    }

    fn cube_points(half: &Vector3<f64>, extra: bool) -> Vec<Vector3<f64>> {
        let mut pts = Vec::new();
        for i in 0..8 {
            let s = |k: usize| if i >> k & 1 == 1 { 1.0 } else { -1.0 };
            pts.push(Vector3::new(s(0) * half.x, s(1) * half.y, s(2) * half.z));
        }
        if extra {
            // points inside and on faces: not hull vertices
            pts.push(Vector3::zeros());
            pts.push(Vector3::new(half.x, 0.1 * half.y, -0.3 * half.z));
            pts.push(Vector3::new(0.2 * half.x, -half.y, 0.5 * half.z));
        }
        pts
    }

    /// A box's hull has its twelve edges (not the faces' diagonals), a tetrahedron six, and
    /// every edge joins two vertices at the box's edge length.
    #[test]
    fn hull_edges_leave_out_face_diagonals() {
        let half = Vector3::new(0.1, 0.2, 0.3);
        let hull = ConvexHull::new(&cube_points(&half, true)).unwrap();
        let edges = hull.edges();
        assert_eq!(edges.len(), 12, "{edges:?}");
        for (i, j) in edges {
            let d = (hull.vertices[i] - hull.vertices[j]).abs();
            let along = (0..3).filter(|&k| d[k] > 1e-12).count();
            assert_eq!(along, 1, "edge {i}-{j} is a diagonal: {d:?}");
        }
        let tetra = [Vector3::zeros(), Vector3::x(), Vector3::y(), Vector3::z()];
        assert_eq!(ConvexHull::new(&tetra).unwrap().edges().len(), 6);
    }

    /// A box's hull is its eight corners in input order (the interior point and the points
    /// on a face are not vertices; each face is two triangles), and the signed distance to it
    /// equals the box kernel's (exact closest points outside, nearest face inside) at random
    /// points.
    #[test]
    fn a_box_hull_measures_distances_as_the_box_does() {
        let half = Vector3::new(0.3, 0.2, 0.1);
        let hull = ConvexHull::new(&cube_points(&half, true)).unwrap();
        assert_eq!(hull.vertices, cube_points(&half, false));
        assert_eq!(hull.triangles.len(), 12);
        let mut rng = Rng(7);
        for _ in 0..2000 {
            let q = Vector3::new(0.6 * rng.next(), 0.4 * rng.next(), 0.3 * rng.next());
            let (d, p, n) = hull.signed_distance(&q);
            let (db, pb, nb) = box_distance(&q, &half);
            assert!((d - db).abs() < 1e-12, "{q:?}: {d} vs {db}");
            assert!((p - pb).amax() < 1e-12, "{q:?}: {p:?} vs {pb:?}");
            if d > 1e-9 || db < -1e-9 {
                assert!(
                    (n - nb).amax() < 1e-9 || d.abs() < 1e-9,
                    "{q:?}: {n:?} vs {nb:?}"
                );
            }
        }
    }

    /// The hull does not depend on the order the quickhull library meets its facets in (it
    /// iterates hash sets seeded per set): built again and again from the same points, and from
    /// the points' mirror order, it is the same, bit for bit.
    #[test]
    fn a_hull_is_the_same_every_time() {
        let mut rng = Rng(11);
        let pts: Vec<Vector3<f64>> = (0..60)
            .map(|_| Vector3::new(rng.next(), 0.7 * rng.next(), 0.4 * rng.next()))
            .chain(cube_points(&Vector3::new(0.5, 0.5, 0.5), true))
            .collect();
        let first = ConvexHull::new(&pts).unwrap();
        for _ in 0..20 {
            assert_eq!(ConvexHull::new(&pts).unwrap(), first);
        }
        let mut reversed = pts.clone();
        reversed.reverse();
        let other = ConvexHull::new(&reversed).unwrap();
        let mut a = first.vertices.clone();
        let mut b = other.vertices.clone();
        let order =
            |x: &Vector3<f64>, y: &Vector3<f64>| x.as_slice().partial_cmp(y.as_slice()).unwrap();
        a.sort_by(order);
        b.sort_by(order);
        assert_eq!(a, b);
        let (va, ca, ia) = first.mass_properties();
        let (vb, cb, ib) = other.mass_properties();
        assert!((va - vb).abs() < 1e-15 && (ca - cb).amax() < 1e-15 && (ia - ib).amax() < 1e-15);
    }

    /// Mass properties of a box hull (shifted and rotated): volume, centre and inertia.
    #[test]
    fn mass_properties_of_a_moved_box_hull() {
        let half = Vector3::new(0.3, 0.2, 0.1);
        let rot = nalgebra::Rotation3::from_euler_angles(0.3, -0.7, 1.1).into_inner();
        let shift = Vector3::new(0.5, -1.0, 2.0);
        let pts: Vec<_> = cube_points(&half, true)
            .iter()
            .map(|p| rot * p + shift)
            .collect();
        let hull = ConvexHull::new(&pts).unwrap();
        let (v, c, i) = hull.mass_properties();
        let (a, b, h) = (2.0 * half.x, 2.0 * half.y, 2.0 * half.z);
        assert!((v - a * b * h).abs() < 1e-14, "{v}");
        assert!((c - shift).amax() < 1e-12, "{c:?}");
        let diag =
            Matrix3::from_diagonal(&Vector3::new(b * b + h * h, a * a + h * h, a * a + b * b))
                * (v / 12.0);
        assert!((i - rot * diag * rot.transpose()).amax() < 1e-14, "{i}");
        // recentred on its principal axes: the box again
        let back = hull.transformed(&rot.transpose(), &shift);
        let (_, c2, i2) = back.mass_properties();
        assert!(c2.amax() < 1e-12 && (i2 - diag).amax() < 1e-14);
    }

    /// A finer convex mesh (points on a sphere): every input point lies inside or on the hull,
    /// every hull vertex is an input point, and its volume approaches the sphere's.
    #[test]
    fn a_sphere_sampled_hull_contains_its_points() {
        let mut rng = Rng(3);
        let pts: Vec<Vector3<f64>> = (0..400)
            .map(|_| {
                let v = Vector3::new(rng.next(), rng.next(), rng.next());
                v.normalize() * 0.5
            })
            .collect();
        let hull = ConvexHull::new(&pts).unwrap();
        for p in &pts {
            assert!(hull.signed_distance(p).0 < 1e-12);
        }
        for v in &hull.vertices {
            assert!(pts.iter().any(|p| (p - v).amax() < 1e-14));
        }
        let (vol, com, _) = hull.mass_properties();
        let sphere = 4.0 / 3.0 * std::f64::consts::PI * 0.125;
        assert!(vol < sphere && vol > 0.9 * sphere, "{vol} vs {sphere}");
        assert!(com.amax() < 0.02);
        assert!(ConvexHull::new(&pts[..3]).is_err());
        let flat: Vec<_> = pts.iter().map(|p| Vector3::new(p.x, p.y, 0.0)).collect();
        assert!(ConvexHull::new(&flat).is_err());
        // degenerate clouds are errors, never panics: repeated points, a line, a sliver
        let mut r = Rng(5);
        for case in 0..300 {
            let n = 4 + r.below(12);
            let cloud: Vec<Vector3<f64>> = (0..n)
                .map(|k| match case % 3 {
                    0 => Vector3::new(0.1, 0.2, 0.3) * f64::from(u8::from(k % 2 == 0)),
                    1 => Vector3::new(1.0, 2.0, 3.0) * r.next(),
                    _ => Vector3::new(r.next(), r.next(), 1e-13 * r.next()),
                })
                .collect();
            if let Ok(h) = ConvexHull::new(&cloud) {
                assert!(h.triangles.len() >= 4 && h.mass_properties().0 > 0.0);
            }
        }
    }
}
