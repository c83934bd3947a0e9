//! Saturated friction held on its cone's boundary: a κ = 0 polish of the interior-point solution.
//!
//! On the central path a friction-cone pair satisfies `ξ ∘ η = κe`, so its slip is
//! `η₂:₃ = -κ ξ₂:₃ / det(ξ)`. While the friction is inside its cone that is O(κ) (a box at rest
//! on a 45° incline at μ = 1.05 creeps 5.6e-10 m in 1 s). Where sticking needs the whole cone —
//! the same box at μ = tan 45° — `det(ξ) → 0`, the pair is not strictly complementary, and the
//! slip the solve leaves is O(√κ): the box crept 1.3e-5 m in 1 s at `kappa_tol` 1e-11, shrinking
//! only as √`kappa_tol` (1.6e-6 m at 1e-13), and since a saturated contact has no friction left
//! to stop it, the creep accumulates from step to step.
//!
//! So after a converged solve, each friction cone that is saturated (`|ξ₂:₃| ≥ (1 - 1e-3) ξ₁`)
//! while slipping slowly (`|η₂:₃| < 1e-3 m/s`) is solved again with its cone's complementarity
//! rows replaced by the equalities of the sliding branch at κ = 0 — friction on the boundary,
//! against the slip, and slip speed free:
//!
//! ```text
//! ξ₂:₃ = ξ₁ d,   η₁ = -d · η₂:₃,   d = -η₂:₃ / |η₂:₃|  (then ξ ∘ η = 0 exactly)
//! ```
//!
//! Below a slip of 1e-6 m/s the direction is undetermined (a stick exactly on the boundary), and
//! `d` is held at the direction of the friction the interior-point solve found. Every other
//! pair, the held contacts' normal pairs `γ s = κ` included, stays on the central path at the
//! solve's final centring `kappa_tol / undercut` (holding the gap at 0 too makes the four
//! corners of a flat box a redundant set of constraints). The polished solution is kept only if
//! it converges to the solver's tolerances, every held contact still pushes (`γ > 0`) and slips
//! against its friction (`η₁ ≥ -1e-8 m/s`, no slip across `d`); otherwise the interior-point
//! solution stands. (A box set down exactly touching a 45° incline at μ = tan 45° lifts off to
//! the central path's gap `κ/γ` in its first step, which tilts it and moves its corners up the
//! slope by ~6.5e-9 m/s at the default `kappa_tol`, 6.5e-7 at 1e-9: the polish holds there only
//! at the default tolerances and tighter.)
//!
//! The gradients (`kappa_grad = None`) linearise the polished solution with these rows: the
//! exact derivative of a contact sliding at the limit (its friction turns with the slip, a
//! lateral stiffness `ξ₁ (I - ddᵀ) / |η₂:₃|`), and a one-sided derivative at a stick on the
//! boundary (free along the friction, unresisted across it). The interior-point solution's own
//! derivative differs by the κ-softness of its cone, O(κ/slip²): 2e-4 relative for a box
//! sliding at 1e-4 m/s. Only friction cones that are saturated and nearly still pay for the
//! polish; the pyramid (`Linear`) model is not polished.
use super::inequality::SOC;
use super::ipm::{fractions_to_boundary, line_search, load_residual, solve_negated};
use super::newton::{assemble, evaluate};
use crate::contact::ContactModel;
use crate::model::Model;
use crate::state::{State, Workspace};

/// A cone counts as saturated when its friction is within this fraction of `μγ`.
const SATURATION: f64 = 1e-3;
/// Largest slip speed (m/s) of a contact that is polished.
const SLIP_MAX: f64 = 1e-3;
/// Slip (m/s) along the friction, or across it, that a held contact may show.
const SLIP_TOL: f64 = 1e-8;
/// Below this slip speed (m/s) a held friction keeps its direction instead of opposing the slip.
const SLIP_FLOOR: f64 = 1e-6;
/// Newton iterations of the polish; its rows are linear in the cone variables, so one or two
/// suffice where the polish is right.
const MAX_ITER: usize = 6;

