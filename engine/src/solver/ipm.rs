//! Primal-dual interior-point solve of a step with contacts or joint limits: Mehrotra's
//! predictor-corrector as Dojo's Algorithm 2.
//!
//! Each iteration factors the Newton matrix once and back-substitutes twice: the affine
//! (predictor) direction aims at κ = 0; the cone line search (Algorithm 1) measures how far it
//! can go; centering picks `κ = max(σμ, κ_tol/undercut)` with `σ = (μ_aff/μ)³` (eqs. 51-54); the
//! corrector direction targets κ with Mehrotra's second-order term `Δb_aff ∘ Δc_aff`. The step is
//! cut to a fraction τ of the distance to the cone boundary and to the angular-speed domain, then
//! backtracked until the centred residual `‖r(w, κ)‖` decreases. Convergence is judged by the
//! violation metrics of eqs. 49-50. When the line search fails, or three steps in a row are
//! shorter than 1e-3, the cones that block the direction are moved onto the central path at
//! the current mean complementarity ([`super::central::unblock`]; at most five times a solve)
//! and the iteration goes on from there. An acceptable iterate that stalls near the tight
//! tolerances ends the solve as `Acceptable` (`Options::acceptable_iter`).
//! The unknowns are velocities, so every iterate's orientation `q ⊗ f(ω⁺)` is exactly unit
//! (the quaternion-aware update of eq. 48 holds by construction).
use super::inequality::{
    add_mehrotra_correction, cone_search, mean_complementarity, scale_soc_rows, update_scalings,
};
use super::newton::{
    Violation, assemble, evaluate, evaluate_kept, for_each_live_range, live_inf_norm, live_norm2,
    recentre, spin_limited_step,
};
use crate::model::Model;
use crate::state::{IterationRecord, SolveStatus, State, StepReport, Workspace};

/// Below this mean complementarity the friction cones' Newton rows go back to the unscaled
/// linearisation of `ξ ∘ η = κe`. Nesterov–Todd scaling keeps the iterates centred while μ is
/// large (the humanoid and A1 drops stop failing), but its scaling point is computed from
/// `ξ₁ - |ξ₂:₃|`, which loses relative accuracy as pairs approach their boundary; the exact
/// Newton step converges fast in that endgame. Measured on the 14-sphere pyramid, 500 steps:
/// 20 unconverged with scaling throughout, 12 with this floor, 117 unscaled.
pub(crate) const NT_MU_FLOOR: f64 = 1e-8;

/// Iterative-refinement rounds of the corrected (and plain) Newton directions (see
/// `BlockMatrix::solve_refined`); the predictor is not refined (see `solve_to`).
pub(crate) const REFINE_ROUNDS: usize = 2;

/// A direction whose linear residual is within `REFINE_ENOUGH` of the right-hand side (max
/// norms) is not refined further. Most first solves are already there (the humanoid's: 80% at
/// or below 1e-10) and a third of a step went into refining them further to 1e-15.
/// `step_bench`, seeds 5..12 × 300 steps, always refining → this: humanoid 4.05 → 2.89
/// ms/step, A1 3.86 → 2.66, X2 0.11 → 0.07, iterations per step unchanged (21.4 → 20.9,
/// 16.9 → 17.0, 4.0); stress scenes unchanged (701 alone fails). 1e-12 and 1e-14 gave the
/// same iterations on the robots (Panda within its run-to-run chaos), 1e-8 and 1e-6 saved
/// little more.
pub(crate) const REFINE_ENOUGH: f64 = 1e-10;

/// The corrected direction is refined only once the iterate's residual or complementarity is
/// below this: far from the solution the line search and the next iterations correct a
/// direction's error of the conditioning's size, and checking a first solve's residual cost a
/// mat-vec every iteration. Same states (`option_ab MODEL 300 SEED` with a temporary switch):
/// the humanoid and A1 (seed 5) the same 5050 and 4215 iterations, 0.319 → 0.306 and 0.236 →
/// 0.230 s; Panda seeds 5/10/11 2753 → 2752, 1931 → 1931, 2534 → 2406 iterations, 0.621 →
/// 0.587, 0.314 → 0.295, 0.821 → 0.584 s.
pub(crate) const REFINE_BELOW: f64 = 1e-6;

