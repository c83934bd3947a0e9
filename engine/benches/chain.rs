//! Per-step time of an N-link pendulum chain, N = 10 … 1000, and the fitted scaling exponent
//! (target: linear, exponent ≤ 1.1). Run: `cargo bench -p ukemi-engine --bench chain`.
//!
//! The chain floats in zero gravity with random joint rates: a 1000-link chain hanging under
//! gravity carries ~10 kN at the top, and its tension-driven transverse modes (ω ~ √(T/mL)) then
//! exceed the integrator's stability limit hω < 2 at h = 0.01 s.
use std::time::Instant;

use criterion::{BenchmarkId, Criterion, Throughput};
use ukemi_engine::{
    BodySpec, JointKind, JointSpec, Model, ModelBuilder, State, Workspace, set_minimal, step,
};

const SIZES: [usize; 5] = [10, 30, 100, 300, 1000];

fn chain(n: usize) -> Model {
    let mut b = ModelBuilder::new().timestep(0.01).gravity([0.0; 3]);
    for i in 0..n {
        let name = format!("link{i}");
        b = b.body(
            BodySpec::new(&name, 1.0, [1.0 / 12.0, 1.0 / 12.0, 1e-3]).pos([
                0.0,
                0.0,
                -(i as f64) - 0.5,
            ]),
        );
        let parent = if i == 0 {
            "world".to_string()
        } else {
            format!("link{}", i - 1)
        };
        let pa = if i == 0 { [0.0; 3] } else { [0.0, 0.0, -0.5] };
        b = b.joint(
            JointSpec::new(&format!("j{i}"), JointKind::Revolute, &parent, &name)
                .axis([0.0, 1.0, 0.0])
                .anchors(pa, [0.0, 0.0, 0.5]),
        );
    }
    b.compile().expect("chain compiles")
}

/// A typical state: bent and moving (joint rates in ±0.05 rad/s), simulated 20 steps.
fn warm_state(model: &Model) -> State {
    let mut state = State::reference(model);
    let n = model.nv;
    let qvel: Vec<f64> = (0..n).map(|i| 0.05 * ((i as f64) * 2.39).sin()).collect();
    set_minimal(model, &mut state, &vec![0.3 / n as f64; n], &qvel).expect("valid");
    let mut ws = Workspace::new(model);
    for _ in 0..20 {
        step(model, &mut state, &mut ws, &[]).expect("steps");
    }
    state
}

fn bench(c: &mut Criterion) {
    let mut group = c.benchmark_group("chain_step");
    for n in SIZES {
        let model = chain(n);
        let start = warm_state(&model);
        let mut ws = Workspace::new(&model);
        group.throughput(criterion::Throughput::Elements(1));
        group.bench_with_input(BenchmarkId::from_parameter(n), &n, |b, _| {
            b.iter_batched_ref(
                || start.clone(),
                |s| step(&model, s, &mut ws, &[]).expect("steps"),
                criterion::BatchSize::SmallInput,
            )
        });
    }
    group.finish();
    let _ = Throughput::Elements(1);
}

/// Least-squares slope of log(y) against log(N).
fn slope(pts: &[(f64, f64)]) -> f64 {
    let k = pts.len() as f64;
    let (mx, my) = pts
        .iter()
        .fold((0.0, 0.0), |a, p| (a.0 + p.0.ln() / k, a.1 + p.1.ln() / k));
    let num: f64 = pts.iter().map(|p| (p.0.ln() - mx) * (p.1.ln() - my)).sum();
    num / pts.iter().map(|p| (p.0.ln() - mx).powi(2)).sum::<f64>()
}

/// Time per step and per Newton iteration for each N, and the fitted exponents.
fn fitted_exponent() {
    let (mut per_step, mut per_iter) = (Vec::new(), Vec::new());
    for n in SIZES {
        let model = chain(n);
        let start = warm_state(&model);
        let mut ws = Workspace::new(&model);
        let reps = (20_000 / n).max(20);
        let (mut s, mut iters) = (start.clone(), 0usize);
        let t0 = Instant::now();
        for _ in 0..reps {
            s.clone_from(&start);
            iters += step(&model, &mut s, &mut ws, &[])
                .expect("steps")
                .iterations;
        }
        let per = t0.elapsed().as_secs_f64() / reps as f64;
        let it = iters as f64 / reps as f64;
        eprintln!(
            "N = {n:5}: {:9.1} µs/step, {it:.2} Newton iterations/step, {:.2} µs per body-iteration",
            per * 1e6,
            per * 1e6 / n as f64 / it.max(1.0)
        );
        per_step.push((n as f64, per));
        per_iter.push((n as f64, per / it.max(1.0)));
    }
    eprintln!(
        "fitted exponent vs N: time per step {:.3}, time per Newton iteration {:.3} (target <= 1.1)",
        slope(&per_step),
        slope(&per_iter)
    );
}

fn main() {
    fitted_exponent();
    let mut c = Criterion::default().configure_from_args().sample_size(20);
    bench(&mut c);
    c.final_summary();
}
