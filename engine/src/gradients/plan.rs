//! The structure the coloured partials follow ([`super::partials`]): each input column's row
//! support, the groups of columns perturbed together in one residual evaluation, what each
//! group's evaluations refresh, and the same for the output map. It depends only on the
//! topology, the coordinates, the inputs and the frozen contact activation, so each thread
//! keeps the last few: the activation-free [`Skeleton`] per (topology, coordinates, inputs),
//! and the whole [`Plan`] per activation too.
use std::sync::Arc;

use super::partials::Input;
use super::sparsity::{Interactions, Support, colour, neighbours, transmission_bodies};
use super::tangent::Coordinates;
use crate::contact::ContactModel;
use crate::contact::geometry::Shape;
use crate::model::params::Param;
use crate::model::topology_body_node as body_node;
use crate::model::{Model, Transmission};
use crate::solver::inequality::SOC;

/// Where each column's entries start in `Partials::r_z` for the supports `rows`, and the
/// total as the last entry.
fn column_starts(rows: &[Vec<(usize, usize)>]) -> Vec<usize> {
    let mut starts = Vec::with_capacity(rows.len() + 1);
    let mut n = 0;
    for rows in rows {
        starts.push(n);
        n += rows.iter().map(|&(_, l)| l).sum::<usize>();
    }
    starts.push(n);
    starts
}

/// The bodies below each joint: its child and every body whose forward kinematics follows it
/// (empty for a loop joint), in body order.
pub(super) fn subtrees(model: &Model) -> Vec<Vec<usize>> {
    let fk = &model.topology.fk_order;
    (0..model.njoint())
        .map(|ji| {
            let mut below = vec![false; model.nbody()];
            for &k in fk {
                let j = &model.joints[k];
                below[j.child] |= k == ji || below[j.parent];
            }
            (1..model.nbody()).filter(|&b| below[b]).collect()
        })
        .collect()
}

/// Bodies whose pose or velocity (`touched`) or pose (`moved`) a perturbation of state tangent
/// direction `i` changes: in minimal coordinates those below the dof's joint (its coordinates
/// move their poses and velocities, its rate their velocities), in maximal ones the direction's
/// own body. What perturbing the state and comparing would find, known from the tree.
pub(super) fn state_bodies(
    model: &Model,
    coords: Coordinates,
    below: &[Vec<usize>],
    i: usize,
) -> (Vec<usize>, Vec<usize>) {
    let (bodies, pose) = match coords {
        Coordinates::Minimal => {
            let nv = model.nv;
            let ji = model.joints.iter().position(|j| {
                !j.is_loop && (j.qvel_adr..j.qvel_adr + j.nfree()).contains(&(i % nv))
            });
            (ji.map_or_else(Vec::new, |ji| below[ji].clone()), i < nv)
        }
        // 12 per body: position, rotation, velocity, angular velocity
        Coordinates::Maximal => (vec![i / 12 + 1], i % 12 < 6),
    };
    let moved = if pose { bodies.clone() } else { Vec::new() };
    (bodies, moved)
}

/// The tree joint whose velocity coordinates hold `qvel` index `i`.
fn dof_joint(model: &Model, i: usize) -> Option<usize> {
    (model.joints.iter())
        .position(|j| !j.is_loop && (j.qvel_adr..j.qvel_adr + j.nfree()).contains(&i))
}

/// Whether state tangent direction `i` translates a whole subtree rigidly, and nothing else
/// of the step depends on where it is: a position dof of a free joint to the world (minimal
/// coordinates), with no spring, limit or actuator of its own and no other joint between its
/// subtree and the rest. Its body rows, joints, springs and self-contacts then read relative
/// poses only (gravity and applied forces are uniform, site wrenches and joint Jacobians
/// rotate with their bodies), so only the contacts between the subtree and the world or
/// other trees change.
pub(super) fn translates_rigidly(
    model: &Model,
    coords: Coordinates,
    below: &[Vec<usize>],
    i: usize,
) -> bool {
    if coords != Coordinates::Minimal || i >= model.nv {
        return false;
    }
    let Some(ji) = dof_joint(model, i) else {
        return false;
    };
    let j = &model.joints[ji];
    let free = j.parent == 0 && j.ncon() == 0 && i < j.qvel_adr + j.ntrans;
    if !free || j.has_spring() || !j.limits.is_empty() {
        return false;
    }
    let driven = model.actuators.iter().any(|a| match &a.transmission {
        Transmission::Joint { joint, .. } => *joint == ji,
        Transmission::Tendon(terms) => terms.iter().any(|t| t.0 == ji),
        Transmission::Site { .. } => false,
    });
    let mut inside = vec![false; model.nbody()];
    below[ji].iter().for_each(|&b| inside[b] = true);
    let bridged = (model.joints.iter().enumerate())
        .any(|(k, o)| k != ji && inside[o.parent] != inside[o.child]);
    !driven && !bridged
}

