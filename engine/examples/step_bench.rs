//! Forward-step speed on an MJCF model, the Table V workload without Jacobians (dt = 0.01,
//! controls uniform in the control range, the same generator as `gradient_phases`):
//! `cargo run --release -p ukemi-engine --example step_bench -- MODEL.xml [STEPS] [REPEATS] [SEED]`
//! (SEED: another control sequence than the default one; `UKEMI_SLOWEST=N` lists the N slowest
//! steps; `UKEMI_DUMP=1` prints every body's final position, quaternion and velocities, to see
//! how far two builds' trajectories drift apart).
//! Prints the best-of-`REPEATS` ms/step, the IPM iterations per step (mean, median, max, and
//! the mean with each step capped at 100, which the rare stalled steps do not dominate), the
//! share of the run's time spent in its slowest 1% of steps, the
//! steps that were not converged, were taken with pyramid friction cones or were subdivided, the mean active contact candidates, and a fingerprint of the final state (bits
//! of every position, orientation and velocity) to check that a speed change kept the physics
//! bit for bit.
#![allow(clippy::print_stdout)]
use std::time::Instant;

use ukemi_engine::{Workspace, step};

#[path = "common/workload.rs"]
mod workload;

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let path = args.get(1).expect("model path");
    let steps: usize = args.get(2).map_or(100, |s| s.parse().unwrap());
    let repeats: usize = args.get(3).map_or(1, |s| s.parse().unwrap());
    let seed: Option<u64> = args.get(4).map(|s| s.parse().unwrap());
    let model = workload::load(path);
    // UKEMI_SLOWEST=N: list the N slowest steps of each repeat
    let slowest: Option<usize> = std::env::var("UKEMI_SLOWEST")
        .ok()
        .map(|s| s.parse().unwrap());
    let mut best = f64::INFINITY;
    let mut last = None;
    for _ in 0..repeats {
        let mut state = workload::start_state(&model);
        let mut ws = Workspace::new(&model);
        let mut controls = match seed {
            Some(seed) => workload::Controls::with_seed(seed),
            None => workload::Controls::new(),
        };
        let ctrls: Vec<Vec<f64>> = (0..steps).map(|_| controls.next(&model)).collect();
        let (mut its, mut failed, mut subdivided, mut active, mut loaded) =
            (Vec::new(), 0, 0, 0, 0);
        let (mut limits, mut pyramid) = (0, 0);
        let mut times = Vec::with_capacity(steps);
        let mut per_step = Vec::with_capacity(steps);
        let t0 = Instant::now();
        for (k, ctrl) in ctrls.iter().enumerate() {
            let ts = Instant::now();
            let r = step(&model, &mut state, &mut ws, ctrl).unwrap();
            times.push(ts.elapsed().as_secs_f64());
            per_step.push((ts.elapsed().as_secs_f64(), k, r.iterations, r.subdivisions));
            its.push(r.iterations);
            failed += usize::from(!r.status.is_success());
            subdivided += usize::from(r.subdivisions > 1);
            pyramid += usize::from(r.status == ukemi_engine::SolveStatus::PyramidFriction);
            active += ws.active_contacts();
            limits += ws.active_limits();
            loaded += state
                .contact_impulse(&model)
                .chunks(3)
                .filter(|f| f[0] > 1e-5)
                .count();
        }
        best = best.min(t0.elapsed().as_secs_f64());
        let mut print = 0u64;
        for b in 1..model.nbody() {
            let p = state.pose(b);
            if std::env::var("UKEMI_DUMP").is_ok() {
                let (v, w) = state.velocity(b);
                println!(
                    "dump {b} {:?} {:?} {:?} {:?}",
                    p.pos.as_slice(),
                    p.quat.coords.as_slice(),
                    v.as_slice(),
                    w.as_slice()
                );
            }
            let (v, w) = state.velocity(b);
            for x in p.pos.iter().chain(p.quat.coords.iter()).chain(&v).chain(&w) {
                print = print.rotate_left(5) ^ x.to_bits();
            }
        }
        times.sort_unstable_by(|a, b| b.total_cmp(a));
        if let Some(n) = slowest {
            per_step.sort_unstable_by(|a, b| b.0.total_cmp(&a.0));
            for (t, k, it, sub) in per_step.iter().take(n) {
                println!(
                    "  step {k:5}: {:.3} ms, {it} iterations, {sub} sub-steps",
                    1e3 * t
                );
            }
        }
        let slow = times.iter().take(steps.div_ceil(100)).sum::<f64>() / times.iter().sum::<f64>();
        last = Some((
            its, failed, subdivided, active, loaded, limits, print, slow, pyramid,
        ));
    }
    let (mut its, failed, subdivided, active, loaded, limits, print, slow, pyramid) = last.unwrap();
    let total: usize = its.iter().sum();
    its.sort_unstable();
    println!(
        "{path}: {steps} steps, {:.3} ms/step (best of {repeats}); iterations/step mean {:.2} median {} max {} (capped at 100: mean {:.2}); slowest 1% of steps {:.0}% of the time; unconverged {failed}, pyramid friction {pyramid}, subdivided {subdivided}; active candidates {:.1} of {} ({:.1} with a normal impulse); limited joints active {:.1}; state fingerprint {print:016x}",
        1e3 * best / steps as f64,
        total as f64 / steps as f64,
        its[steps / 2],
        its[steps - 1],
        its.iter().map(|&i| i.min(100)).sum::<usize>() as f64 / steps as f64,
        100.0 * slow,
        active as f64 / steps as f64,
        model.ncontact(),
        loaded as f64 / steps as f64,
        limits as f64 / steps as f64,
    );
}
