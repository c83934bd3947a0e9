//! Newton's method for the equality-constrained step: unknowns are each moving body's next
//! midpoint velocities `(v⁺, ω⁺)` and each joint's constraint impulses `λ`.
//!
//! ```text
//! body rows:  r_b = momentum(v⁺, ω⁺) - applied_b - Σ_j K_jbᵀ λ_j + h J_fᵀ D J_f w⁺   (impulses)
//! joint rows: r_j = k_j(x⁺_parent, x⁺_child)                                      (eq. 13)
//! ```
//! `K` is the constraint Jacobian at the current configuration, `k` is evaluated at the next
//! one, `x⁺ = (p + h v⁺, q ⊗ f(ω⁺))`. Dampers act on the next velocities (implicit), springs and
//! inputs at the current configuration. Updates of `ω⁺` are limited so `|ω⁺| < 2/h` (eq. 18's
//! domain): a too-fast spin ends as a reported failure, never a crash.
use nalgebra::{Matrix3, Vector3};

use super::activation::Reach;
use super::inequality::FarPairs;
use crate::integrator::variational::{momentum_residual, rot_jacobian};
use crate::joints::Joint;
use crate::joints::geometry::{JointFrame, Pose};
use crate::math::quat;
use crate::model::Model;
use crate::model::Transmission;
use crate::model::topology_body_node as body_node;
use crate::state::{SolveStatus, State, StepReport, Workspace};

/// Applied generalized and Cartesian forces for one step (beyond actuators).
#[derive(Clone, Copy, Debug, Default)]
pub struct AppliedForces<'a> {
    /// Generalized forces on `qvel` dofs (N or N·m). Shape (nv,).
    pub qfrc: Option<&'a [f64]>,
    /// World-frame wrenches `[force, torque]` at each body's COM. Shape (nbody, 6).
    pub xfrc: Option<&'a [f64]>,
}

/// Fraction of the angular-speed limit [`physical_spin_limit`] that an iterate may reach.
const MAX_SPIN_FRACTION: f64 = 0.995;

/// Largest angular speed of the physical branch of the rotational dynamics at time step `h`:
/// `√2 / h`, a step rotating a body by at most 90°.
///
/// The forward discrete momentum `c(ω) J ω` (`integrator::variational`) grows with `|ω|` only
/// while `c(ω) = sqrt(1 - |hω/2|²) ≥ 1/√2`; beyond, it falls again, so a momentum has a second,
/// spurious root between `√2/h` and the step map's limit `2/h`. A solve that reaches for it is
/// stopped here and fails, and the step is subdivided instead (measured: random stress scene
/// 673 jumped to 155 rad/s at h = 0.01 and gained 7.4 J, a third of its energy, in one step).
pub(crate) fn physical_spin_limit(h: f64) -> f64 {
    std::f64::consts::SQRT_2 / h
}

fn body_slot(model: &Model, b: usize) -> usize {
    body_node(b).map_or(0, |n| model.topology.pattern.offset(n))
}

fn w_body(model: &Model, w: &[f64], b: usize) -> (Vector3<f64>, Vector3<f64>) {
    if b == 0 {
        return (Vector3::zeros(), Vector3::zeros());
    }
    let o = body_slot(model, b);
    (
        Vector3::new(w[o], w[o + 1], w[o + 2]),
        Vector3::new(w[o + 3], w[o + 4], w[o + 5]),
    )
}

fn pose(state: &State, b: usize) -> Pose {
    if b == 0 { Pose::world() } else { state.pose(b) }
}

/// Everything of a step that depends on the current state, controls and forces but not on the
/// iterate: applied impulses, current-configuration joint, free and contact Jacobians.
pub(crate) fn prepare_forces(
    model: &Model,
    state: &State,
    ws: &mut Workspace,
    ctrl: &[f64],
    forces: &AppliedForces,
) {
    prepare_smooth_forces(model, state, ws, ctrl, forces);
    if model.topology.has_cones {
        super::activation::prepare(model, state, ws);
    }
}

/// [`prepare_forces`] without the contact frames (the gradients refresh only the candidates a
/// perturbation moves).
pub(crate) fn prepare_smooth_forces(
    model: &Model,
    state: &State,
    ws: &mut Workspace,
    ctrl: &[f64],
    forces: &AppliedForces,
) {
    let h = model.options.timestep;
    let g = model.options.gravity;
    for (b, body) in model.bodies.iter().enumerate() {
        let mut a = [0.0; 6];
        if b > 0 {
            let rot = quat::rotation(&state.pose(b).quat);
            let (f, tau) = match forces.xfrc {
                Some(x) => (
                    Vector3::new(x[6 * b], x[6 * b + 1], x[6 * b + 2]),
                    Vector3::new(x[6 * b + 3], x[6 * b + 4], x[6 * b + 5]),
                ),
                None => (Vector3::zeros(), Vector3::zeros()),
            };
            // gravity less the compensated share (MuJoCo's `gravcomp`)
            let lin = (g * (body.mass * (1.0 - body.gravcomp)) + f) * h;
            let rot_b = rot.transpose() * tau * h;
            a = [lin[0], lin[1], lin[2], rot_b[0], rot_b[1], rot_b[2]];
        }
        ws.applied[b] = a;
    }
    // Jacobians, coordinates and spring forces first: actuator lengths and rates need them
    for (ji, joint) in model.joints.iter().enumerate() {
        if !joint_included(ws, ji) {
            continue;
        }
        let frame = JointFrame::new(joint, &pose(state, joint.parent), &pose(state, joint.child));
        let adr = model.topology.con_adr[ji];
        frame.constraint_jacobian(joint, &mut ws.jac_now[12 * adr..12 * (adr + joint.ncon())]);
        let nf = joint.nfree();
        let fa = ws.free_adr[ji];
        frame.free_jacobian(joint, &mut ws.free_jac[fa..fa + 12 * nf]);
        frame.coordinates(joint, &mut ws.joint_q[ji][..joint.nq()]);
        crate::joints::coordinates::wind(model, state, ji, &mut ws.joint_q[ji][..joint.nq()]);
        let mut tau = [0.0; 6];
        let q = &ws.joint_q[ji][..joint.nq()];
        generalized_force(model, ji, &frame, q, forces, &mut tau[..nf]);
        ws.joint_tau[ji] = tau;
    }
    // passive tendon springs `-k (L - L₀)` (current configuration), applied below with the
    // actuators to every joint whose bodies' rows are written (a restricted evaluation moves
    // one term's coordinate and must see the force on the others)
    for (t, tendon) in model.passive_tendons.iter().enumerate() {
        let len: f64 = tendon
            .terms
            .iter()
            .map(|&(j, d, c)| c * ws.joint_q[j][d])
            .sum();
        ws.tendon_spring[t] = -tendon.stiffness * (len - tendon.springlength);
    }
    super::actuation::actuator_forces(model, state, ws, ctrl);
    let row = |ws: &Workspace, b: usize| b > 0 && (ws.body_filter.is_empty() || ws.body_filter[b]);
    for (ji, joint) in model.joints.iter().enumerate() {
        if !row(ws, joint.parent) && !row(ws, joint.child) {
            continue; // (its forces act on rows outside the body filter alone)
        }
        let nf = joint.nfree();
        let mut tau = ws.joint_tau[ji];
        super::actuation::add_joint_forces(model, ws, ji, &mut tau[..nf]);
        for (t, tendon) in model.passive_tendons.iter().enumerate() {
            for &(_, d, c) in tendon.terms.iter().filter(|term| term.0 == ji) {
                tau[d] += c * ws.tendon_spring[t];
            }
        }
        if tau[..nf].iter().any(|&t| t != 0.0) {
            let fa = ws.free_adr[ji];
            let jf = &ws.free_jac[fa..fa + 12 * nf];
            add_jt_times(&mut ws.applied, joint, jf, &tau[..nf], h);
        }
    }
    super::actuation::add_site_wrenches(model, state, ws);
    super::coupling::prepare(model, state, ws);
    // the applied forces act at the current configuration over half of each adjacent interval:
    // `(h_prev + h) / 2` (the variable-step discrete Euler-Lagrange equations)
    let h = model.options.timestep;
    if state.interval(h) != h {
        let scale = 0.5 * (1.0 + state.interval(h) / h);
        for a in ws.applied.iter_mut() {
            a.iter_mut().for_each(|x| *x *= scale);
        }
    }
}