/// The active contact candidates between the bodies `moved` and the rest (the world or other
/// trees).
fn boundary_contacts(model: &Model, graph: &Interactions, moved: &[usize]) -> Vec<usize> {
    let mut inside = vec![false; model.nbody()];
    moved.iter().for_each(|&b| inside[b] = true);
    (moved.iter())
        .flat_map(|&b| graph.body_contacts[b].iter().copied())
        .filter(|&k| {
            let [a, b] = model.topology.contact_bodies[k];
            inside[a] != inside[b]
        })
        .collect()
}

/// The world plane of contact candidate `k`, if one of its geoms is a plane on the world.
pub(super) fn world_plane(model: &Model, k: usize) -> Option<usize> {
    let c = &model.contacts[k];
    [c.geom_a, c.geom_b]
        .into_iter()
        .find(|&g| model.geoms[g].body == 0 && matches!(model.geoms[g].shape, Shape::Plane))
}

/// `∂R/∂z` of a translation column on the gap rows of the candidates `contacts` between its
/// tree and the rest, when all of them are against world planes (`None` otherwise).
/// Translating the tree by `d` per unit of the coordinate moves each gap to a plane of normal
/// `n` (its z axis) by `n·d` (a gap to a plane is `nᵀ(x − o)` of a point moving with the body,
/// whatever its feature), and nothing else of the residual ([`translates_rigidly`]); a gap
/// enters its candidate's first row as `-φ` in every contact model.
fn plane_entries(model: &Model, input: Input, contacts: &[usize]) -> Option<Vec<f64>> {
    let Input::State(i) = input else { return None };
    let j = &model.joints[dof_joint(model, i)?];
    // the child's world displacement per unit of the coordinate (its parent is the world)
    let d = crate::math::quat::rotation(&j.offset) * j.trans_basis.column(i - j.qvel_adr);
    (contacts.iter())
        .map(|&k| Some(-model.geoms[world_plane(model, k)?].rot.column(2).dot(&d)))
        .collect()
}

/// The rows of candidate `k` that a translation against a world plane changes: its gap row
/// (its node's first) and, with `tapered` (κ weighted by the gap at the step's start,
/// `solver::taper`), its complementarity rows ([`pair_rows`]).
pub(super) fn plane_rows(model: &Model, k: usize, tapered: bool) -> Vec<(usize, usize)> {
    let o = model
        .topology
        .pattern
        .offset(model.topology.contact_node[k]);
    let mut rows = vec![(o, 1)];
    if tapered {
        rows.extend(pair_rows(model, k));
    }
    rows
}

/// The complementarity rows of candidate `k` whose κ shift its weight scales
/// (`solver::taper`): `(γ s)` and the friction cone's first row, or the pyramid's six orthant
/// rows (a held cone's first row is an equality: its entry is then 0).
pub(super) fn pair_rows(model: &Model, k: usize) -> Vec<(usize, usize)> {
    let o = model
        .topology
        .pattern
        .offset(model.topology.contact_node[k]);
    match model.contacts[k].model {
        ContactModel::Impact => vec![(o + 1, 1)],
        ContactModel::Nonlinear => vec![(o + 1, 1), (o + SOC.2, 1)],
        ContactModel::Linear => vec![(o + 6, 6)],
    }
}

/// The complementarity rows of joint `j`'s limits (`γ_lo s_lo`, `γ_hi s_hi` of each), whose κ
/// shifts their weights scale (`solver::taper`).
pub(super) fn limit_pair_rows(model: &Model, j: usize) -> Vec<(usize, usize)> {
    let Some(n) = model.topology.limit_node[j] else {
        return Vec::new();
    };
    let o = model.topology.pattern.offset(n);
    (0..model.joints[j].limits.len())
        .flat_map(|i| [(o + 4 * i + 1, 1), (o + 4 * i + 3, 1)])
        .collect()
}

