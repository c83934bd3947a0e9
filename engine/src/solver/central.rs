//! The central-path point at κ of a solved step: the interior solution of the relaxed problem
//! (each complementarity pair the step activated at `b ∘ c = κ w e`, `w` its contact
//! candidate's or limit's taper weight, [`super::taper`]), the smoothed step of the gradients
//! (`kappa_grad`). Started either from the step's hard solution moved onto the κ
//! central path pair by pair and solved by Newton's method at κ ([`Start::Hard`], [`follow`]),
//! or from the neutral interior point by the predictor-corrector of [`super::ipm`] with
//! centring floored at κ ([`Start::Neutral`], the fallback).
//!
//! NOTE: the hard solution itself is a poor start: its pairs sit at `b ∘ c ≈ κ_tol` on the
//! cones' boundaries, where Newton's method hugs the boundary. Moving each pair to product κ
//! first puts the iterate well inside, at the impulse and velocity scale of the step, while
//! the neutral point (γ = s = 1 on hundreds of candidates) is far from both.
use nalgebra::Vector3;

use super::inequality::{
    add_mehrotra_correction, cone_search, for_each_owned_pair, mean_complementarity,
    scale_soc_rows, update_scalings,
};
use super::ipm;
use super::newton::{Violation, assemble, evaluate};
use crate::contact::ContactModel;
use crate::contact::cone::{orthant_step, soc_step};
use crate::model::Model;
use crate::state::{IterationRecord, SolveStatus, State, StepReport, Workspace};

/// Where the central-path solve starts.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum Start {
    /// The hard solution in `ws.w` with each pair moved to product κ ([`centre`]).
    Hard,
    /// The neutral point γ = s = 1, ξ = η = e; body velocities and joint impulses as in `ws.w`.
    Neutral,
}

/// Fraction of the friction cone that a kept friction impulse may fill: `|ξ₂:₃| ≤ (1 - ε) ξ₁`.
/// A friction impulse at the cone's rim with no slip has no centred partner (the slip speed
/// `κ|ξ₂:₃| / det ξ` blows up); ε bounds the start's slip at `~κ / (2ε μγ)`.
const FRICTION_RIM: f64 = 0.1;

/// [`follow`] gives up (`LineSearchFailed`, so that the caller can restart from the neutral
/// point) after `STALL_COUNT` consecutive steps shorter than `STALL_STEP`: an iterate that has
/// drifted next to a cone's boundary, where the line search only creeps (humanoid, κ = 1e-4:
/// eight steps below 1e-3 before the line search failed outright).
const STALL_STEP: f64 = 1e-2;
const STALL_COUNT: usize = 3;

/// Fraction to the boundary of [`follow`] while the centred residual is above `NEAR`.
///
/// NOTE: the interior-point loop's fraction `1 - ‖r‖²` lets a step go 99.9% of the way to a
/// cone's boundary at a residual of 0.03; from a start on the κ path that is too greedy: a pair
/// left next to its boundary makes every later Newton direction useless for the merit (box
/// pushed at 10 N, κ = 1e-4: steps of α < 1e-3, then the fallback). Measured over 30 steps at
/// κ = 1e-4 (`gradient_phases`): panda 11 fallbacks, gymnasium humanoid 1 without the cap;
/// with 0.9 (or 0.8) none, panda 10 iterations per solve instead of 28.
const TAU_FAR: f64 = 0.9;
const NEAR: f64 = 1e-6;