/// Moves of blocking cones onto the central path per solve ([`super::central::unblock`]), made
/// when the line search fails or `SHORT_COUNT` consecutive steps are shorter than `SHORT_STEP`.
const MAX_UNBLOCKS: usize = 5;
const SHORT_COUNT: usize = 3;
const SHORT_STEP: f64 = 1e-3;

/// A warm start whose first affine step is cut below `WIDEN_BELOW` of its length is pushed
/// inside its cones by `Options::warm_start_widening` (impulses: γ, ξ) and `WIDEN_SLACK` (gaps
/// and slip slacks: s, η) before the first Newton step ([`super::inequality::widen`]).
///
/// Why: the warm start sits on the previous solution's cone boundaries (`warm_start_margin`
/// 1e-6 inside), and when contacts change state the first 5-10 steps were cut to a few percent
/// (A1 step 51: α = 0.001-0.06 for 10 iterations). Measured, `step_bench` 8 seeds × 300 steps:
/// humanoid 31.4 → 21.4 iterations per step, A1 25.4 → 16.9, Panda 19.8 → 20.4. Widening every
/// warm start instead made resting contacts jitter (a sphere at rest at dt 0.001: 9e-7 m/s,
/// its solves ending at different points of the `kappa_tol` band), and the widening alone,
/// before the blocking cones were moved to the central path ([`super::central::unblock`]),
/// failed 22 Panda steps in 12 runs.
///
/// The impulses' widening was 1e-3 until session 29; 1e-2 saves iterations where contacts
/// change state, measured on the same states (`option_ab MODEL 300 SEED warm_start_widening
/// 1e-3 1e-2`), 8 seeds × 300 steps: humanoid 38315 → 35701 iterations (1.89 → 1.80 s), A1
/// 29343 → 27610 (1.35 → 1.27 s), Panda 14057 → 13206 (0.98 → 0.73 s); Table V's 1000 steps:
/// humanoid −9%, A1 −10%, Panda and X2 ±1%. 1e-1 saved the humanoid more and cost the Panda
/// up to twice its time. A widened first attempt that fails is solved again widened by
/// `WIDEN_IMPULSE_GENTLE` (`newton::solve_active`): the humanoid's wedged limb
/// (`tests/hard_steps.rs`, seed 2 step 143) converges in 18 iterations from 1e-3 and failed
/// every attempt from 1e-2.
///
/// Session 31: the widening also scales with the robot, `max(warm_start_widening,
/// warm_start_widening_weight · Σ m g h)` ([`widening`]): a fixed 0.3 N·s saved the robots
/// 2-14% of their iterations and cost the random stress scenes (~3 kg, whose impulses are
/// ~10× smaller) 7.6%; relative to the weight impulse at 0.1, on the same states (`option_ab
/// MODEL 1000 SEED warm_start_widening_weight 0 0.1`, seeds 1-10): humanoid 144752 → 131520
/// iterations (−9.1%), A1 115860 → 106047 (−8.5%), Panda 59480 → 56183 (−5.5%), X2 45324 →
/// 45414; Table V's controls −8.3%, −9.3%, −0.7%, −0.7%; the 1000 stress scenes × 300 steps
/// 684673 → 696649 (+1.7%), none failing.
///
/// Session 38: the second predictor too, when the first did not widen. A first step that went
/// far (the Panda's pad struck into the floor, `step_bench panda.xml 1000 1` step 149: α =
/// 0.79) can leave the pairs of a contact changing state next to their boundaries with the
/// residual still large (0.39 against μ = 9e-6), and the iterations after it crawled at α ~
/// 1e-2 until the stall test. Same states (`option_ab MODEL 1000 SEED` with a temporary
/// switch), iterations: Panda seeds 1-3 −4.7%, −4.7%, −6.5%; A1 seeds 1-5 −4.9%, −5.6%,
/// −2.3%, −4.8%, −3.6%; humanoid seeds 1-3 −0.1% each; X2 seeds 1-2 0%, +0.8%. The third
/// predictor as well changed nothing more (Panda, A1, X2 seeds 1-2: within 0.2%).
const WIDEN_BELOW: f64 = 0.5;