/// Row supports of the columns that are not light at the activation `active` (a light
/// column's rows come from the skeleton; its entry here is empty).
/// `tapered`: the activation when κ is weighted per candidate (`solver::taper`), whose taper
/// distance reads gravity.
fn supports(
    model: &Model,
    graph: &Interactions,
    inputs: &[Input],
    sk: &Skeleton,
    tapered: Option<&[bool]>,
) -> Vec<Support> {
    let all: Vec<usize> = (1..model.nbody()).collect();
    let mut sup: Vec<Support> = Vec::with_capacity(inputs.len());
    for (c, input) in inputs.iter().enumerate() {
        let s = match *input {
            _ if sk.light[c] => Support::default(),
            // the dofs of one joint move the same bodies
            Input::State(_) if sk.same_as[c] < c => sup[sk.same_as[c]].clone(),
            Input::State(_) if sk.translating[c] => {
                // the subtree moves rigidly: only its contacts with the world or other trees
                let boundary = boundary_contacts(model, graph, &sk.bodies[c].1);
                Support::new(model, graph, &[], &[], &boundary, &[])
            }
            Input::State(_) => {
                let (touched, moved) = &sk.bodies[c];
                Support::new(model, graph, touched, moved, &[], moved)
            }
            Input::Ctrl(_) => unreachable!("control columns are light"),
            Input::Param(p) => match p {
                Param::Mass(b) | Param::Inertia(b, _, _) => {
                    Support::new(model, graph, &[b], &[], &[], &[])
                }
                Param::Friction(g) | Param::Size(g, _) | Param::GeomPos(g, _) => {
                    Support::new(model, graph, &[], &[], &graph.geom_contacts[g], &[])
                }
                Param::Stiffness(j, _)
                | Param::Damping(j, _)
                | Param::Armature(j, _)
                | Param::FrictionLoss(j, _) => {
                    let joint = &model.joints[j];
                    let bodies = [joint.parent, joint.child];
                    Support::new(model, graph, &bodies, &[], &[], &bodies)
                }
                Param::TendonStiffness(k) | Param::TendonDamping(k) | Param::TendonFriction(k) => {
                    // (every term's force acts on its joint's bodies)
                    let joints = model.passive_tendons[k].terms.iter().map(|t| t.0);
                    let mut bodies: Vec<usize> = joints
                        .flat_map(|j| [model.joints[j].parent, model.joints[j].child])
                        .collect();
                    bodies.sort_unstable();
                    bodies.dedup();
                    Support::new(model, graph, &bodies, &[], &[], &bodies)
                }
                Param::ActuatorGear(a) | Param::ActuatorGain(a) | Param::ActuatorBias(a, _) => {
                    let bodies = transmission_bodies(model, &model.actuators[a].transmission);
                    Support::new(model, graph, &bodies, &[], &[], &bodies)
                }
                Param::Gravity(_) => {
                    let mut s = Support::new(model, graph, &all, &[], &[], &[]);
                    if let Some(active) = tapered {
                        let t = &model.topology;
                        // (evaluated with their rows: a restricted evaluation leaves out the
                        // others' rows)
                        let weighted = (0..model.ncontact()).filter(|&k| active[k]);
                        s.contacts.extend(weighted);
                        s.contacts.sort_unstable();
                        s.contacts.dedup();
                        s.nodes
                            .extend(s.contacts.iter().map(|&k| t.contact_node[k]));
                        s.nodes.sort_unstable();
                        s.nodes.dedup();
                    }
                    s
                }
                Param::Timestep => Support::everything(model),
            },
        };
        sup.push(s);
    }
    sup
}

/// The part of a [`Plan`] the contact activation does not change: which columns are light
/// (they change current velocities or controls only, so their rows are body rows, taken in
/// closed form by [`super::light`]), their rows and groups, the bodies each state column
/// touches and moves, and the output map's plan.
struct Skeleton {
    light: Vec<bool>,
    /// Per state column, the bodies it touches and moves ([`state_bodies`]); empty otherwise.
    bodies: Vec<(Vec<usize>, Vec<usize>)>,
    /// Per column, whether it translates its bodies rigidly ([`translates_rigidly`]).
    translating: Vec<bool>,
    /// Per column, the first state column with the same bodies and translation (itself if
    /// none before).
    same_as: Vec<usize>,
    /// [`neighbours`].
    neighbours: Vec<Vec<usize>>,
    /// The light columns' row ranges (empty for the others).
    light_rows: Vec<Vec<(usize, usize)>>,
    light_groups: Vec<Vec<usize>>,
    output: Arc<OutputPlan>,
}

