//! Implicit-gradient checks shared by the gradient tests: Jacobians against central finite
//! differences of the engine's own step, and VJP/JVP against the Jacobian products.
#![allow(dead_code)]
use nalgebra::DMatrix;
use ukemi_engine::gradients::tangent::{difference, perturb};
use ukemi_engine::{Coordinates, Linearization, Model, State, Workspace, Wrt, step, step_smoothed};

/// Tight solves so finite differences of the step are accurate.
pub fn tight(model: Model) -> Model {
    let mut o = model.options.clone();
    o.rtol = 1e-14;
    o.max_iter = 100;
    model.with_options(o).unwrap()
}

/// The step map as the gradients see it: hard, or smoothed at `kappa`.
pub fn step_map(model: &Model, state: &State, ctrl: &[f64], kappa: Option<f64>) -> State {
    let mut s = state.clone();
    match kappa {
        Some(k) => {
            step_smoothed(model, &mut s, ctrl, k).unwrap();
        }
        None => {
            let mut ws = Workspace::new(model);
            let r = step(model, &mut s, &mut ws, ctrl).unwrap();
            assert_eq!(r.status.name(), "converged");
        }
    }
    s
}

/// Central-difference Jacobians `(A, B, C)` of the (smoothed) step in `coords`.
pub fn fd_jacobians(
    model: &Model,
    state: &State,
    ctrl: &[f64],
    coords: Coordinates,
    kappa: Option<f64>,
    eps: f64,
) -> (DMatrix<f64>, DMatrix<f64>, DMatrix<f64>) {
    let ny = coords.dim(model);
    let base_in = perturb(model, state, coords, &vec![0.0; ny], 0.0).unwrap();
    let base_out = step_map(model, &base_in, ctrl, kappa);
    let out = |m: &Model, s: &State, u: &[f64]| {
        let next = step_map(m, s, u, kappa);
        nalgebra::DVector::from_vec(difference(m, &base_out, &next, coords).unwrap())
    };
    let mut a = DMatrix::zeros(ny, ny);
    for i in 0..ny {
        let mut dir = vec![0.0; ny];
        dir[i] = 1.0;
        let sp = perturb(model, &base_in, coords, &dir, eps).unwrap();
        let sm = perturb(model, &base_in, coords, &dir, -eps).unwrap();
        a.set_column(
            i,
            &((out(model, &sp, ctrl) - out(model, &sm, ctrl)) / (2.0 * eps)),
        );
    }
    let mut b = DMatrix::zeros(ny, ctrl.len());
    for i in 0..ctrl.len() {
        let (mut up, mut um) = (ctrl.to_vec(), ctrl.to_vec());
        up[i] += eps;
        um[i] -= eps;
        b.set_column(
            i,
            &((out(model, &base_in, &up) - out(model, &base_in, &um)) / (2.0 * eps)),
        );
    }
    let p0 = model.params();
    let mut c = DMatrix::zeros(ny, p0.len());
    for i in 0..p0.len() {
        let e = eps * p0[i].abs().max(1.0);
        let (mut pp, mut pm) = (p0.clone(), p0.clone());
        pp[i] += e;
        pm[i] -= e;
        let mp = model.with_params(&pp).unwrap();
        // parameters at a bound (zero damping or armature) get a one-sided difference of
        // second order, (-3 f(0) + 4 f(e) - f(2e)) / 2e (the first-order one was off by 2e-5
        // for the armature of a light link)
        let col = match model.with_params(&pm) {
            Ok(mm) => (out(&mp, &base_in, ctrl) - out(&mm, &base_in, ctrl)) / (2.0 * e),
            Err(_) => {
                let mut p2 = p0.clone();
                p2[i] += 2.0 * e;
                let m2 = model.with_params(&p2).unwrap();
                (out(&mp, &base_in, ctrl) * 4.0
                    - out(model, &base_in, ctrl) * 3.0
                    - out(&m2, &base_in, ctrl))
                    / (2.0 * e)
            }
        };
        c.set_column(i, &col);
    }
    (a, b, c)
}

pub fn rel_err(x: &DMatrix<f64>, y: &DMatrix<f64>) -> f64 {
    let scale = y.amax().max(1.0);
    (x - y).amax() / scale
}

