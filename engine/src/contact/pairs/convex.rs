//! Cores against convex solids: the candidates of cylinders with spheres, capsules, boxes,
//! meshes and other cylinders ([`super::Feature::CoreSolid`], [`super::Feature::SolidCore`]).
//!
//! A [`Solid`] (box, cylinder, mesh hull) is measured by its exact signed distance `sd(q)`, a
//! convex function of the point `q`. A [`Core`] is the part of the other geom whose nearest
//! point to the solid is the candidate: a ball (sphere, box corner, hull vertex, fixed rim
//! point), a segment (a capsule's, or a cylinder's axis for its side), or an end disk's rim.
//! The candidate is the core point minimising `sd`, so by the envelope theorem its witnesses
//! are all the solver needs: the minimiser is found to round-off, never approximated.
//!
//! * Segment: `g(t) = sd(c + t d)` is convex in `t`, and `g'(t) = n(t) · d` with `n` the
//!   solid's outward normal at the witness. The minimiser is found by a safeguarded root search on the sign of
//!   `g'` (robust at the kinks of `sd`). Where `g` is flat (a segment parallel to a face) the
//!   minimiser nearest the segment's centre is taken, so that it does not wander with the
//!   round-off of `g'`.
//! * Cylinder side: the axis segment with the cylinder's radius, exact only where the nearest
//!   axis point is interior (the witness normal is then perpendicular to the axis and the
//!   capsule's surface point lies on the side). At an end of the axis the candidate is that
//!   end's disk rim instead (the two agree where they meet).
//! * Rim: `g(θ) = sd(c + r (cos θ u + sin θ v))` is not convex on the circle; the best of
//!   [`RIM_SAMPLES`] angles brackets the minimiser, refined by the same search on `g'(θ)`. A disk
//!   lying flat on a face has a flat `g`: the sampled angle is kept (and such a rim is frozen
//!   for the step by the caller, as the disk–plane rim is, see
//!   [`crate::contact::disk_rim_for_step`]). A rim's *second* point (between two cylinders) is
//!   `g`'s least local minimum outside the least one's basin of samples, refined the same way:
//!   a disk under another cylinder's side touches it at a chord's two ends.

use std::sync::Arc;

use nalgebra::{Matrix3, Vector3};

use super::kernels::box_distance;
use super::{Ball, ConvexHull, GeomPose, Segment, Witness};

/// Below this length a vector has no usable direction.
const MIN_NORM: f64 = 1e-100;

/// `|g'|` below this counts as zero (a flat stretch of `g`): a minimiser found within it is off
/// the exact one by at most this times its distance, far below the solver's tolerances.
const FLAT_SLOPE: f64 = 1e-12;

/// Most steps of a minimiser's root search ([`first_rise`]): enough to reach round-off by
/// bisection alone on any bracket.
const BISECTIONS: usize = 64;

/// Angles sampled around a rim before its minimiser is refined.
pub const RIM_SAMPLES: usize = 16;

/// A convex solid measured by its exact signed distance, in its geom frame.
#[derive(Clone, Debug, PartialEq)]
pub enum Solid {
    /// Box of these half extents, centred at the origin.
    Box {
        /// Half the side lengths (m).
        half_extents: Vector3<f64>,
    },
    /// Cylinder along z, centred at the origin.
    Cylinder {
        /// Radius (m).
        radius: f64,
        /// Half the height (m).
        half_length: f64,
    },
    /// A mesh's convex hull.
    Hull(Arc<ConvexHull>),
}

impl Solid {
    /// Signed distance from `q` (solid frame) to the surface: `(distance, surface point,
    /// outward unit normal)`, negative inside (depth below the nearest face).
    pub fn distance(&self, q: &Vector3<f64>) -> (f64, Vector3<f64>, Vector3<f64>) {
        match self {
            Solid::Box { half_extents } => box_distance(q, half_extents),
            Solid::Cylinder {
                radius,
                half_length,
            } => cylinder_distance(q, *radius, *half_length),
            Solid::Hull(hull) => hull.signed_distance(q),
        }
    }
}

