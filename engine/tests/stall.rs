//! `Options::stall_iter`: an interior-point attempt that has stopped making progress ends
//! early and the step goes on to its next retry, instead of spending its whole iteration
//! budget (and the endgame's) at step lengths of ~1e-3.
#[allow(dead_code)]
#[path = "../examples/common/workload.rs"]
mod workload;
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
    // the shared Panda, Table V workload with `step_bench`'s seed-1 controls: its step 162
    // (finger pads sliding on the floor) stalls at step lengths of 1e-3 in every attempt of
    // the retry ladder, 566 iterations without the early end
    let Some(early) = workload::shared("panda") else {
        return;
    };
    // (the widening this stall was found with: relative to the weight, session 31's default,
    // the run's longest stall is 39 iterations)
    let early = early
        .with_options(ukemi_engine::Options {
            warm_start_widening_weight: 0.0,
            ..early.options.clone()
        })
        .unwrap();
    assert_eq!(early.options.stall_iter, 20);
    let mut o = early.options.clone();
    o.stall_iter = 0;
    let full = early.with_options(o).unwrap();
    let mut state = workload::start_state(&early);
    let mut ws = [Workspace::new(&early), Workspace::new(&full)];
    ws.iter_mut().for_each(|w| w.set_trace(true, false));
    let mut controls = workload::Controls::with_seed(1);
    let (mut longest_early, mut longest_full) = (0, 0);
    for k in 0..170 {
        let ctrl = controls.next(&early);
        let mut other = state.clone();
        let b = step(&full, &mut other, &mut ws[1], &ctrl).unwrap();
        let a = step(&early, &mut state, &mut ws[0], &ctrl).unwrap();
        assert!(
            a.status.is_success() && b.status.is_success(),
            "step {k}: {a:?} {b:?}"
        );
        longest_early = longest_early.max(longest_stall(&early, ws[0].trace()));
        longest_full = longest_full.max(longest_stall(&full, ws[1].trace()));
    }
    eprintln!(
        "longest stall: {longest_early} iterations with stall_iter 20, {longest_full} without"
    );
    assert!(longest_full > 40, "no stall to end early: {longest_full}");
    assert!(
        longest_early <= 20,
        "an attempt stalled {longest_early} iterations"
    );
}
