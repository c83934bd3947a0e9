//! Differentiable model parameters as one flat vector (`model.params` in Python).
//!
//! The vector lists, in this order: body masses and inertias (6 unique entries of each moving
//! body's COM inertia, body frame: xx yy zz xy xz yz), geom friction, geom sizes and offsets,
//! joint spring stiffness, damping and armature per free dof, joint dry friction
//! (`frictionloss`) per dof compiled with it, passive tendons' stiffness, damping and dry
//! friction (the last for tendons compiled with it), actuators' gear, gain and bias (constant,
//! per length, per rate: MuJoCo's `gear`, `gainprm[0]`, `biasprm[0..3]`; a site actuator's
//! constant only), gravity, and the time step. Names follow
//! `group[element]` or `group[element][component]`, e.g. `body_mass[torso]`,
//! `geom_size[ball][0]`, `joint_damping[hip][1]`, `joint_frictionloss[knee][0]`,
//! `tendon_stiffness[split]`, `gravity[z]`. Setting the vector never changes the topology
//! (contact candidates, graph, the dry-friction nodes), so states stay valid for the new model:
//! a dry friction compiled in stays > 0 (a model without it is compiled without its node).
use super::{Model, Transmission};
use crate::contact::geometry::Shape;
use crate::{Error, Result, ensure};

const AXES: [&str; 3] = ["x", "y", "z"];
const INERTIA: [(&str, usize, usize); 6] = [
    ("xx", 0, 0),
    ("yy", 1, 1),
    ("zz", 2, 2),
    ("xy", 0, 1),
    ("xz", 0, 2),
    ("yz", 1, 2),
];

/// Where one parameter lives.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) enum Param {
    Mass(usize),
    Inertia(usize, usize, usize),
    Friction(usize),
    Size(usize, usize),
    GeomPos(usize, usize),
    Stiffness(usize, usize),
    Damping(usize, usize),
    Armature(usize, usize),
    /// (joint, free dof) of a dof compiled with dry friction
    FrictionLoss(usize, usize),
    TendonStiffness(usize),
    TendonDamping(usize),
    /// a passive tendon compiled with dry friction
    TendonFriction(usize),
    ActuatorGear(usize),
    ActuatorGain(usize),
    /// (actuator, k): bias term k (constant, per length, per rate; the last two not for site
    /// transmissions, whose servo biases the loaders reject)
    ActuatorBias(usize, usize),
    Gravity(usize),
    Timestep,
}

fn set_shape_size(shape: &mut Shape, i: usize, v: f64) {
    match shape {
        Shape::Plane | Shape::Point | Shape::Mesh { .. } => {}
        Shape::Sphere { radius } => *radius = v,
        Shape::Capsule {
            radius,
            half_length,
        }
        | Shape::Cylinder {
            radius,
            half_length,
        } => *(if i == 0 { radius } else { half_length }) = v,
        Shape::Box { half_extents } => half_extents[i] = v,
        Shape::Ellipsoid { radii } => radii[i] = v,
    }
}