/// The part of a geom whose point nearest a [`Solid`] is a candidate.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Core {
    /// A ball fixed in the geom (a sphere, a box corner, a hull vertex, a fixed rim point).
    Ball(Ball),
    /// A capsule's segment (along the geom's z).
    Segment(Segment),
    /// A cylinder's side: its axis segment with the cylinder's radius; at an end of the axis,
    /// that end's rim.
    Side(Segment),
    /// A box's edge: the segment `centre ± t direction`, `|t| ≤ half_length` (geom frame,
    /// unit direction), of radius 0.
    Edge {
        /// Midpoint of the edge (geom frame).
        centre: Vector3<f64>,
        /// Unit direction of the edge (geom frame).
        direction: Vector3<f64>,
        /// Half the edge's length (m).
        half_length: f64,
    },
    /// The rim of a cylinder's end disk at height `z` on the geom's z axis: its point nearest
    /// the solid, or with `second` its other local minimum of the distance.
    Rim {
        /// Height of the disk's centre on the geom's z axis (m).
        z: f64,
        /// Radius of the disk (m).
        radius: f64,
        /// The rim's second point: where the distance around the rim has a second local
        /// minimum (a disk under a line-like support, another cylinder's side lying across
        /// it, touches it at a chord's two ends), else the point opposite the nearest one.
        /// Always held for the step (`nearest_rim` reports it flat): the minimum it follows
        /// appears and vanishes as the poses change.
        second: bool,
    },
}

impl Core {
    /// An edge's midpoint and direction in a frame where the core's geom has rotation `rot`
    /// and origin `origin`, and its half length (a zero-length edge at the origin for other
    /// cores).
    fn edge_in(
        &self,
        rot: &Matrix3<f64>,
        origin: &Vector3<f64>,
    ) -> (Vector3<f64>, Vector3<f64>, f64) {
        match *self {
            Core::Edge {
                centre,
                direction,
                half_length,
            } => (origin + rot * centre, rot * direction, half_length),
            _ => (*origin, rot.column(2).into_owned(), 0.0),
        }
    }

    /// How far the witness lies from the core point along the normal (the ball's or segment's
    /// radius; 0 for a rim point).
    pub fn radius(&self) -> f64 {
        match self {
            Core::Ball(b) => b.radius,
            Core::Segment(s) | Core::Side(s) => s.radius,
            Core::Rim { .. } | Core::Edge { .. } => 0.0,
        }
    }
}

/// Signed distance from `q` to the solid cylinder of `radius` and `half` height along z:
/// `(distance, surface point, outward normal)`. Outside, the exact closest point (side, cap or
/// rim); inside, the nearest of the side and the cap (the cap on ties). On the axis the
/// radial direction is +x.
pub fn cylinder_distance(
    q: &Vector3<f64>,
    radius: f64,
    half: f64,
) -> (f64, Vector3<f64>, Vector3<f64>) {
    let rho = (q.x * q.x + q.y * q.y).sqrt(); // (libm hypot was 5% of an A1 step)
    let radial = if rho > MIN_NORM {
        Vector3::new(q.x / rho, q.y / rho, 0.0)
    } else {
        Vector3::x()
    };
    let sign = if q.z >= 0.0 { 1.0 } else { -1.0 };
    let (dr, dz) = (rho - radius, q.z.abs() - half); // beyond the side, beyond the cap
    let on_side = |z: f64| Vector3::new(radius * radial.x, radius * radial.y, z);
    if dr > 0.0 && dz > 0.0 {
        // nearest the rim
        let point = on_side(sign * half);
        let gap = q - point;
        let dist = gap.norm();
        if dist > MIN_NORM {
            return (dist, point, gap / dist);
        }
    }
    if dr > 0.0 && dr >= dz {
        return (dr, on_side(q.z), radial); // beside the side (or the side is nearer)
    }
    if dz > 0.0 || dz >= dr {
        let point = Vector3::new(q.x, q.y, sign * half);
        return (dz, point, Vector3::new(0.0, 0.0, sign)); // over a cap (or the cap is nearer)
    }
    (dr, on_side(q.z), radial)
}