/// A friction cone taken out of the interior-point iteration, its complementarity rows
/// `ξ ∘ η = κe` replaced by equalities.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) enum Hold {
    /// Saturated friction on the cone's boundary, against the slip or along this unit
    /// direction (contact tangent frame) below [`SLIP_FLOOR`]: `ξ₂:₃ = ξ₁ d`, `η₁ = -d · η₂:₃`
    /// (the polish and the rescue, see the module docs).
    Sliding([f64; 2]),
    /// No friction, `ξ₂:₃ = 0` and `η₁ = 0`: a contact between bodies that can only slide
    /// along its normal relative to each other, which cannot slip
    /// ([`crate::contact::slide_pair`]). Held for the whole step, and in the gradients'
    /// central-path solves.
    Frictionless,
    /// No friction while the gap stays open: a candidate at least [`SEPARATED_GAP`] apart
    /// when the step starts, until its gap slack falls below that ([`hold_separated`]).
    Separated,
}

/// Gap (m) above which an active candidate's friction is held at zero during a hard solve
/// ([`hold_separated`]), and below which the hold is released.
pub(crate) const SEPARATED_GAP: f64 = 1e-3;

/// Hold the friction of every active candidate that cannot slip at zero ([`Hold::Frictionless`],
/// setting `ξ₂:₃ = η₁ = 0` in the iterate), and release any such hold of a candidate that can
/// slip again (its feature changed). Called whenever a solve starts its iterate.
///
/// Of the candidates that cannot slip between the same two bodies with the same normal, only
/// the tightest (smallest gap) takes part; the others are left out of the step
/// (`Workspace::shadowed`). Why: the two bodies only translate along the normal relative to
/// each other, so each such candidate's gap is the same function of that translation shifted
/// by a constant, and the tightest one implies the rest; their normal impulses are collinear
/// pairs, so where they push does not move anything. Kept, they are a family of equal
/// solutions (the Panda's pressed pads: up to 160 candidates on one relative coordinate).
pub(crate) fn hold_frictionless(model: &Model, ws: &mut Workspace) {
    let t = &model.topology;
    if !model.options.drop_redundant_friction {
        for &c in &t.slide_candidates {
            if ws.saturated[c] == Some(Hold::Frictionless) {
                ws.saturated[c] = None;
            }
        }
        return;
    }
    // (body pair, normal along the slide axis from the first body's side) → tightest candidate
    let mut tightest: Vec<((usize, usize, bool), usize)> = Vec::new();
    for &c in &t.slide_candidates {
        // a candidate shadowed earlier in the step stands again unless still implied
        let pool = ws.active[c] || ws.shadowed[c];
        ws.active[c] = pool;
        ws.shadowed[c] = false;
        let contact = &model.contacts[c];
        let along = contact.normal_along_slide(ws.frozen[c]).filter(|_| pool);
        let Some(along) = along else {
            if ws.saturated[c] == Some(Hold::Frictionless) {
                ws.saturated[c] = None;
            }
            continue;
        };
        hold_without_friction(model, ws, c, Hold::Frictionless);
        let [a, b] = t.contact_bodies[c];
        let key = (a.min(b), a.max(b), (along > 0.0) == (a < b));
        match tightest.iter_mut().find(|(k, _)| *k == key) {
            Some((_, best)) if ws.contact_phi_now[c] < ws.contact_phi_now[*best] => {
                shadow(ws, *best);
                *best = c;
            }
            Some(_) => shadow(ws, c),
            None => tightest.push((key, c)),
        }
    }
}

/// Hold candidate `c` with no friction (`hold`: [`Hold::Frictionless`] or
/// [`Hold::Separated`]), its iterate set on the held rows: `ξ₂:₃ = 0`, `η₁ = 0`.
fn hold_without_friction(model: &Model, ws: &mut Workspace, c: usize, hold: Hold) {
    let t = &model.topology;
    ws.saturated[c] = Some(hold);
    let o = t.pattern.offset(t.contact_node[c]);
    ws.w[o + SOC.0 + 1] = 0.0;
    ws.w[o + SOC.0 + 2] = 0.0;
    ws.w[o + SOC.1] = 0.0;
}

/// Leave candidate `c` out of the step: a tighter one implies it ([`hold_frictionless`]).
fn shadow(ws: &mut Workspace, c: usize) {
    ws.active[c] = false;
    ws.shadowed[c] = true;
    ws.saturated[c] = None;
}