/// Evaluate applied impulses and current-configuration Jacobians; set the initial iterate.
pub(crate) fn prepare(
    model: &Model,
    state: &State,
    ws: &mut Workspace,
    ctrl: &[f64],
    forces: &AppliedForces,
) {
    // the step's candidates are chosen below; until then none is active (so `prepare_forces`
    // may leave out those far from any activation)
    ws.active.fill(false);
    prepare_forces(model, state, ws, ctrl, forces);
    ws.attempt = 0;
    ws.saturated.fill(None);
    ws.shadowed.fill(false);
    if let Some(trace) = ws.trace.as_mut() {
        trace.clear();
    }
    // initial iterate: previous velocities and impulses (warm start)
    for b in 1..model.nbody() {
        let o = body_slot(model, b);
        let (v, w) = state.velocity(b);
        ws.w[o..o + 3].copy_from_slice(v.as_slice());
        ws.w[o + 3..o + 6].copy_from_slice(w.as_slice());
    }
    for (ji, joint) in model.joints.iter().enumerate() {
        if let Some(n) = model.topology.joint_node[ji] {
            let (o, adr) = (model.topology.pattern.offset(n), model.topology.con_adr[ji]);
            ws.w[o..o + joint.ncon()]
                .copy_from_slice(&state.joint_impulse[adr..adr + joint.ncon()]);
        }
    }
    for &n in &model.topology.coupling_node {
        ws.w[model.topology.pattern.offset(n)] = 0.0;
    }
    if model.topology.has_cones {
        let _ = super::activation::activate(model, state, ws, Reach::Approach);
        super::inequality::initialize(model, state, ws, model.options.warm_start);
    }
}

/// Reset the iterate to the state's velocities and the neutral cone point (impulses keep their
/// warm start: they are equality multipliers).
fn restart_cold(model: &Model, state: &State, ws: &mut Workspace) {
    for b in 1..model.nbody() {
        let o = body_slot(model, b);
        let (v, w) = state.velocity(b);
        ws.w[o..o + 3].copy_from_slice(v.as_slice());
        ws.w[o + 3..o + 6].copy_from_slice(w.as_slice());
    }
    super::inequality::initialize(model, state, ws, false);
    // modelled far pairs start where active ones would: at the neutral point
    if ws.far.count > 0.0 {
        ws.far.product = 1.0;
    }
}

/// Spring + applied generalized force on the free dofs of joint `ji` at its coordinates `coords`.
fn generalized_force(
    model: &Model,
    ji: usize,
    frame: &JointFrame,
    coords: &[f64],
    forces: &AppliedForces,
    tau: &mut [f64],
) {
    let joint = &model.joints[ji];
    if joint.has_spring() {
        frame.spring_force(joint, coords, tau);
    }
    if let (Some(q), false) = (forces.qfrc, joint.is_loop) {
        for (i, t) in tau.iter_mut().enumerate() {
            *t += q[joint.qvel_adr + i];
        }
    }
}

/// `applied_b += h J_bᵀ τ` for the joint's parent and child.
fn add_jt_times(applied: &mut [[f64; 6]], joint: &Joint, jac: &[f64], tau: &[f64], h: f64) {
    for (side, b) in [(0, joint.parent), (1, joint.child)] {
        if b == 0 {
            continue;
        }
        for (r, t) in tau.iter().enumerate() {
            let row = &jac[12 * r + 6 * side..12 * r + 6 * side + 6];
            for i in 0..6 {
                applied[b][i] += h * row[i] * t;
            }
        }
    }
}

/// Violation metrics of an iterate (eqs. 49-50).
#[derive(Clone, Copy, Debug)]
pub(crate) struct Violation {
    /// ∞-norm of the equality rows.
    pub r: f64,
    /// Largest complementarity product `|b ∘ c|` (0 without inequality nodes).
    pub k: f64,
}

/// Residual at the iterate `w` with complementarity target `kappa`; also sets `ws.next_pose`.
pub(crate) fn evaluate(
    model: &Model,
    state: &State,
    ws: &mut Workspace,
    use_trial: bool,
    kappa: f64,
) -> Violation {
    // take the buffers out so the iterate, the residual and the rest of the workspace can be
    // borrowed independently (no allocation: Vec moves)
    let w = std::mem::take(if use_trial {
        &mut ws.w_trial
    } else {
        &mut ws.w
    });
    let mut residual = std::mem::take(&mut ws.residual);
    let v = evaluate_in(model, state, ws, &w, &mut residual, kappa);
    *(if use_trial {
        &mut ws.w_trial
    } else {
        &mut ws.w
    }) = w;
    ws.residual = residual;
    v
}

/// What [`evaluate_kept`] keeps for [`recentre`].
#[derive(Clone, Debug)]
pub(crate) struct Kept {
    /// The residual at κ = 0.
    residual: Vec<f64>,
    /// The iterate it was evaluated at.
    iterate: Vec<f64>,
    /// Its violation metrics (they do not depend on κ).
    violation: Violation,
    /// False once anything else was evaluated (the derived quantities in the workspace, e.g.
    /// `next_pose`, are then another iterate's).
    pub(crate) valid: bool,
}

impl Kept {
    pub(crate) fn new(n: usize) -> Self {
        Self {
            residual: vec![0.0; n],
            iterate: vec![0.0; n],
            violation: Violation {
                r: f64::NAN,
                k: f64::NAN,
            },
            valid: false,
        }
    }
}

/// [`evaluate`] that also keeps the residual at κ = 0, the iterate and the violation metrics
/// for [`recentre`].
pub(crate) fn evaluate_kept(
    model: &Model,
    state: &State,
    ws: &mut Workspace,
    use_trial: bool,
    kappa: f64,
) -> Violation {
    // `x - 0.0` is `x`, so shifting afterwards gives the residual `evaluate` would
    let v = evaluate(model, state, ws, use_trial, 0.0);
    let w = if use_trial { &ws.w_trial } else { &ws.w };
    let kept = &mut *ws.kept;
    copy_live_rows(model, &ws.active, &ws.residual, &mut kept.residual);
    copy_live_rows(model, &ws.active, w, &mut kept.iterate);
    kept.violation = v;
    kept.valid = true;
    shift_complementarity(model, ws, kappa);
    v
}

/// The residual at complementarity target `kappa` of the iterate `ws.w`, as
/// `evaluate_kept(…, false, kappa)` gives it, without evaluating it again when it is the
/// iterate of the last evaluation (kept by [`evaluate_kept`]). The interior-point method
/// evaluates each accepted iterate at κ = 0 for its violations and then again at the centring
/// κ; the contact geometry of those evaluations was a fifth of a robot step.
pub(crate) fn recentre(model: &Model, state: &State, ws: &mut Workspace, kappa: f64) -> Violation {
    let same = |a: &[f64], b: &[f64]| a.iter().zip(b).all(|(x, y)| x.to_bits() == y.to_bits());
    let mut unchanged = ws.kept.valid;
    if unchanged {
        let (w, kept) = (&ws.w, &ws.kept.iterate);
        for_each_live_range(model, &ws.active, |r| {
            unchanged &= same(&w[r.clone()], &kept[r]);
        });
    }
    if !unchanged {
        return evaluate_kept(model, state, ws, false, kappa);
    }
    copy_live_rows(model, &ws.active, &ws.kept.residual, &mut ws.residual);
    shift_complementarity(model, ws, kappa);
    ws.kept.violation
}

/// `dst = src` on every row but those of the inactive contact candidates, which every
/// evaluation of a solve sets to the same `w - w₀ = 0` (their variables never move): on the
/// A1 they are 1000 of 1024 candidates, and copying them cost more than the rest.
fn copy_live_rows(model: &Model, active: &[bool], src: &[f64], dst: &mut [f64]) {
    for_each_live_range(model, active, |r| dst[r.clone()].copy_from_slice(&src[r]));
}

/// The row ranges of everything but the inactive contact candidates, joint limits and tendon
/// limits.
pub(crate) fn for_each_live_range(
    model: &Model,
    active: &[bool],
    mut f: impl FnMut(std::ops::Range<usize>),
) {
    use super::inequality::limit_on;
    let t = &model.topology;
    let p = &t.pattern;
    // layout: bodies, joints, couplings, limits | contacts | tendon limits
    let nodes = &t.contact_node;
    let (nc, nj) = (nodes.len(), t.limit_node.len());
    let mut start = 0;
    // the rows from `start` up to inactive node `n`, then past it
    let skip = |n: usize, start: &mut usize, f: &mut dyn FnMut(std::ops::Range<usize>)| {
        debug_assert!(p.offset(n) >= *start);
        if p.offset(n) > *start {
            f(*start..p.offset(n));
        }
        *start = p.offset(n) + p.dim(n);
    };
    for (j, n) in t.limit_node.iter().enumerate() {
        if let (Some(n), false) = (*n, limit_on(active, nc + j)) {
            skip(n, &mut start, &mut f);
        }
    }
    if let (Some(&first), Some(&last)) = (nodes.first(), nodes.last()) {
        if p.offset(first) > start {
            f(start..p.offset(first));
        }
        let contacts = &active[..nc.min(active.len())];
        for n in super::inequality::active_candidates(contacts).map(|c| nodes[c]) {
            f(p.offset(n)..p.offset(n) + p.dim(n));
        }
        start = p.offset(last) + p.dim(last);
    }
    for (k, &n) in t.tendon_node.iter().enumerate() {
        if !limit_on(active, nc + nj + k) {
            skip(n, &mut start, &mut f);
        }
    }
    if p.total_dim() > start {
        f(start..p.total_dim());
    }
}