/// A core of the geom at `pose_core` against `solid` at `pose_solid`: the witness with the
/// core as A (normal from the solid towards the core).
pub fn core_solid(
    core: &Core,
    pose_core: &GeomPose,
    solid: &Solid,
    pose_solid: &GeomPose,
) -> Witness {
    // the core's frame in the solid's: origin c, axes (u, v, w)
    let rot = pose_solid.rot.transpose() * pose_core.rot;
    let origin = pose_solid.rot.transpose() * (pose_core.pos - pose_solid.pos);
    let axis = |k: usize| rot.column(k).into_owned();
    let (q, radius) = match *core {
        Core::Ball(b) => (origin + rot * b.center, b.radius),
        Core::Segment(s) => {
            let t = segment_minimiser(solid, &origin, &axis(2), s.half_length);
            (origin + t * axis(2), s.radius)
        }
        Core::Side(s) => {
            let t = segment_minimiser(solid, &origin, &axis(2), s.half_length);
            if t.abs() < s.half_length {
                (origin + t * axis(2), s.radius)
            } else {
                // at an end of the axis: that end's rim
                let rim = Circle {
                    c: origin + t * axis(2),
                    u: axis(0),
                    v: axis(1),
                    r: s.radius,
                };
                (rim.point(rim.minimiser(solid)), 0.0)
            }
        }
        Core::Rim { z, radius, second } => {
            let rim = Circle {
                c: origin + z * axis(2),
                u: axis(0),
                v: axis(1),
                r: radius,
            };
            let theta = if second {
                rim.second_minimiser(solid)
            } else {
                rim.minimiser(solid)
            };
            (rim.point(theta), 0.0)
        }
        Core::Edge { .. } => {
            let (c, d, half) = core.edge_in(&rot, &origin);
            (c + segment_minimiser(solid, &c, &d, half) * d, 0.0)
        }
    };
    let (dist, point, normal) = solid.distance(&q);
    let normal = pose_solid.rot * normal;
    Witness {
        phi: dist - radius, // φ = sd(q) − r
        point_a: pose_solid.transform_point(&q) - radius * normal,
        point_b: pose_solid.transform_point(&point),
        normal,
    }
}

