//! Mechanism graph (Dojo Fig. 3): bodies and joints are nodes; the block pattern of the Newton
//! matrix and its elimination order are fixed when the model is compiled.
//!
//! Elimination order: post-order over the spanning tree in which each body hangs below its parent
//! joint and each joint below its parent body, so every joint is eliminated after the subtree it
//! carries (its pivot is then the negative-definite Schur complement `-K M⁻¹ Kᵀ`); a joint
//! coupling or tendon limit (a node touching the bodies of several joints) comes just before the
//! lowest body above all of its joints, and loop-closing joints last. Trees have no fill-in;
//! loops fill in along their cycle only, couplings and tendon limits along the tree paths
//! between their bodies and that body.
use std::sync::atomic::{AtomicU64, Ordering};

use crate::contact::{Contact, ContactModel, Geom};
use crate::joints::Joint;
use crate::joints::coupling::Coupling;
use crate::joints::tendon::{PassiveTendon, TendonLimit};
use crate::solver::graph_ldu::BlockPattern;

static NEXT_ID: AtomicU64 = AtomicU64::new(1);

/// Offsets of one joint's blocks in the Newton matrix arena.
#[derive(Clone, Debug, Default)]
pub(crate) struct JointBlocks {
    /// (joint row, parent col) and (parent row, joint col).
    pub jp: Option<(usize, usize)>,
    /// (joint row, child col) and (child row, joint col).
    pub jc: Option<(usize, usize)>,
    /// (parent row, child col) and (child row, parent col): the coupling of terms on the
    /// joint's free rates (dampers, armature, position servos' velocity gains). Every joint
    /// with free dofs between two moving bodies has it, whether or not such a term is
    /// non-zero when the model is compiled: `Model::with_params` may set a joint's damping
    /// later (from 0 the Newton matrix lacked this block: 8× the iterations and Jacobians off
    /// by 0.26 on a two-link chain), and a servo's velocity gain acts only while its force is
    /// inside its range.
    pub pc: Option<(usize, usize)>,
}

/// Everything about connectivity, decided at compile time.
#[derive(Clone, Debug)]
pub(crate) struct Topology {
    pub id: u64,
    /// Tree joints, each after the joint of its parent body.
    pub fk_order: Vec<usize>,
    /// First row of each joint in the impulse vector.
    pub con_adr: Vec<usize>,
    /// Total constraint rows.
    pub ncon: usize,
    pub pattern: BlockPattern,
    /// Graph node of each joint with constraint rows.
    pub joint_node: Vec<Option<usize>>,
    /// Diagonal block offset of each moving body (index by body; world unused).
    pub body_diag: Vec<usize>,
    /// Diagonal block offset of each joint node.
    pub joint_diag: Vec<Option<usize>>,
    pub blocks: Vec<JointBlocks>,
    /// Node of each joint's limit variables (4 per limited dof: γ_lo, s_lo, γ_hi, s_hi).
    pub limit_node: Vec<Option<usize>>,
    /// (node row, body col) and (body row, node col) blocks of each limit node for the joint's
    /// parent and child.
    pub limit_blocks: Vec<[Option<(usize, usize)>; 2]>,
    /// Node (one impulse row) of each joint coupling, eliminated last like loop joints.
    pub coupling_node: Vec<usize>,
    /// Per coupling, each distinct moving body it acts on with its (node row, body col) and
    /// (body row, node col) blocks.
    pub coupling_blocks: Vec<Vec<(usize, (usize, usize))>>,
    /// Node of each tendon limit (`[γ_lo, s_lo, γ_hi, s_hi]`), eliminated last like couplings.
    pub tendon_node: Vec<usize>,
    /// Per tendon limit, each distinct moving body of its joints with its (node row, body col)
    /// and (body row, node col) blocks.
    pub tendon_blocks: Vec<Vec<(usize, (usize, usize))>>,
    /// Node of each passive tendon's dry-friction variables (`[δ_fw, s_fw, δ_bw, s_bw]`),
    /// numbered after the joints' and eliminated first, as a leaf.
    pub tendon_friction_node: Vec<Option<usize>>,
    /// Per passive tendon with friction, each distinct moving body of its joints with its
    /// (node row, body col) and (body row, node col) blocks.
    pub tendon_friction_blocks: Vec<Vec<(usize, (usize, usize))>>,
    /// Index of each winding hinge's turns in [`crate::State`]'s winding ([`Joint::winds`]).
    pub winding_adr: Vec<Option<usize>>,
    /// Node of each joint's dry-friction variables (4 per dof with `frictionloss`:
    /// `[δ_fw, s_fw, δ_bw, s_bw]`, [`crate::solver::friction`]), numbered after every other
    /// node and eliminated first, as a leaf.
    pub friction_node: Vec<Option<usize>>,
    /// (node row, body col) and (body row, node col) blocks of each friction node for the
    /// joint's parent and child.
    pub friction_blocks: Vec<[Option<(usize, usize)>; 2]>,
    /// Node of each contact candidate.
    pub contact_node: Vec<usize>,
    /// Blocks of each contact node for the bodies of geom a and geom b.
    pub contact_blocks: Vec<[Option<(usize, usize)>; 2]>,
    /// Bodies of each contact's geoms (a, b).
    pub contact_bodies: Vec<[usize; 2]>,
    /// Whether the step has inequality variables (contacts, joint or tendon limits):
    /// interior-point path.
    pub has_cones: bool,
    /// Complementarity pairs of the whole problem (orthant pairs and second-order cones of
    /// every contact candidate, joint limit and tendon limit): what the solver's mean
    /// complementarity divides by.
    pub cone_degree: usize,
    /// Rows of bodies, joints and couplings (the inequality nodes follow them).
    pub smooth_dim: usize,
    /// The friction-cone candidates between bodies that can only slide along one axis relative
    /// to each other (`Contact::slide_axes`): those whose friction a step may hold at zero.
    pub slide_candidates: Vec<usize>,
}