/// Subtract κ from every complementarity row (what `inequality::evaluate` does for `kappa`);
/// a friction cone held saturated has equalities in its rows instead (`super::saturation`).
fn shift_complementarity(model: &Model, ws: &mut Workspace, kappa: f64) {
    if kappa != 0.0 {
        let r = &mut ws.residual;
        let start = super::taper::at_start!(ws);
        super::inequality::for_each_owned_pair(
            model,
            &ws.active,
            &ws.saturated,
            |owner, o, p, _, row, _| {
                r[o + row] -= kappa * super::taper::weight(model, start, owner, o, p)
            },
        );
    }
}

pub(crate) fn evaluate_in(
    model: &Model,
    state: &State,
    ws: &mut Workspace,
    w: &[f64],
    residual: &mut [f64],
    kappa: f64,
) -> Violation {
    ws.kept.valid = false;
    if model.topology.has_cones {
        // candidates activated since `prepare` (a wider retry, a missed contact, a copied set)
        super::activation::ensure_prepared(model, state, ws);
    }
    smooth_rows(model, state, ws, w, residual);
    if model.topology.has_cones {
        // adds contact and limit impulses to the body rows, so measure the body rows after it
        let (r, k) = super::inequality::evaluate(model, ws, w, residual, kappa);
        let smooth = inf_norm(&residual[..model.topology.smooth_dim]);
        let r = if r.is_nan() || smooth.is_nan() {
            f64::NAN
        } else {
            r.max(smooth)
        };
        Violation { r, k }
    } else {
        Violation {
            r: inf_norm(residual),
            k: 0.0,
        }
    }
}

/// Whether joint `ji` passes the workspace's joint filter (see `Workspace::joint_filter`).
pub(crate) fn joint_included(ws: &Workspace, ji: usize) -> bool {
    ws.joint_filter.is_empty() || ws.joint_filter[ji]
}

/// Body and joint rows (everything but the inequality nodes).
fn smooth_rows(model: &Model, state: &State, ws: &mut Workspace, w: &[f64], residual: &mut [f64]) {
    let h = model.options.timestep;
    let h_prev = state.interval(h);
    let Workspace {
        next_pose,
        applied,
        jac_now,
        free_jac,
        free_adr,
        joint_filter,
        body_filter,
        servo_damping,
        tendon_damping,
        ..
    } = ws;
    let row = |b: usize| b > 0 && (body_filter.is_empty() || body_filter[b]);
    for (b, body) in model.bodies.iter().enumerate().skip(1) {
        let (v, om) = w_body(model, w, b);
        let now = state.pose(b);
        next_pose[b] = Pose {
            pos: now.pos + v * h,
            quat: now.quat * quat::step_map(&om, h),
        };
        if !row(b) {
            continue;
        }
        let prev = state.velocity(b);
        let (lin, rot) = momentum_residual(
            body.mass,
            &body.inertia,
            (h_prev, h),
            (&prev.0, &prev.1),
            (&v, &om),
        );
        let o = body_slot(model, b);
        for i in 0..3 {
            residual[o + i] = lin[i] - applied[b][i];
            residual[o + 3 + i] = rot[i] - applied[b][3 + i];
        }
    }
    for (ji, joint) in model.joints.iter().enumerate() {
        let ncon = joint.ncon();
        if let Some(n) = model.topology.joint_node[ji] {
            let (o, adr) = (model.topology.pattern.offset(n), model.topology.con_adr[ji]);
            let k = &jac_now[12 * adr..12 * (adr + ncon)];
            for (side, b) in [(0, joint.parent), (1, joint.child)] {
                if !row(b) {
                    continue;
                }
                let ob = body_slot(model, b);
                let rb = &mut residual[ob..ob + 6];
                for (krow, &lam) in k.chunks_exact(12).zip(&w[o..o + ncon]) {
                    let krow = &krow[6 * side..6 * side + 6];
                    rb.iter_mut().zip(krow).for_each(|(r, &kk)| *r -= kk * lam);
                }
            }
            let np = if joint.parent == 0 {
                Pose::world()
            } else {
                next_pose[joint.parent]
            };
            let nc = if joint.child == 0 {
                Pose::world()
            } else {
                next_pose[joint.child]
            };
            if joint_filter.is_empty() || joint_filter[ji] {
                JointFrame::new(joint, &np, &nc).constraint(joint, &mut residual[o..o + ncon]);
            }
        }
        if !row(joint.parent) && !row(joint.child) {
            continue; // (its damper and armature act on these bodies' rows alone)
        }
        let servo = &servo_damping[free_adr[ji] / 12..free_adr[ji] / 12 + joint.nfree()];
        if joint.has_damper() || servo.iter().any(|&d| d != 0.0) {
            let jf = &free_jac[free_adr[ji]..];
            add_damper_residual(model, joint, jf, servo, w, residual, h);
        }
        if joint.has_armature() {
            let jf = &free_jac[free_adr[ji]..];
            super::armature::add_armature_residual(model, state, joint, jf, w, residual);
        }
    }
    add_tendon_servo_residual(model, free_jac, free_adr, tendon_damping, w, residual, h);
    if !model.couplings.is_empty() {
        super::coupling::add_rows(model, ws, w, residual);
    }
}

/// A fixed tendon's terms `(joint, free dof, coef)`.
type TendonTerms = [(usize, usize, f64)];

/// The terms of fixed-tendon servo `a` with its implicit damping `d`
/// (`actuation::actuator_forces`), when it has one.
fn tendon_servo<'m>(model: &'m Model, damping: &[f64], a: usize) -> Option<(&'m TendonTerms, f64)> {
    match (&model.actuators[a].transmission, damping[a]) {
        (Transmission::Tendon(terms), d) if d != 0.0 => Some((terms, d)),
        _ => None,
    }
}