/// For a rim core (or a side core whose nearest axis point is an end): the rim point nearest
/// `solid` in the core's geom frame, and the sine of the angle between its disk and the
/// contact plane there (`|n × w|`, `w` the disk's axis: 0 when the disk lies flat on the
/// solid), or for a side core the slope at which the distance rises along the axis half a
/// half-length away, the slower way, if less (0 when the side lies flat on the solid). For a
/// capsule's segment, or a side core whose nearest axis point is interior: that axis point
/// `(0, 0, t)` and its slope. `None` for a ball.
pub fn nearest_rim(
    core: &Core,
    pose_core: &GeomPose,
    solid: &Solid,
    pose_solid: &GeomPose,
) -> Option<(Vector3<f64>, f64)> {
    let rot = pose_solid.rot.transpose() * pose_core.rot;
    let origin = pose_solid.rot.transpose() * (pose_core.pos - pose_solid.pos);
    let axis = |k: usize| rot.column(k).into_owned();
    let (z, radius, rise) = match *core {
        Core::Rim {
            z,
            radius,
            second: true,
        } => {
            let rim = Circle {
                c: origin + z * axis(2),
                u: axis(0),
                v: axis(1),
                r: radius,
            };
            let (s, c) = rim.second_minimiser(solid).sin_cos();
            // (reported flat: always held)
            return Some((Vector3::new(radius * c, radius * s, z), 0.0));
        }
        Core::Rim { z, radius, .. } => (z, radius, f64::INFINITY),
        Core::Side(s) | Core::Segment(s) => {
            let d = axis(2);
            let t = segment_minimiser(solid, &origin, &d, s.half_length);
            let rise = slowest_rise(solid, &origin, &d, s.half_length, t);
            if t.abs() < s.half_length || matches!(core, Core::Segment(_)) {
                // the axis point itself (a capsule's end is its end ball)
                return Some((Vector3::new(0.0, 0.0, t), rise));
            }
            (t, s.radius, rise)
        }
        Core::Edge {
            centre, direction, ..
        } => {
            let (c, d, half) = core.edge_in(&rot, &origin);
            let t = segment_minimiser(solid, &c, &d, half);
            let rise = slowest_rise(solid, &c, &d, half, t);
            return Some((centre + t * direction, rise));
        }
        Core::Ball(_) => return None,
    };
    let rim = Circle {
        c: origin + z * axis(2),
        u: axis(0),
        v: axis(1),
        r: radius,
    };
    let theta = rim.minimiser(solid);
    let q = rim.point(theta);
    let normal = solid.distance(&q).2;
    let sine = normal.cross(&axis(2)).norm();
    let (s, c) = theta.sin_cos();
    Some((Vector3::new(radius * c, radius * s, z), sine.min(rise)))
}

/// How fast `sd(c + t d)` rises from `t` half a half-length away, the slower way within the
/// segment (0 for a segment lying flat on a face or along another cylinder's side).
fn slowest_rise(solid: &Solid, c: &Vector3<f64>, d: &Vector3<f64>, half: f64, t: f64) -> f64 {
    let g = |t: f64| solid.distance(&(c + t * d)).0;
    let reach = 0.5 * half;
    let inward = |x: f64| x.abs() <= half * (1.0 + 1e-12);
    [t + reach, t - reach]
        .into_iter()
        .filter(|&x| inward(x))
        .map(|x| (g(x) - g(t)) / reach)
        .fold(f64::INFINITY, f64::min)
        .max(0.0)
}

/// The smallest `x ∈ (0, hi]` with `rising(x)` true, given `rising(0)` false and `rising(hi)`
/// true for a monotone predicate on the slope `slope(x)` (`rising(x) = slope(x) ≥ −tol`):
/// regula falsi with the Illinois weighting on `slope`, every other step a bisection unless the
/// bracket at least halved, to round-off. About ten evaluations where `slope` is smooth (64
/// bisections before; it did not measurably change the A1's step).
fn first_rise(slope: impl Fn(f64) -> f64, tol: f64, hi: f64) -> f64 {
    let (mut lo, mut hi) = (0.0, hi);
    let (mut s_lo, mut s_hi) = (slope(lo) + tol, slope(hi) + tol); // < 0 at lo, ≥ 0 at hi
    let mut width = hi - lo;
    for k in 0..BISECTIONS {
        let secant = lo - s_lo * (hi - lo) / (s_hi - s_lo);
        let mid = if k % 2 == 1 && hi - lo > 0.5 * width || !(secant > lo && secant < hi) {
            0.5 * (lo + hi)
        } else {
            secant
        };
        if k % 2 == 1 {
            width = hi - lo;
        }
        if mid <= lo || mid >= hi {
            break;
        }
        let s_mid = slope(mid) + tol;
        if s_mid >= 0.0 {
            (hi, s_hi) = (mid, s_mid);
            s_lo *= 0.5; // Illinois: the end that stays is weighted down
        } else {
            (lo, s_lo) = (mid, s_mid);
            s_hi *= 0.5;
        }
        if hi - lo <= 1e-15 * hi.abs().max(1e-3) {
            break;
        }
    }
    hi
}

