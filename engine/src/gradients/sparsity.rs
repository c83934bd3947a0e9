//! Row supports of the residual partials `∂R/∂z` and their column colouring
//! (Curtis–Powell–Reid).
//!
//! A perturbed input changes the residual only near the bodies it touches: their body rows and
//! those of their neighbours in the *interaction graph* (bodies sharing a joint, a joint
//! coupling, an actuator transmission or a passive tendon), the joint, limit and coupling nodes of their joints,
//! the tendon-limit nodes over their joints, and the nodes of the contact candidates whose
//! geometry it moves together with the rows of those candidates' two bodies. (A tendon limit
//! links no bodies: its impulse acts on each term's bodies through that joint's own free
//! Jacobian, and only its node's rows read the other terms' coordinates.)
//! Columns whose supports are disjoint can be perturbed in one residual evaluation and
//! separated afterwards by their supports; the graph is fixed by the model's topology.
use crate::model::Model;
use crate::model::Transmission;
use crate::model::topology_body_node as body_node;

/// The neighbours of each body through joints, couplings and transmissions (itself
/// included), sorted: what the topology fixes of the interaction graph.
pub(super) fn neighbours(model: &Model) -> Vec<Vec<usize>> {
    let nb = model.nbody();
    let mut nbrs: Vec<Vec<usize>> = (0..nb).map(|b| vec![b]).collect();
    let mut link = |group: &[usize]| {
        for &a in group.iter().filter(|&&a| a > 0) {
            nbrs[a].extend(group.iter().filter(|&&b| b > 0));
        }
    };
    for j in &model.joints {
        link(&[j.parent, j.child]);
    }
    for c in &model.topology.coupling_blocks {
        link(&c.iter().map(|&(b, _)| b).collect::<Vec<_>>());
    }
    for a in &model.actuators {
        link(&transmission_bodies(model, &a.transmission));
    }
    for t in &model.passive_tendons {
        let terms = Transmission::Tendon(t.terms.clone());
        link(&transmission_bodies(model, &terms));
    }
    for n in &mut nbrs {
        n.sort_unstable();
        n.dedup();
    }
    nbrs
}

/// Which bodies interact with which, and which active contact candidates each body and geom
/// has.
pub(super) struct Interactions<'n> {
    /// [`neighbours`].
    nbrs: &'n [Vec<usize>],
    /// Active contact candidates of each body.
    pub body_contacts: Vec<Vec<usize>>,
    /// Active contact candidates of each geom.
    pub geom_contacts: Vec<Vec<usize>>,
}

impl<'n> Interactions<'n> {
    /// The graph of `model` with the body neighbours `nbrs` ([`neighbours`]) and the contact
    /// candidates `active` (the activation frozen for the linearisation: an inactive
    /// candidate's rows are constant, so it is in no support; on the humanoid the inactive
    /// ones linked nearly every body to every other).
    pub fn new(model: &Model, nbrs: &'n [Vec<usize>], active: &[bool]) -> Interactions<'n> {
        let mut body_contacts = vec![Vec::new(); model.nbody()];
        let mut geom_contacts = vec![Vec::new(); model.geoms.len()];
        for (c, contact) in model
            .contacts
            .iter()
            .enumerate()
            .filter(|&(c, _)| active[c])
        {
            // NOTE: no link: a contact changes only when its geometry moves, and then its own
            // rows and the rows of its two bodies are in the support (see `Support::new`)
            let [a, b] = model.topology.contact_bodies[c];
            body_contacts[a].push(c);
            if b != a {
                body_contacts[b].push(c);
            }
            geom_contacts[contact.geom_a].push(c);
            geom_contacts[contact.geom_b].push(c);
        }
        Interactions {
            nbrs,
            body_contacts,
            geom_contacts,
        }
    }
}

/// Bodies an actuator's force acts on (and whose state its length and rate depend on).
pub(super) fn transmission_bodies(model: &Model, t: &Transmission) -> Vec<usize> {
    match t {
        Transmission::Joint { joint, .. } => {
            vec![model.joints[*joint].parent, model.joints[*joint].child]
        }
        Transmission::Tendon(terms) => terms
            .iter()
            .flat_map(|&(j, _, _)| [model.joints[j].parent, model.joints[j].child])
            .collect(),
        Transmission::Site { body, .. } => vec![*body],
    }
}

/// Where one column of `∂R/∂z` can be non-zero, and what its evaluation must refresh.
#[derive(Clone, Debug, Default)]
pub(super) struct Support {
    /// Graph nodes whose rows may change, sorted.
    pub nodes: Vec<usize>,
    /// Contact candidates whose geometry changes (re-evaluated), sorted.
    pub contacts: Vec<usize>,
    /// Bodies whose pose, or whose joints' parameters, change: their joints are re-evaluated,
    /// and their next states are the outputs that move. (A current velocity enters neither:
    /// joint frames, springs and limits read poses, and the next state's velocities are `w`.)
    pub bodies: Vec<usize>,
}

impl Support {
    /// The support of an input that changes the state or the elements of the moving bodies
    /// `touched`, moves the bodies `moved` (a subset) and changes the contact candidates
    /// `contacts` beyond those of the moved bodies.
    /// `joint_bodies` are the bodies of [`Support::bodies`].
    pub fn new(
        model: &Model,
        graph: &Interactions,
        touched: &[usize],
        moved: &[usize],
        contacts: &[usize],
        joint_bodies: &[usize],
    ) -> Support {
        let t = &model.topology;
        let mut cs: Vec<usize> = contacts.to_vec();
        for &b in moved {
            cs.extend(&graph.body_contacts[b]);
        }
        cs.sort_unstable();
        cs.dedup();
        let mut is_touched = vec![false; model.nbody()];
        for &b in touched.iter().filter(|&&b| b > 0) {
            is_touched[b] = true;
        }
        // a contact's impulse acts on its two bodies only
        let mut nodes: Vec<usize> = cs
            .iter()
            .flat_map(|&c| t.contact_bodies[c])
            .filter_map(body_node)
            .collect();
        for &b in touched.iter().filter(|&&b| b > 0) {
            nodes.extend(graph.nbrs[b].iter().filter_map(|&n| body_node(n)));
        }
        for (j, joint) in model.joints.iter().enumerate() {
            if is_touched[joint.parent] || is_touched[joint.child] {
                nodes.extend(t.joint_node[j]);
                nodes.extend(t.limit_node[j]);
                nodes.extend(t.friction_node[j]);
            }
        }
        for (k, blocks) in t.coupling_blocks.iter().enumerate() {
            if blocks.iter().any(|&(b, _)| is_touched[b]) {
                nodes.push(t.coupling_node[k]);
            }
        }
        for (k, blocks) in t.tendon_blocks.iter().enumerate() {
            if blocks.iter().any(|&(b, _)| is_touched[b]) {
                nodes.push(t.tendon_node[k]);
            }
        }
        for (k, blocks) in t.tendon_friction_blocks.iter().enumerate() {
            if blocks.iter().any(|&(b, _)| is_touched[b]) {
                nodes.extend(t.tendon_friction_node[k]);
            }
        }
        nodes.extend(cs.iter().map(|&c| t.contact_node[c]));
        nodes.sort_unstable();
        nodes.dedup();
        Support {
            nodes,
            contacts: cs,
            bodies: joint_bodies.iter().copied().filter(|&b| b > 0).collect(),
        }
    }