/// Solve for the central-path point at `kappa` of the prepared, solved step in `ws` from
/// `start`, over the contact candidates and limits the step's solve activated (those within
/// reach of touching; the others keep no impulse, as in the hard step) and the candidates whose
/// taper weight is above its floor ([`join_weighted`]), each candidate's and joint limit's κ
/// weighted by [`super::taper`]; or over every one at κ with `Options::smooth_every_candidate`.
///
/// Why not every candidate: each pair held at `b ∘ c = κ` pushes with `κ / gap` however far
/// it is, and on the shared robots every candidate joining cost the gradient 6-27× the hard
/// one (371-1024 candidates in the central-path solve, the partials and the
/// back-substitution). The Panda's fingertip pads, 400 corner candidates ~1 cm apart, moved its
/// smoothed velocities 2.6 rad/s off the simulated ones at κ = 3e-4, 0.31 with the activated
/// ones alone; the humanoid's and the A1's come from their activated candidates (0.99 and 2.0
/// either way). With κ alike on every activated candidate, the smoothed map then changed where
/// a candidate came within reach, by its `κ / gap` there (~1 cm): 0.03 N·s at κ = 3e-4; the
/// taper of κ with the distance ([`super::taper`]) makes it continuous.
pub(crate) fn solve(
    model: &Model,
    state: &State,
    ws: &mut Workspace,
    kappa: f64,
    start: Start,
) -> StepReport {
    let every = model.options.smooth_every_candidate;
    if every {
        ws.active.fill(true);
    }
    ws.kappa_taper = !every;
    if ws.kappa_taper {
        join_weighted(model, ws);
    }
    super::saturation::release_sliding(ws);
    super::saturation::release_separated(ws);
    match start {
        Start::Hard => {
            super::activation::ensure_prepared(model, state, ws);
            super::saturation::hold_frictionless(model, ws);
            centre(model, state, ws, kappa);
            follow(model, state, ws, kappa)
        }
        Start::Neutral => {
            super::inequality::initialize(model, state, ws, false);
            ipm::solve_to(model, state, ws, Some(kappa))
        }
    }
}

/// Activate every prepared candidate whose κ weight is above the floor ([`super::taper`]): those
/// within reach that the hard step's activation left out as above their corner group's lowest
/// ([`super::activation::activate`]). Their weight then rises from the floor inside the step,
/// not at the corner rule's boundary. An unprepared candidate is farther than its reach.
fn join_weighted(model: &Model, ws: &mut Workspace) {
    for c in 0..model.ncontact() {
        if !ws.active[c] && ws.prepared[c] {
            let w = super::taper::weight_and_slopes(
                model,
                c,
                ws.contact_phi_now[c],
                ws.contact_rate_now[c],
            )[0];
            ws.active[c] = w > super::taper::WEIGHT_FLOOR;
        }
    }
}

/// Newton's method on the centred residual `r(w, κ)` from a centred start (the friction cones'
/// rows Nesterov–Todd scaled, as in the interior-point loop), with the second-order term of the
/// complementarity rows: Mehrotra's corrector built on the Newton direction at κ itself, not on
/// an affine direction aiming at 0, which would make the iteration converge only linearly to a
/// point off the path's target. Converged when `‖r(w, κ)‖∞ < rtol`, the criterion of
/// [`ipm::solve_to`].
fn follow(model: &Model, state: &State, ws: &mut Workspace, kappa: f64) -> StepReport {
    let o = &model.options;
    let p = &model.topology.pattern;
    ws.nt.fill(None);
    let mut report = StepReport {
        status: SolveStatus::MaxIterations,
        iterations: 0,
        residual: f64::NAN,
        complementarity: kappa,
        subdivisions: 1,
    };
    let mut short_steps = 0;
    for it in 0..o.max_iter {
        let vio = evaluate(model, state, ws, false, kappa);
        let centred = ipm::centred_norm(model, ws);
        report.residual = centred;
        if !(vio.r.is_finite() && vio.k.is_finite() && centred.is_finite()) {
            report.status = SolveStatus::NonFinite;
            break;
        }
        if centred < o.rtol {
            report.status = SolveStatus::Converged;
            break;
        }
        report.iterations = it + 1;
        let mu = mean_complementarity(model, &ws.active, &ws.w, &ws.delta, 0.0);
        ws.nt_on = o.nt_scaling && !ws.nt_disabled && mu > ipm::NT_MU_FLOOR;
        if ws.nt_on {
            update_scalings(model, ws);
            scale_soc_rows(model, ws, false, kappa);
        } else {
            ws.nt.fill(None);
        }
        assemble(model, ws);
        if ws.matrix.factor(p).is_err() {
            report.status = SolveStatus::NonFinite;
            break;
        }
        let merit = super::newton::live_norm2(model, &ws.active, &ws.residual);
        // Newton direction Δ_n = -R⁻¹ r(w, κ), then the corrector -R⁻¹ (r + Δb_n ∘ Δc_n)
        ipm::load_residual(model, &ws.active, &ws.residual, &mut ws.delta_aff, -1.0);
        ws.matrix
            .solve_refined(p, &mut ws.delta_aff, ipm::REFINE_ROUNDS, ipm::REFINE_ENOUGH);
        ipm::load_residual(model, &ws.active, &ws.residual, &mut ws.delta, 1.0);
        add_mehrotra_correction(model, ws);
        ipm::solve_negated(model, ws, p);
        let worst = Violation { r: centred, k: 0.0 };
        let mut taus = ipm::fractions_to_boundary(model, worst);
        if centred > NEAR {
            taus = (taus.0.min(TAU_FAR), taus.1.min(TAU_FAR));
        }
        let mut corrector = true;
        let accepted = match ipm::line_search(model, state, ws, kappa, merit, taus) {
            Some(a) => Some(a),
            None => {
                corrector = false;
                ws.delta.copy_from_slice(&ws.delta_aff);
                ipm::line_search(model, state, ws, kappa, merit, taus)
            }
        };
        if let Some(trace) = ws.trace.as_mut() {
            trace.push(IterationRecord {
                attempt: ws.attempt,
                residual: vio.r,
                complementarity: vio.k,
                mu,
                kappa,
                alpha_aff: cone_search(
                    model,
                    &ws.active,
                    &ws.saturated,
                    &ws.w,
                    &ws.delta_aff,
                    1.0,
                    1.0,
                ),
                alpha: accepted.unwrap_or(0.0),
                corrector,
                condition: f64::NAN,
            });
        }
        short_steps = match accepted {
            Some(a) if a < STALL_STEP => short_steps + 1,
            _ => 0,
        };
        if accepted.is_none() || short_steps == STALL_COUNT {
            evaluate(model, state, ws, false, kappa);
            report.residual = ipm::centred_norm(model, ws);
            report.status = SolveStatus::LineSearchFailed;
            break;
        }
    }
    if report.status == SolveStatus::MaxIterations {
        evaluate(model, state, ws, false, kappa);
        report.residual = ipm::centred_norm(model, ws);
    }
    ws.nt_on = false;
    report
}

