//! Partial derivatives of the residual and the output map at the gradient point `w`:
//! `∂R/∂z`, `∂Y/∂z` and `∂Y/∂w`, by central differences of the engine's own functions
//! (step 1e-6 in state units; relative error ~1e-9).
//!
//! **Coloured** (default): columns of `∂R/∂z` with disjoint row supports ([`super::sparsity`])
//! are perturbed together in one residual evaluation (the groups: [`super::plan`]), and each
//! evaluation refreshes only the contact candidates the perturbation moves; the rest of the
//! residual is recomputed from the same inputs, so it cancels in the difference. Inputs that
//! move no pose (masses, …) evaluate no contact geometry at all. The light columns (current
//! velocities, controls) are taken in closed form ([`super::light`]). `∂Y/∂z` is taken per
//! column from the output map alone (no residual), `∂Y/∂w` per body velocity.
//! **Column by column**: one full residual evaluation per column and sign, the reference the
//! tests compare the coloured partials against.
use std::sync::Arc;

use nalgebra::DMatrix;

use super::light::{Light, light_column};
use super::plan::{OutputPlan, Plan, Refresh, plan_for, state_bodies, subtrees};
use super::tangent::{Coordinates, Point};
use super::{FD_STEP, next_state_into};
use crate::contact::{ContactModel, Frozen};
use crate::model::Model;
use crate::model::params::Param;
use crate::model::topology_body_node as body_node;
use crate::solver::activation::prepare_candidates_holding;
use crate::solver::activation::{coordinate_rate, limit_rates};
use crate::solver::newton;
use crate::solver::saturation::Hold;
use crate::solver::taper::{limit_weight_and_slopes, weight_and_slopes};
use crate::state::{Recycled, State, Workspace};
use crate::step::AppliedForces;

/// How [`super::Linearization`] takes the partial derivatives.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum PartialsMethod {
    /// Columns with disjoint row supports perturbed together; only moved contact candidates
    /// re-evaluated.
    #[default]
    Coloured,
    /// One full residual evaluation per column and sign (the reference).
    ColumnByColumn,
}

/// One input direction of the step.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(super) enum Input {
    State(usize),
    Ctrl(usize),
    Param(Param),
}

/// The partial derivatives and where `∂R/∂z` can be non-zero.
pub(super) struct Partials {
    /// `∂R/∂z` on each column's support: column `c` holds the rows of `rows[c]`, range after
    /// range, at `r_z[r_start[c]..r_start[c + 1]]` (a dense `nw × nz` matrix was mostly the
    /// zero rows of inactive contact candidates: 8400 × 48 on the A1).
    r_z: Vec<f64>,
    r_start: Arc<Vec<usize>>,
    /// `∂Y/∂z`, `ny × nz`.
    pub y_z: DMatrix<f64>,
    /// `∂Y/∂w` on the columns `w_cols`, `ny × w_cols.len()` (the other columns are zero).
    pub y_w: DMatrix<f64>,
    /// Row ranges `(start, len)` of `w` where each column of `r_z` can be non-zero.
    pub rows: Arc<Vec<Vec<(usize, usize)>>>,
    /// Columns of `w` that `Y` depends on (the body velocities, 6 per moving body).
    pub w_cols: Vec<usize>,
    /// Residual evaluations spent.
    pub evaluations: usize,
}

impl Partials {
    /// Size `r_z` for the column starts `r_start`, zero.
    fn allocate_r_z(&mut self) {
        let n = self.r_start.last().copied().unwrap_or(0);
        self.r_z.clear();
        self.r_z.resize(n, 0.0);
    }

    /// Column `c` of `∂R/∂z` on its support, range after range (see `r_z`).
    fn col(&self, c: usize) -> &[f64] {
        &self.r_z[self.r_start[c]..self.r_start[c + 1]]
    }

    /// `∂R/∂z[:, c] · v` over the column's support.
    pub fn col_dot(&self, c: usize, v: &[f64]) -> f64 {
        let mut col = self.col(c);
        let mut sum = 0.0;
        for &(s, l) in &self.rows[c] {
            let (head, rest) = col.split_at(l);
            sum += head
                .iter()
                .zip(&v[s..s + l])
                .map(|(a, b)| a * b)
                .sum::<f64>();
            col = rest;
        }
        sum
    }