impl Skeleton {
    fn new(model: &Model, coords: Coordinates, inputs: &[Input]) -> Skeleton {
        let nbrs = neighbours(model);
        // the body neighbours alone (no contact candidate links bodies)
        let graph = Interactions::new(model, &nbrs, &vec![false; model.ncontact()]);
        let below = subtrees(model);
        let mut light = vec![false; inputs.len()];
        let mut bodies = vec![(Vec::new(), Vec::new()); inputs.len()];
        let mut light_sup = vec![Support::default(); inputs.len()];
        for (c, input) in inputs.iter().enumerate() {
            match *input {
                Input::State(i) => {
                    let (touched, moved) = state_bodies(model, coords, &below, i);
                    if moved.is_empty() {
                        light[c] = true;
                        light_sup[c] = Support::body_rows(&graph, &touched);
                    }
                    bodies[c] = (touched, moved);
                }
                Input::Ctrl(i) => {
                    light[c] = true;
                    let touched = transmission_bodies(model, &model.actuators[i].transmission);
                    light_sup[c] = Support::body_rows(&graph, &touched);
                }
                Input::Param(_) => {}
            }
        }
        // (their velocity columns coloured apart for the forward kinematics they share)
        let light_groups = coloured_columns(&light_sup, |c| light[c], model);
        let translating: Vec<bool> = (inputs.iter())
            .map(|input| match *input {
                Input::State(i) => translates_rigidly(model, coords, &below, i),
                _ => false,
            })
            .collect();
        // a rigid translation moves the next state's coordinates of its own joint alone: the
        // others are relative (the joint's child stands for it)
        let own: Vec<Vec<usize>> = (inputs.iter().zip(&translating))
            .map(|(input, &t)| match (*input, t) {
                (Input::State(i), true) => {
                    dof_joint(model, i).map_or_else(Vec::new, |j| vec![model.joints[j].child])
                }
                _ => Vec::new(),
            })
            .collect();
        let moved: Vec<&[usize]> = (bodies.iter().zip(&own).zip(&translating))
            .map(|(((_, m), own), &t)| if t { own.as_slice() } else { m.as_slice() })
            .collect();
        let same_as = (0..inputs.len())
            .map(|c| match inputs[c] {
                Input::State(_) => (0..c)
                    .find(|&k| {
                        matches!(inputs[k], Input::State(_))
                            && bodies[k] == bodies[c]
                            && translating[k] == translating[c]
                    })
                    .unwrap_or(c),
                _ => c,
            })
            .collect();
        Skeleton {
            neighbours: nbrs,
            same_as,
            light_rows: light_sup
                .iter()
                .map(|s| node_rows(model, &s.nodes))
                .collect(),
            light_groups,
            output: Arc::new(OutputPlan::new(
                model,
                coords,
                inputs,
                Some(&moved),
                &translating,
            )),
            light,
            bodies,
            translating,
        }
    }
}

/// Groups of the columns `c` with `pick(c)`, pairwise disjoint in their supports `sup`.
fn coloured_columns(
    sup: &[Support],
    pick: impl Fn(usize) -> bool,
    model: &Model,
) -> Vec<Vec<usize>> {
    let cols: Vec<usize> = (0..sup.len()).filter(|&c| pick(c)).collect();
    let nodes: Vec<&[usize]> = cols.iter().map(|&c| sup[c].nodes.as_slice()).collect();
    colour(&nodes, model.topology.pattern.nnodes())
        .into_iter()
        .map(|g| g.into_iter().map(|k| cols[k]).collect())
        .collect()
}

/// Row ranges of a sorted node list, adjacent ranges merged.
fn node_rows(model: &Model, nodes: &[usize]) -> Vec<(usize, usize)> {
    let p = &model.topology.pattern;
    let mut out: Vec<(usize, usize)> = Vec::new();
    let mut sorted: Vec<(usize, usize)> = nodes.iter().map(|&n| (p.offset(n), p.dim(n))).collect();
    sorted.sort_unstable();
    for (o, d) in sorted {
        match out.last_mut() {
            Some((s, l)) if *s + *l == o => *l += d,
            _ => out.push((o, d)),
        }
    }
    out
}

/// The structure the partials' evaluations follow: each column's row support, the groups of
/// columns perturbed together and what each group's evaluations refresh, and the same for the
/// output map. It depends only on the topology, the coordinates, the inputs and the frozen
/// contact activation, which consecutive steps mostly share, so each thread keeps the last
/// few ([`plan_for`]): building it was ~9% of the humanoid's partials.
pub(super) struct Plan {
    pub(super) rows: Arc<Vec<Vec<(usize, usize)>>>,
    pub(super) r_start: Arc<Vec<usize>>,
    /// Columns evaluated together by residual differences.
    pub(super) groups: Vec<Vec<usize>>,
    /// What each group's evaluations refresh (coloured); `None`: everything.
    pub(super) refresh: Option<Vec<Refresh>>,
    /// The light columns' groups (closed form, [`light_columns`]); empty column by column.
    pub(super) light_groups: Vec<Vec<usize>>,
    /// Per light column, how many of its row ranges are body rows (the first ones).
    pub(super) light_body_ranges: Vec<usize>,
    /// Per light column, the active candidates whose complementarity rows ([`pair_rows`])
    /// follow its body rows: those on the bodies whose twists it changes, when κ is weighted
    /// by the gap rates at the start (`solver::taper`); empty otherwise.
    pub(super) light_pairs: Vec<Vec<usize>>,
    /// Likewise the active limited joints on those bodies, whose rows ([`limit_pair_rows`])
    /// follow the candidates'.
    pub(super) light_limits: Vec<Vec<usize>>,
    /// Likewise the active tendon limits with a term on such a joint, whose rows follow.
    pub(super) light_tendons: Vec<Vec<usize>>,
    /// Translation columns whose tree meets the rest only at world planes, with each boundary
    /// candidate and its gap row's entry: closed form, no evaluation ([`plane_entries`]). Their
    /// rows are [`plane_rows`]'s.
    pub(super) plane_columns: Vec<(usize, Vec<(usize, f64)>)>,
    pub(super) output: Arc<OutputPlan>,
}

