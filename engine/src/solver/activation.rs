//! Which contact candidates and joint limits take part in a step (Dojo's contact candidates
//! with an activation heuristic, MuJoCo's broad phase in spirit): each candidate's data at the
//! step's start ([`prepare`]), the activation by reach ([`activate`], [`Reach`],
//! [`candidate_margin`]), and the checks after a solve that bring a missed contact or limit into
//! the step ([`missed_contacts`], [`missed_limits`], [`refreeze_disks`]). Inactive candidates and
//! limits carry no impulse and cost no solver work.
use nalgebra::Vector3;

use super::inequality::active_candidates;
use crate::contact::geometry::{Feature, GeomPose};
use crate::contact::{Frozen, StepRows, predicted_pose, witness_frozen};
use crate::joints::geometry::{JointFrame, Pose};
use crate::model::Model;
use crate::state::{State, Workspace};

/// Contact frames at the current configuration (impulse directions, tangential velocity map),
/// and the features held fixed for the step (near-flat disk rim points, box corners' faces:
/// [`crate::contact::freeze_for_step`]).
///
/// An inactive candidate whose geoms are apart (by their bounding spheres, or
/// [`convex_pair_gap`]) by more than the step could close (`margin + h (2 u + h |g|)`, the
/// candidate's margin ([`candidate_margin`]), `u` the smaller of the sum of the fastest any
/// point of either geom moves and the pair's [`relative_speed`]) skips the narrow phase: its
/// distance is recorded as that lower bound, and its data are computed if it is activated
/// ([`ensure_prepared`]). Measured 2026-12-02: the narrow phase of every candidate was 11% of
/// an A1 step (1024 candidates). The relative speed (session 45): the Panda's finger pads ride
/// a hand swinging at metres per second but close only at the fingers' slide speed; by the
/// speeds' sum all 25 pad pairs were prepared at every Table V step.
pub(crate) fn prepare(model: &Model, state: &State, ws: &mut Workspace) {
    let h = model.options.timestep;
    let drift = h * h * model.options.gravity.norm();
    for (g, geom) in model.geoms.iter().enumerate() {
        ws.geom_bounds[g] = GeomBound::new(state, geom);
    }
    let mut memo = crate::contact::BoxPairMemo::default();
    let mut poses = std::mem::take(&mut ws.geom_poses);
    let mut posed = false;
    let n = model.ncontact();
    let mut run = 0..0;
    while run.end < n {
        // a geom pair's run of candidates shares its margin and the lower bounds on its
        // distance and closing speed, computed once for the run
        run = run.end..pair_run_end(model, run.end);
        let contact = &model.contacts[run.start];
        let margin = candidate_margin(model, contact);
        let skip = margin.is_finite() && run.clone().any(|c| !ws.active[c]) && {
            let key = (contact.geom_a, contact.geom_b);
            let (a, b) = (&ws.geom_bounds[key.0], &ws.geom_bounds[key.1]);
            let reach = |speed: f64| margin + 2.0 * h * speed + drift;
            let (mut gap, mut speed) = (a.gap(b), a.speed + b.speed);
            // the tighter bounds only where the cheaper ones do not cull: the shapes' support
            // functions, then the relative speed (two geoms moving together, such as a
            // gripper's finger pads, close at their relative speed)
            if gap <= reach(speed) {
                gap = gap.max(convex_pair_gap(model, key, a, b));
            }
            if gap <= reach(speed) {
                let (ga, gb) = (&model.geoms[key.0], &model.geoms[key.1]);
                speed = speed.min(relative_speed(state, ga, gb));
            }
            gap > reach(speed) && {
                for c in run.clone().filter(|&c| !ws.active[c]) {
                    ws.prepared[c] = false;
                    ws.frozen[c] = None;
                    ws.contact_phi_now[c] = gap;
                    ws.contact_rate_now[c] = 0.0;
                }
                true
            }
        };
        for c in run.clone() {
            if skip && !ws.active[c] {
                continue;
            }
            if !posed {
                GeomPoses::fill(model, state, &ws.geom_bounds, &mut poses);
                posed = true;
            }
            let contact = &model.contacts[c];
            let [a, b] = [contact.geom_a, contact.geom_b].map(|g| &poses[g]);
            let inactive = !ws.active[c];
            prepare_candidate_at(model, ws, c, (a, b), &mut memo, inactive, None);
        }
    }
    ws.geom_poses = poses;
}

/// A geom's body pose and velocity and its world poses at the body's current pose and one step
/// ahead at its current velocities ([`predicted_pose`]): what preparing a candidate reads,
/// computed once per [`prepare`] pass rather than for each candidate. Measured 2026-12-03
/// (callgrind, `gradient_phases panda.xml 100 none coloured`): preparing the 368 of the
/// Panda's 835 candidates near enough per step was 12.9% of its instructions, the world
/// poses, predicted poses and state reads in it about half of that (its 400 finger-pad
/// corners share ten geoms).
#[derive(Clone, Copy, Debug)]
pub(crate) struct GeomPoses {
    body: Pose,
    /// The body's COM velocity and angular velocity, world frame (zero for the world).
    velocity: (Vector3<f64>, Vector3<f64>),
    now: GeomPose,
    ahead: GeomPose,
}

impl Default for GeomPoses {
    fn default() -> Self {
        Self {
            body: Pose::world(),
            velocity: (Vector3::zeros(), Vector3::zeros()),
            now: GeomPose::default(),
            ahead: GeomPose::default(),
        }
    }
}

impl GeomPoses {
    /// The poses of geom `geom` at `state`, its current world pose `now` if known.
    fn of(
        model: &Model,
        state: &State,
        geom: &crate::contact::Geom,
        now: Option<GeomPose>,
    ) -> Self {
        let h = model.options.timestep;
        let body = body_pose(state, geom.body);
        let velocity = if geom.body == 0 {
            (Vector3::zeros(), Vector3::zeros())
        } else {
            let (v, w) = state.velocity(geom.body);
            (v, crate::math::quat::rotation(&body.quat) * w)
        };
        Self {
            body,
            velocity,
            now: now.unwrap_or_else(|| geom.world_pose(&body)),
            ahead: geom.world_pose(&predicted_pose(state, geom.body, h)),
        }
    }

    /// The poses of every geom at `state`, the current world poses taken from `bounds` (the
    /// geoms' bounds at `state`).
    fn fill(model: &Model, state: &State, bounds: &[GeomBound], out: &mut [GeomPoses]) {
        for (g, geom) in model.geoms.iter().enumerate() {
            out[g] = Self::of(model, state, geom, Some(bounds[g].frame));
        }
    }

    /// Velocity of the material point at `p` (world) of the geom's body.
    fn point_velocity(&self, p: &Vector3<f64>) -> Vector3<f64> {
        let (v, w) = self.velocity;
        v + w.cross(&(p - self.body.pos))
    }
}

/// The pose of body `b` in a step's solved next poses `next` (the world frame for body 0).
fn next_pose(next: &[Pose], b: usize) -> Pose {
    if b == 0 { Pose::world() } else { next[b] }
}

/// The pose of body `b` at `state` (the world frame for body 0).
fn body_pose(state: &State, b: usize) -> Pose {
    if b == 0 { Pose::world() } else { state.pose(b) }
}