/// Hold the friction of every active friction-cone candidate that is at least
/// [`SEPARATED_GAP`] apart at the step's start at zero ([`Hold::Separated`]: `ξ₂:₃ = 0`,
/// `η₁ = 0` set in the iterate); returns how many. Released by [`release_closing`] as soon
/// as an iterate's gap slack comes within [`SEPARATED_GAP`], so at the solution every held
/// candidate is apart, where its friction is zero (up to the central path's `O(κ)`).
///
/// Why: such a candidate (activated because it may come within reach during the step) has
/// no friction at the solution, but its cone pair still takes part in the iteration: its
/// slip member sits on its cone's boundary at the tangential velocity, and when the velocity
/// turns, the pair, its impulse member ~1e-6, cuts the step (humanoid, Table V step 100: four
/// such candidates cut the first iterations to α = 7e-4…0.2). Measured with `option_ab`
/// (same states) in BENCHMARKS "Session 24".
pub(crate) fn hold_separated(model: &Model, ws: &mut Workspace) -> usize {
    let mut held = 0;
    for (c, contact) in model.contacts.iter().enumerate() {
        if !ws.active[c]
            || ws.saturated[c].is_some()
            || contact.model != ContactModel::Nonlinear
            || ws.contact_phi_now[c].is_nan()
            || ws.contact_phi_now[c] <= SEPARATED_GAP
        {
            continue;
        }
        hold_without_friction(model, ws, c, Hold::Separated);
        held += 1;
    }
    held
}

/// Release the [`Hold::Separated`] candidates whose gap slack `s` fell below
/// [`SEPARATED_GAP`], their cone pairs moved onto the central path at `kappa`
/// ([`super::central::centre_some`]); returns how many.
pub(crate) fn release_closing(
    model: &Model,
    state: &State,
    ws: &mut Workspace,
    kappa: f64,
) -> usize {
    let t = &model.topology;
    let mut closing = std::mem::take(&mut ws.blocking);
    closing.fill(false);
    let mut released = 0;
    for (c, close) in closing.iter_mut().enumerate().take(model.ncontact()) {
        if ws.saturated[c] != Some(Hold::Separated) {
            continue;
        }
        if ws.w[t.pattern.offset(t.contact_node[c]) + 1] < SEPARATED_GAP {
            ws.saturated[c] = None;
            *close = true;
            released += 1;
        }
    }
    if released > 0 {
        super::central::centre_some(model, state, ws, kappa, |c| closing[c], |_| false);
    }
    ws.blocking = closing;
    released
}

/// Release every [`Hold::Separated`] candidate (their iterate values are left as they are).
pub(crate) fn release_separated(ws: &mut Workspace) {
    for held in &mut ws.saturated {
        if *held == Some(Hold::Separated) {
            *held = None;
        }
    }
}

/// Release the sliding holds, keeping the frictionless ones.
pub(crate) fn release_sliding(ws: &mut Workspace) {
    for held in &mut ws.saturated {
        if matches!(held, Some(Hold::Sliding(_))) {
            *held = None;
        }
    }
}

/// Polish the converged solution in `ws` (see the module docs); returns the iterations spent.
/// On return `ws.saturated` marks the contacts held on their cone's boundary (none when the
/// polish was not needed or not kept).
pub(crate) fn polish(model: &Model, state: &State, ws: &mut Workspace) -> usize {
    hold(model, state, ws, SLIP_MAX).0
}

/// A solve that failed, retried from its last iterate with every saturated friction cone held on
/// the sliding branch (any slip speed): a cone sliding at the limit is strictly complementary at
/// κ = 0, where its held rows are well conditioned, while the interior-point iterates can stall
/// next to it (random scene 225's step 51 stalled at every subdivision and converges with it;
/// scenes 351, 762 and 955, whose stalls also leave a sliding cone's complementarity at
/// 1e-7..1e-5, stall in their other pairs too and are not rescued). Returns the iterations spent
/// and whether the held solution converged and is consistent (then it is in `ws`; else `ws` is
/// as before).
pub(crate) fn rescue(model: &Model, state: &State, ws: &mut Workspace) -> (usize, bool) {
    let (iterations, kept) = hold(model, state, ws, f64::INFINITY);
    if kept {
        // no converged interior-point solution to keep the held friction impulses of
        // (`inequality::store`): the held ones are stored
        ws.w_acceptable.copy_from_slice(&ws.w);
    }
    (iterations, kept)
}

