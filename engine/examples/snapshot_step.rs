//! Keep a step of the Table V workload as a fixture: the state before step STEP of the
//! controls of SEED (`step_bench`'s), bit for bit with its warm start ([`State::snapshot`]),
//! and that step's controls:
//! `cargo run --release -p ukemi-engine --example snapshot_step -- ROBOT STEP SEED [as_found] > FILE`
//! (ROBOT: a model of `../shared/models/`, e.g. `humanoid`; `as_found`: the trajectory taken
//! with the warm-start widening of before session 31, `warm_start_widening` 1e-3 and none
//! relative to the weight). A hard step found by a chaotic trajectory moves whenever a solver
//! change moves the trajectory; kept this way, the tests of `tests/hard_steps.rs` keep
//! stepping the state that was hard.
#![allow(clippy::print_stdout)]
use ukemi_engine::{Model, Options, Workspace, step};

#[allow(dead_code)]
#[path = "common/workload.rs"]
mod workload;

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let robot = args.get(1).expect("robot name, e.g. humanoid");
    let at: usize = args.get(2).expect("step").parse().unwrap();
    let seed: u64 = args.get(3).expect("seed").parse().unwrap();
    let as_found = args.get(4).is_some_and(|a| a == "as_found");
    let model = workload::shared(robot).expect("../shared/models");
    let stepping: Model = if as_found {
        model
            .with_options(Options {
                warm_start_widening: 1e-3,
                warm_start_widening_weight: 0.0,
                ..model.options.clone()
            })
            .unwrap()
    } else {
        model.clone()
    };
    let mut state = workload::start_state(&model);
    let mut ws = Workspace::new(&model);
    let mut controls = workload::Controls::with_seed(seed);
    for k in 0..at {
        let u = controls.next(&model);
        let r = step(&stepping, &mut state, &mut ws, &u).unwrap();
        assert!(r.status.is_success(), "step {k} failed: {r:?}");
    }
    let u = controls.next(&model);
    let line = |xs: &[f64]| xs.iter().map(|x| format!("{x:?}")).collect::<Vec<_>>();
    let found = if as_found { ", options as found" } else { "" };
    println!("# {robot}, seed {seed}, the state before step {at}{found}");
    println!("robot {robot}");
    println!("ctrl {}", line(&u).join(" "));
    println!("state {}", line(&state.snapshot()).join(" "));
}