/// A geom's bounding sphere at the current configuration and the fastest any of its points
/// moves (world frame). A plane is bounded by its half-space (`radius` infinite, `centre` a
/// point of it, `normal` its outward normal) and is only bounded when on the world.
#[derive(Clone, Copy, Debug, Default)]
pub(crate) struct GeomBound {
    /// The geom's world pose, which the narrow phase reuses.
    frame: GeomPose,
    centre: Vector3<f64>,
    normal: Vector3<f64>,
    radius: f64,
    speed: f64,
}

impl GeomBound {
    fn new(state: &State, geom: &crate::contact::Geom) -> Self {
        let pose = body_pose(state, geom.body);
        let mut bound = Self::at(geom, &pose);
        if geom.body != 0 && bound.radius.is_finite() {
            let (v, w) = state.velocity(geom.body);
            let w = crate::math::quat::rotation(&pose.quat) * w;
            bound.speed =
                (v + w.cross(&(bound.centre - pose.pos))).norm() + w.norm() * bound.radius;
        }
        bound
    }

    /// The bounding sphere (or half-space) with the geom's body at `pose`, at rest. A plane on
    /// a moving body bounds nothing (`radius` NaN): its half-space turns with the body.
    fn at(geom: &crate::contact::Geom, pose: &Pose) -> Self {
        let frame = geom.world_pose(pose);
        let radius = match bounding_radius(&geom.shape) {
            r if r.is_infinite() && geom.body != 0 => f64::NAN,
            r => r,
        };
        GeomBound {
            frame,
            centre: frame.pos,
            normal: frame.rot.column(2).into_owned(),
            radius,
            speed: 0.0,
        }
    }

    /// A lower bound on the distance between the two geoms (−∞ when there is none).
    fn gap(&self, other: &GeomBound) -> f64 {
        let plane = |b: &GeomBound| b.radius == f64::INFINITY;
        let sphere = |b: &GeomBound| b.radius.is_finite();
        if sphere(self) && sphere(other) {
            (self.centre - other.centre).norm() - self.radius - other.radius
        } else if plane(self) && sphere(other) {
            self.normal.dot(&(other.centre - self.centre)) - other.radius
        } else if sphere(self) && plane(other) {
            other.gap(self)
        } else {
            f64::NEG_INFINITY
        }
    }
}

/// A lower bound on the distance between two geoms of which one is a mesh, a box or a cylinder:
/// their separation along the axis through their origins, `d · (o_b - o_a) - h_a(d) - h_b(-d)`
/// with `h` each shape's support function about its origin, or along a box's face normals
/// where larger (−∞ for other pairs, or a plane). A mesh has
/// one candidate per hull vertex, each an `O(faces)` distance to prepare: arm links two joints
/// apart lie within each other's bounding spheres yet well apart along the arm (pybullet_data's
/// Panda URDF, 10330 candidates).
///
/// A pair with a cylinder takes this bound too, and, when both are spheres, capsules or
/// cylinders, the distance between their core segments less their radii (a cylinder lies in
/// the capsule of its radius about its axis): each of its candidates finds a nearest point by
/// a 1-D search, and the shared A1's legs lie within the bounding spheres of its trunk's and
/// hips' cylinders at every step.
fn convex_pair_gap(model: &Model, (ga, gb): (usize, usize), a: &GeomBound, b: &GeomBound) -> f64 {
    use crate::contact::geometry::Shape;
    let (sa, sb) = (&model.geoms[ga].shape, &model.geoms[gb].shape);
    let mesh = |s: &Shape| matches!(s, Shape::Mesh { .. });
    let cylinder = |s: &Shape| matches!(s, Shape::Cylinder { .. });
    let offset = b.frame.pos - a.frame.pos;
    let dist = offset.norm();
    let boxed = |s: &Shape| matches!(s, Shape::Box { .. });
    let with_cylinder = cylinder(sa) || cylinder(sb);
    if !(mesh(sa) || mesh(sb) || with_cylinder || boxed(sa) || boxed(sb)) || dist < 1e-12 {
        return f64::NEG_INFINITY;
    }
    // separation along the unit direction `d` (from a to b): a lower bound on the distance
    let apart = |d: &Vector3<f64>| {
        offset.dot(d)
            - support(sa, &(a.frame.rot.transpose() * d))
            - support(sb, &(b.frame.rot.transpose() * -d))
    };
    let mut along = apart(&(offset / dist));
    // and along a box's face normals: two boxes face to face but offset sideways (a gripper's
    // finger pads) are apart along those, by less along the line of their centres
    for (s, g) in [(sa, a), (sb, b)] {
        if boxed(s) {
            for k in 0..3 {
                let n = g.frame.rot.column(k).into_owned();
                along = along.max(apart(&n)).max(apart(&-n));
            }
        }
    }
    match (sa.core_segment(), sb.core_segment()) {
        (Some((half_a, ra)), Some((half_b, rb))) if with_cylinder => {
            let axis = |g: &GeomBound| g.frame.rot.column(2).into_owned();
            let (da, db) = (axis(a), axis(b));
            let cores = crate::contact::geometry::segment_distance(
                (&a.frame.pos, &da, half_a),
                (&b.frame.pos, &db, half_b),
            );
            along.max(cores - ra - rb)
        }
        _ => along,
    }
}

/// The support function of a shape about its origin along the unit direction `u` (its frame):
/// the largest `x · u` over its points (∞ for a plane).
fn support(shape: &crate::contact::geometry::Shape, u: &Vector3<f64>) -> f64 {
    use crate::contact::geometry::Shape;
    match *shape {
        Shape::Plane => f64::INFINITY,
        Shape::Point => 0.0,
        Shape::Sphere { radius } => radius,
        Shape::Capsule {
            radius,
            half_length,
        } => radius + half_length * u.z.abs(),
        Shape::Cylinder {
            radius,
            half_length,
        } => radius * (u.x * u.x + u.y * u.y).sqrt() + half_length * u.z.abs(),
        Shape::Box { half_extents } => half_extents.dot(&u.abs()),
        Shape::Ellipsoid { radii } => radii.component_mul(u).norm(),
        Shape::Mesh { ref hull } => (hull.vertices.iter())
            .map(|v| v.dot(u))
            .fold(f64::NEG_INFINITY, f64::max),
    }
}

/// [`prepare`] for every active candidate that it left out.
pub(crate) fn ensure_prepared(model: &Model, state: &State, ws: &mut Workspace) {
    let active = std::mem::take(&mut ws.active);
    let mut memo = crate::contact::BoxPairMemo::default();
    for c in active_candidates(&active[..model.ncontact()]) {
        if !ws.prepared[c] {
            prepare_candidate_with(model, state, ws, c, &mut memo, None);
        }
    }
    ws.active = active;
}

