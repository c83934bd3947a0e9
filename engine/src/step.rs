//! `step` and `rollout`: the only place that sequences the modules (validate, prepare, solve,
//! write back).
use crate::model::Model;
use crate::solver::newton;
pub use crate::solver::newton::AppliedForces;
use crate::state::{SolveStatus, State, StepReport, Workspace};
use crate::{Error, Result, ensure};

/// Check a step's inputs: sizes, finiteness, and that state and workspace belong to `model`.
pub fn validate_inputs(
    model: &Model,
    state: &State,
    ws: &Workspace,
    ctrl: &[f64],
    forces: &AppliedForces,
) -> Result<()> {
    state.check_model(model)?;
    ensure!(
        ws.topology_id == model.topology_id(),
        Error::ModelMismatch {
            detail: "workspace was built for another model".into()
        }
    );
    ensure!(
        ctrl.len() == model.nu(),
        Error::shape("ctrl", &[model.nu()], &[ctrl.len()])
    );
    Error::check_finite("ctrl", ctrl)?;
    if let Some(q) = forces.qfrc {
        ensure!(
            q.len() == model.nv,
            Error::shape("qfrc_applied", &[model.nv], &[q.len()])
        );
        ensure!(
            q.iter().all(|x| x.is_finite()),
            Error::input("qfrc_applied", q, "must be finite")
        );
    }
    if let Some(x) = forces.xfrc {
        ensure!(
            x.len() == 6 * model.nbody(),
            Error::shape("xfrc_applied", &[model.nbody(), 6], &[x.len()])
        );
        ensure!(
            x.iter().all(|v| v.is_finite()),
            Error::input("xfrc_applied", x, "must be finite")
        );
    }
    Ok(())
}

/// Advance `state` by one time step with controls `ctrl` (length `nu`).
///
/// Returns a report; a solve that did not converge still writes its last iterate into `state`
/// (so it can be inspected) and says so in [`StepReport::status`].
///
/// ```
/// use ukemi_engine::{BodySpec, JointKind, JointSpec, ModelBuilder, State, Workspace, step};
/// let model = ModelBuilder::new()
///     .body(BodySpec::new("ball", 1.0, [0.1, 0.1, 0.1]).pos([0.0, 0.0, 1.0]))
///     .joint(JointSpec::new("free", JointKind::Floating, "world", "ball"))
///     .compile()
///     .unwrap();
/// let mut state = State::reference(&model);
/// let mut ws = Workspace::new(&model);
/// let report = step(&model, &mut state, &mut ws, &[]).unwrap();
/// assert_eq!(report.status.name(), "converged");
/// // free fall: z = 1 - g h² after one step of the variational integrator
/// assert!((state.com_pos[5] - (1.0 - 9.81 * 0.01 * 0.01)).abs() < 1e-12);
/// ```
pub fn step(
    model: &Model,
    state: &mut State,
    ws: &mut Workspace,
    ctrl: &[f64],
) -> Result<StepReport> {
    step_with(model, state, ws, ctrl, &AppliedForces::default())
}

/// [`step`] with applied generalized forces and body wrenches.
pub fn step_with(
    model: &Model,
    state: &mut State,
    ws: &mut Workspace,
    ctrl: &[f64],
    forces: &AppliedForces,
) -> Result<StepReport> {
    validate_inputs(model, state, ws, ctrl, forces)?;
    let report = attempts(model, state, ws, ctrl, forces)?;
    if report.status.is_success() {
        return Ok(report);
    }
    // Last resorts, in turn, from the failed step's start:
    // * the step with pyramid friction cones, then the exact cones warm-started from its
    //   impulses (`Options::pyramid_fallback`): the humanoid's seed-155 step 188 jams the
    //   exact cones from the previous step's impulses and converges from the pyramid's; its
    //   seed-21 step 591 jams the pyramid too and converges from its last iterate's;
    // * the exact problem: no friction held by `drop_redundant_friction`'s shortcuts (the
    //   humanoid's seed-13 step 127, `tests/hard_steps.rs`, fails every attempt with them and
    //   converges without; it converges from the pyramid's impulses too, which come first as
    //   they cost half as much on the jammed steps: 3130 → 1549 iterations on seed 155's);
    // * the start rebuilt from its minimal coordinates (joint drift and velocities off the
    //   joints' motion subspaces projected out, what `rollout_vjp` and the flat JAX/torch
    //   layers step from): the humanoid's seed-97 step 53 jams from its exact start on every
    //   problem and converges from the rebuilt one;
    // * the pyramid's step itself, reported as `PyramidFriction`.
    // (`crate::gradients` takes the same decisions up to the rebuilt start.)
    let start = ws.start.clone();
    let mut iterations = report.iterations;
    let mut tried = |m: &Model, from: &State, ws: &mut Workspace, state: &mut State| {
        let mut next = from.clone();
        let retry = attempts(m, &mut next, ws, ctrl, forces)?;
        iterations += retry.iterations;
        let done = retry.status.is_success().then(|| {
            *state = next;
            StepReport {
                iterations,
                ..retry
            }
        });
        Result::Ok(done)
    };
    let pyramid = pyramid_step(model, &start, ctrl, forces)?;
    // (the pyramid's and the whole step's from its impulses)
    let mut pyramid_iterations = pyramid.as_ref().map_or(0, |(_, r)| r.iterations);
    let warm = pyramid
        .as_ref()
        .and_then(|(p, _)| warm_started_from(&start, p));
    if let Some(warm) = warm {
        let (r, kept) = whole_step(model, &warm, ws, ctrl, forces);
        pyramid_iterations += r.iterations;
        if let Some(next) = kept {
            *state = next;
            return Ok(StepReport {
                iterations: report.iterations + pyramid_iterations,
                ..r
            });
        }
    }
    if model.options.drop_redundant_friction {
        let exact = model.with_options(crate::Options {
            drop_redundant_friction: false,
            ..model.options.clone()
        })?;
        if let Some(done) = tried(&exact, &start, ws, state)? {
            return Ok(StepReport {
                iterations: done.iterations + pyramid_iterations,
                ..done
            });
        }
    }
    // (the exact problem from the rebuilt start too rescued no step found so far, and a step
    // that nothing solves spent a quarter of its ~6000 iterations on it)
    if let Some(rebuilt) = rebuilt(model, &start)?
        && let Some(done) = tried(model, &rebuilt, ws, state)?
    {
        return Ok(StepReport {
            iterations: done.iterations + pyramid_iterations,
            ..done
        });
    }
    ws.start = start;
    let iterations = iterations + pyramid_iterations;
    Ok(match pyramid.filter(|(_, pr)| pr.status.is_success()) {
        Some((mapped, pr)) => {
            *state = mapped;
            StepReport {
                status: SolveStatus::PyramidFriction,
                iterations,
                ..pr
            }
        }
        None => StepReport {
            iterations,
            ..report
        },
    })
}

