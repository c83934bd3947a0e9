//! Conserved quantities of the discrete system, for tests and diagnostics.
//!
//! Momenta are the *discrete* momenta that the variational integrator conserves exactly (up to
//! the solver tolerance) in the absence of external forces: linear `Σ m v_{k-1/2}` and angular
//! `Σ [R(q_k) (c J ω - (h/2) ω × J ω) + p_k × m v]` with the midpoint velocities of the state.
use nalgebra::Vector3;

use crate::integrator::variational::angular_momentum_backward;
use crate::math::quat;
use crate::model::Model;
use crate::state::State;

/// Discrete linear momentum, world (kg·m/s).
pub fn linear_momentum(model: &Model, state: &State) -> Vector3<f64> {
    (1..model.nbody())
        .map(|b| state.velocity(b).0 * model.bodies[b].mass)
        .sum()
}

/// Discrete angular momentum about the world origin, world frame (kg·m²/s).
pub fn angular_momentum(model: &Model, state: &State) -> Vector3<f64> {
    let h = state.interval(model.options.timestep);
    (1..model.nbody())
        .map(|b| {
            let body = &model.bodies[b];
            let pose = state.pose(b);
            let (v, w) = state.velocity(b);
            quat::rotation(&pose.quat) * angular_momentum_backward(&body.inertia, &w, h)
                + pose.pos.cross(&(v * body.mass))
        })
        .sum()
}

/// Kinetic energy of the midpoint velocities (J).
pub fn kinetic_energy(model: &Model, state: &State) -> f64 {
    (1..model.nbody())
        .map(|b| {
            let body = &model.bodies[b];
            let (v, w) = state.velocity(b);
            0.5 * body.mass * v.norm_squared() + 0.5 * w.dot(&(body.inertia * w))
        })
        .sum()
}

/// Work the constraint impulses (joints, contacts, limits) did over one step from `start` to
/// `next` under the applied impulses `applied` (per body `[linear (world), angular (body frame)]`,
/// the solver's `Workspace::applied`: gravity, springs, actuators, external forces), and the
/// kinetic energies of the two states (J): `(ΔT - W_applied, T + T⁺)` with the work taken at
/// the mean of the two midpoint velocities, which makes the linear balance exact.
///
/// Constraint impulses do no work up to O(h) discretisation terms, and contacts and limits
/// only dissipate; a clearly positive value marks a solve that found a spurious, energy-gaining
/// root of the implicit step (see `step`).
pub(crate) fn constraint_work(
    model: &Model,
    start: &State,
    next: &State,
    applied: &[[f64; 6]],
) -> (f64, f64) {
    let (mut work, mut t0, mut t1) = (0.0, 0.0, 0.0);
    for (b, (body, a)) in model.bodies.iter().zip(applied).enumerate().skip(1) {
        let ((v0, w0), (v1, w1)) = (start.velocity(b), next.velocity(b));
        let ke = |v: &Vector3<f64>, w: &Vector3<f64>| {
            0.5 * body.mass * v.norm_squared() + 0.5 * w.dot(&(body.inertia * w))
        };
        t0 += ke(&v0, &w0);
        t1 += ke(&v1, &w1);
        let (vm, wm) = ((v0 + v1) * 0.5, (w0 + w1) * 0.5);
        work += a[0] * vm[0] + a[1] * vm[1] + a[2] * vm[2];
        work += a[3] * wm[0] + a[4] * wm[1] + a[5] * wm[2];
    }
    let (a0, a1) = (armature_energy(model, start), armature_energy(model, next));
    (t1 + a1 - t0 - a0 - work, t0 + t1 + a0 + a1)
}

/// Gravitational potential energy `-Σ m (1 - gravcomp) g·p` (J): a compensated share of a
/// body's weight does no work.
pub fn potential_energy(model: &Model, state: &State) -> f64 {
    (1..model.nbody())
        .map(|b| -weight_mass(model, b) * model.options.gravity.dot(&state.pose(b).pos))
        .sum()
}

/// The mass gravity pulls on body `b` net of its compensation.
fn weight_mass(model: &Model, b: usize) -> f64 {
    model.bodies[b].mass * (1.0 - model.bodies[b].gravcomp)
}

/// Discrete total energy of the step that led to `state`: midpoint kinetic energy plus the mean
/// of the gravitational potential at the previous (`p - h v`) and current positions, i.e. the
/// energy of the trapezoidal discrete Lagrangian, which the integrator keeps bounded (J).
/// Joint springs are not included; see [`spring_energy`].
pub fn total_energy(model: &Model, state: &State) -> f64 {
    let h = state.interval(model.options.timestep);
    let g = model.options.gravity;
    let pe: f64 = (1..model.nbody())
        .map(|b| {
            let p = state.pose(b).pos;
            let v = state.velocity(b).0;
            -weight_mass(model, b) * g.dot(&(p - v * (0.5 * h)))
        })
        .sum();
    kinetic_energy(model, state) + pe + spring_energy(model, state) + armature_energy(model, state)
}

