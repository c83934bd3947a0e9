//! Contact forces of one step as a simulator user reads them: per candidate in its contact
//! frame, and per body as the external wrench the contacts exert (MuJoCo's `cfrc_ext`).
//!
//! The step's contact impulse `λ = (γ, β₁, β₂)` acts along the contact frame of the step's
//! initial configuration (see the module above) for one time step `h`, so the force is
//! `λ / h`. On body a it acts at the witness point `p_a` as `f = [n t₁ t₂] λ / h`, on body b
//! as `−f` at `p_b`.
use nalgebra::Vector3;

use super::{freeze_for_step, predicted_pose, witness_frozen};
use crate::joints::geometry::Pose;
use crate::math::spatial::basis_from_axis;
use crate::model::Model;
use crate::state::State;

/// Contact forces of the step that led to `state_next` from `state`.
#[derive(Clone, Debug, PartialEq)]
pub struct ContactForces {
    /// Force of every candidate in its contact frame (normal, t1, t2), N. Shape (ncontact, 3).
    pub force_c: Vec<f64>,
    /// External contact wrench on every body, world frame: torque about the world origin (N·m)
    /// then force (N). Shape (nbody, 6); the world body's row is zero.
    pub body_wrench: Vec<f64>,
}

/// Forces of the step `state → state_next` (impulses read from `state_next`).
pub fn contact_forces(model: &Model, state: &State, state_next: &State) -> ContactForces {
    let h = model.timestep();
    let force_c: Vec<f64> = state_next
        .contact_impulse(model)
        .iter()
        .map(|l| l / h)
        .collect();
    let mut body_wrench = vec![0.0; 6 * model.nbody()];
    let pose = |b: usize| if b == 0 { Pose::world() } else { state.pose(b) };
    for (k, c) in model.contacts.iter().enumerate() {
        let f_c = Vector3::new(force_c[3 * k], force_c[3 * k + 1], force_c[3 * k + 2]);
        if f_c == Vector3::zeros() {
            continue;
        }
        // the frame the step's impulse acted along: the candidate as frozen for the step
        let (ga, gb) = (&model.geoms[c.geom_a], &model.geoms[c.geom_b]);
        let frozen = freeze_for_step(
            c,
            &model.geoms,
            (&pose(ga.body), &pose(gb.body)),
            (
                &predicted_pose(state, ga.body, h),
                &predicted_pose(state, gb.body, h),
            ),
        );
        let (w, _, _) = witness_frozen(c, &model.geoms, pose, frozen);
        // f = [n t1 t2] f_c on a at p_a; -f on b at p_b
        let f = basis_from_axis(&w.normal) * f_c;
        let bodies = [
            (model.geoms[c.geom_a].body, w.point_a, f),
            (model.geoms[c.geom_b].body, w.point_b, -f),
        ];
        for (b, p, f) in bodies {
            if b == 0 {
                continue;
            }
            let torque = p.cross(&f);
            for i in 0..3 {
                body_wrench[6 * b + i] += torque[i];
                body_wrench[6 * b + 3 + i] += f[i];
            }
        }
    }
    ContactForces {
        force_c,
        body_wrench,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn resting_sphere_carries_its_weight() {
        // a 2 kg sphere resting on a plane at (1, 0.5): once settled the contact force is m g
        // up, at the contact point (1, 0.5, 0), so the torque about the origin is p × f
        let xml = r#"<mujoco><option timestep="0.01"/><worldbody>
            <geom type="plane" size="5 5 0.1"/>
            <body pos="1 0.5 0.1"><freejoint/><geom type="sphere" size="0.1" mass="2"/></body>
            </worldbody></mujoco>"#;
        let model = crate::mjcf::load_str(xml, "<string>")
            .unwrap_or_else(|e| panic!("{e}"))
            .model;
        let mut s = State::reference(&model);
        let mut ws = crate::state::Workspace::new(&model);
        let mut prev = s.clone();
        for _ in 0..20 {
            prev = s.clone();
            crate::step::step(&model, &mut s, &mut ws, &[]).unwrap_or_else(|e| panic!("{e}"));
        }
        let cf = contact_forces(&model, &prev, &s);
        let weight = 9.81 * 2.0;
        let close = |a: f64, b: f64| (a - b).abs() < 1e-6 * weight;
        assert!(
            close(cf.force_c[0], weight),
            "normal force {}",
            cf.force_c[0]
        );
        let w = &cf.body_wrench[6..12];
        let expected = [0.5 * weight, -weight, 0.0, 0.0, 0.0, weight];
        for (got, want) in w.iter().zip(expected) {
            assert!(close(*got, want), "wrench {w:?}, expected {expected:?}");
        }
        assert!(cf.body_wrench[..6].iter().all(|x| *x == 0.0));
    }
}
