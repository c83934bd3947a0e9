//! Model construction and validation: [`ModelBuilder::compile`] is the only way to a [`Model`].
use nalgebra::{Matrix3, Vector3};

use super::transmission::{
    CouplingSpec, PassiveTendonSpec, TendonLimitSpec, TransmissionSpec, compile_couplings,
    compile_passive_tendons, compile_tendon_limits, compile_transmission,
};
use super::{Actuator, Body, Model, Options, Topology};
use crate::contact::geometry::{self, Shape};
use crate::contact::{Contact, ContactModel, Geom};
use crate::joints::geometry::{JointFrame, Pose};
use crate::joints::{Joint, JointKind, RotDofs};
use crate::math::quat;
use crate::math::spatial::basis_from_axis;
use crate::{Error, Result, ensure};

/// A rigid body to add. Positions and orientation are the body frame's world pose at the
/// reference configuration.
#[derive(Clone, Debug)]
pub struct BodySpec {
    /// Unique name.
    pub name: String,
    /// Mass (kg), > 0.
    pub mass: f64,
    /// Inertia about the COM, body frame (kg·m²): symmetric positive definite.
    pub inertia: Matrix3<f64>,
    /// COM in the body frame (m). Default 0.
    pub com: Vector3<f64>,
    /// Body frame origin, world (m).
    pub pos: Vector3<f64>,
    /// Body orientation `(w, x, y, z)`, unit.
    pub quat: [f64; 4],
    /// Gravity compensation (MuJoCo's `gravcomp`): the share of the body's weight cancelled by
    /// an upward force at its COM. Default 0.
    pub gravcomp: f64,
}

impl BodySpec {
    /// A body with principal moments `inertia` (kg·m²) at the origin.
    pub fn new(name: &str, mass: f64, inertia: [f64; 3]) -> Self {
        BodySpec {
            name: name.to_string(),
            mass,
            inertia: Matrix3::from_diagonal(&Vector3::from(inertia)),
            com: Vector3::zeros(),
            pos: Vector3::zeros(),
            quat: [1.0, 0.0, 0.0, 0.0],
            gravcomp: 0.0,
        }
    }
    /// Gravity compensation: the share of the body's weight an upward force at its COM
    /// cancels (MuJoCo's `gravcomp`; 1 floats the body).
    pub fn gravcomp(mut self, share: f64) -> Self {
        self.gravcomp = share;
        self
    }
    /// Full 3×3 inertia about the COM, body frame.
    pub fn inertia_matrix(mut self, inertia: Matrix3<f64>) -> Self {
        self.inertia = inertia;
        self
    }
    /// Reference position of the body frame (m).
    pub fn pos(mut self, pos: [f64; 3]) -> Self {
        self.pos = Vector3::from(pos);
        self
    }
    /// Reference orientation `(w, x, y, z)`.
    pub fn quat(mut self, quat: [f64; 4]) -> Self {
        self.quat = quat;
        self
    }
    /// COM offset in the body frame (m).
    pub fn com(mut self, com: [f64; 3]) -> Self {
        self.com = Vector3::from(com);
        self
    }
}

/// A joint to add. Anchors are in the parent's and child's body frames (for the world: world
/// coordinates); `axis` is in the child's body frame (MuJoCo's convention).
#[derive(Clone, Debug)]
pub struct JointSpec {
    /// Unique name.
    pub name: String,
    /// Kind.
    pub kind: JointKind,
    /// Parent body name (`"world"` for the ground).
    pub parent: String,
    /// Child body name.
    pub child: String,
    /// Joint axis, child body frame; normalised at compile. Default z.
    pub axis: Vector3<f64>,
    /// Anchor in the parent body frame (m).
    pub parent_anchor: Vector3<f64>,
    /// Anchor in the child body frame (m).
    pub child_anchor: Vector3<f64>,
    /// Stiffness: one value for every free dof, or one per dof.
    pub stiffness: Vec<f64>,
    /// Damping: one value for every free dof, or one per dof.
    pub damping: Vec<f64>,
    /// Spring rest position in `qpos` units (default: the reference configuration).
    pub spring_ref: Option<Vec<f64>>,
    /// Per free dof `(lower, upper)` limits.
    pub range: Option<Vec<(f64, f64)>>,
    /// This joint closes a kinematic loop (it is not part of the spanning tree).
    pub is_loop: bool,
    /// Explicit free translation axes (child body frame), in `qpos` order; their number must be
    /// the kind's. Empty: derived from `axis` ([`JointKind::frame`]). Used for MJCF bodies with
    /// several slide joints (MuJoCo's dof order).
    pub trans_axes: Vec<Vector3<f64>>,
    /// Explicit hinge axes in sequence (child body frame), 1-3 of them, possibly non-orthogonal;
    /// their number must be the kind's number of rotations (3 gives three hinges instead of a
    /// ball). Empty: derived from `axis`. Used for MJCF bodies with several hinge joints.
    pub rot_axes: Vec<Vector3<f64>>,
    /// `qpos` of the reference configuration per scalar coordinate (MuJoCo's `ref`); empty: 0.
    pub qpos_ref: Vec<f64>,
    /// Rotor inertia (MuJoCo's `armature`): one value for every free dof, or one per dof.
    pub armature: Vec<f64>,
    /// Dry friction (MuJoCo's `frictionloss`, N or N·m): one value for every free dof, or one
    /// per dof.
    pub frictionloss: Vec<f64>,
    /// Hinges about different anchors (MuJoCo's sequential joints): `p_{i+1} - p_i` for each
    /// consecutive pair of the `rot_axes` hinges, child body frame (m). `child_anchor` (and
    /// `parent_anchor`) are the first hinge's anchor. Empty: all hinges turn about one point.
    pub hinge_offsets: Vec<Vector3<f64>>,
}

