//! Actuator forces (MuJoCo's affine `general` actuator): the scalar force
//! `F = clamp(gain · clamp(ctrl) + bias₀ + bias₁ L + bias₂ L̇, forcerange)` with the transmission
//! length `L = gear · q` (joint) or `gear · Σ coef q` (fixed tendon), evaluated at the current
//! configuration and the previous midpoint velocity like springs (explicit). The force acts as
//! `gear · moment · F` on joint dofs, or as a site wrench. NOTE: the force clamp is not smooth;
//! beyond it the force does not depend on the state or the control (zero derivative), which the
//! central-difference partials of the gradients reproduce.
use nalgebra::Vector3;

use crate::math::quat;
use crate::model::{Actuator, Model, Transmission};
use crate::state::{State, Workspace};

/// Rate of free dof `dof` of joint `ji` through the current free Jacobian (`ws.free_jac`, from
/// `prepare_smooth_forces`) at the body twists `twist(b)` (linear velocity, angular velocity as
/// [`State::velocity`] holds them).
pub(crate) fn dof_rate(
    model: &Model,
    ws: &Workspace,
    ji: usize,
    dof: usize,
    twist: &dyn Fn(usize) -> (Vector3<f64>, Vector3<f64>),
) -> f64 {
    let joint = &model.joints[ji];
    let row = &ws.free_jac[ws.free_adr[ji] + 12 * dof..ws.free_adr[ji] + 12 * dof + 12];
    let mut rate = 0.0;
    for (side, b) in [(0, joint.parent), (1, joint.child)] {
        if b > 0 {
            let (v, w) = twist(b);
            for i in 0..3 {
                rate += row[6 * side + i] * v[i] + row[6 * side + 3 + i] * w[i];
            }
        }
    }
    rate
}

/// Transmission length `Σ coef q` and rate `Σ coef q̇` of actuator `a` (0 for a site), the
/// rates at the body twists `twist(b)`; the coordinates from `ws.joint_q`.
pub(crate) fn length_and_rate(
    model: &Model,
    ws: &Workspace,
    a: usize,
    twist: &dyn Fn(usize) -> (Vector3<f64>, Vector3<f64>),
) -> (f64, f64) {
    let (mut length, mut rate) = (0.0, 0.0);
    let mut add = |ji: usize, dof: usize, coef: f64| {
        length += coef * ws.joint_q[ji][dof];
        rate += coef * dof_rate(model, ws, ji, dof, twist);
    };
    match &model.actuators[a].transmission {
        Transmission::Joint { joint, dof } => add(*joint, *dof, 1.0),
        Transmission::Tendon(terms) => terms.iter().for_each(|t| add(t.0, t.1, t.2)),
        // no `refsite`: MuJoCo's site length is 0 (the loader rejects servo biases there)
        Transmission::Site { .. } => {}
    }
    (length, rate)
}

/// The scalar force of actuator `act` at control `ctrl` and transmission length and rate.
pub(crate) fn actuator_force(act: &Actuator, ctrl: f64, length: f64, rate: f64) -> f64 {
    let u = match act.ctrlrange {
        Some((lo, hi)) => ctrl.clamp(lo, hi),
        None => ctrl,
    };
    let mut force = act.gain * u + act.bias[0];
    if act.has_bias() {
        force += act.bias[1] * act.gear * length + act.bias[2] * act.gear * rate;
    }
    match act.forcerange {
        Some((lo, hi)) => force.clamp(lo, hi),
        None => force,
    }
}

/// Scalar force of every actuator into `ws.act_force` (needs `ws.free_jac` and `ws.joint_q` at
/// the current state).
pub(crate) fn actuator_forces(model: &Model, state: &State, ws: &mut Workspace, ctrl: &[f64]) {
    let twist = |b: usize| state.velocity(b);
    for (a, act) in model.actuators.iter().enumerate() {
        let (length, rate) = if act.has_bias() {
            length_and_rate(model, ws, a, &twist)
        } else {
            (0.0, 0.0)
        };
        ws.act_force[a] = actuator_force(act, ctrl[a], length, rate);
    }
}

/// Add the generalized actuator forces on joint `ji`'s free dofs to `tau`.
pub(crate) fn add_joint_forces(model: &Model, ws: &Workspace, ji: usize, tau: &mut [f64]) {
    for (a, act) in model.actuators.iter().enumerate() {
        if act.transmission.acts_on(ji) {
            for (dof, t) in tau.iter_mut().enumerate() {
                *t += act.gear * act.transmission.moment(ji, dof) * ws.act_force[a];
            }
        }
    }
}

/// Site wrenches: `applied_b += h [R f_site ; τ_site + r × f_site]` (force world frame, torque
/// body frame about the COM), with `f_site = gear[0..3] F`, `τ_site = gear[3..6] F` (site frame).
pub(crate) fn add_site_wrenches(model: &Model, state: &State, ws: &mut Workspace) {
    let h = model.options.timestep;
    for (a, act) in model.actuators.iter().enumerate() {
        let Transmission::Site {
            body,
            pos,
            rot,
            gear,
        } = &act.transmission
        else {
            continue;
        };
        let f = ws.act_force[a];
        let force_b = rot * Vector3::new(gear[0], gear[1], gear[2]) * f;
        let torque_b = rot * Vector3::new(gear[3], gear[4], gear[5]) * f + pos.cross(&force_b);
        let force_w = quat::rotation(&state.pose(*body).quat) * force_b;
        let ap = &mut ws.applied[*body];
        for i in 0..3 {
            ap[i] += h * force_w[i];
            ap[3 + i] += h * torque_b[i];
        }
    }
}