/// [`prepare`] for each `(c, frozen)` of `candidates` (its contact frame at `state` with the
/// feature chosen at the state's predicted poses, as a solve prepares it, or with the held
/// rim point or edge crossing), then holding `frozen` as the feature its gap at the next poses
/// is measured with: the one the solve ended with, which [`refreeze_disks`] may have moved.
/// The gradients linearise a solved step so, also at perturbed states (the features are material: a rim
/// point or a face of the geom). Each geom's poses are computed once per call (a box's corner
/// candidates share their geom), bit for bit what preparing each candidate alone computes.
pub(crate) fn prepare_candidates_holding(
    model: &Model,
    state: &State,
    ws: &mut Workspace,
    candidates: impl IntoIterator<Item = (usize, Option<Frozen>)>,
) {
    let mut memo = crate::contact::BoxPairMemo::default();
    // (geom, its poses), searched linearly: a pass touches few geoms
    let mut posed: Vec<(usize, GeomPoses)> = Vec::new();
    let mut poses_of = |g: usize| match posed.iter().find(|(k, _)| *k == g) {
        Some((_, p)) => *p,
        None => {
            let p = GeomPoses::of(model, state, &model.geoms[g], None);
            posed.push((g, p));
            p
        }
    };
    for (c, frozen) in candidates {
        let contact = &model.contacts[c];
        let (a, b) = (poses_of(contact.geom_a), poses_of(contact.geom_b));
        prepare_candidate_at(model, ws, c, (&a, &b), &mut memo, false, frozen);
        ws.frozen[c] = frozen;
    }
}

/// [`prepare`] for candidate `c` within a pass over the candidates at `state` (`memo`: see
/// [`crate::contact::BoxPairMemo`]).
fn prepare_candidate_with(
    model: &Model,
    state: &State,
    ws: &mut Workspace,
    c: usize,
    memo: &mut crate::contact::BoxPairMemo,
    hold: Option<Frozen>,
) {
    let contact = &model.contacts[c];
    let [a, b] = [contact.geom_a, contact.geom_b]
        .map(|g| GeomPoses::of(model, state, &model.geoms[g], None));
    prepare_candidate_at(model, ws, c, (&a, &b), memo, false, hold);
}

/// [`prepare_candidate_with`] with the poses and velocities of the candidate's geoms; with
/// `skip_empty`, an edge slot that holds no crossing this step is left unprepared (see
/// below). An edge slot given a crossing to `hold` builds its frame from it (one found after a
/// solve, [`refreeze_crossings`]), a disk given a [`Frozen::RimFramed`] at its `frame` point
/// ([`refreeze_disks`]); other candidates build theirs from the feature frozen at the step's
/// start whatever they hold later (a disk's rim point re-frozen within a quarter turn of it).
fn prepare_candidate_at(
    model: &Model,
    ws: &mut Workspace,
    c: usize,
    (a, b): (&GeomPoses, &GeomPoses),
    memo: &mut crate::contact::BoxPairMemo,
    skip_empty: bool,
    hold: Option<Frozen>,
) {
    let contact = &model.contacts[c];
    // (only an edge slot reads the margin: computed for every candidate it was 3% of a Panda
    // step)
    let slot = contact.feature.is_crossing_slot();
    let margin = if slot {
        candidate_margin(model, contact)
    } else {
        f64::INFINITY
    };
    ws.frozen[c] = match hold {
        Some(held @ Frozen::Crossing { .. }) if slot => Some(held),
        Some(Frozen::RimFramed { frame, .. }) => Some(Frozen::Rim(frame)),
        _ => crate::contact::freeze_for_step_at(
            contact,
            &model.geoms,
            (&a.now, &b.now),
            (&a.ahead, &b.ahead),
            margin,
            memo,
        ),
    };
    let w =
        crate::contact::witness_frozen_at(contact, &model.geoms, (&a.now, &b.now), ws.frozen[c]);
    if skip_empty && ws.frozen[c] == Some(Frozen::NoCrossing) {
        // an empty edge slot takes no part in the step (`activate`): its frame is built only
        // if a solve activates every candidate (`ensure_prepared`). Why: the Panda's 25
        // finger-pad pairs have 200 slots, all empty, and building their frames every step
        // was a third of what the slots cost it.
        ws.prepared[c] = false;
        ws.contact_phi_now[c] = w.phi;
        ws.contact_rate_now[c] = 0.0;
        return;
    }
    ws.prepared[c] = true;
    ws.contact_phi_now[c] = w.phi;
    // φ̇ = n · (velocity of A's witness − velocity of B's witness), n from B to A
    ws.contact_rate_now[c] = w
        .normal
        .dot(&(a.point_velocity(&w.point_a) - b.point_velocity(&w.point_b)));
    ws.contact_step[c] = StepRows::new(w, a.body, b.body);
}

/// Largest distance (m) from a body's centre of mass to any point of `geom` (infinite for a
/// plane on a moving body).
fn geom_reach(geom: &crate::contact::Geom) -> f64 {
    geom.pos.norm() + bounding_radius(&geom.shape)
}

/// Radius of the smallest sphere about a shape's frame origin that holds it (infinite for a
/// plane).
fn bounding_radius(shape: &crate::contact::geometry::Shape) -> f64 {
    use crate::contact::geometry::Shape;
    match *shape {
        Shape::Plane => f64::INFINITY,
        Shape::Sphere { radius } => radius,
        Shape::Capsule {
            radius,
            half_length,
        } => radius + half_length,
        Shape::Box { half_extents } => half_extents.norm(),
        Shape::Cylinder {
            radius,
            half_length,
        } => (radius * radius + half_length * half_length).sqrt(), // (libm hypot: 1% of an A1 step)
        Shape::Ellipsoid { radii } => radii.max(),
        Shape::Point => 0.0,
        Shape::Mesh { ref hull } => hull.radius(),
    }
}

/// Add to the step the candidates within reach (after [`prepare`]): those whose current
/// distance is within `margin + h (2 u + h |g|)` (the candidate's margin:
/// [`candidate_margin`]), with the approach speed `u` as
/// `reach` says. The step starts with [`Reach::Approach`], the rate at which the witness points
/// close along the normal: measured 2026-12-02 (`step_bench`, seed 5, 300 steps), it keeps
/// 11.6 of the A1's 1024 candidates active per step instead of 54.4 under [`Reach::Bound`]
/// (1.3 of them carry an impulse), and the A1 step costs 39% fewer instructions. A step that
/// closes a gap faster than this estimate (a swinging box corner, an impulsive actuator) is
/// caught by [`missed_contacts`] and re-solved; a solve that fails is solved again with the
/// candidates of [`Reach::Bound`], then with all of them.
/// Joint and tendon limits are activated likewise ([`activate_limits`]). Returns how many
/// candidates, limited joints and tendon limits it added.
pub(crate) fn activate(model: &Model, state: &State, ws: &mut Workspace, reach: Reach) -> usize {
    let margin = model.options.activation_margin;
    let before = ws.active_contacts();
    if margin == f64::INFINITY || reach == Reach::All {
        let nc = model.ncontact();
        let limits = (0..model.njoint())
            .filter(|&j| model.topology.limit_node[j].is_some() && !ws.active[nc + j])
            .count()
            + ws.tendon_active().iter().filter(|a| !**a).count();
        ws.active.fill(true);
        return nc - before + limits;
    }
    let limits = activate_limits(model, state, ws, reach);
    let h = model.options.timestep;
    let drift = h * h * model.options.gravity.norm();
    let mut run = 0..0;
    let mut lowest = None;
    let (mut margins, mut rooms) = (MarginMemo::default(), PairMemo::default());
    for (c, contact) in model.contacts.iter().enumerate() {
        if c == run.end {
            run = corner_group(model, c);
            lowest = (reach == Reach::Approach && run.len() >= LOWEST_OF)
                .then(|| lowest_candidate(ws, run.clone()))
                .flatten();
        }
        // (an edge slot without a crossing this step has nothing to hold)
        if matches!(ws.frozen[c], Some(Frozen::NoCrossing)) {
            continue;
        }
        let margin = margins.of(model, contact);
        let speed = match reach {
            Reach::All => unreachable!(),
            Reach::Approach => (-ws.contact_rate_now[c]).max(0.0),
            Reach::Bound => relative_speed(
                state,
                &model.geoms[contact.geom_a],
                &model.geoms[contact.geom_b],
            ),
        };
        let mut travel = 2.0 * h * speed;
        if let (Reach::Approach, Some(limits)) = (reach, &contact.slide_limits) {
            travel = travel.min(rooms.of(contact, || slide_room(ws, limits)));
        }
        let reach = margin + travel + drift;
        // NaN distances or speeds stay active (the solve then reports them)
        let phi = ws.contact_phi_now[c];
        // a corner above its pair's lowest by more than half the margin and the step's turn
        // (twice the step's travel at the difference of their approach rates) cannot touch
        // in this step: the lowest one touches first
        let above = lowest.is_some_and(|(low, low_rate)| {
            phi > low + 0.5 * margin + 2.0 * h * (ws.contact_rate_now[c] - low_rate).abs()
        });
        ws.active[c] |= phi.is_nan() || reach.is_nan() || (phi <= reach && !above);
    }
    ws.active_contacts() - before + limits
}

