//! Per-rollout [`State`], reusable scratch [`Workspace`], and the per-step [`StepReport`].
use nalgebra::{Matrix3, Vector3};

use crate::joints::geometry::Pose;
use crate::math::quat;
use crate::model::Model;
use crate::solver::graph_ldu::BlockMatrix;

/// Everything that evolves. Flat arrays, body-major, world body included at index 0.
///
/// Velocities are the *midpoint* velocities of the variational integrator: the velocity that
/// carried the previous configuration to this one (`v_{k-1/2}`), which is what the next step
/// needs. They are used as the body velocities everywhere (minimal coordinates included).
#[derive(Clone, Debug, PartialEq)]
pub struct State {
    /// Simulation time (s).
    pub time: f64,
    /// COM positions, world (m). Shape (nbody, 3).
    pub com_pos: Vec<f64>,
    /// Orientations `(w, x, y, z)`, body to world. Shape (nbody, 4).
    pub quat: Vec<f64>,
    /// COM linear midpoint velocities, world (m/s). Shape (nbody, 3).
    pub com_linvel: Vec<f64>,
    /// Angular midpoint velocities, body frame (rad/s). Shape (nbody, 3).
    pub angvel_b: Vec<f64>,
    /// Joint constraint impulses of the last step (N·s), the solver's warm start. Shape (ncon,).
    pub joint_impulse: Vec<f64>,
    /// Turns of each winding hinge ([`crate::Joint::winds`]), as the multiple of 2π its `qpos`
    /// adds to the angle its bodies' poses give in (-π, π]: a wheel's angle winds on as
    /// MuJoCo's does, and its springs and servos see the wound angle. Each step carries the
    /// turns on (no hinge turns by π in one step: `newton::physical_spin_limit`).
    pub(crate) winding: Vec<f64>,
    /// Interior-point variables of every contact candidate, then every joint limit, then every
    /// tendon limit (their node layouts, see `solver::inequality`), from the last step.
    pub ineq_vars: Vec<f64>,
    /// Length of the time interval whose midpoint velocities the state holds, as a fraction of
    /// the time step of the model that steps it: 1 after a step, `1/n` after a step taken as `n`
    /// sub-steps (see `step`); `None` before the first step (velocities set by the user count
    /// as the interval of whatever step takes them: a spin set past the step map's domain `2/h`
    /// is then taken as sub-steps of its own length). Setting velocities (`set_minimal`) keeps
    /// it, so the gradients' rebuilt states step as the states they came from. The discrete momentum a step starts from is that
    /// interval's. A fraction rather than seconds, so that the derivative with respect to the
    /// time step (a model parameter) sees both intervals scale with it; a state stepped by a
    /// model with another time step counts its interval in that model's.
    pub(crate) interval: Option<f64>,
    pub(crate) topology_id: u64,
}

impl State {
    /// Bytes of the state's arrays (what keeping it costs).
    pub(crate) fn heap_bytes(&self) -> usize {
        8 * self.parts().iter().map(|v| v.len()).sum::<usize>()
    }

    /// The length of the interval of the state's velocities ([`State::interval`]) when stepped
    /// with time step `h`.
    pub(crate) fn interval(&self, h: f64) -> f64 {
        h * self.interval.unwrap_or(1.0)
    }

    /// Copy the motion of `other` (a state of the same model: time, poses, velocities and
    /// their interval) into `self`, leaving the solver's warm start (impulses, interior-point
    /// variables) as it is.
    pub(crate) fn copy_motion_from(&mut self, other: &State) {
        self.time = other.time;
        self.com_pos.copy_from_slice(&other.com_pos);
        self.quat.copy_from_slice(&other.quat);
        self.com_linvel.copy_from_slice(&other.com_linvel);
        self.angvel_b.copy_from_slice(&other.angvel_b);
        self.winding.copy_from_slice(&other.winding);
        self.interval = other.interval;
    }

    /// Copy `other` (a state of the same model) into `self` without allocating.
    pub(crate) fn copy_from(&mut self, other: &State) {
        self.copy_all_but_ineq_vars(other);
        self.ineq_vars.copy_from_slice(&other.ineq_vars);
    }

    /// [`Self::copy_from`] but for the inequality variables.
    fn copy_all_but_ineq_vars(&mut self, other: &State) {
        self.copy_motion_from(other);
        self.joint_impulse.copy_from_slice(&other.joint_impulse);
        self.topology_id = other.topology_id;
    }

    /// [`Self::copy_from`] that takes `other`'s inequality variables by swapping them with
    /// `self`'s, for a caller that rewrites every one of `other`'s next
    /// ([`crate::solver::newton::write_state`] of a model with complementarity pairs).
    pub(crate) fn copy_taking_ineq_vars(&mut self, other: &mut State) {
        self.copy_all_but_ineq_vars(other);
        assert_eq!(
            self.ineq_vars.len(),
            other.ineq_vars.len(),
            "states of one model"
        );
        std::mem::swap(&mut self.ineq_vars, &mut other.ineq_vars);
    }

    /// The reference configuration at rest.
    pub fn reference(model: &Model) -> State {
        let n = model.nbody();
        let mut s = State {
            time: 0.0,
            com_pos: vec![0.0; 3 * n],
            quat: vec![0.0; 4 * n],
            com_linvel: vec![0.0; 3 * n],
            angvel_b: vec![0.0; 3 * n],
            joint_impulse: vec![0.0; model.ncon()],
            winding: vec![0.0; model.topology.winding_adr.iter().flatten().count()],
            ineq_vars: Vec::new(),
            interval: None,
            topology_id: model.topology_id(),
        };
        s.ineq_vars = neutral_ineq_vars(model);
        for (b, body) in model.bodies.iter().enumerate() {
            s.set_pose(b, &body.ref_pose);
        }
        s
    }

    /// Every number of the state in one flat vector, which [`State::from_snapshot`] turns back
    /// into the same state bit for bit: `[time, interval, com_pos, quat, com_linvel, angvel_b,
    /// joint_impulse, winding, ineq_vars]` (the interval NaN when unset; winding only for
    /// models with winding hinges). Unlike `[qpos, qvel]` it
    /// keeps the solver's warm start, so a step from the restored state takes the same
    /// iterates: a checkpoint of a run, or a hard step kept as a test fixture.
    pub fn snapshot(&self) -> Vec<f64> {
        let mut out = Vec::with_capacity(2 + self.heap_bytes() / 8);
        out.extend([self.time, self.interval.unwrap_or(f64::NAN)]);
        for part in self.parts() {
            out.extend_from_slice(part);
        }
        out
    }

