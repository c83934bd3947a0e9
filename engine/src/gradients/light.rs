//! The light columns of `∂R/∂z` in closed form: what a change of the current velocities or of a
//! control does to the body rows of the residual `R = momentum - applied + armature`, at the
//! prepared poses (joint frames, free Jacobians and coordinates of the gradient point).
//!
//! - Momenta (Dojo eqs. 16-17): `r_lin = m (v⁺ - v⁻)`, `r_rot = p⁺(ω⁺) - p⁻(ω⁻)` with the backward
//!   discrete momentum `p⁻(ω) = c J ω - (h/2) ω × J ω`, so `∂r/∂(v⁻, ω⁻) = -diag(m I, ∂p⁻/∂ω)`
//!   ([`rot_jacobian`] at `-h`: `p⁻` is the forward momentum of the reversed step).
//! - Actuator forces `F(ctrl, L, L̇)` through their transmissions: each scalar force's explicit
//!   part (`actuation::split_force`: a servo's velocity term is taken at the next velocity, so
//!   inside its force range the current rate drops out) is central-differenced along the column
//!   (two calls of the scalar function), so its control and force clamps act exactly as in the
//!   residual's own central differences.
//! - Armature `a (J_f w⁺ - J_f w⁻)`: linear in the current twists.
//!
//! Why: these columns were two residual evaluations each (every body's momentum, every actuator
//! and joint term) for what is a few small products on the bodies a column touches.
use nalgebra::Vector3;

use crate::integrator::variational::rot_jacobian;
use crate::model::{Model, Transmission};
use crate::solver::actuation::{length_and_rate, split_force};
use crate::state::{State, Workspace};

/// What a light column changes.
#[derive(Clone, Copy, Debug)]
pub(super) enum Light<'d> {
    /// The current body twists, by `dt[b]` (linear velocity, angular velocity as
    /// [`State::velocity`] holds them) per unit of the input.
    Twists(&'d [[f64; 6]]),
    /// Control `a`.
    Ctrl(usize),
}

/// `dr[b] = ∂R_b/∂z` (body rows) of the light input `input` at the prepared point: `state` the
/// current state, `ws` prepared at it (`prepare_smooth_forces`: free Jacobians, coordinates),
/// `ctrl` the controls, `eps` the input's central-difference step (for the actuator forces).
/// Adds to `dr`, which the caller zeroes.
pub(super) fn light_column(
    model: &Model,
    state: &State,
    ws: &Workspace,
    ctrl: &[f64],
    input: Light,
    eps: f64,
    dr: &mut [[f64; 6]],
) {
    let h = model.options.timestep;
    let h_prev = state.interval(h);
    // the applied impulses act over (h_prev + h) / 2 (see `prepare_smooth_forces`)
    let over = if h_prev == h {
        h
    } else {
        h * 0.5 * (1.0 + h_prev / h)
    };
    let twist = |b: usize| state.velocity(b);
    for (a, act) in model.actuators.iter().enumerate() {
        let moves = match input {
            Light::Ctrl(c) => c == a,
            Light::Twists(_) => act.bias[2] != 0.0,
        };
        if !moves {
            continue;
        }
        let (length, rate) = if act.has_bias() {
            length_and_rate(model, ws, a, &twist)
        } else {
            (0.0, 0.0)
        };
        let df = match input {
            Light::Ctrl(_) => {
                let f = |u: f64| split_force(act, u, length, rate).0;
                (f(ctrl[a] + eps) - f(ctrl[a] - eps)) / (2.0 * eps)
            }
            Light::Twists(dt) => {
                let d = |b: usize| (v3(&dt[b][..3]), v3(&dt[b][3..]));
                let (_, drate) = length_and_rate(model, ws, a, &d);
                let f = |r: f64| split_force(act, ctrl[a], length, r).0;
                (f(rate + eps * drate) - f(rate - eps * drate)) / (2.0 * eps)
            }
        };
        if df != 0.0 {
            add_actuator(model, state, ws, a, -over * df, dr);
        }
    }
    let Light::Twists(dt) = input else {
        return;
    };
    for (b, body) in model.bodies.iter().enumerate().skip(1) {
        if dt[b] == [0.0; 6] {
            continue;
        }
        let (_, om) = state.velocity(b);
        let rot = rot_jacobian(&body.inertia, &om, -h_prev) * v3(&dt[b][3..]);
        for i in 0..3 {
            dr[b][i] -= body.mass * dt[b][i];
            dr[b][3 + i] -= rot[i];
        }
    }
    for (ji, joint) in model.joints.iter().enumerate() {
        if !joint.has_armature() || (dt[joint.parent] == [0.0; 6] && dt[joint.child] == [0.0; 6]) {
            continue;
        }
        let jf = &ws.free_jac[ws.free_adr[ji]..];
        for (r, &arm) in joint.armature.iter().enumerate() {
            let row = &jf[12 * r..12 * r + 12];
            let sides = [(0, joint.parent), (1, joint.child)];
            let drate: f64 = sides
                .iter()
                .filter(|s| s.1 > 0)
                .map(|&(side, b)| (0..6).map(|i| row[6 * side + i] * dt[b][i]).sum::<f64>())
                .sum();
            // f = a (rate(w⁺) - rate(current)): the current rate enters with a minus
            let df = -arm * drate;
            for (side, b) in sides.into_iter().filter(|s| s.1 > 0) {
                for i in 0..6 {
                    dr[b][i] += row[6 * side + i] * df;
                }
            }
        }
    }
}

/// `dr += scale · (generalised impulse of a unit force of actuator a)` on the body rows of its
/// transmission (`scale` carries the sign and the interval).
fn add_actuator(
    model: &Model,
    state: &State,
    ws: &Workspace,
    a: usize,
    scale: f64,
    dr: &mut [[f64; 6]],
) {
    let act = &model.actuators[a];
    let mut on_dof = |ji: usize, dof: usize, coef: f64| {
        let joint = &model.joints[ji];
        let row = &ws.free_jac[ws.free_adr[ji] + 12 * dof..ws.free_adr[ji] + 12 * dof + 12];
        let tau = act.gear * coef * scale;
        for (side, b) in [(0, joint.parent), (1, joint.child)] {
            if b > 0 {
                for i in 0..6 {
                    dr[b][i] += row[6 * side + i] * tau;
                }
            }
        }
    };
    match &act.transmission {
        Transmission::Joint { joint, dof } => on_dof(*joint, *dof, 1.0),
        Transmission::Tendon(terms) => terms.iter().for_each(|t| on_dof(t.0, t.1, t.2)),
        Transmission::Site {
            body,
            pos,
            rot,
            gear,
        } => {
            let force_b = rot * Vector3::new(gear[0], gear[1], gear[2]);
            let torque_b = rot * Vector3::new(gear[3], gear[4], gear[5]) + pos.cross(&force_b);
            let force_w = crate::math::quat::rotation(&state.pose(*body).quat) * force_b;
            for i in 0..3 {
                dr[*body][i] += scale * force_w[i];
                dr[*body][3 + i] += scale * torque_b[i];
            }
        }
    }
}

fn v3(x: &[f64]) -> Vector3<f64> {
    Vector3::new(x[0], x[1], x[2])
}