/// How far the two bodies of a slide pair can still move along their axis in the direction
/// they move now (both directions when at rest), by the slacks of the limits that bound them
/// (`Contact::slide_limits`, recorded this step in `limit_slack_now`): no candidate between
/// them closes by more in the step.
///
/// Why: a parallel gripper's fingers slam shut at ~1 m/s under random controls, so the
/// approach term `2 h u` reached every pad pair between them (the Panda under `step_bench`
/// seed 1, step 155: 225 candidates active, 218 of them over 1 cm apart, the approach rates'
/// median 2.2 m/s), while the fingers' limits stop them within millimetres.
fn slide_room(ws: &Workspace, limits: &[(usize, usize, f64)]) -> f64 {
    let (mut rate, mut up, mut down) = (0.0, 0.0, 0.0);
    for &(j, i, coef) in limits {
        let k = ws.limit_adr[j] + i;
        let [lo, hi] = ws.limit_slack_now[k].map(|x| x.max(0.0));
        rate += coef * ws.limit_rate_now[k];
        // Δd = Σ coef Δq with Δq in [-lo, hi]
        let (more, less) = if coef > 0.0 { (hi, lo) } else { (lo, hi) };
        up += coef.abs() * more;
        down += coef.abs() * less;
    }
    match rate {
        r if r > 0.0 => up,
        r if r < 0.0 => down,
        _ => up.max(down),
    }
}

/// Runs of at least this many candidates of one geom pair and feature kind
/// ([`same_pair_run`]: the corners of one box against a plane or another box) are where
/// [`activate`] leaves out, with [`Reach::Approach`], the candidates well above the run's
/// lowest; not the two ends of a capsule.
///
/// Why: the Panda's fingertip pads are boxes of 4-8 mm, smaller than the 1 cm margin and than
/// the step's travel when the hand moves at ~1 m/s, so all eight corners of a pad over the floor
/// or over the other finger's pad were active, where at most its lower four can touch within
/// a step: 287 active candidates in one attempt of `step_bench` seed 3's step 51, ~0.5 ms an
/// iteration. Measured on the same states (`option_ab MODEL.xml 300 SEED` with a temporary
/// switch, seeds 1-8, seconds summed): Panda 1.421 → 1.273, every seed faster, no step
/// failed; A1 1.471 → 1.496 (29261 → 29356 iterations); the humanoid the same iterations and
/// states (1.971 → 2.007 s: the B side of `option_ab` runs ~2% slower for an option that changes
/// nothing). Applied to every pair (capsules too) the humanoid took 1-2% more iterations; with
/// the whole margin instead of half, Panda seed 5 lost 15% (its corners missed at the end of
/// the step are solved again); with none, a tenth more iterations (more missed corners).
/// Compared across a box pair's two kinds of feature, the big box's corners beside a small
/// one's face were left out against the small box's corners on the big one's face, which
/// changed a pressed gripper's steps (`cargo test --release --test slide_pair`).
const LOWEST_OF: usize = 4;

/// [`same_pair_run`] from `c`, and when it is a corner run (at least [`LOWEST_OF`]), the corner
/// runs right after it of other geoms of the same body against the same geom with the same
/// kind of feature: the corners of a body's boxes on one plane are points of one rigid body,
/// and the lowest of them all touches first.
///
/// Why: the Skydio X2 upside down on the floor (Table V from step ~330 on) rests on the tops
/// of three boxes within a centimetre of one another; box by box, each box's four top corners
/// stayed active (9.5 of its 36 candidates a step over 1000 steps, 14 at step 416, ~3 with a
/// normal impulse).
fn corner_group(model: &Model, c: usize) -> std::ops::Range<usize> {
    let mut run = same_pair_run(model, c);
    if run.len() < LOWEST_OF {
        return run;
    }
    let key = |k: usize| {
        let k = &model.contacts[k];
        (
            model.geoms[k.geom_a].body,
            k.geom_b,
            std::mem::discriminant(&k.feature),
        )
    };
    while run.end < model.ncontact() && key(run.end) == key(c) {
        let next = same_pair_run(model, run.end);
        if next.len() < LOWEST_OF {
            break;
        }
        run.end = next.end;
    }
    run
}

/// The end of the run of consecutive candidates from `c` between the same two geoms.
fn pair_run_end(model: &Model, c: usize) -> usize {
    let key = |k: &crate::contact::Contact| (k.geom_a, k.geom_b);
    let first = key(&model.contacts[c]);
    (model.contacts[c + 1..].iter())
        .position(|k| key(k) != first)
        .map_or(model.ncontact(), |i| c + 1 + i)
}

/// The run of consecutive candidates from `c` between the same two geoms with the same kind of
/// feature (a box pair's corners of one box against the other, then the other's).
fn same_pair_run(model: &Model, c: usize) -> std::ops::Range<usize> {
    let pair = |c: usize| {
        let k = &model.contacts[c];
        (k.geom_a, k.geom_b, std::mem::discriminant(&k.feature))
    };
    let end = (c + 1..model.ncontact())
        .find(|&k| pair(k) != pair(c))
        .unwrap_or(model.ncontact());
    c..end
}

/// The smallest current gap among `run` and its candidate's approach rate
/// (`contact_rate_now`), if any gap is finite.
fn lowest_candidate(ws: &Workspace, run: std::ops::Range<usize>) -> Option<(f64, f64)> {
    run.filter(|&c| ws.contact_phi_now[c].is_finite())
        .min_by(|&a, &b| ws.contact_phi_now[a].total_cmp(&ws.contact_phi_now[b]))
        .map(|c| (ws.contact_phi_now[c], ws.contact_rate_now[c]))
}

/// A value of the last geom pair asked for, computed again only when the pair changes: a
/// pair's candidates are consecutive. Why: [`activate`] and [`missed_contacts`] computed the
/// margin, a slide pair's room and the bounding-sphere gap for each candidate, the Panda's
/// 899 finger-pad candidates among them (callgrind, `step_bench panda.xml 1000 1 1`: 2.1% of
/// its instructions, the same steps bit for bit).
#[derive(Default)]
struct PairMemo(Option<((usize, usize), f64)>);