impl Plan {
    /// Coloured: supports from the interaction graph of the activation `active`.
    fn coloured(
        model: &Model,
        active: &[bool],
        inputs: &[Input],
        sk: &Skeleton,
        tapered: bool,
    ) -> Plan {
        let graph = Interactions::new(model, &sk.neighbours, active);
        let sup = supports(model, &graph, inputs, sk, tapered.then_some(active));
        // a rigid translation against world planes only moves their gaps, by n·d: the gap
        // rows of those candidates are its whole column
        let plane: Vec<Option<(Vec<usize>, Vec<f64>)>> = (0..inputs.len())
            .map(|c| {
                // (a translation column's support holds exactly its boundary candidates)
                let boundary = sk.translating[c].then(|| sup[c].contacts.clone())?;
                let entries = plane_entries(model, inputs[c], &boundary)?;
                Some((boundary, entries))
            })
            .collect();
        // with κ weighted by the gaps' rates at the start, a change of the current twists
        // moves the weights of the active candidates on the bodies it touches
        let light_pairs: Vec<Vec<usize>> = (0..inputs.len())
            .map(|c| match inputs[c] {
                Input::State(_) if tapered && sk.light[c] => {
                    let touched = &sk.bodies[c].0;
                    let on = |g: usize| touched.contains(&model.geoms[g].body);
                    (0..model.ncontact())
                        .filter(|&k| active[k])
                        .filter(|&k| on(model.contacts[k].geom_a) || on(model.contacts[k].geom_b))
                        .collect()
                }
                _ => Vec::new(),
            })
            .collect();
        // and of the active limits of the joints on those bodies
        let nc = model.ncontact();
        let light_limits: Vec<Vec<usize>> = (0..inputs.len())
            .map(|c| match inputs[c] {
                Input::State(_) if tapered && sk.light[c] => {
                    let touched = &sk.bodies[c].0;
                    let on = |b: usize| touched.contains(&b);
                    (model.joints.iter().enumerate())
                        .filter(|(j, _)| model.topology.limit_node[*j].is_some() && active[nc + j])
                        .filter(|(_, joint)| on(joint.parent) || on(joint.child))
                        .map(|(j, _)| j)
                        .collect()
                }
                _ => Vec::new(),
            })
            .collect();
        // and of the active tendon limits with a term on a joint of those bodies
        let tendons = nc + model.njoint();
        let light_tendons: Vec<Vec<usize>> = (0..inputs.len())
            .map(|c| match inputs[c] {
                Input::State(_) if tapered && sk.light[c] => {
                    let touched = &sk.bodies[c].0;
                    let on = |j: usize| {
                        let joint = &model.joints[j];
                        touched.contains(&joint.parent) || touched.contains(&joint.child)
                    };
                    (model.tendon_limits.iter().enumerate())
                        .filter(|(k, _)| active[tendons + k])
                        .filter(|(_, t)| t.terms.iter().any(|&(j, _, _)| on(j)))
                        .map(|(k, _)| k)
                        .collect()
                }
                _ => Vec::new(),
            })
            .collect();
        let rows: Vec<Vec<(usize, usize)>> = sup
            .iter()
            .zip(&sk.light_rows)
            .enumerate()
            .map(|(c, (s, light))| match (sk.light[c], &plane[c]) {
                (true, _) => {
                    let pairs = light_pairs[c].iter().flat_map(|&k| pair_rows(model, k));
                    let limits = light_limits[c]
                        .iter()
                        .flat_map(|&j| limit_pair_rows(model, j));
                    let tendon_rows = light_tendons[c].iter().flat_map(|&k| {
                        let o = model.topology.pattern.offset(model.topology.tendon_node[k]);
                        [(o + 1, 1), (o + 3, 1)]
                    });
                    let (light, pairs) = (light.iter().copied(), pairs);
                    light
                        .chain(pairs)
                        .chain(limits)
                        .chain(tendon_rows)
                        .collect()
                }
                (false, Some((ks, _))) => ks
                    .iter()
                    .flat_map(|&k| plane_rows(model, k, tapered))
                    .collect(),
                (false, None) => node_rows(model, &s.nodes),
            })
            .collect();
        // full columns by coloured residual evaluations, light and plane ones in closed form
        let groups = coloured_columns(&sup, |c| !sk.light[c] && plane[c].is_none(), model);
        let plane_columns = (plane.into_iter().enumerate())
            .filter_map(|(c, p)| {
                let (ks, entries) = p?;
                Some((c, ks.into_iter().zip(entries).collect()))
            })
            .collect();
        // contacts and joints each group must refresh
        let refresh: Vec<Refresh> = groups
            .iter()
            .map(|g| {
                let mut cs: Vec<usize> = g
                    .iter()
                    .flat_map(|&c| sup[c].contacts.iter().copied())
                    .collect();
                cs.sort_unstable();
                cs.dedup();
                let mut touched = vec![false; model.nbody()];
                for b in g.iter().flat_map(|&c| &sup[c].bodies) {
                    touched[*b] = true;
                }
                let joints = model
                    .joints
                    .iter()
                    .map(|j| touched[j.parent] || touched[j.child])
                    .collect();
                // the bodies whose rows the group's supports hold
                let mut in_group = vec![false; model.topology.pattern.nnodes()];
                for &n in g.iter().flat_map(|&c| &sup[c].nodes) {
                    in_group[n] = true;
                }
                let bodies = (0..model.nbody())
                    .map(|b| body_node(b).is_some_and(|n| in_group[n]))
                    .collect();
                Refresh {
                    contacts: cs,
                    joints,
                    bodies,
                }
            })
            .collect();
        Plan {
            r_start: Arc::new(column_starts(&rows)),
            rows: Arc::new(rows),
            groups,
            refresh: Some(refresh),
            light_groups: sk.light_groups.clone(),
            light_body_ranges: sk.light_rows.iter().map(Vec::len).collect(),
            light_pairs,
            light_limits,
            light_tendons,
            plane_columns,
            output: sk.output.clone(),
        }
    }