    /// The state of `model` that [`State::snapshot`] wrote; the snapshot's length must be the
    /// one `model`'s states have, its interval NaN or positive and finite, its time, poses,
    /// velocities and joint impulses finite and its orientations unit quaternions (the
    /// interior-point variables may hold anything: a warm start that is not finite starts from
    /// the neutral point).
    pub fn from_snapshot(model: &Model, values: &[f64]) -> crate::Result<State> {
        let mut s = State::reference(model);
        let len = 2 + s.heap_bytes() / 8;
        crate::ensure!(
            values.len() == len,
            crate::Error::Shape {
                name: "snapshot".into(),
                expected: vec![len],
                got: vec![values.len()],
            }
        );
        let interval = values[1];
        crate::ensure!(
            interval.is_nan() || (interval > 0.0 && interval.is_finite()),
            crate::Error::InvalidInput {
                field: "snapshot[1] (interval)".into(),
                value: interval.to_string(),
                reason: "must be NaN (unset) or positive and finite".into(),
            }
        );
        let ineq = len - s.ineq_vars.len();
        if let Some(i) = (0..ineq).find(|&i| i != 1 && !values[i].is_finite()) {
            return Err(crate::Error::InvalidInput {
                field: format!("snapshot[{i}]"),
                value: values[i].to_string(),
                reason: "time, poses, velocities and joint impulses must be finite".into(),
            });
        }
        let quats = 2 + s.com_pos.len();
        for (b, q) in values[quats..quats + s.quat.len()].chunks(4).enumerate() {
            let norm = q.iter().map(|x| x * x).sum::<f64>().sqrt();
            crate::ensure!(
                (norm - 1.0).abs() < 1e-9,
                crate::Error::InvalidInput {
                    field: format!(
                        "snapshot[{}..{}] (orientation of body {b})",
                        quats + 4 * b,
                        quats + 4 * b + 4
                    ),
                    value: format!("{q:?}"),
                    reason: format!("must be a unit quaternion (norm {norm})"),
                }
            );
        }
        s.time = values[0];
        s.interval = (!interval.is_nan()).then_some(interval);
        let mut rest = &values[2..];
        for part in s.parts_mut() {
            let (head, tail) = rest.split_at(part.len());
            part.copy_from_slice(head);
            rest = tail;
        }
        Ok(s)
    }

    /// The state's arrays, in [`State::snapshot`]'s order.
    fn parts(&self) -> [&Vec<f64>; 7] {
        [
            &self.com_pos,
            &self.quat,
            &self.com_linvel,
            &self.angvel_b,
            &self.joint_impulse,
            &self.winding,
            &self.ineq_vars,
        ]
    }

    /// [`State::parts`], mutable.
    fn parts_mut(&mut self) -> [&mut Vec<f64>; 7] {
        [
            &mut self.com_pos,
            &mut self.quat,
            &mut self.com_linvel,
            &mut self.angvel_b,
            &mut self.joint_impulse,
            &mut self.winding,
            &mut self.ineq_vars,
        ]
    }

    /// This state's motion (poses, velocities, joint impulses, time) as a state of `model`, a
    /// model with the same bodies and joints (e.g. [`Model::with_contact_model`]); the
    /// inequality variables start from `model`'s neutral point.
    pub fn moved_to(&self, model: &Model) -> State {
        let mut s = State::reference(model);
        s.copy_motion_from(self);
        s.joint_impulse.copy_from_slice(&self.joint_impulse);
        s
    }

    /// `other`, a state of `pyramid` (this state's model `model` with its second-order friction
    /// cones as pyramids, [`Model::with_contact_model`]), written into this state: motion and
    /// joint impulses as they are; each pyramid candidate's impulse `(γ, β₁ - β₂, β₃ - β₄)` as
    /// the cone's `ξ = (μγ, β₁ - β₂, β₃ - β₄)` (inside the cone: the pyramid is inscribed),
    /// and its slip `(ψ, v_t)` (`η_k = ψ ± v_t·t`) as the cone's dual `η`; limits unchanged.
    /// What the next step warm-starts from and `contact_impulse` reports.
    pub fn take_pyramid(&mut self, model: &Model, pyramid: &Model, other: &State) {
        use crate::contact::ContactModel::{Linear, Nonlinear};
        self.copy_motion_from(other);
        self.joint_impulse.copy_from_slice(&other.joint_impulse);
        let (mut k, mut j) = (0, 0);
        for (c, p) in model.contacts.iter().zip(&pyramid.contacts) {
            let (me, x) = (
                &mut self.ineq_vars[k..k + c.model.dim()],
                &other.ineq_vars[j..j + p.model.dim()],
            );
            if (c.model, p.model) == (Nonlinear, Linear) {
                let xi = [c.friction * x[0], x[4] - x[5], x[6] - x[7]];
                let eta = [x[2], 0.5 * (x[8] - x[9]), 0.5 * (x[10] - x[11])];
                me[..2].copy_from_slice(&x[..2]);
                me[2..5].copy_from_slice(&xi);
                me[5..].copy_from_slice(&eta);
            } else {
                me.copy_from_slice(x);
            }
            k += c.model.dim();
            j += p.model.dim();
        }
        self.ineq_vars[k..].copy_from_slice(&other.ineq_vars[j..]);
    }

    /// COM pose of body `b`.
    pub fn pose(&self, b: usize) -> Pose {
        Pose {
            pos: self.v3(&self.com_pos, b),
            quat: quat::from_wxyz(&self.quat[4 * b..4 * b + 4]),
        }
    }

    /// Set the COM pose of body `b`.
    pub fn set_pose(&mut self, b: usize, pose: &Pose) {
        self.com_pos[3 * b..3 * b + 3].copy_from_slice(pose.pos.as_slice());
        self.quat[4 * b..4 * b + 4].copy_from_slice(quat::wxyz(&pose.quat).as_slice());
    }

    /// `(v, ω_b)` of body `b`.
    pub fn velocity(&self, b: usize) -> (Vector3<f64>, Vector3<f64>) {
        (self.v3(&self.com_linvel, b), self.v3(&self.angvel_b, b))
    }

    /// Set `(v, ω_b)` of body `b`.
    pub fn set_velocity(&mut self, b: usize, v: &Vector3<f64>, w: &Vector3<f64>) {
        self.com_linvel[3 * b..3 * b + 3].copy_from_slice(v.as_slice());
        self.angvel_b[3 * b..3 * b + 3].copy_from_slice(w.as_slice());
    }

    fn v3(&self, a: &[f64], b: usize) -> Vector3<f64> {
        Vector3::new(a[3 * b], a[3 * b + 1], a[3 * b + 2])
    }

    /// Whether this state was made for `model`'s topology.
    pub fn check_model(&self, model: &Model) -> crate::Result<()> {
        crate::ensure!(
            self.topology_id == model.topology_id() && self.com_pos.len() == 3 * model.nbody(),
            crate::Error::ModelMismatch {
                detail: format!(
                    "state has {} bodies, model has {}",
                    self.com_pos.len() / 3,
                    model.nbody()
                )
            }
        );
        Ok(())
    }