impl PairMemo {
    /// `value()` for `contact`'s geom pair.
    fn of(&mut self, contact: &crate::contact::Contact, value: impl FnOnce() -> f64) -> f64 {
        let key = (contact.geom_a, contact.geom_b);
        match self.0 {
            Some((k, v)) if k == key => v,
            _ => {
                let v = value();
                self.0 = Some((key, v));
                v
            }
        }
    }
}

/// [`candidate_margin`] through a [`PairMemo`].
#[derive(Default)]
struct MarginMemo(PairMemo);

impl MarginMemo {
    fn of(&mut self, model: &Model, contact: &crate::contact::Contact) -> f64 {
        self.0.of(contact, || candidate_margin(model, contact))
    }
}

/// The activation margin of candidate `contact` ([`activate`], [`missed_contacts`]):
/// `Options::activation_margin`, but at most the bounding radius of the pair's smaller geom
/// (a point, of radius 0, does not count as the smaller).
///
/// An infinite margin (every candidate active) stays infinite.
///
/// Why: the margin is a buffer against the approach-rate estimate, in metres, sized for
/// links; pairs with a small geom sat active at several times its size. The Panda's
/// fingertip pads (boxes of bounding radius 4.7–5.0 mm) made 16 corner candidates per pad
/// pair within the 1 cm margin whenever the fingers were less than 1 cm apart: 15.4–25.5 of
/// its 835 candidates active per Table V step (`step_bench panda.xml 300 1 SEED`, seeds
/// 9..12), about one with an impulse. Measured on the same states (`option_ab panda.xml 300
/// SEED` with a temporary switch for the cap, applied in the activation only), seeds
/// 9/10/11/12: 1738 → 1720, 1743 → 1772, 3876 → 3082, 2225 → 2129 iterations and
/// 0.187 → 0.142, 0.266 → 0.249, 2.09 → 1.20, 0.37 → 0.21 s, every step converged, positions
/// within 1e-5 m. The shared humanoid, A1 and X2 have no geom smaller than the margin: their
/// steps are bit for bit the same.
pub(crate) fn candidate_margin(model: &Model, contact: &crate::contact::Contact) -> f64 {
    let margin = model.options.activation_margin;
    if !margin.is_finite() {
        return margin;
    }
    let size = |g: usize| match bounding_radius(&model.geoms[g].shape) {
        r if r > 0.0 => r,
        _ => f64::INFINITY,
    };
    margin.min(size(contact.geom_a).min(size(contact.geom_b)))
}

/// Reach of a joint limit's activation (rad or m) before the rate term: [`activate_limits`].
pub(crate) const LIMIT_REACH: f64 = 0.1;

/// Activate the limits of every joint with a limited coordinate within `max(activation_margin,
/// LIMIT_REACH) + 4 h |θ̇|` of a bound at the step's start (θ̇ the joint's current rate); with
/// [`Reach::Bound`], every limited joint. Tendon limits likewise, by their length `Σ coef q`
/// and the rate bound `Σ |coef q̇|`. Records every limit's slacks at the step's start
/// (`limit_slack_now`). Returns how many joints and tendon limits it added.
///
/// Why: a limit far from its bounds carries no impulse, but as a node of the Newton system it
/// cost its assembly, factorisation and line-search evaluations in every iteration: on the
/// shared A1 (12 limited hinges, 0.1 of them active per Table V step) an iteration costs 22%
/// fewer instructions (callgrind, `step_bench a1.xml 60 1`: 688k → 535k, the same as the model
/// without limits). The reach: with the activation margin (0.01) and `2 h |θ̇|`, 19 of the
/// humanoid's 300 steps (seed 5) moved an inactive limit's coordinate to its bound and were
/// solved again; with 0.1 and `4 h |θ̇|`, none. The mean complementarity still counts the
/// inactive limits' pairs ([`super::inequality::mean_complementarity`]; left out, the
/// humanoid took 21.11 instead of 19.65 iterations per step, counted 19.06). `step_bench`, 8 seeds × 300 steps:
/// humanoid 19.65 → 19.06 iterations per step, A1 15.97 → 15.34, and 17% and 32% less time
/// per step (BENCHMARKS.md, session 19). A step that moves a coordinate past this reach is
/// caught by [`missed_limits`] and solved again.
fn activate_limits(model: &Model, state: &State, ws: &mut Workspace, reach: Reach) -> usize {
    let (margin, h) = (model.options.activation_margin, model.options.timestep);
    // NaN coordinates or rates stay active (the solve then reports them)
    let within_reach = |slack: [f64; 2], rate: f64| {
        let within = margin.max(LIMIT_REACH) + 4.0 * h * rate;
        !(slack[0] > within && slack[1] > within)
    };
    let nc = model.ncontact();
    let mut added = 0;
    for (j, joint) in model.joints.iter().enumerate() {
        if model.topology.limit_node[j].is_none() {
            continue;
        }
        record_limit_start(state, ws, j, joint);
        let mut near = reach == Reach::Bound;
        for i in 0..joint.limits.len() {
            let k = ws.limit_adr[j] + i;
            near |= within_reach(ws.limit_slack_now[k], ws.limit_rate_now[k].abs());
        }
        if near && !ws.active[nc + j] {
            ws.active[nc + j] = true;
            added += 1;
        }
    }
    // tendon limits: the length `L = Σ coef q` and a bound on its rate, `Σ |coef| |q̇|`
    let (nl, nj) = (
        ws.limit_slack_now.len() - model.tendon_limits.len(),
        model.njoint(),
    );
    for k in 0..model.tendon_limits.len() {
        let rate = record_tendon_start(model, state, ws, k);
        let slack = ws.limit_slack_now[nl + k];
        let near = reach == Reach::Bound || within_reach(slack, rate);
        if near && !ws.active[nc + nj + k] {
            ws.active[nc + nj + k] = true;
            added += 1;
        }
    }
    added
}

/// Record the slacks `(q - lo, hi - q)` and rates `q̇` of joint `j`'s limited coordinates at
/// `state` (`limit_slack_now`, `limit_rate_now`).
pub(crate) fn record_limit_start(
    state: &State,
    ws: &mut Workspace,
    j: usize,
    joint: &crate::joints::Joint,
) {
    if joint.limits.is_empty() {
        return;
    }
    let (q, qd) = joint_state(state, joint);
    for (i, &(dof, lo, hi)) in joint.limits.iter().enumerate() {
        let k = ws.limit_adr[j] + i;
        ws.limit_slack_now[k] = [q[dof] - lo, hi - q[dof]];
        ws.limit_rate_now[k] = qd[dof];
    }
}

/// Record tendon limit `k`'s slacks `(L - lo, hi - L)` and rate `L̇` at `state`
/// (`limit_slack_now`, `limit_rate_now` past the joints' limits); returns the bound on the rate
/// that the activation reads, `Σ |coef q̇|`.
pub(crate) fn record_tendon_start(
    model: &Model,
    state: &State,
    ws: &mut Workspace,
    k: usize,
) -> f64 {
    let tendon = &model.tendon_limits[k];
    let (mut len, mut bound, mut rate) = (0.0, 0.0, 0.0);
    for &(ji, dof, coef) in &tendon.terms {
        let (mut q, qd) = joint_state(state, &model.joints[ji]);
        crate::joints::coordinates::wind(model, state, ji, &mut q);
        len += coef * q[dof];
        bound += (coef * qd[dof]).abs();
        rate += coef * qd[dof];
    }
    let (lo, hi) = tendon.range;
    let at = ws.limit_slack_now.len() - model.tendon_limits.len() + k;
    ws.limit_slack_now[at] = [len - lo, hi - len];
    ws.limit_rate_now[at] = rate;
    bound
}