    /// [`Self::col_dot`] against each of `k` vectors at once: `out[i] = ∂R/∂z[:, c] · v_i`,
    /// where row `r` of `xs` holds `v_0[r], …, v_{k-1}[r]` (see
    /// `BlockMatrix::solve_transpose_many`); the sums are formed in `col_dot`'s order.
    pub fn col_dot_many(&self, c: usize, xs: &[f64], k: usize, part: &mut [f64], out: &mut [f64]) {
        let mut col = self.col(c);
        out[..k].fill(0.0);
        for &(s, l) in &self.rows[c] {
            let (head, rest) = col.split_at(l);
            part[..k].fill(-0.0);
            for (a, x) in head.iter().zip(xs[s * k..(s + l) * k].chunks_exact(k)) {
                part.iter_mut().zip(x).for_each(|(p, x)| *p += a * x);
            }
            out.iter_mut().zip(&part[..k]).for_each(|(o, p)| *o += p);
            col = rest;
        }
    }

    /// `dst += scale · ∂R/∂z[:, c]` (only the column's support is touched).
    pub fn col_add_to(&self, c: usize, scale: f64, dst: &mut [f64]) {
        let mut col = self.col(c);
        for &(s, l) in &self.rows[c] {
            let (head, rest) = col.split_at(l);
            for (d, r) in dst[s..s + l].iter_mut().zip(head) {
                *d += scale * r;
            }
            col = rest;
        }
    }
}

/// `jac_now`, `free_jac`, `joint_tau` and `joint_q` of a workspace.
struct BaseJoints {
    jac_now: Vec<f64>,
    free_jac: Vec<f64>,
    joint_tau: Vec<[f64; 6]>,
    joint_q: Vec<[f64; 7]>,
}

impl BaseJoints {
    fn of(ws: &Workspace) -> BaseJoints {
        BaseJoints {
            jac_now: ws.jac_now.clone(),
            free_jac: ws.free_jac.clone(),
            joint_tau: ws.joint_tau.clone(),
            joint_q: ws.joint_q.clone(),
        }
    }

    fn restore(&self, ws: &mut Workspace) {
        ws.jac_now.copy_from_slice(&self.jac_now);
        ws.free_jac.copy_from_slice(&self.free_jac);
        ws.joint_tau.copy_from_slice(&self.joint_tau);
        ws.joint_q.copy_from_slice(&self.joint_q);
    }
}

/// The contact activation of the gradient point and the feature each active candidate held.
pub(super) type Held<'h> = (&'h [bool], &'h [(usize, Option<Frozen>)]);

/// Scratch for evaluating the residual and output map at perturbed inputs.
struct Probe<'a> {
    base: &'a Model,
    point: &'a Point,
    ctrl0: &'a [f64],
    /// The model with perturbed parameters, copied from `base` at the first parameter
    /// perturbation (a copy is ~4e5 instructions on the A1, 5% of its partials).
    perturbed: Option<Model>,
    state: State,
    next: State,
    ctrl: Vec<f64>,
    ws: Recycled,
    residual: Vec<f64>,
    scratch: Vec<f64>,
    dir: Vec<f64>,
    /// The joint terms at the unperturbed inputs: a restricted residual recomputes only the
    /// joints its perturbation touches (`Workspace::joint_filter`).
    base_joints: BaseJoints,
    /// The feature each active contact candidate held at the gradient point: perturbed states
    /// keep it (the residual map is the solve's, with its features).
    frozen: Vec<Option<Frozen>>,
    /// κ of the residual: the smoothed step's with κ weighted by each candidate's gap at the
    /// step's start (`solver::taper`), whose change with the inputs is then in the
    /// differences; 0 otherwise (a constant κ cancels in them).
    kappa: f64,
}