    /// Body frame origins, world (MuJoCo's `xpos`). Shape (nbody, 3).
    pub fn body_pos(&self, model: &Model) -> Vec<f64> {
        let mut out = Vec::with_capacity(3 * model.nbody());
        for (b, body) in model.bodies.iter().enumerate() {
            let p = self.pose(b);
            out.extend((p.pos - quat::rotation(&p.quat) * body.com).iter());
        }
        out
    }

    /// Linear velocities of the body frame origins, world (m/s). Shape (nbody, 3).
    pub fn body_linvel(&self, model: &Model) -> Vec<f64> {
        let mut out = Vec::with_capacity(3 * model.nbody());
        for (b, body) in model.bodies.iter().enumerate() {
            let r = quat::rotation(&self.pose(b).quat);
            let (v, w) = self.velocity(b);
            out.extend((v - (r * w).cross(&(r * body.com))).iter());
        }
        out
    }

    /// Angular velocities, world frame (rad/s). Shape (nbody, 3).
    pub fn body_angvel(&self, _model: &Model) -> Vec<f64> {
        let mut out = Vec::with_capacity(self.angvel_b.len());
        for b in 0..self.angvel_b.len() / 3 {
            out.extend((quat::rotation(&self.pose(b).quat) * self.velocity(b).1).iter());
        }
        out
    }
}

/// The neutral interior point (γ = s = 1, cones at e) for every inequality node.
fn neutral_ineq_vars(model: &Model) -> Vec<f64> {
    use crate::contact::ContactModel;
    let mut v = Vec::new();
    for c in &model.contacts {
        let mut x = vec![1.0; c.model.dim()];
        if c.model == ContactModel::Nonlinear {
            x[3] = 0.0;
            x[4] = 0.0;
            x[6] = 0.0;
            x[7] = 0.0;
        }
        v.extend(x);
    }
    v.extend(std::iter::repeat_n(1.0, 4 * model.nlimit()));
    v.extend(std::iter::repeat_n(1.0, 4 * model.tendon_limits.len()));
    // dry friction, joints' then tendons': at rest (equal displacements both ways, 1 rad/s or
    // m/s), τ = 0 (`solver::friction`)
    let h = model.options.timestep;
    let joints = model
        .joints
        .iter()
        .flat_map(|j| j.friction_dofs().map(|(_, f)| f));
    let tendons = model.passive_tendons.iter().map(|t| t.frictionloss);
    for f in joints.chain(tendons.filter(|&f| f > 0.0)) {
        v.extend([h, f * h, h, f * h]);
    }
    v
}

impl State {
    /// Contact impulses of the last step in each candidate's contact frame `(normal, t1, t2)`
    /// (N·s). Shape (ncontact, 3).
    pub fn contact_impulse(&self, model: &Model) -> Vec<f64> {
        use crate::contact::ContactModel;
        let mut out = Vec::with_capacity(3 * model.ncontact());
        let mut k = 0;
        for c in &model.contacts {
            let x = &self.ineq_vars[k..k + c.model.dim()];
            out.extend(match c.model {
                ContactModel::Impact => [x[0], 0.0, 0.0],
                ContactModel::Nonlinear => [x[0], x[3], x[4]],
                ContactModel::Linear => [x[0], x[4] - x[5], x[6] - x[7]],
            });
            k += c.model.dim();
        }
        out
    }

    /// Add the impulses of `other` (a state of the same model) to this state's: joint impulses
    /// and the impulse entries of every inequality node (γ, friction; limit and tendon γ's),
    /// leaving slacks and velocity-like entries alone. Sums the sub-steps of a subdivided step,
    /// so that the state reports the impulse over the whole step and warm-starts the next
    /// full step at the right scale.
    pub(crate) fn add_impulses(&mut self, model: &Model, other: &State) {
        use crate::contact::ContactModel;
        for (a, b) in self.joint_impulse.iter_mut().zip(&other.joint_impulse) {
            *a += b;
        }
        let mut k = 0;
        let add = |k: usize, idx: &[usize], me: &mut [f64]| {
            for &i in idx {
                me[k + i] += other.ineq_vars[k + i];
            }
        };
        for c in &model.contacts {
            let idx: &[usize] = match c.model {
                ContactModel::Impact => &[0],
                ContactModel::Nonlinear => &[0, 2, 3, 4],
                ContactModel::Linear => &[0, 3, 4, 5, 6, 7],
            };
            add(k, idx, &mut self.ineq_vars);
            k += c.model.dim();
        }
        while k < self.ineq_vars.len() {
            add(k, &[0, 2], &mut self.ineq_vars); // limit dofs and tendon limits: [γ_lo, s_lo, γ_hi, s_hi]
            k += 4;
        }
    }

    /// Length `Σ coef q` of each tendon limit's tendon (m or rad). Shape (n tendon limits,).
    pub fn tendon_length(&self, model: &Model) -> Vec<f64> {
        let q = crate::joints::coordinates::qpos(model, self);
        // hinge/slide terms only: the term's dof is its qpos index within the joint
        let at = |j: usize, d: usize| q[model.joints[j].qpos_adr + d];
        model.tendon_limits.iter().map(|t| t.length(at)).collect()
    }

    /// Impulse of each tendon limit in the last step, `γ_lo - γ_hi` (N·s for slide terms, N·m·s
    /// for hinge terms, per unit of coef): positive pushes the length up off its lower limit.
    /// Shape (n tendon limits,).
    pub fn tendon_impulse(&self, model: &Model) -> Vec<f64> {
        let end = self.ineq_vars.len() - 4 * (model.nfriction() + model.ntendon_friction());
        let start = end - 4 * model.tendon_limits.len();
        self.ineq_vars[start..end]
            .chunks_exact(4)
            .map(|x| x[0] - x[2])
            .collect()
    }

    /// Dry-friction impulse of each joint dof with `frictionloss` in the last step (joints in
    /// order, their dofs in order; N·s or N·m·s), positive resisting a positive rate: `±f h`
    /// while the dof slides, less while it sticks. Shape (n friction dofs,).
    pub fn joint_friction_impulse(&self, model: &Model) -> Vec<f64> {
        let end = self.ineq_vars.len() - 4 * model.ntendon_friction();
        let start = end - 4 * model.nfriction();
        crate::solver::friction::impulses(&self.ineq_vars[start..end]).collect()
    }

