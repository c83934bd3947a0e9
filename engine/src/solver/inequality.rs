//! Inequality nodes of the step: contact candidates, joint limits and tendon limits (Dojo §IV-A,
//! eq. 26; the tendon-limit rows are in [`super::tendon`]).
//!
//! Residual rows, Jacobian blocks, complementarity bookkeeping and the cone line search for the
//! interior-point solve. Node-local variable layouts:
//!
//! ```text
//! impact     [γ, s]
//! nonlinear  [γ, s, ξ₁, ξ₂, ξ₃, η₁, η₂, η₃]
//! linear     [γ, s, ψ, s_ψ, β₁..β₄, η₁..η₄]          (β along +t1, -t1, +t2, -t2)
//! limit dof  [γ_lo, s_lo, γ_hi, s_hi]                   (4 per limited dof)
//! tendon     [γ_lo, s_lo, γ_hi, s_hi]                   (4 per tendon limit)
//! ```
use nalgebra::{Matrix3, Vector3};

use crate::contact::cone::{NtScaling, arrow, orthant_step, soc_product, soc_step};
use crate::contact::geometry::GeomPose;
use crate::contact::{
    ContactFrame, ContactModel, Frozen, StepRows, predicted_pose, witness_frozen,
};
use crate::joints::geometry::{JointFrame, Pose};
use crate::model::Model;
use crate::model::topology_body_node as body_node;
use crate::state::{State, Workspace};

/// Orthant pairs `(primal, dual, complementarity row)` of a model's node, node-local indices.
fn orthant_pairs(model: ContactModel) -> &'static [(usize, usize, usize)] {
    match model {
        ContactModel::Impact => &[(0, 1, 1)],
        ContactModel::Nonlinear => &[(0, 1, 1)],
        ContactModel::Linear => &[
            (0, 1, 6),
            (2, 3, 7),
            (4, 8, 8),
            (5, 9, 9),
            (6, 10, 10),
            (7, 11, 11),
        ],
    }
}

/// Node-local index of each limit pair: `(primal, dual, row)`.
const LIMIT_PAIRS: [(usize, usize, usize); 2] = [(0, 1, 1), (2, 3, 3)];

/// Second-order cone `(ξ start, η start, first row)` of a nonlinear contact node.
pub(crate) const SOC: (usize, usize, usize) = (2, 5, 3);

/// Visit every complementarity pair of the step: `f(offset, primal, dual, row, is_soc)` with
/// node-local indices relative to the node offset. Inactive contact candidates (`active[c]`
/// false) are left out.
pub(crate) fn for_each_pair(
    model: &Model,
    active: &[bool],
    f: impl FnMut(usize, usize, usize, usize, bool),
) {
    for_each_pair_except(model, active, &[], f)
}

/// [`for_each_pair`] leaving out the friction cones held saturated (`saturated[c]` set, see
/// [`super::saturation`]; an empty slice holds none): their rows are equalities.
pub(crate) fn for_each_pair_except(
    model: &Model,
    active: &[bool],
    saturated: &[Option<[f64; 2]>],
    mut f: impl FnMut(usize, usize, usize, usize, bool),
) {
    for_each_owned_pair(model, active, saturated, |_, o, p, d, r, soc| {
        f(o, p, d, r, soc)
    });
}

/// [`for_each_pair_except`], also passing who owns the pair: `Some(c)` for contact candidate
/// `c`, `Some(ncontact + j)` for a limit of joint `j`, `None` for a tendon limit.
pub(crate) fn for_each_owned_pair(
    model: &Model,
    active: &[bool],
    saturated: &[Option<[f64; 2]>],
    mut f: impl FnMut(Option<usize>, usize, usize, usize, usize, bool),
) {
    let t = &model.topology;
    let nc = model.ncontact();
    for c in active_candidates(&active[..nc.min(active.len())]) {
        let contact = &model.contacts[c];
        let o = t.pattern.offset(t.contact_node[c]);
        for &(p, d, r) in orthant_pairs(contact.model) {
            f(Some(c), o, p, d, r, false);
        }
        let held = saturated.get(c).is_some_and(|s| s.is_some());
        if contact.model == ContactModel::Nonlinear && !held {
            f(Some(c), o, SOC.0, SOC.1, SOC.2, true);
        }
    }
    for (j, joint) in model.joints.iter().enumerate() {
        if let (Some(n), true) = (t.limit_node[j], limit_on(active, nc + j)) {
            let o = t.pattern.offset(n);
            for i in 0..joint.limits.len() {
                for &(p, d, r) in &LIMIT_PAIRS {
                    f(Some(nc + j), o + 4 * i, p, d, r, false);
                }
            }
        }
    }
    let tendons = nc + model.njoint();
    for (k, &n) in t.tendon_node.iter().enumerate() {
        if !limit_on(active, tendons + k) {
            continue;
        }
        for &(p, d, r) in &LIMIT_PAIRS {
            f(None, t.pattern.offset(n), p, d, r, false);
        }
    }
}

/// Whether the limits with activation flag `i` (`ncontact + joint`) take part: flags past the
/// end of `active` (a contacts-only slice) count as active.
pub(crate) fn limit_on(active: &[bool], i: usize) -> bool {
    active.get(i).copied().unwrap_or(true)
}

/// Indices of the active candidates (`active`: the contact candidates' flags), skipping inactive ones sixteen at a time (most are: 1000
/// of the A1's 1024).
pub(crate) fn active_candidates(active: &[bool]) -> impl Iterator<Item = usize> + '_ {
    active
        .chunks(CHUNK)
        .enumerate()
        .filter(|(_, flags)| any_set(flags))
        .flat_map(|(k, flags)| {
            let set = flags.iter().enumerate().filter(|(_, a)| **a);
            set.map(move |(i, _)| k * CHUNK + i)
        })
}

/// Activation flags tested at once by [`active_candidates`] and `assemble`.
const CHUNK: usize = 16;

/// Whether any flag is set; a full chunk is tested as one 128-bit word (the byte-by-byte scan
/// of 1024 flags ran at every live-row loop of every iteration).
fn any_set(flags: &[bool]) -> bool {
    match <&[bool; CHUNK]>::try_from(flags) {
        Ok(chunk) => u128::from_ne_bytes(chunk.map(u8::from)) != 0,
        Err(_) => flags.contains(&true),
    }
}

fn v3(x: &[f64], i: usize) -> Vector3<f64> {
    Vector3::new(x[i], x[i + 1], x[i + 2])
}