impl<'a> Probe<'a> {
    fn new(
        model: &'a Model,
        point: &'a Point,
        ctrl: &'a [f64],
        held: Held,
        tapered: Option<f64>,
    ) -> Probe<'a> {
        let (active, held_frozen) = held;
        let mut ws = Recycled::new(Workspace::pooled_scratch(model));
        ws.kappa_taper = tapered.is_some();
        // the residual map is linearised with the solve's contact activation frozen
        ws.active.copy_from_slice(active);
        let mut frozen = vec![None; model.contacts.len()];
        for &(c, f) in held_frozen {
            frozen[c] = f;
        }
        newton::prepare_smooth_forces(
            model,
            &point.state,
            &mut ws,
            ctrl,
            &AppliedForces::default(),
        );
        if tapered.is_some() {
            record_limit_starts(model, &point.state, &mut ws, None);
        }
        let base_joints = BaseJoints::of(&ws);
        Probe {
            frozen,
            kappa: tapered.unwrap_or(0.0),
            base_joints,
            base: model,
            point,
            ctrl0: ctrl,
            perturbed: None,
            state: point.state.clone(),
            next: point.state.clone(),
            ctrl: ctrl.to_vec(),
            ws,
            residual: vec![0.0; model.topology.pattern.total_dim()],
            scratch: vec![0.0; Point::scratch_len(model)],
            dir: vec![0.0; point.coords.dim(model)],
        }
    }

    /// Perturb the inputs `cols` by `sign · eps[c]` (state directions together).
    fn perturb(&mut self, inputs: &[Input], eps: &[f64], cols: &[usize], sign: f64) {
        self.dir.fill(0.0);
        let mut state = false;
        for &c in cols {
            match inputs[c] {
                Input::State(i) => {
                    self.dir[i] = 1.0;
                    state = true;
                }
                Input::Ctrl(i) => self.ctrl[i] = self.ctrl0[i] + sign * eps[c],
                Input::Param(p) => {
                    let model = self.perturbed.get_or_insert_with(|| self.base.clone());
                    model.set_param(p, self.base.param(p) + sign * eps[c]);
                }
            }
        }
        if state {
            let (model, dir) = (self.base, &self.dir);
            self.point.perturbed(
                model,
                dir,
                sign * FD_STEP,
                &mut self.state,
                &mut self.scratch,
            );
        }
    }

    fn restore(&mut self, inputs: &[Input], cols: &[usize]) {
        for &c in cols {
            match inputs[c] {
                // a perturbation moves poses and velocities only
                Input::State(_) => self.state.copy_motion_from(&self.point.state),
                Input::Ctrl(i) => self.ctrl[i] = self.ctrl0[i],
                Input::Param(p) => {
                    if let Some(model) = self.perturbed.as_mut() {
                        model.set_param(p, self.base.param(p));
                    }
                }
            }
        }
    }

    /// Full residual at `w` with the probe's inputs.
    fn residual_full(&mut self, w: &[f64]) {
        self.ws.joint_filter.clear();
        self.ws.body_filter.clear();
        let forces = AppliedForces::default();
        let model = self.perturbed.as_ref().unwrap_or(self.base);
        newton::prepare_forces(model, &self.state, &mut self.ws, &self.ctrl, &forces);
        let active = std::mem::take(&mut self.ws.active);
        let candidates = crate::solver::inequality::active_candidates(&active[..model.ncontact()])
            .map(|c| (c, self.frozen[c]));
        prepare_candidates_holding(model, &self.state, &mut self.ws, candidates);
        self.ws.active = active;
        let kappa = self.kappa;
        if kappa != 0.0 {
            record_limit_starts(model, &self.state, &mut self.ws, None);
        }
        newton::evaluate_in(
            model,
            &self.state,
            &mut self.ws,
            w,
            &mut self.residual,
            kappa,
        );
    }

    /// Residual at `w` with only the contact candidates `contacts` (of those `active`)
    /// evaluated; the others are left out of both rows and impulses (they do not change).
    /// Likewise only the `joints` set are re-evaluated; the others keep their terms at the
    /// unperturbed inputs, and their own rows are not written. Only the rows of the `bodies`
    /// set are written of the body rows.
    fn residual_restricted(&mut self, w: &[f64], active: &[bool], refresh: &Refresh) {
        let (contacts, joints) = (&refresh.contacts, &refresh.joints);
        self.base_joints.restore(&mut self.ws);
        self.ws.joint_filter.clear();
        self.ws.joint_filter.extend_from_slice(joints);
        self.ws.body_filter.clear();
        self.ws.body_filter.extend_from_slice(&refresh.bodies);
        let (model, state) = (self.perturbed.as_ref().unwrap_or(self.base), &self.state);
        let forces = AppliedForces::default();
        newton::prepare_smooth_forces(model, state, &mut self.ws, &self.ctrl, &forces);
        let nc = model.ncontact();
        self.ws.active[..nc].fill(false);
        self.ws.active[nc..].copy_from_slice(&active[nc..]);
        // the contact frames (and frozen disk rim points) of `activation::prepare`, for the
        // candidates that move
        let moved = contacts.iter().filter(|&&c| active[c]);
        for &c in moved.clone() {
            self.ws.active[c] = true;
        }
        let candidates = moved.map(|&c| (c, self.frozen[c]));
        prepare_candidates_holding(model, state, &mut self.ws, candidates);
        if self.kappa != 0.0 {
            record_limit_starts(model, state, &mut self.ws, Some(joints));
        }
        newton::evaluate_in(
            model,
            state,
            &mut self.ws,
            w,
            &mut self.residual,
            self.kappa,
        );
    }

    /// Output tangent (relative to `out_base`) of the next state from `w` with the probe's inputs.
    /// With `joints`, only the rows of those joints (minimal coordinates) are written.
    fn output(&mut self, w: &[f64], out_base: &Point, joints: Option<&[bool]>, y: &mut [f64]) {
        let model = self.perturbed.as_ref().unwrap_or(self.base);
        next_state_into(model, &self.state, w, &mut self.next);
        match joints {
            Some(js) => out_base.difference_joints(model, &self.next, js, y, &mut self.scratch),
            None => out_base.difference(model, &self.next, y, &mut self.scratch),
        }
    }
}

