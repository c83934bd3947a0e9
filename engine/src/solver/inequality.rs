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

use super::saturation::Hold;
use crate::contact::cone::{NtScaling, arrow, orthant_step, soc_product, soc_step};
use crate::contact::{ContactFrame, ContactModel, witness_frozen};
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
    saturated: &[Option<Hold>],
    mut f: impl FnMut(usize, usize, usize, usize, bool),
) {
    for_each_owned_pair(model, active, saturated, |_, o, p, d, r, soc| {
        f(o, p, d, r, soc)
    });
}

/// [`for_each_pair_except`], also passing who owns the pair (its activation flag's index): `c`
/// for contact candidate `c`, `ncontact + j` for a limit of joint `j`, `ncontact + njoint + k`
/// for tendon limit `k`, `ncontact + njoint + ntendon + j` for joint `j`'s dry friction and
/// `ncontact + 2 njoint + ntendon + k` for passive tendon `k`'s.
pub(crate) fn for_each_owned_pair(
    model: &Model,
    active: &[bool],
    saturated: &[Option<Hold>],
    mut f: impl FnMut(usize, usize, usize, usize, usize, bool),
) {
    let t = &model.topology;
    let nc = model.ncontact();
    for c in active_candidates(&active[..nc.min(active.len())]) {
        let contact = &model.contacts[c];
        let o = t.pattern.offset(t.contact_node[c]);
        for &(p, d, r) in orthant_pairs(contact.model) {
            f(c, o, p, d, r, false);
        }
        let held = saturated.get(c).is_some_and(|s| s.is_some());
        if contact.model == ContactModel::Nonlinear && !held {
            f(c, o, SOC.0, SOC.1, SOC.2, true);
        }
    }
    for (j, joint) in model.joints.iter().enumerate() {
        if let (Some(n), true) = (t.limit_node[j], limit_on(active, nc + j)) {
            let o = t.pattern.offset(n);
            for i in 0..joint.limits.len() {
                for &(p, d, r) in &LIMIT_PAIRS {
                    f(nc + j, o + 4 * i, p, d, r, false);
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
            f(tendons + k, t.pattern.offset(n), p, d, r, false);
        }
    }
    // dry friction, joints' then tendons': always active (owners past the activation flags)
    let frictions = tendons + t.tendon_node.len();
    let nodes = t.friction_node.iter().chain(&t.tendon_friction_node);
    for (j, n) in nodes.enumerate() {
        let Some(n) = *n else { continue };
        for i in 0..t.pattern.dim(n) / 4 {
            for &(p, d, r) in &LIMIT_PAIRS {
                f(frictions + j, t.pattern.offset(n) + 4 * i, p, d, r, false);
            }
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
    initialize_from(model, state, ws, warm, WarmFrom::State);
}

/// Where [`initialize_from`] takes a warm start's inequality variables.
#[derive(Clone, Copy, PartialEq, Eq)]
pub(crate) enum WarmFrom {
    /// The state's (the previous step's solution).
    State,
    /// The converged iterate kept in `ws.w_solved` for the pairs active there
    /// (`ws.active_solved`), the state's for the others.
    Solution,
}

/// [`initialize`] with the warm start taken from `from`.
pub(crate) fn initialize_from(
    model: &Model,
    state: &State,
    ws: &mut Workspace,
    warm: bool,
    from: WarmFrom,
) {
    let t = &model.topology;
    let mut k = 0;
    let nc = model.ncontact();
    let owners = (0..nc)
        .map(Some)
        .chain(
            t.limit_node
                .iter()
                .enumerate()
                .map(|(j, n)| n.map(|_| nc + j)),
        )
        .chain((0..t.tendon_node.len()).map(|i| Some(nc + model.njoint() + i)))
        .chain(t.friction_nodes().map(|_| Some(usize::MAX)))
        .flatten();
    let nodes = t
        .contact_node
        .iter()
        .chain(t.limit_node.iter().flatten())
        .chain(&t.tendon_node)
        .copied()
        .chain(t.friction_nodes())
        .map(|n| (n, t.pattern.dim(n)));
    for ((n, dim), owner) in nodes.zip(owners) {
        let o = t.pattern.offset(n);
        // (dry friction, owner `usize::MAX`, is always active)
        let solved = ws.active_solved.get(owner).copied().unwrap_or(true);
        if from == WarmFrom::Solution && solved {
            ws.w[o..o + dim].copy_from_slice(&ws.w_solved[o..o + dim]);
        } else {
            ws.w[o..o + dim].copy_from_slice(&state.ineq_vars[k..k + dim]);
        }
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
    super::saturation::hold_frictionless(model, ws);
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
    super::activation::ensure_prepared(model, state, ws);
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

/// Relative distance from its cone's boundary within which a warm-started friction member
/// counts as on it ([`turning_on_boundaries`]); the warm start leaves it
/// `Options::warm_start_margin` (1e-6) inside.
const ON_BOUNDARY: f64 = 1e-4;
/// The longest step to a sliding cone's boundary, estimated from its slip rows' residual
/// alone, at which [`turning_on_boundaries`] counts the first predictor as cut: that estimate
/// leaves out the turn of the velocities themselves, so it runs long.
const TURN_REACH: f64 = 5.0;

/// Whether a friction cone of the iterate slides with both members on their cones' boundaries
/// while the step must turn its slip: friction `ξ` at `μγ` against the slip `u = η₂:₃`, each
/// member within [`ON_BOUNDARY`] of its boundary (the previous step's sliding contact, warm
/// started), and the slip rows' residual `u - v_t` (the slip the new configuration gives the
/// warm velocities) turning `u`. Such a warm start cuts the first affine step short
/// (`ipm::WIDEN_BELOW`): a member `(|u| + m, u)` stays in its cone along a direction whose
/// component across `u` is `d⊥` only up to `α ≈ √(2 m |u|) / |d⊥|`, ~1e-3 at the warm start's
/// `m` = 1e-6, `|u|` = 0.5 m/s and `|d⊥|` ~ 1. Counted where that step, with `d⊥` the
/// residual's component across `u`, is below [`TURN_REACH`]; a straight slide, whose slip only
/// slows, is not cut and not counted. Measured (the first affine step of each whole step,
/// `step_bench MODEL 1000 1 SEED`): of the steps counted none had its predictor reach
/// `WIDEN_BELOW` on the shared humanoid, A1 and Panda at seeds 2, 3, 5 (3909 counted of 5899
/// cut) or the gymnasium humanoid at seed 2 (788 of 974); on the gymnasium ant, seeds 1-8,
/// 3 of 4534 counted had a predictor just past it (0.504, 0.528, 0.533), and are widened
/// where the test would not have widened them (seed 3's step 455: 9 iterations instead of
/// 15). The planar half_cheetah, hopper and walker2d: none counted.
pub(crate) fn turning_on_boundaries(model: &Model, ws: &Workspace) -> bool {
    let (w, r) = (&ws.w, &ws.residual);
    let t = &model.topology;
    active_candidates(&ws.active[..model.ncontact()]).any(|c| {
        if model.contacts[c].model != ContactModel::Nonlinear || ws.saturated[c].is_some() {
            return false;
        }
        let o = t.pattern.offset(t.contact_node[c]);
        let (xi, eta) = (v3(w, o + SOC.0), v3(w, o + SOC.1));
        let (friction, speed) = (xi[1].hypot(xi[2]), eta[1].hypot(eta[2]));
        let margin = eta[0] - speed;
        let on = xi[0] - friction <= ON_BOUNDARY * xi[0] && margin <= ON_BOUNDARY * eta[0];
        if !on || speed == 0.0 {
            return false;
        }
        // the slip rows' residual across the slip
        let (ux, uy) = (eta[1] / speed, eta[2] / speed);
        let across = (-uy * r[o + SOC.1 + 1] + ux * r[o + SOC.1 + 2]).abs();
        (2.0 * margin.max(0.0) * speed).sqrt() < TURN_REACH * across
    })
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
    super::friction::add_rows(model, ws, w, residual);
    let start = super::taper::at_start!(ws);
    let shifts = Shifts {
        kappa,
        start,
        joint_filter: &ws.joint_filter,
    };
    violations(model, &ws.active, &ws.saturated, w, residual, shifts)
}

/// What [`violations`] subtracts from the complementarity rows: κ, weighted by
/// [`super::taper`] with the gaps and rates at the step's start `start` when given, on the rows this
/// evaluation wrote (a joint left out by `joint_filter` keeps its limit rows as they were).
struct Shifts<'a> {
    kappa: f64,
    start: Option<super::taper::AtStart<'a>>,
    joint_filter: &'a [bool],
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
                Some(Hold::Sliding(held)) => {
                    // friction on the cone's boundary along d, η₁ the slip speed along -d
                    let (d, _) = super::saturation::direction(held, [eta[1], eta[2]]);
                    r[3] = eta[0] + d[0] * eta[1] + d[1] * eta[2];
                    r[4] = xi[1] - xi[0] * d[0];
                    r[5] = xi[2] - xi[0] * d[1];
                }
                Some(Hold::Frictionless | Hold::Separated) => {
                    r[3..6].copy_from_slice(&[eta[0], xi[1], xi[2]]);
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

/// Subtract κ ([`Shifts`]) from the complementarity rows' identity components; return
/// (equality ∞-norm of the inequality nodes, max |b ∘ c| / max(1, |b|) before the shift).
fn violations(
    model: &Model,
    active: &[bool],
    saturated: &[Option<Hold>],
    w: &[f64],
    residual: &mut [f64],
    shifts: Shifts,
) -> (f64, f64) {
    let t = &model.topology;
    // complementarity violation per pair, relative to the primal (impulse) variable once it
    // exceeds 1 N·s: a 1000 kg box's contact carries a product γ s 25× larger than a 1 kg box's
    // for the same hovering distance s, and round-off limits s, not γ s
    let mut kvio: f64 = 0.0;
    let cone_gap = model.options.cone_gap;
    let mut is_comp = |o: usize, p: usize, row: usize, soc: bool, k: f64, residual: &mut [f64]| {
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
        residual[o + row] -= k;
    };
    let nc = model.ncontact();
    let written = |owner: usize| match owner {
        i if i >= nc => shifts.joint_filter.get(i - nc).is_none_or(|&on| on),
        _ => true,
    };
    for_each_owned_pair(model, active, saturated, |owner, o, p, _, row, soc| {
        let k = match written(owner) && shifts.kappa != 0.0 {
            true => shifts.kappa * super::taper::weight(model, shifts.start, owner, o, p),
            false => 0.0,
        };
        is_comp(o, p, row, soc, k, residual)
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
    for n in t.friction_nodes() {
        for i in 0..t.pattern.dim(n) / 4 {
            eq(t.pattern.offset(n) + 4 * i, &[0, 2], residual, &mut rvio);
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
            (ws.proximal, ws.slack_floor),
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
    super::friction::assemble(model, ws, w);
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
    saturated: Option<Hold>,
    (rho, floor): (f64, f64),
    d: &mut [f64],
) {
    let dim = model.dim();
    d.fill(0.0);
    let mut set = |r: usize, c: usize, v: f64| d[r * dim + c] = v;
    set(0, 1, 1.0); // s - φ
    // orthant complementarity rows b c - κ: ∂/∂b = c, ∂/∂c = b (c at least `floor · b`)
    for &(p, q, r) in orthant_pairs(model) {
        set(r, p, x[q].max(floor * x[p]));
        set(r, q, x[p]);
    }
    match model {
        ContactModel::Impact => {}
        ContactModel::Nonlinear => {
            set(2, 2, 1.0); // ξ₁ - μγ
            set(2, 0, -mu);
            if saturated.is_none() {
                // the proximal term on the friction impulses (`Options::friction_proximal`):
                // matrix only, the residual rows stay η₂:₃ - v_t
                set(6, 3, -rho);
                set(7, 4, -rho);
            }
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
            if matches!(saturated, Some(Hold::Frictionless | Hold::Separated)) {
                // η₁ and ξ₂:₃
                for r in 3..6 {
                    for k in 2..8 {
                        set(r, k, 0.0);
                    }
                }
                set(3, 5, 1.0);
                set(4, 3, 1.0);
                set(5, 4, 1.0);
            } else if let Some(Hold::Sliding(held)) = saturated {
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
            d[(b + 1) * dim + b] = x[1].max(ws.slack_floor * x[0]);
            d[(b + 1) * dim + b + 1] = x[0];
            d[(b + 2) * dim + b + 3] = 1.0; // s_hi
            d[(b + 3) * dim + b + 2] = x[3].max(ws.slack_floor * x[2]);
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
    saturated: &[Option<Hold>],
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

/// The complementarity pairs of the candidates a solve leaves out, modelled as if they were
/// active and on the central path: each far pair's product `bᵀc` moves with every accepted step
/// `α` towards the step's target, `(1 - α) bᵀc + α κ` (a far pair's gap hardly changes, so its
/// Newton row is linear in its impulse and the step takes it exactly that far), and they add
/// `n · bᵀc / deg(K)` to the mean complementarity ([`mean_complementarity`]) without rows in the
/// Newton system.
///
/// Why: a solve that stalls with the activated candidates sometimes converges with every
/// candidate active, because the far pairs, tracking the targets, hold `μ` up and slow the
/// centring down. Activating every candidate did that at the cost of their rows: the shared
/// humanoid's 371 candidates made such an iteration ~7× as costly (22–27 ms per 50 iterations
/// against 3 ms), and Table V's slowest humanoid step spent 122 of its 414 iterations there
/// (failing anyway; BENCHMARKS.md, session 25).
#[derive(Clone, Copy, Debug, Default)]
pub(crate) struct FarPairs {
    /// How many pairs are modelled (0: none).
    pub count: f64,
    /// Their common product `bᵀc`.
    pub product: f64,
}

impl FarPairs {
    /// The pairs of every candidate and limit not active in `active`, with product `product`.
    pub fn left_out(model: &Model, active: &[bool], product: f64) -> FarPairs {
        // (a box pair's edge-crossing slots are not pairs of the problem's degree either,
        // [`crate::model::topology::Topology::cone_degree`])
        let slot = |c: usize| c < model.ncontact() && model.contacts[c].feature.is_crossing_slot();
        let every: Vec<bool> = (0..active.len()).map(|c| !slot(c)).collect();
        let taking: Vec<bool> = (0..active.len()).map(|c| active[c] && !slot(c)).collect();
        let mut count = 0usize;
        for_each_pair(model, &every, |_, _, _, _, _| count += 1);
        for_each_pair(model, &taking, |_, _, _, _, _| count -= 1);
        FarPairs {
            count: count as f64,
            product,
        }
    }

    /// What they add to the mean complementarity after an affine step `α` (target 0).
    pub fn mean(&self, model: &Model, alpha: f64) -> f64 {
        (1.0 - alpha) * self.count * self.product / model.topology.cone_degree.max(1) as f64
    }

    /// Move them along an accepted step `α` towards the target `κ`.
    pub fn advance(&mut self, alpha: f64, kappa: f64) {
        self.product = (1.0 - alpha) * self.product + alpha * kappa;
    }
}

/// Nesterov–Todd scalings of the active friction cones at the iterate `ws.w` (see
/// [`NtScaling`]); a pair that is not strictly interior keeps unscaled rows. (The inactive
/// candidates' scalings stay `None`: every solve clears them all before its first iteration,
/// and the activation does not change during a solve.)
pub(crate) fn update_scalings(model: &Model, ws: &mut Workspace) {
    let t = &model.topology;
    for c in active_candidates(&ws.active[..model.ncontact()]) {
        ws.nt[c] = None;
        if model.contacts[c].model == ContactModel::Nonlinear && ws.saturated[c].is_none() {
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
        let start = super::taper::at_start!(ws);
        let k = kappa * super::taper::weight(model, start, c, o, SOC.0);
        ws.residual[o + SOC.2] = r[0] - k;
        ws.residual[o + SOC.2 + 1] = r[1];
        ws.residual[o + SOC.2 + 2] = r[2];
    }
}

/// Mehrotra's second-order term: add `Δb_aff ∘ Δc_aff` to the complementarity rows (in the
/// scaled variables `WΔξ`, `W⁻¹Δη` for a friction cone with a scaling in `nt`).
pub(crate) fn add_mehrotra_correction(model: &Model, ws: &mut Workspace) {
    let (active, nt, delta_aff) = (&ws.active, &ws.nt, &ws.delta_aff);
    let residual = &mut ws.delta;
    for_each_pair(model, active, |o, p, d, row, soc| {
        if !soc {
            residual[o + row] += delta_aff[o + p] * delta_aff[o + d];
        }
    });
    let t = &model.topology;
    for c in active_candidates(&active[..model.ncontact().min(active.len())]) {
        // (a held cone's rows are equalities)
        if model.contacts[c].model != ContactModel::Nonlinear || ws.saturated[c].is_some() {
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
        if ws.active[c] && matches!(ws.saturated[c], Some(Hold::Sliding(_))) {
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
    for n in t.friction_nodes() {
        let (o, dim) = (t.pattern.offset(n), t.pattern.dim(n));
        state.ineq_vars[k..k + dim].copy_from_slice(&ws.w[o..o + dim]);
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
pub(crate) mod tests {
    use super::*;
    use crate::contact::geometry::Shape;
    use crate::joints::JointKind;
    use crate::model::{BodySpec, GeomSpec, JointSpec, ModelBuilder};

    /// The floor and one free body per shape, each geom offset and turned in its body.
    pub(crate) fn scene(shapes: &[Shape]) -> Model {
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

    /// Modelled far pairs add to the mean complementarity exactly what the same candidates
    /// would, active and on the central path at κ (`bᵀc = κ` for an orthant pair, `ξᵀη = κ`
    /// for a friction cone with `ξ = η = √κ e`), and each accepted step moves them along the
    /// line from their product to its target, as the Newton step moves such a pair.
    #[test]
    fn far_pairs_count_as_candidates_on_the_central_path() {
        let shapes = [
            Shape::Sphere { radius: 0.1 },
            Shape::Box {
                half_extents: Vector3::new(0.1, 0.2, 0.05),
            },
        ];
        let model = scene(&shapes);
        let n = model.ncontact() + model.njoint();
        assert!(model.ncontact() >= 3, "{} candidates", model.ncontact());
        let kappa: f64 = 3e-5;
        let mut w = vec![0.0; model.topology.pattern.total_dim()];
        let all = vec![true; n];
        for_each_pair(&model, &all, |o, p, d, _, soc| {
            for s in [o + p, o + d] {
                w[s] = kappa.sqrt();
                if soc {
                    w[s + 1..s + 3].fill(0.0);
                }
            }
        });
        let zero = vec![0.0; w.len()];
        let every = mean_complementarity(&model, &all, &w, &zero, 0.0);
        let mut some = all.clone();
        some[0] = false;
        some[2] = false;
        let far = FarPairs::left_out(&model, &some, kappa);
        assert!(far.count >= 2.0, "{far:?}");
        let modelled = mean_complementarity(&model, &some, &w, &zero, 0.0) + far.mean(&model, 0.0);
        assert!(
            (modelled - every).abs() <= 1e-15 * every,
            "{modelled:e} vs {every:e}"
        );
        // every candidate active: nothing left out
        assert_eq!(FarPairs::left_out(&model, &all, kappa).count, 0.0);
        // an affine step α scales them by 1 - α; an accepted step moves them towards κ'
        assert!((far.mean(&model, 0.25) - 0.75 * far.mean(&model, 0.0)).abs() < 1e-20);
        let mut moved = far;
        moved.advance(0.4, 1e-6);
        assert!((moved.product - (0.6 * kappa + 0.4 * 1e-6)).abs() < 1e-18);
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
