//! Time contact-rich steps of an MJCF model from a keyframe with zero control:
//! `cargo run --release -p ukemi-engine --example contact_bench -- MODEL.xml [KEYFRAME] [STEPS]`.
//! Prints ms/step, IPM iterations (mean, max), unconverged steps and the mean number of active
//! contact candidates. `BENCH_MARGIN=0.01` sets `Options::activation_margin`; `BENCH_VERBOSE=1`
//! prints the initial distance distribution and every step.
#![allow(clippy::print_stdout)]
use std::time::Instant;

use ukemi_engine::{SolveStatus, State, Workspace, mjcf, set_minimal, step};

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let path = args.get(1).expect("model path");
    let key = args.get(2).map(String::as_str).unwrap_or("");
    let steps: usize = args.get(3).map_or(200, |s| s.parse().unwrap());
    let mut model = mjcf::load_path(std::path::Path::new(path)).unwrap().model;
    let mut state = State::reference(&model);
    let (qpos, qvel) = match model.keyframes.iter().find(|k| k.name == key) {
        Some(k) => (k.qpos.clone(), k.qvel.clone()),
        None => (model.qpos0.clone(), vec![0.0; model.nv]),
    };
    set_minimal(&model, &mut state, &qpos, &qvel).unwrap();
    let mut ws = Workspace::new(&model);
    let ctrl = vec![0.0; model.nu()];
    let (mut iters, mut max_it, mut bad, mut active) = (0usize, 0usize, 0usize, 0usize);
    let verbose = std::env::var_os("BENCH_VERBOSE").is_some();
    if let Some(m) = std::env::var("BENCH_MARGIN")
        .ok()
        .and_then(|s| s.parse::<f64>().ok())
    {
        let mut o = model.options.clone();
        o.activation_margin = m;
        model = model.with_options(o).unwrap();
    }
    if verbose {
        let mut d = ukemi_engine::contact::signed_distances(&model, &state);
        d.sort_by(f64::total_cmp);
        let q = |f: f64| d[((d.len() - 1) as f64 * f) as usize];
        println!(
            "initial distances: min {:.3e} p10 {:.3e} p50 {:.3e} p90 {:.3e}; below 1 mm: {}, below 1 cm: {}",
            q(0.0),
            q(0.1),
            q(0.5),
            q(0.9),
            d.iter().filter(|&&x| x < 1e-3).count(),
            d.iter().filter(|&&x| x < 1e-2).count()
        );
    }
    let mut statuses = Vec::new();
    let t0 = Instant::now();
    for _ in 0..steps {
        let r = step(&model, &mut state, &mut ws, &ctrl).unwrap();
        iters += r.iterations;
        active += ws.active_contacts();
        if verbose {
            println!(
                "step {:.4}: {} it {} active {}",
                state.time,
                r.status.name(),
                r.iterations,
                ws.active_contacts()
            );
        }
        max_it = max_it.max(r.iterations);
        if r.status != SolveStatus::Converged {
            bad += 1;
            statuses.push(r.status.name());
        }
    }
    let dt = t0.elapsed().as_secs_f64();
    println!(
        "{path} key={key:?} ncontact={} steps={steps}: {:.3} ms/step, iterations mean {:.2} max {max_it}, unconverged {bad} {:?}, active candidates mean {:.1}",
        model.ncontact(),
        1e3 * dt / steps as f64,
        iters as f64 / steps as f64,
        statuses.iter().take(5).collect::<Vec<_>>(),
        active as f64 / steps as f64
    );
}