/// Central-difference step of each input.
fn steps(model: &Model, inputs: &[Input]) -> Vec<f64> {
    inputs
        .iter()
        .map(|i| match i {
            Input::Param(p) => 1e-6 * model.param(*p).abs().max(1.0),
            _ => FD_STEP,
        })
        .collect()
}

/// With κ tapered (`solver::taper`): the slacks and rates at `state` of the limited joints
/// (those set in `joints`, every one with `None`) and of every tendon limit, which the limits'
/// κ weights read.
fn record_limit_starts(model: &Model, state: &State, ws: &mut Workspace, joints: Option<&[bool]>) {
    use crate::solver::activation::{record_limit_start, record_tendon_start};
    for (j, joint) in model.joints.iter().enumerate() {
        if joints.is_none_or(|on| on[j]) {
            record_limit_start(state, ws, j, joint);
        }
    }
    for k in 0..model.tendon_limits.len() {
        record_tendon_start(model, state, ws, k);
    }
}

/// Compute the partials at `w` (the gradient point of `point` with controls `ctrl`; contact
/// activation `active`); the output tangent is taken relative to the next state at `w`.
/// `taper`: the smoothed step's κ weights, when each candidate's gap weighs its κ
/// (`solver::taper`).
#[allow(clippy::too_many_arguments)]
pub(super) fn partials(
    model: &Model,
    point: &Point,
    ctrl: &[f64],
    w: &[f64],
    held: Held,
    inputs: &[Input],
    method: PartialsMethod,
    taper: Option<Taper>,
) -> crate::Result<Partials> {
    let (nw, ny, nz) = (w.len(), point.coords.dim(model), inputs.len());
    let eps = steps(model, inputs);
    let mut probe = Probe::new(model, point, ctrl, held, taper.as_ref().map(|t| t.kappa));
    if let Some(t) = &taper {
        // a held cone's first row is an equality, with no κ to weigh (as in the solve)
        probe.ws.saturated.copy_from_slice(t.saturated);
    }
    let nwc = 6 * (model.nbody() - 1);
    let plan = match method {
        PartialsMethod::Coloured => plan_for(model, point.coords, held.0, inputs, taper.is_some()),
        PartialsMethod::ColumnByColumn => {
            Arc::new(Plan::column_by_column(model, point.coords, inputs, nw))
        }
    };
    let mut out = Partials {
        r_z: Vec::new(),
        r_start: plan.r_start.clone(),
        y_z: DMatrix::zeros(ny, nz),
        y_w: DMatrix::zeros(ny, nwc),
        rows: plan.rows.clone(),
        w_cols: (1..model.nbody())
            .flat_map(|b| {
                let o = body_node(b).map_or(0, |n| model.topology.pattern.offset(n));
                o..o + 6
            })
            .collect(),
        evaluations: 0,
    };
    out.allocate_r_z();
    // base of the output tangent: the next state at the gradient point
    let mut base_next = point.state.clone();
    next_state_into(model, &point.state, w, &mut base_next);
    // (maximal coordinates leave the state as it is: the next state itself)
    let mut out_base = Point::from_state(model, base_next, Coordinates::Maximal)?;
    out_base.coords = point.coords;
    let refresh = plan.refresh.as_deref();
    residual_columns(&mut probe, &mut out, inputs, &eps, w, &plan.groups, refresh);
    light_columns(&mut probe, &mut out, inputs, &eps, &plan, taper.as_ref());
    plane_columns(model, &mut out, &plan.plane_columns, taper.as_ref());
    output_partials(
        &mut probe,
        &mut out,
        inputs,
        &eps,
        w,
        &out_base,
        &plan.output,
    );
    Ok(out)
}

/// `∂R/∂z` by central differences, one residual evaluation per group and sign; with
/// `refresh`, each group evaluates only its contact candidates and joints and scatters by the
/// supports.
fn residual_columns(
    probe: &mut Probe,
    out: &mut Partials,
    inputs: &[Input],
    eps: &[f64],
    w: &[f64],
    groups: &[Vec<usize>],
    refresh: Option<&[Refresh]>,
) {
    let active = probe.ws.active.clone();
    let mut plus = vec![0.0; w.len()];
    for (k, group) in groups.iter().enumerate() {
        for sign in [1.0, -1.0] {
            probe.perturb(inputs, eps, group, sign);
            match refresh {
                Some(r) => probe.residual_restricted(w, &active, &r[k]),
                None => probe.residual_full(w),
            }
            out.evaluations += 1;
            probe.restore(inputs, group);
            if sign > 0.0 {
                for &(s, l) in group.iter().flat_map(|&c| &out.rows[c]) {
                    plus[s..s + l].copy_from_slice(&probe.residual[s..s + l]);
                }
            }
        }
        for &c in group {
            let inv = 1.0 / (2.0 * eps[c]);
            let mut k = out.r_start[c];
            for &(s, l) in &out.rows[c] {
                let (p, m) = (&plus[s..s + l], &probe.residual[s..s + l]);
                for (p, m) in p.iter().zip(m) {
                    out.r_z[k] = (p - m) * inv;
                    k += 1;
                }
            }
        }
    }
    probe.ws.active.copy_from_slice(&active);
}