impl JointSpec {
    /// A joint of `kind` between `parent` and `child` with axis z and anchors at the body origins.
    pub fn new(name: &str, kind: JointKind, parent: &str, child: &str) -> Self {
        JointSpec {
            name: name.to_string(),
            kind,
            parent: parent.to_string(),
            child: child.to_string(),
            axis: Vector3::z(),
            parent_anchor: Vector3::zeros(),
            child_anchor: Vector3::zeros(),
            stiffness: vec![0.0],
            damping: vec![0.0],
            spring_ref: None,
            range: None,
            is_loop: false,
            trans_axes: vec![],
            rot_axes: vec![],
            qpos_ref: vec![],
            armature: vec![],
            frictionloss: vec![],
            hinge_offsets: vec![],
        }
    }
    /// Axis in the child body frame.
    pub fn axis(mut self, axis: [f64; 3]) -> Self {
        self.axis = Vector3::from(axis);
        self
    }
    /// Anchors in the parent and child body frames.
    pub fn anchors(mut self, parent: [f64; 3], child: [f64; 3]) -> Self {
        self.parent_anchor = Vector3::from(parent);
        self.child_anchor = Vector3::from(child);
        self
    }
    /// Spring stiffness (all free dofs).
    pub fn stiffness(mut self, k: f64) -> Self {
        self.stiffness = vec![k];
        self
    }
    /// Damping (all free dofs).
    pub fn damping(mut self, d: f64) -> Self {
        self.damping = vec![d];
        self
    }
    /// Dry friction (all free dofs): the joint resists motion with up to this force or torque.
    pub fn frictionloss(mut self, f: f64) -> Self {
        self.frictionloss = vec![f];
        self
    }
    /// Spring rest position in `qpos` units.
    pub fn spring_ref(mut self, q: Vec<f64>) -> Self {
        self.spring_ref = Some(q);
        self
    }
    /// Mark as loop-closing.
    pub fn closing_loop(mut self) -> Self {
        self.is_loop = true;
        self
    }
}

/// An actuator to add: generalized force `gear · (gain · ctrl + bias₀ + bias₁ · gear · q +
/// bias₂ · gear · q̇)` on free dof `dof` of `joint` (MuJoCo's affine `general` actuator with a joint
/// transmission). A motor has `gain = 1`, `bias = 0`; a position servo `gain = kp`,
/// `bias = [0, -kp, -kv]`; a velocity servo `gain = kv`, `bias = [0, 0, -kv]`.
#[derive(Clone, Debug)]
pub struct ActuatorSpec {
    /// Unique name.
    pub name: String,
    /// Joint name.
    pub joint: String,
    /// Free dof of the joint (0-based).
    pub dof: usize,
    /// Gear ratio.
    pub gear: f64,
    /// Control clamp.
    pub ctrlrange: Option<(f64, f64)>,
    /// Gain on the control (1 for a motor).
    pub gain: f64,
    /// Bias terms: constant, per unit of actuator length `gear·q`, per unit of its rate.
    pub bias: [f64; 3],
    /// Clamp of the scalar actuator force (MuJoCo's `forcerange`), if any.
    pub forcerange: Option<(f64, f64)>,
    /// Clamp of the generalized force `gear · F` on the joint dof, after `forcerange` (MuJoCo's
    /// joint `actuatorfrcrange` where this actuator alone drives the dof); joint
    /// transmissions only.
    pub joint_forcerange: Option<(f64, f64)>,
    /// Where the force acts (default: `joint`'s dof `dof`).
    pub transmission: TransmissionSpec,
}

impl ActuatorSpec {
    /// A motor: force `gear · clamp(ctrl)` on dof `dof` of `joint`.
    pub fn motor(name: &str, joint: &str, dof: usize, gear: f64) -> Self {
        ActuatorSpec {
            name: name.to_string(),
            joint: joint.to_string(),
            dof,
            gear,
            ctrlrange: None,
            gain: 1.0,
            bias: [0.0; 3],
            forcerange: None,
            joint_forcerange: None,
            transmission: TransmissionSpec::Joint,
        }
    }
}

/// A collision geometry to add, posed in its body's frame.
#[derive(Clone, Debug)]
pub struct GeomSpec {
    /// Unique name.
    pub name: String,
    /// Body name (`"world"` for static geometry such as the floor).
    pub body: String,
    /// Shape and sizes (m).
    pub shape: Shape,
    /// Geom origin in the body frame (m).
    pub pos: Vector3<f64>,
    /// Geom orientation in the body frame `(w, x, y, z)`.
    pub quat: [f64; 4],
    /// Coulomb friction coefficient (≥ 0). Default 0.5.
    pub friction: f64,
    /// Contact model; `None` makes the geom visual only. Default nonlinear.
    pub model: Option<ContactModel>,
    /// MuJoCo's `contype` bits. Default 1.
    pub contype: u32,
    /// MuJoCo's `conaffinity` bits. Default 1.
    pub conaffinity: u32,
}

impl GeomSpec {
    /// A geom of `shape` on `body` at the body origin, friction 0.5, nonlinear cone.
    pub fn new(name: &str, body: &str, shape: Shape) -> Self {
        GeomSpec {
            name: name.to_string(),
            body: body.to_string(),
            shape,
            pos: Vector3::zeros(),
            quat: [1.0, 0.0, 0.0, 0.0],
            friction: 0.5,
            model: Some(ContactModel::Nonlinear),
            contype: 1,
            conaffinity: 1,
        }
    }
    /// Position in the body frame.
    pub fn pos(mut self, pos: [f64; 3]) -> Self {
        self.pos = Vector3::from(pos);
        self
    }
    /// Orientation in the body frame.
    pub fn quat(mut self, quat: [f64; 4]) -> Self {
        self.quat = quat;
        self
    }
    /// Friction coefficient.
    pub fn friction(mut self, mu: f64) -> Self {
        self.friction = mu;
        self
    }
    /// Contact model (`None`: never collides).
    pub fn model(mut self, model: Option<ContactModel>) -> Self {
        self.model = model;
        self
    }
}

