//! How much a step's contact solve could gain from knowing its answer, on the Table V workload
//! (dt = 0.01, controls from `workload::Controls` of SEED):
//! `cargo run --release -p ukemi-engine --example contact_modes -- MODEL.xml [STEPS] [SEED]`
//!
//! Prints two measures:
//! - **Mode stability**: how many steps end with every contact candidate in the same mode as
//!   the step before (apart, sticking inside its friction cone, or sliding on its boundary),
//!   and the transitions between modes. An active-set method that guesses the modes from the
//!   last step pays only where they stay.
//! - **Oracle warm start**: the iterations of each step, and of the same step solved again
//!   warm-started from its own solution's impulses (`step::warm_started_from`): what a perfect
//!   prediction of the impulses would save the interior-point solve.
#![allow(clippy::print_stdout)]
use ukemi_engine::{Model, State, Workspace, step};

#[allow(dead_code)]
#[path = "common/workload.rs"]
mod workload;

/// Each candidate's mode at the end of the step that made `state`: 0 apart (normal impulse
/// under 1e-6 N·s), 1 sticking (friction under `(1 - 1e-4) μ` times the normal impulse), 2
/// sliding.
fn modes(model: &Model, state: &State) -> Vec<usize> {
    let f = state.contact_impulse(model);
    let mode = |(c, contact): (usize, &ukemi_engine::contact::Contact)| {
        let (normal, friction) = (f[3 * c], f[3 * c + 1].hypot(f[3 * c + 2]));
        match normal {
            n if n < 1e-6 => 0,
            n if friction < contact.friction * n * (1.0 - 1e-4) => 1,
            _ => 2,
        }
    };
    model.contacts.iter().enumerate().map(mode).collect()
}

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let path = args.get(1).expect("model path");
    let steps: usize = args.get(2).map_or(300, |s| s.parse().unwrap());
    let seed: u64 = args.get(3).map_or(1, |s| s.parse().unwrap());
    let model = workload::load(path);
    let mut state = workload::start_state(&model);
    let (mut ws, mut oracle_ws) = (Workspace::new(&model), Workspace::new(&model));
    let mut controls = workload::Controls::with_seed(seed);
    // (a fresh state's warm start is the neutral point, not a solution: modes from step 1 on)
    let mut prev: Option<Vec<usize>> = None;
    let (mut same, mut loaded, mut changes) = (0, 0, 0);
    let mut transitions = [[0usize; 3]; 3];
    let (mut iterations, mut oracle_iterations, mut oracle_steps) = (0, 0, 0);
    for _ in 0..steps {
        let ctrl = controls.next(&model);
        let start = state.clone();
        iterations += step(&model, &mut state, &mut ws, &ctrl).unwrap().iterations;
        if let Some(mut warm) = ukemi_engine::step::warm_started_from(&start, &state) {
            oracle_iterations += step(&model, &mut warm, &mut oracle_ws, &ctrl)
                .unwrap()
                .iterations;
            oracle_steps += 1;
        }
        let now = modes(&model, &state);
        loaded += usize::from(now.iter().any(|&m| m > 0));
        if let Some(prev) = &prev {
            let changed = now.iter().zip(prev).filter(|(a, b)| a != b).count();
            for (&to, &from) in now.iter().zip(prev) {
                if to != 0 || from != 0 {
                    transitions[from][to] += 1;
                }
            }
            same += usize::from(changed == 0);
            changes += changed;
        }
        prev = Some(now);
    }
    let compared = steps.saturating_sub(1).max(1);
    println!(
        "{path}: {steps} steps (seed {seed}), {loaded} with a loaded contact; {same} of {compared} \
         with every candidate's mode as the step before, {:.2} mode changes a step",
        changes as f64 / compared as f64
    );
    let names = ["apart", "sticking", "sliding"];
    for (from, row) in transitions.iter().enumerate() {
        let to: Vec<String> = (row.iter().zip(names))
            .map(|(n, name)| format!("{name} {n}"))
            .collect();
        println!("  from {:8}: {}", names[from], to.join(", "));
    }
    println!(
        "  iterations a step {:.2}; warm-started from its own solution {:.2} ({oracle_steps} steps)",
        iterations as f64 / steps as f64,
        oracle_iterations as f64 / oracle_steps.max(1) as f64
    );
}