    /// Dry-friction impulse of each passive tendon with `frictionloss` in the last step (N·s or
    /// N·m·s per unit length), positive resisting a lengthening tendon. Shape (n tendons with
    /// friction,).
    pub fn tendon_friction_impulse(&self, model: &Model) -> Vec<f64> {
        let start = self.ineq_vars.len() - 4 * model.ntendon_friction();
        crate::solver::friction::impulses(&self.ineq_vars[start..]).collect()
    }
}

/// How a solve ended.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum SolveStatus {
    /// Residual below `rtol` (and complementarity below `kappa_tol`).
    Converged,
    /// The iteration stalled (line search or `max_iter`) before reaching `rtol`/`kappa_tol`,
    /// at an iterate within `acceptable_rtol`/`acceptable_kappa_tol` (IPOPT's "solved to
    /// acceptable level"): round-off in an ill-conditioned Newton matrix, typically a
    /// statically indeterminate contact set, keeps the tight tolerances out of reach. A
    /// success: the state is valid to the acceptable tolerances, which `residual` and
    /// `complementarity` report.
    Acceptable,
    /// `max_iter` reached first, or the attempt stalled (`Options::stall_iter`).
    MaxIterations,
    /// No step length reduced the residual.
    LineSearchFailed,
    /// A NaN or infinity appeared (or a pivot was singular).
    NonFinite,
    /// Every attempt with the exact friction cones failed and the step converged with each
    /// cone replaced by its inscribed four-sided pyramid (`Options::pyramid_fallback`). A
    /// success: no penetration, contact forces inside the Coulomb cones, residual to `rtol` (of
    /// the pyramid problem); a sliding contact's friction direction is the pyramid's. Not
    /// differentiable: the gradients, linearising the exact cones, report such a step as
    /// unconverged.
    PyramidFriction,
}

impl SolveStatus {
    /// Python-facing name (`"converged"`, ...).
    pub fn name(self) -> &'static str {
        match self {
            SolveStatus::Converged => "converged",
            SolveStatus::Acceptable => "acceptable",
            SolveStatus::MaxIterations => "max_iterations",
            SolveStatus::LineSearchFailed => "line_search_failed",
            SolveStatus::NonFinite => "non_finite",
            SolveStatus::PyramidFriction => "pyramid_friction",
        }
    }
    /// Small integer code for status arrays: 0 = converged, 1 = acceptable, 2-4 = failures,
    /// 5 = pyramid friction (valid, not differentiable; last so that the earlier codes keep
    /// their meaning).
    pub fn code(self) -> u8 {
        self as u8
    }
    /// Every status in code order.
    pub const ALL: [SolveStatus; 6] = [
        SolveStatus::Converged,
        SolveStatus::Acceptable,
        SolveStatus::MaxIterations,
        SolveStatus::LineSearchFailed,
        SolveStatus::NonFinite,
        SolveStatus::PyramidFriction,
    ];
    /// Whether the step's state is valid: converged, solved to the acceptable level, or
    /// converged with pyramid friction cones.
    pub fn is_success(self) -> bool {
        matches!(
            self,
            SolveStatus::Converged | SolveStatus::Acceptable | SolveStatus::PyramidFriction
        )
    }
}

/// What one step reports. Non-convergence is a result, never silent.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct StepReport {
    /// How the solve ended.
    pub status: SolveStatus,
    /// Newton iterations used.
    pub iterations: usize,
    /// Final ∞-norm of the residual.
    pub residual: f64,
    /// Final complementarity violation (0 without inequality constraints).
    pub complementarity: f64,
    /// Equal sub-steps the step was taken in: 1, or `n > 1` when the solve of the whole step
    /// failed and `n` sub-steps of `h / n` succeeded ([`crate::Options::max_subdivisions`]);
    /// iterations then count every attempt, residual and complementarity are the worst
    /// sub-step's.
    pub subdivisions: u32,
}

/// One interior-point iteration, as recorded by [`Workspace::set_trace`] (the convergence study
/// of Dojo's Figs. 9-10 and solver debugging).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct IterationRecord {
    /// Attempt within the step, counting up: 0 = first solve, then each retry in turn (the
    /// first attempt widened gently, cold retries, wider activations, re-solves after a missed
    /// contact).
    pub attempt: u8,
    /// Equality residual ∞-norm before the iteration (eq. 49).
    pub residual: f64,
    /// Complementarity violation before the iteration (eq. 50).
    pub complementarity: f64,
    /// Mean complementarity `μ`.
    pub mu: f64,
    /// Central-path target of the corrector.
    pub kappa: f64,
    /// Affine (predictor) step length.
    pub alpha_aff: f64,
    /// Accepted step length (0 when the line search failed).
    pub alpha: f64,
    /// Whether Mehrotra's corrected direction was accepted (else the plain centred Newton one).
    pub corrector: bool,
    /// 2-norm condition number of the Newton matrix on the rows the solve factors (the contact
    /// candidates left out are not among them; only with `set_trace(true, true)`; NaN
    /// otherwise).
    pub condition: f64,
}