/// An explicit contact pair (MuJoCo's `contact/pair`): the two geoms collide with this
/// friction and contact model whatever their bit masks, bodies and exclusions say, and in
/// place of the pair those rules would make.
#[derive(Clone, Debug)]
pub struct PairSpec {
    /// First geom's name.
    pub geom_a: String,
    /// Second geom's name.
    pub geom_b: String,
    /// Coulomb friction coefficient (≥ 0).
    pub friction: f64,
    /// Contact model (frictionless where `friction` is 0).
    pub model: ContactModel,
}

/// Builds and validates a [`Model`].
#[derive(Clone, Debug, Default)]
pub struct ModelBuilder {
    /// Options (time step, gravity, solver).
    pub options: Options,
    bodies: Vec<BodySpec>,
    joints: Vec<JointSpec>,
    actuators: Vec<ActuatorSpec>,
    geoms: Vec<GeomSpec>,
    excludes: Vec<(String, String)>,
    geom_excludes: Vec<(String, String)>,
    pairs: Vec<PairSpec>,
    condim_max: bool,
    couplings: Vec<CouplingSpec>,
    tendon_limits: Vec<TendonLimitSpec>,
    passive_tendons: Vec<PassiveTendonSpec>,
}

impl ModelBuilder {
    /// Empty builder with default options.
    pub fn new() -> Self {
        Self::default()
    }
    /// Set the time step (s).
    pub fn timestep(mut self, h: f64) -> Self {
        self.options.timestep = h;
        self
    }
    /// Set gravity (m/s²).
    pub fn gravity(mut self, g: [f64; 3]) -> Self {
        self.options.gravity = Vector3::from(g);
        self
    }
    /// Add a body (fluent).
    pub fn body(mut self, b: BodySpec) -> Self {
        self.bodies.push(b);
        self
    }
    /// Add a joint (fluent).
    pub fn joint(mut self, j: JointSpec) -> Self {
        self.joints.push(j);
        self
    }
    /// Add an actuator (fluent).
    pub fn actuator(mut self, a: ActuatorSpec) -> Self {
        self.actuators.push(a);
        self
    }
    /// Add a body.
    pub fn add_body(&mut self, b: BodySpec) {
        self.bodies.push(b);
    }
    /// Add a joint.
    pub fn add_joint(&mut self, j: JointSpec) {
        self.joints.push(j);
    }
    /// How many actuators have been added.
    pub fn actuator_count(&self) -> usize {
        self.actuators.len()
    }
    /// Add an actuator.
    pub fn add_actuator(&mut self, a: ActuatorSpec) {
        self.actuators.push(a);
    }
    /// Add a joint coupling (MuJoCo's `equality/joint`).
    pub fn add_coupling(&mut self, c: CouplingSpec) {
        self.couplings.push(c);
    }
    /// Add a fixed-tendon limit (MuJoCo's limited `<tendon><fixed>`).
    pub fn add_tendon_limit(&mut self, t: TendonLimitSpec) {
        self.tendon_limits.push(t);
    }
    /// Add a collision geometry (fluent).
    pub fn geom(mut self, g: GeomSpec) -> Self {
        self.geoms.push(g);
        self
    }
    /// Add a collision geometry.
    pub fn add_geom(&mut self, g: GeomSpec) {
        self.geoms.push(g);
    }
    /// Never collide the geoms of these two bodies (MuJoCo's `contact/exclude`).
    pub fn add_exclude(&mut self, body_a: &str, body_b: &str) {
        self.excludes.push((body_a.to_string(), body_b.to_string()));
    }

    /// Never collide these two geoms (used by the MJCF loader for shape pairs without a
    /// collision kernel, each reported as a warning).
    pub fn add_geom_exclude(&mut self, geom_a: &str, geom_b: &str) {
        self.geom_excludes
            .push((geom_a.to_string(), geom_b.to_string()));
    }
    /// Add a passive fixed tendon (a spring and a damper on a tendon length).
    pub fn add_passive_tendon(&mut self, t: PassiveTendonSpec) {
        self.passive_tendons.push(t);
    }
    /// Whether a geom of this name has been added.
    pub fn has_geom(&self, name: &str) -> bool {
        self.geoms.iter().any(|g| g.name == name)
    }
    /// Collide two geoms explicitly (MuJoCo's `contact/pair`, see [`PairSpec`]).
    pub fn add_pair(&mut self, p: PairSpec) {
        self.pairs.push(p);
    }
    /// MuJoCo's pair rule: a pair is frictionless only if *both* geoms ask for
    /// [`ContactModel::Impact`] (MuJoCo's `condim = max`), instead of either.
    pub fn set_condim_max(&mut self, on: bool) {
        self.condim_max = on;
    }

