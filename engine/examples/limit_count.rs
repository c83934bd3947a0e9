#![allow(clippy::print_stdout)]
use ukemi_engine::{Workspace, step};
#[path = "common/workload.rs"]
mod workload;
fn main() {
    let args: Vec<String> = std::env::args().collect();
    let model = workload::load(&args[1]);
    let mut state = workload::start_state(&model);
    let mut ws = Workspace::new(&model);
    let mut controls = workload::Controls::new();
    let ntl: usize = args[2].parse().unwrap();
    let nlim: usize = model.joints.iter().map(|j| j.limits.len()).sum::<usize>() + ntl;
    let nc = state.ineq_vars.len() - 4 * nlim;
    let (mut near, mut loaded) = (0usize, 0usize);
    let steps = 300;
    for _ in 0..steps {
        let u = controls.next(&model);
        step(&model, &mut state, &mut ws, &u).unwrap();
        let lim = &state.ineq_vars[nc..nc + 4 * nlim];
        for d in lim.chunks(4) {
            if d[1].min(d[3]) < 0.05 {
                near += 1;
            }
            if d[0].max(d[2]) > 1e-6 {
                loaded += 1;
            }
        }
    }
    println!(
        "limited dofs {nlim}: near (<0.05) {:.2}/step, loaded {:.2}/step",
        near as f64 / steps as f64,
        loaded as f64 / steps as f64
    );
}