impl Topology {
    /// The dry-friction nodes, joints' then passive tendons', in node order.
    pub fn friction_nodes(&self) -> impl Iterator<Item = usize> + '_ {
        self.friction_node
            .iter()
            .chain(&self.tendon_friction_node)
            .flatten()
            .copied()
    }
}

/// Graph node of a moving body.
pub(crate) fn body_node(b: usize) -> Option<usize> {
    b.checked_sub(1)
}

impl Topology {
    /// Build the graph; `parent_joint[b]` is the tree joint whose child is `b` (`None` for world).
    #[allow(clippy::too_many_arguments)]
    pub fn new(
        nbody: usize,
        joints: &[Joint],
        parent_joint: &[Option<usize>],
        geoms: &[Geom],
        contacts: &[Contact],
        couplings: &[Coupling],
        tendons: &[TendonLimit],
        (actuators, passive): (&[crate::model::Actuator], &[PassiveTendon]),
    ) -> Result<Self, String> {
        let nmoving = nbody - 1;
        let mut dims = vec![6; nmoving];
        let mut joint_node = vec![None; joints.len()];
        let mut con_adr = Vec::with_capacity(joints.len());
        let mut ncon = 0;
        for (j, joint) in joints.iter().enumerate() {
            con_adr.push(ncon);
            ncon += joint.ncon();
            if joint.ncon() > 0 {
                joint_node[j] = Some(dims.len());
                dims.push(joint.ncon());
            }
        }
        // couplings: smooth nodes (before the inequality leaves), touching up to four bodies
        let mut coupling_node = Vec::with_capacity(couplings.len());
        let mut coupling_bodies = Vec::with_capacity(couplings.len());
        for c in couplings {
            coupling_node.push(dims.len());
            dims.push(1);
            let terms = std::iter::once(c.joint1).chain(c.joint2);
            coupling_bodies.push(moving_bodies(joints, terms.map(|t| t.0)));
        }
        let mut leaves = Vec::new();
        let mut limit_node = vec![None; joints.len()];
        for (j, joint) in joints.iter().enumerate() {
            if !joint.limits.is_empty() {
                limit_node[j] = Some(dims.len());
                leaves.push(dims.len());
                dims.push(4 * joint.limits.len());
            }
        }
        let mut contact_node = Vec::with_capacity(contacts.len());
        let mut contact_bodies = Vec::with_capacity(contacts.len());
        let mut cone_degree = 2 * joints.iter().map(|j| j.limits.len()).sum::<usize>();
        for c in contacts {
            contact_node.push(dims.len());
            leaves.push(dims.len());
            dims.push(c.model.dim());
            contact_bodies.push([geoms[c.geom_a].body, geoms[c.geom_b].body]);
            // (a box pair's edge-crossing slots are not counted: most hold nothing, and the
            // degree sets the interior-point centring of every step, so adding them would have
            // moved every box model's steps)
            if !c.feature.is_crossing_slot() {
                let (o, q) = c.model.cones();
                cone_degree += o + q;
            }
        }
        // tendon limits: inequality nodes, but eliminated with the couplings (they touch
        // several joints' bodies: as leaves they would fill in between all of them)
        let mut tendon_node = Vec::with_capacity(tendons.len());
        let mut tendon_bodies = Vec::with_capacity(tendons.len());
        for t in tendons {
            tendon_node.push(dims.len());
            dims.push(4);
            tendon_bodies.push(moving_bodies(joints, t.terms.iter().map(|t| t.0)));
            cone_degree += 2;
        }
        // dry joint friction: leaves numbered last (always live: `for_each_live_range`)
        let mut friction_node = vec![None; joints.len()];
        for (j, joint) in joints.iter().enumerate() {
            if joint.nfriction() > 0 {
                friction_node[j] = Some(dims.len());
                leaves.push(dims.len());
                dims.push(4 * joint.nfriction());
                cone_degree += 2 * joint.nfriction();
            }
        }
        // dry tendon friction: numbered last, eliminated first as a leaf although it fills in
        // between its joints' bodies. Eliminated late like a tendon limit, a sliding tendon's
        // pivots (room ~1e-12 against a displacement ~1e-2) came after the bodies' Schur
        // updates and the solve stalled: a three-link chain at rtol 1e-14 took 27 iterations
        // and ended `acceptable` at 1e-12, against 5 iterations converged as a leaf.
        let mut tendon_friction_node = vec![None; passive.len()];
        let mut tendon_friction_bodies = vec![Vec::new(); passive.len()];
        for (k, t) in passive.iter().enumerate() {
            if t.frictionloss > 0.0 {
                tendon_friction_node[k] = Some(dims.len());
                leaves.push(dims.len());
                dims.push(4);
                tendon_friction_bodies[k] = moving_bodies(joints, t.terms.iter().map(|t| t.0));
                cone_degree += 2;
            }
        }
        let mut edges = Vec::new();
        for (k, bodies) in tendon_friction_bodies.iter().enumerate() {
            if let Some(n) = tendon_friction_node[k] {
                edges.extend(bodies.iter().filter_map(|&b| Some((n, body_node(b)?))));
            }
        }
        for (c, bodies) in coupling_bodies.iter().enumerate() {
            edges.extend(
                bodies
                    .iter()
                    .filter_map(|&b| Some((coupling_node[c], body_node(b)?))),
            );
        }
        for (t, bodies) in tendon_bodies.iter().enumerate() {
            edges.extend(
                bodies
                    .iter()
                    .filter_map(|&b| Some((tendon_node[t], body_node(b)?))),
            );
        }
        for (j, joint) in joints.iter().enumerate() {
            for n in [limit_node[j], friction_node[j]].into_iter().flatten() {
                edges.extend(body_node(joint.parent).map(|b| (n, b)));
                edges.extend(body_node(joint.child).map(|b| (n, b)));
            }
        }
        for (c, bodies) in contact_bodies.iter().enumerate() {
            for b in bodies {
                edges.extend(body_node(*b).map(|b| (contact_node[c], b)));
            }
        }
        // an implicit tendon damper (a tendon servo's velocity gain, `actuation::split_force`;
        // a passive tendon's damping) couples every pair of its joints' bodies
        for terms in &crate::solver::actuation::damped_tendons(actuators, passive) {
            let bodies = moving_bodies(joints, terms.iter().copied());
            for (i, &a) in bodies.iter().enumerate() {
                for &b in &bodies[i + 1..] {
                    edges.extend(body_node(a).zip(body_node(b)));
                }
            }
        }
        for (j, joint) in joints.iter().enumerate() {
            let (p, c) = (body_node(joint.parent), body_node(joint.child));
            if let Some(jn) = joint_node[j] {
                edges.extend(p.map(|p| (jn, p)));
                edges.extend(c.map(|c| (jn, c)));
            }
            if let (Some(p), Some(c), true) = (p, c, joint.nfree() > 0) {
                edges.push((p, c));
            }
        }
        // contact and joint-limit nodes are leaves: eliminated first; couplings and tendon
        // limits below the lowest body above their joints (`elimination_order`)
        let mut order = leaves.clone();
        // couplings and tendon limits with the joints of their terms
        let mut late: Vec<(usize, Vec<usize>)> = (couplings.iter().zip(&coupling_node))
            .map(|(c, &n)| {
                (
                    n,
                    std::iter::once(c.joint1.0)
                        .chain(c.joint2.map(|t| t.0))
                        .collect(),
                )
            })
            .collect();
        late.extend(
            (tendons.iter().zip(&tendon_node))
                .map(|(t, &n)| (n, t.terms.iter().map(|t| t.0).collect())),
        );

        order.extend(elimination_order(
            nmoving,
            joints,
            parent_joint,
            &joint_node,
            dims.len(),
            &leaves,
            &late,
        ));
        let pattern = BlockPattern::new(&dims, &edges, &order)?;
        let blk = |i: usize, j: usize| -> Option<(usize, usize)> {
            Some((pattern.block(i, j)?, pattern.block(j, i)?))
        };
        let blocks = joints
            .iter()
            .enumerate()
            .map(|(j, joint)| {
                let (p, c) = (body_node(joint.parent), body_node(joint.child));
                let jn = joint_node[j];
                JointBlocks {
                    jp: jn.zip(p).and_then(|(jn, p)| blk(jn, p)),
                    jc: jn.zip(c).and_then(|(jn, c)| blk(jn, c)),
                    pc: if joint.nfree() > 0 {
                        p.zip(c).and_then(|(p, c)| blk(p, c))
                    } else {
                        None
                    },
                }
            })
            .collect();
        let pair = |n: usize, b: usize| body_node(b).and_then(|b| blk(n, b));
        let limit_blocks = joints
            .iter()
            .enumerate()
            .map(|(j, joint)| match limit_node[j] {
                Some(n) => [pair(n, joint.parent), pair(n, joint.child)],
                None => [None, None],
            })
            .collect();
        let friction_blocks = joints
            .iter()
            .enumerate()
            .map(|(j, joint)| match friction_node[j] {
                Some(n) => [pair(n, joint.parent), pair(n, joint.child)],
                None => [None, None],
            })
            .collect();
        let tendon_friction_blocks = tendon_friction_bodies
            .iter()
            .enumerate()
            .map(|(k, bodies)| match tendon_friction_node[k] {
                Some(n) => bodies
                    .iter()
                    .filter_map(|&b| Some((b, pair(n, b)?)))
                    .collect(),
                None => Vec::new(),
            })
            .collect();
        let coupling_blocks = coupling_bodies
            .iter()
            .enumerate()
            .map(|(c, bodies)| {
                bodies
                    .iter()
                    .filter_map(|&b| Some((b, pair(coupling_node[c], b)?)))
                    .collect()
            })
            .collect();
        let tendon_blocks = tendon_bodies
            .iter()
            .enumerate()
            .map(|(t, bodies)| {
                bodies
                    .iter()
                    .filter_map(|&b| Some((b, pair(tendon_node[t], b)?)))
                    .collect()
            })
            .collect();
        let contact_blocks = contact_bodies
            .iter()
            .enumerate()
            .map(|(c, [a, b])| [pair(contact_node[c], *a), pair(contact_node[c], *b)])
            .collect();
        let body_diag = (0..nbody)
            .map(|b| body_node(b).and_then(|n| pattern.block(n, n)).unwrap_or(0))
            .collect();
        let joint_diag = joint_node
            .iter()
            .map(|n| n.and_then(|n| pattern.block(n, n)))
            .collect();
        let fk_order = fk_order(joints, parent_joint);
        let smooth_dim = leaves
            .iter()
            .chain(&tendon_node)
            .map(|&n| pattern.offset(n))
            .min()
            .unwrap_or(pattern.total_dim());
        Ok(Topology {
            id: NEXT_ID.fetch_add(1, Ordering::Relaxed),
            fk_order,
            con_adr,
            ncon,
            pattern,
            joint_node,
            body_diag,
            joint_diag,
            blocks,
            has_cones: cone_degree > 0,
            cone_degree,
            limit_node,
            limit_blocks,
            coupling_node,
            coupling_blocks,
            tendon_node,
            tendon_blocks,
            friction_node,
            friction_blocks,
            tendon_friction_node,
            tendon_friction_blocks,
            winding_adr: {
                let mut k = 0;
                joints
                    .iter()
                    .map(|j| {
                        j.winds().then(|| {
                            k += 1;
                            k - 1
                        })
                    })
                    .collect()
            },
            contact_node,
            contact_blocks,
            contact_bodies,
            smooth_dim,
            slide_candidates: contacts
                .iter()
                .enumerate()
                .filter(|(_, c)| c.slide_axes.is_some() && c.model == ContactModel::Nonlinear)
                .map(|(i, _)| i)
                .collect(),
        })
    }
}