/// The step from `start` with each second-order friction cone replaced by its inscribed
/// four-sided pyramid (the `linear` contact model), through the same attempts as any step
/// (whole, subdivisions, long solve): `start` written as the exact model's state with the
/// pyramid's next state's motion and impulses ([`State::take_pyramid`]) and the pyramid's
/// report (a failed pyramid's last iterate too: still a warm start for the exact cones), or
/// `None` when the option is off or the model has no cones.
pub fn pyramid_step(
    model: &Model,
    start: &State,
    ctrl: &[f64],
    forces: &AppliedForces,
) -> Result<Option<(State, StepReport)>> {
    use crate::contact::ContactModel::{Linear, Nonlinear};
    let cones = model.contacts.iter().any(|c| c.model == Nonlinear);
    if !model.options.pyramid_fallback || !cones {
        return Ok(None);
    }
    let lin = model.with_contact_model(Nonlinear, Linear)?;
    let mut next = start.moved_to(&lin);
    let report = attempts(&lin, &mut next, &mut Workspace::new(&lin), ctrl, forces)?;
    let mut mapped = start.clone();
    mapped.take_pyramid(model, &lin, &next);
    Ok(Some((mapped, report)))
}

/// The whole step from `state` (its warm start as it is), kept only if it converges and is not
/// [`suspect`]: its report, and its next state when kept (the solution in `ws` either way).
/// The exact cones from the pyramid's impulses are tried so (here and in the gradients'
/// ladder): the warm start is the whole step's (sub-steps of `h / n` would start from a whole
/// step's impulses), and on the Panda's seed-371 step 159, where that fails, the subdivisions
/// and long solves after it cost 1563 iterations at ~300 active candidates.
pub(crate) fn whole_step(
    model: &Model,
    state: &State,
    ws: &mut Workspace,
    ctrl: &[f64],
    forces: &AppliedForces,
) -> (StepReport, Option<State>) {
    newton::prepare(model, state, ws, ctrl, forces);
    let report = newton::solve(model, state, ws);
    if !report.status.is_success() {
        return (report, None);
    }
    let mut next = state.clone();
    newton::write_state(model, &mut next, ws);
    let kept = !suspect(model, state, &next, ws);
    (report, kept.then_some(next))
}

/// `start` with the impulses (joint, contact and limit variables) of `solution` as its warm
/// start: where an exact-cone solve that jammed from the previous step's impulses begins again.
/// `None` when they are not all finite (a pyramid solve that failed with a NaN).
pub fn warm_started_from(start: &State, solution: &State) -> Option<State> {
    let finite = solution
        .ineq_vars
        .iter()
        .chain(&solution.joint_impulse)
        .all(|x| x.is_finite());
    finite.then(|| {
        let mut warm = start.clone();
        warm.ineq_vars.copy_from_slice(&solution.ineq_vars);
        warm.joint_impulse.copy_from_slice(&solution.joint_impulse);
        warm
    })
}

/// `state` rebuilt from its minimal coordinates by forward kinematics, or `None` when that
/// changes nothing (loose bodies, an already consistent state).
fn rebuilt(model: &Model, state: &State) -> Result<Option<State>> {
    use crate::joints::coordinates::{qpos, qvel, set_minimal};
    let mut out = state.clone();
    set_minimal(model, &mut out, &qpos(model, state), &qvel(model, state))?;
    Ok((out != *state).then_some(out))
}

