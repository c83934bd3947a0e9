//! Spring-damper joints against the analytic damped oscillator `m x'' + c x' + k x = 0`:
//! decay rate `ζω₀` and damped frequency `ω₀ sqrt(1 - ζ²)` within 1%.
mod common;
use common::*;
use ukemi_engine::{
    BodySpec, JointKind, JointSpec, ModelBuilder, State, Workspace, qpos, set_minimal,
};

/// Fit (decay rate, damped angular frequency) from the peaks of x(t).
fn fit(t: &[f64], x: &[f64]) -> (f64, f64) {
    let peaks: Vec<(f64, f64)> = (1..x.len() - 1)
        .filter(|&i| x[i] > x[i - 1] && x[i] >= x[i + 1] && x[i] > 0.0)
        .map(|i| (t[i], x[i]))
        .collect();
    let (first, last) = (peaks[0], peaks[peaks.len() - 1]);
    let n = (peaks.len() - 1) as f64;
    let period = (last.0 - first.0) / n;
    let decay = (first.1 / last.1).ln() / (last.0 - first.0);
    (decay, 2.0 * std::f64::consts::PI / period)
}

fn check(kind: JointKind, mass_or_inertia: f64, k: f64, c: f64) {
    let h = 5e-4;
    let body = match kind {
        JointKind::Prismatic => BodySpec::new("m", mass_or_inertia, [0.1, 0.1, 0.1]),
        _ => BodySpec::new("m", 3.0, [0.5, 0.5, mass_or_inertia]),
    };
    let model = ModelBuilder::new()
        .timestep(h)
        .gravity([0.0; 3])
        .body(body)
        .joint(
            JointSpec::new("j", kind, "world", "m")
                .axis([0.0, 0.0, 1.0])
                .stiffness(k)
                .damping(c),
        )
        .compile()
        .unwrap();
    let mut state = State::reference(&model);
    set_minimal(&model, &mut state, &[0.2], &[0.0]).unwrap();
    let mut ws = Workspace::new(&model);
    let (mut t, mut x) = (vec![0.0], vec![0.2]);
    for _ in 0..(6.0 / h) as usize {
        step_ok(&model, &mut state, &mut ws, &[]);
        t.push(state.time);
        x.push(qpos(&model, &state)[0]);
    }
    let (decay, freq) = fit(&t, &x);
    let w0 = (k / mass_or_inertia).sqrt();
    let zeta = c / (2.0 * (k * mass_or_inertia).sqrt());
    let (decay_a, freq_a) = (zeta * w0, w0 * (1.0 - zeta * zeta).sqrt());
    eprintln!("{kind:?}: decay {decay:.5} vs {decay_a:.5}, frequency {freq:.5} vs {freq_a:.5}");
    assert!(
        (decay - decay_a).abs() / decay_a < 0.01,
        "decay rate {decay} vs analytic {decay_a}"
    );
    assert!(
        (freq - freq_a).abs() / freq_a < 0.01,
        "frequency {freq} vs analytic {freq_a}"
    );
}

#[test]
fn prismatic_spring_damper_matches_analytic_oscillator() {
    check(JointKind::Prismatic, 2.0, 200.0, 2.0);
}

#[test]
fn revolute_spring_damper_matches_analytic_oscillator() {
    check(JointKind::Revolute, 0.4, 10.0, 0.3);
}