/// Distinct moving bodies (parents and children) of the given joints.
fn moving_bodies(joints: &[Joint], terms: impl Iterator<Item = usize>) -> Vec<usize> {
    let mut bodies: Vec<usize> = Vec::new();
    for j in terms {
        for b in [joints[j].parent, joints[j].child] {
            if b > 0 && !bodies.contains(&b) {
                bodies.push(b);
            }
        }
    }
    bodies
}

/// Tree joints ordered so that a body's parent joint precedes the joints of its children.
fn fk_order(joints: &[Joint], parent_joint: &[Option<usize>]) -> Vec<usize> {
    let mut order = Vec::new();
    let mut done = vec![false; joints.len()];
    fn visit(
        j: usize,
        joints: &[Joint],
        pj: &[Option<usize>],
        done: &mut [bool],
        order: &mut Vec<usize>,
    ) {
        if done[j] {
            return;
        }
        done[j] = true;
        if let Some(up) = pj[joints[j].parent] {
            visit(up, joints, pj, done, order);
        }
        order.push(j);
    }
    for (j, joint) in joints.iter().enumerate() {
        if !joint.is_loop {
            visit(j, joints, parent_joint, &mut done, &mut order);
        }
    }
    order
}

/// The body below which a coupling or tendon limit over the joints `terms` is eliminated: the
/// lowest common ancestor of the terms' bodies, when it is a moving body that is no term's
/// child (every term's child is then eliminated before it, so its pivot holds each term's
/// free motion); `None` otherwise (a term on the world or on a loop joint).
fn late_parent(joints: &[Joint], parent_joint: &[Option<usize>], terms: &[usize]) -> Option<usize> {
    let up = |b: usize| parent_joint[b].map_or(0, |j| joints[j].parent);
    let path = |mut b: usize| {
        let mut p = vec![b];
        while b != 0 {
            b = up(b);
            p.push(b);
        }
        p
    };
    if terms.iter().any(|&j| joints[j].is_loop) {
        return None;
    }
    let mut common = path(joints[*terms.first()?].parent);
    for &j in terms {
        for b in [joints[j].parent, joints[j].child] {
            let p = path(b);
            common.retain(|a| p.contains(a));
        }
    }
    let lca = *common.first()?;
    (lca != 0 && terms.iter().all(|&j| joints[j].child != lca)).then_some(lca)
}