/// Scratch memory for [`crate::step()`], allocated once per model and reused (no allocation in
/// steady state).
pub struct Workspace {
    pub(crate) matrix: BlockMatrix,
    /// Newton unknowns `[v⁺, ω⁺ per moving body; λ per constraint row]`, node layout.
    pub(crate) w: Vec<f64>,
    /// The best acceptable iterate of a failed attempt, kept while retries try to converge; the
    /// interior-point solution while `solver::saturation` polishes it.
    pub(crate) w_acceptable: Vec<f64>,
    /// The friction holds (`saturated`) of the acceptable iterate in `w_acceptable` kept by a
    /// failed attempt: restored with it (the retries release and reset holds).
    pub(crate) saturated_acceptable: Vec<Option<crate::solver::saturation::Hold>>,
    /// A converged solve's iterate and activation, kept while a missed-contact round solves
    /// the step again with more candidates (`newton::restart_from_solution`).
    pub(crate) w_solved: Vec<f64>,
    pub(crate) active_solved: Vec<bool>,
    pub(crate) w_trial: Vec<f64>,
    pub(crate) residual: Vec<f64>,
    /// The last `newton::evaluate_kept` (boxed: a workspace is moved around by value).
    pub(crate) kept: Box<crate::solver::newton::Kept>,
    pub(crate) delta: Vec<f64>,
    /// Applied impulses per body, `[h(m g + f); h τ_b]` plus joint springs and inputs.
    pub(crate) applied: Vec<[f64; 6]>,
    /// The state a step started from, kept for its energy check and a retry as sub-steps
    /// (`step::step_with`) without allocating.
    pub(crate) start: State,
    /// `∂φ/∂ω` at the trial next configuration, per body.
    pub(crate) dphi: Vec<Matrix3<f64>>,
    pub(crate) next_pose: Vec<Pose>,
    /// Constraint Jacobian at the current configuration (impulse map), `ncon × 12` rows.
    pub(crate) jac_now: Vec<f64>,
    /// Constraint Jacobian at the trial next configuration.
    pub(crate) jac_next: Vec<f64>,
    /// Free-coordinate Jacobian at the current configuration, per joint `nfree × 12`.
    pub(crate) free_jac: Vec<f64>,
    pub(crate) free_adr: Vec<usize>,
    /// Spring and applied generalized forces per joint free dof (current configuration).
    pub(crate) joint_tau: Vec<[f64; 6]>,
    /// Coordinates of each joint at the current configuration (the actuators' lengths).
    pub(crate) joint_q: Vec<[f64; 7]>,
    /// Joints whose current- and next-configuration terms are recomputed (empty: all). Set only
    /// by the gradients' partials, whose perturbations move a few bodies: the other joints'
    /// `jac_now`, `free_jac`, `joint_tau` and `joint_q` are kept from the unperturbed point, and
    /// their own rows and limit rows are left stale (they lie outside the perturbation's
    /// support).
    pub(crate) joint_filter: Vec<bool>,
    /// Bodies whose rows are written (empty: all). Set only by the gradients' partials with
    /// [`Self::joint_filter`]: the other bodies' rows lie outside the perturbation's support, so
    /// their momenta and the joint terms acting on them alone are not computed.
    pub(crate) body_filter: Vec<bool>,
    /// Scalar force of each actuator (current state and controls), less the velocity term of
    /// a servo whose velocity gain acts implicitly (`actuation::split_force`).
    pub(crate) act_force: Vec<f64>,
    /// Per free dof (`free_adr[j] / 12 + dof`): the damping that servos' velocity gains add to
    /// the joint's own for this step, taken implicitly like it.
    pub(crate) servo_damping: Vec<f64>,
    /// Per actuator: the damping a fixed-tendon servo's velocity gain puts on the tendon's rate
    /// for this step (0 for the others), taken implicitly.
    pub(crate) tendon_damping: Vec<f64>,
    /// Spring force `-k (L - L₀)` of each passive tendon at the current configuration.
    pub(crate) tendon_spring: Vec<f64>,
    /// `∂k/∂x` of each joint coupling at the current configuration.
    pub(crate) coupling_slope: Vec<f64>,
    /// Per candidate: the feature held fixed for this step (a near-flat disk's rim point, a box
    /// corner's face), see [`crate::contact::freeze_for_step`].
    pub(crate) frozen: Vec<Option<crate::contact::Frozen>>,
    /// Signed distance of each candidate at the current configuration.
    pub(crate) contact_phi_now: Vec<f64>,
    /// Rate of change of each candidate's distance at its current witness points (m/s,
    /// negative when approaching): the activation's estimate of the step's approach.
    pub(crate) contact_rate_now: Vec<f64>,
    /// Whether each candidate's current-configuration data (`frozen`, `contact_phi_now`,
    /// `contact_rate_now`, `contact_step`) were computed this step; a candidate out of any
    /// activation's reach skips them (`activation::prepare`) until it is activated.
    pub(crate) prepared: Vec<bool>,
    /// Each geom's bounding sphere and speed at the current configuration (`prepare`).
    pub(crate) geom_bounds: Vec<crate::solver::activation::GeomBound>,
    /// Each geom's body pose and world poses, current and predicted, for one pass of
    /// `activation::prepare` (see `activation::GeomPoses`).
    pub(crate) geom_poses: Vec<crate::solver::activation::GeomPoses>,
    /// Impulse rows and no-slip measures of the step (current configuration, built on first
    /// use).
    pub(crate) contact_step: Vec<crate::contact::StepRows>,
    /// Signed distance and its gradient row at the trial next configuration, per contact.
    pub(crate) contact_phi: Vec<f64>,
    pub(crate) contact_dphi: Vec<[f64; 12]>,
    /// First limited dof of each joint in `limit_dtheta`.
    pub(crate) limit_adr: Vec<usize>,
    /// `∂θ/∂(δx⁺)` of each limited dof at the trial next configuration.
    pub(crate) limit_dtheta: Vec<[f64; 12]>,
    pub(crate) delta_aff: Vec<f64>,
    /// The right-hand sides of the Jacobians' transposed solves, `rows × outputs` row-major;
    /// zero between uses (a use clears the rows it wrote), so it is sized once per workspace.
    pub(crate) jacobian_rhs: Vec<f64>,
    /// Whether each contact candidate, then each joint's limits (index `ncontact + j`), then
    /// each tendon limit (`ncontact + njoint + k`) take part in the current step (see
    /// [`crate::Options::activation_margin`]); inactive ones carry no impulse and no solver
    /// work.
    pub(crate) active: Vec<bool>,
    /// Per limited dof (`limit_adr`), then per tendon limit: its slacks `(q - lo, hi - q)` at
    /// the step's start, what an inactive limit keeps in its slack variables.
    pub(crate) limit_slack_now: Vec<[f64; 2]>,
    /// Per limited dof, then per tendon limit: the rate of its coordinate at the step's start,
    /// `q̇` (what the κ taper of the smoothed step reads, `solver::taper`).
    pub(crate) limit_rate_now: Vec<f64>,
    /// Per candidate: how its friction cone is held out of the interior-point iteration — on
    /// the cone's boundary after the solve, or at zero for a pair that cannot slip (see
    /// `solver::saturation::Hold`); `None` for complementarity rows.
    pub(crate) saturated: Vec<Option<crate::solver::saturation::Hold>>,
    /// Per contact candidate, then per joint: whether its complementarity pairs block the
    /// interior-point direction (`solver::central::unblock`'s scratch).
    pub(crate) blocking: Vec<bool>,
    /// Per contact candidate: left out of this step's solve because a tighter candidate between
    /// the same two sliding bodies, along the same normal, implies it
    /// (`solver::saturation::hold_frictionless`).
    pub(crate) shadowed: Vec<bool>,
    pub(crate) topology_id: u64,
    /// Nesterov–Todd scaling of each contact's friction-cone pair at the current interior-point
    /// iterate (`None`: unscaled rows), used while `nt_on` (the IPM's directions; the
    /// gradients linearise the unscaled residual).
    pub(crate) nt: Vec<Option<crate::contact::cone::NtScaling>>,
    pub(crate) nt_on: bool,
    /// Set for a retry without scaling (see `newton::solve_active`).
    pub(crate) nt_disabled: bool,
    /// Per-iteration records of the last step (`None`: not recorded, the default).
    pub(crate) trace: Option<Vec<IterationRecord>>,
    /// Whether the trace also estimates condition numbers (dense, slow).
    pub(crate) trace_condition: bool,
    pub(crate) attempt: u8,
    /// Whether the last interior-point attempt ended stalled near convergence
    /// (`Options::acceptable_iter`): its acceptable iterate ends the solve without retries.
    pub(crate) stalled_near: bool,
    /// The proximal term `ρ` on the friction impulses in the Newton matrix
    /// (`Options::friction_proximal`; 0 outside a hard interior-point solve).
    pub(crate) proximal: f64,
    /// The least slack of an orthant complementarity pair in the Newton matrix relative to its
    /// impulse, `s ≥ slack_floor · γ` (matrix only; 0 but while the gradients assemble their
    /// matrix at the gradient point, see `gradients::SLACK_FLOOR`).
    pub(crate) slack_floor: f64,
    /// Whether κ weighs each contact candidate's and limit's pairs by its gap (slack) and rate
    /// at the step's start (`solver::taper`): set by the smoothed step's solve (`solver::central::solve`) for the
    /// gradients at `kappa_grad`, cleared by every hard solve (`solver::ipm::solve_to`).
    pub(crate) kappa_taper: bool,
    /// The left-out candidates' pairs modelled in the mean complementarity (none but in the
    /// third activation tier, see `FarPairs`).
    pub(crate) far: crate::solver::inequality::FarPairs,
    /// Whether the third activation tier activates every candidate rather than modelling the
    /// left-out ones (`newton::solve`): set by a step's last resort (`step::long_solve`).
    pub(crate) every_candidate: bool,
    /// Set while a failed first attempt is solved again with its warm start widened by the
    /// gentle `ipm::WIDEN_IMPULSE_GENTLE` instead of `Options::warm_start_widening`
    /// (`newton::solve_active`).
    pub(crate) gentle_widening: bool,
    /// Set while a missed-contact round solves the step again from the converged solution
    /// (`newton::restart_from_solution`): a warm start too, widened when its first predictor
    /// is cut as a first attempt's is. The next interior-point solve takes (clears) it.
    pub(crate) resumed: bool,
    /// Whether the last interior-point attempt widened its warm start.
    pub(crate) widened: bool,
    /// Set while a sub-step of a subdivided step is solved (`step::attempt`): its warm start,
    /// the previous sub-step's solution, turns less than a whole step's, so a sliding cone
    /// need not cut its first predictor (`inequality::turning_on_boundaries`).
    pub(crate) substep: bool,
}