/// `∂R/∂z` of the light columns (current velocities, controls) in closed form
/// ([`super::light`]); the twists a group of velocity columns moves come from one forward
/// kinematics pass (the twists are linear in the velocity coordinates at fixed poses, so the
/// one-sided difference is exact to round-off; the columns of a group touch disjoint bodies).
fn light_columns(
    probe: &mut Probe,
    out: &mut Partials,
    inputs: &[Input],
    eps: &[f64],
    plan: &Plan,
    taper: Option<&Taper>,
) {
    let groups = &plan.light_groups;
    let (model, point) = (probe.base, probe.point);
    // the free Jacobians and coordinates of the gradient point (a residual evaluation leaves
    // those of its perturbed joints)
    probe.base_joints.restore(&mut probe.ws);
    let below = subtrees(model);
    let nb = model.nbody();
    let (mut dt, mut dr) = (vec![[0.0; 6]; nb], vec![[0.0; 6]; nb]);
    // the first row of each body's node, sorted, for scattering body rows onto the supports
    let p = &model.topology.pattern;
    let mut starts: Vec<(usize, usize)> = (1..nb)
        .filter_map(|b| Some((p.offset(body_node(b)?), b)))
        .collect();
    starts.sort_unstable();
    let body_row = |dr: &[[f64; 6]], r: usize| -> f64 {
        let i = starts.partition_point(|&(o, _)| o <= r);
        match i.checked_sub(1).map(|i| starts[i]) {
            Some((o, b)) if r < o + 6 => dr[b][r - o],
            _ => 0.0,
        }
    };
    for group in groups {
        let states: Vec<usize> = group
            .iter()
            .copied()
            .filter(|&c| matches!(inputs[c], Input::State(_)))
            .collect();
        if !states.is_empty() {
            probe.perturb(inputs, eps, &states, 1.0);
        }
        for &c in group {
            dr.fill([0.0; 6]);
            let mut touched = Vec::new();
            let input = match inputs[c] {
                Input::State(i) => {
                    dt.fill([0.0; 6]);
                    touched = state_bodies(model, point.coords, &below, i).0;
                    for &b in &touched {
                        let ((v1, w1), (v0, w0)) =
                            (probe.state.velocity(b), point.state.velocity(b));
                        let d = [v1 - v0, w1 - w0];
                        for k in 0..6 {
                            dt[b][k] = d[k / 3][k % 3] / FD_STEP;
                        }
                    }
                    Light::Twists(&dt)
                }
                Input::Ctrl(a) => Light::Ctrl(a),
                Input::Param(_) => unreachable!("parameter columns are never light"),
            };
            light_column(
                model,
                &point.state,
                &probe.ws,
                probe.ctrl0,
                input,
                eps[c],
                &mut dr,
            );
            // scatter the body rows onto the column's support; the candidates' rows follow
            let mut k = out.r_start[c];
            for &(s, l) in &out.rows[c][..plan.light_body_ranges[c]] {
                for r in s..s + l {
                    out.r_z[k] = body_row(&dr, r);
                    k += 1;
                }
            }
            if let (Some(t), Light::Twists(dt)) = (taper, input) {
                let moved = (&probe.state, &touched[..], dt);
                k += weight_rows(model, plan, c, t, point, moved, &mut out.r_z[k..]);
            }
            debug_assert_eq!(k, out.r_start[c + 1]);
        }
        if !states.is_empty() {
            probe.restore(inputs, &states);
        }
    }
}