    /// Column by column, every row (the reference).
    pub(super) fn column_by_column(
        model: &Model,
        coords: Coordinates,
        inputs: &[Input],
        nw: usize,
    ) -> Plan {
        let rows = vec![vec![(0, nw)]; inputs.len()];
        Plan {
            r_start: Arc::new(column_starts(&rows)),
            rows: Arc::new(rows),
            groups: (0..inputs.len()).map(|c| vec![c]).collect(),
            refresh: None,
            light_groups: Vec::new(),
            light_body_ranges: vec![0; inputs.len()],
            light_pairs: vec![Vec::new(); inputs.len()],
            light_limits: vec![Vec::new(); inputs.len()],
            light_tendons: vec![Vec::new(); inputs.len()],
            plane_columns: Vec::new(),
            output: Arc::new(OutputPlan::new(model, coords, inputs, None, &[])),
        }
    }
}

/// Plans kept per thread, most recently used first.
const KEPT_PLANS: usize = 8;

/// A kept [`Plan`], with its skeleton's key and the activation it was built for.
type KeptPlan = (SkeletonKey, Vec<bool>, bool, Arc<Plan>);

/// What a [`Skeleton`] is built from.
#[derive(PartialEq)]
struct SkeletonKey {
    topology: u64,
    coords: Coordinates,
    inputs: Vec<Input>,
}

thread_local! {
    static SKELETONS: std::cell::RefCell<Vec<(SkeletonKey, Arc<Skeleton>)>> =
        const { std::cell::RefCell::new(Vec::new()) };
    static PLANS: std::cell::RefCell<Vec<KeptPlan>> =
        const { std::cell::RefCell::new(Vec::new()) };
}

/// Move the entry at `i` to the front (most recently used).
fn to_front<T>(kept: &mut [T], i: usize) {
    kept[..=i].rotate_right(1);
}