/// Cold start: the neutral point (γ = s = 1, ξ = η = e). Warm start: the previous step's values
/// (stored in `state`) pushed at least `warm_start_margin` inside their cones.
pub(crate) fn initialize(model: &Model, state: &State, ws: &mut Workspace, warm: bool) {
    let t = &model.topology;
    let mut k = 0;
    let nodes = t
        .contact_node
        .iter()
        .chain(t.limit_node.iter().flatten())
        .chain(&t.tendon_node)
        .map(|&n| (n, t.pattern.dim(n)));
    for (n, dim) in nodes {
        let o = t.pattern.offset(n);
        let prev = &state.ineq_vars[k..k + dim];
        ws.w[o..o + dim].copy_from_slice(prev);
        k += dim;
    }
    let margin = model.options.warm_start_margin;
    let w = &mut ws.w;
    for_each_pair(model, &ws.active, |o, p, d, _, soc| {
        if soc {
            for start in [o + p, o + d] {
                let mut y = v3(w, start);
                if !warm || !y.iter().all(|v| v.is_finite()) {
                    y = Vector3::new(1.0, 0.0, 0.0);
                }
                crate::contact::cone::soc_interior(&mut y, margin);
                w[start..start + 3].copy_from_slice(y.as_slice());
            }
        } else {
            for i in [o + p, o + d] {
                w[i] = if warm && w[i].is_finite() {
                    w[i].max(margin)
                } else {
                    1.0
                };
            }
        }
    });
    // inactive limits: no impulse, the slacks of the step's start
    let nc = model.ncontact();
    for (j, joint) in model.joints.iter().enumerate() {
        if let (Some(n), false) = (t.limit_node[j], ws.active[nc + j]) {
            let o = t.pattern.offset(n);
            let mut x = [0.0; 4 * 6];
            let x = &mut x[..4 * joint.limits.len()];
            inactive_limit_vars(ws, j, joint.limits.len(), x);
            ws.w[o..o + x.len()].copy_from_slice(x);
        }
    }
    let nl = ws.limit_slack_now.len() - t.tendon_node.len();
    for (k, &n) in t.tendon_node.iter().enumerate() {
        if !ws.active[nc + model.njoint() + k] {
            let [lo, hi] = ws.limit_slack_now[nl + k];
            let o = t.pattern.offset(n);
            ws.w[o..o + 4].copy_from_slice(&[0.0, lo, 0.0, hi]);
        }
    }
    // other node entries (the ψ-slack pairs are covered above; nothing else is free)
    slip_at_start(model, state, ws, margin, warm);
}

/// Start the slip member `η` of the active friction cones at the tangential slip of the initial
/// iterate (so its equality rows `η₂:₃ = v_t` hold), its first entry raised to `|v_t| + margin`
/// where the cone needs it: every cone of a cold start or of a fresh state (the neutral point),
/// and of a warm start those whose contact carried no impulse in the last step (`γ` at the
/// margin: newly active or separated). The impulse member `ξ` is left as it is.
///
/// Why: such a cone started with no slip (`η = margin e`, or `e` cold) whatever the slip of the
/// contact, and its first Newton steps were cut by the cone while `η₁` grew (the A1 under
/// Table V controls, seed 5, step 41: affine steps cut to 5e-3…0.3 for seven iterations while
/// `η₁` of a newly touching foot grew from 1e-2 to 1.3). Measured with `step_bench MODEL 300 1
/// SEED`, seeds 5..12, iterations per step with each step capped at 100 (and the plain mean):
/// A1 16.53 → 15.73 (16.81 → 16.19), humanoid 19.41 → 18.51 (20.89 → 19.41), Panda 7.71 → 7.64
/// (14.64 → 14.84, its finger-pad stalls moved: one step of the 2400 unconverged, none before);
/// the 1000 random stress scenes still all pass. Aligning the persistent contacts' slip too
/// gave A1 15.50, humanoid 18.47, Panda 7.20, but stress scene 613 failed a step; raising `η₁`
/// further inside (`+ 0.1 |v_t|` or `+ |v_t|`), turning `ξ` against the new slip, or starting
/// the gap slack `s` at the predicted gap were worse.
fn slip_at_start(model: &Model, state: &State, ws: &mut Workspace, margin: f64, warm: bool) {
    ensure_prepared(model, state, ws);
    let t = &model.topology;
    let h = model.options.timestep;
    for c in active_candidates(&ws.active[..model.ncontact()]) {
        let contact = &model.contacts[c];
        if contact.model != ContactModel::Nonlinear || ws.saturated[c].is_some() {
            continue;
        }
        let o = t.pattern.offset(t.contact_node[c]);
        // (a warm start's γ is at least the margin; a fresh state's is at the neutral point)
        let neutral = ws.w[o..o + 8] == [1.0, 1.0, 1.0, 0.0, 0.0, 1.0, 0.0, 0.0];
        if warm && ws.w[o] > 2.0 * margin && !neutral {
            continue;
        }
        let motion = contact_motion(model, c, &ws.w);
        let (_, slip) = ws.contact_step[c].get(contact.radii());
        let vt = slip.tangential(h, &motion);
        let e = o + SOC.1;
        let mut eta = Vector3::new(ws.w[e], vt[0], vt[1]);
        crate::contact::cone::soc_interior(&mut eta, margin);
        ws.w[e..e + 3].copy_from_slice(eta.as_slice());
    }
}

/// Push every complementarity pair of the iterate at least `impulse` (its impulse member: γ,
/// ξ) and `slack` (its gap or slip member: s, η) inside its cone (see `ipm::WIDEN_BELOW`).
pub(crate) fn widen(model: &Model, ws: &mut Workspace, impulse: f64, slack: f64) {
    let w = &mut ws.w;
    for_each_pair_except(model, &ws.active, &ws.saturated, |o, p, d, _, soc| {
        if soc {
            for (start, m) in [(o + p, impulse), (o + d, slack)] {
                let mut y = v3(w, start);
                crate::contact::cone::soc_interior(&mut y, m);
                w[start..start + 3].copy_from_slice(y.as_slice());
            }
        } else {
            w[o + p] = w[o + p].max(impulse);
            w[o + d] = w[o + d].max(slack);
        }
    });
}

/// Contact frames at the current configuration (impulse directions, tangential velocity map),
/// and the features held fixed for the step (near-flat disk rim points, box corners' faces:
/// [`crate::contact::freeze_for_step`]).
///
/// An inactive candidate whose geoms' bounding spheres are apart by more than the step could
/// close at their speeds (`activation_margin + h (2 (u_a + u_b) + h |g|)`, `u` the fastest any
/// point of a geom moves) skips the narrow phase: its distance is recorded as that lower bound,
/// and its data are computed if it is activated ([`ensure_prepared`]). Measured 2026-12-02:
/// the narrow phase of every candidate was 11% of an A1 step (1024 candidates).
pub(crate) fn prepare(model: &Model, state: &State, ws: &mut Workspace) {
    let h = model.options.timestep;
    let drift = h * h * model.options.gravity.norm();
    for (g, geom) in model.geoms.iter().enumerate() {
        ws.geom_bounds[g] = GeomBound::new(state, geom);
    }
    let mut memo = crate::contact::BoxPairMemo::default();
    let mut poses = std::mem::take(&mut ws.geom_poses);
    let mut posed = false;
    for (c, contact) in model.contacts.iter().enumerate() {
        let margin = candidate_margin(model, contact);
        if !ws.active[c] && margin.is_finite() {
            let (a, b) = (
                &ws.geom_bounds[contact.geom_a],
                &ws.geom_bounds[contact.geom_b],
            );
            let gap = a.gap(b);
            if gap > margin + 2.0 * h * (a.speed + b.speed) + drift {
                ws.prepared[c] = false;
                ws.frozen[c] = None;
                ws.contact_phi_now[c] = gap;
                ws.contact_rate_now[c] = 0.0;
                continue;
            }
        }
        if !posed {
            GeomPoses::fill(model, state, &ws.geom_bounds, &mut poses);
            posed = true;
        }
        let [a, b] = [contact.geom_a, contact.geom_b].map(|g| &poses[g]);
        prepare_candidate_at(model, state, ws, c, (a, b), &mut memo);
    }
    ws.geom_poses = poses;
}

