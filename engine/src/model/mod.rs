//! The model: compiled once by [`ModelBuilder::compile`], then immutable (MuJoCo's `mjModel`,
//! Drake's finalized plant). Per-rollout data lives in [`crate::State`].
mod builder;
mod options;
pub(crate) mod params;
mod topology;
mod transmission;

pub use builder::{ActuatorSpec, BodySpec, GeomSpec, JointSpec, ModelBuilder, PairSpec};
pub use options::Options;
pub(crate) use topology::Topology;
pub(crate) use topology::body_node as topology_body_node;
pub use transmission::{
    CouplingSpec, PassiveTendonSpec, TendonLimitSpec, Transmission, TransmissionSpec,
};

use nalgebra::{Matrix3, Vector3};

use crate::contact::{Contact, Geom};
use crate::joints::Joint;
use crate::joints::coupling::Coupling;
use crate::joints::geometry::Pose;
use crate::joints::tendon::TendonLimit;

/// A rigid body. Body 0 is the world.
#[derive(Clone, Debug)]
pub struct Body {
    /// Unique name (`"world"` for body 0).
    pub name: String,
    /// Mass (kg); 0 for the world.
    pub mass: f64,
    /// Inertia about the COM in the body frame (kg·m²), symmetric positive definite.
    pub inertia: Matrix3<f64>,
    /// COM position in the body frame (m).
    pub com: Vector3<f64>,
    /// COM pose at the reference configuration.
    pub ref_pose: Pose,
    /// Gravity compensation (MuJoCo's `gravcomp`): an upward force `gravcomp · m g` at the COM
    /// cancels that share of the body's weight (1: it floats).
    pub gravcomp: f64,
}

/// An actuator: a scalar force `F = clamp(gain · clamp(ctrl) + bias₀ + bias₁ L + bias₂ L̇,
/// forcerange)` (`L = gear · length` of the transmission), applied as `gear · F` on a joint dof,
/// `gear · coef_i · F` on each dof of a fixed tendon, or as a site wrench (MuJoCo's affine
/// `general` actuator; `gain = 1`, `bias = 0`: a motor).
#[derive(Clone, Debug)]
pub struct Actuator {
    /// Unique name.
    pub name: String,
    /// Where the force acts.
    pub transmission: Transmission,
    /// Gear ratio (joint and tendon transmissions; the first gear entry for sites).
    pub gear: f64,
    /// Control clamp, if any.
    pub ctrlrange: Option<(f64, f64)>,
    /// Clamp of the scalar force `F` (N or N·m), if any (MuJoCo's `forcerange`).
    pub forcerange: Option<(f64, f64)>,
    /// Clamp of its generalized force `gear · F` on its joint dof, applied after `forcerange`
    /// (MuJoCo's joint `actuatorfrcrange`, which clamps the total actuator force on a dof:
    /// the same where this actuator alone drives it). Joint transmissions only.
    pub joint_forcerange: Option<(f64, f64)>,
    /// Gain on the control.
    pub gain: f64,
    /// Bias: constant, per unit of `gear·q`, per unit of `gear·q̇` (position/velocity servos).
    pub bias: [f64; 3],
}

impl Actuator {
    /// Whether the force depends on the joint state (a servo), not only on the control.
    pub fn has_bias(&self) -> bool {
        self.bias[1] != 0.0 || self.bias[2] != 0.0
    }
}

/// A named configuration (MJCF `keyframe/key`): minimal coordinates and controls.
#[derive(Clone, Debug, Default)]
pub struct Keyframe {
    /// Name (may be empty).
    pub name: String,
    /// Simulation time (s).
    pub time: f64,
    /// Positions, length `nq`.
    pub qpos: Vec<f64>,
    /// Velocities, length `nv`.
    pub qvel: Vec<f64>,
    /// Controls, length `nu`.
    pub ctrl: Vec<f64>,
}

/// Compiled, immutable model.
#[derive(Clone, Debug)]
pub struct Model {
    /// Options (time step, gravity, solver settings).
    pub options: Options,
    /// Bodies, world first.
    pub bodies: Vec<Body>,
    /// Joints, in declaration order (`qpos`/`qvel` follow it; loop joints have none).
    pub joints: Vec<Joint>,
    /// Actuators, in declaration order (`ctrl` follows it).
    pub actuators: Vec<Actuator>,
    /// Joint couplings (MuJoCo's `equality/joint`), solved with the joints.
    pub couplings: Vec<Coupling>,
    /// Fixed-tendon limits, solved as inequality constraints with the contacts.
    pub tendon_limits: Vec<TendonLimit>,
    /// Passive fixed tendons (springs and dampers on tendon lengths).
    pub passive_tendons: Vec<crate::joints::tendon::PassiveTendon>,
    /// Collision geometries.
    pub geoms: Vec<Geom>,
    /// Contact candidates, decided at compile time.
    pub contacts: Vec<Contact>,
    /// Number of position coordinates.
    pub nq: usize,
    /// Number of velocity coordinates.
    pub nv: usize,
    /// `qpos` of the reference configuration.
    pub qpos0: Vec<f64>,
    /// Named configurations (MJCF keyframes); empty for models built in code.
    pub keyframes: Vec<Keyframe>,
    pub(crate) topology: Topology,
}

impl Model {
    /// The impulse the moving bodies' weight delivers in one step, `Σ m g h` (N·s): the scale
    /// of a step's contact impulses.
    pub fn weight_impulse(&self) -> f64 {
        let mass: f64 = self.bodies.iter().skip(1).map(|b| b.mass).sum();
        mass * self.options.gravity.norm() * self.options.timestep
    }