/// The rates `q̇` of joint `j`'s limited coordinates at `state`, into `out`.
pub(crate) fn limit_rates(state: &State, joint: &crate::joints::Joint, out: &mut [f64]) {
    let (_, qd) = joint_state(state, joint);
    for (o, &(dof, _, _)) in out.iter_mut().zip(&joint.limits) {
        *o = qd[dof];
    }
}

/// The rate `q̇` of `joint`'s coordinate `dof` at `state`.
pub(crate) fn coordinate_rate(state: &State, joint: &crate::joints::Joint, dof: usize) -> f64 {
    joint_state(state, joint).1[dof]
}

/// Coordinates and rates of `joint` at `state`.
fn joint_state(state: &State, joint: &crate::joints::Joint) -> ([f64; 7], [f64; 6]) {
    use crate::joints::coordinates::{joint_qvel_in_frame, pose_of};
    let frame = JointFrame::new(
        joint,
        &pose_of(state, joint.parent),
        &pose_of(state, joint.child),
    );
    let (mut q, mut qd) = ([0.0; 7], [0.0; 6]);
    frame.coordinates(joint, &mut q[..joint.nq()]);
    joint_qvel_in_frame(state, joint, &frame, &mut qd[..joint.nfree()]);
    (q, qd)
}

/// After a solve with some joint limits inactive: activate those of every joint with a limited
/// coordinate within `activation_margin / 4` of a bound at the new configuration
/// (`ws.next_pose`); returns how many joints were activated (the step must then be solved
/// again).
pub(crate) fn missed_limits(model: &Model, ws: &mut Workspace) -> usize {
    let floor = 0.25 * model.options.activation_margin;
    let nc = model.ncontact();
    let mut n = 0;
    for (j, joint) in model.joints.iter().enumerate() {
        if model.topology.limit_node[j].is_none() || ws.active[nc + j] {
            continue;
        }
        let pose = |b: usize| next_pose(&ws.next_pose, b);
        let frame = JointFrame::new(joint, &pose(joint.parent), &pose(joint.child));
        let mut q = [0.0; 7];
        frame.coordinates(joint, &mut q[..joint.nq()]);
        let near = joint
            .limits
            .iter()
            .any(|&(dof, lo, hi)| !(q[dof] - lo > floor && hi - q[dof] > floor));
        if near {
            ws.active[nc + j] = true;
            n += 1;
        }
    }
    let nj = model.njoint();
    for k in 0..model.tendon_limits.len() {
        if ws.active[nc + nj + k] {
            continue;
        }
        let len = super::tendon::next_length(model, ws, k);
        let (lo, hi) = model.tendon_limits[k].range;
        if !(len - lo > floor && hi - len > floor) {
            ws.active[nc + nj + k] = true;
            n += 1;
        }
    }
    n
}

/// How far ahead [`activate`] looks: the speed `u` in its reach `margin + h (2 u + h |g|)`.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum Reach {
    /// The rate at which the candidate's current witness points approach along its normal.
    /// Two links swinging past each other, or a foot swinging above the floor, stay inactive.
    Approach,
    /// A bound on the speed of any point of one geom relative to the other's body
    /// ([`relative_speed`]): covers every feature of the pair, at several times the cost.
    Bound,
    /// Every candidate.
    All,
}

/// Bound on the speed of any point of one geom relative to the material of the other's body at
/// the current velocities. With `a` the geom of finite reach `ρ` from its body's centre `c_a`
/// (and not on the world), a point `p` of `a` moves relative to `b`'s body at
/// `V + Ω × (p - c_a)`, `V = v_a - v_b - ω_b × (c_a - c_b)`, `Ω = ω_a - ω_b` (world frame), so
/// at most `|V| + |Ω| ρ`: two links moving rigidly together have none.
fn relative_speed(state: &State, ga: &crate::contact::Geom, gb: &crate::contact::Geom) -> f64 {
    let swap = ga.body == 0 || (gb.body != 0 && geom_reach(gb) < geom_reach(ga));
    let (a, b) = if swap { (gb, ga) } else { (ga, gb) };
    let motion = |body: usize| {
        if body == 0 {
            (Vector3::zeros(), Vector3::zeros(), Vector3::zeros())
        } else {
            let pose = state.pose(body);
            let (v, w) = state.velocity(body);
            (pose.pos, v, crate::math::quat::rotation(&pose.quat) * w)
        }
    };
    let ((ca, va, wa), (cb, vb, wb)) = (motion(a.body), motion(b.body));
    let spin = (wa - wb).norm();
    let turn = if spin > 0.0 {
        spin * geom_reach(a)
    } else {
        0.0
    };
    (va - vb - wb.cross(&(ca - cb))).norm() + turn
}

/// After a solve with some candidates inactive: activate every inactive candidate whose
/// distance at the new configuration (`ws.next_pose`) is below a quarter of its margin
/// ([`candidate_margin`]);
/// returns how many were activated (the step must then be solved again).
pub(crate) fn missed_contacts(model: &Model, ws: &mut Workspace) -> usize {
    let mut n = 0;
    let next = std::mem::take(&mut ws.next_pose);
    for (g, geom) in model.geoms.iter().enumerate() {
        ws.geom_bounds[g] = GeomBound::at(geom, &next_pose(&next, geom.body));
    }
    let (mut margins, mut gaps) = (MarginMemo::default(), PairMemo::default());
    for (c, contact) in model.contacts.iter().enumerate() {
        // (a shadowed candidate is implied by a tighter one that took part)
        if ws.active[c] || ws.shadowed[c] {
            continue;
        }
        // (an empty edge slot, or one left out of the step's preparation, holds no crossing:
        // a crossing the step brought in is found by `refreeze_crossings`, pair by pair)
        if contact.feature.is_crossing_slot()
            && matches!(ws.frozen[c], None | Some(Frozen::NoCrossing))
        {
            continue;
        }
        let floor = 0.25 * margins.of(model, contact);
        // far apart by the geoms' bounding spheres: no narrow phase (a frozen feature is
        // measured against its own plane, which such a bound does not cover)
        let (a, b) = (
            &ws.geom_bounds[contact.geom_a],
            &ws.geom_bounds[contact.geom_b],
        );
        if ws.frozen[c].is_none() && gaps.of(contact, || a.gap(b)) > floor {
            continue;
        }
        let wit = crate::contact::witness_frozen_at(
            contact,
            &model.geoms,
            (&a.frame, &b.frame),
            ws.frozen[c],
        );
        if wit.phi.is_nan() || wit.phi <= floor {
            ws.active[c] = true;
            n += 1;
        }
    }
    ws.next_pose = next;
    n
}

/// Penetration (m) of the exact disk rim that a solve with frozen rim points may leave before
/// the rim points are re-frozen at the solved pose and the step solved again.
const DISK_REFREEZE_TOL: f64 = 1e-10;