impl Workspace {
    /// Whether the interior-point attempt under way is a step's first (or that attempt again,
    /// widened gently): it may widen its warm start and hold separated candidates' friction.
    pub(crate) fn first_attempt(&self) -> bool {
        self.attempt == 0 || self.gentle_widening
    }
}

/// Most spare workspaces kept per thread ([`Workspace::pooled`]): a linearisation holds two
/// (the solve's and the partials'). The memory stays with the thread until other workspaces
/// replace them: measured (RSS after a step) 0.9 MB per workspace for the humanoid, 3.7 MB for
/// the A1 (1024 contact candidates), 4.5 MB for the Panda, so a batched gradient of the Panda
/// over 16 threads may keep ~150 MB.
const SPARES: usize = 2;

thread_local! {
    /// Spare workspaces of the internal entry points (gradients, flat steps), per thread.
    static SPARE: std::cell::RefCell<Vec<Workspace>> = const { std::cell::RefCell::new(Vec::new()) };
}

/// A workspace that goes back to this thread's spares when dropped (see
/// [`Workspace::pooled`]); it dereferences to the workspace.
///
/// The `Option` is `Some` from construction until `into_inner` (which consumes the wrapper) or
/// `drop` takes it, so the `expect`s below cannot fire (hence the local allowances).
pub(crate) struct Recycled(Option<Workspace>);

impl Recycled {
    pub(crate) fn new(ws: Workspace) -> Recycled {
        Recycled(Some(ws))
    }

    /// The workspace itself, kept by the caller (not recycled).
    #[allow(clippy::expect_used)]
    pub(crate) fn into_inner(mut self) -> Workspace {
        self.0
            .take()
            .expect("a recycled workspace is present until dropped")
    }
}

impl std::ops::Deref for Recycled {
    type Target = Workspace;
    #[allow(clippy::expect_used)]
    fn deref(&self) -> &Workspace {
        self.0
            .as_ref()
            .expect("a recycled workspace is present until dropped")
    }
}

impl std::ops::DerefMut for Recycled {
    #[allow(clippy::expect_used)]
    fn deref_mut(&mut self) -> &mut Workspace {
        self.0
            .as_mut()
            .expect("a recycled workspace is present until dropped")
    }
}

impl Drop for Recycled {
    fn drop(&mut self) {
        if let Some(ws) = self.0.take() {
            // a thread being torn down has no spares left to keep it in
            let _ = SPARE.try_with(|s| {
                if let Ok(mut s) = s.try_borrow_mut() {
                    if s.len() >= SPARES {
                        s.remove(0);
                    }
                    s.push(ws);
                }
            });
        }
    }
}

impl Workspace {
    /// A workspace for `model`: one of this thread's spares of the same topology, reset to
    /// what [`Workspace::new`] returns in every field a step or a residual evaluation reads
    /// before writing, else a new one. Why: a new workspace costs 0.5-0.7 ms on the A1 and
    /// the Panda (page faults of the block-matrix arena with ~1000 contact candidates), as much
    /// as the step, and the gradients and flat steps used one or two per call.
    pub(crate) fn pooled(model: &Model) -> Workspace {
        Workspace::pooled_with(model, true)
    }

    /// [`Workspace::pooled`] for residual evaluations that bring their own iterate and residual
    /// (the gradients' partials): the iterate, residual and direction buffers are left as the
    /// last use left them, since such a use never reads them. Why: clearing those six
    /// `total_dim` vectors was most of a reset on robots with ~1000 contact candidates (the
    /// Panda: ~0.3 of ~3.4 million instructions of its partials).
    pub(crate) fn pooled_scratch(model: &Model) -> Workspace {
        Workspace::pooled_with(model, false)
    }

    fn pooled_with(model: &Model, iterate: bool) -> Workspace {
        let id = model.topology_id();
        let spare = SPARE
            .try_with(|s| {
                let mut s = s.try_borrow_mut().ok()?;
                let i = s.iter().position(|w| w.topology_id == id)?;
                Some(s.swap_remove(i))
            })
            .ok()
            .flatten();
        match spare {
            Some(mut ws) => {
                ws.reset(iterate);
                ws
            }
            None => Workspace::new(model),
        }
    }

