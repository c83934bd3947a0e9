//! Simple pendulum: small-angle period against 2π√(L/g); bounded energy at 60° amplitude.
mod common;
use common::*;
use ukemi_engine::{State, Workspace, qpos, set_minimal};

#[test]
fn small_angle_period_matches_analytic() {
    let (len, h) = (1.0, 0.01);
    let model = pendulum(len, h);
    let mut state = State::reference(&model);
    set_minimal(&model, &mut state, &[0.01], &[0.0]).unwrap();
    let mut ws = Workspace::new(&model);
    let (mut t, mut x) = (vec![0.0], vec![0.01]);
    for _ in 0..2000 {
        step_ok(&model, &mut state, &mut ws, &[]);
        t.push(state.time);
        x.push(qpos(&model, &state)[0]);
    }
    let c = upward_crossings(&t, &x);
    let period = (c[c.len() - 1] - c[0]) / (c.len() - 1) as f64;
    let analytic = 2.0 * std::f64::consts::PI * (len / 9.81f64).sqrt();
    let rel = (period - analytic).abs() / analytic;
    eprintln!("period {period} analytic {analytic} rel {rel:.3e}");
    assert!(rel < 5e-3, "period {period} vs {analytic} (rel {rel:.2e})");
}

#[test]
fn large_amplitude_energy_stays_bounded() {
    let model = pendulum(1.0, 0.01);
    let mut state = State::reference(&model);
    set_minimal(&model, &mut state, &[60f64.to_radians()], &[0.0]).unwrap();
    let mut ws = Workspace::new(&model);
    let e0 = energy(&model, &state);
    let scale = 9.81 * 0.5; // m g L (1 - cos 60°)
    let (mut lo, mut hi) = (f64::MAX, f64::MIN);
    let mut late = (f64::MAX, f64::MIN);
    for k in 0..100_000 {
        step_ok(&model, &mut state, &mut ws, &[]);
        let e = energy(&model, &state) - e0;
        lo = lo.min(e);
        hi = hi.max(e);
        if k >= 90_000 {
            late = (late.0.min(e), late.1.max(e));
        }
    }
    // bounded oscillation (the midpoint kinetic energy lags the potential by h/2), no drift:
    assert!(
        (hi - lo) / scale < 2e-3,
        "energy band {:.3e} of {scale}",
        hi - lo
    );
    let drift = ((late.0 + late.1) - (lo + hi)).abs() / 2.0 / scale;
    eprintln!(
        "energy band {:.3e} (rel {:.3e}), drift {drift:.3e}",
        hi - lo,
        (hi - lo) / scale
    );
    assert!(drift < 1e-6, "energy band centre moved by {drift:.3e}");
}
