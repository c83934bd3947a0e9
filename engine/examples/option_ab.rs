//! A/B of a solver option on the same states, free of the chaos that makes two trajectories
//! meet different hard steps: the Table V workload (dt = 0.01, controls uniform in the control
//! range) runs with option value A, and every step is also solved from the same state with
//! value B. `cargo run --release -p ukemi-engine --example option_ab -- MODEL.xml STEPS SEED
//! OPTION A B` (SEED `default`: `step_bench`'s controls without a seed), OPTION one of
//! `acceptable_iter`, `stall_iter`, `endgame_iter`, `max_iter`, `kappa_tol`, `rtol`, `cone_gap`, `activation_margin`, `drop_redundant_friction`, `warm_start_widening`, `warm_start_margin`, `tau_min`, `tau_max`, `undercut`, `friction_proximal`. Prints, for A and B, the total iterations and seconds, the slowest step, failed
//! steps, and the largest difference of the next states' positions (m); with `AB_VERBOSE=1`
//! every step whose positions differ by more than 1e-7 m, with the energies before and after.
#![allow(clippy::print_stdout)]
use std::time::Instant;

use ukemi_engine::{Model, Workspace, step};

#[path = "common/workload.rs"]
mod workload;

fn with(model: &Model, option: &str, value: f64) -> Model {
    let mut o = model.options.clone();
    match option {
        "acceptable_iter" => o.acceptable_iter = value as usize,
        "stall_iter" => o.stall_iter = value as usize,
        "endgame_iter" => o.endgame_iter = value as usize,
        "max_iter" => o.max_iter = value as usize,
        "kappa_tol" => o.kappa_tol = value,
        "rtol" => o.rtol = value,
        "cone_gap" => o.cone_gap = value != 0.0,
        "drop_redundant_friction" => o.drop_redundant_friction = value != 0.0,
        "activation_margin" => o.activation_margin = value,
        "warm_start_widening" => o.warm_start_widening = value,
        "warm_start_margin" => o.warm_start_margin = value,
        "tau_min" => o.tau_min = value,
        "friction_proximal" => o.friction_proximal = value,
        "warm_start_widening_weight" => o.warm_start_widening_weight = value,
        "tau_max" => o.tau_max = value,
        "undercut" => o.undercut = value,
        _ => panic!("unknown option {option}"),
    }
    model.with_options(o).unwrap()
}

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let base = workload::load(&args[1]);
    let steps: usize = args[2].parse().unwrap();
    let option = &args[4];
    let (va, vb): (f64, f64) = (args[5].parse().unwrap(), args[6].parse().unwrap());
    let models = [with(&base, option, va), with(&base, option, vb)];
    let mut state = workload::start_state(&base);
    let mut ws = [Workspace::new(&base), Workspace::new(&base)];
    // SEED `default`: the control sequence of `step_bench` without a seed
    let mut controls = match args[3].as_str() {
        "default" => workload::Controls::new(),
        seed => workload::Controls::with_seed(seed.parse().unwrap()),
    };
    let (mut its, mut secs, mut worst, mut failed) =
        ([0usize; 2], [0.0f64; 2], [0.0f64; 2], [0; 2]);
    let mut diff: f64 = 0.0;
    for i in 0..steps {
        let ctrl = controls.next(&base);
        let mut next = [state.clone(), state.clone()];
        let mut reports = Vec::new();
        for k in [1, 0] {
            let t0 = Instant::now();
            let r = step(&models[k], &mut next[k], &mut ws[k], &ctrl).unwrap();
            let dt = t0.elapsed().as_secs_f64();
            its[k] += r.iterations;
            secs[k] += dt;
            worst[k] = worst[k].max(dt);
            failed[k] += usize::from(!r.status.is_success());
            reports.push(r);
        }
        let mut d: f64 = 0.0;
        for b in 1..base.nbody() {
            d = d.max((next[0].pose(b).pos - next[1].pose(b).pos).amax());
        }
        if d > 1e-7 && std::env::var("AB_VERBOSE").is_ok() {
            let e = |s: &ukemi_engine::State| ukemi_engine::mechanics::total_energy(&base, s);
            println!(
                "step {i}: positions differ by {d:.2e} m; B {:?}; A {:?}; energy {:.6} J -> A {:.6} J, B {:.6} J",
                reports[0],
                reports[1],
                e(&state),
                e(&next[0]),
                e(&next[1])
            );
            let (fa, fb) = (
                next[0].contact_impulse(&base),
                next[1].contact_impulse(&base),
            );
            for (c, (x, y)) in fa.chunks(3).zip(fb.chunks(3)).enumerate() {
                if (x[0] - y[0]).abs() + (x[1] - y[1]).abs() + (x[2] - y[2]).abs() > 1e-4 {
                    println!("  contact {c}: A {x:?} B {y:?}");
                }
            }
        }
        diff = diff.max(d);
        let [a, _] = next;
        state = a;
    }
    for (k, v) in [va, vb].iter().enumerate() {
        println!(
            "{option} = {v}: {} iterations, {:.3} s, slowest step {:.1} ms, {} failed",
            its[k],
            secs[k],
            1e3 * worst[k],
            failed[k]
        );
    }
    println!("largest difference of a step's next positions: {diff:.2e} m");
}