impl Model {
    /// The parameter layout: one entry per differentiable parameter.
    pub(crate) fn param_layout(&self) -> Vec<Param> {
        let mut p = Vec::new();
        for b in 1..self.nbody() {
            p.push(Param::Mass(b));
        }
        for b in 1..self.nbody() {
            p.extend(INERTIA.iter().map(|&(_, i, k)| Param::Inertia(b, i, k)));
        }
        let colliding = |g: usize| self.contacts.iter().any(|c| c.geom_a == g || c.geom_b == g);
        for g in (0..self.geoms.len()).filter(|&g| colliding(g)) {
            p.push(Param::Friction(g));
        }
        for g in (0..self.geoms.len()).filter(|&g| colliding(g)) {
            let n = self.geoms[g].shape.sizes().len();
            p.extend((0..n).map(|i| Param::Size(g, i)));
            p.extend((0..3).map(|i| Param::GeomPos(g, i)));
        }
        for (j, joint) in self.joints.iter().enumerate() {
            p.extend((0..joint.nfree()).map(|d| Param::Stiffness(j, d)));
        }
        for (j, joint) in self.joints.iter().enumerate() {
            p.extend((0..joint.nfree()).map(|d| Param::Damping(j, d)));
        }
        for (j, joint) in self.joints.iter().enumerate() {
            p.extend((0..joint.nfree()).map(|d| Param::Armature(j, d)));
        }
        for (j, joint) in self.joints.iter().enumerate() {
            p.extend(
                joint
                    .friction_dofs()
                    .map(|(d, _)| Param::FrictionLoss(j, d)),
            );
        }
        let tendons = 0..self.passive_tendons.len();
        p.extend(tendons.clone().map(Param::TendonStiffness));
        p.extend(tendons.clone().map(Param::TendonDamping));
        p.extend(
            tendons
                .filter(|&k| self.passive_tendons[k].frictionloss > 0.0)
                .map(Param::TendonFriction),
        );
        let actuators = 0..self.actuators.len();
        p.extend(actuators.clone().map(Param::ActuatorGear));
        p.extend(actuators.clone().map(Param::ActuatorGain));
        for a in actuators {
            let site = matches!(self.actuators[a].transmission, Transmission::Site { .. });
            let n = if site { 1 } else { 3 };
            p.extend((0..n).map(|k| Param::ActuatorBias(a, k)));
        }
        p.extend((0..3).map(Param::Gravity));
        p.push(Param::Timestep);
        p
    }

    /// Names of [`Model::params`], one per entry.
    pub fn param_names(&self) -> Vec<String> {
        self.param_layout()
            .into_iter()
            .map(|p| match p {
                Param::Mass(b) => format!("body_mass[{}]", self.bodies[b].name),
                Param::Inertia(b, i, k) => {
                    let c = INERTIA
                        .iter()
                        .find(|e| e.1 == i && e.2 == k)
                        .map_or("", |e| e.0);
                    format!("body_inertia[{}][{c}]", self.bodies[b].name)
                }
                Param::Friction(g) => format!("geom_friction[{}]", self.geoms[g].name),
                Param::Size(g, i) => format!("geom_size[{}][{i}]", self.geoms[g].name),
                Param::GeomPos(g, i) => format!("geom_pos[{}][{}]", self.geoms[g].name, AXES[i]),
                Param::Stiffness(j, d) => format!("joint_stiffness[{}][{d}]", self.joints[j].name),
                Param::Damping(j, d) => format!("joint_damping[{}][{d}]", self.joints[j].name),
                Param::Armature(j, d) => format!("joint_armature[{}][{d}]", self.joints[j].name),
                Param::FrictionLoss(j, d) => {
                    format!("joint_frictionloss[{}][{d}]", self.joints[j].name)
                }
                Param::TendonStiffness(k) => {
                    format!("tendon_stiffness[{}]", self.passive_tendons[k].name)
                }
                Param::TendonDamping(k) => {
                    format!("tendon_damping[{}]", self.passive_tendons[k].name)
                }
                Param::TendonFriction(k) => {
                    format!("tendon_frictionloss[{}]", self.passive_tendons[k].name)
                }
                Param::ActuatorGear(a) => format!("actuator_gear[{}]", self.actuators[a].name),
                Param::ActuatorGain(a) => format!("actuator_gain[{}]", self.actuators[a].name),
                Param::ActuatorBias(a, k) => {
                    format!("actuator_bias[{}][{k}]", self.actuators[a].name)
                }
                Param::Gravity(i) => format!("gravity[{}]", AXES[i]),
                Param::Timestep => "timestep".to_string(),
            })
            .collect()
    }

    /// Current parameter values (see the module docs for the layout).
    pub fn params(&self) -> Vec<f64> {
        self.param_layout()
            .into_iter()
            .map(|p| self.param(p))
            .collect()
    }