/// The κ weights' rows of the twist column `c` (`plan`'s `light_pairs`, `light_limits`,
/// `light_tendons`, in that order) into `out`: `-κ ∂w/∂(rate) · ∂(rate)/∂z` of each contact
/// candidate, limit side and tendon limit side on the bodies it moves. `moved`: the perturbed
/// state, the bodies whose twists the column changes and their twists per unit (`dt`). A rate
/// is linear in the twists, so its change along the column is the perturbed state's: the
/// group's other columns move none of these bodies (their supports would share the rows).
/// Returns how many entries it wrote.
fn weight_rows(
    model: &Model,
    plan: &Plan,
    c: usize,
    t: &Taper,
    point: &Point,
    (state, touched, dt): (&State, &[usize], &[[f64; 6]]),
    out: &mut [f64],
) -> usize {
    let mut k = 0;
    for &j in &plan.light_pairs[c] {
        let drate = t.rate_rows[j].map_or(0.0, |row| {
            let contact = &model.contacts[j];
            let [a, b] = [contact.geom_a, contact.geom_b].map(|g| model.geoms[g].body);
            let twist = |b: usize| if b == 0 { [0.0; 6] } else { dt[b] };
            let (ta, tb) = (twist(a), twist(b));
            (0..6).map(|i| row[i] * ta[i] + row[6 + i] * tb[i]).sum()
        });
        let shift = t.shift(model, j, 0.0, drate);
        k += t.write_pairs(model, j, shift, &mut out[k..]);
    }
    for &j in &plan.light_limits[c] {
        let joint = &model.joints[j];
        let mut rates = [0.0; 6];
        let n = joint.limits.len();
        limit_rates(state, joint, &mut rates[..n]);
        // (against the rates the step recorded at the gradient point, `t.limit_rate`)
        for (i, rate) in rates[..n].iter().enumerate() {
            let a = t.limit_adr[j] + i;
            let drate = (rate - t.limit_rate[a]) / FD_STEP;
            k += t.write_limit_sides(model, a, drate, &mut out[k..]);
        }
    }
    // a tendon's rate `Σ coef q̇`, over its terms on the joints the column moves
    let nl = t.limit_slack.len() - model.tendon_limits.len();
    for &n in &plan.light_tendons[c] {
        let mut drate = 0.0;
        for &(j, dof, coef) in &model.tendon_limits[n].terms {
            let joint = &model.joints[j];
            if touched.contains(&joint.parent) || touched.contains(&joint.child) {
                let rate = |s: &State| coordinate_rate(s, joint, dof);
                drate += coef * (rate(state) - rate(&point.state)) / FD_STEP;
            }
        }
        k += t.write_limit_sides(model, nl + n, drate, &mut out[k..]);
    }
    k
}

/// The smoothed step's κ weights at the gradient point (`solver::taper`).
pub(super) struct Taper<'t> {
    pub kappa: f64,
    /// Each candidate's gap and its rate at the step's start.
    pub phi_now: &'t [f64],
    pub rate_now: &'t [f64],
    /// The friction cones held saturated (their first row is an equality).
    pub saturated: &'t [Option<Hold>],
    /// Each active candidate's gap rate as a row in the twists `(v, ω_body)` of its bodies a
    /// (0..6) and b (6..12): `ContactFrame`'s normal row at the step's start.
    pub rate_rows: Vec<Option<[f64; 12]>>,
    /// Each limited coordinate's slacks and rate at the step's start, from `limit_adr[j]`.
    pub limit_slack: &'t [[f64; 2]],
    pub limit_rate: &'t [f64],
    pub limit_adr: &'t [usize],
}

impl Taper<'_> {
    /// `-κ ∂w/∂z` of candidate `k` for a change `dphi` of its gap and `drate` of its rate.
    fn shift(&self, model: &Model, k: usize, dphi: f64, drate: f64) -> f64 {
        let [_, by_gap, by_rate] = weight_and_slopes(model, k, self.phi_now[k], self.rate_now[k]);
        -self.kappa * (by_gap * dphi + by_rate * drate)
    }

    /// Write `-κ ∂w/∂q̇ · drate` of both sides of limit `a` (its index in `limit_slack`) to
    /// `out[0..2]`; returns 2.
    fn write_limit_sides(&self, model: &Model, a: usize, drate: f64, out: &mut [f64]) -> usize {
        for (o, slack) in out.iter_mut().zip(self.limit_slack[a]) {
            let [_, _, by_rate] = limit_weight_and_slopes(model, slack, self.limit_rate[a]);
            *o = -self.kappa * by_rate * drate;
        }
        2
    }

    /// Write `shift` on candidate `k`'s complementarity rows (`plan::pair_rows`) from `out[0]`;
    /// returns how many rows.
    fn write_pairs(&self, model: &Model, k: usize, shift: f64, out: &mut [f64]) -> usize {
        let rows: &[f64] = match model.contacts[k].model {
            ContactModel::Impact => &[shift],
            ContactModel::Nonlinear if self.saturated[k].is_some() => &[shift, 0.0],
            ContactModel::Nonlinear => &[shift, shift],
            ContactModel::Linear => &[shift; 6],
        };
        out[..rows.len()].copy_from_slice(rows);
        rows.len()
    }
}