/// Move every complementarity pair of the iterate in `ws.w` to product κ, strictly interior,
/// keeping of each pair the member that the step determines (the impulse of a touching contact,
/// the gap of a separated one) and raising the other: `b' = b, c' = κ / b` for the larger.
/// Gaps, tangential velocities and limit distances are read from the residual rows at the
/// current velocities, so candidates that the hard step left inactive start at their distance.
pub(crate) fn centre(model: &Model, state: &State, ws: &mut Workspace, kappa: f64) {
    centre_some(model, state, ws, kappa, |_| true, |_| true);
}

/// [`centre`] for the contact candidates `c` with `contact(c)` and the limited joints `j` with
/// `limit(j)` only; the other pairs keep their values.
pub(crate) fn centre_some(
    model: &Model,
    state: &State,
    ws: &mut Workspace,
    kappa: f64,
    contact_selected: impl Fn(usize) -> bool,
    limit_selected: impl Fn(usize) -> bool,
) {
    // rows `s - φ`, `η₂:₃ - v_t`, ... at the hard velocities (independent of κ)
    evaluate(model, state, ws, false, 0.0);
    let t = &model.topology;
    for (c, contact) in model.contacts.iter().enumerate() {
        if !contact_selected(c) {
            continue;
        }
        // (an inactive candidate's gap at the start may be a bound, `activation::prepare`)
        let start = super::taper::at_start!(ws).filter(|_| ws.active[c]);
        let kappa = kappa * super::taper::weight(model, start, c, 0, 0);
        let o = t.pattern.offset(t.contact_node[c]);
        let dim = contact.model.dim();
        let (x, r) = (&mut ws.w[o..o + dim], &ws.residual[o..o + dim]);
        let phi = x[1] - r[0];
        let (gamma, gap) = orthant_pair(x[0], phi, kappa);
        x[0] = gamma;
        x[1] = gap;
        match contact.model {
            ContactModel::Impact => {}
            ContactModel::Nonlinear => {
                let slip = [x[6] - r[6], x[7] - r[7]];
                let (xi, eta) = friction_pair(contact.friction * gamma, [x[3], x[4]], slip, kappa);
                x[2..5].copy_from_slice(xi.as_slice());
                x[5..8].copy_from_slice(eta.as_slice());
            }
            ContactModel::Linear => {
                // (ψ, s_ψ) and (β_i, η_i) with the slacks their equality rows imply
                let implied_s_psi = x[3] - r[1];
                (x[2], x[3]) = orthant_pair(x[2], implied_s_psi, kappa);
                for i in 0..4 {
                    let implied_eta = x[8 + i] - r[2 + i];
                    (x[4 + i], x[8 + i]) = orthant_pair(x[4 + i], implied_eta, kappa);
                }
            }
        }
    }
    for (j, joint) in model.joints.iter().enumerate() {
        let Some(n) = t.limit_node[j] else { continue };
        if !limit_selected(j) {
            continue;
        }
        let o = t.pattern.offset(n);
        let owner = model.ncontact() + j;
        for i in 0..joint.limits.len() {
            let b = o + 4 * i;
            for (g, s) in [(b, b + 1), (b + 2, b + 3)] {
                // row `s - distance`
                let distance = ws.w[s] - ws.residual[s - 1];
                let start = super::taper::at_start!(ws).filter(|_| ws.active[owner]);
                let kappa = kappa * super::taper::weight(model, start, owner, b, g - b);
                (ws.w[g], ws.w[s]) = orthant_pair(ws.w[g], distance, kappa);
            }
        }
    }
    // dry joint friction: each side's displacement and its room to the bound (the equality rows
    // `s_fw + s_bw = 2 f h` and `δ_fw - δ_bw = h θ̇⁺` are left to the Newton steps at κ)
    for n in t.friction_nodes() {
        let o = t.pattern.offset(n);
        for i in 0..t.pattern.dim(n) / 4 {
            for (g, s) in [(o + 4 * i, o + 4 * i + 1), (o + 4 * i + 2, o + 4 * i + 3)] {
                (ws.w[g], ws.w[s]) = orthant_pair(ws.w[g], ws.w[s], kappa);
            }
        }
    }
}