    /// Validate everything and compile the immutable model.
    pub fn compile(&self) -> Result<Model> {
        self.options.validate()?;
        let bodies = self.compile_bodies()?;
        let names: Vec<&str> = bodies.iter().map(|b| b.name.as_str()).collect();
        let mut joints = Vec::with_capacity(self.joints.len());
        for (i, spec) in self.joints.iter().enumerate() {
            ensure!(
                !self.joints[..i].iter().any(|o| o.name == spec.name),
                Error::model(
                    format!("joint[{}].name", spec.name),
                    &spec.name,
                    "duplicate joint name"
                )
            );
            joints.push(compile_joint(spec, &names, &bodies)?);
        }
        let parent_joint = spanning_tree(&bodies, &joints)?;
        assign_addresses(&mut joints);
        let geoms = self.compile_geoms(&names, &bodies)?;
        let contacts = self.compile_pairs(&geoms, &joints, &bodies, &names)?;
        let couplings = compile_couplings(&self.couplings, &joints)?;
        let tendon_limits = compile_tendon_limits(&self.tendon_limits, &joints)?;
        let passive_tendons = compile_passive_tendons(&self.passive_tendons, &joints)?;
        let actuators = self.compile_actuators(&joints, &bodies)?;
        let topology = Topology::new(
            bodies.len(),
            &joints,
            &parent_joint,
            &geoms,
            &contacts,
            &couplings,
            &tendon_limits,
            (&actuators, &passive_tendons),
        )
        .map_err(|e| Error::model("joints", "graph", e))?;
        let nq = joints.iter().filter(|j| !j.is_loop).map(Joint::nq).sum();
        let nv = joints.iter().filter(|j| !j.is_loop).map(Joint::nfree).sum();
        let mut model = Model {
            options: self.options.clone(),
            bodies,
            joints,
            actuators,
            couplings,
            tendon_limits,
            passive_tendons,
            geoms,
            contacts,
            nq,
            nv,
            qpos0: vec![],
            keyframes: vec![],
            topology,
        };
        let reference = crate::State::reference(&model);
        model.qpos0 = crate::joints::coordinates::qpos(&model, &reference);
        for j in 0..model.joints.len() {
            if model.joints[j].spring_ref.is_empty() {
                let frame = joint_frame_at_reference(&model.joints[j], &model.bodies);
                let mut c = vec![0.0; model.joints[j].nq()];
                frame.coordinates(&model.joints[j], &mut c);
                model.joints[j].spring_ref = c;
            }
        }
        Ok(model)
    }

    fn compile_bodies(&self) -> Result<Vec<Body>> {
        let world = Body {
            name: "world".into(),
            mass: 0.0,
            inertia: Matrix3::zeros(),
            com: Vector3::zeros(),
            ref_pose: Pose::world(),
            gravcomp: 0.0,
        };
        let mut out = vec![world];
        for spec in &self.bodies {
            let f = |field: &str| format!("body[{}].{field}", spec.name);
            ensure!(
                !spec.name.is_empty(),
                Error::model("body.name", "", "must not be empty")
            );
            ensure!(
                !out.iter().any(|b| b.name == spec.name),
                Error::model(
                    f("name"),
                    &spec.name,
                    "duplicate body name (\"world\" is reserved)"
                )
            );
            ensure!(
                spec.mass.is_finite() && spec.mass > 0.0,
                Error::model(f("mass"), spec.mass, "must be finite and > 0")
            );
            check_inertia(&spec.inertia, &f("inertia"))?;
            check_finite(spec.pos.as_slice(), &f("pos"))?;
            check_finite(spec.com.as_slice(), &f("com"))?;
            check_unit_quat(&spec.quat, &f("quat"))?;
            check_finite(&[spec.gravcomp], &f("gravcomp"))?;
            let q = quat::from_wxyz(&spec.quat);
            out.push(Body {
                name: spec.name.clone(),
                mass: spec.mass,
                inertia: spec.inertia,
                com: spec.com,
                ref_pose: Pose {
                    pos: spec.pos + quat::rotation(&q) * spec.com,
                    quat: q,
                },
                gravcomp: spec.gravcomp,
            });
        }
        Ok(out)
    }

    fn compile_geoms(&self, names: &[&str], bodies: &[Body]) -> Result<Vec<Geom>> {
        let mut out: Vec<Geom> = Vec::with_capacity(self.geoms.len());
        for spec in &self.geoms {
            let f = |field: &str| format!("geom[{}].{field}", spec.name);
            ensure!(
                !out.iter().any(|g| g.name == spec.name),
                Error::model(f("name"), &spec.name, "duplicate geom name")
            );
            let body = names
                .iter()
                .position(|n| *n == spec.body)
                .ok_or_else(|| Error::model(f("body"), &spec.body, "unknown body"))?;
            check_shape(&spec.shape, &f("size"))?;
            check_finite(spec.pos.as_slice(), &f("pos"))?;
            check_unit_quat(&spec.quat, &f("quat"))?;
            ensure!(
                spec.friction.is_finite() && spec.friction >= 0.0,
                Error::model(f("friction"), spec.friction, "must be finite and >= 0")
            );
            let com = bodies[body].com;
            out.push(Geom {
                name: spec.name.clone(),
                body,
                shape: spec.shape.clone(),
                pos: spec.pos - com,
                rot: quat::rotation(&quat::from_wxyz(&spec.quat)),
                friction: spec.friction,
                model: spec.model,
                contype: spec.contype,
                conaffinity: spec.conaffinity,
            });
        }
        Ok(out)
    }