    pub(crate) fn param(&self, p: Param) -> f64 {
        match p {
            Param::Mass(b) => self.bodies[b].mass,
            Param::Inertia(b, i, k) => self.bodies[b].inertia[(i, k)],
            Param::Friction(g) => self.geoms[g].friction,
            Param::Size(g, i) => self.geoms[g].shape.sizes()[i],
            Param::GeomPos(g, i) => self.geoms[g].pos[i],
            Param::Stiffness(j, d) => self.joints[j].stiffness[d],
            Param::Damping(j, d) => self.joints[j].damping[d],
            Param::Armature(j, d) => self.joints[j].armature.get(d).copied().unwrap_or(0.0),
            Param::FrictionLoss(j, d) => self.joints[j].frictionloss[d],
            Param::TendonStiffness(k) => self.passive_tendons[k].stiffness,
            Param::TendonDamping(k) => self.passive_tendons[k].damping,
            Param::TendonFriction(k) => self.passive_tendons[k].frictionloss,
            Param::ActuatorGear(a) => self.actuators[a].gear,
            Param::ActuatorGain(a) => self.actuators[a].gain,
            Param::ActuatorBias(a, k) => self.actuators[a].bias[k],
            Param::Gravity(i) => self.options.gravity[i],
            Param::Timestep => self.options.timestep,
        }
    }

    /// Set one parameter in place, keeping derived data (pair friction) consistent. No
    /// validation: callers perturb valid values slightly or go through [`Model::with_params`].
    pub(crate) fn set_param(&mut self, p: Param, v: f64) {
        match p {
            Param::Mass(b) => self.bodies[b].mass = v,
            Param::Inertia(b, i, k) => {
                self.bodies[b].inertia[(i, k)] = v;
                self.bodies[b].inertia[(k, i)] = v;
            }
            Param::Friction(g) => {
                self.geoms[g].friction = v;
                for c in self
                    .contacts
                    .iter_mut()
                    .filter(|c| c.geom_a == g || c.geom_b == g)
                {
                    c.friction = self.geoms[c.geom_a]
                        .friction
                        .max(self.geoms[c.geom_b].friction);
                }
            }
            Param::Size(g, i) => set_shape_size(&mut self.geoms[g].shape, i, v),
            Param::GeomPos(g, i) => self.geoms[g].pos[i] = v,
            Param::Stiffness(j, d) => self.joints[j].stiffness[d] = v,
            Param::Damping(j, d) => self.joints[j].damping[d] = v,
            Param::Armature(j, d) => {
                // (empty means none: filled with zeros on the first value set)
                let joint = &mut self.joints[j];
                let n = joint.nfree();
                joint.armature.resize(n, 0.0);
                joint.armature[d] = v;
            }
            Param::FrictionLoss(j, d) => self.joints[j].frictionloss[d] = v,
            Param::TendonStiffness(k) => self.passive_tendons[k].stiffness = v,
            Param::TendonDamping(k) => self.passive_tendons[k].damping = v,
            Param::TendonFriction(k) => self.passive_tendons[k].frictionloss = v,
            Param::ActuatorGear(a) => self.actuators[a].gear = v,
            Param::ActuatorGain(a) => self.actuators[a].gain = v,
            Param::ActuatorBias(a, k) => self.actuators[a].bias[k] = v,
            Param::Gravity(i) => self.options.gravity[i] = v,
            Param::Timestep => self.options.timestep = v,
        }
    }