/// The coloured [`Plan`] for these inputs at the activation `active`: a kept one (the Panda
/// repeats its activation over most steps), or one built on the kept [`Skeleton`] (the
/// humanoid's and the A1's change nearly every step). `tapered`: whether κ's weights move
/// with the gaps (`solver::taper`), so that a translation against world planes also changes
/// the complementarity rows ([`plane_rows`]).
pub(super) fn plan_for(
    model: &Model,
    coords: Coordinates,
    active: &[bool],
    inputs: &[Input],
    tapered: bool,
) -> Arc<Plan> {
    let key = SkeletonKey {
        topology: model.topology_id(),
        coords,
        inputs: inputs.to_vec(),
    };
    let kept = PLANS
        .try_with(|p| {
            let mut p = p.try_borrow_mut().ok()?;
            let i = p
                .iter()
                .position(|(k, a, t, _)| *k == key && a == active && *t == tapered)?;
            to_front(&mut p, i);
            Some(p[0].3.clone())
        })
        .ok()
        .flatten();
    if let Some(plan) = kept {
        return plan;
    }
    let kept = SKELETONS
        .try_with(|s| {
            let mut s = s.try_borrow_mut().ok()?;
            let i = s.iter().position(|(k, _)| *k == key)?;
            to_front(&mut s, i);
            Some(s[0].1.clone())
        })
        .ok()
        .flatten();
    let sk = kept.unwrap_or_else(|| {
        let sk = Arc::new(Skeleton::new(model, coords, inputs));
        let _ = SKELETONS.try_with(|s| {
            if let Ok(mut s) = s.try_borrow_mut() {
                s.truncate(KEPT_PLANS - 1);
                let key = SkeletonKey {
                    inputs: inputs.to_vec(),
                    ..key
                };
                s.insert(0, (key, sk.clone()));
            }
        });
        sk
    });
    let plan = Arc::new(Plan::coloured(model, active, inputs, &sk, tapered));
    let _ = PLANS.try_with(|p| {
        if let Ok(mut p) = p.try_borrow_mut() {
            p.truncate(KEPT_PLANS - 1);
            p.insert(0, (key, active.to_vec(), tapered, plan.clone()));
        }
    });
    plan
}

/// What one group's residual evaluations recompute: its contact candidates and its joints
/// (those of the bodies it touches).
pub(super) struct Refresh {
    pub(super) contacts: Vec<usize>,
    pub(super) joints: Vec<bool>,
    /// The bodies whose rows its supports hold (the others' rows are not computed).
    pub(super) bodies: Vec<bool>,
}

/// The joints whose output rows a group of body velocities covers, and those of them with
/// free translations.
type JointsCovered = (Vec<bool>, Vec<bool>);

/// The structure of [`output_partials`]: which output rows each input column and each body
/// velocity reaches, and the groups perturbed together.
pub(super) struct OutputPlan {
    /// Output rows of each input column (empty: its `∂Y/∂z` column is zero).
    pub(super) col_rows: Vec<Vec<usize>>,
    /// Groups of state (and time-step) columns, with the joints whose output rows they cover
    /// when only those are recomputed (minimal coordinates, coloured).
    pub(super) z_groups: Vec<(Vec<usize>, Option<Vec<bool>>)>,
    /// Output rows of each moving body's velocity.
    pub(super) body_rows: Vec<Vec<usize>>,
    /// Groups of moving bodies (index `b - 1`), with the joints they cover and those of them
    /// with free translations (coloured minimal coordinates).
    pub(super) w_groups: Vec<(Vec<usize>, Option<JointsCovered>)>,
    /// The joint of each velocity coordinate.
    pub(super) dof_joint: Vec<usize>,
    /// Translation columns ([`translates_rigidly`]): a rigid translation by `ε` moves the next
    /// state's own coordinate by `ε` and nothing else (the next position is the current one
    /// plus the step's travel; the other coordinates are relative), so `∂Y/∂z` is its unit
    /// row, with no evaluation.
    pub(super) unit_cols: Vec<usize>,
}