/// The `t ∈ [−half, half]` minimising `sd(c + t d)`, nearest 0 where the minimum is flat (or,
/// against a cylinder, the point nearest its axis where that is a minimiser).
fn segment_minimiser(solid: &Solid, c: &Vector3<f64>, d: &Vector3<f64>, half: f64) -> f64 {
    let slope = |t: f64| solid.distance(&(c + t * d)).2.dot(d); // g'(t) = n · d
    let s0 = slope(0.0);
    if s0.abs() <= FLAT_SLOPE || half <= 0.0 {
        return 0.0;
    }
    // the minimiser lies on the side `g` decreases towards; find the nearest t there where
    // g stops decreasing (g' ≥ −FLAT_SLOPE going outwards)
    let dir = if s0 < 0.0 { 1.0 } else { -1.0 };
    if let Solid::Cylinder { half_length, .. } = *solid {
        // against a cylinder's side the minimiser is the segment's point nearest its axis
        // (most capsule–cylinder contacts: one evaluation instead of a search)
        let (t, _) = super::kernels::segment_params(c, d, half, &Vector3::z(), half_length);
        if dir * t > 0.0 && slope(t).abs() <= FLAT_SLOPE {
            return t;
        }
    }
    let rising = |t: f64| dir * slope(dir * t) >= -FLAT_SLOPE;
    if !rising(half) {
        return dir * half;
    }
    dir * first_rise(|t| dir * slope(dir * t), FLAT_SLOPE, half)
}

/// A rim: the circle `c + r (cos θ u + sin θ v)` (`u`, `v` orthonormal), in a solid's frame.
struct Circle {
    c: Vector3<f64>,
    u: Vector3<f64>,
    v: Vector3<f64>,
    r: f64,
}

impl Circle {
    /// The point at angle `θ`.
    fn point(&self, theta: f64) -> Vector3<f64> {
        let (s, co) = theta.sin_cos();
        self.c + self.r * (co * self.u + s * self.v)
    }

    /// The angle minimising `sd` over the circle: the best of [`RIM_SAMPLES`] angles (the first
    /// on ties), refined by [`first_rise`] on `g'(θ)` between its neighbours.
    fn minimiser(&self, solid: &Solid) -> f64 {
        let samples = self.samples(solid);
        self.refine(solid, lowest(&samples, 0..RIM_SAMPLES))
    }

    /// The angle of the circle's second local minimum of `sd` (see [`Core::Rim`]): the least
    /// sample outside the basin of the least one (the samples rising from it both ways),
    /// refined as [`Self::minimiser`] refines; the angle opposite the least sample where there
    /// is none (a distance with one minimum around the circle, or flat).
    fn second_minimiser(&self, solid: &Solid) -> f64 {
        const N: usize = RIM_SAMPLES;
        let samples = self.samples(solid);
        let k0 = lowest(&samples, 0..N);
        let at = |k: usize| samples[k % N];
        // the basin's ends: the last samples reached rising (not falling) from k0 either way
        let ahead = (1..N).take_while(|&i| at(k0 + i) >= at(k0 + i - 1)).count();
        let behind = (1..N)
            .take_while(|&i| at(k0 + N - i) >= at(k0 + N - i + 1))
            .count();
        // the samples strictly between the basin's ends, the other way round
        let (first, last) = (k0 + ahead + 1, k0 + N - behind);
        if first >= last {
            return (k0 as f64 + 0.5 * N as f64) * std::f64::consts::TAU / N as f64;
        }
        self.refine(solid, lowest(&samples, first..last))
    }

    /// `sd` at the [`RIM_SAMPLES`] angles `k τ / RIM_SAMPLES`.
    fn samples(&self, solid: &Solid) -> [f64; RIM_SAMPLES] {
        let step = std::f64::consts::TAU / RIM_SAMPLES as f64;
        std::array::from_fn(|k| solid.distance(&self.point(k as f64 * step)).0)
    }