/// `∂R/∂z` of the translation columns whose tree meets the rest only at world planes: the
/// plan's gap entries (`plan::plane_entries`) and, with `taper`, the complementarity rows'
/// `-κ ∂w/∂z`, the gap at the start moving as the gap row does (`∂φ/∂z = -(gap entry)`; a
/// translation leaves the rate to a plane as it is).
fn plane_columns(
    model: &Model,
    out: &mut Partials,
    columns: &[(usize, Vec<(usize, f64)>)],
    taper: Option<&Taper>,
) {
    for (c, entries) in columns {
        let mut k = out.r_start[*c];
        for &(contact, gap) in entries {
            out.r_z[k] = gap;
            k += 1;
            if let Some(t) = taper {
                let shift = t.shift(model, contact, -gap, 0.0);
                k += t.write_pairs(model, contact, shift, &mut out.r_z[k..]);
            }
        }
        debug_assert_eq!(k, out.r_start[*c + 1]);
    }
}

/// `∂Y/∂z` (the output map alone: only state columns and the time step enter it) and `∂Y/∂w`
/// per body velocity component, by the groups of `plan`.
fn output_partials(
    probe: &mut Probe,
    out: &mut Partials,
    inputs: &[Input],
    eps: &[f64],
    w: &[f64],
    out_base: &Point,
    plan: &OutputPlan,
) {
    let model = probe.base;
    let ny = out.y_z.nrows();
    let (mut yp, mut ym) = (vec![0.0; ny], vec![0.0; ny]);
    for &c in &plan.unit_cols {
        for &i in &plan.col_rows[c] {
            out.y_z[(i, c)] = 1.0;
        }
    }
    for (group, js) in &plan.z_groups {
        for (sign, y) in [(1.0, &mut yp), (-1.0, &mut ym)] {
            probe.perturb(inputs, eps, group, sign);
            probe.output(w, out_base, js.as_deref(), y);
            probe.restore(inputs, group);
        }
        for &c in group {
            for &i in &plan.col_rows[c] {
                out.y_z[(i, c)] = (yp[i] - ym[i]) / (2.0 * eps[c]);
            }
        }
    }
    let slot = |b: usize| body_node(b + 1).map_or(0, |n| model.topology.pattern.offset(n));
    let mut wp = w.to_vec();
    for (group, restricted) in &plan.w_groups {
        for comp in 0..6 {
            let (js, only) = match restricted {
                Some((_, t)) if comp < 3 => (Some(t), true),
                Some((js, _)) => (Some(js), false),
                None => (None, false),
            };
            if only && !js.is_some_and(|t| t.contains(&true)) {
                continue;
            }
            for (sign, y) in [(1.0, &mut yp), (-1.0, &mut ym)] {
                for &b in group {
                    wp[slot(b) + comp] = w[slot(b) + comp] + sign * FD_STEP;
                }
                probe.output(&wp, out_base, js.map(Vec::as_slice), y);
            }
            for &b in group {
                let k = slot(b) + comp;
                wp[k] = w[k];
                // `w_cols` lists the moving bodies' six velocity rows in body order
                for &i in &plan.body_rows[b] {
                    if only && !js.is_some_and(|t| t[plan.dof_joint[i % model.nv.max(1)]]) {
                        continue;
                    }
                    out.y_w[(i, 6 * b + comp)] = (yp[i] - ym[i]) / (2.0 * FD_STEP);
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::gradients::plan::translates_rigidly;
    use crate::{BodySpec, JointKind, JointSpec, ModelBuilder, Workspace};

    /// Bodies whose pose (`moved`) or pose or velocity (`touched`) differ between two states.
    fn changed_bodies(model: &Model, a: &State, b: &State) -> (Vec<usize>, Vec<usize>) {
        let (mut touched, mut moved) = (Vec::new(), Vec::new());
        for k in 1..model.nbody() {
            let (pa, pb) = (a.pose(k), b.pose(k));
            let pose = pa.pos != pb.pos || pa.quat != pb.quat;
            if pose {
                moved.push(k);
            }
            if pose || a.velocity(k) != b.velocity(k) {
                touched.push(k);
            }
        }
        (touched, moved)
    }

    /// A free base with two branches holding every other joint kind (a welded body among them),
    /// each with a spring and a damper, moving after a few steps under gravity.
    fn every_kind() -> (Model, State) {
        use JointKind::*;
        let kinds = [
            Revolute,
            Prismatic,
            Spherical,
            Cylindrical,
            Orbital,
            Planar,
            FixedOrientation,
            Fixed,
            PlanarAxis,
            FreeRevolute,
            PrismaticOrbital,
            PlanarOrbital,
            FreeOrbital,
            CylindricalFree,
            PlanarFree,
        ];
        let mut b = ModelBuilder::new()
            .timestep(0.01)
            .body(BodySpec::new("base", 2.0, [0.1, 0.2, 0.3]).pos([0.0, 0.0, 1.0]))
            .joint(JointSpec::new("root", Floating, "world", "base"));
        // two branches: even kinds below base along x, odd ones along y, each joint at its
        // child's origin
        let pos = |i: usize| {
            let r = 0.2 * (i / 2 + 1) as f64;
            if i.is_multiple_of(2) {
                [r, 0.0, 1.0]
            } else {
                [0.0, r, 1.0]
            }
        };
        for (i, kind) in kinds.iter().enumerate() {
            let (parent, at) = match i {
                0 | 1 => ("base".to_string(), [0.0, 0.0, 1.0]),
                _ => (format!("b{}", i - 2), pos(i - 2)),
            };
            let (name, p) = (format!("b{i}"), pos(i));
            let anchor = [p[0] - at[0], p[1] - at[1], p[2] - at[2]];
            b = b
                .body(BodySpec::new(&name, 1.0, [0.01, 0.02, 0.03]).pos(p))
                .joint(
                    JointSpec::new(&format!("j{i}"), *kind, &parent, &name)
                        .axis([0.2, 1.0, 0.3])
                        .anchors(anchor, [0.0; 3])
                        .stiffness(2.0)
                        .damping(0.3),
                );
        }
        let m = b.compile().unwrap();
        let mut s = State::reference(&m);
        let mut ws = Workspace::new(&m);
        for _ in 0..3 {
            crate::step(&m, &mut s, &mut ws, &[]).unwrap();
        }
        (m, s)
    }

    /// Translating a free base moves its whole tree rigidly: with springs and dampers on every
    /// joint kind below it, each deflected and moving, and no contact, no row of the residual
    /// changes (to round-off), which lets `plan::translates_rigidly` columns leave all but the
    /// world's contacts out of their supports. Every other position direction changes rows.
    #[test]
    fn translating_a_free_tree_changes_no_residual_row() {
        let (m, mut s) = every_kind();
        // every joint deflected and moving (springs loaded, joint impulses and spins non-zero)
        let wave = |k: usize| ((k as f64 * 12.9898).sin() * 43758.5453).fract();
        let qpos: Vec<f64> = (crate::qpos(&m, &s).iter().enumerate())
            .map(|(k, q)| q + 0.2 * wave(k))
            .collect();
        let qvel: Vec<f64> = (0..m.nv).map(|k| 2.0 * wave(k + 1000)).collect();
        crate::set_minimal(&m, &mut s, &qpos, &qvel).unwrap();
        let below = subtrees(&m);
        let mut ws = Workspace::new(&m);
        crate::step(&m, &mut s.clone(), &mut ws, &[]).unwrap();
        let w = ws.w.clone();
        let point = Point::new(&m, &s, Coordinates::Minimal).unwrap();
        let active = vec![false; ws.active.len()];
        let mut probe = Probe::new(&m, &point, &[], (&active, &[]), None);
        let inputs: Vec<Input> = (0..2 * m.nv).map(Input::State).collect();
        let eps = steps(&m, &inputs);
        let mut residual = |i: usize, sign: f64| {
            probe.perturb(&inputs, &eps, &[i], sign);
            probe.residual_full(&w);
            probe.restore(&inputs, &[i]);
            probe.residual.clone()
        };
        for i in 0..m.nv {
            let (plus, minus) = (residual(i, 1.0), residual(i, -1.0));
            let change = (plus.iter().zip(&minus))
                .map(|(p, q)| (p - q).abs() / (2.0 * FD_STEP))
                .fold(0.0, f64::max);
            let translating = translates_rigidly(&m, Coordinates::Minimal, &below, i);
            assert_eq!(translating, i < 3, "direction {i}");
            if translating {
                assert!(
                    change < 1e-7,
                    "direction {i} changes the residual by {change:e}"
                );
            } else {
                assert!(change > 1e-3, "direction {i} changes nothing: {change:e}");
            }
        }
    }

    /// The bodies a state direction moves, known from the tree, are those perturbing the state
    /// and comparing finds, for every direction of every joint kind in both coordinates.
    #[test]
    fn state_bodies_are_those_a_perturbation_changes() {
        let (m, s) = every_kind();
        let below = subtrees(&m);
        for coords in [Coordinates::Minimal, Coordinates::Maximal] {
            let p = Point::new(&m, &s, coords).unwrap();
            let mut scratch = vec![0.0; Point::scratch_len(&m)];
            for i in 0..coords.dim(&m) {
                let mut dir = vec![0.0; coords.dim(&m)];
                dir[i] = 1.0;
                let mut out = p.state.clone();
                p.perturbed(&m, &dir, FD_STEP, &mut out, &mut scratch);
                let found = changed_bodies(&m, &p.state, &out);
                assert!(
                    !found.0.is_empty(),
                    "{coords:?} direction {i} moves nothing"
                );
                assert_eq!(
                    state_bodies(&m, coords, &below, i),
                    found,
                    "{coords:?} direction {i}"
                );
            }
        }
    }
}