/// Post-order of the node tree (children before parents), each coupling or tendon limit of
/// `late` (node, term joints) just before the body below which all its terms lie
/// ([`late_parent`]: it then fills in between its terms' bodies and that body alone, where
/// eliminated last it filled in along the whole path to the root, and the humanoid's two
/// hamstring tendons with each other); loop joints and the late nodes over the world last.
fn elimination_order(
    nmoving: usize,
    joints: &[Joint],
    parent_joint: &[Option<usize>],
    joint_node: &[Option<usize>],
    nnodes: usize,
    leaves: &[usize],
    late: &[(usize, Vec<usize>)],
) -> Vec<usize> {
    let mut before: Vec<Vec<usize>> = vec![Vec::new(); nnodes];
    let mut last = Vec::new();
    for (n, terms) in late {
        match late_parent(joints, parent_joint, terms).and_then(body_node) {
            Some(b) => before[b].push(*n),
            None => last.push(*n),
        }
    }
    let late: Vec<usize> = late.iter().map(|&(n, _)| n).collect();
    // parent node of every node in the elimination tree (None = root)
    let mut up: Vec<Option<usize>> = vec![None; nnodes];
    for b in 1..=nmoving {
        if let Some(j) = parent_joint[b] {
            up[b - 1] = joint_node[j].or_else(|| body_node(joints[j].parent));
        }
    }
    let mut loops = Vec::new();
    for (j, joint) in joints.iter().enumerate() {
        if let Some(n) = joint_node[j] {
            if joint.is_loop {
                loops.push(n);
            } else {
                up[n] = body_node(joint.parent);
            }
        }
    }
    let mut children: Vec<Vec<usize>> = vec![Vec::new(); nnodes];
    let mut roots = Vec::new();
    for (n, parent) in up.iter().enumerate() {
        if loops.contains(&n) || leaves.contains(&n) || late.contains(&n) {
            continue;
        }
        match *parent {
            Some(p) => children[p].push(n),
            None => roots.push(n),
        }
    }
    let mut order = Vec::with_capacity(nnodes);
    // iterative post-order DFS (deep chains must not overflow the stack)
    for r in roots {
        let mut stack = vec![(r, 0usize)];
        while let Some((n, i)) = stack.pop() {
            if i < children[n].len() {
                stack.push((n, i + 1));
                stack.push((children[n][i], 0));
            } else {
                order.extend(&before[n]);
                order.push(n);
            }
        }
    }
    order.extend(loops);
    order.extend(last);
    order
}