/// A geom's body pose and its world poses at the body's current pose and one step ahead at
/// its current velocities ([`predicted_pose`]): what preparing a candidate reads, computed
/// once per [`prepare`] pass rather than for each candidate. Measured 2026-12-03
/// (callgrind, `gradient_phases panda.xml 100 none coloured`): preparing the 368 of the
/// Panda's 835 candidates near enough per step was 12.9% of its instructions, the world
/// poses, predicted poses and state reads in it about half of that (its 400 finger-pad
/// corners share ten geoms).
#[derive(Clone, Copy, Debug)]
pub(crate) struct GeomPoses {
    body: Pose,
    now: GeomPose,
    ahead: GeomPose,
}

impl Default for GeomPoses {
    fn default() -> Self {
        Self {
            body: Pose::world(),
            now: GeomPose::default(),
            ahead: GeomPose::default(),
        }
    }
}

impl GeomPoses {
    /// The poses of geom `geom` at `state`.
    fn of(model: &Model, state: &State, geom: &crate::contact::Geom) -> Self {
        let h = model.options.timestep;
        let body = body_pose(state, geom.body);
        Self {
            body,
            now: geom.world_pose(&body),
            ahead: geom.world_pose(&predicted_pose(state, geom.body, h)),
        }
    }

    /// The poses of every geom at `state`, the current world poses taken from `bounds` (the
    /// geoms' bounds at `state`).
    fn fill(model: &Model, state: &State, bounds: &[GeomBound], out: &mut [GeomPoses]) {
        let h = model.options.timestep;
        for (g, geom) in model.geoms.iter().enumerate() {
            out[g] = Self {
                body: body_pose(state, geom.body),
                now: bounds[g].frame,
                ahead: geom.world_pose(&predicted_pose(state, geom.body, h)),
            };
        }
    }
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

/// [`prepare`] for every active candidate that it left out.
pub(crate) fn ensure_prepared(model: &Model, state: &State, ws: &mut Workspace) {
    let active = std::mem::take(&mut ws.active);
    let mut memo = crate::contact::BoxPairMemo::default();
    for c in active_candidates(&active[..model.ncontact()]) {
        if !ws.prepared[c] {
            prepare_candidate_with(model, state, ws, c, &mut memo);
        }
    }
    ws.active = active;
}

/// [`prepare`] for candidate `c` alone (its contact frame at `state` with the feature chosen
/// at the state's predicted poses, as a solve prepares it), then holding `frozen` as the
/// feature its gap at the next poses is measured with: the one the solve ended with, which
/// [`refreeze_disks`] may have moved after the frame was prepared. The gradients linearise a
/// solved step so, also at perturbed states (the features are material: a rim point or a face
/// of the geom).
pub(crate) fn prepare_candidate_holding(
    model: &Model,
    state: &State,
    ws: &mut Workspace,
    c: usize,
    frozen: Option<Frozen>,
) {
    prepare_candidate_with(model, state, ws, c, &mut Default::default());
    ws.frozen[c] = frozen;
}

/// [`prepare`] for candidate `c` within a pass over the candidates at `state` (`memo`: see
/// [`crate::contact::BoxPairMemo`]).
fn prepare_candidate_with(
    model: &Model,
    state: &State,
    ws: &mut Workspace,
    c: usize,
    memo: &mut crate::contact::BoxPairMemo,
) {
    let contact = &model.contacts[c];
    let [a, b] =
        [contact.geom_a, contact.geom_b].map(|g| GeomPoses::of(model, state, &model.geoms[g]));
    prepare_candidate_at(model, state, ws, c, (&a, &b), memo);
}

/// [`prepare_candidate_with`] with the poses of the candidate's geoms.
fn prepare_candidate_at(
    model: &Model,
    state: &State,
    ws: &mut Workspace,
    c: usize,
    (a, b): (&GeomPoses, &GeomPoses),
    memo: &mut crate::contact::BoxPairMemo,
) {
    let contact = &model.contacts[c];
    let (ga, gb) = (&model.geoms[contact.geom_a], &model.geoms[contact.geom_b]);
    ws.frozen[c] = crate::contact::freeze_for_step_at(
        contact,
        &model.geoms,
        (&a.now, &b.now),
        (&a.ahead, &b.ahead),
        memo,
    );
    let w =
        crate::contact::witness_frozen_at(contact, &model.geoms, (&a.now, &b.now), ws.frozen[c]);
    let (pa, pb) = (a.body, b.body);
    ws.prepared[c] = true;
    ws.contact_phi_now[c] = w.phi;
    // φ̇ = n · (velocity of A's witness − velocity of B's witness), n from B to A
    let point_velocity = |b: usize, pose: &Pose, p: &Vector3<f64>| {
        if b == 0 {
            return Vector3::zeros();
        }
        let (v, wb) = state.velocity(b);
        v + (crate::math::quat::rotation(&pose.quat) * wb).cross(&(p - pose.pos))
    };
    ws.contact_rate_now[c] = w.normal.dot(
        &(point_velocity(ga.body, &pa, &w.point_a) - point_velocity(gb.body, &pb, &w.point_b)),
    );
    ws.contact_step[c] = StepRows::new(w, pa, pb);
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
        } => radius.hypot(half_length),
        Shape::Ellipsoid { radii } => radii.max(),
        Shape::Point => 0.0,
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
    for (c, contact) in model.contacts.iter().enumerate() {
        let margin = candidate_margin(model, contact);
        let speed = match reach {
            Reach::All => unreachable!(),
            Reach::Approach => (-ws.contact_rate_now[c]).max(0.0),
            Reach::Bound => relative_speed(
                state,
                &model.geoms[contact.geom_a],
                &model.geoms[contact.geom_b],
            ),
        };
        let reach = margin + 2.0 * h * speed + drift;
        // NaN distances or speeds stay active (the solve then reports them)
        let phi = ws.contact_phi_now[c];
        ws.active[c] |= phi.is_nan() || reach.is_nan() || phi <= reach;
    }
    ws.active_contacts() - before + limits
}

/// The activation margin of candidate `contact` ([`activate`], [`missed_contacts`]):
/// `Options::activation_margin`, but at most the bounding radius of the pair's smaller geom
/// (a point, of radius 0, does not count as the smaller).
///
/// Why: the margin is a buffer against the approach-rate estimate, in metres, sized for
/// links; pairs of small geoms sat active at several times their own size. The Panda's
/// fingertip pads (boxes of bounding radius 4.7 mm) made 16 corner candidates per pad pair
/// within the 1 cm margin whenever the fingers were less than 1 cm apart: 15.4–25.5 of its
/// 835 candidates active per Table V step (`step_bench panda.xml 300 1 SEED`, seeds 9..12),
/// about one with an impulse. Measured on the same states (`option_ab panda.xml 300 SEED`,
/// the cap against the plain margin), seeds 9/10/11/12: 1738 → 1720, 1743 → 1772,
/// 3876 → 3082, 2225 → 2129 iterations and 0.187 → 0.142, 0.266 → 0.249, 2.09 → 1.20,
/// 0.37 → 0.21 s, every step converged, positions within 1e-5 m. The shared humanoid, A1 and X2
/// have no geom smaller than the margin: their steps are bit for bit the same.
pub(crate) fn candidate_margin(model: &Model, contact: &crate::contact::Contact) -> f64 {
    let size = |g: usize| match bounding_radius(&model.geoms[g].shape) {
        r if r > 0.0 => r,
        _ => f64::INFINITY,
    };
    model
        .options
        .activation_margin
        .min(size(contact.geom_a).min(size(contact.geom_b)))
}

