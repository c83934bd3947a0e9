//! Per-phase timing of step Jacobians on an MJCF model (Table V workload: dt = 0.01, random
//! controls in the control range, full minimal-coordinate A and B every step):
//! `cargo run --release -p ukemi-engine --example gradient_phases -- MODEL.xml [STEPS] [KAPPA_GRAD|none] [coloured] [neutral] [maximal]`
//! (`coloured` skips the column-by-column reference; `neutral` starts the central-path solve
//! from the neutral point, `Options::central_warm_start = false`; `maximal` takes the
//! Jacobians in maximal coordinates).
//! Linearises every step twice, with the coloured partials and with the column-by-column
//! reference, and prints for each the mean milliseconds per step of the solve, the
//! central-path move, the factorisation, the partial derivatives and the back-substitutions,
//! the residual evaluations, and the largest difference between the two Jacobians; with
//! `KAPPA_GRAD`, the central-path solve's iterations and how often it fell back to the neutral
//! start; and a fingerprint of the coloured Jacobians' bits (to compare two builds).
#![allow(clippy::print_stdout)]
use ukemi_engine::{Coordinates, Linearization, PartialsMethod, PhaseTimes, Workspace, Wrt, step};

#[path = "common/workload.rs"]
mod workload;

#[derive(Default)]
struct Sum {
    t: PhaseTimes,
    evaluations: usize,
    n: usize,
    central_iterations: Vec<usize>,
    fallbacks: usize,
}

impl Sum {
    fn add(&mut self, lin: &Linearization) {
        let t = lin.phase_times();
        self.t.solve += t.solve;
        self.t.central += t.central;
        self.t.factor += t.factor;
        self.t.partials += t.partials;
        self.t.backsub += t.backsub;
        self.evaluations += lin.residual_evaluations();
        self.n += 1;
        if let Some(c) = lin.central_report() {
            self.central_iterations.push(c.iterations);
            self.fallbacks += usize::from(lin.central_fallback());
        }
    }
    fn print(&self, name: &str) {
        let ms = |x: f64| 1e3 * x / self.n.max(1) as f64;
        println!(
            "  {name:16} ms/step: solve {:7.3}  central {:7.3}  factor {:6.3}  partials {:6.3}  backsub {:6.3}  | residual evaluations/step {:.0}",
            ms(self.t.solve),
            ms(self.t.central),
            ms(self.t.factor),
            ms(self.t.partials),
            ms(self.t.backsub),
            self.evaluations as f64 / self.n.max(1) as f64
        );
        let its = &self.central_iterations;
        if !its.is_empty() {
            println!(
                "  {:16} central iterations mean {:.1} max {}, fallbacks to the neutral start {}",
                "",
                its.iter().sum::<usize>() as f64 / its.len() as f64,
                its.iter().max().unwrap_or(&0),
                self.fallbacks
            );
        }
    }
}

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let path = args.get(1).expect("model path");
    let steps: usize = args.get(2).map_or(20, |s| s.parse().unwrap());
    let kappa: Option<f64> = args.get(3).and_then(|s| s.parse().ok());
    let flag = |f: &str| args.iter().skip(4).any(|s| s == f);
    let with_reference = !flag("coloured");
    let maximal = flag("maximal");
    let mut print = 0u64;
    let model = workload::load(path);
    let mut opts = model.options.clone();
    opts.central_warm_start = !flag("neutral");
    let model = model.with_options(opts).unwrap();
    let mut state = workload::start_state(&model);
    let mut ws = Workspace::new(&model);
    // deterministic controls uniform in the control range
    let mut controls = workload::Controls::new();
    let (mut coloured, mut reference) = (Sum::default(), Sum::default());
    let (mut failed, mut central_failed, mut worst) = (0, 0, 0.0f64);
    let (mut plain, mut with_jac) = (0.0, 0.0);
    for _ in 0..steps {
        let ctrl = controls.next(&model);
        let lin = |m| {
            let c = match maximal {
                true => Coordinates::Maximal,
                false => Coordinates::Minimal,
            };
            Linearization::with_method(&model, &state, &ctrl, c, Wrt::STATE_CTRL, kappa, m)
        };
        // a plain step from the same state, for the gradient overhead
        let t0 = std::time::Instant::now();
        let _ = step(&model, &mut state.clone(), &mut ws, &ctrl);
        plain += t0.elapsed().as_secs_f64();
        let t0 = std::time::Instant::now();
        let coloured_lin = lin(PartialsMethod::Coloured).and_then(|mut a| {
            let ja = a.jacobians(&model)?;
            Ok((a, ja))
        });
        with_jac += t0.elapsed().as_secs_f64();
        let both = coloured_lin.and_then(|(a, ja)| {
            let b = with_reference
                .then(|| lin(PartialsMethod::ColumnByColumn))
                .transpose()?;
            Ok((a, ja, b))
        });
        match both {
            Ok((a, ja, b)) => {
                coloured.add(&a);
                for x in ja.a.iter().chain(ja.b.iter()) {
                    print = print.rotate_left(5) ^ x.to_bits();
                }
                if let Some(mut b) = b {
                    let jb = b.jacobians(&model).unwrap();
                    reference.add(&b);
                    for (x, y) in [(&ja.a, &jb.a), (&ja.b, &jb.b)] {
                        let scale = y.amax().max(1.0);
                        worst = worst.max((x - y).amax() / scale);
                    }
                }
                state = a.next_state().clone();
            }
            Err(e) => {
                failed += 1;
                central_failed += usize::from(e.to_string().contains("central-path"));
                if failed <= 3 {
                    println!("failed: {e}");
                }
                let _ = step(&model, &mut state, &mut ws, &ctrl);
            }
        }
    }
    println!(
        "{path}: nv {} nu {} ncontact {}, {steps} steps, kappa_grad {kappa:?}, central start {}, {failed} failed ({central_failed} in the central-path solve)",
        model.nv,
        model.nu(),
        model.ncontact(),
        if model.options.central_warm_start {
            "hard"
        } else {
            "neutral"
        }
    );
    let n = steps as f64;
    println!(
        "  plain step {:.3} ms/step, linearisation + Jacobians {:.3} ms/step (coloured)",
        1e3 * plain / n,
        1e3 * with_jac / n
    );
    coloured.print("coloured");
    println!("  Jacobian fingerprint {print:016x}");
    if with_reference {
        reference.print("column-by-column");
        println!("  max |J_coloured - J_reference| / max(1, max|J_reference|) = {worst:.1e}");
    }
}