    /// Back to the state of [`Workspace::new`] in everything but the matrix values (written
    /// before they are read) and, unless `iterate`, the iterate, residual and direction buffers.
    fn reset(&mut self, iterate: bool) {
        self.contact_phi_now.fill(0.0);
        self.contact_rate_now.fill(0.0);
        self.prepared.fill(false);
        // (`contact_step` is read only for prepared candidates, and preparing writes it: the
        // element-by-element fill of its 1024 entries was two thirds of a reset on the A1)
        self.frozen.fill(None);
        // (`contact_phi`, `contact_dphi` and `limit_dtheta` are written by every evaluation
        // before anything reads them: left as they are, see `poison_written_before_read`)
        self.active.fill(true);
        self.saturated.fill(None);
        self.blocking.fill(false);
        self.applied.fill([0.0; 6]);
        // (`start` is written by every step before it is read)
        self.dphi.fill(Matrix3::zeros());
        self.next_pose.fill(Pose::world());
        self.jac_now.fill(0.0);
        self.jac_next.fill(0.0);
        self.free_jac.fill(0.0);
        self.joint_tau.fill([0.0; 6]);
        self.joint_q.fill([0.0; 7]);
        self.joint_filter.clear();
        self.body_filter.clear();
        self.act_force.fill(0.0);
        self.servo_damping.fill(0.0);
        self.tendon_damping.fill(0.0);
        self.tendon_spring.fill(0.0);
        self.coupling_slope.fill(0.0);
        // (`nt` is read only while `nt_on`, and every solve clears it first)
        self.nt_on = false;
        self.nt_disabled = false;
        self.kappa_taper = false;
        self.trace = None;
        self.trace_condition = false;
        self.attempt = 0;
        self.gentle_widening = false;
        self.resumed = false;
        self.widened = false;
        self.substep = false;
        self.kept.valid = false;
        #[cfg(debug_assertions)]
        self.poison_written_before_read(iterate);
        if !iterate {
            return;
        }
        // The directions are read through `w + 0 · Δ` (the mean complementarity before a
        // step), so they are cleared; the iterate's other buffers are not (see
        // `poison_written_before_read`).
        self.delta.fill(0.0);
        self.delta_aff.fill(0.0);
    }

    /// Fill with NaN the buffers that a reset leaves as the last use left them because every
    /// step writes them before it reads them: the iterate, trial, acceptable-iterate and
    /// residual vectors (with `iterate`), and the contacts' and limits' distances and gradient
    /// rows at the trial configuration. Debug builds do so at every reset, so that a read
    /// before a write shows as a non-finite solve. Checked: the Rust and Python suites and
    /// the full stress suite pass with this fill in release builds. Clearing them instead
    /// was 4% of the Panda's step Jacobians (six `total_dim` vectors and 835 gradient rows).
    #[cfg(debug_assertions)]
    fn poison_written_before_read(&mut self, iterate: bool) {
        self.contact_phi.fill(f64::NAN);
        self.contact_dphi.fill([f64::NAN; 12]);
        self.limit_dtheta.fill([f64::NAN; 12]);
        if iterate {
            for v in [
                &mut self.w,
                &mut self.w_trial,
                &mut self.w_acceptable,
                &mut self.w_solved,
                &mut self.residual,
            ] {
                v.fill(f64::NAN);
            }
        }
    }

    /// Contact candidates that took part in the last step solved with this workspace (all of
    /// them before the first step); the others were farther than the step's reach and carried
    /// no impulse (see [`crate::Options::activation_margin`]).
    pub fn active_contacts(&self) -> usize {
        self.contact_active().iter().filter(|&&a| a).count()
    }

    /// Joints whose limits took part in the last step (see [`Self::active_contacts`]; a limit
    /// is active when its coordinate is within reach of a bound).
    pub fn active_limits(&self) -> usize {
        let (nj, nt) = (self.limit_adr.len(), self.tendon_active().len());
        let total = self.limit_slack_now.len() - nt;
        let ends = self.limit_adr.iter().skip(1).copied().chain([total]);
        let joints = self.limit_adr.iter().zip(ends);
        let nc = self.saturated.len();
        self.active[nc..nc + nj]
            .iter()
            .zip(joints)
            .filter(|&(&a, (&start, end))| a && end > start)
            .count()
    }

    /// Per tendon limit, whether it took part in the last step (see [`Self::active_limits`]).
    pub fn tendon_active(&self) -> &[bool] {
        &self.active[self.saturated.len() + self.limit_adr.len()..]
    }

    /// Active contacts whose friction the last step held at zero: pairs that can only slide
    /// along the contact normal (`Options::drop_redundant_friction`).
    pub fn frictionless_contacts(&self) -> usize {
        self.active_held(crate::solver::saturation::Hold::Frictionless)
    }

    /// Active contacts held with `hold` by the last step.
    fn active_held(&self, hold: crate::solver::saturation::Hold) -> usize {
        self.saturated
            .iter()
            .zip(&self.active)
            .filter(|&(s, &a)| a && *s == Some(hold))
            .count()
    }

    /// Active contacts whose friction the last step held at zero because they stayed apart
    /// (`Options::drop_redundant_friction`, `solver::saturation::hold_separated`).
    pub fn separated_contacts(&self) -> usize {
        self.active_held(crate::solver::saturation::Hold::Separated)
    }

    /// Contact candidates the last step left out because a tighter parallel one between the same
    /// sliding bodies implies them (`Options::drop_redundant_friction`).
    pub fn shadowed_contacts(&self) -> usize {
        self.shadowed.iter().filter(|&&s| s).count()
    }

    /// Contacts whose friction the last step held on its cone's boundary, saturated and
    /// nearly still (the κ = 0 polish of `solver::saturation`).
    pub fn saturated_contacts(&self) -> usize {
        self.saturated
            .iter()
            .filter(|s| matches!(s, Some(crate::solver::saturation::Hold::Sliding(_))))
            .count()
    }

    /// Per candidate, whether it took part in the last step (see [`Self::active_contacts`]).
    pub fn contact_active(&self) -> &[bool] {
        &self.active[..self.saturated.len()]
    }

    /// Record every interior-point iteration of the following steps (allocates; for studies
    /// and debugging). `condition` also estimates the Newton matrix's condition number per
    /// iteration from a dense copy (small models only).
    pub fn set_trace(&mut self, on: bool, condition: bool) {
        self.trace = on.then(Vec::new);
        self.trace_condition = on && condition;
    }

    /// The iterations of the last step (empty unless [`Self::set_trace`] is on).
    pub fn trace(&self) -> &[IterationRecord] {
        self.trace.as_deref().unwrap_or(&[])
    }