#[cfg(test)]
mod tests {
    use super::body_node;

    /// A parallel gripper on a three-link arm: two finger slides on the hand, held symmetric by
    /// a joint equality (a coupling node), a motor on one finger.
    const GRIPPER: &str = r#"<mujoco><option gravity="0 0 -9.81" timestep="0.01"/><worldbody>
      <body name="l1"><joint name="j1" type="hinge" axis="0 0 1"/>
        <inertial pos=".15 0 0" mass="1" diaginertia=".01 .01 .01"/>
        <body name="l2" pos=".3 0 0"><joint name="j2" type="hinge" axis="0 1 0"/>
          <inertial pos=".15 0 0" mass="1" diaginertia=".01 .01 .01"/>
          <body name="hand" pos=".3 0 0"><joint name="j3" type="hinge" axis="1 0 0"/>
            <inertial pos="0 0 0" mass=".5" diaginertia=".001 .001 .001"/>
            <body name="f1" pos="0 .02 0"><joint name="x" type="slide" axis="0 1 0"/>
              <inertial pos="0 0 0" mass=".05" diaginertia="1e-5 1e-5 1e-5"/></body>
            <body name="f2" pos="0 -.02 0"><joint name="y" type="slide" axis="0 -1 0"/>
              <inertial pos="0 0 0" mass=".05" diaginertia="1e-5 1e-5 1e-5"/></body>
          </body></body></body></worldbody>
      <equality><joint joint1="y" joint2="x"/></equality>
      <actuator><motor joint="x"/></actuator></mujoco>"#;

