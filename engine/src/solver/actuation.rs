//! Actuator forces (MuJoCo's affine `general` actuator): the scalar force
//! `F = clamp(gain · clamp(ctrl) + bias₀ + bias₁ L + bias₂ L̇, forcerange)` with the transmission
//! length `L = gear · q` (joint) or `gear · Σ coef q` (fixed tendon), evaluated at the current
//! configuration and the previous midpoint velocity like springs (explicit). The force acts as
//! `gear · moment · F` on joint dofs, or as a site wrench. NOTE: the force clamp is not smooth;
//! beyond it the force does not depend on the state or the control (zero derivative), which the
//! central-difference partials of the gradients reproduce.
//!
//! **A servo's velocity gain is implicit** ([`split_force`]): on a joint transmission whose
//! force is inside its range, `bias₂ L̇` is taken at the step's own (next midpoint) velocity, a
//! damper of `-bias₂ gear²` on the dof, as MuJoCo's `implicit` and `implicitfast` integrators
//! take it. Why: position servos are stiff dampers. The Franka Panda's (`kv` = 200-450 N·m·s
//! on ~0.1-2 kg·m²) need `h kv / I < 2` when explicit, and at h = 0.01 its arm held at its home
//! pose shook at ±3.5 rad/s, as it does in MuJoCo with the Euler integrator (its MJCF asks for
//! `implicitfast`), and a rollout's adjoints grew ~10× every 25 steps. A fixed-tendon servo's
//! velocity term is implicit the same way, a damper on the tendon's rate coupling every pair
//! of its joints' bodies (the topology links them: [`damped_tendons`]); a site keeps none.
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
    clamped(act, unclamped_force(act, ctrl, length, rate)).0
}

/// `force` clamped to the actuator's `forcerange`, then its generalized force `gear · F` to
/// `joint_forcerange` (MuJoCo's order); and whether it lies strictly inside both ranges.
fn clamped(act: &Actuator, force: f64) -> (f64, bool) {
    let mut inside = true;
    let mut f = force;
    if let Some((lo, hi)) = act.forcerange {
        inside &= lo < f && f < hi;
        f = f.clamp(lo, hi);
    }
    if let Some((lo, hi)) = act.joint_forcerange {
        let g = act.gear * f;
        inside &= lo < g && g < hi;
        if act.gear != 0.0 && !(lo <= g && g <= hi) {
            f = g.clamp(lo, hi) / act.gear;
        }
    }
    (f, inside)
}

/// [`actuator_force`] before its force range.
fn unclamped_force(act: &Actuator, ctrl: f64, length: f64, rate: f64) -> f64 {
    let u = match act.ctrlrange {
        Some((lo, hi)) => ctrl.clamp(lo, hi),
        None => ctrl,
    };
    let mut force = act.gain * u + act.bias[0];
    if act.has_bias() {
        force += act.bias[1] * act.gear * length + act.bias[2] * act.gear * rate;
    }
    force
}

/// The explicit part of actuator `act`'s force and the velocity gain `∂F/∂L̇` taken implicitly
/// (0: none), at control `ctrl` and transmission length and current rate: a joint or tendon
/// servo (`bias₂ ≠ 0`) whose unclamped force lies inside its force ranges (`forcerange`,
/// `joint_forcerange`) has the force less its
/// velocity term, and gain `bias₂ gear`; any other actuator its whole force ([`actuator_force`]),
/// and gain 0. The force is then `explicit + gain · L̇⁺`, `L̇⁺` at the next midpoint velocity.
pub(crate) fn split_force(act: &Actuator, ctrl: f64, length: f64, rate: f64) -> (f64, f64) {
    let implicit = !matches!(act.transmission, Transmission::Site { .. }) && act.bias[2] != 0.0;
    if !implicit {
        return (actuator_force(act, ctrl, length, rate), 0.0);
    }
    let force = unclamped_force(act, ctrl, length, rate);
    let gain = act.bias[2] * act.gear;
    match clamped(act, force) {
        (f, false) => (f, 0.0),
        (_, true) => (force - gain * rate, gain),
    }
}

/// The joints of each implicit tendon damper: every fixed-tendon actuator, with a velocity gain
/// (`bias₂ ≠ 0`, [`split_force`]) or not, and every passive tendon, damped or not: its damping is a
/// parameter (`Model::with_params`) that may be set from zero. The body pairs its damping
/// couples need blocks in the Newton matrix (an undamped tendon's stay zero and are skipped).
pub(crate) fn damped_tendons(
    actuators: &[Actuator],
    passive: &[crate::joints::tendon::PassiveTendon],
) -> Vec<Vec<usize>> {
    // (every tendon actuator: its velocity gain is a parameter that may be set from zero)
    let servos = actuators.iter().filter_map(|a| match &a.transmission {
        Transmission::Tendon(terms) => Some(terms.iter().map(|t| t.0).collect()),
        _ => None,
    });
    let dampers = passive
        .iter()
        .map(|t| t.terms.iter().map(|&(j, _, _)| j).collect());
    servos.chain(dampers).collect()
}