/// Check A, B, C against finite differences, and VJP/JVP against the Jacobian products.
pub fn check(
    model: &Model,
    state: &State,
    ctrl: &[f64],
    coords: Coordinates,
    kappa: Option<f64>,
    tol: f64,
) -> f64 {
    let mut lin = Linearization::new(model, state, ctrl, coords, Wrt::ALL, kappa).unwrap();
    let jac = lin.jacobians(model).unwrap();
    let (a, b, c) = fd_jacobians(model, state, ctrl, coords, kappa, 1e-6);
    let (ea, eb, ec) = (
        rel_err(&jac.a, &a),
        rel_err(&jac.b, &b),
        rel_err(&jac.c, &c),
    );
    let names = model.param_names();
    if ec > tol {
        for (j, name) in names.iter().enumerate() {
            let e = (jac.c.column(j) - c.column(j)).amax();
            if e > tol * c.amax().max(1.0) {
                eprintln!("param {name} err {e:e}");
            }
        }
    }
    assert!(ea < tol, "A: {ea:e}\nengine {:.6}\nfd {:.6}", jac.a, a);
    assert!(eb < tol, "B: {eb:e}\nengine {:.6}\nfd {:.6}", jac.b, b);
    assert!(ec < tol, "C: {ec:e}");
    // products equal the Jacobian products
    let ny = coords.dim(model);
    let adj: Vec<f64> = (0..ny)
        .map(|i| ((i * 7 + 3) % 11) as f64 / 11.0 - 0.4)
        .collect();
    let vjp = lin.vjp(model, &adj).unwrap();
    let adjv = nalgebra::DVector::from_vec(adj);
    let scale = |m: &DMatrix<f64>| m.amax().max(1.0);
    let d_state = (jac.a.transpose() * &adjv - nalgebra::DVector::from_vec(vjp.state)).amax();
    let d_ctrl = (jac.b.transpose() * &adjv - nalgebra::DVector::from_vec(vjp.ctrl)).amax();
    let d_par = (jac.c.transpose() * &adjv - nalgebra::DVector::from_vec(vjp.params)).amax();
    assert!(
        d_state < 1e-10 * scale(&jac.a) * ny as f64,
        "vjp state {d_state:e}"
    );
    assert!(
        d_ctrl < 1e-10 * scale(&jac.b) * ny as f64,
        "vjp ctrl {d_ctrl:e}"
    );
    assert!(
        d_par < 1e-10 * scale(&jac.c) * ny as f64,
        "vjp params {d_par:e}"
    );
    let dx: Vec<f64> = (0..ny)
        .map(|i| ((i * 5 + 1) % 7) as f64 / 7.0 - 0.5)
        .collect();
    let du = vec![0.3; ctrl.len()];
    let dp = vec![0.0; model.params().len()];
    let jvp = lin.jvp(model, &dx, &du, &dp).unwrap();
    let expect =
        &jac.a * nalgebra::DVector::from_vec(dx) + &jac.b * nalgebra::DVector::from_vec(du);
    let d_jvp = (expect - nalgebra::DVector::from_vec(jvp)).amax();
    assert!(d_jvp < 1e-10 * scale(&jac.a) * ny as f64, "jvp {d_jvp:e}");
    ea.max(eb).max(ec)
}

/// `rollout_vjp` over `t` steps against the chained transposes of each step's Jacobians.
pub fn check_rollout_vjp(m: &Model, s0: &State, t: usize, kappa: Option<f64>) {
    check_rollout_vjp_in(m, s0, t, kappa, Coordinates::Minimal, 1e-10);
}

pub fn check_rollout_vjp_in(
    m: &Model,
    s0: &State,
    t: usize,
    kappa: Option<f64>,
    coords: Coordinates,
    tol: f64,
) {
    use ukemi_engine::gradients::rollout_vjp;
    let (ny, nu) = (coords.dim(m), m.nu());
    let ctrls: Vec<f64> = (0..t * nu).map(|i| (i as f64 * 0.37).sin()).collect();
    let adj: Vec<f64> = (0..(t + 1) * ny).map(|i| (i as f64 * 0.91).cos()).collect();
    let r = rollout_vjp(m, s0, &ctrls, t, &adj, coords, kappa, true).unwrap();
    // on one thread the sweep linearises each step when it reaches it and applies one
    // transposed back-substitution (with more, the steps' Jacobians are formed on the pool
    // during the forward pass): check that sweep too
    let one = rayon::ThreadPoolBuilder::new()
        .num_threads(1)
        .build()
        .unwrap();
    let r_seq = one
        .install(|| rollout_vjp(m, s0, &ctrls, t, &adj, coords, kappa, true))
        .unwrap();
    // forward: Jacobians of every step along the same chain
    let mut states = vec![s0.clone()];
    let mut jacs = Vec::new();
    for k in 0..t {
        let u = &ctrls[k * nu..(k + 1) * nu];
        let mut lin = Linearization::new(m, &states[k], u, coords, Wrt::ALL, kappa).unwrap();
        jacs.push(lin.jacobians(m).unwrap());
        states.push(lin.next_state().clone());
    }
    let mut a = nalgebra::DVector::from_column_slice(&adj[t * ny..]);
    let mut params = nalgebra::DVector::zeros(m.params().len());
    let mut g_us = vec![nalgebra::DVector::zeros(nu); t];
    for k in (0..t).rev() {
        g_us[k] = jacs[k].b.transpose() * &a;
        params += jacs[k].c.transpose() * &a;
        a = jacs[k].a.transpose() * &a
            + nalgebra::DVector::from_column_slice(&adj[k * ny..(k + 1) * ny]);
    }
    for r in [r, r_seq] {
        for (k, g_u) in g_us.iter().enumerate() {
            for i in 0..nu {
                assert!((g_u[i] - r.ctrls[k * nu + i]).abs() < tol * g_u.amax().max(1.0));
            }
        }
        let d0 = (a.clone() - nalgebra::DVector::from_vec(r.state0)).amax();
        let dp = (params.clone() - nalgebra::DVector::from_vec(r.params)).amax();
        assert!(d0 < tol * a.amax().max(1.0), "state0 {d0:e}");
        assert!(dp < tol * params.amax().max(1.0), "params {dp:e}");
    }
}