    /// The finger coupling is eliminated just before the hand: it fills in with the hand alone,
    /// not with the arm's links and joints on the way to the root (as when it came last).
    #[test]
    fn a_finger_coupling_fills_in_below_the_hand_only() {
        let m = crate::mjcf::load_str(GRIPPER, "gripper").unwrap().model;
        let t = &m.topology;
        let c = t.coupling_node[0];
        let body = |name: &str| body_node(m.body_id(name).unwrap()).unwrap();
        let joint = |name: &str| t.joint_node[m.joint_id(name).unwrap()].unwrap();
        for n in [body("f1"), body("f2"), body("hand")] {
            assert!(t.pattern.block(c, n).is_some(), "node {n}");
        }
        for n in [
            body("l1"),
            body("l2"),
            joint("j1"),
            joint("j2"),
            joint("j3"),
        ] {
            assert!(t.pattern.block(c, n).is_none(), "fill with node {n}");
        }
    }

    /// The gripper's coupling holds while the arm swings under gravity and a finger is driven
    /// (the coupling's pivot, taken before the hand's, holds the fingers' free motion).
    #[test]
    fn a_finger_coupling_holds_on_a_swinging_arm() {
        let m = crate::mjcf::load_str(GRIPPER, "gripper").unwrap().model;
        let mut s = crate::State::reference(&m);
        let q0 = crate::qpos(&m, &s);
        let mut qv = vec![0.0; m.nv];
        qv[..3].copy_from_slice(&[1.0, -0.5, 2.0]);
        crate::set_minimal(&m, &mut s, &q0, &qv).unwrap();
        let mut ws = crate::Workspace::new(&m);
        let (x, y) = (m.joint_id("x").unwrap(), m.joint_id("y").unwrap());
        let (ax, ay) = (m.joints[x].qpos_adr, m.joints[y].qpos_adr);
        for k in 0..100 {
            let r = crate::step(&m, &mut s, &mut ws, &[0.2 * (0.1 * k as f64).sin()]).unwrap();
            assert!(r.status.is_success(), "step {k}: {r:?}");
            let q = crate::qpos(&m, &s);
            assert!(
                (q[ay] - q[ax]).abs() < 1e-9,
                "step {k}: {} vs {}",
                q[ay],
                q[ax]
            );
        }
        let q = crate::qpos(&m, &s);
        assert!(q[ax].abs() > 1e-3, "the fingers did not move: {}", q[ax]);
    }
}