    /// The local minimiser of `sd` near sample `k`, found by [`first_rise`] on `g'(θ)`
    /// between the sample's neighbours.
    fn refine(&self, solid: &Solid, k: usize) -> f64 {
        let (u, v, r) = (&self.u, &self.v, self.r);
        let step = std::f64::consts::TAU / RIM_SAMPLES as f64;
        let theta0 = k as f64 * step;
        // g'(θ) = n · r (−sin θ u + cos θ v)
        let slope = |theta: f64| {
            let (s, co) = theta.sin_cos();
            let n = solid.distance(&self.point(theta)).2;
            r * n.dot(&(co * v - s * u))
        };
        let s0 = slope(theta0);
        if s0.abs() <= FLAT_SLOPE * r.max(1.0) {
            return theta0;
        }
        let dir = if s0 < 0.0 { 1.0 } else { -1.0 };
        let rising = |a: f64| dir * slope(theta0 + dir * a) >= -FLAT_SLOPE * r.max(1.0);
        if !rising(step) {
            return theta0 + dir * step; // (not unimodal in the bracket: its end)
        }
        let tol = FLAT_SLOPE * r.max(1.0);
        theta0 + dir * first_rise(|a| dir * slope(theta0 + dir * a), tol, step)
    }
}

/// The index (mod [`RIM_SAMPLES`]) of the least sample among `range` (the first on ties).
fn lowest(samples: &[f64; RIM_SAMPLES], range: std::ops::Range<usize>) -> usize {
    range
        .map(|k| k % RIM_SAMPLES)
        .fold(None, |best: Option<usize>, k| match best {
            Some(b) if samples[b] <= samples[k] => Some(b),
            _ => Some(k),
        })
        .unwrap_or(0)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn cylinder_distance_regions() {
        let (r, h) = (0.5, 1.0);
        // beside the side
        let (d, p, n) = cylinder_distance(&Vector3::new(2.0, 0.0, 0.3), r, h);
        assert!((d - 1.5).abs() < 1e-15 && (p - Vector3::new(0.5, 0.0, 0.3)).norm() < 1e-15);
        assert!((n - Vector3::x()).norm() < 1e-15);
        // over the cap
        let (d, p, n) = cylinder_distance(&Vector3::new(0.1, 0.2, -1.5), r, h);
        assert!((d - 0.5).abs() < 1e-15 && (p - Vector3::new(0.1, 0.2, -1.0)).norm() < 1e-15);
        assert!((n + Vector3::z()).norm() < 1e-15);
        // past the rim
        let (d, p, _) = cylinder_distance(&Vector3::new(0.0, 1.5, 2.0), r, h);
        assert!(
            (d - 2f64.sqrt()).abs() < 1e-15 && (p - Vector3::new(0.0, 0.5, 1.0)).norm() < 1e-15
        );
        // inside: nearer the side, then nearer the cap
        let (d, _, n) = cylinder_distance(&Vector3::new(0.4, 0.0, 0.0), r, h);
        assert!((d + 0.1).abs() < 1e-15 && (n - Vector3::x()).norm() < 1e-15);
        let (d, _, n) = cylinder_distance(&Vector3::new(0.0, 0.0, 0.95), r, h);
        assert!((d + 0.05).abs() < 1e-15 && (n - Vector3::z()).norm() < 1e-15);
    }

    #[test]
    fn segment_minimiser_finds_the_crossing_and_prefers_the_centre_on_flats() {
        // a segment along x over the top of an upright cylinder: flat over the cap
        let solid = Solid::Cylinder {
            radius: 0.5,
            half_length: 1.0,
        };
        let t = segment_minimiser(&solid, &Vector3::new(0.3, 0.0, 1.2), &Vector3::x(), 1.0);
        assert_eq!(t, 0.0);
        // a horizontal segment along y passing beside the side at x = 0.7, centred off at y = 0.4
        let t = segment_minimiser(&solid, &Vector3::new(0.7, 0.4, 0.0), &Vector3::y(), 1.0);
        assert!((t + 0.4).abs() < 1e-12, "{t}");
        // a segment whose nearest point is its end
        let t = segment_minimiser(&solid, &Vector3::new(0.0, 3.0, 0.0), &Vector3::y(), 1.0);
        assert_eq!(t, -1.0);
    }

    #[test]
    fn a_rim_under_a_lying_cylinder_has_its_second_point_at_the_other_chord_end() {
        // a disk of radius 0.05 at z = 0 (its rim in the xy plane, centred at the origin) under
        // a cylinder of radius 0.04 lying along y with its axis at x = 0.01, z = 0.05: the rim
        // meets the lying cylinder's lowest line at the chord's ends, θ = ±acos(0.01 / 0.05)
        let (r, x_axis) = (0.05, 0.01);
        let solid = Solid::Cylinder {
            radius: 0.04,
            half_length: 0.3,
        };
        // the solid's frame: its axis along y, so the disk's frame in it is turned by 90° about x
        let to_solid = |p: Vector3<f64>| Vector3::new(p.x - x_axis, -(p.z - 0.05), p.y);
        let c = to_solid(Vector3::zeros());
        let (u, v) = (to_solid(Vector3::x()) - c, to_solid(Vector3::y()) - c);
        let end = (x_axis / r).acos();
        let rim = Circle { c, u, v, r };
        let (first, second) = (rim.minimiser(&solid), rim.second_minimiser(&solid));
        let [a, b] = [first, second].map(|t| t.sin().atan2(t.cos()));
        let (lo, hi) = (a.min(b), a.max(b));
        assert!(
            (lo + end).abs() < 1e-9 && (hi - end).abs() < 1e-9,
            "{a} {b} vs ±{end}"
        );
        // both 1 cm below the lying cylinder's lowest line (z = 0.01)
        for t in [first, second] {
            let d = solid.distance(&rim.point(t)).0;
            assert!((d - 0.01).abs() < 1e-12, "{d}");
        }
    }

    #[test]
    fn a_rim_with_one_minimum_has_its_second_point_opposite() {
        // tilted over a box (one minimum at −y) and flat on it (every point a minimum)
        let solid = Solid::Box {
            half_extents: Vector3::new(2.0, 2.0, 0.5),
        };
        let c = Vector3::new(0.1, 0.2, 1.0);
        for tilt in [0.3f64, 0.0] {
            let (u, v) = (Vector3::x(), Vector3::new(0.0, tilt.cos(), tilt.sin()));
            let rim = Circle { c, u, v, r: 0.4 };
            let (first, second) = (rim.minimiser(&solid), rim.second_minimiser(&solid));
            let turn = (second - first).rem_euclid(std::f64::consts::TAU);
            assert!(
                (turn - std::f64::consts::PI).abs() < 1e-9,
                "{tilt}: {first} {second}"
            );
        }
    }

    #[test]
    fn rim_minimiser_finds_the_lowest_point_over_a_box() {
        // a disk tilted about x over a box's top face: its lowest rim point is at −y
        let solid = Solid::Box {
            half_extents: Vector3::new(2.0, 2.0, 0.5),
        };
        let tilt = 0.3f64;
        let (u, v) = (Vector3::x(), Vector3::new(0.0, tilt.cos(), tilt.sin()));
        let c = Vector3::new(0.1, 0.2, 1.0);
        let rim = Circle { c, u, v, r: 0.4 };
        let theta = rim.minimiser(&solid);
        let p = rim.point(theta);
        assert!((p.z - (1.0 - 0.4 * tilt.sin())).abs() < 1e-14, "{p:?}");
        assert!((theta - 1.5 * std::f64::consts::PI).abs() < 1e-9, "{theta}");
    }
}