/// The impulse widening of a blocked warm start (see [`WIDEN_BELOW`]).
pub(crate) fn widening(model: &Model) -> f64 {
    let o = &model.options;
    o.warm_start_widening
        .max(o.warm_start_widening_weight * model.weight_impulse())
}
pub(crate) const WIDEN_IMPULSE_GENTLE: f64 = 1e-3;
const WIDEN_SLACK: f64 = 1e-2;

/// A hard solve that reaches `max_iter` with its equality residual below `ENDGAME_RESIDUAL`
/// goes on for up to `Options::endgame_iter` more iterations: it is in the endgame, where a
/// complementarity stall (residual ~1e-6, complementarity ~1e-3, corrector steps of ~1e-2)
/// often ends by itself, while a failed attempt costs the cold retries, the wider activations
/// and the subdivisions. The shared humanoid's first Table V step from `squat` converges in 67
/// iterations; stopped at 50 it took 1124 (8 sub-steps). Measured, `ukemi.step` over 6 × 300
/// random-control steps (numpy seeds 10..15), iterations per step, 0 → 150 extra iterations:
/// Panda 20.3 → 15.2 (one unconverged step → none), humanoid 22.1 → 21.7, A1 15.6 → 15.6; 50
/// or 350 extra, or a residual bound of 1e-3, gave Panda 13.6–16.4 and humanoid 21.9–23.0.
pub(crate) const ENDGAME_RESIDUAL: f64 = 1e-4;

/// How near the tight tolerances (`max(r / rtol, k / kappa_tol)`) an acceptable iterate must
/// be for a stall there to end the solve (`Options::acceptable_iter`). The stalls that
/// motivated it sat at 3.5 (Panda, `step_bench` seed 12, step 261) and 8.7 (the rolling ball
/// of `engine/tests/rolling.rs` in a trial build). Without this bound, only the acceptable
/// tolerances, the early stop also cut an A1 step (`option_ab a1.xml 300 8`, step 75) that
/// converges in 39 iterations at 20, with k = 9.4e-9 and its next positions 2.2e-5 m off.
const STALL_NEAR: f64 = 100.0;

/// Largest fraction to the boundary.
const TAU_CAP: f64 = 1.0 - 1e-6;

/// Run the interior-point method from the prepared iterate.
pub(crate) fn solve(model: &Model, state: &State, ws: &mut Workspace) -> StepReport {
    solve_to(model, state, ws, None)
}

/// Largest entry of the centred residual `r(w, κ)` left in `ws.residual` by `evaluate`.
pub(crate) fn centred_norm(model: &Model, ws: &Workspace) -> f64 {
    live_inf_norm(model, &ws.active, &ws.residual)
}