    /// The support of an input that changes only the current velocities or the applied forces
    /// of the bodies `touched` (a velocity, a control): the body rows of those bodies and their
    /// neighbours (momenta, actuator rates, armature). Joint, limit and contact rows read poses
    /// and `w` only, so they are not in it; such a column is taken in closed form on body rows
    /// alone (`gradients::light`).
    pub fn body_rows(graph: &Interactions, touched: &[usize]) -> Support {
        let mut nodes: Vec<usize> = touched
            .iter()
            .filter(|&&b| b > 0)
            .flat_map(|&b| graph.nbrs[b].iter().filter_map(|&n| body_node(n)))
            .collect();
        nodes.sort_unstable();
        nodes.dedup();
        Support {
            nodes,
            ..Support::default()
        }
    }

    /// Every row and every contact candidate (inputs that change the whole step).
    pub fn everything(model: &Model) -> Support {
        Support {
            nodes: (0..model.topology.pattern.nnodes()).collect(),
            contacts: (0..model.ncontact()).collect(),
            bodies: (1..model.nbody()).collect(),
        }
    }
}

/// Greedy colouring: groups of columns with pairwise disjoint supports, columns with the
/// largest supports placed first.
pub(super) fn colour(supports: &[&[usize]], nnodes: usize) -> Vec<Vec<usize>> {
    let mut order: Vec<usize> = (0..supports.len()).collect();
    order.sort_by_key(|&c| std::cmp::Reverse(supports[c].len()));
    let mut groups: Vec<Vec<usize>> = Vec::new();
    let mut used: Vec<Vec<bool>> = Vec::new();
    for c in order {
        let nodes = supports[c];
        let k = match used.iter().position(|u| nodes.iter().all(|&n| !u[n])) {
            Some(k) => k,
            None => {
                groups.push(Vec::new());
                used.push(vec![false; nnodes]);
                groups.len() - 1
            }
        };
        groups[k].push(c);
        for &n in nodes {
            used[k][n] = true;
        }
    }
    groups
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn colour_groups_are_disjoint_and_cover_every_column() {
        // a chain of supports {i, i+1} over 10 nodes, plus one column touching everything
        let mut sup: Vec<Support> = (0..9)
            .map(|i| Support {
                nodes: vec![i, i + 1],
                ..Support::default()
            })
            .collect();
        sup.push(Support {
            nodes: (0..10).collect(),
            ..Support::default()
        });
        let nodes: Vec<&[usize]> = sup.iter().map(|s| s.nodes.as_slice()).collect();
        let groups = colour(&nodes, 10);
        let mut seen = vec![false; sup.len()];
        for g in &groups {
            let mut used = [false; 10];
            for &c in g {
                assert!(!seen[c], "column {c} coloured twice");
                seen[c] = true;
                for &n in &sup[c].nodes {
                    assert!(!used[n], "group {g:?} shares node {n}");
                    used[n] = true;
                }
            }
        }
        assert!(seen.iter().all(|&s| s));
        // the full column alone, the chain in two alternating groups
        assert_eq!(groups.len(), 3);
    }
}