/// Every implicit tendon damper `(terms, d)`: the fixed-tendon servos' velocity gains
/// (`damping`, per actuator) and the passive tendons' dampers.
fn tendon_dampers<'m>(
    model: &'m Model,
    damping: &'m [f64],
) -> impl Iterator<Item = (&'m TendonTerms, f64)> + 'm {
    (0..model.actuators.len())
        .filter_map(move |a| tendon_servo(model, damping, a))
        .chain(
            // (`!= 0`: the partials difference a damping of zero centrally, its negative side
            // included, or its column comes out halved)
            (model.passive_tendons.iter().filter(|t| t.damping != 0.0))
                .map(|t| (t.terms.as_slice(), t.damping)),
        )
}

/// `r_b += h d coef_t J_tbᵀ L̇⁺` for each term `t` of each implicit tendon damper `d`
/// ([`tendon_dampers`]), `L̇⁺ = Σ coef J_f w⁺` the tendon's rate at the iterate (the joint
/// damper's form, [`add_damper_residual`], on the tendon's rate).
fn add_tendon_servo_residual(
    model: &Model,
    free_jac: &[f64],
    free_adr: &[usize],
    damping: &[f64],
    w: &[f64],
    residual: &mut [f64],
    h: f64,
) {
    for (terms, d) in tendon_dampers(model, damping) {
        let row =
            |j: usize, dof: usize| &free_jac[free_adr[j] + 12 * dof..free_adr[j] + 12 * dof + 12];
        let mut rate = 0.0;
        for &(j, dof, coef) in terms {
            let joint = &model.joints[j];
            for (side, b) in [(0, joint.parent), (1, joint.child)]
                .into_iter()
                .filter(|s| s.1 > 0)
            {
                let (v, om) = w_body(model, w, b);
                let r = &row(j, dof)[6 * side..6 * side + 6];
                rate += coef
                    * (r[0] * v[0]
                        + r[1] * v[1]
                        + r[2] * v[2]
                        + r[3] * om[0]
                        + r[4] * om[1]
                        + r[5] * om[2]);
            }
        }
        for &(j, dof, coef) in terms {
            let joint = &model.joints[j];
            let f = h * d * coef * rate;
            for (side, b) in [(0, joint.parent), (1, joint.child)]
                .into_iter()
                .filter(|s| s.1 > 0)
            {
                let ob = body_slot(model, b);
                let r = &row(j, dof)[6 * side..6 * side + 6];
                for i in 0..6 {
                    residual[ob + i] += r[i] * f;
                }
            }
        }
    }
}

/// `h d coef_t coef_u J_taᵀ J_ub` into the body blocks (a, b) of every pair of terms `t, u` of
/// each implicit tendon damper `d` ([`tendon_dampers`]; the topology gives every pair of its
/// bodies a block: `ModelBuilder::compile`'s damped tendons).
fn add_tendon_servo_blocks(model: &Model, ws: &mut Workspace, h: f64) {
    let t = &model.topology;
    let damping = std::mem::take(&mut ws.tendon_damping);
    for (terms, d) in tendon_dampers(model, &damping) {
        for &(ja, da, ca) in terms {
            for &(jb, db, cb) in terms {
                let (joint_a, joint_b) = (&model.joints[ja], &model.joints[jb]);
                let ra = ws.free_adr[ja] + 12 * da;
                let rb = ws.free_adr[jb] + 12 * db;
                for (sa, ba) in [(0, joint_a.parent), (1, joint_a.child)] {
                    for (sb, bb) in [(0, joint_b.parent), (1, joint_b.child)] {
                        let (Some(na), Some(nb)) = (body_node(ba), body_node(bb)) else {
                            continue;
                        };
                        let off = match (ba == bb, t.pattern.block(na, nb)) {
                            (true, _) => t.body_diag[ba],
                            (false, Some(off)) => off,
                            (false, None) => {
                                debug_assert!(false, "tendon servo bodies {ba}, {bb}: no block");
                                continue;
                            }
                        };
                        let scale = h * d * ca * cb;
                        for r in 0..6 {
                            let x = scale * ws.free_jac[ra + 6 * sa + r];
                            for c in 0..6 {
                                ws.matrix.values[off + 6 * r + c] +=
                                    x * ws.free_jac[rb + 6 * sb + c];
                            }
                        }
                    }
                }
            }
        }
    }
    ws.tendon_damping = damping;
}

/// 2-norm of `x` over the live rows ([`for_each_live_range`]): the rows of inactive candidates
/// are never evaluated during a solve.
pub(crate) fn live_norm2(model: &Model, active: &[bool], x: &[f64]) -> f64 {
    let mut sum = 0.0;
    for_each_live_range(model, active, |r| {
        sum += x[r].iter().map(|v| v * v).sum::<f64>();
    });
    sum.sqrt()
}

/// ∞-norm of `x` over the live rows, propagating NaN.
pub(crate) fn live_inf_norm(model: &Model, active: &[bool], x: &[f64]) -> f64 {
    let mut m = 0.0f64;
    for_each_live_range(model, active, |r| {
        let n = inf_norm(&x[r]);
        m = if m.is_nan() || n.is_nan() {
            f64::NAN
        } else {
            m.max(n)
        };
    });
    m
}

/// ∞-norm that propagates NaN (`f64::max` alone would drop it).
fn inf_norm(x: &[f64]) -> f64 {
    x.iter().fold(0.0f64, |m, r| {
        if m.is_nan() || r.is_nan() {
            f64::NAN
        } else {
            m.max(r.abs())
        }
    })
}

/// `r_b += h J_bᵀ D (J_f w⁺)`: implicit damper impulses on both bodies, `D` the joint's damping
/// plus the servos' (`servo`, per free dof: `actuation::split_force`).
fn add_damper_residual(
    model: &Model,
    joint: &Joint,
    jf: &[f64],
    servo: &[f64],
    w: &[f64],
    residual: &mut [f64],
    h: f64,
) {
    let (wp, wc) = (
        w_body(model, w, joint.parent),
        w_body(model, w, joint.child),
    );
    let x = [
        wp.0[0], wp.0[1], wp.0[2], wp.1[0], wp.1[1], wp.1[2], wc.0[0], wc.0[1], wc.0[2], wc.1[0],
        wc.1[1], wc.1[2],
    ];
    for r in 0..joint.nfree() {
        let row = &jf[12 * r..12 * r + 12];
        let rate: f64 = row.iter().zip(x.iter()).map(|(a, b)| a * b).sum();
        let f = h * (joint.damping[r] + servo[r]) * rate;
        for (side, b) in [(0, joint.parent), (1, joint.child)] {
            if b > 0 {
                let ob = body_slot(model, b);
                for i in 0..6 {
                    residual[ob + i] += row[6 * side + i] * f;
                }
            }
        }
    }
}

/// Newton matrix at the iterate of the last [`evaluate`] (which set `ws.next_pose`).
pub(crate) fn assemble(model: &Model, ws: &mut Workspace) {
    let h = model.options.timestep;
    let t = &model.topology;
    ws.matrix.zero(&t.pattern);
    for (b, body) in model.bodies.iter().enumerate().skip(1) {
        let (_, om) = w_body(model, &ws.w, b);
        ws.dphi[b] = quat::step_map_dphi_domega(&om, h);
        let rj = rot_jacobian(&body.inertia, &om, h);
        let d = &mut ws.matrix.values[t.body_diag[b]..t.body_diag[b] + 36];
        for i in 0..3 {
            d[6 * i + i] = body.mass;
            for k in 0..3 {
                d[6 * (3 + i) + 3 + k] = rj[(i, k)];
            }
        }
    }
    for (ji, joint) in model.joints.iter().enumerate() {
        assemble_joint(model, ws, ji, joint, h);
    }
    add_tendon_servo_blocks(model, ws, h);
    super::coupling::assemble(model, ws, h);
    if t.has_cones {
        let w = std::mem::take(&mut ws.w);
        super::inequality::assemble(model, ws, &w, h);
        ws.w = w;
    }
}

fn assemble_joint(model: &Model, ws: &mut Workspace, ji: usize, joint: &Joint, h: f64) {
    let t = &model.topology;
    let ncon = joint.ncon();
    if let Some(dj) = t.joint_diag[ji] {
        let adr = t.con_adr[ji];
        let np = if joint.parent == 0 {
            Pose::world()
        } else {
            ws.next_pose[joint.parent]
        };
        let nc = if joint.child == 0 {
            Pose::world()
        } else {
            ws.next_pose[joint.child]
        };
        let jn = &mut ws.jac_next[12 * adr..12 * (adr + ncon)];
        JointFrame::new(joint, &np, &nc).constraint_jacobian(joint, jn);
        for r in 0..ncon {
            ws.matrix.values[dj + r * ncon + r] = -model.options.regularization;
        }
        for (side, b, blk) in [
            (0, joint.parent, &t.blocks[ji].jp),
            (1, joint.child, &t.blocks[ji].jc),
        ] {
            let Some((row_j, row_b)) = *blk else { continue };
            let dphi: Matrix3<f64> = ws.dphi[b];
            for r in 0..ncon {
                let jrow = &ws.jac_next[12 * (adr + r) + 6 * side..12 * (adr + r) + 6 * side + 6];
                let krow = &ws.jac_now[12 * (adr + r) + 6 * side..12 * (adr + r) + 6 * side + 6];
                let vals = &mut ws.matrix.values;
                // ∂k/∂v⁺ = h ∂k/∂δp ;  ∂k/∂ω⁺ = ∂k/∂δφ · ∂φ/∂ω
                for i in 0..3 {
                    vals[row_j + 6 * r + i] = h * jrow[i];
                    vals[row_j + 6 * r + 3 + i] = (0..3).map(|k| jrow[3 + k] * dphi[(k, i)]).sum();
                }
                // ∂r_b/∂λ = -K_bᵀ
                for i in 0..6 {
                    vals[row_b + ncon * i + r] = -krow[i];
                }
            }
        }
    }
    let fd = ws.free_adr[ji] / 12;
    let servo = ws.servo_damping[fd..fd + joint.nfree()]
        .iter()
        .any(|&d| d != 0.0);
    if joint.has_damper() || joint.has_armature() || servo {
        add_free_coupling_blocks(model, ws, ji, joint, h);
    }
}

/// `J_aᵀ C J_b` into the body blocks (a, b) for a, b ∈ {parent, child}, with the per-dof
/// coefficient `C = h · (damping + servo damping) + armature`: implicit dampers and rotor
/// inertia both act on the next free-coordinate rates, so they share one coupling term.
fn add_free_coupling_blocks(model: &Model, ws: &mut Workspace, ji: usize, joint: &Joint, h: f64) {
    let t = &model.topology;
    let fa = ws.free_adr[ji];
    let sides = [(0, joint.parent), (1, joint.child)];
    for (sa, a) in sides {
        for (sb, b) in sides {
            if a == 0 || b == 0 {
                continue;
            }
            let off = if a == b {
                t.body_diag[a]
            } else {
                match t.blocks[ji].pc {
                    Some((pc, cp)) => {
                        if sa == 0 {
                            pc
                        } else {
                            cp
                        }
                    }
                    None => continue,
                }
            };
            let block = &mut ws.matrix.values[off..off + 36];
            for r in 0..joint.nfree() {
                let row = &ws.free_jac[fa + 12 * r..fa + 12 * r + 12];
                let servo = ws.servo_damping[fa / 12 + r];
                let d =
                    h * (joint.damping[r] + servo) + joint.armature.get(r).copied().unwrap_or(0.0);
                let (ra, rb) = (&row[6 * sa..6 * sa + 6], &row[6 * sb..6 * sb + 6]);
                for (out, &a) in block.chunks_exact_mut(6).zip(ra) {
                    // (d a) b: the product in the order written before
                    let da = d * a;
                    out.iter_mut().zip(rb).for_each(|(o, &b)| *o += da * b);
                }
            }
        }
    }
}

/// Scale `α` so no body's `|ω + α Δω|` exceeds the step map's limit.
pub(crate) fn spin_limited_step(model: &Model, ws: &Workspace) -> f64 {
    let limit = MAX_SPIN_FRACTION * physical_spin_limit(model.options.timestep);
    let mut alpha: f64 = 1.0;
    for b in 1..model.nbody() {
        let (_, w) = w_body(model, &ws.w, b);
        let (_, d) = w_body(model, &ws.delta, b);
        while alpha > 1e-6 && (w + d * alpha).norm() > limit {
            alpha *= 0.5;
        }
    }
    alpha
}

/// Rounds of [`solve`]'s check of the solved step (candidates it reached, limits, re-frozen rims).
const ROUNDS: usize = 6;

/// Solve the prepared step: plain Newton without inequality nodes, the interior-point method
/// with them. Leaves the solution in `ws.w` and `ws.next_pose`.
pub(crate) fn solve(model: &Model, state: &State, ws: &mut Workspace) -> StepReport {
    if !model.topology.has_cones {
        return solve_newton(model, state, ws);
    }
    let mut report = solve_active(model, state, ws, RETRIES);
    // Activation is a speed heuristic and must never cost a step: a solve that failed with
    // some candidates left out is solved again with the candidates any point of whose geoms
    // could reach (`Reach::Bound`), then with the others' pairs modelled on the central path
    // (`FarPairs`), or, in a step's last resort (`Workspace::every_candidate`), with every
    // candidate active. (Far candidates hold complementarity pairs that sit on the central
    // path at every κ; with them the mean complementarity, hence the centering, changes, and
    // some stalled solves converge: random scene 543 step 38 stalls at k = 1.3e-8 without them
    // and converges in 13 iterations with.)
    // Warm, then one cold retry: the Panda's 835 candidates made the second cold retry cost
    // more than the rest of a run (`step_bench`, 8 × 300 steps: 16-18 → 14-15 ms/step, the same
    // unconverged steps; the stress suite unchanged; with no cold retry scene 613 fails).
    for wider in [Reach::Bound, Reach::All] {
        if report.status.is_success() {
            break;
        }
        if wider == Reach::All && !ws.every_candidate {
            let far = FarPairs::left_out(model, &ws.active, 0.0);
            if far.count == 0.0 {
                continue; // nothing left out: the same solve again
            }
            let iterations = report.iterations;
            ws.attempt = ws.attempt.saturating_add(1);
            ws.far = far;
            restart_warm(model, state, ws);
            report = solve_active(model, state, ws, 1);
            ws.far = FarPairs::default();
            report.iterations += iterations;
            continue;
        }
        // (a wider set that adds nothing would fail the same way)
        if super::activation::activate(model, state, ws, wider) == 0 {
            continue;
        }
        let iterations = report.iterations;
        ws.attempt = ws.attempt.saturating_add(1);
        restart_warm(model, state, ws);
        report = solve_active(model, state, ws, 1);
        report.iterations += iterations;
    }
    // Candidates left out of the step must not have been reached by it: check each at the new
    // configuration; if the step brought one within a quarter of the activation margin, solve
    // the step again with it active (rare: the activation reach already covers twice the
    // current speeds). Likewise a near-flat disk whose frozen rim point was not the lowest at
    // the new configuration is re-frozen there. Six rounds at most (three before cylinders met
    // other solids: piles of cylinders ended steps with a re-frozen rim still 8 µm deep, and one
    // step took 14k iterations; six left 0.1 µm and 4.5k, BENCHMARKS.md session 42); the
    // fifth and sixth have every candidate active.
    let mut unchecked = false;
    for round in 0..ROUNDS {
        unchecked = false;
        if !report.status.is_success() {
            break;
        }
        // (the checks below activate what they find and leave the iterate alone: the
        // converged iterate is kept only when a round follows)
        ws.active_solved.copy_from_slice(&ws.active);
        let missed = super::activation::missed_contacts(model, ws)
            + super::activation::missed_limits(model, ws)
            + super::activation::refreeze_disks(model, state, ws)
            + super::activation::refreeze_crossings(model, state, ws);
        if missed == 0 {
            break;
        }
        ws.w_solved.copy_from_slice(&ws.w);
        if round == ROUNDS - 2 {
            ws.active.fill(true);
        }
        let iterations = report.iterations;
        ws.attempt = ws.attempt.saturating_add(1);
        restart_from_solution(model, state, ws);
        ws.resumed = true;
        report = solve_active(model, state, ws, RETRIES);
        report.iterations += iterations;
        unchecked = true;
    }
    if report.status.is_success() {
        report.iterations += super::saturation::polish(model, state, ws);
    } else {
        let (iterations, kept) = super::saturation::rescue(model, state, ws);
        report.iterations += iterations;
        if kept {
            let vio = evaluate(model, state, ws, false, 0.0);
            report.status = SolveStatus::Converged;
            report.residual = vio.r;
            report.complementarity = vio.k;
        }
    }
    // the last round's solve was not checked: a step it leaves deeper than UNRESOLVED_DEPTH in
    // anything is no valid state (random pile 159: a cylinder lying across another's rim, its
    // held point swapping between the chord's two ends every round, was returned converged
    // 1.7 cm deep); reported unconverged, the step is subdivided, and if nothing does better
    // the caller sees the failure
    if unchecked && report.status.is_success() && deepest_at_solution(model, ws) < -UNRESOLVED_DEPTH
    {
        report.status = SolveStatus::MaxIterations;
    }
    report
}

/// Penetration (m) a solve whose check rounds ran out may leave and still be a success:
/// between the rounds' re-freezing tolerance (1e-10 m) and what a user sees. Over the 250
/// random piles of `tests/stress` (300 steps), 250 solves ran out of rounds: 98 left less
/// than 1e-7 m, 16 1e-7 to 1e-6 m, 136 more (115 of them in pile 235).
const UNRESOLVED_DEPTH: f64 = 1e-6;

/// The least exact signed distance of any candidate at the solved poses `ws.next_pose`.
fn deepest_at_solution(model: &Model, ws: &Workspace) -> f64 {
    let pose = |b: usize| {
        if b == 0 {
            Pose::world()
        } else {
            ws.next_pose[b]
        }
    };
    crate::contact::signed_distances_at(model, pose).fold(f64::INFINITY, f64::min)
}

/// Reset the iterate to the state's velocities and warm-started inequality variables, keeping
/// the current activation.
fn restart_warm(model: &Model, state: &State, ws: &mut Workspace) {
    for b in 1..model.nbody() {
        let o = body_slot(model, b);
        let (v, w) = state.velocity(b);
        ws.w[o..o + 3].copy_from_slice(v.as_slice());
        ws.w[o + 3..o + 6].copy_from_slice(w.as_slice());
    }
    super::inequality::initialize(model, state, ws, model.options.warm_start);
}

/// Restart a converged solve whose activation grew (a missed-contact round): its velocities,
/// joint impulses and the variables of the pairs that took part (`ws.w_solved`,
/// `ws.active_solved`) as the warm start, the pairs just activated warm-started from the state
/// as [`restart_warm`] starts them. The warm-start rules (interior margin, slip of fresh
/// cones) apply to both, and a first predictor cut short widens it as it widens a first
/// attempt (`Workspace::resumed`): the converged pairs sit at complementarity ~1e-11, and
/// where the new pair's residual moves them the iterates jammed at step lengths 1e-2..1e-8
/// until the cold retry. A1, `step_bench a1.xml 1000 1 SEED`, seeds 1-3, iterations of the
/// rounds: restarted from the state ~25 a round; from the solution ~14 (bimodal: 2-5, or
/// ~33 through the cold retry); widened too ~6.
fn restart_from_solution(model: &Model, state: &State, ws: &mut Workspace) {
    let t = &model.topology;
    for b in 1..model.nbody() {
        let o = body_slot(model, b);
        ws.w[o..o + 6].copy_from_slice(&ws.w_solved[o..o + 6]);
    }
    let joints = t.joint_node.iter().flatten().chain(&t.coupling_node);
    for &n in joints {
        let o = t.pattern.offset(n);
        let d = t.pattern.dim(n);
        ws.w[o..o + d].copy_from_slice(&ws.w_solved[o..o + d]);
    }
    super::inequality::initialize_from(
        model,
        state,
        ws,
        model.options.warm_start,
        super::inequality::WarmFrom::Solution,
    );
}

/// Whether every active complementarity pair of the iterate is at the neutral point (γ = s = 1,
/// cones at e), the cold start of [`restart_cold`].
fn at_neutral_point(model: &Model, ws: &Workspace) -> bool {
    let w = &ws.w;
    let mut neutral = true;
    super::inequality::for_each_pair_except(model, &ws.active, &ws.saturated, |o, p, d, _, soc| {
        neutral &= if soc {
            [o + p, o + d]
                .iter()
                .all(|&i| w[i] == 1.0 && w[i + 1] == 0.0 && w[i + 2] == 0.0)
        } else {
            w[o + p] == 1.0 && w[o + d] == 1.0
        };
    });
    neutral
}

/// Cold retries of a failed activated solve ([`solve_active`]).
const RETRIES: usize = 2;

/// The interior-point solve with the current activation; on failure retried cold, then cold
/// with unscaled friction-cone rows, at most `max_retries` retries (each rescues steps the
/// others stall on: a warm start sits on the previous solution's cone boundary, poor when
/// contacts change state; the scaled and unscaled directions stall in different degenerate
/// configurations). An attempt that stalls at an acceptable iterate is first solved on from
/// that iterate recentred ([`resume_recentred`]), then the retries try for full convergence;
/// if they all fail, the acceptable iterate is the result.
fn solve_active(
    model: &Model,
    state: &State,
    ws: &mut Workspace,
    max_retries: usize,
) -> StepReport {
    // a warm start that is the neutral point (a fresh state's) is the scaled cold start: its
    // retry would repeat the failed solve (measured: the shared humanoid's first Table V step
    // from `squat` followed the same iterates from the eighth iteration on, 50 iterations per tier)
    let warm_is_cold = at_neutral_point(model, ws);
    let mut report = super::ipm::solve(model, state, ws);
    let gentler = super::ipm::widening(model) > super::ipm::WIDEN_IMPULSE_GENTLE;
    if !report.status.is_success() && ws.widened && ws.attempt == 0 && gentler {
        // the widened warm start failed: once more from the warm start widened gently
        // (`ipm::WIDEN_IMPULSE_GENTLE`)
        let first = report.iterations;
        restart_warm(model, state, ws);
        ws.attempt = ws.attempt.saturating_add(1);
        ws.gentle_widening = true;
        report = super::ipm::solve(model, state, ws);
        ws.gentle_widening = false;
        report.iterations += first;
    }
    let retries: &[bool] = match (model.options.warm_start, model.options.nt_scaling) {
        (true, true) if warm_is_cold => &[false],
        (true, true) => &[true, false],
        (true, false) | (false, true) => &[false],
        (false, false) => &[],
    };
    let retries = &retries[..retries.len().min(max_retries)];
    let mut acceptable: Option<StepReport> = None;
    let mut iterations = report.iterations;
    for &scaled in retries {
        // (an attempt stalled near convergence ends the solve: `Options::acceptable_iter`)
        let stalled_near = report.status == SolveStatus::Acceptable && ws.stalled_near;
        if report.status == SolveStatus::Converged || stalled_near {
            break;
        }
        if report.status == SolveStatus::Acceptable && acceptable.is_none() {
            ws.w_acceptable.copy_from_slice(&ws.w);
            ws.saturated_acceptable.copy_from_slice(&ws.saturated);
            acceptable = Some(report);
            // first on from the acceptable iterate itself, recentred; cold only if that fails
            report = resume_recentred(model, state, ws);
            iterations += report.iterations;
            let stalled_near = report.status == SolveStatus::Acceptable && ws.stalled_near;
            if report.status == SolveStatus::Converged || stalled_near {
                break;
            }
        }
        restart_cold(model, state, ws);
        ws.attempt = ws.attempt.saturating_add(1);
        ws.nt_disabled = !scaled;
        report = super::ipm::solve(model, state, ws);
        ws.nt_disabled = false;
        iterations += report.iterations;
    }
    if let Some(best) = acceptable.filter(|_| !report.status.is_success()) {
        std::mem::swap(&mut ws.w, &mut ws.w_acceptable);
        // with its friction holds: a candidate held apart (`Hold::Separated`) in the acceptable
        // attempt has `ξ₂:₃ = η₁ = 0` there, outside its slip cone once released (the retries
        // release every such hold), and a singular complementarity block at the gradient point
        ws.saturated.copy_from_slice(&ws.saturated_acceptable);
        // recompute the derived quantities (next poses, residual) of the restored iterate
        evaluate(model, state, ws, false, 0.0);
        report = best;
    }
    report.iterations = iterations;
    report
}

/// Mean complementarity at which [`resume_recentred`] puts an acceptable iterate's pairs back
/// on the central path.
const RECENTRE_KAPPA: f64 = 1e-7;

/// Solve on from an attempt that ended at an acceptable iterate without converging, its
/// complementarity pairs (those of the active candidates and limits whose friction is not held)
/// moved onto the central path at [`RECENTRE_KAPPA`] first ([`super::central::centre_some`]).
///
/// Why: such attempts stall with pairs pressed against their cones' boundaries (the direction
/// cut to ~1e-13 of its length by a cone the pair cannot turn inside), within the acceptable
/// tolerances of the solution; the cold retries that followed threw that iterate away and took
/// 25-30 iterations each, and converged in 1911 of the 4864 such steps of the 250 hull piles
/// (246k of their 1.18M iterations). Recentred, the pairs can turn: hull pile 114's step 126
/// converges in 32 iterations where it ended acceptable after 78, and on the same states the
/// hull piles take 6.8% fewer iterations, the shared robots 0-1.3% fewer; the cold retries stay
/// for the attempts that stall again (BENCHMARKS.md, session 46).
fn resume_recentred(model: &Model, state: &State, ws: &mut Workspace) -> StepReport {
    let nc = model.ncontact();
    let active = ws.active.clone();
    let free: Vec<bool> = ws.saturated.iter().map(Option::is_none).collect();
    let contact = |c: usize| active[c] && free[c];
    let limit = |j: usize| active[nc + j];
    super::central::centre_some(model, state, ws, RECENTRE_KAPPA, contact, limit);
    ws.attempt = ws.attempt.saturating_add(1);
    super::ipm::solve(model, state, ws)
}

fn solve_newton(model: &Model, state: &State, ws: &mut Workspace) -> StepReport {
    let opts = &model.options;
    let mut norm = evaluate(model, state, ws, false, 0.0).r;
    let mut report = StepReport {
        status: SolveStatus::MaxIterations,
        iterations: 0,
        residual: norm,
        complementarity: 0.0,
        subdivisions: 1,
    };
    for it in 0..opts.max_iter {
        if !norm.is_finite() {
            report.status = SolveStatus::NonFinite;
            break;
        }
        if norm <= opts.rtol {
            report.status = SolveStatus::Converged;
            break;
        }
        report.iterations = it + 1;
        assemble(model, ws);
        if ws.matrix.factor(&model.topology.pattern).is_err() {
            report.status = SolveStatus::NonFinite;
            break;
        }
        for (d, r) in ws.delta.iter_mut().zip(ws.residual.iter()) {
            *d = -r;
        }
        ws.matrix.solve_refined(
            &model.topology.pattern,
            &mut ws.delta,
            super::ipm::REFINE_ROUNDS,
            super::ipm::REFINE_ENOUGH,
        );
        let mut alpha = spin_limited_step(model, ws);
        let mut accepted = false;
        for _ in 0..=opts.max_ls {
            for i in 0..ws.w.len() {
                ws.w_trial[i] = ws.w[i] + alpha * ws.delta[i];
            }
            let trial = evaluate(model, state, ws, true, 0.0).r;
            if trial < norm || trial <= opts.rtol {
                std::mem::swap(&mut ws.w, &mut ws.w_trial);
                norm = trial;
                accepted = true;
                break;
            }
            alpha *= 0.5;
        }
        if !accepted {
            norm = evaluate(model, state, ws, false, 0.0).r;
            report.status = SolveStatus::LineSearchFailed;
            break;
        }
        if it + 1 == opts.max_iter && norm <= opts.rtol {
            report.status = SolveStatus::Converged;
        }
    }
    if !report.status.is_success()
        && report.status != SolveStatus::NonFinite
        && norm < opts.acceptable_rtol
    {
        report.status = SolveStatus::Acceptable;
    }
    report.residual = norm;
    report
}

/// Write the solved next state.
pub(crate) fn write_state(model: &Model, state: &mut State, ws: &Workspace) {
    // the winding hinges' turns, from the start's poses (still in `state`) to the next ones
    for (ji, joint) in model.joints.iter().enumerate() {
        if let Some(k) = model.topology.winding_adr[ji] {
            let next = |b: usize| {
                if b == 0 {
                    Pose::world()
                } else {
                    ws.next_pose[b]
                }
            };
            let (p, c) = (next(joint.parent), next(joint.child));
            state.winding[k] = crate::joints::coordinates::turns_after(model, state, ji, &p, &c);
        }
    }
    for b in 1..model.nbody() {
        let p = ws.next_pose[b];
        state.set_pose(
            b,
            &Pose {
                pos: p.pos,
                quat: p.quat.normalize(),
            },
        );
        let (v, w) = w_body(model, &ws.w, b);
        state.set_velocity(b, &v, &w);
    }
    for (ji, joint) in model.joints.iter().enumerate() {
        if let Some(n) = model.topology.joint_node[ji] {
            let (o, adr) = (model.topology.pattern.offset(n), model.topology.con_adr[ji]);
            state.joint_impulse[adr..adr + joint.ncon()]
                .copy_from_slice(&ws.w[o..o + joint.ncon()]);
        }
    }
    if model.topology.has_cones {
        super::inequality::store(model, state, ws);
    }
    state.interval = Some(1.0);
    state.time += model.options.timestep;
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::{BodySpec, JointKind, JointSpec, ModelBuilder};

    /// A model exercising every Jacobian block: chain of revolute, universal, ball, prismatic and
    /// a damped cylindrical joint, with a non-trivial state.
    fn model() -> Model {
        let mut b = ModelBuilder::new().timestep(0.02);
        let kinds = [
            JointKind::Revolute,
            JointKind::Orbital,
            JointKind::Spherical,
            JointKind::Prismatic,
            JointKind::Cylindrical,
            JointKind::Fixed,
        ];
        let q = quat::from_wxyz(&[0.9, 0.1, -0.3, 0.2]).normalize();
        let rot = quat::rotation(&q);
        let mut prev = Vector3::zeros();
        for (i, kind) in kinds.iter().enumerate() {
            let name = format!("b{i}");
            let pos = Vector3::new(0.3 * i as f64, 0.1, -(i as f64) - 0.4);
            b = b.body(
                BodySpec::new(&name, 1.0 + i as f64, [0.1, 0.2, 0.25])
                    .pos(pos.into())
                    .quat(quat::wxyz(&q).into()),
            );
            let parent = if i == 0 {
                "world".to_string()
            } else {
                format!("b{}", i - 1)
            };
            let pa = if i == 0 {
                Vector3::new(0.0, 0.1, 0.5)
            } else {
                Vector3::new(0.15, 0.0, -0.5)
            };
            let world_anchor = if i == 0 { pa } else { prev + rot * pa };
            let ca = rot.transpose() * (world_anchor - pos);
            let mut j = JointSpec::new(&format!("j{i}"), *kind, &parent, &name)
                .axis([0.2, 1.0, 0.3])
                .anchors(pa.into(), ca.into());
            if *kind == JointKind::Cylindrical {
                j = j.damping(0.7);
            }
            if matches!(*kind, JointKind::Revolute | JointKind::Orbital) {
                j.armature = vec![0.4];
            }
            b = b.joint(j);
            prev = pos;
        }
        b.compile().unwrap()
    }

    /// Contacts of every model, a limit and a joint: a box with a limited slider on the floor.
    fn contact_model() -> Model {
        use crate::contact::ContactModel;
        use crate::{GeomSpec, Shape};
        let mut slide = JointSpec::new("slide", JointKind::Prismatic, "box", "puck")
            .axis([1.0, 0.0, 0.0])
            .anchors([0.0, 0.0, 0.1], [0.0; 3]);
        slide.range = Some(vec![(-0.3, 0.4)]);
        ModelBuilder::new()
            .timestep(0.02)
            .geom(GeomSpec::new("floor", "world", Shape::Plane).friction(0.7))
            .body(BodySpec::new("box", 1.0, [0.1, 0.12, 0.15]).pos([0.0, 0.0, 0.1]))
            .joint(JointSpec::new("free", JointKind::Floating, "world", "box"))
            .geom(
                GeomSpec::new(
                    "box",
                    "box",
                    Shape::Box {
                        half_extents: Vector3::new(0.1, 0.1, 0.1),
                    },
                )
                .friction(0.7),
            )
            .body(BodySpec::new("puck", 0.5, [0.01, 0.01, 0.01]).pos([0.0, 0.0, 0.2]))
            .joint(slide)
            .geom(
                GeomSpec::new("p1", "puck", Shape::Sphere { radius: 0.05 })
                    .pos([0.1, 0.0, -0.15])
                    .model(Some(ContactModel::Linear)),
            )
            .geom(
                GeomSpec::new("p2", "puck", Shape::Sphere { radius: 0.05 })
                    .pos([-0.1, 0.0, -0.15])
                    .model(Some(ContactModel::Impact)),
            )
            .compile()
            .unwrap()
    }

    /// Messages name the graph's nodes: bodies, joints, limits and contact candidates.
    #[test]
    fn nodes_are_named_for_messages() {
        let model = contact_model();
        let t = &model.topology;
        assert_eq!(model.node_name(0), "body 'box'");
        assert_eq!(model.node_name(1), "body 'puck'");
        let slide = model.joint_id("slide").unwrap();
        let joint = t.joint_node[slide].unwrap();
        assert_eq!(model.node_name(joint), "joint 'slide'");
        let limits = t.limit_node[slide].unwrap();
        assert_eq!(model.node_name(limits), "the limits of joint 'slide'");
        let c = t.contact_node[0];
        let ct = &model.contacts[0];
        let (a, b) = (&model.geoms[ct.geom_a].name, &model.geoms[ct.geom_b].name);
        assert_eq!(
            model.node_name(c),
            format!("contact candidate 0 ('{a}' / '{b}')")
        );
    }

    #[test]
    fn newton_matrix_with_contacts_and_limits_matches_finite_differences() {
        let model = contact_model();
        assert!(model.topology.has_cones);
        check_newton_matrix(&model, 0.3);
    }

    /// A slide–hinge–slide chain with a tendon limit over joints `terms` (name, coef) and an
    /// optional limit `range` on the hinge.
    fn tendon_model(terms: &[(&str, f64)], range: (f64, f64), hinge_limit: bool) -> Model {
        use crate::model::TendonLimitSpec;
        let mut b = ModelBuilder::new().timestep(0.02);
        let kinds = [
            JointKind::Prismatic,
            JointKind::Revolute,
            JointKind::Prismatic,
        ];
        for (i, kind) in kinds.iter().enumerate() {
            let name = format!("b{i}");
            b = b.body(
                BodySpec::new(&name, 1.0 + 0.3 * i as f64, [0.1, 0.2, 0.15]).pos([
                    0.0,
                    0.0,
                    -0.5 - i as f64,
                ]),
            );
            let parent = if i == 0 {
                "world".into()
            } else {
                format!("b{}", i - 1)
            };
            let z = if i == 0 { 0.0 } else { -0.5 };
            let mut j = JointSpec::new(&format!("j{i}"), *kind, &parent, &name)
                .axis([0.3, 1.0, 0.2 * i as f64])
                .anchors([0.0, 0.0, z], [0.0, 0.0, 0.5]);
            if i == 1 && hinge_limit {
                j.range = Some(vec![range]);
            }
            b = b.joint(j);
        }
        b.add_tendon_limit(TendonLimitSpec {
            name: "t".into(),
            terms: terms.iter().map(|&(j, c)| (j.to_string(), 0, c)).collect(),
            range,
        });
        b.compile().unwrap()
    }

    /// Dry friction on every joint of the tendon model and on a tendon over non-adjacent
    /// joints, with a passive tendon spring and damper: the assembled blocks are the residual's
    /// derivatives.
    #[test]
    fn newton_matrix_with_dry_friction_and_passive_tendons_matches_finite_differences() {
        use crate::model::PassiveTendonSpec;
        let base = tendon_model(&[("j0", 0.5), ("j2", -2.0)], (-0.2, 0.3), false);
        let mut b = ModelBuilder::new().timestep(0.02);
        for (i, body) in base.bodies.iter().enumerate().skip(1) {
            b = b.body(BodySpec::new(&body.name, body.mass, [0.1, 0.2, 0.15]).pos([
                0.0,
                0.0,
                -0.5 - (i - 1) as f64,
            ]));
        }
        let kinds = [
            JointKind::Prismatic,
            JointKind::Revolute,
            JointKind::Prismatic,
        ];
        for (i, kind) in kinds.iter().enumerate() {
            let parent = if i == 0 {
                "world".into()
            } else {
                format!("b{}", i - 1)
            };
            let z = if i == 0 { 0.0 } else { -0.5 };
            b = b.joint(
                JointSpec::new(&format!("j{i}"), *kind, &parent, &format!("b{i}"))
                    .axis([0.3, 1.0, 0.2 * i as f64])
                    .anchors([0.0, 0.0, z], [0.0, 0.0, 0.5])
                    .frictionloss(0.7 + i as f64),
            );
        }
        b.add_passive_tendon(PassiveTendonSpec {
            name: "t".into(),
            terms: vec![("j0".into(), 0, 0.5), ("j2".into(), 0, -2.0)],
            stiffness: 3.0,
            springlength: Some(0.1),
            damping: 2.0,
            frictionloss: 1.5,
        });
        let model = b.compile().unwrap();
        assert_eq!(
            model.variable_counts()[7..],
            [("joint_friction", 12), ("tendon_friction", 4)]
        );
        check_newton_matrix(&model, 0.3);
    }

    #[test]
    fn newton_matrix_with_a_tendon_limit_matches_finite_differences() {
        // slide coordinates: their free-Jacobian rows are exact derivatives everywhere (a
        // hinge angle's are exact on the constraint manifold only, as for joint limits)
        let model = tendon_model(&[("j0", 0.5), ("j2", -2.0)], (-0.2, 0.3), false);
        assert!(model.topology.has_cones);
        assert_eq!(model.topology.tendon_blocks[0].len(), 3);
        check_newton_matrix(&model, 0.3);
    }

    #[test]
    fn a_one_joint_tendon_limit_has_the_rows_of_the_joint_limit() {
        let model = tendon_model(&[("j1", 1.0)], (-0.4, 0.6), true);
        let mut state = crate::State::reference(&model);
        crate::set_minimal(&model, &mut state, &[0.1, 0.5, -0.2], &[0.3, -2.0, 0.7]).unwrap();
        let mut ws = Workspace::new(&model);
        prepare(&model, &state, &mut ws, &[], &AppliedForces::default());
        ws.active[model.ncontact()..].fill(true); // the limit takes part even far from its bounds
        let t = &model.topology;
        let (lim, ten) = (
            t.pattern.offset(t.limit_node[1].unwrap()),
            t.pattern.offset(t.tendon_node[0]),
        );
        for (i, w) in ws.w.iter_mut().enumerate() {
            *w += 0.3 * ((i as f64) * 1.3).cos();
        }
        for i in 0..4 {
            ws.w[lim + i] = 0.5 + 0.2 * i as f64;
            ws.w[ten + i] = ws.w[lim + i];
        }
        evaluate(&model, &state, &mut ws, false, 0.1);
        assemble(&model, &mut ws);
        let n = ws.w.len();
        let col = |j: usize, ws: &Workspace| {
            let mut x = vec![0.0; n];
            x[j] = 1.0;
            let mut ax = vec![0.0; n];
            ws.matrix.matvec(&t.pattern, &x, &mut ax);
            ax
        };
        let close = |a: f64, b: f64| (a - b).abs() <= 1e-14 * (1.0 + a.abs());
        for i in 0..4 {
            assert!(close(ws.residual[lim + i], ws.residual[ten + i]), "row {i}");
            let (cl, ct) = (col(lim + i, &ws), col(ten + i, &ws));
            for r in 0..t.smooth_dim {
                assert!(close(cl[r], ct[r]), "body row {r}, col {i}");
            }
        }
        for j in 0..t.smooth_dim {
            let c = col(j, &ws);
            for i in 0..4 {
                assert!(close(c[lim + i], c[ten + i]), "row {i}, body col {j}");
            }
        }
    }

    /// The central path puts every complementarity pair (contact orthant and cone, joint limit,
    /// tendon limit) at the same κ: a pair with `b ∘ c = κe` has zero rows. (Limit rows were
    /// once shifted twice, so limits sat at 2κ; the humanoid's 42 limit pairs outnumber its
    /// active contacts, so μ stopped falling once σ > 1/2 and its steps stalled.)
    #[test]
    fn every_complementarity_pair_is_centred_at_the_same_kappa() {
        let kappa = 0.3;
        for model in [
            contact_model(),
            tendon_model(&[("j1", 1.0)], (-0.4, 0.6), true),
        ] {
            let state = crate::State::reference(&model);
            let mut ws = Workspace::new(&model);
            prepare(&model, &state, &mut ws, &[], &AppliedForces::default());
            ws.active.fill(true);
            let mut pairs = Vec::new();
            super::super::inequality::for_each_pair(&model, &ws.active, |o, p, d, row, soc| {
                pairs.push((o, p, d, row, if soc { 3 } else { 1 }));
            });
            let kinds = (model.contacts.len(), model.tendon_limits.len());
            assert!(pairs.len() >= 4, "{kinds:?}");
            for &(o, p, d, _, n) in &pairs {
                for i in 0..n {
                    ws.w[o + p + i] = if i == 0 { 2.0 } else { 0.0 };
                    ws.w[o + d + i] = if i == 0 { kappa / 2.0 } else { 0.0 };
                }
            }
            evaluate(&model, &state, &mut ws, false, kappa);
            for &(o, _, _, row, n) in &pairs {
                for i in 0..n {
                    let r = ws.residual[o + row + i];
                    assert!(r.abs() < 1e-15, "{kinds:?}: row {} = {r}", o + row + i);
                }
            }
        }
    }

    /// `recentre` gives what a full evaluation gives, bit for bit: from the kept residual when
    /// the iterate was the last one evaluated, by evaluating again when the iterate changed or
    /// another point (a line-search trial) was evaluated since.
    #[test]
    fn recentre_equals_a_full_evaluation() {
        let model = contact_model();
        let state = crate::State::reference(&model);
        let mut ws = Workspace::new(&model);
        prepare(&model, &state, &mut ws, &[], &AppliedForces::default());
        ws.active.fill(true);
        for (i, w) in ws.w.iter_mut().enumerate() {
            *w += 0.3 * ((i as f64) * 1.3).cos();
            if i >= model.topology.smooth_dim {
                *w = w.abs() + 0.5;
            }
        }
        let kappa = 0.3;
        let bits = |x: &[f64]| x.iter().map(|v| v.to_bits()).collect::<Vec<_>>();
        let full = |ws: &mut Workspace| {
            let v = evaluate(&model, &state, ws, false, kappa);
            (
                bits(&ws.residual),
                v.r.to_bits(),
                v.k.to_bits(),
                ws.next_pose.clone(),
            )
        };
        // the last cases hold a friction cone on its boundary (`super::saturation`): its rows
        // are equalities, which the κ shift must leave alone as `evaluate` does
        let cone = model
            .contacts
            .iter()
            .position(|c| c.model == crate::contact::ContactModel::Nonlinear)
            .expect("a friction cone");
        for case in 0..6 {
            if case == 3 {
                ws.saturated[cone] = Some(super::super::saturation::Hold::Sliding([0.6, 0.8]));
            }
            evaluate_kept(&model, &state, &mut ws, false, 0.0);
            match case % 3 {
                1 => ws.w[2] += 0.1,
                2 => {
                    ws.w_trial.copy_from_slice(&ws.w);
                    ws.w_trial[2] += 0.1;
                    evaluate_kept(&model, &state, &mut ws, true, kappa);
                }
                _ => {}
            }
            let v = recentre(&model, &state, &mut ws, kappa);
            let fast = (
                bits(&ws.residual),
                v.r.to_bits(),
                v.k.to_bits(),
                ws.next_pose.clone(),
            );
            let slow = full(&mut ws);
            assert!(
                fast.0 == slow.0 && fast.1 == slow.1 && fast.2 == slow.2,
                "case {case}"
            );
            let mut poses = fast.3.iter().zip(&slow.3);
            assert!(
                poses.all(|(a, b)| a.pos == b.pos && a.quat == b.quat),
                "case {case}"
            );
        }
    }

    #[test]
    fn newton_matrix_matches_finite_differences_of_the_residual() {
        check_newton_matrix(&model(), 0.0);
    }

    fn check_newton_matrix(model: &Model, kappa: f64) {
        let model = model.clone();
        let mut state = crate::State::reference(&model);
        let qpos = model.qpos0.clone();
        let qvel: Vec<f64> = (0..model.nv)
            .map(|i| (i as f64 * 0.7).sin() * 3.0)
            .collect();
        crate::set_minimal(&model, &mut state, &qpos, &qvel).unwrap();
        let mut ws = Workspace::new(&model);
        prepare(&model, &state, &mut ws, &[], &AppliedForces::default());
        // every joint limit takes part (far ones are left out of a step)
        ws.active[model.ncontact()..].fill(true);
        // move the iterate away from the state so every block is generic
        for (i, w) in ws.w.iter_mut().enumerate() {
            // stay inside the cones: perturb, then keep positive
            *w += 0.3 * ((i as f64) * 1.3).cos();
            if i >= model.topology.smooth_dim {
                *w = w.abs() + 0.5;
            }
        }
        let n = ws.w.len();
        evaluate(&model, &state, &mut ws, false, kappa);
        assemble(&model, &mut ws);
        let base = ws.w.clone();
        let eps = 1e-6;
        // an inactive candidate's rows are neither evaluated nor factored
        let mut live = vec![false; n];
        for_each_live_range(&model, &ws.active, |r| live[r].fill(true));
        for col in (0..n).filter(|&c| live[c]) {
            let mut x = vec![0.0; n];
            x[col] = 1.0;
            let mut ax = vec![0.0; n];
            ws.matrix.matvec(&model.topology.pattern, &x, &mut ax);
            ws.w_trial.copy_from_slice(&base);
            ws.w_trial[col] += eps;
            evaluate(&model, &state, &mut ws, true, kappa);
            let rp = ws.residual.clone();
            ws.w_trial[col] -= 2.0 * eps;
            evaluate(&model, &state, &mut ws, true, kappa);
            for row in (0..n).filter(|&r| live[r]) {
                let fd = (rp[row] - ws.residual[row]) / (2.0 * eps);
                let reg = if row == col && row >= 6 * (model.nbody() - 1) {
                    -model.options.regularization
                } else {
                    0.0
                };
                assert!(
                    (fd - (ax[row] - reg)).abs() < 1e-6 * (1.0 + fd.abs()),
                    "row {row} col {col}: fd {fd} vs {}",
                    ax[row]
                );
            }
        }
    }
}
