//! Which steps of the Table V workload fail, from the exact states and from the same states
//! rebuilt from their minimal coordinates (what `rollout_vjp`, the flat JAX/torch layers and
//! `step_jacobians` in minimal coordinates step from):
//! `cargo run --release -p ukemi-engine --example rebuilt_scan -- MODEL.xml SEED` (controls of
//! `step_bench` with that seed, 300 steps; the trajectory follows the exact states). Prints the
//! failing step indices of each.
#![allow(clippy::print_stdout)]
use ukemi_engine::{Workspace, qpos, qvel, set_minimal, step};
#[allow(dead_code)]
#[path = "common/workload.rs"]
mod workload;
fn main() {
    let args: Vec<String> = std::env::args().collect();
    let model = workload::load(&args[1]);
    let seed: u64 = args[2].parse().unwrap();
    let mut state = workload::start_state(&model);
    let mut ws = Workspace::new(&model);
    let mut ws2 = Workspace::new(&model);
    let mut controls = workload::Controls::with_seed(seed);
    let (mut exact_fail, mut rebuilt_fail) = (Vec::new(), Vec::new());
    for k in 0..300 {
        let u = controls.next(&model);
        let mut rebuilt = state.clone();
        set_minimal(
            &model,
            &mut rebuilt,
            &qpos(&model, &state),
            &qvel(&model, &state),
        )
        .unwrap();
        let r = step(&model, &mut rebuilt, &mut ws2, &u).unwrap();
        if !r.status.is_success() {
            rebuilt_fail.push(k);
        }
        let r = step(&model, &mut state, &mut ws, &u).unwrap();
        if !r.status.is_success() {
            exact_fail.push(k);
        }
    }
    println!(
        "{} seed {seed}: exact fails {exact_fail:?} rebuilt fails {rebuilt_fail:?}",
        args[1]
    );
}