/// Scalar force of every actuator into `ws.act_force`, and the servos' implicit velocity gains
/// as damping: of a joint servo on its dof (`ws.servo_damping`), of a tendon servo on the
/// tendon's rate (`ws.tendon_damping`) ([`split_force`]; needs `ws.free_jac` and `ws.joint_q`
/// at the current state).
pub(crate) fn actuator_forces(model: &Model, state: &State, ws: &mut Workspace, ctrl: &[f64]) {
    let twist = |b: usize| state.velocity(b);
    // the applied impulses act over (h_prev + h) / 2 (see `prepare_smooth_forces`), a damper's
    // over h: the damping that gives the servo's impulse over the former
    let h = model.options.timestep;
    let over = 0.5 * (1.0 + state.interval(h) / h);
    ws.servo_damping.fill(0.0);
    for (a, act) in model.actuators.iter().enumerate() {
        let (length, rate) = if act.has_bias() {
            length_and_rate(model, ws, a, &twist)
        } else {
            (0.0, 0.0)
        };
        let (force, gain) = split_force(act, ctrl[a], length, rate);
        ws.act_force[a] = force;
        let damping = -gain * act.gear * over;
        ws.tendon_damping[a] = 0.0;
        match &act.transmission {
            Transmission::Joint { joint, dof } => {
                ws.servo_damping[ws.free_adr[*joint] / 12 + dof] += damping;
            }
            Transmission::Tendon(_) => ws.tendon_damping[a] = damping,
            Transmission::Site { .. } => {}
        }
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

#[cfg(test)]
mod tests {
    use super::*;

    /// A position servo on dof 0 of joint 0: `F = kp (u - q) - kv q̇`, gear 2.
    fn servo(forcerange: Option<(f64, f64)>) -> Actuator {
        Actuator {
            name: "servo".into(),
            transmission: Transmission::Joint { joint: 0, dof: 0 },
            gear: 2.0,
            ctrlrange: None,
            forcerange,
            joint_forcerange: None,
            gain: 50.0,
            bias: [0.0, -50.0, -8.0],
        }
    }

    /// Inside its force range a servo's force is its explicit part plus its velocity gain times
    /// the rate, whatever the rate it is split at; clamped, it is the clamp, all explicit; a
    /// motor (no velocity term) stays explicit, and a tendon servo splits as a joint servo does.
    #[test]
    fn a_servo_splits_off_its_velocity_gain_only_inside_its_range() {
        let (u, length, rate) = (0.3, 0.1, 0.2);
        let act = servo(Some((-10.0, 10.0)));
        let whole = actuator_force(&act, u, length, rate);
        let (explicit, gain) = split_force(&act, u, length, rate);
        assert_eq!(gain, -8.0 * 2.0);
        assert!(
            (explicit + gain * rate - whole).abs() < 1e-12,
            "{explicit} {gain} {whole}"
        );
        let (at_rest, same) = split_force(&act, u, length, 0.0);
        assert!((at_rest - explicit).abs() < 1e-12 && same == gain);
        // 50 · 0.3 - 50 · 2 · 0.1 - 8 · 2 · 5 = -75: clamped at -10 (at rate 0.2: 1.8, inside)
        assert_eq!(split_force(&act, u, length, 5.0), (-10.0, 0.0));
        let motor = Actuator {
            bias: [0.0; 3],
            ..servo(None)
        };
        assert_eq!(split_force(&motor, u, length, rate), (50.0 * u, 0.0));
        let tendon = Actuator {
            transmission: Transmission::Tendon(vec![(0, 0, 1.0)]),
            ..servo(None)
        };
        assert_eq!(split_force(&tendon, u, length, rate).1, -8.0 * 2.0);
    }

    /// A joint's range clamps the generalized force `gear · F` after the actuator's own range
    /// (MuJoCo's order), splitting off the velocity gain only inside both.
    #[test]
    fn a_joint_force_range_clamps_the_generalized_force_after_the_force_range() {
        let (u, length, rate) = (0.3, 0.1, 0.2);
        // F = 1.8 inside forcerange (-10, 10); gear · F = 3.6
        let act = Actuator {
            joint_forcerange: Some((-3.0, 3.0)),
            ..servo(Some((-10.0, 10.0)))
        };
        assert_eq!(actuator_force(&act, u, length, rate), 1.5);
        assert_eq!(split_force(&act, u, length, rate), (1.5, 0.0));
        // inside both at rate 0.3: split as before (F = 15 - 10 - 16 · 0.3 = 0.2, gear · F = 0.4)
        let (explicit, gain) = split_force(&act, u, length, 0.3);
        assert!((explicit + gain * 0.3 - 0.2).abs() < 1e-12 && gain == -16.0);
        // the force range first: F = -75 → -10, then gear · F = -20 → -3
        assert_eq!(actuator_force(&act, u, length, 5.0), -1.5);
        // a negative gear: F = 15 + 10 + 3.2 → 10, gear · F = -20 → -3, so F = 1.5
        let flipped = Actuator { gear: -2.0, ..act };
        assert_eq!(actuator_force(&flipped, u, length, rate), 1.5);
    }
}