    /// The same model with new parameter values (validated; the topology is shared, so states
    /// made for `self` work with the result).
    pub fn with_params(&self, params: &[f64]) -> Result<Model> {
        let layout = self.param_layout();
        ensure!(
            params.len() == layout.len(),
            Error::shape("params", &[layout.len()], &[params.len()])
        );
        let names = self.param_names();
        let mut m = self.clone();
        for (i, (&p, &v)) in layout.iter().zip(params).enumerate() {
            ensure!(
                v.is_finite(),
                Error::input(format!("params[{i}] ({})", names[i]), v, "must be finite")
            );
            // (a dry friction compiled in has its node in the topology: it stays > 0)
            let positive = matches!(
                p,
                Param::Mass(_)
                    | Param::Size(..)
                    | Param::Timestep
                    | Param::FrictionLoss(..)
                    | Param::TendonFriction(_)
            );
            let nonneg = matches!(
                p,
                Param::Friction(_)
                    | Param::Stiffness(..)
                    | Param::Damping(..)
                    | Param::Armature(..)
                    | Param::TendonStiffness(_)
                    | Param::TendonDamping(_)
            );
            ensure!(
                !(positive && v <= 0.0 || nonneg && v < 0.0),
                Error::input(
                    format!("params[{i}] ({})", names[i]),
                    v,
                    if positive {
                        "must be > 0"
                    } else {
                        "must be >= 0"
                    }
                )
            );
            m.set_param(p, v);
        }
        for b in 1..m.nbody() {
            let eig = m.bodies[b].inertia.symmetric_eigenvalues();
            ensure!(
                eig.iter().all(|&e| e > 0.0),
                Error::input(
                    format!("params (body_inertia[{}])", m.bodies[b].name),
                    eig.as_slice(),
                    "inertia must be positive definite"
                )
            );
        }
        m.options.validate()?;
        Ok(m)
    }
}

#[cfg(test)]
mod tests {
    use crate::contact::geometry::Shape;
    use crate::{BodySpec, GeomSpec, JointKind, JointSpec, ModelBuilder};

    fn model() -> crate::Model {
        ModelBuilder::new()
            .body(BodySpec::new("ball", 2.0, [0.1, 0.2, 0.3]).pos([0.0, 0.0, 1.0]))
            .joint(JointSpec::new("free", JointKind::Floating, "world", "ball").damping(0.1))
            .geom(GeomSpec::new("floor", "world", Shape::Plane).friction(0.3))
            .geom(GeomSpec::new("ball", "ball", Shape::Sphere { radius: 0.1 }).friction(0.7))
            .compile()
            .unwrap()
    }

    #[test]
    fn params_round_trip_and_names_line_up() {
        let m = model();
        let (p, names) = (m.params(), m.param_names());
        assert_eq!(p.len(), names.len());
        let at = |n: &str| names.iter().position(|x| x == n).unwrap();
        assert_eq!(p[at("body_mass[ball]")], 2.0);
        assert_eq!(p[at("body_inertia[ball][yy]")], 0.2);
        assert_eq!(p[at("geom_size[ball][0]")], 0.1);
        assert_eq!(p[at("joint_damping[free][5]")], 0.1);
        // armature for every free dof (none compiled: zero); no dry friction compiled, none
        assert_eq!(p[at("joint_armature[free][2]")], 0.0);
        assert!(!names.iter().any(|n| n.starts_with("joint_frictionloss")));
        assert_eq!(p[at("gravity[z]")], -9.81);
        let mut q = p.clone();
        q[at("geom_friction[ball]")] = 0.9;
        q[at("body_inertia[ball][xy]")] = 0.01;
        let m2 = m.with_params(&q).unwrap();
        assert_eq!(m2.params(), q);
        assert_eq!(m2.contacts[0].friction, 0.9);
        assert_eq!(m2.bodies[1].inertia[(1, 0)], 0.01);
        assert_eq!(m2.topology_id(), m.topology_id());
    }

    #[test]
    fn with_params_rejects_bad_values_by_name() {
        let m = model();
        let names = m.param_names();
        let mut q = m.params();
        q[0] = -1.0;
        let e = m.with_params(&q).unwrap_err().to_string();
        assert!(e.contains("body_mass[ball]") && e.contains("-1"), "{e}");
        let i = names
            .iter()
            .position(|n| n == "body_inertia[ball][xy]")
            .unwrap();
        let mut q = m.params();
        q[i] = 1.0;
        assert!(m.with_params(&q).is_err());
        assert!(m.with_params(&[1.0]).is_err());
    }
}