    /// MuJoCo's pair rules: different bodies, not both static, not joined by a joint (unless one
    /// is the world), not excluded, and `contype & conaffinity` matching one way or the other.
    fn compile_pairs(
        &self,
        geoms: &[Geom],
        joints: &[Joint],
        bodies: &[Body],
        names: &[&str],
    ) -> Result<Vec<Contact>> {
        let mut excluded = Vec::new();
        for (a, b) in &self.excludes {
            let find = |n: &String| {
                names
                    .iter()
                    .position(|x| x == n)
                    .ok_or_else(|| Error::model("exclude", n, "unknown body"))
            };
            excluded.push((find(a)?, find(b)?));
        }
        // parent-child filtering, except against the world (MuJoCo's filterparent)
        let linked = |a: usize, b: usize| {
            (a != 0
                && b != 0
                && joints
                    .iter()
                    .any(|j| (j.parent == a && j.child == b) || (j.parent == b && j.child == a)))
                || excluded
                    .iter()
                    .any(|&(x, y)| (x == a && y == b) || (x == b && y == a))
        };
        // explicit pairs first, then the pairs the rules make, less those named explicitly
        let mut explicit = Vec::with_capacity(self.pairs.len());
        for (k, p) in self.pairs.iter().enumerate() {
            let f = |field: &str| format!("pair[{k}].{field}");
            let find = |n: &String, field: &str| {
                geoms
                    .iter()
                    .position(|g| g.name == *n)
                    .ok_or_else(|| Error::model(f(field), n, "unknown geom"))
            };
            let (a, b) = (find(&p.geom_a, "geom_a")?, find(&p.geom_b, "geom_b")?);
            ensure!(
                p.friction.is_finite() && p.friction >= 0.0,
                Error::model(f("friction"), p.friction, "must be finite and >= 0")
            );
            ensure!(
                geoms[a].body != geoms[b].body,
                Error::model(
                    f("geom_b"),
                    &p.geom_b,
                    format!("is on the body of geom {:?}", p.geom_a)
                )
            );
            explicit.push(((a.min(b), a.max(b)), p));
        }
        let mut out = Vec::new();
        for &((i, j), p) in &explicit {
            let model = pair_model(p.model, p.model, p.friction);
            add_candidates(&mut out, (geoms, joints, bodies), (i, j), p.friction, model)?;
        }
        for i in 0..geoms.len() {
            for j in i + 1..geoms.len() {
                let (ga, gb) = (&geoms[i], &geoms[j]);
                let (Some(ma), Some(mb)) = (ga.model, gb.model) else {
                    continue;
                };
                let pair_excluded = self.geom_excludes.iter().any(|(x, y)| {
                    (*x == ga.name && *y == gb.name) || (*x == gb.name && *y == ga.name)
                });
                if pair_excluded || explicit.iter().any(|e| e.0 == (i, j)) {
                    continue;
                }
                let affinity =
                    (ga.contype & gb.conaffinity) != 0 || (gb.contype & ga.conaffinity) != 0;
                if ga.body == gb.body
                    || (ga.body == 0 && gb.body == 0)
                    || !affinity
                    || linked(ga.body, gb.body)
                {
                    continue;
                }
                let friction = ga.friction.max(gb.friction);
                let model = if self.condim_max
                    && (ma == ContactModel::Impact) != (mb == ContactModel::Impact)
                {
                    let other = if ma == ContactModel::Impact { mb } else { ma };
                    pair_model(other, other, friction)
                } else {
                    pair_model(ma, mb, friction)
                };
                add_candidates(&mut out, (geoms, joints, bodies), (i, j), friction, model)?;
            }
        }
        // box pairs' edge-crossing slots last (each pair's consecutive): most are empty at any
        // step, and the solver's loops skip runs of inactive candidates as a whole
        let (mut kept, slots): (Vec<Contact>, Vec<Contact>) =
            out.into_iter().partition(|c| !c.feature.is_crossing_slot());
        kept.extend(slots);
        Ok(kept)
    }

    fn compile_actuators(&self, joints: &[Joint], bodies: &[Body]) -> Result<Vec<Actuator>> {
        let mut out: Vec<Actuator> = Vec::new();
        for spec in &self.actuators {
            let f = |field: &str| format!("actuator[{}].{field}", spec.name);
            ensure!(
                !out.iter().any(|a| a.name == spec.name),
                Error::model(f("name"), &spec.name, "duplicate actuator name")
            );
            let transmission = compile_transmission(spec, joints, bodies, &f)?;
            ensure!(
                spec.gear.is_finite(),
                Error::model(f("gear"), spec.gear, "must be finite")
            );
            ensure!(
                spec.gain.is_finite() && spec.bias.iter().all(|b| b.is_finite()),
                Error::model(f("gain/bias"), (spec.gain, spec.bias), "must be finite")
            );
            if let Some((lo, hi)) = spec.ctrlrange {
                ensure!(
                    lo.is_finite() && hi.is_finite() && lo < hi,
                    Error::model(f("ctrlrange"), (lo, hi), "need finite lower < upper")
                );
            }
            for (field, range) in [
                ("forcerange", spec.forcerange),
                ("joint_forcerange", spec.joint_forcerange),
            ] {
                if let Some((lo, hi)) = range {
                    ensure!(
                        !lo.is_nan() && !hi.is_nan() && lo <= hi,
                        Error::model(f(field), (lo, hi), "need lower <= upper")
                    );
                }
            }
            ensure!(
                spec.joint_forcerange.is_none()
                    || matches!(transmission, crate::model::Transmission::Joint { .. }),
                Error::model(
                    f("joint_forcerange"),
                    format!("{:?}", spec.joint_forcerange),
                    "applies to joint transmissions only"
                )
            );
            out.push(Actuator {
                name: spec.name.clone(),
                transmission,
                gear: spec.gear,
                ctrlrange: spec.ctrlrange,
                forcerange: spec.forcerange,
                joint_forcerange: spec.joint_forcerange,
                gain: spec.gain,
                bias: spec.bias,
            });
        }
        Ok(out)
    }
}