/// Move the complementarity pairs that block the direction `ws.delta` onto the κ central path
/// ([`centre`]): those of every active contact candidate and limited joint whose cones the
/// direction leaves within `BLOCKING` times the shortest such step. Returns how many nodes moved
/// (0 when the direction leaves no cone).
///
/// Why: a pair whose members both sit next to their cones' boundaries cannot turn within a
/// step; a contact whose slip must change direction then stalls the iteration (random stress
/// scene 955 step 94: a nearly sticking contact, slip speed 5e-5 m/s, whose slip and friction
/// must turn by ~100°, cut every step to 1e-4 of the Newton step for 40 iterations). On the
/// central path at the current mean complementarity, the pair is inside both cones by
/// `O(κ / |b|)` and can turn.
pub(crate) fn unblock(model: &Model, state: &State, ws: &mut Workspace, kappa: f64) -> usize {
    const BLOCKING: f64 = 10.0;
    // each pair's step along `ws.delta` to its cones' boundary, twice: the shortest, then the
    // owners of the pairs within BLOCKING times it
    let reach = |w: &[f64], d: &[f64], o: usize, p: usize, q: usize, soc: bool| {
        if soc {
            let v = |x: &[f64], i: usize| Vector3::new(x[i], x[i + 1], x[i + 2]);
            soc_step(&v(w, o + p), &v(d, o + p), 1.0).min(soc_step(&v(w, o + q), &v(d, o + q), 1.0))
        } else {
            orthant_step(&[w[o + p], w[o + q]], &[d[o + p], d[o + q]], 1.0)
        }
    };
    let mut shortest: f64 = f64::INFINITY;
    let (w, d) = (&ws.w, &ws.delta);
    // (the contacts' and the joint limits' pairs: tendon limits are not moved)
    let unblocked = model.ncontact() + model.njoint();
    for_each_owned_pair(
        model,
        &ws.active,
        &ws.saturated,
        |owner, o, p, q, _, soc| {
            if owner < unblocked {
                shortest = shortest.min(reach(w, d, o, p, q, soc));
            }
        },
    );
    if shortest.is_nan() || shortest >= 1.0 {
        return 0;
    }
    let mut blocking = std::mem::take(&mut ws.blocking);
    blocking.fill(false);
    for_each_owned_pair(
        model,
        &ws.active,
        &ws.saturated,
        |owner, o, p, q, _, soc| {
            if owner < unblocked {
                blocking[owner] |= reach(w, d, o, p, q, soc) <= BLOCKING * shortest;
            }
        },
    );
    let count = blocking.iter().filter(|&&b| b).count();
    let nc = model.ncontact();
    centre_some(
        model,
        state,
        ws,
        kappa,
        |c| blocking[c],
        |j| blocking[nc + j],
    );
    ws.blocking = blocking;
    count
}