impl OutputPlan {
    /// With the residual supports `sup` (coloured partials), columns and bodies whose output
    /// rows do not overlap are grouped; without, one by one.
    fn new(
        model: &Model,
        coords: Coordinates,
        inputs: &[Input],
        moved: Option<&[&[usize]]>,
        translating: &[bool],
    ) -> Self {
        let ny = coords.dim(model);
        let unit = |c: usize| translating.get(c).copied().unwrap_or(false);
        let cols: Vec<usize> = (0..inputs.len())
            .filter(|&c| matches!(inputs[c], Input::State(_) | Input::Param(Param::Timestep)))
            .filter(|&c| !unit(c))
            .collect();
        // output rows of each column: those of the bodies it moves (a body's next state is its
        // own pose stepped by its velocity in `w`; the current velocities do not enter)
        let body_rows = output_rows(model, coords);
        let col_rows: Vec<Support> = (0..inputs.len())
            .map(|c| {
                let mut nodes: Vec<usize> = match (moved, inputs[c]) {
                    (_, Input::State(i)) if unit(c) => vec![i],
                    (Some(moved), Input::State(_)) => moved[c]
                        .iter()
                        .flat_map(|&b| body_rows[b - 1].nodes.iter().copied())
                        .collect(),
                    _ => (0..ny).collect(),
                };
                nodes.sort_unstable();
                nodes.dedup();
                Support {
                    nodes,
                    ..Support::default()
                }
            })
            .collect();
        let groups: Vec<Vec<usize>> = match moved {
            Some(_) => {
                let supports: Vec<&[usize]> =
                    cols.iter().map(|&c| col_rows[c].nodes.as_slice()).collect();
                colour(&supports, ny)
                    .into_iter()
                    .map(|g| g.into_iter().map(|k| cols[k]).collect())
                    .collect()
            }
            None => cols.iter().map(|&c| vec![c]).collect(),
        };
        // the joints whose output rows a set of rows (minimal coordinates) covers
        let dof_joint: Vec<usize> = {
            let mut d = vec![0; model.nv];
            for (ji, j) in model.joints.iter().enumerate().filter(|(_, j)| !j.is_loop) {
                d[j.qvel_adr..j.qvel_adr + j.nfree()].fill(ji);
            }
            d
        };
        let joints_of = |rows: &mut dyn Iterator<Item = usize>| -> Vec<bool> {
            let mut js = vec![false; model.njoint()];
            for i in rows {
                js[dof_joint[i % model.nv.max(1)]] = true;
            }
            js
        };
        let restrict = moved.is_some() && coords == Coordinates::Minimal;
        let z_groups = groups
            .into_iter()
            // velocity columns: ∂Y/∂z is zero
            .filter(|group| group.iter().any(|&c| !col_rows[c].nodes.is_empty()))
            .map(|group| {
                let js = restrict.then(|| {
                    joints_of(
                        &mut group
                            .iter()
                            .flat_map(|&c| col_rows[c].nodes.iter().copied()),
                    )
                });
                (group, js)
            })
            .collect();
        // ∂Y/∂w: bodies whose outputs do not overlap are perturbed together
        let (rows, groups) = match moved {
            Some(_) => {
                let nodes: Vec<&[usize]> = body_rows.iter().map(|s| s.nodes.as_slice()).collect();
                let groups = colour(&nodes, ny);
                (body_rows, groups)
            }
            None => {
                let all = Support {
                    nodes: (0..ny).collect(),
                    ..Support::default()
                };
                let n = model.nbody() - 1;
                (vec![all; n], (0..n).map(|b| vec![b]).collect())
            }
        };
        let w_groups = groups
            .into_iter()
            .map(|group| {
                let js = restrict.then(|| {
                    let js =
                        joints_of(&mut group.iter().flat_map(|&b| rows[b].nodes.iter().copied()));
                    // a joint without free translations has coordinates and rates of its
                    // bodies' orientations and angular velocities alone: the linear velocity
                    // components move only the rows of the joints with translations (the
                    // others' entries are exactly zero)
                    let translating = (0..model.njoint())
                        .map(|ji| js[ji] && model.joints[ji].ntrans > 0)
                        .collect();
                    (js, translating)
                });
                (group, js)
            })
            .collect();
        OutputPlan {
            unit_cols: (0..inputs.len()).filter(|&c| unit(c)).collect(),
            col_rows: col_rows.into_iter().map(|s| s.nodes).collect(),
            z_groups,
            body_rows: rows.into_iter().map(|s| s.nodes).collect(),
            w_groups,
            dof_joint,
        }
    }
}

/// Output rows (as a [`Support`]'s `nodes`) that each moving body's next velocities reach:
/// its own 12 in maximal coordinates; in minimal ones the dofs of the joints it is the parent
/// or child of (a joint's coordinates and rates are those of its child relative to its parent).
fn output_rows(model: &Model, coords: Coordinates) -> Vec<Support> {
    let nv = model.nv;
    (1..model.nbody())
        .map(|b| {
            let nodes = match coords {
                Coordinates::Maximal => (12 * (b - 1)..12 * b).collect(),
                Coordinates::Minimal => {
                    let mut rows: Vec<usize> = model
                        .joints
                        .iter()
                        .filter(|j| !j.is_loop && (j.parent == b || j.child == b))
                        .flat_map(|j| j.qvel_adr..j.qvel_adr + j.nfree())
                        .flat_map(|i| [i, nv + i])
                        .collect();
                    rows.sort_unstable();
                    rows
                }
            };
            Support {
                nodes,
                ..Support::default()
            }
        })
        .collect()
}