/// The interior-point loop. `central = None` drives complementarity to `kappa_tol` (the hard
/// step); `Some(κ)` stops on the central path at κ: centering never targets below κ, and the
/// solve has converged when the centred residual `r(w, κ)` is below `rtol`.
pub(crate) fn solve_to(
    model: &Model,
    state: &State,
    ws: &mut Workspace,
    central: Option<f64>,
) -> StepReport {
    let o = &model.options;
    let p = &model.topology.pattern;
    let floor = central.unwrap_or(o.kappa_tol / o.undercut);
    if central.is_none() {
        ws.kappa_taper = false;
    }
    ws.nt.fill(None);
    ws.widened = false;
    // (this solve's only: a retry of it starts cold)
    let resumed = std::mem::take(&mut ws.resumed);
    // friction of candidates apart, held at zero while they stay apart (hard solves only: the
    // central path gives every candidate its friction)
    super::saturation::release_separated(ws);
    let separated = central.is_none()
        && o.drop_redundant_friction
        && ws.first_attempt()
        && super::saturation::hold_separated(model, ws) > 0;
    let mut vio = evaluate_kept(model, state, ws, false, 0.0);
    let mut report = StepReport {
        status: SolveStatus::MaxIterations,
        iterations: 0,
        residual: vio.r,
        complementarity: vio.k,
        subdivisions: 1,
    };
    let (mut unblocked, mut short, mut acceptable_run) = (0, 0, 0);
    let mut window_start = f64::INFINITY;
    let (mut checkpoint, mut checkpoint_at) = (f64::INFINITY, 0);
    ws.stalled_near = false;
    for it in 0..o.max_iter + o.endgame_iter {
        if !(vio.r.is_finite() && vio.k.is_finite()) {
            report.status = SolveStatus::NonFinite;
            break;
        }
        if it >= o.max_iter && !(central.is_none() && vio.r < ENDGAME_RESIDUAL) {
            break;
        }
        let done = match central {
            None => vio.r < o.rtol && vio.k < o.kappa_tol,
            Some(k) => {
                recentre(model, state, ws, k);
                let c = centred_norm(model, ws);
                recentre(model, state, ws, 0.0);
                c < o.rtol
            }
        };
        if done && separated && super::saturation::release_closing(model, state, ws, floor) > 0 {
            // a held candidate closed in the last step: not a solution of the whole problem
            vio = evaluate_kept(model, state, ws, false, 0.0);
            continue;
        }
        if done {
            report.status = SolveStatus::Converged;
            break;
        }
        // an acceptable iterate within `STALL_NEAR` of the tight tolerances for
        // `Options::acceptable_iter` iterations in a row, over which its worst violation
        // relative to them did not halve, has stalled there
        let acceptable = vio.r < o.acceptable_rtol && vio.k < o.acceptable_kappa_tol;
        let progress = (vio.r / o.rtol).max(vio.k / o.kappa_tol);
        acceptable_run = if central.is_none() && acceptable && progress < STALL_NEAR {
            acceptable_run + 1
        } else {
            0
        };
        if acceptable_run == 1 {
            window_start = progress;
        }
        if o.acceptable_iter > 0 && acceptable_run > o.acceptable_iter {
            if progress > 0.5 * window_start {
                report.status = SolveStatus::Acceptable;
                ws.stalled_near = true;
                break;
            }
            acceptable_run = 1;
            window_start = progress;
        }
        // an attempt whose worst violation has not fallen tenfold in `Options::stall_iter`
        // iterations has stalled: the next retry (or sub-steps) does better than its budget
        if progress < 0.1 * checkpoint {
            (checkpoint, checkpoint_at) = (progress, it);
        }
        if o.stall_iter > 0
            && central.is_none()
            && !ws.every_candidate
            && it >= checkpoint_at + o.stall_iter
        {
            break;
        }
        report.iterations = it + 1;
        // a warm start that the first predictor cannot leave far: pushed further inside (a
        // whole step's turning slide cuts that predictor: widened without computing it)
        let widen_now = it == 0
            && ws.first_attempt()
            && central.is_none()
            && o.warm_start
            && !ws.substep
            && super::inequality::turning_on_boundaries(model, ws);
        if widen_now {
            widen_warm_start(model, ws);
            vio = evaluate_kept(model, state, ws, false, 0.0);
            continue;
        }
        let mu0 = mean_complementarity(model, &ws.active, &ws.w, &ws.delta_aff, 0.0)
            + ws.far.mean(model, 0.0);
        ws.nt_on = o.nt_scaling && !ws.nt_disabled && mu0 > NT_MU_FLOOR;
        // (hard solves only: a central-path solve's matrix is the gradients' `R̄`)
        ws.proximal = match central {
            None => o.friction_proximal * mu0,
            Some(_) => 0.0,
        };
        if ws.nt_on {
            update_scalings(model, ws);
            scale_soc_rows(model, ws, false, 0.0);
        } else {
            ws.nt.fill(None);
        }
        assemble(model, ws);
        let condition = if ws.trace_condition {
            condition_number(ws, p)
        } else {
            f64::NAN
        };
        // far from the solution no direction is refined (see `REFINE_BELOW`; the plain
        // direction after a failed line search neither): no copy of the matrix to refine with
        let refine = vio.r <= REFINE_BELOW || vio.k <= REFINE_BELOW;
        if ws.matrix.factor_keeping(p, refine).is_err() {
            report.status = SolveStatus::NonFinite;
            break;
        }
        // predictor: Δ_aff = -R⁻¹ r(w, 0)  (ws.residual holds r(w, 0))
        load_residual(model, &ws.active, &ws.residual, &mut ws.delta_aff, -1.0);
        // (not refined: the predictor only sets α_aff, σ and the second-order term; skipping its
        // residual product saved 5.4% of the A1's instructions at the same 14.22 iterations per
        // step, `step_bench` seed 5, and left the stress suite unchanged)
        ws.matrix.solve(p, &mut ws.delta_aff);
        let act = &ws.active;
        let alpha_aff = cone_search(model, act, &ws.saturated, &ws.w, &ws.delta_aff, 1.0, 1.0);
        // (the first two predictors: a first step that went far can leave the pairs of a
        // contact changing state on their boundaries, where the second predictor is cut)
        if it <= 1
            && !ws.widened
            && (ws.first_attempt() || resumed)
            && central.is_none()
            && o.warm_start
            && alpha_aff < WIDEN_BELOW
        {
            widen_warm_start(model, ws);
            vio = evaluate_kept(model, state, ws, false, 0.0);
            continue;
        }
        let mu =
            mean_complementarity(model, act, &ws.w, &ws.delta_aff, 0.0) + ws.far.mean(model, 0.0);
        let mu_aff = mean_complementarity(model, act, &ws.w, &ws.delta_aff, alpha_aff)
            + ws.far.mean(model, alpha_aff);
        let sigma = (mu_aff / mu).clamp(0.0, 1.0).powi(3);
        let kappa = (sigma * mu).max(floor);
        // corrector: Δ = -R⁻¹ (r(w, κ) + Δb_aff ∘ Δc_aff), reusing the factorisation
        recentre(model, state, ws, kappa);
        scale_soc_rows(model, ws, false, kappa);
        let merit = live_norm2(model, &ws.active, &ws.residual);
        load_residual(model, &ws.active, &ws.residual, &mut ws.delta, 1.0);
        add_mehrotra_correction(model, ws);
        if !refine {
            let delta = &mut ws.delta;
            for_each_live_range(model, &ws.active, |r| {
                delta[r].iter_mut().for_each(|d| *d = -*d)
            });
            ws.matrix.solve(p, &mut ws.delta);
        } else {
            solve_negated(model, ws, p);
        }
        let taus = fractions_to_boundary(model, vio);
        let mut corrector = true;
        let accepted = match line_search(model, state, ws, kappa, merit, taus) {
            Some(a) => Some(a),
            None => {
                // the second-order term can spoil descent far from the central path: fall back to
                // the plain Newton direction of r(w, κ), a descent direction of its norm
                corrector = false;
                recentre(model, state, ws, kappa);
                scale_soc_rows(model, ws, false, kappa);
                load_residual(model, &ws.active, &ws.residual, &mut ws.delta, 1.0);
                solve_negated(model, ws, p);
                line_search(model, state, ws, kappa, merit, taus)
            }
        };
        if let Some(trace) = ws.trace.as_mut() {
            trace.push(IterationRecord {
                attempt: ws.attempt,
                residual: vio.r,
                complementarity: vio.k,
                mu,
                kappa,
                alpha_aff,
                alpha: accepted.unwrap_or(0.0),
                corrector,
                condition,
            });
        }
        if let Some(a) = accepted {
            ws.far.advance(a, kappa);
        }
        // (the line search evaluated an accepted iterate last: no evaluation then)
        vio = recentre(model, state, ws, 0.0);
        if separated && super::saturation::release_closing(model, state, ws, mu.max(floor)) > 0 {
            vio = evaluate_kept(model, state, ws, false, 0.0);
        }
        // a run of short steps (or none) behind blocking cones: move those onto the central path
        short = if accepted.is_none_or(|a| a < SHORT_STEP) {
            short + 1
        } else {
            0
        };
        let stuck = accepted.is_none() || short >= SHORT_COUNT;
        let acceptable = vio.r < o.acceptable_rtol && vio.k < o.acceptable_kappa_tol;
        if stuck
            && central.is_none()
            && !acceptable
            && unblocked < MAX_UNBLOCKS
            && super::central::unblock(model, state, ws, mu.max(floor)) > 0
        {
            unblocked += 1;
            short = 0;
            vio = evaluate_kept(model, state, ws, false, 0.0);
            continue;
        }
        if accepted.is_none() {
            report.status = SolveStatus::LineSearchFailed;
            break;
        }
        // (the last iteration of the budget, whichever it is, is judged here)
        if it + 1 >= o.max_iter && central.is_none() && vio.r < o.rtol && vio.k < o.kappa_tol {
            report.status = SolveStatus::Converged;
        }
    }
    ws.nt_on = false;
    ws.proximal = 0.0;
    let stalled = matches!(
        report.status,
        SolveStatus::LineSearchFailed | SolveStatus::MaxIterations
    );
    if central.is_none() && stalled && vio.r < o.acceptable_rtol && vio.k < o.acceptable_kappa_tol {
        report.status = SolveStatus::Acceptable;
    }
    report.residual = vio.r;
    report.complementarity = vio.k;
    if let Some(k) = central {
        evaluate(model, state, ws, false, k);
        report.residual = centred_norm(model, ws);
        report.complementarity = k;
    }
    report
}

