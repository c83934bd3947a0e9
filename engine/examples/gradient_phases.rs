//! Per-phase timing of step Jacobians on an MJCF model (Table V workload: dt = 0.01, random
//! controls in the control range, full minimal-coordinate A and B every step):
//! `cargo run --release -p ukemi-engine --example gradient_phases -- MODEL.xml [STEPS] [KAPPA_GRAD]`.
//! Prints the mean milliseconds per step of the solve, the central-path move, the factorisation,
//! the partial derivatives and the back-substitutions, and the number of failed linearisations.
#![allow(clippy::print_stdout)]
use std::time::Instant;

use ukemi_engine::gradients::PhaseTimes;
use ukemi_engine::{Coordinates, Linearization, State, Workspace, Wrt, mjcf, set_minimal, step};

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let path = args.get(1).expect("model path");
    let steps: usize = args.get(2).map_or(20, |s| s.parse().unwrap());
    let kappa: Option<f64> = args.get(3).map(|s| s.parse().unwrap());
    let model = mjcf::load_path(std::path::Path::new(path)).unwrap().model;
    let mut opts = model.options.clone();
    opts.timestep = 0.01;
    let model = model.with_options(opts).unwrap();
    let mut state = State::reference(&model);
    let (qpos, qvel) = match model.keyframes.first() {
        Some(k) => (k.qpos.clone(), k.qvel.clone()),
        None => (model.qpos0.clone(), vec![0.0; model.nv]),
    };
    set_minimal(&model, &mut state, &qpos, &qvel).unwrap();
    let mut ws = Workspace::new(&model);
    // deterministic controls uniform in the control range
    let mut seed = 12345u64;
    let mut rand = move || {
        seed = seed.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
        (seed >> 11) as f64 / (1u64 << 53) as f64
    };
    let mut sum = PhaseTimes::default();
    let (mut failed, mut total) = (0, 0.0);
    for _ in 0..steps {
        let ctrl: Vec<f64> = model
            .actuators
            .iter()
            .map(|a| {
                let (lo, hi) = a.ctrlrange.unwrap_or((-1.0, 1.0));
                lo + (hi - lo) * rand()
            })
            .collect();
        let t0 = Instant::now();
        match Linearization::new(&model, &state, &ctrl, Coordinates::Minimal, Wrt::STATE_CTRL, kappa) {
            Ok(mut lin) => {
                lin.jacobians(&model).unwrap();
                let t = lin.phase_times();
                sum.solve += t.solve;
                sum.central += t.central;
                sum.factor += t.factor;
                sum.partials += t.partials;
                sum.backsub += t.backsub;
                state = lin.next_state().clone();
            }
            Err(e) => {
                failed += 1;
                if failed <= 3 {
                    println!("failed: {e}");
                }
                let _ = step(&model, &mut state, &mut ws, &ctrl);
            }
        }
        total += t0.elapsed().as_secs_f64();
    }
    let ok = (steps - failed).max(1) as f64;
    let ms = |x: f64| 1e3 * x / ok;
    println!(
        "{path}: nv {} nu {} ncontact {}, {steps} steps, kappa_grad {kappa:?}: ms/step over {} linearised: solve {:.2} central {:.2} factor {:.3} partials {:.2} backsub {:.3}; total {:.2} ms/step (all steps); failed {failed}",
        model.nv,
        model.nu(),
        model.ncontact(),
        steps - failed,
        ms(sum.solve),
        ms(sum.central),
        ms(sum.factor),
        ms(sum.partials),
        ms(sum.backsub),
        1e3 * total / steps as f64
    );
}