/// A step's attempts in turn: the whole step, its subdivisions, then [`long_solve`].
fn attempts(
    model: &Model,
    state: &mut State,
    ws: &mut Workspace,
    ctrl: &[f64],
    forces: &AppliedForces,
) -> Result<StepReport> {
    newton::prepare(model, state, ws, ctrl, forces);
    let report = newton::solve(model, state, ws);
    // the step's start, for its retries and the energy guard: `write_state` rewrites every
    // inequality variable (`inequality::store`), so the start's are moved, not copied (the
    // copy of the A1's 1024 candidates' was 1.1% of its steps)
    if model.topology.has_cones {
        ws.start.copy_taking_ineq_vars(state);
    } else {
        ws.start.copy_from(state);
    }
    newton::write_state(model, state, ws);
    let whole_converged = report.status.is_success();
    // a failed iterate's speeds mean nothing: its subdivision starts at 2
    let first = if whole_converged {
        rotation_substeps(model, state)
    } else {
        2
    };
    let retry = !whole_converged || first > 1 || gains_energy(model, &ws.start, state, ws);
    if !retry || model.options.max_subdivisions == 1 {
        return Ok(report);
    }
    let ceiling = whole_converged.then(|| energy_ceiling(model, &ws.start, state));
    // keep the whole step (written above) unless a subdivision succeeds
    let mut s = ws.start.clone();
    Ok(
        match subdivided(
            model,
            &mut s,
            ws,
            ctrl,
            forces,
            whole_converged,
            first,
            ceiling,
        )? {
            Ok(r) => {
                *state = s;
                StepReport {
                    iterations: r.iterations + report.iterations,
                    ..r
                }
            }
            Err(iterations) => {
                let start = ws.start.clone();
                match long_solve(model, &start, ws, ctrl, forces, whole_converged)? {
                    Ok((next, r)) => {
                        *state = next;
                        StepReport {
                            iterations: r.iterations + iterations + report.iterations,
                            ..r
                        }
                    }
                    Err(spent) => StepReport {
                        iterations: spent + iterations + report.iterations,
                        ..report
                    },
                }
            }
        },
    )
}

/// The last resort of a step whose whole solve and every subdivision failed (with
/// `whole_converged` it does nothing): the whole step from `start` solved again with four times
/// the iteration budget and every candidate active from the first attempt on, then, if that
/// fails (or gains energy, [`gains_energy`]), tier by tier with every candidate active in the
/// third tier (`Workspace::every_candidate`). Its next state and report (solution in `ws`, the
/// iterations of both), else the iterations it spent. The humanoid with a lower arm wedged
/// between its waist and the floor (`tests/hard_steps.rs`) failed every tier-by-tier attempt
/// (~1350 iterations) and converges in ~20 with every candidate active from the start, as it
/// does with `activation_margin = inf`; the shared Panda's step 782 under `step_bench` seed 1 (a
/// fingertip pad's corner pressed into the floor with ~330 N) spent 1400 iterations in the
/// tiers (up to 686 candidates active) and converges in 46 all-active (844 → 195 ms for the
/// step). The tiers stay as the second pass: when they came first, the Panda's step 135
/// under session 25's Table V controls (fingers closing onto their limits and each other
/// while a pad slides on the floor) converged there in 141 iterations. Random scene 701's
/// long solves converge to energy-gaining roots and are refused.
pub(crate) fn long_solve(
    model: &Model,
    start: &State,
    ws: &mut Workspace,
    ctrl: &[f64],
    forces: &AppliedForces,
    whole_converged: bool,
) -> Result<std::result::Result<(State, StepReport), usize>> {
    if whole_converged {
        return Ok(Err(0));
    }
    let o = &model.options;
    // in turn, until one converges to a root that gains no energy: every candidate active from
    // the first attempt on, then the activation tiers with every candidate in the third
    let margins: &[f64] = match o.activation_margin.is_finite() {
        true => &[f64::INFINITY, o.activation_margin],
        false => &[f64::INFINITY],
    };
    let mut spent = 0;
    for &activation_margin in margins {
        let long = model.with_options(crate::Options {
            max_iter: 4 * o.max_iter,
            activation_margin,
            ..o.clone()
        })?;
        newton::prepare(&long, start, ws, ctrl, forces);
        ws.every_candidate = true;
        let report = newton::solve(&long, start, ws);
        ws.every_candidate = false;
        spent += report.iterations;
        if !report.status.is_success() {
            continue;
        }
        let mut next = start.clone();
        newton::write_state(&long, &mut next, ws);
        if !gains_energy(&long, start, &next, ws) {
            let report = StepReport {
                iterations: spent,
                ..report
            };
            return Ok(Ok((next, report)));
        }
    }
    Ok(Err(spent))
}

/// The fewest sub-steps, a power of two (1: none), in which no body of the step that ended in
/// `next` turns more than [`crate::Options::max_step_rotation`] per sub-step: `h |ω|` with
/// `ω` the step's midpoint angular velocity, capped at `max_subdivisions`.
///
/// Why: the variational integrator's energy error grows with the rotation per step. Random
/// stress scene 34, a sphere on a universal joint whose arm swings past the joint's first
/// axis (its twist then whips to 80 rad/s, h |ω| = 0.79), gained 8.8% of its energy in 300
/// steps of 10 ms, all converged; at 0.3 rad per step it gains 0.3% (17 of 300 steps taken
/// as sub-steps). The Table V robots under random controls turn at most 0.12 rad per step
/// (humanoid), 0.04 (A1), 0.014 (Panda) and 0.30 (the X2 tumbling) at h = 0.01.
pub(crate) fn rotation_substeps(model: &Model, next: &State) -> u32 {
    let o = &model.options;
    let fastest = (1..model.nbody())
        .map(|b| next.velocity(b).1.norm())
        .fold(0.0, f64::max);
    let rotation = o.timestep * fastest;
    let mut n = 1;
    while rotation > o.max_step_rotation * n as f64 && n < o.max_subdivisions {
        n *= 2;
    }
    n.min(o.max_subdivisions)
}