/// The contact candidates of geoms `i` and `j` with this friction and contact model.
fn add_candidates(
    out: &mut Vec<Contact>,
    (geoms, joints, bodies): (&[Geom], &[Joint], &[Body]),
    (i, j): (usize, usize),
    friction: f64,
    model: ContactModel,
) -> Result<()> {
    let (ga, gb) = (&geoms[i], &geoms[j]);
    let (features, swapped) = geometry::candidates(&ga.shape, &gb.shape).map_err(|e| {
        Error::Unsupported(format!(
            "contact between geom[{}] and geom[{}]: {e}",
            ga.name, gb.name
        ))
    })?;
    let (a, b) = if swapped { (j, i) } else { (i, j) };
    let slide_axes = crate::contact::slide_pair::slide_axis(joints, geoms[a].body, geoms[b].body)
        .map(|[ax, bx]| [geoms[a].rot.transpose() * ax, geoms[b].rot.transpose() * bx]);
    let slide_limits =
        crate::contact::slide_pair::slide_limits(joints, geoms[a].body, geoms[b].body)
            .map(std::sync::Arc::from);
    // a slide pair of aligned boxes whose edges can never cross needs no crossing slots (the
    // shared Panda's 25 finger-pad pairs: their 200 empty slots cost it ~15% a step)
    let never_cross = match (&geoms[a].shape, &geoms[b].shape, slide_axes) {
        (Shape::Box { half_extents: ha }, Shape::Box { half_extents: hb }, Some([axis, _])) => {
            let (wa, wb) = (
                geoms[a].world_pose(&bodies[geoms[a].body].ref_pose),
                geoms[b].world_pose(&bodies[geoms[b].body].ref_pose),
            );
            let s = (wa.rot * axis).normalize();
            geometry::box_edges::slide_pair_never_crosses(ha, &wa, hb, &wb, &s)
        }
        _ => false,
    };
    let features = features
        .into_iter()
        .filter(|f| !(never_cross && f.is_crossing_slot()));
    out.extend(features.into_iter().map(|feature| Contact {
        geom_a: a,
        geom_b: b,
        feature,
        model,
        friction,
        slide_axes,
        slide_limits: slide_limits.clone(),
    }));
    Ok(())
}

/// Frictionless if either geom asks for impact or the pair's friction is 0, else linear if either
/// asks for the pyramid, else the nonlinear cone.
fn pair_model(a: ContactModel, b: ContactModel, friction: f64) -> ContactModel {
    use ContactModel::*;
    if a == Impact || b == Impact || friction == 0.0 {
        Impact
    } else if a == Linear || b == Linear {
        Linear
    } else {
        Nonlinear
    }
}

fn check_shape(shape: &Shape, field: &str) -> Result<()> {
    // (a mesh's hull was checked when it was built: it has no sizes)
    let sizes = shape.sizes();
    ensure!(
        sizes.iter().all(|x| x.is_finite() && *x > 0.0),
        Error::model(field, &sizes, "sizes must be finite and > 0")
    );
    Ok(())
}

fn check_finite(v: &[f64], field: &str) -> Result<()> {
    ensure!(
        v.iter().all(|x| x.is_finite()),
        Error::model(field, v, "must be finite")
    );
    Ok(())
}

fn check_unit_quat(q: &[f64; 4], field: &str) -> Result<()> {
    check_finite(q, field)?;
    let n = q.iter().map(|x| x * x).sum::<f64>().sqrt();
    ensure!(
        (n - 1.0).abs() <= 1e-6,
        Error::model(
            field,
            q,
            format!("quaternion must have unit norm (norm {n})")
        )
    );
    Ok(())
}

fn check_inertia(m: &Matrix3<f64>, field: &str) -> Result<()> {
    let rows: Vec<[f64; 3]> = (0..3).map(|i| [m[(i, 0)], m[(i, 1)], m[(i, 2)]]).collect();
    check_finite(m.as_slice(), field)?;
    let scale = m.abs().max().max(1e-300);
    ensure!(
        (m - m.transpose()).abs().max() <= 1e-9 * scale,
        Error::model(field, &rows, "inertia must be symmetric")
    );
    let eig = m.symmetric_eigenvalues();
    ensure!(
        eig.iter().all(|&e| e > 0.0),
        Error::model(
            field,
            &rows,
            format!(
                "inertia must be positive definite (eigenvalues {:?})",
                eig.as_slice()
            )
        )
    );
    let (a, b, c) = (eig[0], eig[1], eig[2]);
    let tol = 1e-9 * (a + b + c);
    ensure!(
        a + b + tol >= c && a + c + tol >= b && b + c + tol >= a,
        Error::model(
            field,
            &rows,
            format!(
                "principal moments {:?} violate the triangle inequality A + B >= C",
                eig.as_slice()
            )
        )
    );
    Ok(())
}

fn broadcast(v: &[f64], n: usize, field: &str) -> Result<Vec<f64>> {
    check_finite(v, field)?;
    ensure!(
        v.iter().all(|&x| x >= 0.0),
        Error::model(field, v, "must be >= 0")
    );
    match v.len() {
        1 => Ok(vec![v[0]; n]),
        len if len == n => Ok(v.to_vec()),
        _ => Err(Error::model(
            field,
            v,
            format!("need 1 or {n} values (one per free dof)"),
        )),
    }
}

