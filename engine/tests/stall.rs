//! `Options::stall_iter`: an interior-point attempt that has stopped making progress ends
//! early and the step goes on to its next retry, instead of spending its whole iteration
//! budget (and the endgame's) at step lengths of ~1e-3.
#[path = "common/fixtures.rs"]
mod fixtures;
#[allow(dead_code)]
#[path = "../examples/common/workload.rs"]
mod workload;
use fixtures::fixture;
use ukemi_engine::{IterationRecord, Model, Workspace, step};

/// The longest run of iterations in one attempt of `trace` over which the worst violation
/// relative to the tolerances, `max(r / rtol, k / kappa_tol)`, did not fall tenfold below its
/// best (the quantity `stall_iter` bounds).
fn longest_stall(model: &Model, trace: &[IterationRecord]) -> usize {
    let o = &model.options;
    let (mut longest, mut run) = (0, 0);
    let mut checkpoint = f64::INFINITY;
    for (i, t) in trace.iter().enumerate() {
        if i > 0 && trace[i - 1].attempt != t.attempt {
            (checkpoint, run) = (f64::INFINITY, 0);
        }
        let progress = (t.residual / o.rtol).max(t.complementarity / o.kappa_tol);
        if progress < 0.1 * checkpoint {
            (checkpoint, run) = (progress, 0);
        } else {
            run += 1;
        }
        longest = longest.max(run);
    }
    longest
}

#[test]
fn stalled_attempts_end_early_and_the_steps_still_converge() {
    // the shared Panda, Table V workload with `step_bench`'s seed-5 controls: its step 152
    // (a finger pad struck onto the floor) stalls at short step lengths for 46 iterations of
    // one attempt without the early end. (Until session 39 this test replayed seed 1's first
    // 170 steps, whose stalls came from the arm's shaking servos: with their velocity gains
    // implicit, that run has none longer than 7.)
    let Some((early, state, ctrl)) = fixture("panda_seed5_step152") else {
        return;
    };
    assert_eq!(early.options.stall_iter, 20);
    let mut o = early.options.clone();
    o.stall_iter = 0;
    let full = early.with_options(o).unwrap();
    let mut ws = [Workspace::new(&early), Workspace::new(&full)];
    ws.iter_mut().for_each(|w| w.set_trace(true, false));
    let a = step(&early, &mut state.clone(), &mut ws[0], &ctrl).unwrap();
    let b = step(&full, &mut state.clone(), &mut ws[1], &ctrl).unwrap();
    assert!(
        a.status.is_success() && b.status.is_success(),
        "{a:?} {b:?}"
    );
    let (longest_early, longest_full) = (
        longest_stall(&early, ws[0].trace()),
        longest_stall(&full, ws[1].trace()),
    );
    eprintln!(
        "longest stall: {longest_early} iterations with stall_iter 20, {longest_full} without \
         ({} and {} iterations in all)",
        a.iterations, b.iterations
    );
    assert!(longest_full > 40, "no stall to end early: {longest_full}");
    assert!(
        longest_early <= 20,
        "an attempt stalled {longest_early} iterations"
    );
}