/// Push the warm start inside its cones (see [`WIDEN_BELOW`]; gently on the retry of a
/// widened first attempt that failed).
fn widen_warm_start(model: &Model, ws: &mut Workspace) {
    let impulse = if ws.gentle_widening {
        WIDEN_IMPULSE_GENTLE.min(widening(model))
    } else {
        widening(model)
    };
    super::inequality::widen(model, ws, impulse, WIDEN_SLACK);
    ws.widened = true;
}

/// `Δ ← -R⁻¹ Δ` with the current factorisation.
pub(crate) fn solve_negated(
    model: &Model,
    ws: &mut Workspace,
    p: &crate::solver::graph_ldu::BlockPattern,
) {
    let delta = &mut ws.delta;
    for_each_live_range(model, &ws.active, |r| {
        delta[r].iter_mut().for_each(|d| *d = -*d)
    });
    ws.matrix
        .solve_refined(p, &mut ws.delta, REFINE_ROUNDS, REFINE_ENOUGH);
}

/// `dst = sign · residual` on the live rows: the rows of inactive candidates are neither
/// solved for nor stepped along ([`line_search`]).
pub(crate) fn load_residual(
    model: &Model,
    active: &[bool],
    residual: &[f64],
    dst: &mut [f64],
    sign: f64,
) {
    for_each_live_range(model, active, |r| {
        for (d, x) in dst[r.clone()].iter_mut().zip(&residual[r]) {
            *d = sign * x;
        }
    });
}