fn compile_joint(spec: &JointSpec, names: &[&str], bodies: &[Body]) -> Result<Joint> {
    let f = |field: &str| format!("joint[{}].{field}", spec.name);
    ensure!(
        !spec.name.is_empty(),
        Error::model("joint.name", "", "must not be empty")
    );
    let find = |name: &str, field: &str| {
        names
            .iter()
            .position(|n| *n == name)
            .ok_or_else(|| Error::model(f(field), name, "unknown body"))
    };
    let (parent, child) = (find(&spec.parent, "parent")?, find(&spec.child, "child")?);
    ensure!(
        parent != child,
        Error::model(f("child"), &spec.child, "parent and child must differ")
    );
    ensure!(
        child != 0 || spec.is_loop,
        Error::model(
            f("child"),
            &spec.child,
            "the world can be a child only of a loop joint"
        )
    );
    check_finite(spec.axis.as_slice(), &f("axis"))?;
    let norm = spec.axis.norm();
    ensure!(
        norm > 1e-9,
        Error::model(
            f("axis"),
            spec.axis.as_slice(),
            "axis must have non-zero length"
        )
    );
    check_finite(spec.parent_anchor.as_slice(), &f("parent_anchor"))?;
    check_finite(spec.child_anchor.as_slice(), &f("child_anchor"))?;
    let (pb, cb) = (&bodies[parent], &bodies[child]);
    // The axis is given in the child body frame; the joint frame is the child's reference frame,
    // which has the same orientation, so the axis is used as is.
    let (trans_basis, trans_dual, rot) = joint_axes(spec, &(spec.axis / norm))?;
    let floating =
        spec.kind == JointKind::Floating && spec.trans_axes.is_empty() && spec.rot_axes.is_empty();
    // Floating joints (MuJoCo's free joint) measure the child body frame's pose in the parent
    // body frame: no orientation offset, anchors at the body frame origins.
    let (pa, ca) = if floating {
        (Vector3::zeros(), Vector3::zeros())
    } else {
        (spec.parent_anchor, spec.child_anchor)
    };
    let offset = if floating {
        quat::identity()
    } else {
        quat::conj(&pb.ref_pose.quat) * cb.ref_pose.quat
    };
    let nfree = spec.kind.ntrans() + spec.kind.nrot();
    let mut joint = Joint {
        name: spec.name.clone(),
        kind: spec.kind,
        parent,
        child,
        parent_anchor: pa - pb.com,
        // with offset hinges the child side is anchored at the last hinge (joints::offsets)
        child_anchor: ca + spec.hinge_offsets.iter().sum::<Vector3<f64>>() - cb.com,
        offset,
        trans_basis,
        trans_dual,
        ntrans: spec.kind.ntrans(),
        rot,
        is_loop: spec.is_loop,
        limits: compile_limits(spec, nfree)?,
        stiffness: broadcast(&spec.stiffness, nfree, &f("stiffness"))?,
        damping: broadcast(&spec.damping, nfree, &f("damping"))?,
        spring_ref: vec![],
        qpos_ref: vec![],
        armature: if spec.armature.is_empty() {
            vec![]
        } else {
            broadcast(&spec.armature, nfree, &f("armature"))?
        },
        frictionloss: match spec.frictionloss.is_empty() {
            true => vec![],
            false => broadcast(&spec.frictionloss, nfree, &f("frictionloss"))?,
        },
        hinge_offsets: hinge_offsets(spec)?,
        qpos_adr: 0,
        qvel_adr: 0,
    };
    if !spec.qpos_ref.is_empty() {
        check_finite(&spec.qpos_ref, &f("qpos_ref"))?;
        let quat_entries = (joint.ntrans..joint.nq()).filter(|_| joint.rot.nq() == 4);
        ensure!(
            spec.qpos_ref.len() == joint.nq()
                && quat_entries.clone().all(|i| spec.qpos_ref[i] == 0.0),
            Error::model(
                f("qpos_ref"),
                &spec.qpos_ref,
                format!(
                    "need {} values (qpos of the joint), 0 on quaternion entries",
                    joint.nq()
                )
            )
        );
        joint.qpos_ref = spec.qpos_ref.clone();
    }
    if let Some(r) = &spec.spring_ref {
        check_finite(r, &f("spring_ref"))?;
        ensure!(
            r.len() == joint.nq(),
            Error::model(
                f("spring_ref"),
                r,
                format!("need {} values (qpos of the joint)", joint.nq())
            )
        );
        let mut r = r.clone();
        if matches!(joint.rot, RotDofs::Ball) {
            let q = &mut r[joint.ntrans..];
            let n = q.iter().map(|x| x * x).sum::<f64>().sqrt();
            ensure!(
                n > 1e-9,
                Error::model(f("spring_ref"), &r, "rest quaternion must be non-zero")
            );
            q.iter_mut().for_each(|x| *x /= n);
        }
        joint.spring_ref = r;
    }
    // The anchors must coincide along every constrained direction at the reference pose.
    let mut k = vec![0.0; joint.ncon()];
    joint_frame_at_reference(&joint, bodies).constraint(&joint, &mut k);
    let gap = k.iter().fold(0.0f64, |m, x| m.max(x.abs()));
    ensure!(
        gap <= 1e-6,
        Error::model(
            f("anchors"),
            (spec.parent_anchor.as_slice(), spec.child_anchor.as_slice()),
            format!(
                "constraint violated by {gap:.3e} at the reference pose: anchors or body poses disagree"
            )
        )
    );
    Ok(joint)
}

/// Validated hinge offsets: one per consecutive pair of explicit hinge axes, finite; all-zero
/// offsets are dropped (one common anchor).
fn hinge_offsets(spec: &JointSpec) -> Result<Vec<Vector3<f64>>> {
    let field = format!("joint[{}].hinge_offsets", spec.name);
    if spec.hinge_offsets.iter().all(|d| d.norm() == 0.0) {
        return Ok(vec![]);
    }
    for d in &spec.hinge_offsets {
        check_finite(d.as_slice(), &field)?;
    }
    let n = spec.rot_axes.len();
    ensure!(
        n >= 2 && spec.hinge_offsets.len() == n - 1,
        Error::model(
            &field,
            spec.hinge_offsets.len(),
            format!(
                "need one offset per consecutive pair of the {n} explicit hinge axes (rot_axes)"
            )
        )
    );
    Ok(spec.hinge_offsets.clone())
}

/// Limits on every free dof (one `(lower, upper)` pair each); ball rotations cannot be limited.
fn compile_limits(spec: &JointSpec, nfree: usize) -> Result<Vec<(usize, f64, f64)>> {
    let Some(range) = &spec.range else {
        return Ok(vec![]);
    };
    let field = format!("joint[{}].range", spec.name);
    ensure!(
        range.len() == nfree,
        Error::model(
            &field,
            range,
            format!("need one (lower, upper) pair per free dof ({nfree})")
        )
    );
    ensure!(
        spec.kind.nrot() < 3 || spec.rot_axes.len() == 3,
        Error::Unsupported(format!(
            "{field}: limits on ball rotations (quaternion coordinates) are not supported"
        ))
    );
    // (-inf, inf) leaves a dof unlimited (a composite MJCF joint may limit only some dofs)
    let unlimited = |lo: f64, hi: f64| lo == f64::NEG_INFINITY && hi == f64::INFINITY;
    for &(lo, hi) in range {
        ensure!(
            unlimited(lo, hi) || (lo.is_finite() && hi.is_finite() && lo < hi),
            Error::model(&field, range, "need finite lower < upper")
        );
    }
    Ok(range
        .iter()
        .enumerate()
        .filter(|(_, (lo, hi))| !unlimited(*lo, *hi))
        .map(|(i, &(lo, hi))| (i, lo, hi))
        .collect())
}