/// Whether a converged step from `start` to `next` (solution in `ws`) must be taken again as
/// sub-steps: it gained energy ([`gains_energy`]) or turned a body too far
/// ([`rotation_substeps`]).
pub(crate) fn suspect(model: &Model, start: &State, next: &State, ws: &Workspace) -> bool {
    rotation_substeps(model, next) > 1 || gains_energy(model, start, next, ws)
}

/// The most total energy a subdivision of a converged whole step from `start` to `next` may
/// end with: the larger of the two states' energies, plus `energy_guard (T + T⁺)`. Sub-steps
/// under the same control and forces should land near the whole step, with less of its
/// integration error; one that ends well above both found a spurious root. Random stress
/// scene 760 (a ball-jointed link bouncing off the floor at 0.31 rad per step, before session
/// 43 let its links meet edge on edge): the whole step ended at 17.45 J from 17.95 J, its two
/// sub-steps at 21.96 J, each within the energy guard's allowance.
pub(crate) fn energy_ceiling(model: &Model, start: &State, next: &State) -> f64 {
    use crate::mechanics::{kinetic_energy, total_energy};
    let kinetic = kinetic_energy(model, start) + kinetic_energy(model, next);
    total_energy(model, start).max(total_energy(model, next)) + model.options.energy_guard * kinetic
}

/// Whether a converged step from `start` to `next` (applied impulses in `ws`) let its
/// constraint impulses add more kinetic energy than [`crate::Options::energy_guard`] allows:
/// the mark of a spurious root of the implicit step.
pub(crate) fn gains_energy(model: &Model, start: &State, next: &State, ws: &Workspace) -> bool {
    let o = &model.options;
    if o.energy_guard == 0.0 {
        return false;
    }
    let (work, kinetic) = crate::mechanics::constraint_work(model, start, next, &ws.applied);
    let mass: f64 = model.bodies.iter().skip(1).map(|b| b.mass).sum();
    let quantum = mass * o.gravity.norm_squared() * o.timestep * o.timestep;
    work > o.energy_guard * kinetic + quantum + depenetration_work(model, ws) + 1e-12
}

/// The work the step's contacts may do pushing out of penetrations they started in: each
/// contact's mean force `γ/h` over its starting depth. Hard contacts resolve a penetration in one
/// step, and that work is no spurious root: the shared humanoid's `squat` keyframe starts 8
/// candidates up to 0.35 mm inside the floor, its first step converged while gaining 7.3 J,
/// and the guard then tried every subdivision (1109 iterations for one step).
fn depenetration_work(model: &Model, ws: &Workspace) -> f64 {
    let t = &model.topology;
    (0..model.ncontact())
        .filter(|&c| ws.active[c] && ws.contact_phi_now[c] < 0.0)
        .map(|c| {
            let gamma = ws.w[t.pattern.offset(t.contact_node[c])];
            gamma.max(0.0) * -ws.contact_phi_now[c] / model.options.timestep
        })
        .sum()
}

/// A step whose solve failed (or was [`suspect`]), taken again as `n` = `first` (≥ 2, from
/// [`rotation_substeps`]), then finer, ≤ `max_subdivisions` equal sub-steps from `state` under
/// the same control and forces. On success `state` holds the end of the last sub-step with the
/// impulses summed over the sub-steps ([`State::add_impulses`]) and the report; otherwise
/// `Err(iterations spent)` and `state` is untouched.
///
/// An attempt whose sub-step fails is followed by one twice as fine. The first attempt whose
/// sub-steps all converge, none gaining energy or turning a body further than
/// `max_step_rotation`, is taken. A converged attempt that does not pass is the fallback, and
/// one finer attempt is tried (twice as fine after an energy gain, as fine as the rotation
/// needs after a fast turn); if it does not pass either, the fallback is taken. Then:
/// - a converged whole step is kept when no attempt converged (`guard`: energy-gaining
///   sub-steps count as failed), or when an attempt ends above `ceiling`
///   ([`energy_ceiling`]);
/// - a failed whole step takes the fallback: a converged step beats a failed one (the shared
///   humanoid's first step from its `squat` keyframe, where 8 contact candidates start up to
///   0.35 mm inside the floor, gains 7.3 J as the contacts push them out, and converges in 8
///   sub-steps).
///
/// Taking the first converged subdivision outright instead kept spurious roots: random scene
/// 34's step 30 ended at 29.30 J in 2 sub-steps where 4, 8, 16, 64 sub-steps give 26.65, 26.43,
/// 26.39, 26.37 J. Jumping past a converged subdivision to the one the rotation asks for lost
/// steps: random scene 613's step 83 converges in 2 sub-steps and in none of 8, 16 or 32.
#[allow(clippy::too_many_arguments)]
fn subdivided(
    model: &Model,
    state: &mut State,
    ws: &mut Workspace,
    ctrl: &[f64],
    forces: &AppliedForces,
    guard: bool,
    first: u32,
    ceiling: Option<f64>,
) -> Result<std::result::Result<StepReport, usize>> {
    let mut none = |_: u32, _: usize, _: &State, _: &Workspace, _: StepReport| {};
    subdivided_with(
        model, state, ws, ctrl, forces, guard, first, ceiling, false, &mut none,
    )
}

