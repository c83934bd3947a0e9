//! The interior-point iterations of one step of the Table V workload (dt = 0.01, controls from
//! `workload::Controls`), for diagnosing a hard step:
//! `cargo run --release -p ukemi-engine --example trace_step -- MODEL.xml STEP [SEED]`
//! Prints the steps before STEP that took over 100 iterations, then one line per iteration of
//! STEP (attempt, residual, complementarity, μ, affine and accepted step lengths, whether the
//! corrected direction was taken). Attempts restart per sub-step of a subdivided step.
//! `UKEMI_TRACE_MAX_ITER=N` solves the traced step (only) with an iteration budget of N, and
//! `UKEMI_TRACE_CTRL=u1,u2,...` with those controls. `UKEMI_TRACE_CTRLS=FILE` takes every
//! step's controls from FILE, one step per line, separated by commas or white space (e.g. a Python
//! run's controls written with `np.savetxt(FILE, ctrls, delimiter=",")`). `UKEMI_TRACE_WHOLE=1`
//! takes the traced step without sub-steps, so that the whole step's attempts are the ones
//! traced; `UKEMI_TRACE_LOADED=1` lists the candidates that end the step with a normal impulse,
//! `UKEMI_TRACE_GAPS=1` those within 1 mm of contact (or penetrating) at its start, and
//! `UKEMI_TRACE_LINEAR=1` takes the traced step also with pyramid friction cones and then with
//! the exact cones warm-started from the pyramid's impulses (`step::pyramid_step`).
#![allow(clippy::print_stdout)]
use ukemi_engine::{Workspace, step};

#[path = "common/workload.rs"]
mod workload;

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let model = workload::load(&args[1]);
    let which: usize = args.get(2).map_or(0, |s| s.parse().unwrap());
    let mut state = workload::start_state(&model);
    let mut ws = Workspace::new(&model);
    let mut controls = match args.get(3) {
        Some(s) => workload::Controls::with_seed(s.parse().unwrap()),
        None => workload::Controls::new(),
    };
    // UKEMI_TRACE_CTRL=u1,u2,...: these controls for the traced step instead
    let given: Option<Vec<f64>> = std::env::var("UKEMI_TRACE_CTRL")
        .ok()
        .map(|s| s.split(',').map(|x| x.trim().parse().unwrap()).collect());
    // UKEMI_TRACE_CTRLS=FILE: each step's controls from a file, one line per step
    let from_file: Option<Vec<Vec<f64>>> = std::env::var("UKEMI_TRACE_CTRLS")
        .ok()
        .map(|f| workload::read_rows(&f));
    for k in 0..=which {
        let mut ctrl = controls.next(&model);
        if let Some(rows) = &from_file {
            let row = rows
                .get(k)
                .unwrap_or_else(|| panic!("no controls for step {k} in the file"));
            assert_eq!(
                row.len(),
                model.nu(),
                "step {k}: {} controls, the model has {}",
                row.len(),
                model.nu()
            );
            ctrl.clone_from(row);
        }
        if let (true, Some(u)) = (k == which, &given) {
            ctrl.clone_from(u);
        }
        ws.set_trace(k == which, false);
        // UKEMI_TRACE_MAX_ITER: another iteration budget for the traced step only
        let long = std::env::var("UKEMI_TRACE_MAX_ITER").ok().map(|n| {
            let mut o = model.options.clone();
            o.max_iter = n.parse().unwrap();
            model.with_options(o).unwrap()
        });
        // UKEMI_TRACE_WHOLE: the traced step without sub-steps (its whole-step attempts traced)
        let long = match std::env::var("UKEMI_TRACE_WHOLE") {
            Ok(_) => {
                let mut o = long.as_ref().unwrap_or(&model).options.clone();
                o.max_subdivisions = 1;
                Some(model.with_options(o).unwrap())
            }
            Err(_) => long,
        };
        let m = if k == which {
            long.as_ref().unwrap_or(&model)
        } else {
            &model
        };
        if k == which && std::env::var("UKEMI_TRACE_GAPS").is_ok() {
            // the candidates within 1 mm (or penetrating) at the start of the traced step
            let phi = ukemi_engine::contact::signed_distances(&model, &state);
            for (c, d) in phi.iter().enumerate().filter(|(_, d)| **d < 1e-3) {
                let ct = &model.contacts[c];
                let (a, b) = (&model.geoms[ct.geom_a].name, &model.geoms[ct.geom_b].name);
                println!("  start: candidate {c} {a} / {b}: signed distance {d:.3e} m");
            }
        }
        if k == which && std::env::var("UKEMI_TRACE_LINEAR").is_ok() {
            // the traced step with pyramid friction cones instead of the exact ones
            use ukemi_engine::ContactModel::{Linear, Nonlinear};
            let lin = m.with_contact_model(Nonlinear, Linear).unwrap();
            let mut s = state.moved_to(&lin);
            let mut w = Workspace::new(&lin);
            let t = std::time::Instant::now();
            let r = step(&lin, &mut s, &mut w, &ctrl).unwrap();
            println!(
                "linear friction: {:?}, {} iterations, {} sub-steps, residual {:.2e}, {:.1} ms",
                r.status,
                r.iterations,
                r.subdivisions,
                r.residual,
                t.elapsed().as_secs_f64() * 1e3
            );
            // and the exact cones warm-started from the pyramid's impulses
            let forces = ukemi_engine::AppliedForces::default();
            let pyramid = ukemi_engine::step::pyramid_step(m, &state, &ctrl, &forces).unwrap();
            if let Some(mut warm) =
                pyramid.and_then(|(p, _)| ukemi_engine::step::warm_started_from(&state, &p))
            {
                let t = std::time::Instant::now();
                let r = step(m, &mut warm, &mut Workspace::new(m), &ctrl).unwrap();
                println!(
                    "exact from the pyramid's impulses: {:?}, {} iterations, {} sub-steps, {:.1} ms",
                    r.status,
                    r.iterations,
                    r.subdivisions,
                    t.elapsed().as_secs_f64() * 1e3
                );
            }
        }
        let r = step(m, &mut state, &mut ws, &ctrl).unwrap();
        if k < which && r.iterations > 100 {
            println!(
                "step {k}: {} iterations, {} sub-steps",
                r.iterations, r.subdivisions
            );
        }
        if k == which {
            println!(
                "step {k}: {} iterations, {:?}, {} sub-steps, {} active candidates",
                r.iterations,
                r.status,
                r.subdivisions,
                ws.active_contacts()
            );
            if std::env::var("UKEMI_TRACE_LOADED").is_ok() {
                let impulse = state.contact_impulse(&model);
                for (c, f) in impulse.chunks(3).enumerate().filter(|(_, f)| f[0] > 1e-6) {
                    let ct = &model.contacts[c];
                    let (a, b) = (&model.geoms[ct.geom_a].name, &model.geoms[ct.geom_b].name);
                    println!(
                        "  candidate {c} {a} / {b}: impulse normal {:.3e} tangential {:.3e} {:.3e}",
                        f[0], f[1], f[2]
                    );
                }
            }
            for (i, t) in ws.trace().iter().enumerate() {
                println!(
                    "{i:4} attempt {} residual {:.2e} compl {:.2e} mu {:.2e} alpha_aff {:.2e} alpha {:.2e} corrector {}",
                    t.attempt,
                    t.residual,
                    t.complementarity,
                    t.mu,
                    t.alpha_aff,
                    t.alpha,
                    t.corrector
                );
            }
        }
    }
}