/// Unit axes of `axes`, each finite and non-zero.
fn unit_axes(axes: &[Vector3<f64>], field: &str) -> Result<Vec<Vector3<f64>>> {
    axes.iter()
        .map(|a| {
            check_finite(a.as_slice(), field)?;
            let n = a.norm();
            ensure!(
                n > 1e-9,
                Error::model(field, a.as_slice(), "axis must have non-zero length")
            );
            Ok(a / n)
        })
        .collect()
}

/// Translational basis, its dual (inverse transpose) and the rotational dofs of a joint: from
/// the kind and `axis`, or from the explicit axes of the spec.
fn joint_axes(
    spec: &JointSpec,
    axis: &Vector3<f64>,
) -> Result<(Matrix3<f64>, Matrix3<f64>, RotDofs)> {
    let f = |field: &str| format!("joint[{}].{field}", spec.name);
    let (mut basis, mut rot) = spec.kind.frame(axis);
    let mut dual = basis;
    if !spec.trans_axes.is_empty() {
        let field = f("trans_axes");
        ensure!(
            spec.trans_axes.len() == spec.kind.ntrans(),
            Error::model(
                &field,
                spec.trans_axes.len(),
                format!(
                    "kind {} needs {} axes",
                    spec.kind.name(),
                    spec.kind.ntrans()
                )
            )
        );
        let mut cols = unit_axes(&spec.trans_axes, &field)?;
        match cols.len() {
            1 => {
                let m = basis_from_axis(&cols[0]);
                cols.extend([m.column(1).into_owned(), m.column(2).into_owned()]);
            }
            2 => cols.push(cols[0].cross(&cols[1]).normalize()),
            _ => {}
        }
        basis = Matrix3::from_columns(&cols);
        let inv = basis
            .try_inverse()
            .filter(|_| basis.determinant().abs() > 1e-9);
        dual = inv
            .ok_or_else(|| {
                Error::model(
                    &field,
                    &spec.trans_axes,
                    "slide axes must be linearly independent",
                )
            })?
            .transpose();
    }
    if !spec.rot_axes.is_empty() {
        let field = f("rot_axes");
        let n = spec.rot_axes.len();
        ensure!(
            n == spec.kind.nrot(),
            Error::model(
                &field,
                n,
                format!("kind {} needs {} axes", spec.kind.name(), spec.kind.nrot())
            )
        );
        let a = unit_axes(&spec.rot_axes, &field)?;
        ensure!(
            a.windows(2).all(|w| w[0].cross(&w[1]).norm() > 1e-6),
            Error::model(
                &field,
                &spec.rot_axes,
                "consecutive hinge axes must not be parallel"
            )
        );
        rot = match n {
            1 => {
                let m = basis_from_axis(&a[0]);
                RotDofs::Hinge {
                    axis: a[0],
                    perp: [m.column(1).into_owned(), m.column(2).into_owned()],
                }
            }
            2 => RotDofs::Universal { a1: a[0], a2: a[1] },
            _ => RotDofs::Hinges3 {
                axes: [a[0], a[1], a[2]],
            },
        };
    }
    Ok((basis, dual, rot))
}

fn joint_frame_at_reference(joint: &Joint, bodies: &[Body]) -> JointFrame {
    JointFrame::new(
        joint,
        &bodies[joint.parent].ref_pose,
        &bodies[joint.child].ref_pose,
    )
}

/// Each moving body must be the child of exactly one tree joint, and following parent joints
/// from any body must reach the world.
pub(super) fn spanning_tree(bodies: &[Body], joints: &[Joint]) -> Result<Vec<Option<usize>>> {
    let mut parent_joint: Vec<Option<usize>> = vec![None; bodies.len()];
    for (j, joint) in joints.iter().enumerate().filter(|(_, j)| !j.is_loop) {
        if let Some(other) = parent_joint[joint.child] {
            return Err(Error::model(
                format!("joint[{}].child", joint.name),
                &bodies[joint.child].name,
                format!(
                    "body is already the child of joint '{}'; declare one of them as a loop joint",
                    joints[other].name
                ),
            ));
        }
        parent_joint[joint.child] = Some(j);
    }
    for (b, body) in bodies.iter().enumerate().skip(1) {
        ensure!(
            parent_joint[b].is_some(),
            Error::model(
                format!("body[{}]", body.name),
                &body.name,
                "body has no joint: add a 'floating' joint to make it free or a 'fixed' joint to weld it"
            )
        );
    }
    for b in 1..bodies.len() {
        // walk up: more than nbody steps means a cycle
        let (mut cur, mut steps, mut path) = (b, 0, Vec::new());
        while cur != 0 {
            let j = parent_joint[cur].unwrap_or(0);
            path.push(joints[j].name.clone());
            cur = joints[j].parent;
            steps += 1;
            ensure!(
                steps <= bodies.len(),
                Error::model(
                    "joints",
                    &path[path.len().saturating_sub(bodies.len())..],
                    "these joints form a cycle that is not declared as a loop (set loop=True on one)"
                )
            );
        }
    }
    Ok(parent_joint)
}

fn assign_addresses(joints: &mut [Joint]) {
    let (mut qa, mut va) = (0, 0);
    for j in joints.iter_mut().filter(|j| !j.is_loop) {
        j.qpos_adr = qa;
        j.qvel_adr = va;
        qa += j.nq();
        va += j.nfree();
    }
}