    /// Scratch sized for `model`.
    pub fn new(model: &Model) -> Workspace {
        let t = &model.topology;
        let n = t.pattern.total_dim();
        let nb = model.nbody();
        let mut free_adr = Vec::with_capacity(model.njoint());
        let mut nfree = 0;
        for j in &model.joints {
            free_adr.push(nfree);
            nfree += j.nfree() * 12;
        }
        let mut limit_adr = Vec::with_capacity(model.njoint());
        let mut nlim = 0;
        for j in &model.joints {
            limit_adr.push(nlim);
            nlim += j.limits.len();
        }
        Workspace {
            contact_phi_now: vec![0.0; model.ncontact()],
            contact_rate_now: vec![0.0; model.ncontact()],
            prepared: vec![false; model.ncontact()],
            geom_bounds: vec![Default::default(); model.geoms.len()],
            geom_poses: vec![Default::default(); model.geoms.len()],
            contact_step: vec![Default::default(); model.ncontact()],
            frozen: vec![None; model.ncontact()],
            contact_phi: vec![0.0; model.ncontact()],
            contact_dphi: vec![[0.0; 12]; model.ncontact()],
            limit_adr,
            limit_dtheta: vec![[0.0; 12]; nlim],
            delta_aff: vec![0.0; n],
            jacobian_rhs: Vec::new(),
            active: vec![true; model.ncontact() + model.njoint() + model.tendon_limits.len()],
            limit_slack_now: vec![[1.0; 2]; nlim + model.tendon_limits.len()],
            limit_rate_now: vec![0.0; nlim + model.tendon_limits.len()],
            saturated: vec![None; model.ncontact()],
            saturated_acceptable: vec![None; model.ncontact()],
            w_solved: vec![0.0; n],
            active_solved: vec![
                false;
                model.ncontact() + model.njoint() + model.tendon_limits.len()
            ],
            blocking: vec![false; model.ncontact() + model.joints.len()],
            shadowed: vec![false; model.ncontact()],
            matrix: BlockMatrix::new(&t.pattern),
            w: vec![0.0; n],
            w_trial: vec![0.0; n],
            w_acceptable: vec![0.0; n],
            residual: vec![0.0; n],
            kept: Box::new(crate::solver::newton::Kept::new(n)),
            delta: vec![0.0; n],
            applied: vec![[0.0; 6]; nb],
            start: State::reference(model),
            dphi: vec![Matrix3::zeros(); nb],
            next_pose: vec![Pose::world(); nb],
            jac_now: vec![0.0; 12 * t.ncon],
            jac_next: vec![0.0; 12 * t.ncon],
            free_jac: vec![0.0; nfree],
            free_adr,
            joint_tau: vec![[0.0; 6]; model.njoint()],
            joint_q: vec![[0.0; 7]; model.njoint()],
            joint_filter: Vec::new(),
            body_filter: Vec::new(),
            act_force: vec![0.0; model.nu()],
            servo_damping: vec![0.0; nfree / 12],
            tendon_damping: vec![0.0; model.nu()],
            tendon_spring: vec![0.0; model.passive_tendons.len()],
            coupling_slope: vec![0.0; model.couplings.len()],
            topology_id: model.topology_id(),
            nt: vec![None; model.ncontact()],
            nt_on: false,
            nt_disabled: false,
            trace: None,
            trace_condition: false,
            attempt: 0,
            stalled_near: false,
            proximal: 0.0,
            slack_floor: 0.0,
            kappa_taper: false,
            far: Default::default(),
            every_candidate: false,
            gentle_widening: false,
            resumed: false,
            widened: false,
            substep: false,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A pooled workspace keeps buffers that every step writes before reading them
    /// (`Workspace::poison_written_before_read`): whatever step it solved last, its next step
    /// is bit for bit the one a new workspace takes. A box sliding and spinning on the floor
    /// (sliding cones, a widened warm start) and one at rest take turns on one pooled
    /// workspace.
    #[test]
    fn a_pooled_workspace_steps_as_a_new_one_whatever_it_solved_last() {
        let model = crate::gradients::test_scenes::box_on_floor(0.01, 0.5);
        let stepped = |state: &State, ws: &mut Workspace| {
            let mut next = state.clone();
            crate::step(&model, &mut next, ws, &[]).unwrap();
            next
        };
        let mut spinning = State::reference(&model);
        let (v, w) = (Vector3::new(1.0, 0.0, 0.0), Vector3::new(0.0, 0.0, 3.0));
        spinning.set_velocity(1, &v, &w);
        let spinning = stepped(&spinning, &mut Workspace::new(&model));
        let rest = stepped(&State::reference(&model), &mut Workspace::new(&model));
        for state in [&spinning, &rest, &spinning, &rest] {
            let fresh = stepped(state, &mut Workspace::new(&model));
            let pooled = stepped(state, &mut Recycled::new(Workspace::pooled(&model)));
            assert_eq!(pooled, fresh);
        }
    }

    /// A snapshot restores the state bit for bit, warm start and sub-step interval included,
    /// so the step from it is the original's; a snapshot of the wrong length or with a bad
    /// interval is refused by name.
    #[test]
    fn a_snapshot_restores_the_state_and_its_next_step_bit_for_bit() {
        let model = crate::gradients::test_scenes::box_on_floor(0.01, 0.5);
        let mut state = State::reference(&model);
        let (v, w) = (Vector3::new(1.0, 0.0, 0.0), Vector3::new(0.0, 0.0, 3.0));
        state.set_velocity(1, &v, &w);
        let mut ws = Workspace::new(&model);
        for _ in 0..3 {
            crate::step(&model, &mut state, &mut ws, &[]).unwrap();
        }
        state.interval = Some(0.25);
        let restored = State::from_snapshot(&model, &state.snapshot()).unwrap();
        assert_eq!(restored, state);
        let (mut a, mut b) = (state.clone(), restored);
        crate::step(&model, &mut a, &mut Workspace::new(&model), &[]).unwrap();
        crate::step(&model, &mut b, &mut Workspace::new(&model), &[]).unwrap();
        let bits = |s: &State| s.snapshot().iter().map(|x| x.to_bits()).collect::<Vec<_>>();
        assert_eq!(bits(&a), bits(&b));
        let mut short = state.snapshot();
        short.pop();
        let err = State::from_snapshot(&model, &short)
            .unwrap_err()
            .to_string();
        assert!(err.contains("snapshot"), "{err}");
        let mut bad = state.snapshot();
        bad[1] = -2.0;
        let err = State::from_snapshot(&model, &bad).unwrap_err().to_string();
        assert!(err.contains("interval") && err.contains("-2"), "{err}");
        // a position that is not finite, and an orientation that is not a unit quaternion
        let mut bad = state.snapshot();
        bad[2 + 3] = f64::NAN;
        let err = State::from_snapshot(&model, &bad).unwrap_err().to_string();
        assert!(err.contains("snapshot[5]") && err.contains("NaN"), "{err}");
        let mut bad = state.snapshot();
        bad[2 + state.com_pos.len() + 4] *= 2.0;
        let err = State::from_snapshot(&model, &bad).unwrap_err().to_string();
        assert!(err.contains("orientation of body 1"), "{err}");
    }
}