    /// Number of bodies including the world.
    pub fn nbody(&self) -> usize {
        self.bodies.len()
    }
    /// Number of joints (tree and loop).
    pub fn njoint(&self) -> usize {
        self.joints.len()
    }
    /// Number of actuators (length of `ctrl`).
    pub fn nu(&self) -> usize {
        self.actuators.len()
    }
    /// Total number of joint constraint rows (joint impulse unknowns).
    pub fn ncon(&self) -> usize {
        self.topology.ncon
    }
    /// Time step (s).
    pub fn timestep(&self) -> f64 {
        self.options.timestep
    }
    /// Index of a body by name.
    pub fn body_id(&self, name: &str) -> Option<usize> {
        self.bodies.iter().position(|b| b.name == name)
    }
    /// Index of a joint by name.
    pub fn joint_id(&self, name: &str) -> Option<usize> {
        self.joints.iter().position(|j| j.name == name)
    }
    /// The same model with other options (validated). Topology and parameters are shared.
    pub fn with_options(&self, options: Options) -> crate::Result<Model> {
        options.validate()?;
        let mut m = self.clone();
        m.options = options;
        Ok(m)
    }
    /// The same model with the contact candidates of friction model `from` modelled as `to`
    /// (the topology recompiled: its states do not carry over, see
    /// [`crate::State::moved_to`]).
    pub fn with_contact_model(
        &self,
        from: crate::contact::ContactModel,
        to: crate::contact::ContactModel,
    ) -> crate::Result<Model> {
        let mut m = self.clone();
        for c in m.contacts.iter_mut().filter(|c| c.model == from) {
            c.model = to;
        }
        let parent_joint = builder::spanning_tree(&m.bodies, &m.joints)?;
        m.topology = Topology::new(
            m.bodies.len(),
            &m.joints,
            &parent_joint,
            &m.geoms,
            &m.contacts,
            &m.couplings,
            &m.tendon_limits,
            (&m.actuators, &m.passive_tendons),
        )
        .map_err(|e| crate::Error::model("joints", "graph", e))?;
        Ok(m)
    }
    /// Number of contact candidates.
    pub fn ncontact(&self) -> usize {
        self.contacts.len()
    }
    /// Number of limited joint dofs.
    pub fn nlimit(&self) -> usize {
        self.joints.iter().map(|j| j.limits.len()).sum()
    }
    /// Number of joint dofs with dry friction (`frictionloss`).
    pub fn nfriction(&self) -> usize {
        self.joints.iter().map(|j| j.nfriction()).sum()
    }
    /// Number of passive tendons with dry friction.
    pub fn ntendon_friction(&self) -> usize {
        self.passive_tendons
            .iter()
            .filter(|t| t.frictionloss > 0.0)
            .count()
    }
    /// Unknowns of one step per effect: `(name, count)` for body velocities, joint impulses, limit
    /// variables, contact variables of each model, tendon-limit and joint-friction variables.
    /// Effects a scene
    /// does not use count 0.
    pub fn variable_counts(&self) -> Vec<(&'static str, usize)> {
        use crate::contact::ContactModel::*;
        let per = |m| {
            self.contacts
                .iter()
                .filter(|c| c.model == m)
                .map(|c| c.model.dim())
                .sum::<usize>()
        };
        vec![
            ("body_velocity", 6 * (self.nbody() - 1)),
            ("joint_impulse", self.ncon()),
            ("joint_limit", 4 * self.nlimit()),
            ("contact_impact", per(Impact)),
            ("contact_nonlinear_cone", per(Nonlinear)),
            ("contact_linear_cone", per(Linear)),
            ("tendon_limit", 4 * self.tendon_limits.len()),
            ("joint_friction", 4 * self.nfriction()),
            ("tendon_friction", 4 * self.ntendon_friction()),
        ]
    }
    /// What node `n` of the Newton matrix's graph is, for messages: a body, a joint, a joint's
    /// limits, a coupling, a tendon limit or a contact candidate (with the names).
    pub fn node_name(&self, n: usize) -> String {
        let t = &self.topology;
        if n + 1 < self.nbody() {
            return format!("body '{}'", self.bodies[n + 1].name);
        }
        if let Some(j) = t.joint_node.iter().position(|&x| x == Some(n)) {
            return format!("joint '{}'", self.joints[j].name);
        }
        if let Some(j) = t.limit_node.iter().position(|&x| x == Some(n)) {
            return format!("the limits of joint '{}'", self.joints[j].name);
        }
        if let Some(c) = t.contact_node.iter().position(|&x| x == n) {
            let ct = &self.contacts[c];
            let (a, b) = (&self.geoms[ct.geom_a].name, &self.geoms[ct.geom_b].name);
            return format!("contact candidate {c} ('{a}' / '{b}')");
        }
        if let Some(k) = t.coupling_node.iter().position(|&x| x == n) {
            return format!("joint coupling {k}");
        }
        if let Some(k) = t.tendon_node.iter().position(|&x| x == n) {
            return format!("tendon limit {k}");
        }
        if let Some(j) = t.friction_node.iter().position(|&x| x == Some(n)) {
            return format!("the dry friction of joint '{}'", self.joints[j].name);
        }
        if let Some(k) = t.tendon_friction_node.iter().position(|&x| x == Some(n)) {
            return format!(
                "the dry friction of tendon '{}'",
                self.passive_tendons[k].name
            );
        }
        format!("node {n}")
    }
    /// Identifier of the topology; a [`crate::State`] remembers it.
    pub fn topology_id(&self) -> u64 {
        self.topology.id
    }
}