/// Reach of a joint limit's activation (rad or m) before the rate term: [`activate_limits`].
const LIMIT_REACH: f64 = 0.1;

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
/// inactive limits' pairs ([`mean_complementarity`]; left out, the humanoid took 21.11
/// instead of 19.65 iterations per step, counted 19.06). `step_bench`, 8 seeds × 300 steps:
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
        let (q, qd) = joint_state(state, joint);
        let mut near = reach == Reach::Bound;
        for (i, &(dof, lo, hi)) in joint.limits.iter().enumerate() {
            let slack = [q[dof] - lo, hi - q[dof]];
            ws.limit_slack_now[ws.limit_adr[j] + i] = slack;
            near |= within_reach(slack, qd[dof].abs());
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
    for (k, tendon) in model.tendon_limits.iter().enumerate() {
        let (mut len, mut rate) = (0.0, 0.0);
        for &(ji, dof, coef) in &tendon.terms {
            let (q, qd) = joint_state(state, &model.joints[ji]);
            len += coef * q[dof];
            rate += (coef * qd[dof]).abs();
        }
        let (lo, hi) = tendon.range;
        let slack = [len - lo, hi - len];
        ws.limit_slack_now[nl + k] = slack;
        let near = reach == Reach::Bound || within_reach(slack, rate);
        if near && !ws.active[nc + nj + k] {
            ws.active[nc + nj + k] = true;
            added += 1;
        }
    }
    added
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
        let pose = |b: usize| {
            if b == 0 {
                Pose::world()
            } else {
                ws.next_pose[b]
            }
        };
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
    let pose = |x: usize| if x == 0 { Pose::world() } else { next[x] };
    for (g, geom) in model.geoms.iter().enumerate() {
        ws.geom_bounds[g] = GeomBound::at(geom, &pose(geom.body));
    }
    for (c, contact) in model.contacts.iter().enumerate() {
        if ws.active[c] {
            continue;
        }
        let floor = 0.25 * candidate_margin(model, contact);
        // far apart by the geoms' bounding spheres: no narrow phase (a frozen feature is
        // measured against its own plane, which such a bound does not cover)
        let (a, b) = (
            &ws.geom_bounds[contact.geom_a],
            &ws.geom_bounds[contact.geom_b],
        );
        if ws.frozen[c].is_none() && a.gap(b) > floor {
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
/// step must then be solved again). The contact frames stay those prepared with the first
/// freeze; the gradients linearise the step so (`prepare_candidate_holding`).
pub(crate) fn refreeze_disks(model: &Model, ws: &mut Workspace) -> usize {
    let mut n = 0;
    for (c, contact) in model.contacts.iter().enumerate() {
        if !matches!(ws.frozen[c], Some(Frozen::Rim(_))) || !ws.active[c] {
            continue;
        }
        let next = |x: usize| {
            if x == 0 {
                Pose::world()
            } else {
                ws.next_pose[x]
            }
        };
        let (exact, pa, pb) = witness_frozen(contact, &model.geoms, next, None);
        if exact.phi < -DISK_REFREEZE_TOL {
            ws.frozen[c] = crate::contact::disk_rim_for_step(contact, &model.geoms, &pa, &pb, true)
                .map(Frozen::Rim);
            n += 1;
        }
    }
    n
}

/// Add the inequality rows at the iterate `w` (with `ws.next_pose` set) and their impulses on
/// the body rows. Complementarity rows hold `b ∘ c - κ e`. Returns (equality ∞-norm of these
/// nodes, max |b ∘ c|). An inactive candidate's variables are frozen at the step's starting
/// values `state.ineq_vars` (no impulse); its rows are left as they are.
pub(crate) fn evaluate(
    model: &Model,
    ws: &mut Workspace,
    w: &[f64],
    residual: &mut [f64],
    kappa: f64,
) -> (f64, f64) {
    let t = &model.topology;
    let next = |ws: &Workspace, b: usize| {
        if b == 0 {
            Pose::world()
        } else {
            ws.next_pose[b]
        }
    };
    // an inactive candidate has no impulse; its variables stay at their start and its rows
    // are not read (`newton::for_each_live_range`)
    let active = std::mem::take(&mut ws.active);
    for c in active_candidates(&active[..model.ncontact()]) {
        let contact = &model.contacts[c];
        let [a, b] = t.contact_bodies[c];
        let (wit, pa, pb) = witness_frozen(
            contact,
            &model.geoms,
            |x| {
                if x == a {
                    next(ws, a)
                } else if x == b {
                    next(ws, b)
                } else {
                    Pose::world()
                }
            },
            ws.frozen[c],
        );
        ws.contact_phi[c] = wit.phi;
        ws.contact_dphi[c] = ContactFrame::normal_row(&wit, &pa, &pb);
        let motion = contact_motion(model, c, w);
        let (jac, slip) = ws.contact_step[c].get(contact.radii());
        let (jac, slip) = (*jac, slip.tangential(model.options.timestep, &motion));
        contact_rows(model, ws, c, w, &jac, slip, residual);
    }
    ws.active = active;
    let nc = model.ncontact();
    for (j, joint) in model.joints.iter().enumerate() {
        let Some(n) = t.limit_node[j] else { continue };
        if !super::newton::joint_included(ws, j) {
            continue;
        }
        if !ws.active[nc + j] {
            // an inactive limit: no impulse, its variables fixed (rows `w - w₀ = 0`)
            let o = t.pattern.offset(n);
            residual[o..o + 4 * joint.limits.len()].fill(0.0);
            continue;
        }
        let frame = JointFrame::new(joint, &next(ws, joint.parent), &next(ws, joint.child));
        let mut q = [0.0; 7];
        frame.coordinates(joint, &mut q[..joint.nq()]);
        let mut jf = [0.0; 6 * 12];
        frame.free_jacobian(joint, &mut jf[..12 * joint.nfree()]);
        let (o, la) = (t.pattern.offset(n), ws.limit_adr[j]);
        for (i, &(dof, lo, hi)) in joint.limits.iter().enumerate() {
            let theta = q[dof]; // limits exist only on scalar coordinates (qpos index = dof)
            ws.limit_dtheta[la + i].copy_from_slice(&jf[12 * dof..12 * dof + 12]);
            let x = &w[o + 4 * i..o + 4 * i + 4];
            let r = &mut residual[o + 4 * i..o + 4 * i + 4];
            // products only: `violations` shifts every pair's row by κ
            r[0] = x[1] - (theta - lo);
            r[1] = x[0] * x[1];
            r[2] = x[3] - (hi - theta);
            r[3] = x[2] * x[3];
            // generalized limit impulse γ_lo - γ_hi on the dof, through J_f at the current configuration
            let imp = x[0] - x[2];
            let fa = ws.free_adr[j] + 12 * dof;
            for (side, body) in [(0, joint.parent), (1, joint.child)] {
                if let Some(bn) = body_node(body) {
                    let ob = t.pattern.offset(bn);
                    for k in 0..6 {
                        residual[ob + k] -= ws.free_jac[fa + 6 * side + k] * imp;
                    }
                }
            }
        }
    }
    super::tendon::add_rows(model, ws, w, residual);
    violations(model, &ws.active, &ws.saturated, w, residual, kappa)
}

/// The velocities `(v, ω_body)` of contact `c`'s two bodies in the iterate `w` (the next
/// midpoint velocities; zero for the world).
fn contact_motion(model: &Model, c: usize, w: &[f64]) -> [(Vector3<f64>, Vector3<f64>); 2] {
    let t = &model.topology;
    let mut motion = [(Vector3::zeros(), Vector3::zeros()); 2];
    for (side, body) in t.contact_bodies[c].into_iter().enumerate() {
        if let Some(bn) = body_node(body) {
            let ob = t.pattern.offset(bn);
            motion[side] = (v3(w, ob), v3(w, ob + 3));
        }
    }
    motion
}

/// Residual rows of contact `c` and its impulse on the bodies along the rows `now` of its
/// current contact frame, given its tangential `slip` at `w`
/// ([`crate::contact::slip::Slip::tangential`]).
fn contact_rows(
    model: &Model,
    ws: &Workspace,
    c: usize,
    w: &[f64],
    now: &[[f64; 12]; 3],
    slip: [f64; 2],
    residual: &mut [f64],
) {
    let t = &model.topology;
    let contact = &model.contacts[c];
    let o = t.pattern.offset(t.contact_node[c]);
    let x = &w[o..o + contact.model.dim()];
    let (mu, phi) = (contact.friction, ws.contact_phi[c]);
    let vt = |k: usize| slip[k - 1];
    let r = &mut residual[o..o + contact.model.dim()];
    let force: [f64; 3] = match contact.model {
        ContactModel::Impact => {
            r[0] = x[1] - phi;
            r[1] = x[0] * x[1];
            [x[0], 0.0, 0.0]
        }
        ContactModel::Nonlinear => {
            let (xi, eta) = (v3(x, 2), v3(x, 5));
            r[0] = x[1] - phi;
            r[1] = x[0] * x[1];
            r[2] = xi[0] - mu * x[0];
            match ws.saturated[c] {
                None => r[3..6].copy_from_slice(soc_product(&xi, &eta).as_slice()),
                Some(held) => {
                    // friction on the cone's boundary along d, η₁ the slip speed along -d
                    let (d, _) = super::saturation::direction(held, [eta[1], eta[2]]);
                    r[3] = eta[0] + d[0] * eta[1] + d[1] * eta[2];
                    r[4] = xi[1] - xi[0] * d[0];
                    r[5] = xi[2] - xi[0] * d[1];
                }
            }
            r[6] = eta[1] - vt(1);
            r[7] = eta[2] - vt(2);
            [x[0], xi[1], xi[2]]
        }
        ContactModel::Linear => {
            let beta = &x[4..8];
            let (v1, v2) = (vt(1), vt(2));
            r[0] = x[1] - phi;
            r[1] = x[3] - (mu * x[0] - beta.iter().sum::<f64>());
            for (i, d) in [v1, -v1, v2, -v2].iter().enumerate() {
                r[2 + i] = x[8 + i] - (d + x[2]);
            }
            r[6] = x[0] * x[1];
            r[7] = x[2] * x[3];
            for i in 0..4 {
                r[8 + i] = x[4 + i] * x[8 + i];
            }
            [x[0], beta[0] - beta[1], beta[2] - beta[3]]
        }
    };
    // body rows: -J_cᵀ f
    let [a, b] = t.contact_bodies[c];
    for (side, body) in [(0, a), (1, b)] {
        if let Some(bn) = body_node(body) {
            let ob = t.pattern.offset(bn);
            for k in 0..6 {
                residual[ob + k] -= (0..3).map(|d| now[d][6 * side + k] * force[d]).sum::<f64>();
            }
        }
    }
}

/// Subtract κ from the complementarity rows' identity components; return (equality ∞-norm of the
/// inequality nodes, max |b ∘ c| / max(1, |b|) before the shift).
fn violations(
    model: &Model,
    active: &[bool],
    saturated: &[Option<[f64; 2]>],
    w: &[f64],
    residual: &mut [f64],
    kappa: f64,
) -> (f64, f64) {
    let t = &model.topology;
    // complementarity violation per pair, relative to the primal (impulse) variable once it
    // exceeds 1 N·s: a 1000 kg box's contact carries a product γ s 25× larger than a 1 kg box's
    // for the same hovering distance s, and round-off limits s, not γ s
    let mut kvio: f64 = 0.0;
    let cone_gap = model.options.cone_gap;
    let mut is_comp = |o: usize, p: usize, row: usize, soc: bool, residual: &mut [f64]| {
        let n = if soc && !cone_gap { 3 } else { 1 };
        let scale = w[o + p].abs().max(1.0);
        for i in 0..n {
            let v = residual[o + row + i] / scale;
            kvio = if v.is_nan() || kvio.is_nan() {
                f64::NAN
            } else {
                kvio.max(v.abs())
            };
        }
        residual[o + row] -= kappa;
    };
    for_each_pair_except(model, active, saturated, |o, p, _, row, soc| {
        is_comp(o, p, row, soc, residual)
    });
    // equality rows = all node rows that are not complementarity rows
    let mut rvio: f64 = 0.0;
    let eq = |o: usize, rows: &[usize], residual: &[f64], rvio: &mut f64| {
        for &r in rows {
            let v = residual[o + r];
            *rvio = if v.is_nan() || rvio.is_nan() {
                f64::NAN
            } else {
                rvio.max(v.abs())
            };
        }
    };
    let nc = model.ncontact();
    for c in active_candidates(&active[..nc.min(active.len())]) {
        let o = t.pattern.offset(t.contact_node[c]);
        let rows: &[usize] = match model.contacts[c].model {
            ContactModel::Impact => &[0],
            ContactModel::Nonlinear if saturated[c].is_some() => &[0, 2, 3, 4, 5, 6, 7],
            ContactModel::Nonlinear => &[0, 2, 6, 7],
            ContactModel::Linear => &[0, 1, 2, 3, 4, 5],
        };
        eq(o, rows, residual, &mut rvio);
    }
    for (j, joint) in model.joints.iter().enumerate() {
        if let (Some(n), true) = (t.limit_node[j], limit_on(active, nc + j)) {
            let o = t.pattern.offset(n);
            for i in 0..joint.limits.len() {
                eq(o + 4 * i, &[0, 2], residual, &mut rvio);
            }
        }
    }
    for (k, &n) in t.tendon_node.iter().enumerate() {
        if limit_on(active, nc + model.njoint() + k) {
            eq(t.pattern.offset(n), &[0, 2], residual, &mut rvio);
        }
    }
    (rvio, kvio)
}

/// Newton-matrix blocks of the inequality nodes at the iterate `w`.
pub(crate) fn assemble(model: &Model, ws: &mut Workspace, w: &[f64], h: f64) {
    let t = &model.topology;
    let mut idle_until = 0;
    for (c, contact) in model.contacts.iter().enumerate() {
        let n = t.contact_node[c];
        // a chunk of inactive candidates whose nodes are already skipped has nothing to do
        // (the candidates' nodes are consecutive)
        if c % CHUNK == 0 && c + CHUNK <= model.ncontact() {
            let chunk = c..c + CHUNK;
            if !any_set(&ws.active[chunk]) && ws.matrix.all_skipped(n..n + CHUNK) {
                idle_until = c + CHUNK;
            }
        }
        if c < idle_until {
            continue;
        }
        let active = ws.active[c];
        // frozen variables: `set_skipped` keeps the identity row and column of the node, so
        // the factorisation can skip it
        if ws.matrix.is_skipped(n) == active {
            ws.matrix.set_skipped(&t.pattern, n, !active);
        }
        if !active {
            continue;
        }
        let (o, dim) = (t.pattern.offset(n), contact.model.dim());
        let diag = t.pattern.block(n, n).unwrap_or(0);
        let nt = if ws.nt_on { ws.nt[c].as_ref() } else { None };
        contact_diag(
            contact.model,
            contact.friction,
            &w[o..o + dim],
            nt,
            ws.saturated[c],
            &mut ws.matrix.values[diag..diag + dim * dim],
        );
        let (now, slip) = ws.contact_step[c].get(contact.radii());
        let now = *now;
        let slip_rows = match contact.model {
            ContactModel::Impact => [[0.0; 12]; 2],
            _ => slip.rows(h, &contact_motion(model, c, w)),
        };
        let [a, b] = t.contact_bodies[c];
        for (side, body) in [(0, a), (1, b)] {
            let Some((row_n, row_b)) = t.contact_blocks[c][side] else {
                continue;
            };
            let dphi = ws.contact_dphi[c];
            let chain = chain_row(&dphi[6 * side..6 * side + 6], h, &ws.dphi[body]);
            let vals = &mut ws.matrix.values;
            // node rows × body cols
            let phi_row = 0;
            for k in 0..6 {
                vals[row_n + 6 * phi_row + k] = -chain[k];
            }
            let tangential: &[(usize, usize, f64)] = match contact.model {
                ContactModel::Impact => &[],
                ContactModel::Nonlinear => &[(6, 1, 1.0), (7, 2, 1.0)],
                ContactModel::Linear => &[(2, 1, 1.0), (3, 1, -1.0), (4, 2, 1.0), (5, 2, -1.0)],
            };
            for &(row, dir, sign) in tangential {
                let slip = slip_rows[dir - 1];
                for k in 0..6 {
                    vals[row_n + 6 * row + k] = -sign * slip[6 * side + k];
                }
            }
            // body rows × node cols: -J_cᵀ on the force variables
            let forces: &[(usize, usize, f64)] = match contact.model {
                ContactModel::Impact => &[(0, 0, 1.0)],
                ContactModel::Nonlinear => &[(0, 0, 1.0), (3, 1, 1.0), (4, 2, 1.0)],
                ContactModel::Linear => &[
                    (0, 0, 1.0),
                    (4, 1, 1.0),
                    (5, 1, -1.0),
                    (6, 2, 1.0),
                    (7, 2, -1.0),
                ],
            };
            for &(col, dir, sign) in forces {
                for k in 0..6 {
                    vals[row_b + dim * k + col] = -sign * now[dir][6 * side + k];
                }
            }
        }
    }
    assemble_limits(model, ws, w, h);
    super::tendon::assemble(model, ws, w, h);
}

/// `∂(row · δx⁺)/∂w` for one body: `[h row_p, row_φ · ∂φ/∂ω]`.
pub(super) fn chain_row(row: &[f64], h: f64, dphi: &Matrix3<f64>) -> [f64; 6] {
    let mut out = [0.0; 6];
    for i in 0..3 {
        out[i] = h * row[i];
        out[3 + i] = (0..3).map(|k| row[3 + k] * dphi[(k, i)]).sum();
    }
    out
}

/// Diagonal block of a contact node (row-major `dim × dim`), derivatives of its rows w.r.t. its
/// own variables; with a Nesterov–Todd scaling `nt`, the friction-cone rows are those of the
/// scaled complementarity `(W ξ) ∘ (W⁻¹ η)` (see [`scale_soc_rows`]); with a held saturated
/// friction direction, the equalities of [`super::saturation`] instead.
fn contact_diag(
    model: ContactModel,
    mu: f64,
    x: &[f64],
    nt: Option<&NtScaling>,
    saturated: Option<[f64; 2]>,
    d: &mut [f64],
) {
    let dim = model.dim();
    d.fill(0.0);
    let mut set = |r: usize, c: usize, v: f64| d[r * dim + c] = v;
    set(0, 1, 1.0); // s - φ
    // orthant complementarity rows b c - κ: ∂/∂b = c, ∂/∂c = b
    for &(p, q, r) in orthant_pairs(model) {
        set(r, p, x[q]);
        set(r, q, x[p]);
    }
    match model {
        ContactModel::Impact => {}
        ContactModel::Nonlinear => {
            set(2, 2, 1.0); // ξ₁ - μγ
            set(2, 0, -mu);
            // ξ ∘ η: row 3 = ξᵀη; rows 4,5 = ξ₁ η₂:₃ + η₁ ξ₂:₃
            for i in 0..3 {
                set(3, 2 + i, x[5 + i]);
                set(3, 5 + i, x[2 + i]);
            }
            for i in 0..2 {
                set(4 + i, 2, x[6 + i]);
                set(4 + i, 3 + i, x[5]);
                set(4 + i, 5, x[3 + i]);
                set(4 + i, 6 + i, x[2]);
                set(6 + i, 6 + i, 1.0); // η₂:₃ - v_t
            }
            if let Some(held) = saturated {
                // η₁ + d·η₂:₃ and ξ₂:₃ - ξ₁ d, with d = -η̂₂:₃ turning with a sliding slip:
                // ∂(ξ₁ d)/∂η₂:₃ = -ξ₁ (I - ddᵀ) / |η₂:₃|
                let (dir, turn) = super::saturation::direction(held, [x[6], x[7]]);
                for r in 3..6 {
                    for k in 2..8 {
                        set(r, k, 0.0);
                    }
                }
                set(3, 5, 1.0);
                for i in 0..2 {
                    set(3, 6 + i, dir[i]);
                    set(4 + i, 3 + i, 1.0);
                    set(4 + i, 2, -dir[i]);
                    for j in 0..2 {
                        let eye = if i == j { 1.0 } else { 0.0 };
                        set(4 + i, 6 + j, x[2] * turn * (eye - dir[i] * dir[j]));
                    }
                }
            } else if let Some(nt) = nt {
                // ∂/∂ξ = Arw(λ) W, ∂/∂η = Arw(λ) W⁻¹
                let a = arrow(&nt.lambda);
                let (dx, ds) = (a * nt.w, a * nt.w_inv);
                for r in 0..3 {
                    for k in 0..3 {
                        set(3 + r, 2 + k, dx[(r, k)]);
                        set(3 + r, 5 + k, ds[(r, k)]);
                    }
                }
            }
        }
        ContactModel::Linear => {
            set(1, 3, 1.0); // s_ψ - (μγ - Σβ)
            set(1, 0, -mu);
            for i in 0..4 {
                set(1, 4 + i, 1.0);
                set(2 + i, 8 + i, 1.0); // η_i - (d_iᵀ v + ψ)
                set(2 + i, 2, -1.0);
            }
        }
    }
}

fn assemble_limits(model: &Model, ws: &mut Workspace, w: &[f64], h: f64) {
    let t = &model.topology;
    let nc = model.ncontact();
    for (j, joint) in model.joints.iter().enumerate() {
        let Some(n) = t.limit_node[j] else { continue };
        // an inactive limit's node keeps the identity row and column (see `assemble`)
        let active = ws.active[nc + j];
        if ws.matrix.is_skipped(n) == active {
            ws.matrix.set_skipped(&t.pattern, n, !active);
        }
        if !active {
            continue;
        }
        let (o, dim) = (t.pattern.offset(n), 4 * joint.limits.len());
        let diag = t.pattern.block(n, n).unwrap_or(0);
        let d = &mut ws.matrix.values[diag..diag + dim * dim];
        d.fill(0.0);
        for i in 0..joint.limits.len() {
            let b = 4 * i;
            let x = &w[o + b..o + b + 4];
            d[b * dim + b + 1] = 1.0; // s_lo
            d[(b + 1) * dim + b] = x[1];
            d[(b + 1) * dim + b + 1] = x[0];
            d[(b + 2) * dim + b + 3] = 1.0; // s_hi
            d[(b + 3) * dim + b + 2] = x[3];
            d[(b + 3) * dim + b + 3] = x[2];
        }
        for (side, body) in [(0, joint.parent), (1, joint.child)] {
            let Some((row_n, row_b)) = t.limit_blocks[j][side] else {
                continue;
            };
            for (i, &(dof, _, _)) in joint.limits.iter().enumerate() {
                let dtheta = ws.limit_dtheta[ws.limit_adr[j] + i];
                let chain = chain_row(&dtheta[6 * side..6 * side + 6], h, &ws.dphi[body]);
                let fa = ws.free_adr[j] + 12 * dof + 6 * side;
                let vals = &mut ws.matrix.values;
                for k in 0..6 {
                    vals[row_n + 6 * (4 * i) + k] = -chain[k]; // s_lo - (θ - lo)
                    vals[row_n + 6 * (4 * i + 2) + k] = chain[k]; // s_hi - (hi - θ)
                    vals[row_b + dim * k + 4 * i] = -ws.free_jac[fa + k]; // -J_fᵀ γ_lo
                    vals[row_b + dim * k + 4 * i + 2] = ws.free_jac[fa + k]; // +J_fᵀ γ_hi
                }
            }
        }
    }
}

/// Largest step keeping every cone variable inside its cone with fractions `τ_ort`, `τ_soc`
/// (Algorithm 1).
pub(crate) fn cone_search(
    model: &Model,
    active: &[bool],
    saturated: &[Option<[f64; 2]>],
    w: &[f64],
    delta: &[f64],
    tau_ort: f64,
    tau_soc: f64,
) -> f64 {
    let mut alpha: f64 = 1.0;
    for_each_pair_except(model, active, saturated, |o, p, d, _, soc| {
        if soc {
            for s in [o + p, o + d] {
                alpha = alpha.min(soc_step(&v3(w, s), &v3(delta, s), tau_soc));
            }
        } else {
            alpha = alpha.min(orthant_step(
                &[w[o + p], w[o + d]],
                &[delta[o + p], delta[o + d]],
                tau_ort,
            ));
        }
    });
    alpha
}

/// Mean complementarity `μ = Σ bᵀc / deg(K)` at `w + α Δ` (eqs. 52-53) over every pair of the
/// problem: inactive contact candidates and joint limits are exactly complementary (no impulse,
/// product 0), so the sum runs over the active pairs and `deg(K)` is the whole problem's
/// ([`crate::model::topology::Topology::cone_degree`]).
///
/// Why the whole problem's degree: dividing by the active pairs only made the centring target
/// `σμ` tens of times larger on robots whose activation leaves most pairs out (the A1's 1024
/// candidates, ~5 active), and the Panda's finger-pad steps stalled with μ creeping down from
/// 1e-5 until a retry with every candidate active converged at once. `step_bench MODEL 300 1
/// SEED`, seeds 5..12, mean iterations per step (capped at 100): Panda 12.06 (6.96) → 7.87
/// (6.80), A1 15.34 (15.14) → 14.20 (14.19), humanoid 19.06 (18.20) → 17.11 (16.77) (counting
/// each inactive candidate as one pair; BENCHMARKS.md, session 19). A constant tenfold smaller
/// target `σμ/10` did as well on these (7.80, 14.60, 16.70) but moves every scene; with every
/// pair active this is the mean it always was.
pub(crate) fn mean_complementarity(
    model: &Model,
    active: &[bool],
    w: &[f64],
    delta: &[f64],
    alpha: f64,
) -> f64 {
    let mut sum = 0.0;
    let at = |i: usize| w[i] + alpha * delta[i];
    for_each_pair(model, active, |o, p, d, _, soc| {
        let n = if soc { 3 } else { 1 };
        sum += (0..n).map(|i| at(o + p + i) * at(o + d + i)).sum::<f64>();
    });
    sum / model.topology.cone_degree.max(1) as f64
}

/// Nesterov–Todd scalings of the active friction cones at the iterate `ws.w` (see
/// [`NtScaling`]); a pair that is not strictly interior keeps unscaled rows. (The inactive
/// candidates' scalings stay `None`: every solve clears them all before its first iteration,
/// and the activation does not change during a solve.)
pub(crate) fn update_scalings(model: &Model, ws: &mut Workspace) {
    let t = &model.topology;
    for c in active_candidates(&ws.active[..model.ncontact()]) {
        ws.nt[c] = None;
        if model.contacts[c].model == ContactModel::Nonlinear {
            let o = t.pattern.offset(t.contact_node[c]);
            ws.nt[c] = NtScaling::new(&v3(&ws.w, o + SOC.0), &v3(&ws.w, o + SOC.1));
        }
    }
}

/// Replace the friction-cone complementarity rows `ξ ∘ η - κe` of the residual at `w` by the
/// scaled `(W ξ) ∘ (W⁻¹ η) - κe` with the current scalings held fixed: the residual whose
/// Newton direction the scaled matrix rows give, so the line search measures what the step
/// decreases. Both vanish on the same central path (`W` is a cone automorphism).
pub(crate) fn scale_soc_rows(model: &Model, ws: &mut Workspace, trial: bool, kappa: f64) {
    if !ws.nt_on {
        return;
    }
    let t = &model.topology;
    let w = if trial { &ws.w_trial } else { &ws.w };
    for c in active_candidates(&ws.active[..model.ncontact()]) {
        let Some(nt) = &ws.nt[c] else { continue };
        let o = t.pattern.offset(t.contact_node[c]);
        let (xi, eta) = (nt.w * v3(w, o + SOC.0), nt.w_inv * v3(w, o + SOC.1));
        let r = soc_product(&xi, &eta);
        ws.residual[o + SOC.2] = r[0] - kappa;
        ws.residual[o + SOC.2 + 1] = r[1];
        ws.residual[o + SOC.2 + 2] = r[2];
    }
}

/// Mehrotra's second-order term: add `Δb_aff ∘ Δc_aff` to the complementarity rows (in the
/// scaled variables `WΔξ`, `W⁻¹Δη` for a friction cone with a scaling in `nt`).
pub(crate) fn add_mehrotra_correction(
    model: &Model,
    active: &[bool],
    nt: &[Option<NtScaling>],
    delta_aff: &[f64],
    residual: &mut [f64],
) {
    for_each_pair(model, active, |o, p, d, row, soc| {
        if !soc {
            residual[o + row] += delta_aff[o + p] * delta_aff[o + d];
        }
    });
    let t = &model.topology;
    for c in active_candidates(&active[..model.ncontact().min(active.len())]) {
        if model.contacts[c].model != ContactModel::Nonlinear {
            continue;
        }
        let o = t.pattern.offset(t.contact_node[c]);
        let (dp, dd) = (v3(delta_aff, o + SOC.0), v3(delta_aff, o + SOC.1));
        let corr = match &nt[c] {
            Some(s) => soc_product(&(s.w * dp), &(s.w_inv * dd)),
            None => soc_product(&dp, &dd),
        };
        for i in 0..3 {
            residual[o + SOC.2 + i] += corr[i];
        }
    }
}

/// Copy the inequality variables of the solved iterate into the state (warm start and output).
/// An inactive candidate stores zero impulse (γ = 0 marks it as inactive for the next warm
/// start) and its slack at the current distance.
pub(crate) fn store(model: &Model, state: &mut State, ws: &Workspace) {
    let t = &model.topology;
    let mut k = 0;
    for (c, &n) in t.contact_node.iter().enumerate() {
        let (o, dim) = (t.pattern.offset(n), t.pattern.dim(n));
        let x = &mut state.ineq_vars[k..k + dim];
        if ws.active[c] && ws.saturated[c].is_some() {
            // a friction cone held saturated by the polish: its friction impulse is kept at the
            // interior-point value (within the solver tolerance of the held one): the next
            // step's warm start from a point on the cone's boundary cost the 14-sphere pyramid
            // 27001 instead of 1140 iterations in 500 steps, and a failed step
            x.copy_from_slice(&ws.w[o..o + dim]);
            let xi = SOC.0..SOC.0 + 3;
            x[xi.clone()].copy_from_slice(&ws.w_acceptable[o + xi.start..o + xi.end]);
        } else if ws.active[c] {
            x.copy_from_slice(&ws.w[o..o + dim]);
        } else {
            x.fill(0.0);
            x[1] = ws.contact_phi_now[c].max(0.0);
        }
        k += dim;
    }
    let nc = model.ncontact();
    for (j, joint) in model.joints.iter().enumerate() {
        let Some(n) = t.limit_node[j] else { continue };
        let (o, dim) = (t.pattern.offset(n), t.pattern.dim(n));
        let x = &mut state.ineq_vars[k..k + dim];
        if ws.active[nc + j] {
            x.copy_from_slice(&ws.w[o..o + dim]);
        } else {
            inactive_limit_vars(ws, j, joint.limits.len(), x);
        }
        k += dim;
    }
    let nl = ws.limit_slack_now.len() - t.tendon_node.len();
    for (i, &n) in t.tendon_node.iter().enumerate() {
        let (o, dim) = (t.pattern.offset(n), t.pattern.dim(n));
        let x = &mut state.ineq_vars[k..k + dim];
        if ws.active[nc + model.njoint() + i] {
            x.copy_from_slice(&ws.w[o..o + dim]);
        } else {
            let [lo, hi] = ws.limit_slack_now[nl + i];
            x.copy_from_slice(&[0.0, lo, 0.0, hi]);
        }
        k += dim;
    }
}

/// The variables of joint `j`'s inactive limits (`n` dofs): no impulse, the slacks of the
/// step's start.
fn inactive_limit_vars(ws: &Workspace, j: usize, n: usize, x: &mut [f64]) {
    for i in 0..n {
        let [lo, hi] = ws.limit_slack_now[ws.limit_adr[j] + i];
        x[4 * i..4 * i + 4].copy_from_slice(&[0.0, lo, 0.0, hi]);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::contact::geometry::Shape;
    use crate::joints::JointKind;
    use crate::model::{BodySpec, GeomSpec, JointSpec, ModelBuilder};

    use crate::solver::test_rng::Rng;

    /// The floor and one free body per shape, each geom offset and turned in its body.
    fn scene(shapes: &[Shape]) -> Model {
        let mut b = ModelBuilder::new().geom(GeomSpec::new("floor", "world", Shape::Plane));
        for (i, shape) in shapes.iter().enumerate() {
            let name = format!("b{i}");
            b = b
                .body(BodySpec::new(&name, 1.0, [0.1; 3]))
                .joint(JointSpec::new(
                    &format!("j{i}"),
                    JointKind::Floating,
                    "world",
                    &name,
                ))
                .geom(
                    GeomSpec::new(&format!("g{i}"), &name, shape.clone())
                        .pos([0.05, -0.1, 0.08])
                        .quat([0.5, 0.5, -0.5, 0.5]),
                );
        }
        b.compile().unwrap()
    }

    #[test]
    fn bounding_spheres_never_exceed_the_distance() {
        // every shape against the floor and the others it collides with, random poses: the
        // bound that lets `prepare` and `missed_contacts` skip the narrow phase must be at most
        // the signed distance (cylinders and ellipsoids collide with planes only)
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
        let scenes = [
            vec![sphere, capsule, cuboid],
            vec![cylinder],
            vec![ellipsoid],
        ];
        let mut rng = Rng(7);
        let mut informative = 0;
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
                let pose = |b: usize| if b == 0 { Pose::world() } else { state.pose(b) };
                for (c, contact) in model.contacts.iter().enumerate() {
                    let (ga, gb) = (&model.geoms[contact.geom_a], &model.geoms[contact.geom_b]);
                    let a = GeomBound::at(ga, &pose(ga.body));
                    let gap = a.gap(&GeomBound::at(gb, &pose(gb.body)));
                    assert!(
                        gap <= exact[c] + 1e-12,
                        "candidate {c}: bound {gap} > distance {}",
                        exact[c]
                    );
                    informative += usize::from(gap > 0.0);
                }
            }
        }
        assert!(
            informative > 1000,
            "a bound that never culls ({informative} positive)"
        );
    }

    #[test]
    fn a_touching_contact_starts_its_slip_cone_at_its_slip() {
        // a sphere 1 mm above the floor sliding at 1.7 m/s: a newly active contact (no impulse
        // last step) starts η at its slip, a contact that carried impulse keeps its warm start
        let model = scene(&[Shape::Sphere { radius: 0.1 }]);
        let mut state = crate::State::reference(&model);
        let pose = Pose {
            pos: Vector3::new(0.0, 0.0, 0.1 + 0.001 - 0.08),
            quat: nalgebra::UnitQuaternion::identity().into_inner(),
        };
        state.set_pose(1, &pose);
        state.set_velocity(1, &Vector3::new(1.5, -0.8, 0.0), &Vector3::zeros());
        let eta = |state: &State| {
            let mut ws = Workspace::new(&model);
            let forces = crate::AppliedForces::default();
            crate::solver::newton::prepare(&model, state, &mut ws, &[], &forces);
            assert!(ws.active[0], "the touching contact is active");
            let e = model
                .topology
                .pattern
                .offset(model.topology.contact_node[0])
                + SOC.1;
            v3(&ws.w, e)
        };
        let new = eta(&state);
        let slip = new[1].hypot(new[2]);
        assert!((slip - 1.5f64.hypot(0.8)).abs() < 1e-12, "slip {slip}");
        assert!(
            new[0] >= slip && new[0] - slip < 1e-5,
            "η₁ {} at slip {slip}",
            new[0]
        );
        // the same contact carrying impulse (γ = 0.5, η = (0.5, 0.3, 0)): its warm start stands
        state.ineq_vars[..8].copy_from_slice(&[0.5, 1e-4, 0.2, 0.1, 0.0, 0.5, 0.3, 0.0]);
        assert_eq!(eta(&state), Vector3::new(0.5, 0.3, 0.0));
    }
}