/// After a solve: every frozen disk–plane candidate whose exact lowest rim point at the new
/// configuration is below `-DISK_REFREEZE_TOL` is re-frozen at that point (the velocity change
/// of the step moved the lowest point away from the predicted one); returns how many were (the
/// step must then be solved again). A disk against a plane whose lowest point jumped across
/// the disk, more than a quarter turn round the rim both from the point it held and from the
/// point its contact frame was built at, has its frame built again at the new point
/// ([`Frozen::RimFramed`]): an upward impulse at a rim point tips a thin disk's far side down,
/// so the old frame could not lift the new point. (Random pile 198's cylinder lying flat on the
/// floor, struck by a capsule at 4.4 m/s, was re-frozen on the opposite side of its rim 3 mm
/// deep: no solution, and the step failed 14 mm deep; with the frame moved it converges in 69
/// iterations.) Otherwise the frame stays: a frame that followed every re-freeze made the
/// rounds rock a disk between two rim points 30° apart (random pile 20), one moved when a
/// lowest point that slid round the rim in steps of 10-30° passed a quarter turn left a wobbling
/// disk's step unconverged (pile 210), and a cylinder against another solid (a core point that
/// slides along the axes of two cylinders lying side by side: pile 10) never moves it. The
/// gradients linearise the step so (`prepare_candidates_holding`).
pub(crate) fn refreeze_disks(model: &Model, state: &State, ws: &mut Workspace) -> usize {
    let mut n = 0;
    let mut memo = crate::contact::BoxPairMemo::default();
    for (c, contact) in model.contacts.iter().enumerate() {
        let held = ws.frozen[c];
        if !matches!(held, Some(Frozen::Rim(_) | Frozen::RimFramed { .. })) || !ws.active[c] {
            continue;
        }
        let next = |x: usize| next_pose(&ws.next_pose, x);
        let (exact, pa, pb) = witness_frozen(contact, &model.geoms, next, None);
        if exact.phi >= -DISK_REFREEZE_TOL {
            continue;
        }
        n += 1;
        let rim = crate::contact::disk_rim_for_step(contact, &model.geoms, &pa, &pb, true);
        let (Some(point), Some(Frozen::Rim(last) | Frozen::RimFramed { point: last, .. })) =
            (rim, held)
        else {
            ws.frozen[c] = rim.map(Frozen::Rim);
            continue;
        };
        // (a cylinder against another solid keeps its frame: only disk–plane rims jump)
        let far = match contact.feature {
            Feature::DiskPlane { center_a, .. } => {
                let across = |p: Vector3<f64>| (p - center_a).dot(&(point - center_a)) < 0.0;
                across(last) && rim_frame_point(model, state, c, held).is_some_and(across)
            }
            _ => false,
        };
        if far {
            let moved = Frozen::RimFramed {
                point,
                frame: point,
            };
            prepare_candidate_with(model, state, ws, c, &mut memo, Some(moved));
            ws.frozen[c] = Some(moved);
        } else if let Some(Frozen::RimFramed { frame, .. }) = held {
            ws.frozen[c] = Some(Frozen::RimFramed { point, frame });
        } else {
            ws.frozen[c] = Some(Frozen::Rim(point));
        }
    }
    n
}

/// The rim point (the disk's geom frame) that candidate `c`'s contact frame was built at while
/// it holds `held`: a moved frame's, else the point frozen at the step's predicted poses (as
/// [`prepare`] froze it).
fn rim_frame_point(
    model: &Model,
    state: &State,
    c: usize,
    held: Option<Frozen>,
) -> Option<Vector3<f64>> {
    if let Some(Frozen::RimFramed { frame, .. }) = held {
        return Some(frame);
    }
    let contact = &model.contacts[c];
    let h = model.options.timestep;
    let ahead = |g: usize| predicted_pose(state, model.geoms[g].body, h);
    crate::contact::disk_rim_for_step(
        contact,
        &model.geoms,
        &ahead(contact.geom_a),
        &ahead(contact.geom_b),
        false,
    )
}

/// Penetration (m) of an edge crossing that a solve did not hold (the crossings were found at
/// the predicted poses) before it is brought into the step and the step solved again.
const CROSSING_REFREEZE_TOL: f64 = 1e-10;