fn hold(model: &Model, state: &State, ws: &mut Workspace, slip_max: f64) -> (usize, bool) {
    if !select(model, ws, slip_max) {
        return (0, false);
    }
    ws.w_acceptable.copy_from_slice(&ws.w);
    let o = &model.options;
    let p = &model.topology.pattern;
    let kappa = o.kappa_tol / o.undercut;
    let mut vio = evaluate(model, state, ws, false, 0.0);
    let mut iterations = 0;
    let mut converged = false;
    loop {
        if vio.r < o.rtol && vio.k < o.kappa_tol {
            converged = true;
            break;
        }
        if iterations == MAX_ITER {
            break;
        }
        iterations += 1;
        evaluate(model, state, ws, false, kappa);
        let merit = super::newton::live_norm2(model, &ws.active, &ws.residual);
        load_residual(model, &ws.active, &ws.residual, &mut ws.delta, 1.0);
        assemble(model, ws);
        if ws.matrix.factor(p).is_err() {
            break;
        }
        solve_negated(model, ws, p);
        let accepted = line_search(
            model,
            state,
            ws,
            kappa,
            merit,
            fractions_to_boundary(model, vio),
        );
        vio = evaluate(model, state, ws, false, 0.0);
        if accepted.is_none() {
            break;
        }
    }
    let kept = converged && consistent(model, ws);
    if !kept {
        std::mem::swap(&mut ws.w, &mut ws.w_acceptable);
        release_sliding(ws);
        // the derived quantities (next poses, residual) of the restored solution
        evaluate(model, state, ws, false, 0.0);
    }
    (iterations, kept)
}

/// Mark the saturated, slowly slipping friction cones; whether there is any.
fn select(model: &Model, ws: &mut Workspace, slip_max: f64) -> bool {
    let t = &model.topology;
    let mut any = false;
    for (c, contact) in model.contacts.iter().enumerate() {
        if matches!(ws.saturated[c], Some(Hold::Frictionless | Hold::Separated)) {
            continue;
        }
        ws.saturated[c] = None;
        if !ws.active[c] || contact.model != ContactModel::Nonlinear {
            continue;
        }
        let o = t.pattern.offset(t.contact_node[c]);
        let (xi, eta) = (
            &ws.w[o + SOC.0..o + SOC.0 + 3],
            &ws.w[o + SOC.1..o + SOC.1 + 3],
        );
        let friction = xi[1].hypot(xi[2]);
        if xi[0] > 0.0 && friction >= (1.0 - SATURATION) * xi[0] && eta[1].hypot(eta[2]) < slip_max
        {
            ws.saturated[c] = Some(Hold::Sliding([xi[1] / friction, xi[2] / friction]));
            any = true;
        }
    }
    any
}

/// Whether every held contact pushes (`γ > 0`) and slips against its friction direction `d`
/// (`η₂:₃ = -η₁ d` with `η₁ ≥ 0`), to [`SLIP_TOL`] (the velocities are solved to `rtol`, their
/// slip is meaningful far below this).
fn consistent(model: &Model, ws: &Workspace) -> bool {
    let t = &model.topology;
    ws.saturated.iter().enumerate().all(|(c, held)| {
        let Some(Hold::Sliding(held)) = *held else {
            return true;
        };
        let o = t.pattern.offset(t.contact_node[c]);
        let (speed, slip) = (ws.w[o + SOC.1], [ws.w[o + SOC.1 + 1], ws.w[o + SOC.1 + 2]]);
        let (d, _) = direction(held, slip);
        let across = (slip[0] + speed * d[0]).hypot(slip[1] + speed * d[1]);
        ws.w[o] > 0.0 && speed >= -SLIP_TOL && across <= SLIP_TOL + SATURATION * speed.abs()
    })
}

/// The direction a held friction acts along at `slip` (contact tangent frame): against the slip
/// when it is faster than [`SLIP_FLOOR`], else the `held` one; with the rate `1/|slip|` at which
/// it turns with the slip (0 when held).
pub(crate) fn direction(held: [f64; 2], slip: [f64; 2]) -> ([f64; 2], f64) {
    let speed = slip[0].hypot(slip[1]);
    if speed > SLIP_FLOOR {
        ([-slip[0] / speed, -slip[1] / speed], 1.0 / speed)
    } else {
        (held, 0.0)
    }
}