/// An orthant pair `(b, c)` moved to `b c = κ`: the larger of the two is kept and the other
/// raised to κ over it (a negative `c`, a penetration, counts as 0). Neither usable: both √κ.
fn orthant_pair(b: f64, c: f64, kappa: f64) -> (f64, f64) {
    if !(b.is_finite() && c.is_finite()) || b.max(c) <= 0.0 {
        let r = kappa.sqrt();
        return (r, r);
    }
    let (b, c) = (b.max(0.0), c.max(0.0));
    if b >= c {
        (b, kappa / b)
    } else {
        (kappa / c, c)
    }
}

/// A friction-cone pair `(ξ, η)` on the κ central path with `ξ₁ = a = μγ`, given the step's
/// friction impulse `friction` (ξ₂:₃) and slip velocity `slip` (η₂:₃).
///
/// The centred pairs with `ξ₁ = a` are a one-parameter family: `ξ = (a, -p d)`,
/// `η = (q, u d)` with `d` a unit direction, `u = κ p / (a² - p²)`, `q = κ a / (a² - p²)`
/// (`ξ ∘ η = κ e`). Keeping the friction magnitude (`p = |ξ₂:₃|`, a sticking contact) or the
/// slip speed (`u = |v_t|`, a sliding one) each fixes `p`; the larger `p` is taken (both
/// friction and slip at least their hard values, as [`orthant_pair`] raises the smaller).
fn friction_pair(
    a: f64,
    friction: [f64; 2],
    slip: [f64; 2],
    kappa: f64,
) -> (Vector3<f64>, Vector3<f64>) {
    let (f, v) = (friction[0].hypot(friction[1]), slip[0].hypot(slip[1]));
    if !(a > 0.0 && a.is_finite() && f.is_finite() && v.is_finite()) {
        let r = kappa.sqrt();
        return (Vector3::new(r, 0.0, 0.0), Vector3::new(r, 0.0, 0.0));
    }
    let p_stick = f.min((1.0 - FRICTION_RIM) * a);
    // root of v p² + κ p - v a² = 0 in [0, a), in the form without cancellation
    let p_slide = 2.0 * v * a * a / (kappa + (kappa * kappa + 4.0 * v * v * a * a).sqrt());
    let (p, d) = if p_slide >= p_stick && v > 0.0 {
        (p_slide, [slip[0] / v, slip[1] / v])
    } else if f > 0.0 {
        (p_stick, [-friction[0] / f, -friction[1] / f])
    } else {
        (0.0, [0.0, 0.0])
    };
    let det = (a - p) * (a + p);
    let (u, q) = (kappa * p / det, kappa * a / det);
    (
        Vector3::new(a, -p * d[0], -p * d[1]),
        Vector3::new(q, u * d[0], u * d[1]),
    )
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::contact::cone::{soc_det, soc_product};

    #[test]
    fn friction_pairs_are_centred_and_interior() {
        let kappa = 1e-4;
        let cases = [
            // sticking, sliding, at the rim without slip, separated, at rest
            (0.02, [0.005, -0.003], [1e-11, 0.0]),
            (0.02, [-0.02, 0.0], [0.3, 0.0]),
            (0.02, [0.0, 0.02], [0.0, 0.0]),
            (1e-7, [0.0, 0.0], [0.1, -0.2]),
            (0.5, [0.0, 0.0], [0.0, 0.0]),
        ];
        for (a, f, v) in cases {
            let (xi, eta) = friction_pair(a, f, v, kappa);
            let prod = soc_product(&xi, &eta);
            assert!(
                (prod - Vector3::new(kappa, 0.0, 0.0)).norm() < 1e-12,
                "{prod}"
            );
            assert!(soc_det(&xi) > 0.0 && soc_det(&eta) > 0.0);
            assert_eq!(xi[0], a);
            // friction and slip are at least their hard values (up to the rim margin)
            let (fn_, vn) = (xi.fixed_rows::<2>(1).norm(), eta.fixed_rows::<2>(1).norm());
            let f0 = f[0].hypot(f[1]).min((1.0 - FRICTION_RIM) * a);
            assert!(fn_ >= f0 * (1.0 - 1e-12) || vn >= v[0].hypot(v[1]) * (1.0 - 1e-12));
        }
        // sliding keeps the slip speed and opposes it
        let (xi, eta) = friction_pair(0.02, [-0.02, 0.0], [0.3, 0.0], kappa);
        assert!((eta[1] - 0.3).abs() < 1e-12 && eta[2] == 0.0);
        assert!(xi[1] < 0.0 && xi[1].abs() > 0.99 * 0.02);
    }

    #[test]
    fn orthant_pairs_keep_the_larger_member() {
        let kappa = 1e-4;
        assert_eq!(orthant_pair(0.025, 4e-10, kappa), (0.025, kappa / 0.025));
        assert_eq!(orthant_pair(1e-10, 0.1, kappa), (kappa / 0.1, 0.1));
        assert_eq!(orthant_pair(0.0, -1e-3, kappa), (1e-2, 1e-2));
        assert_eq!(orthant_pair(f64::NAN, 0.1, kappa), (1e-2, 1e-2));
    }

    /// `unblock` moves exactly the candidates whose cones stop the direction (within 10x the
    /// shortest step to a boundary) onto the central path at κ, and leaves every other pair
    /// and the velocities alone.
    #[test]
    fn unblock_centres_the_blocking_cones_only() {
        // (the exact cones: the default contact model)
        let model = crate::gradients::test_scenes::box_on_floor(0.01, 0.8);
        let state = State::reference(&model);
        let mut ws = Workspace::new(&model);
        crate::solver::newton::prepare(&model, &state, &mut ws, &[], &Default::default());
        ws.active.fill(true);
        let t = &model.topology;
        let offset = |c: usize| t.pattern.offset(t.contact_node[c]);
        // every pair well inside; candidate 1's friction pair next to its boundaries
        for c in 0..model.ncontact() {
            let o = offset(c);
            ws.w[o..o + 8].copy_from_slice(&[0.2, 0.3, 0.16, 0.05, 0.0, 0.4, 0.1, 0.0]);
        }
        let o1 = offset(1);
        ws.w[o1 + 2..o1 + 8].copy_from_slice(&[0.16, 0.16 - 1e-9, 0.0, 0.01, -0.01 + 1e-9, 0.0]);
        // a direction that turns candidate 1's friction and slip (and moves the rest a little)
        ws.delta.fill(0.0);
        for c in 0..model.ncontact() {
            ws.delta[offset(c)] = -0.01;
        }
        ws.delta[o1 + 4] = 0.1;
        ws.delta[o1 + 7] = 0.1;
        let before = ws.w.clone();
        let kappa = 1e-6;
        assert_eq!(unblock(&model, &state, &mut ws, kappa), 1);
        for c in 0..model.ncontact() {
            let o = offset(c);
            if c == 1 {
                let (xi, eta) = (
                    Vector3::new(ws.w[o + 2], ws.w[o + 3], ws.w[o + 4]),
                    Vector3::new(ws.w[o + 5], ws.w[o + 6], ws.w[o + 7]),
                );
                let prod = soc_product(&xi, &eta);
                assert!(
                    (prod - Vector3::new(kappa, 0.0, 0.0)).norm() < 1e-12,
                    "{prod}"
                );
                assert!(soc_det(&xi) > 0.0 && soc_det(&eta) > 0.0);
                assert!((xi[0] - 0.8 * ws.w[o]).abs() < 1e-15, "ξ₁ = μγ");
                assert!((ws.w[o] * ws.w[o + 1] - kappa).abs() < 1e-15);
            } else {
                assert_eq!(ws.w[o..o + 8], before[o..o + 8], "candidate {c}");
            }
        }
        assert_eq!(ws.w[..t.smooth_dim], before[..t.smooth_dim]);
        // a direction that leaves no cone: nothing moves
        ws.delta.fill(0.0);
        let kept = ws.w.clone();
        assert_eq!(unblock(&model, &state, &mut ws, kappa), 0);
        assert_eq!(ws.w, kept);
    }
}