/// After a solve: every box pair's edge crossing that penetrates at the new configuration
/// and that none of the pair's edge slots holds is put in a free slot, active (the step must
/// then be solved again); returns how many were. A slot outside the step's activation is
/// prepared first, so that preparing it later does not replace the crossing. The crossings
/// are found at the step's predicted poses ([`crate::contact::freeze_for_step`]); a box
/// knocked over by the step crosses edges the prediction did not.
pub(crate) fn refreeze_crossings(model: &Model, state: &State, ws: &mut Workspace) -> usize {
    use crate::contact::geometry::box_edges;
    let mut n = 0;
    // (the slots come after every other candidate: `ModelBuilder`'s order)
    let mut c = model
        .contacts
        .partition_point(|k| !k.feature.is_crossing_slot());
    let mut memo = crate::contact::BoxPairMemo::default();
    while c < model.ncontact() {
        let contact = &model.contacts[c];
        let same_pair = |k: &usize| {
            let other = &model.contacts[*k];
            (other.geom_a, other.geom_b) == (contact.geom_a, contact.geom_b)
                && other.feature.is_crossing_slot()
        };
        // (a pair's slots are consecutive)
        let end = (c..model.ncontact())
            .find(|k| !same_pair(k))
            .unwrap_or(model.ncontact());
        let slots = c..end.max(c + 1);
        c = slots.end;
        let (ga, gb) = (&model.geoms[contact.geom_a], &model.geoms[contact.geom_b]);
        // (bounding spheres at the new poses, from `missed_contacts`: apart, nothing crosses)
        if ws.geom_bounds[contact.geom_a].gap(&ws.geom_bounds[contact.geom_b]) > 0.0 {
            continue;
        }
        let pa = ga.world_pose(&next_pose(&ws.next_pose, ga.body));
        let pb = gb.world_pose(&next_pose(&ws.next_pose, gb.body));
        if crate::contact::crossing_pair_gap(&contact.feature, (&pa, &pb)) > 0.0 {
            continue; // apart: nothing crosses
        }
        let found = crate::contact::crossings_at(&contact.feature, (&pa, &pb));
        for x in (0..box_edges::EDGE_SLOTS).filter_map(|k| found.slot(k)) {
            let held = |k: &usize| matches!(ws.frozen[*k], Some(Frozen::Crossing { a, b, .. }) if (a, b) == (x.a, x.b));
            if x.phi >= -CROSSING_REFREEZE_TOL || slots.clone().any(|k| held(&k)) {
                continue;
            }
            for k in slots.clone() {
                if !ws.prepared[k] {
                    prepare_candidate_with(model, state, ws, k, &mut memo, None);
                }
            }
            let free = slots
                .clone()
                .find(|&k| matches!(ws.frozen[k], Some(Frozen::NoCrossing) | None));
            if let Some(k) = free {
                // its frame at the step's start from the crossing it now holds (built from
                // the empty slot's far witness, the impulse pushed along the line of the two
                // centres: random scene 765 gained 15% of its energy in a step)
                let frozen = crate::contact::crossing_frozen(Some(x));
                prepare_candidate_with(model, state, ws, k, &mut memo, Some(frozen));
                ws.active[k] = true;
                n += 1;
            }
        }
    }
    n
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::contact::geometry::Shape;
    use crate::solver::inequality::tests::scene;
    use crate::solver::test_rng::Rng;

    #[test]
    fn bounding_spheres_never_exceed_the_distance() {
        // every shape against the floor and the others it collides with, random poses: the
        // bound that lets `prepare` and `missed_contacts` skip the narrow phase must be at most
        // the signed distance (ellipsoids collide with planes only)
        let sphere = Shape::Sphere { radius: 0.1 };
        let capsule = Shape::Capsule {
            radius: 0.05,
            half_length: 0.2,
        };
        let cuboid = Shape::Box {
            half_extents: Vector3::new(0.1, 0.2, 0.05),
        };
        let cylinder = Shape::Cylinder {
            radius: 0.1,
            half_length: 0.15,
        };
        let ellipsoid = Shape::Ellipsoid {
            radii: Vector3::new(0.1, 0.05, 0.2),
        };
        // an elongated irregular hull (a rod with a bulge)
        let mesh = Shape::Mesh {
            hull: std::sync::Arc::new(
                crate::contact::hull::ConvexHull::new(&[
                    Vector3::new(0.3, 0.0, 0.0),
                    Vector3::new(-0.3, 0.02, 0.0),
                    Vector3::new(0.0, 0.08, 0.03),
                    Vector3::new(0.05, -0.04, 0.05),
                    Vector3::new(-0.1, 0.0, -0.06),
                    Vector3::new(0.1, 0.03, -0.04),
                ])
                .unwrap(),
            ),
        };
        let scenes = [
            vec![sphere.clone(), capsule.clone(), cuboid.clone()],
            vec![cylinder.clone()],
            vec![ellipsoid],
            vec![
                cylinder.clone(),
                sphere.clone(),
                capsule.clone(),
                cuboid.clone(),
                cylinder,
            ],
            vec![mesh.clone(), sphere, capsule, cuboid, mesh],
        ];
        let mut rng = Rng(7);
        let (mut informative, mut tighter) = (0, 0);
        for shapes in &scenes {
            let model = scene(shapes);
            let mut state = crate::State::reference(&model);
            for _ in 0..200 {
                for body in 1..model.nbody() {
                    let (w, x, y, z) = (rng.next(), rng.next(), rng.next(), rng.next());
                    let quat = nalgebra::Quaternion::new(w, x, y, z).normalize();
                    let pos = Vector3::new(rng.next(), rng.next(), 0.5 * rng.next() + 0.3) * 0.6;
                    state.set_pose(body, &Pose { pos, quat });
                }
                let exact = crate::contact::signed_distances(&model, &state);
                let pose = |b: usize| body_pose(&state, b);
                for (c, contact) in model.contacts.iter().enumerate() {
                    let (ga, gb) = (&model.geoms[contact.geom_a], &model.geoms[contact.geom_b]);
                    let a = GeomBound::at(ga, &pose(ga.body));
                    let b = GeomBound::at(gb, &pose(gb.body));
                    let gap = a.gap(&b);
                    assert!(
                        gap <= exact[c] + 1e-12,
                        "candidate {c}: bound {gap} > distance {}",
                        exact[c]
                    );
                    informative += usize::from(gap > 0.0);
                    // a mesh, box or cylinder pair's separation along its origins' axis (and a
                    // box's face normals): a bound too, and one that culls where the spheres
                    // do not
                    // (where positive: it culls only pairs apart by more than a margin; two
                    // geoms overlapping are overlapped by some candidates by more than both)
                    let axis = convex_pair_gap(&model, (contact.geom_a, contact.geom_b), &a, &b);
                    assert!(
                        axis <= 0.0 || axis <= exact[c] + 1e-12,
                        "candidate {c}: axis bound {axis} > distance {}",
                        exact[c]
                    );
                    tighter += usize::from(axis > 0.0 && gap <= 0.0);
                }
            }
        }
        assert!(
            informative > 1000,
            "a bound that never culls ({informative} positive)"
        );
        assert!(tighter > 100, "the axis bound never culls more ({tighter})");
    }

    #[test]
    fn geoms_moving_together_skip_the_narrow_phase_but_approaching_ones_do_not() {
        // two boxes 3 cm apart along x, 1 m above the floor, both flying at 5 m/s: each moves
        // 5 cm in a step, more than their gap, so their speeds alone cannot cull the pair, but
        // their relative speed is 0 and no candidate between them is prepared; with the same
        // speeds towards each other, every one is (and a step then brings them into contact)
        let cube = Shape::Box {
            half_extents: Vector3::new(0.05, 0.05, 0.05),
        };
        let model = scene(&[cube.clone(), cube]);
        let between: Vec<usize> = (model.contacts.iter().enumerate())
            .filter(|(_, k)| model.geoms[k.geom_a].body != 0 && model.geoms[k.geom_b].body != 0)
            .map(|(c, _)| c)
            .collect();
        assert!(between.len() >= 8, "{} box-box candidates", between.len());
        let offset = Vector3::new(0.05, -0.1, 0.08); // the geoms' offset in their bodies
        for (speed_b, prepared) in [(5.0, false), (-5.0, true)] {
            let mut state = crate::State::reference(&model);
            for (body, x) in [(1, 0.0), (2, 0.13)] {
                let pos = Vector3::new(x, 0.0, 1.0) - offset;
                let quat = nalgebra::UnitQuaternion::identity().into_inner();
                state.set_pose(body, &Pose { pos, quat });
            }
            state.set_velocity(1, &Vector3::new(5.0, 0.0, 0.0), &Vector3::zeros());
            state.set_velocity(2, &Vector3::new(speed_b, 0.0, 0.0), &Vector3::zeros());
            let mut ws = Workspace::new(&model);
            ws.active.fill(false);
            prepare(&model, &state, &mut ws);
            for &c in &between {
                // (an edge slot without a crossing is left unprepared in any case)
                if prepared && model.contacts[c].feature.is_crossing_slot() {
                    continue;
                }
                assert_eq!(ws.prepared[c], prepared, "candidate {c}, speed {speed_b}");
                assert!(ws.contact_phi_now[c] > 0.029, "{}", ws.contact_phi_now[c]);
            }
        }
    }

    #[test]
    fn a_small_geom_caps_its_candidates_margin() {
        // the floor, a 3 mm box, a point and a 20 cm sphere: every candidate with the box is
        // capped at its bounding radius, whatever the other geom; the point does not count as
        // small; an infinite margin (every candidate active) stays infinite
        let half = Vector3::new(0.003, 0.002, 0.003);
        let shapes = [
            Shape::Box { half_extents: half },
            Shape::Point,
            Shape::Sphere { radius: 0.2 },
        ];
        let model = scene(&shapes);
        let name = |g: usize| model.geoms[g].name.as_str();
        let mut seen = 0;
        for margin in [0.01, f64::INFINITY] {
            let mut o = model.options.clone();
            o.activation_margin = margin;
            let m = model.with_options(o).unwrap();
            for contact in &m.contacts {
                let pair = [name(contact.geom_a), name(contact.geom_b)];
                let expected = if !margin.is_finite() {
                    margin
                } else if pair.contains(&"g0") {
                    half.norm()
                } else {
                    margin
                };
                assert_eq!(candidate_margin(&m, contact), expected, "{pair:?}");
                seen += usize::from(pair.contains(&"g0") && pair.contains(&"floor"));
            }
        }
        assert!(seen > 0, "no box-floor candidate in the scene");
        assert!(half.norm() < 0.01);
    }
}