/// Fractions to the boundary `(τ_ort, τ_soc)`: τ → 1 as the violations vanish (superlinear
/// endgame), capped below 1 so rounding never lands an iterate on a cone's boundary; the
/// second-order cones keep the τ_max cap until the iterate is within 1e-4 of converging.
pub(crate) fn fractions_to_boundary(model: &Model, vio: Violation) -> (f64, f64) {
    let o = &model.options;
    let worst = vio.r.max(vio.k);
    let tau_ort = o.tau_min.max(1.0 - worst.powi(2)).min(TAU_CAP);
    let tau_soc = if worst < 1e-4 {
        tau_ort
    } else {
        o.tau_max.min(tau_ort)
    };
    (tau_ort, tau_soc)
}

/// 2-norm condition number of the assembled (not yet factored) Newton matrix on its live rows,
/// from a dense copy. The rows and columns of the candidates left out of the solve are the
/// identity's, decoupled from the rest (`BlockMatrix::set_skipped`): they are left out, so
/// that a robot's hundreds of far candidates neither hide the solve's conditioning nor make
/// the dense SVD thousands of rows wide (the shared humanoid's 371 candidates: ~3000).
fn condition_number(ws: &Workspace, p: &crate::solver::graph_ldu::BlockPattern) -> f64 {
    let live: Vec<usize> = (0..p.nnodes())
        .filter(|&n| !ws.matrix.is_skipped(n))
        .flat_map(|n| p.offset(n)..p.offset(n) + p.dim(n))
        .collect();
    let (n, m) = (ws.w.len(), live.len());
    let mut dense = nalgebra::DMatrix::zeros(m, m);
    let (mut e, mut col) = (vec![0.0; n], vec![0.0; n]);
    for (j, &c) in live.iter().enumerate() {
        e[c] = 1.0;
        ws.matrix.matvec(p, &e, &mut col);
        e[c] = 0.0;
        for (i, &r) in live.iter().enumerate() {
            dense[(i, j)] = col[r];
        }
    }
    let sv = dense.singular_values();
    sv.max() / sv.min()
}