/// [`subdivided`], calling `solved(n, i, start, ws, report)` after sub-step `i` of an attempt
/// with `n` sub-steps converged, with the sub-step's start state and its solution in `ws` (the
/// gradients keep them to linearise every sub-step; an attempt that is not taken is abandoned,
/// and the next attempt starts again at `i = 0`). With `replay`, a fallback attempt that is
/// taken is solved again so that it is the last one reported.
#[allow(clippy::too_many_arguments)]
pub(crate) fn subdivided_with(
    model: &Model,
    state: &mut State,
    ws: &mut Workspace,
    ctrl: &[f64],
    forces: &AppliedForces,
    guard: bool,
    first: u32,
    ceiling: Option<f64>,
    replay: bool,
    solved: &mut dyn FnMut(u32, usize, &State, &Workspace, StepReport),
) -> Result<std::result::Result<StepReport, usize>> {
    let most = model.options.max_subdivisions;
    let mut iterations = 0;
    let mut fallback: Option<(u32, State, StepReport)> = None;
    let mut n = first.max(2);
    while n <= most {
        let outcome = attempt(
            model,
            state,
            ws,
            ctrl,
            forces,
            n,
            guard,
            solved,
            &mut iterations,
        )?;
        let next_n = match outcome {
            Attempt::Failed => 2 * n,
            Attempt::Done { end, .. }
                if ceiling.is_some_and(|c| crate::mechanics::total_energy(model, &end) > c) =>
            {
                // a spurious root of the sub-steps: finer ones rarely do better
                return Ok(Err(iterations));
            }
            Attempt::Done {
                end,
                report,
                gained,
                finer,
            } => {
                let finer = if n < most { finer } else { 1 };
                if !gained && finer == 1 {
                    *state = *end;
                    return Ok(Ok(StepReport {
                        iterations,
                        ..report
                    }));
                }
                if fallback.is_none() {
                    fallback = Some((n, *end, report));
                }
                (n * finer).clamp(2 * n, most.max(2 * n))
            }
        };
        // past a converged fallback, one finer subdivision is tried for an energy-consistent
        // step, or for one that turns no body too far (the shared humanoid's squat start gains
        // energy at every subdivision: trying all of them doubled its cost)
        if fallback.as_ref().is_some_and(|(m, _, _)| n > *m) {
            break;
        }
        n = next_n;
    }
    let Some((n, end, report)) = fallback else {
        return Ok(Err(iterations));
    };
    let mut end = end;
    if replay {
        // reported to `solved` last: taken again (the solves are deterministic)
        let again = attempt(
            model,
            state,
            ws,
            ctrl,
            forces,
            n,
            false,
            solved,
            &mut iterations,
        )?;
        if let Attempt::Done { end: same, .. } = again {
            end = *same;
        }
    }
    *state = end;
    Ok(Ok(StepReport {
        iterations,
        ..report
    }))
}

/// What one attempt of [`subdivided_with`] came to.
enum Attempt {
    /// A sub-step failed, or gained energy ([`gains_energy`]) with `stop_on_energy`.
    Failed,
    /// Every sub-step converged.
    Done {
        /// The end state (impulses summed over the sub-steps).
        end: Box<State>,
        report: StepReport,
        /// Whether a sub-step gained energy.
        gained: bool,
        /// How many times finer the sub-steps must be for none to turn a body further than
        /// `max_step_rotation` ([`rotation_substeps`]; 1: they are fine).
        finer: u32,
    },
}

/// One attempt of [`subdivided_with`]: the step from `state` as `n` sub-steps.
#[allow(clippy::too_many_arguments)]
fn attempt(
    model: &Model,
    state: &State,
    ws: &mut Workspace,
    ctrl: &[f64],
    forces: &AppliedForces,
    n: u32,
    stop_on_energy: bool,
    solved: &mut dyn FnMut(u32, usize, &State, &Workspace, StepReport),
    iterations: &mut usize,
) -> Result<Attempt> {
    let sub = substep_model(model, n)?;
    let mut report = StepReport {
        status: SolveStatus::Converged,
        iterations: 0,
        residual: 0.0,
        complementarity: 0.0,
        subdivisions: n,
    };
    let mut ends: Vec<State> = Vec::with_capacity(n as usize);
    let mut s = state.clone();
    // the interval of the state's velocities in units of the sub-step
    s.interval = s.interval.map(|i| i * n as f64);
    let (mut gained, mut finer) = (false, 1);
    for i in 0..n as usize {
        newton::prepare(&sub, &s, ws, ctrl, forces);
        ws.substep = n > 1;
        let r = newton::solve(&sub, &s, ws);
        ws.substep = false;
        *iterations += r.iterations;
        let mut next = s.clone();
        newton::write_state(&sub, &mut next, ws);
        if !r.status.is_success() {
            return Ok(Attempt::Failed);
        }
        if gains_energy(&sub, &s, &next, ws) {
            if stop_on_energy {
                return Ok(Attempt::Failed);
            }
            gained = true;
        }
        finer = finer.max(rotation_substeps(&sub, &next));
        solved(n, i, &s, ws, r);
        if r.status == SolveStatus::Acceptable {
            report.status = SolveStatus::Acceptable;
        }
        report.residual = report.residual.max(r.residual);
        report.complementarity = report.complementarity.max(r.complementarity);
        s = next;
        ends.push(s.clone());
    }
    // the last sub-step's poses, velocities and slacks; the whole step's impulses
    for end in &ends[..ends.len() - 1] {
        s.add_impulses(model, end);
    }
    s.time = state.time + model.options.timestep;
    // the velocities are the last sub-step's: an interval of h / n
    s.interval = Some(1.0 / n as f64);
    Ok(Attempt::Done {
        end: Box::new(s),
        report,
        gained,
        finer,
    })
}