/// Kinetic energy of the joints' rotor inertia (MuJoCo's `armature`), `½ Σ a θ̇²` with the dof
/// rates of the state's velocities (J); part of the discrete Lagrangian the integrator
/// conserves (see `solver::armature`).
pub fn armature_energy(model: &Model, state: &State) -> f64 {
    let mut rates = [0.0; 6];
    model
        .joints
        .iter()
        .filter(|j| !j.is_loop && j.has_armature())
        .map(|j| {
            crate::joints::coordinates::joint_qvel_into(state, j, &mut rates);
            (0..j.nfree())
                .map(|i| 0.5 * j.armature[i] * rates[i].powi(2))
                .sum::<f64>()
        })
        .sum()
}

/// Potential energy stored in joint springs at the current configuration (J).
pub fn spring_energy(model: &Model, state: &State) -> f64 {
    use crate::joints::geometry::{JointFrame, Pose};
    let pose = |b: usize| if b == 0 { Pose::world() } else { state.pose(b) };
    let mut e = 0.0;
    for (ji, j) in model
        .joints
        .iter()
        .enumerate()
        .filter(|(_, j)| j.has_spring())
    {
        let frame = JointFrame::new(j, &pose(j.parent), &pose(j.child));
        let mut q = [0.0; 7];
        let mut f = [0.0; 6];
        frame.coordinates(j, &mut q[..j.nq()]);
        crate::joints::coordinates::wind(model, state, ji, &mut q[..j.nq()]);
        frame.spring_force(j, &q[..j.nq()], &mut f[..j.nfree()]);
        // ½ k x² = ½ f² / k per dof
        e += (0..j.nfree())
            .filter(|&i| j.stiffness[i] > 0.0)
            .map(|i| 0.5 * f[i] * f[i] / j.stiffness[i])
            .sum::<f64>();
    }
    // passive tendon springs ½ k (L - L₀)²
    if model.passive_tendons.is_empty() {
        return e;
    }
    let q = crate::joints::coordinates::qpos(model, state);
    for t in &model.passive_tendons {
        let len: f64 = t
            .terms
            .iter()
            .map(|&(j, d, c)| c * q[model.joints[j].qpos_adr + d])
            .sum();
        e += 0.5 * t.stiffness * (len - t.springlength).powi(2);
    }
    e
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::{BodySpec, GeomSpec, JointKind, JointSpec, ModelBuilder, Shape, Workspace};

    fn step_work(model: &Model, state: &mut State, ws: &mut Workspace) -> (f64, f64) {
        let start = state.clone();
        crate::step(model, state, ws, &[]).unwrap();
        constraint_work(model, &start, state, &ws.applied)
    }

    /// The balance is exact where only applied impulses act: a tumbling body in free fall.
    #[test]
    fn constraint_work_is_zero_in_free_flight() {
        let m = ModelBuilder::new()
            .body(BodySpec::new("b", 2.0, [0.1, 0.2, 0.3]).pos([0.0, 0.0, 1.0]))
            .joint(JointSpec::new("free", JointKind::Floating, "world", "b"))
            .compile()
            .unwrap();
        let mut s = State::reference(&m);
        crate::set_minimal(
            &m,
            &mut s,
            &m.qpos0.clone(),
            &[1.0, 0.0, 2.0, 0.5, 3.0, -1.0],
        )
        .unwrap();
        let mut ws = Workspace::new(&m);
        for _ in 0..20 {
            let (work, kinetic) = step_work(&m, &mut s, &mut ws);
            // rotation: the discrete momentum map matches ½ωᵀJω only to O((hω)²)
            assert!(work.abs() < 1e-3 * kinetic, "{work:e} of {kinetic:e}");
        }
    }

    /// Contacts only dissipate: a box dropped on the floor does negative constraint work at
    /// impact and none in flight, far below the energy guard.
    #[test]
    fn contact_work_is_dissipative() {
        let half = nalgebra::Vector3::new(0.1, 0.1, 0.1);
        let m = ModelBuilder::new()
            .geom(GeomSpec::new("floor", "world", Shape::Plane))
            .body(BodySpec::new("box", 1.0, [1.0 / 150.0; 3]).pos([0.0, 0.0, 0.3]))
            .joint(JointSpec::new("free", JointKind::Floating, "world", "box"))
            .geom(GeomSpec::new(
                "box",
                "box",
                Shape::Box { half_extents: half },
            ))
            .compile()
            .unwrap();
        let mut s = State::reference(&m);
        let mut ws = Workspace::new(&m);
        let mut total = 0.0;
        for _ in 0..60 {
            let (work, kinetic) = step_work(&m, &mut s, &mut ws);
            assert!(
                work < m.options.energy_guard * kinetic + 1e-9,
                "{work:e} of {kinetic:e}"
            );
            total += work;
        }
        // it hit the floor (0.2 m drop, 1.96 J) and came to rest: the contacts took it all
        assert!((total + 1.96).abs() < 0.1, "total constraint work {total}");
    }
}
