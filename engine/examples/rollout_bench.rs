//! The Table V rollout VJP on an MJCF model: one `rollout_vjp` over STEPS steps at dt = 0.01
//! with deterministic random controls (`common/workload.rs`), all-ones state adjoints,
//! minimal coordinates, no parameters; prints the seconds of the whole sweep (forward and
//! reverse) and of a plain forward rollout of the same controls, for instruction counts under
//! `valgrind --tool=callgrind`:
//! `cargo run --release -p ukemi-engine --example rollout_bench -- MODEL.xml [STEPS] [KAPPA_GRAD|none]`
#![allow(clippy::print_stdout)]
use ukemi_engine::gradients::rollout_vjp;
use ukemi_engine::{Coordinates, Workspace, step};

#[path = "common/workload.rs"]
mod workload;

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let path = args.get(1).expect("model path");
    let steps: usize = args.get(2).map_or(100, |s| s.parse().unwrap());
    let kappa: Option<f64> = args.get(3).and_then(|s| s.parse().ok());
    let model = workload::load(path);
    let state = workload::start_state(&model);
    let mut controls = workload::Controls::new();
    let ctrls: Vec<f64> = (0..steps).flat_map(|_| controls.next(&model)).collect();
    let ny = 2 * model.nv;
    let adjoint = vec![1.0; (steps + 1) * ny];
    let t0 = std::time::Instant::now();
    let (mut s, mut ws) = (state.clone(), Workspace::new(&model));
    for u in ctrls.chunks(model.nu().max(1)).take(steps) {
        let _ = step(&model, &mut s, &mut ws, u);
    }
    let forward = t0.elapsed().as_secs_f64();
    let t0 = std::time::Instant::now();
    let coords = Coordinates::Minimal;
    let result = rollout_vjp(
        &model, &state, &ctrls, steps, &adjoint, coords, kappa, false,
    );
    let vjp = t0.elapsed().as_secs_f64();
    let norm = result
        .as_ref()
        .map(|r| r.ctrls.iter().map(|x| x * x).sum::<f64>().sqrt());
    println!(
        "{path}: {steps} steps, kappa_grad {kappa:?}: forward {forward:.3} s, rollout VJP {vjp:.3} s (|adj ctrls| {norm:?})"
    );
}