/// The model a step of `model` is subdivided into: the same with time step `h / n`.
pub(crate) fn substep_model(model: &Model, n: u32) -> Result<Model> {
    model.with_options(crate::Options {
        timestep: model.options.timestep / n as f64,
        ..model.options.clone()
    })
}

/// Step `nstep` times with controls `ctrls` (row-major `(nstep, nu)`), calling `record` after every
/// step with the new state and its report. Stops at the first step that fails to converge when
/// `stop_on_failure` is set (the failing step is still recorded).
pub fn rollout(
    model: &Model,
    state: &mut State,
    ws: &mut Workspace,
    ctrls: &[f64],
    nstep: usize,
    stop_on_failure: bool,
    mut record: impl FnMut(usize, &State, &StepReport),
) -> Result<()> {
    let nu = model.nu();
    ensure!(
        ctrls.len() == nstep * nu,
        Error::shape("ctrls", &[nstep, nu], &[ctrls.len() / nu.max(1), nu])
    );
    for k in 0..nstep {
        let report = step(model, state, ws, &ctrls[k * nu..(k + 1) * nu])?;
        record(k, state, &report);
        if stop_on_failure && !report.status.is_success() {
            break;
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::{BodySpec, JointKind, JointSpec, ModelBuilder};
    use nalgebra::Vector3;

    /// A subdivision of a converged whole step that ends above the energy ceiling
    /// ([`energy_ceiling`]) is refused, the whole step kept; below it, taken. (The case that
    /// showed the need, random scene 760's step 41, where two sub-steps found a root 4.5 J above
    /// the whole step's, is no longer reached since session 43: its links had passed through
    /// each other edge on edge on the way there. So the decision is checked here directly, on a
    /// body spinning 0.62 rad a step, which the rotation limit takes as sub-steps.)
    #[test]
    fn a_subdivision_ending_above_the_energy_ceiling_is_refused() {
        let model = ModelBuilder::new()
            .timestep(0.01)
            .body(BodySpec::new("b", 2.0, [0.3, 0.1, 0.2]).pos([0.0, 0.0, 1.0]))
            .joint(JointSpec::new("free", JointKind::Floating, "world", "b"))
            .compile()
            .unwrap();
        let mut start = State::reference(&model);
        start.set_velocity(1, &Vector3::zeros(), &Vector3::new(30.0, -50.0, 20.0));
        let forces = AppliedForces::default();
        let mut ws = Workspace::new(&model);
        let mut whole = start.clone();
        newton::prepare(&model, &whole, &mut ws, &[], &forces);
        assert!(newton::solve(&model, &whole, &mut ws).status.is_success());
        newton::write_state(&model, &mut whole, &ws);
        let first = rotation_substeps(&model, &whole);
        assert!(first > 1);
        let ceiling = energy_ceiling(&model, &start, &whole);
        let energy = |s: &State| crate::mechanics::total_energy(&model, s);
        assert!(ceiling >= energy(&start).max(energy(&whole)));
        // below the ceiling: taken
        let mut taken = start.clone();
        let out = subdivided(
            &model,
            &mut taken,
            &mut ws,
            &[],
            &forces,
            true,
            first,
            Some(ceiling),
        );
        assert!(out.unwrap().is_ok());
        assert!(energy(&taken) <= ceiling && taken != start);
        // a ceiling under the sub-steps' end: refused, the state untouched
        let mut refused = start.clone();
        let low = Some(energy(&taken) - 1e-3);
        let out = subdivided(
            &model,
            &mut refused,
            &mut ws,
            &[],
            &forces,
            true,
            first,
            low,
        );
        assert!(out.unwrap().is_err());
        assert!(refused == start);
    }

    /// A step taken as sub-steps leaves the velocities of an interval h/n in the state; the steps
    /// before and after must use the variable-step discrete Euler-Lagrange equations (backward
    /// momentum of the previous interval's length, applied impulses over the mean of the two
    /// intervals). Checked on a tumbling body in free fall: the discrete angular momentum is
    /// conserved exactly and the centre of mass stays on the exact parabola of the midpoint
    /// velocities. (With the step's own h for both intervals, the first switch changed the
    /// angular momentum by 8.8e-2 of itself, and gravity's impulse over the first sub-step,
    /// h/2 · g instead of 3h/4 · g, left the body g·h/4 behind the parabola.)
    #[test]
    fn subdivided_steps_keep_the_discrete_momenta_of_a_variable_step() {
        let h = 0.01;
        let model = ModelBuilder::new()
            .timestep(h)
            .body(BodySpec::new("b", 2.0, [0.3, 0.1, 0.2]).pos([0.0, 0.0, 1.0]))
            .joint(JointSpec::new("free", JointKind::Floating, "world", "b"))
            .compile()
            .unwrap();
        // whole steps between the forced subdivisions (this spin turns 0.62 rad a step)
        let model = model
            .with_options(crate::Options {
                max_step_rotation: f64::INFINITY,
                ..model.options.clone()
            })
            .unwrap();
        let mut state = State::reference(&model);
        state.set_velocity(1, &Vector3::zeros(), &Vector3::new(30.0, -50.0, 20.0));
        let mut ws = Workspace::new(&model);
        let l0 = crate::mechanics::angular_momentum(&model, &state);
        let g = model.options.gravity.z;
        // z of the exact parabola whose midpoint velocity over [-h, 0] is 0, at time t
        let exact = |t: f64| 1.0 + 0.5 * g * ((t + 0.5 * h).powi(2) - 0.25 * h * h);
        let forces = AppliedForces::default();
        for k in 0..20 {
            if k % 5 == 2 {
                // take this step as n sub-steps, as `step` does after a failed solve
                let n = 2u32.pow(1 + k % 2);
                let mut none = |_: u32, _: usize, _: &State, _: &Workspace, _: StepReport| {};
                let done = attempt(
                    &model,
                    &state,
                    &mut ws,
                    &[],
                    &forces,
                    n,
                    true,
                    &mut none,
                    &mut 0,
                )
                .unwrap();
                let Attempt::Done { end, gained, .. } = done else {
                    panic!("step {k}: an attempt failed");
                };
                assert!(!gained);
                state = *end;
            } else {
                assert!(
                    step(&model, &mut state, &mut ws, &[])
                        .unwrap()
                        .status
                        .is_success()
                );
            }
            let l = crate::mechanics::angular_momentum(&model, &state);
            assert!(
                (l - l0).norm() < 1e-10 * l0.norm(),
                "step {k}: {:e}",
                (l - l0).norm() / l0.norm()
            );
            let z = state.pose(1).pos.z;
            assert!((z - exact(state.time)).abs() < 1e-12, "step {k}: z {z}");
        }
    }

    /// A body turning ~0.6 rad a step (61.6 rad/s at h = 0.01, |ω| varying as it tumbles) is
    /// taken as sub-steps that turn it at most `max_step_rotation` = 0.3 rad each. The
    /// sub-steps are steps of the variational integrator, so the tumble keeps its discrete
    /// angular momentum exactly across them and across the switches between step lengths.
    #[test]
    fn fast_turns_are_subdivided_and_keep_the_discrete_momenta() {
        let model = ModelBuilder::new()
            .timestep(0.01)
            .gravity([0.0, 0.0, 0.0])
            .body(BodySpec::new("b", 2.0, [0.3, 0.1, 0.2]).pos([0.0, 0.0, 1.0]))
            .joint(JointSpec::new("free", JointKind::Floating, "world", "b"))
            .compile()
            .unwrap();
        assert_eq!(model.options.max_step_rotation, 0.3);
        let mut state = State::reference(&model);
        state.set_velocity(1, &Vector3::zeros(), &Vector3::new(30.0, -50.0, 20.0));
        let mut ws = Workspace::new(&model);
        let mut l0 = None;
        for k in 0..20 {
            let report = step(&model, &mut state, &mut ws, &[]).unwrap();
            assert!(report.status.is_success(), "step {k}");
            let n = report.subdivisions;
            let turn = state.velocity(1).1.norm() * 0.01 / n as f64;
            assert!(
                n >= 2 && turn <= 0.3,
                "step {k}: {n} sub-steps of {turn} rad"
            );
            let l = crate::mechanics::angular_momentum(&model, &state);
            let l0 = *l0.get_or_insert(l);
            assert!((l - l0).norm() < 1e-10 * l0.norm(), "step {k}");
        }
        // the limit off: whole steps
        let whole = model
            .with_options(crate::Options {
                max_step_rotation: f64::INFINITY,
                ..model.options.clone()
            })
            .unwrap();
        let report = step(&whole, &mut state, &mut Workspace::new(&whole), &[]).unwrap();
        assert_eq!(report.subdivisions, 1);
    }

    /// The pyramid last resort on a 1 kg box sliding on the floor (μ = 0.5). The pyramid's
    /// step ([`pyramid_step`]) is the pyramid model's own step, with its impulses (inside the
    /// exact cone) in the exact model's layout; the floor's tangents are world x and y, so
    /// sliding along x the inscribed pyramid's friction is the cone's, `μ m g h` a step, and
    /// along the diagonal `μ m g h / √2` (the pyramid's edge), against the slip. The exact
    /// cones warm-started from the pyramid's impulses ([`warm_started_from`]) land on the exact
    /// step.
    #[test]
    fn the_pyramid_last_resort_slides_a_box_by_the_inscribed_pyramid() {
        use crate::contact::ContactModel::{Linear, Nonlinear};
        let (h, mu, g) = (0.01, 0.5, 9.81);
        let model = crate::gradients::test_scenes::box_on_floor(h, mu);
        let lin = model.with_contact_model(Nonlinear, Linear).unwrap();
        assert!(lin.contacts.iter().all(|c| c.model == Linear));
        let forces = AppliedForces::default();
        for (dir, share) in [
            (Vector3::new(1.0, 0.0, 0.0), 1.0),
            (Vector3::new(1.0, 1.0, 0.0).normalize(), 0.5f64.sqrt()),
        ] {
            // sliding at 2 m/s, resting on the floor (one exact step settles the impulses)
            let mut start = State::reference(&model);
            start.set_velocity(1, &(2.0 * dir), &Vector3::zeros());
            let mut ws = Workspace::new(&model);
            assert!(
                step(&model, &mut start, &mut ws, &[])
                    .unwrap()
                    .status
                    .is_success()
            );
            let v0 = start.velocity(1).0;
            // the pyramid's step, and the pyramid model's own step from the same start
            let (mapped, r) = pyramid_step(&model, &start, &[], &forces).unwrap().unwrap();
            assert_eq!(r.status, SolveStatus::Converged);
            let mut direct = start.moved_to(&lin);
            let rd = step(&lin, &mut direct, &mut Workspace::new(&lin), &[]).unwrap();
            assert_eq!(rd.status, SolveStatus::Converged);
            assert_eq!(mapped.com_pos, direct.com_pos);
            assert_eq!(mapped.com_linvel, direct.com_linvel);
            assert_eq!(mapped.contact_impulse(&model), direct.contact_impulse(&lin));
            let dv = mapped.velocity(1).0 - v0;
            let expect = -mu * g * h * share * dir;
            assert!((dv - expect).norm() < 1e-8, "{dv:?} vs {expect:?}");
            for (c, f) in mapped.contact_impulse(&model).chunks(3).enumerate() {
                let tangential = (f[1] * f[1] + f[2] * f[2]).sqrt();
                assert!(
                    tangential <= mu * f[0] * (1.0 + 1e-12),
                    "candidate {c}: {f:?}"
                );
            }
            // the last resort: the exact cones from the pyramid's impulses, the exact step
            let mut exact = start.clone();
            step(&model, &mut exact, &mut ws, &[]).unwrap();
            let mut next = warm_started_from(&start, &mapped).unwrap();
            assert_eq!(next.contact_impulse(&model), mapped.contact_impulse(&model));
            let r = attempts(&model, &mut next, &mut ws, &[], &forces).unwrap();
            assert_eq!(r.status, SolveStatus::Converged);
            let dv = next.velocity(1).0 - v0;
            assert!((dv + mu * g * h * dir).norm() < 1e-8, "{dv:?}");
            assert!((next.pose(1).pos - exact.pose(1).pos).norm() < 1e-10);
            // and the exact cones go on from the pyramid's state
            let mut after = mapped.clone();
            let r = step(&model, &mut after, &mut ws, &[]).unwrap();
            assert_eq!(r.status, SolveStatus::Converged);
            let dv = after.velocity(1).0 - mapped.velocity(1).0;
            assert!((dv + mu * g * h * dir).norm() < 1e-8, "{dv:?}");
        }
        // switched off, or without cones: no last resort
        let off = model
            .with_options(crate::Options {
                pyramid_fallback: false,
                ..model.options.clone()
            })
            .unwrap();
        let s = State::reference(&off);
        assert!(pyramid_step(&off, &s, &[], &forces).unwrap().is_none());
        let s = State::reference(&lin);
        assert!(pyramid_step(&lin, &s, &[], &forces).unwrap().is_none());
    }

    /// A step that fails every attempt reports every iteration it spent, those of the long
    /// solve's failed passes included (they were left out: the shared Panda's seed-5 step 549
    /// reported 2015 iterations of the ~5100 it took).
    #[test]
    fn a_failed_step_counts_the_iterations_of_its_long_solve() {
        let model = crate::gradients::test_scenes::box_on_floor(0.01, 0.5);
        // tolerances no iterate meets: nothing converges
        let model = model
            .with_options(crate::Options {
                max_iter: 1,
                kappa_tol: 1e-300,
                rtol: 1e-300,
                acceptable_rtol: 0.0,
                endgame_iter: 0,
                max_subdivisions: 2,
                pyramid_fallback: false,
                drop_redundant_friction: false,
                ..model.options.clone()
            })
            .unwrap();
        let mut start = State::reference(&model);
        start.set_velocity(
            1,
            &Vector3::new(2.0, 0.0, -1.0),
            &Vector3::new(0.0, 3.0, 0.0),
        );
        let forces = AppliedForces::default();
        let mut ws = Workspace::new(&model);
        newton::prepare(&model, &start, &mut ws, &[], &forces);
        let whole = newton::solve(&model, &start, &mut ws);
        assert!(!whole.status.is_success());
        let spent = match long_solve(&model, &start, &mut ws, &[], &forces, false).unwrap() {
            Err(spent) => spent,
            Ok((_, r)) => panic!("the long solve converged: {r:?}; whole {whole:?}"),
        };
        assert!(spent > whole.iterations, "{spent} vs {}", whole.iterations);
        let mut state = start.clone();
        let report = step(&model, &mut state, &mut Workspace::new(&model), &[]).unwrap();
        assert!(!report.status.is_success());
        assert!(
            report.iterations >= whole.iterations + spent,
            "{} iterations reported, {} in the whole step and {spent} in the long solve",
            report.iterations,
            whole.iterations
        );
    }
}