/// Step along `ws.delta` from the largest cone-feasible length, halving until the centred
/// residual `‖r(w, κ)‖₂` decreases (Armijo); the accepted trial becomes the iterate; returns
/// the step length.
///
/// NOTE: Dojo accepts a step when either violation (eqs. 49-50) decreases. That let a box
/// tipping onto a corner cycle forever (complementarity rising while the equality residual sat
/// at round-off); the centred residual is the quantity the Newton step actually decreases.
pub(crate) fn line_search(
    model: &Model,
    state: &State,
    ws: &mut Workspace,
    kappa: f64,
    merit: f64,
    (tau_ort, tau_soc): (f64, f64),
) -> Option<f64> {
    let mut alpha = cone_search(
        model,
        &ws.active,
        &ws.saturated,
        &ws.w,
        &ws.delta,
        tau_ort,
        tau_soc,
    )
    .min(spin_limited_step(model, ws));
    if alpha < 1e-14 {
        // an iterate on a cone's boundary (round-off): no step can help
        return None;
    }
    // only the live rows move: an inactive candidate's variables stay at their start in `w`
    // (its rows of `w_trial`, `delta` and the residual are never read during the solve)
    for _ in 0..=model.options.max_ls {
        let (w, trial, delta) = (&ws.w, &mut ws.w_trial, &ws.delta);
        for_each_live_range(model, &ws.active, |r| {
            for i in r {
                trial[i] = w[i] + alpha * delta[i];
            }
        });
        evaluate_kept(model, state, ws, true, kappa);
        scale_soc_rows(model, ws, true, kappa);
        if live_norm2(model, &ws.active, &ws.residual) <= (1.0 - 1e-4 * alpha) * merit {
            let (w, trial) = (&mut ws.w, &ws.w_trial);
            for_each_live_range(model, &ws.active, |r| {
                w[r.clone()].copy_from_slice(&trial[r])
            });
            return Some(alpha);
        }
        alpha *= 0.5;
    }
    None
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::{BodySpec, GeomSpec, JointKind, JointSpec, ModelBuilder, Shape};

    /// One interior-point attempt of a ball landing at 3 m/s while sliding, with `max_iter`,
    /// `endgame_iter` as given: its report. (It starts 0.5 mm above the floor, within
    /// `saturation::SEPARATED_GAP`, so its friction takes part from the first iteration.)
    fn landing(max_iter: usize, endgame_iter: usize) -> StepReport {
        let model = ModelBuilder::new()
            .timestep(0.01)
            .geom(GeomSpec::new("floor", "world", Shape::Plane).friction(0.8))
            .body(BodySpec::new("ball", 1.0, [0.004; 3]).pos([0.0, 0.0, 0.1005]))
            .joint(JointSpec::new("free", JointKind::Floating, "world", "ball"))
            .geom(GeomSpec::new("ball", "ball", Shape::Sphere { radius: 0.1 }))
            .compile()
            .unwrap();
        let model = model
            .with_options(crate::Options {
                max_iter,
                endgame_iter,
                ..model.options.clone()
            })
            .unwrap();
        let mut state = State::reference(&model);
        let v = nalgebra::Vector3::new(1.0, 0.0, -3.0);
        state.set_velocity(1, &v, &nalgebra::Vector3::zeros());
        let mut ws = Workspace::new(&model);
        crate::solver::newton::prepare(&model, &state, &mut ws, &[], &Default::default());
        solve(&model, &state, &mut ws)
    }

    /// An attempt that reaches `max_iter` in its endgame (equality residual below
    /// `ENDGAME_RESIDUAL`) goes on to converge within `endgame_iter` more iterations;
    /// `endgame_iter = 0` keeps `max_iter` a hard cap.
    #[test]
    fn an_attempt_in_its_endgame_may_pass_max_iter() {
        let full = landing(500, 0);
        assert!(full.status.is_success(), "{full:?}");
        let n = full.iterations;
        let cut = landing(n - 2, 0);
        assert_eq!(cut.status, SolveStatus::MaxIterations, "{cut:?}");
        assert_eq!(cut.iterations, n - 2);
        assert!(
            cut.residual < ENDGAME_RESIDUAL,
            "not in the endgame: {cut:?}"
        );
        let extended = landing(n - 2, 150);
        assert!(extended.status.is_success(), "{extended:?}");
        assert_eq!(extended.iterations, n);
        // far from it, the cap holds
        let early = landing(1, 150);
        assert!(
            early.residual >= ENDGAME_RESIDUAL && early.iterations == 1,
            "{early:?}"
        );
    }

    /// A box sliding and spinning on the floor (its corners' slip turns every step): the
    /// second step's warm start has its corners' cones sliding on their boundaries while the
    /// step turns their slip (`inequality::turning_on_boundaries`), and widening it without the
    /// first predictor lands on the same iterate, bit for bit and in as many iterations, as the
    /// predictor's test does (a sub-step takes that test). A box at rest, or sliding straight
    /// (its slip only slows, and the predictor is not cut), has no such cone.
    #[test]
    fn a_turning_slide_is_widened_as_its_cut_predictor_would_widen_it() {
        let model = crate::gradients::test_scenes::box_on_floor(0.01, 0.5);
        // the second step's workspace, prepared and evaluated at its warm start
        let second = |v: [f64; 3], w: [f64; 3]| {
            let mut state = State::reference(&model);
            let v = nalgebra::Vector3::from(v);
            state.set_velocity(1, &v, &nalgebra::Vector3::from(w));
            crate::step(&model, &mut state, &mut Workspace::new(&model), &[]).unwrap();
            let mut ws = Workspace::new(&model);
            crate::solver::newton::prepare(&model, &state, &mut ws, &[], &Default::default());
            crate::solver::newton::evaluate(&model, &state, &mut ws, false, 0.0);
            let turning = super::super::inequality::turning_on_boundaries(&model, &ws);
            (state, ws, turning)
        };
        assert!(!second([0.0; 3], [0.0; 3]).2);
        let (state, mut straight, turning) = second([1.0, 0.0, 0.0], [0.0; 3]);
        assert!(!turning);
        assert!(solve(&model, &state, &mut straight).status.is_success());
        assert!(!straight.widened);
        let (state, mut fast, turning) = second([1.0, 0.0, 0.0], [0.0, 0.0, 3.0]);
        assert!(turning);
        let (_, mut tested, _) = second([1.0, 0.0, 0.0], [0.0, 0.0, 3.0]);
        tested.substep = true;
        let (a, b) = (
            solve(&model, &state, &mut fast),
            solve(&model, &state, &mut tested),
        );
        assert!(
            a.status.is_success() && fast.widened && tested.widened,
            "{a:?}"
        );
        assert_eq!(a.iterations, b.iterations);
        let bits = |x: &[f64]| x.iter().map(|v| v.to_bits()).collect::<Vec<_>>();
        assert_eq!(bits(&fast.w), bits(&tested.w));
    }
}
