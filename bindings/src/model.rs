//! `ModelBuilder` and `Model` classes: thin wrappers over the engine's builder and compiled model.
use std::sync::{Arc, Mutex};

use nalgebra::{Matrix3, Vector3};
use numpy::{PyArray1, PyArray2, PyArrayMethods};
use pyo3::prelude::*;
use ukemi_engine::{
    ActuatorSpec, BodySpec, ContactModel, GeomSpec, JointKind, JointSpec, Model, ModelBuilder,
    Shape, State, Workspace,
};

use crate::errors::{IntoPy, ModelError, guard};
use crate::state::PyState;

/// Builds a model; the Python `ukemi.ModelBuilder` converts arguments and calls these methods.
#[pyclass(name = "_ModelBuilder", module = "ukemi._ukemi")]
pub struct PyModelBuilder {
    inner: ModelBuilder,
}

#[pymethods]
impl PyModelBuilder {
    #[new]
    fn new(timestep: f64, gravity: [f64; 3]) -> Self {
        PyModelBuilder {
            inner: ModelBuilder::new().timestep(timestep).gravity(gravity),
        }
    }

    #[allow(clippy::too_many_arguments)]
    #[allow(clippy::too_many_arguments)]
    #[pyo3(signature = (name, mass, inertia, pos, quat, com, gravcomp=0.0))]
    fn add_body(
        &mut self,
        name: String,
        mass: f64,
        inertia: [f64; 9],
        pos: [f64; 3],
        quat: [f64; 4],
        com: [f64; 3],
        gravcomp: f64,
    ) {
        let spec = BodySpec::new(&name, mass, [1.0; 3])
            .inertia_matrix(Matrix3::from_row_slice(&inertia))
            .pos(pos)
            .quat(quat)
            .com(com)
            .gravcomp(gravcomp);
        self.inner.add_body(spec);
    }

    #[allow(clippy::too_many_arguments)]
    fn add_joint(
        &mut self,
        name: String,
        kind: &str,
        parent: String,
        child: String,
        axis: [f64; 3],
        parent_anchor: [f64; 3],
        child_anchor: [f64; 3],
        stiffness: Vec<f64>,
        damping: Vec<f64>,
        spring_ref: Option<Vec<f64>>,
        range: Option<Vec<(f64, f64)>>,
        is_loop: bool,
        frictionloss: Vec<f64>,
    ) -> PyResult<()> {
        let kind = JointKind::from_name(kind).ok_or_else(|| {
            let names: Vec<&str> = JointKind::ALL.iter().map(|k| k.name()).collect();
            ModelError::new_err(format!("invalid model: `joint[{name}].kind` = {kind:?}: unknown joint kind; expected one of {names:?}"))
        })?;
        let mut spec = JointSpec::new(&name, kind, &parent, &child)
            .axis(axis)
            .anchors(parent_anchor, child_anchor);
        spec.stiffness = stiffness;
        spec.damping = damping;
        spec.spring_ref = spring_ref;
        spec.range = range;
        spec.is_loop = is_loop;
        spec.frictionloss = frictionloss;
        self.inner.add_joint(spec);
        Ok(())
    }

    #[allow(clippy::too_many_arguments)]
    #[pyo3(signature = (name, joint, dof, gear, ctrlrange, kp=0.0, kv=0.0, forcerange=None, actuatorfrcrange=None))]
    fn add_actuator(
        &mut self,
        name: String,
        joint: String,
        dof: usize,
        gear: f64,
        ctrlrange: Option<(f64, f64)>,
        kp: f64,
        kv: f64,
        forcerange: Option<(f64, f64)>,
        actuatorfrcrange: Option<(f64, f64)>,
    ) {
        let mut spec = ActuatorSpec::motor(&name, &joint, dof, gear);
        spec.ctrlrange = ctrlrange;
        spec.forcerange = forcerange;
        spec.joint_forcerange = actuatorfrcrange;
        // MuJoCo's shortcuts: a position servo `kp (u - L) - kv L̇`, a velocity servo
        // `kv (u - L̇)`, with `L = gear q`
        if kp != 0.0 {
            (spec.gain, spec.bias) = (kp, [0.0, -kp, -kv]);
        } else if kv != 0.0 {
            (spec.gain, spec.bias) = (kv, [0.0, 0.0, -kv]);
        }
        self.inner.add_actuator(spec);
    }

    #[allow(clippy::too_many_arguments)]
    fn add_geom(
        &mut self,
        name: String,
        body: String,
        shape: &str,
        size: Vec<f64>,
        pos: [f64; 3],
        quat: [f64; 4],
        friction: f64,
        contact: Option<&str>,
        contype: u32,
        conaffinity: u32,
        vertices: Option<Vec<[f64; 3]>>,
    ) -> PyResult<()> {
        let bad =
            |what: String| ModelError::new_err(format!("invalid model: `geom[{name}].{what}"));
        if vertices.is_some() && shape != "mesh" {
            return Err(bad(format!(
                "vertices`: apply to shape \"mesh\" only, not {shape:?}"
            )));
        }
        let need = |n: usize| -> PyResult<()> {
            if size.len() < n {
                return Err(bad(format!(
                    "size` = {size:?}: shape {shape:?} needs {n} size values"
                )));
            }
            Ok(())
        };
        let shape = match shape {
            "plane" => Shape::Plane,
            "point" => Shape::Point,
            "sphere" => {
                need(1)?;
                Shape::Sphere { radius: size[0] }
            }
            "capsule" => {
                need(2)?;
                Shape::Capsule {
                    radius: size[0],
                    half_length: size[1],
                }
            }
            "cylinder" => {
                need(2)?;
                Shape::Cylinder {
                    radius: size[0],
                    half_length: size[1],
                }
            }
            "box" => {
                need(3)?;
                Shape::Box {
                    half_extents: Vector3::new(size[0], size[1], size[2]),
                }
            }
            "ellipsoid" => {
                need(3)?;
                Shape::Ellipsoid {
                    radii: Vector3::new(size[0], size[1], size[2]),
                }
            }
            "mesh" => {
                let points: Vec<Vector3<f64>> = (vertices.iter().flatten())
                    .map(|v| Vector3::from(*v))
                    .collect();
                let hull = ukemi_engine::contact::geometry::ConvexHull::new(&points)
                    .map_err(|e| bad(format!("vertices`: {e}")))?;
                Shape::Mesh {
                    hull: std::sync::Arc::new(hull),
                }
            }
            other => {
                return Err(bad(format!(
                    "shape` = {other:?}: expected one of plane, sphere, capsule, box, cylinder, ellipsoid, mesh, point"
                )));
            }
        };
        let model = match contact {
            None => None,
            Some(m) => Some(ContactModel::from_name(m).ok_or_else(|| {
                bad(format!(
                    "contact` = {m:?}: expected \"nonlinear\", \"linear\", \"impact\" or None"
                ))
            })?),
        };
        let mut g = GeomSpec::new(&name, &body, shape)
            .pos(pos)
            .quat(quat)
            .friction(friction)
            .model(model);
        g.contype = contype;
        g.conaffinity = conaffinity;
        self.inner.add_geom(g);
        Ok(())
    }

    fn add_tendon_limit(
        &mut self,
        name: String,
        terms: Vec<(String, usize, f64)>,
        range: (f64, f64),
    ) {
        self.inner
            .add_tendon_limit(ukemi_engine::model::TendonLimitSpec { name, terms, range });
    }

    #[pyo3(signature = (name, terms, stiffness, damping, springlength=None, frictionloss=0.0))]
    fn add_passive_tendon(
        &mut self,
        name: String,
        terms: Vec<(String, usize, f64)>,
        stiffness: f64,
        damping: f64,
        springlength: Option<f64>,
        frictionloss: f64,
    ) {
        self.inner
            .add_passive_tendon(ukemi_engine::model::PassiveTendonSpec {
                name,
                terms,
                stiffness,
                springlength,
                damping,
                frictionloss,
            });
    }

    fn add_pair(
        &mut self,
        geom_a: String,
        geom_b: String,
        friction: f64,
        contact: &str,
    ) -> PyResult<()> {
        let model = ContactModel::from_name(contact).ok_or_else(|| {
            ModelError::new_err(format!(
                "invalid model: `pair[{geom_a}, {geom_b}].contact` = {contact:?}: expected \"nonlinear\", \"linear\" or \"impact\""
            ))
        })?;
        self.inner.add_pair(ukemi_engine::PairSpec {
            geom_a,
            geom_b,
            friction,
            model,
        });
        Ok(())
    }

    fn add_exclude(&mut self, body_a: &str, body_b: &str) {
        self.inner.add_exclude(body_a, body_b);
    }

    fn compile(&self) -> PyResult<PyModel> {
        guard(|| Ok(PyModel::new(self.inner.compile().py()?)))
    }
}

/// A compiled, immutable model.
#[pyclass(name = "Model", module = "ukemi._ukemi", frozen)]
pub struct PyModel {
    pub inner: Arc<Model>,
    /// Solver workspaces of finished calls, reused by the next ones: a workspace holds the
    /// Newton matrix of every contact candidate (megabytes for a robot), and allocating it
    /// for each `ukemi.step` cost more than the step (panda: 3.4 ms per step). Every step
    /// reinitialises what it reads, so results do not depend on the workspace's history.
    workspaces: Mutex<Vec<Workspace>>,
}

impl PyModel {
    pub fn new(inner: Model) -> Self {
        PyModel {
            inner: Arc::new(inner),
            workspaces: Mutex::new(Vec::new()),
        }
    }

    /// A workspace for this model: a pooled one, or a new one when all are in use.
    pub fn take_workspace(&self) -> Workspace {
        let pooled = self.pool().pop();
        pooled.unwrap_or_else(|| Workspace::new(&self.inner))
    }

    /// Return a workspace to the pool (at most one per concurrent caller is ever kept).
    pub fn give_workspace(&self, ws: Workspace) {
        self.pool().push(ws);
    }

    fn pool(&self) -> std::sync::MutexGuard<'_, Vec<Workspace>> {
        // nothing panics while the lock is held; a poisoned pool is still a valid list
        self.workspaces.lock().unwrap_or_else(|e| e.into_inner())
    }
}

#[pymethods]
impl PyModel {
    /// Number of position coordinates.
    #[getter]
    fn nq(&self) -> usize {
        self.inner.nq
    }
    /// Number of velocity coordinates.
    #[getter]
    fn nv(&self) -> usize {
        self.inner.nv
    }
    /// Number of actuators.
    #[getter]
    fn nu(&self) -> usize {
        self.inner.nu()
    }
    /// Number of bodies including the world.
    #[getter]
    fn nbody(&self) -> usize {
        self.inner.nbody()
    }
    /// Number of joints.
    #[getter]
    fn njoint(&self) -> usize {
        self.inner.njoint()
    }
    /// Number of collision geometries.
    #[getter]
    fn ngeom(&self) -> usize {
        self.inner.geoms.len()
    }
    #[getter]
    fn geom_names(&self) -> Vec<String> {
        self.inner.geoms.iter().map(|g| g.name.clone()).collect()
    }
    /// Number of contact candidates (decided at compile time).
    #[getter]
    fn ncontact(&self) -> usize {
        self.inner.ncontact()
    }
    /// Contact candidates as (geom_a, geom_b, model) names.
    #[getter]
    fn contact_pairs(&self) -> Vec<(String, String, &'static str)> {
        let g = &self.inner.geoms;
        self.inner
            .contacts
            .iter()
            .map(|c| {
                (
                    g[c.geom_a].name.clone(),
                    g[c.geom_b].name.clone(),
                    c.model.name(),
                )
            })
            .collect()
    }
    /// Number of limited joint dofs.
    #[getter]
    fn nlimit(&self) -> usize {
        self.inner.nlimit()
    }
    /// Names of the tendon limits (limited fixed tendons).
    #[getter]
    fn tendon_limit_names(&self) -> Vec<String> {
        self.inner
            .tendon_limits
            .iter()
            .map(|t| t.name.clone())
            .collect()
    }
    /// Range `(lo, hi)` of each tendon limit, (n, 2).
    #[getter]
    fn tendon_limit_range<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyArray2<f64>>> {
        let flat: Vec<f64> = self
            .inner
            .tendon_limits
            .iter()
            .flat_map(|t| [t.range.0, t.range.1])
            .collect();
        PyArray1::from_vec(py, flat).reshape([self.inner.tendon_limits.len(), 2])
    }
    /// Unknowns of one step per effect (what the scene pays for).
    #[getter]
    fn variable_counts(&self) -> Vec<(&'static str, usize)> {
        self.inner.variable_counts()
    }
    /// Number of joint constraint rows (impulse unknowns).
    #[getter]
    fn ncon(&self) -> usize {
        self.inner.ncon()
    }
    #[getter]
    fn body_names(&self) -> Vec<String> {
        self.inner.bodies.iter().map(|b| b.name.clone()).collect()
    }
    #[getter]
    fn joint_names(&self) -> Vec<String> {
        self.inner.joints.iter().map(|j| j.name.clone()).collect()
    }
    #[getter]
    fn joint_kinds(&self) -> Vec<&'static str> {
        self.inner.joints.iter().map(|j| j.kind.name()).collect()
    }
    #[getter]
    fn actuator_names(&self) -> Vec<String> {
        self.inner
            .actuators
            .iter()
            .map(|a| a.name.clone())
            .collect()
    }
    /// Joint limits per velocity dof, (nv, 2); `(-inf, inf)` where a dof is unlimited.
    #[getter]
    fn dof_range<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyArray2<f64>>> {
        let m = &self.inner;
        let mut r = vec![[f64::NEG_INFINITY, f64::INFINITY]; m.nv];
        for j in m.joints.iter().filter(|j| !j.is_loop) {
            for &(dof, lo, hi) in &j.limits {
                if let Some(x) = r.get_mut(j.qvel_adr + dof) {
                    *x = [lo, hi];
                }
            }
        }
        PyArray1::from_vec(py, r.concat()).reshape([m.nv, 2])
    }
    /// Gear ratio of each actuator, (nu,).
    #[getter]
    fn actuator_gear<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray1<f64>> {
        PyArray1::from_vec(py, self.inner.actuators.iter().map(|a| a.gear).collect())
    }
    /// Control range of each actuator, (nu, 2); `(-inf, inf)` where unclamped.
    #[getter]
    fn actuator_ctrlrange<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyArray2<f64>>> {
        let flat: Vec<f64> = self
            .inner
            .actuators
            .iter()
            .flat_map(|a| {
                let (lo, hi) = a.ctrlrange.unwrap_or((f64::NEG_INFINITY, f64::INFINITY));
                [lo, hi]
            })
            .collect();
        PyArray1::from_vec(py, flat).reshape([self.inner.nu(), 2])
    }
    #[getter]
    fn keyframe_names(&self) -> Vec<String> {
        self.inner
            .keyframes
            .iter()
            .map(|k| k.name.clone())
            .collect()
    }
    /// Keyframe positions, shape (nkey, nq) (MuJoCo's `key_qpos`).
    #[getter]
    fn key_qpos<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyArray2<f64>>> {
        let flat: Vec<f64> = self
            .inner
            .keyframes
            .iter()
            .flat_map(|k| k.qpos.clone())
            .collect();
        PyArray1::from_vec(py, flat).reshape([self.inner.keyframes.len(), self.inner.nq])
    }
    /// Keyframe velocities, shape (nkey, nv) (MuJoCo's `key_qvel`).
    #[getter]
    fn key_qvel<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyArray2<f64>>> {
        let flat: Vec<f64> = self
            .inner
            .keyframes
            .iter()
            .flat_map(|k| k.qvel.clone())
            .collect();
        PyArray1::from_vec(py, flat).reshape([self.inner.keyframes.len(), self.inner.nv])
    }
    /// Keyframe controls, shape (nkey, nu) (MuJoCo's `key_ctrl`).
    #[getter]
    fn key_ctrl<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyArray2<f64>>> {
        let flat: Vec<f64> = self
            .inner
            .keyframes
            .iter()
            .flat_map(|k| k.ctrl.clone())
            .collect();
        PyArray1::from_vec(py, flat).reshape([self.inner.keyframes.len(), self.inner.nu()])
    }
    /// Load a URDF file: `floating=True` gives the root link a free joint, `False` fixes it to
    /// the world (warnings about ignored features become `UserWarning`s).
    #[staticmethod]
    #[pyo3(signature = (path, floating=true))]
    fn from_urdf_path(
        py: Python<'_>,
        path: std::path::PathBuf,
        floating: bool,
    ) -> PyResult<PyModel> {
        crate::mjcf::from_urdf_path(py, &path.to_string_lossy(), floating)
    }
    /// Load URDF text (see `from_urdf_path`).
    #[staticmethod]
    #[pyo3(signature = (xml, floating=true))]
    fn from_urdf_string(py: Python<'_>, xml: &str, floating: bool) -> PyResult<PyModel> {
        crate::mjcf::from_urdf_string(py, xml, floating)
    }
    /// The MJCF document that URDF text translates to (fixed joints merged), for inspection.
    #[staticmethod]
    #[pyo3(signature = (xml, floating=true))]
    fn urdf_to_mjcf(py: Python<'_>, xml: &str, floating: bool) -> PyResult<String> {
        crate::mjcf::urdf_to_mjcf(py, xml, floating)
    }
    /// Load an MJCF file (warnings about ignored features become `UserWarning`s).
    #[staticmethod]
    fn from_xml_path(py: Python<'_>, path: std::path::PathBuf) -> PyResult<PyModel> {
        crate::mjcf::from_path(py, &path.to_string_lossy())
    }
    /// Load MJCF text.
    #[staticmethod]
    fn from_xml_string(py: Python<'_>, xml: &str) -> PyResult<PyModel> {
        crate::mjcf::from_string(py, xml)
    }
    #[getter]
    fn timestep(&self) -> f64 {
        self.inner.options.timestep
    }
    #[getter]
    fn gravity<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray1<f64>> {
        PyArray1::from_slice(py, self.inner.options.gravity.as_slice())
    }
    /// Solver options as a dict.
    #[getter]
    fn options(&self) -> std::collections::HashMap<&'static str, f64> {
        let o = &self.inner.options;
        [
            ("timestep", o.timestep),
            ("rtol", o.rtol),
            ("kappa_tol", o.kappa_tol),
            ("acceptable_rtol", o.acceptable_rtol),
            ("acceptable_kappa_tol", o.acceptable_kappa_tol),
            ("max_iter", o.max_iter as f64),
            ("endgame_iter", o.endgame_iter as f64),
            ("acceptable_iter", o.acceptable_iter as f64),
            ("stall_iter", o.stall_iter as f64),
            ("max_ls", o.max_ls as f64),
            ("undercut", o.undercut),
            ("warm_start_margin", o.warm_start_margin),
            ("warm_start_widening", o.warm_start_widening),
            ("warm_start_widening_weight", o.warm_start_widening_weight),
            ("regularization", o.regularization),
            ("friction_proximal", o.friction_proximal),
            ("activation_margin", o.activation_margin),
            ("max_subdivisions", o.max_subdivisions as f64),
            ("energy_guard", o.energy_guard),
            ("max_step_rotation", o.max_step_rotation),
            ("kappa_grad", o.kappa_grad.unwrap_or(0.0)),
        ]
        .into_iter()
        .collect()
    }
    #[getter]
    fn body_mass<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray1<f64>> {
        PyArray1::from_vec(py, self.inner.bodies.iter().map(|b| b.mass).collect())
    }
    /// Inertia about the COM in the body frame, (nbody, 3, 3).
    #[getter]
    fn body_inertia<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, numpy::PyArray3<f64>>> {
        let flat: Vec<f64> = self
            .inner
            .bodies
            .iter()
            .flat_map(|b| b.inertia.transpose().as_slice().to_vec())
            .collect();
        PyArray1::from_vec(py, flat).reshape([self.inner.nbody(), 3, 3])
    }
    /// COM position in each body frame, (nbody, 3).
    #[getter]
    fn body_com<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyArray2<f64>>> {
        let flat: Vec<f64> = self
            .inner
            .bodies
            .iter()
            .flat_map(|b| b.com.as_slice().to_vec())
            .collect();
        PyArray1::from_vec(py, flat).reshape([self.inner.nbody(), 3])
    }
    #[getter]
    fn qpos0<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray1<f64>> {
        PyArray1::from_slice(py, &self.inner.qpos0)
    }

    /// A new model with other options (any subset of the keywords).
    #[pyo3(signature = (*, timestep=None, gravity=None, rtol=None, kappa_tol=None, acceptable_rtol=None, acceptable_kappa_tol=None, max_iter=None, endgame_iter=None, acceptable_iter=None, stall_iter=None, cone_gap=None, drop_redundant_friction=None, pyramid_fallback=None, max_ls=None, undercut=None, warm_start=None, warm_start_margin=None, warm_start_widening=None, warm_start_widening_weight=None, regularization=None, friction_proximal=None, kappa_grad=None, activation_margin=None, nt_scaling=None, central_warm_start=None, smooth_every_candidate=None, max_subdivisions=None, energy_guard=None, max_step_rotation=None))]
    #[allow(clippy::too_many_arguments)]
    fn with_options(
        &self,
        timestep: Option<f64>,
        gravity: Option<[f64; 3]>,
        rtol: Option<f64>,
        kappa_tol: Option<f64>,
        acceptable_rtol: Option<f64>,
        acceptable_kappa_tol: Option<f64>,
        max_iter: Option<i64>,
        endgame_iter: Option<i64>,
        acceptable_iter: Option<i64>,
        stall_iter: Option<i64>,
        cone_gap: Option<Bound<'_, PyAny>>,
        drop_redundant_friction: Option<Bound<'_, PyAny>>,
        pyramid_fallback: Option<Bound<'_, PyAny>>,
        max_ls: Option<i64>,
        undercut: Option<f64>,
        warm_start: Option<Bound<'_, PyAny>>,
        warm_start_margin: Option<f64>,
        warm_start_widening: Option<f64>,
        warm_start_widening_weight: Option<f64>,
        regularization: Option<f64>,
        friction_proximal: Option<f64>,
        kappa_grad: Option<f64>,
        activation_margin: Option<f64>,
        nt_scaling: Option<Bound<'_, PyAny>>,
        central_warm_start: Option<Bound<'_, PyAny>>,
        smooth_every_candidate: Option<Bound<'_, PyAny>>,
        max_subdivisions: Option<i64>,
        energy_guard: Option<f64>,
        max_step_rotation: Option<f64>,
    ) -> PyResult<PyModel> {
        guard(|| {
            // counts arrive as Python ints: one out of range is a named error, not an
            // OverflowError
            fn count<T: TryFrom<i64>>(name: &str, v: Option<i64>, now: T) -> PyResult<T> {
                v.map_or(Ok(now), |v| {
                    T::try_from(v)
                        .map_err(|_| {
                            ukemi_engine::Error::model(name, v, "must be >= 0 and in range")
                        })
                        .py()
                })
            }
            // switches must be Python bools (1 or "yes" would be a silent typo): a named error
            fn flag(name: &str, v: Option<Bound<'_, PyAny>>, now: bool) -> PyResult<bool> {
                v.map_or(Ok(now), |v| {
                    v.cast::<pyo3::types::PyBool>()
                        .map(|b| b.is_true())
                        .map_err(|_| {
                            pyo3::exceptions::PyTypeError::new_err(format!(
                                "`{name}` must be True or False, got {v}"
                            ))
                        })
                })
            }
            let mut o = self.inner.options.clone();
            o.timestep = timestep.unwrap_or(o.timestep);
            o.gravity = gravity.map(Vector3::from).unwrap_or(o.gravity);
            o.rtol = rtol.unwrap_or(o.rtol);
            o.max_iter = count("max_iter", max_iter, o.max_iter)?;
            o.endgame_iter = count("endgame_iter", endgame_iter, o.endgame_iter)?;
            o.acceptable_iter = count("acceptable_iter", acceptable_iter, o.acceptable_iter)?;
            o.stall_iter = count("stall_iter", stall_iter, o.stall_iter)?;
            o.cone_gap = flag("cone_gap", cone_gap, o.cone_gap)?;
            o.drop_redundant_friction = flag(
                "drop_redundant_friction",
                drop_redundant_friction,
                o.drop_redundant_friction,
            )?;
            o.pyramid_fallback = flag("pyramid_fallback", pyramid_fallback, o.pyramid_fallback)?;
            o.max_ls = count("max_ls", max_ls, o.max_ls)?;
            o.regularization = regularization.unwrap_or(o.regularization);
            o.friction_proximal = friction_proximal.unwrap_or(o.friction_proximal);
            o.kappa_tol = kappa_tol.unwrap_or(o.kappa_tol);
            o.acceptable_rtol = acceptable_rtol.unwrap_or(o.acceptable_rtol);
            o.acceptable_kappa_tol = acceptable_kappa_tol.unwrap_or(o.acceptable_kappa_tol);
            o.undercut = undercut.unwrap_or(o.undercut);
            o.warm_start = flag("warm_start", warm_start, o.warm_start)?;
            o.warm_start_margin = warm_start_margin.unwrap_or(o.warm_start_margin);
            o.warm_start_widening = warm_start_widening.unwrap_or(o.warm_start_widening);
            o.warm_start_widening_weight =
                warm_start_widening_weight.unwrap_or(o.warm_start_widening_weight);
            o.nt_scaling = flag("nt_scaling", nt_scaling, o.nt_scaling)?;
            o.central_warm_start = flag(
                "central_warm_start",
                central_warm_start,
                o.central_warm_start,
            )?;
            o.smooth_every_candidate = flag(
                "smooth_every_candidate",
                smooth_every_candidate,
                o.smooth_every_candidate,
            )?;
            o.max_subdivisions = count("max_subdivisions", max_subdivisions, o.max_subdivisions)?;
            o.energy_guard = energy_guard.unwrap_or(o.energy_guard);
            // max_step_rotation = inf turns the rotation limit off
            o.max_step_rotation = max_step_rotation.unwrap_or(o.max_step_rotation);
            // activation_margin = inf keeps every contact candidate active
            o.activation_margin = activation_margin.unwrap_or(o.activation_margin);
            // kappa_grad = 0 selects the exact (unsmoothed) derivative
            if let Some(k) = kappa_grad {
                o.kappa_grad = if k == 0.0 { None } else { Some(k) };
            }
            Ok(PyModel::new(self.inner.with_options(o).py()?))
        })
    }

    /// Differentiable parameters as one flat vector (see `param_names`).
    #[getter]
    fn params<'py>(&self, py: Python<'py>) -> Bound<'py, numpy::PyArray1<f64>> {
        numpy::PyArray1::from_vec(py, self.inner.params())
    }

    /// One name per entry of `params`, e.g. `"body_mass[torso]"`. Groups, in order: body_mass,
    /// body_inertia, geom_friction, geom_size and geom_pos (geom by geom), joint_stiffness,
    /// joint_damping, joint_armature, joint_frictionloss, tendon_stiffness, tendon_damping,
    /// tendon_frictionloss, actuator_gear, actuator_gain, actuator_bias, gravity, timestep.
    #[getter]
    fn param_names(&self) -> Vec<String> {
        self.inner.param_names()
    }

    /// The same model with new parameter values (same topology: states stay valid).
    fn with_params(&self, params: Vec<f64>) -> PyResult<PyModel> {
        guard(|| Ok(PyModel::new(self.inner.with_params(&params).py()?)))
    }

    /// Default central-path parameter of the gradients (None: exact derivative).
    #[getter]
    fn kappa_grad(&self) -> Option<f64> {
        self.inner.options.kappa_grad
    }

    /// State at the reference pose, or at the given minimal coordinates. `velocity` says what
    /// `qvel` is: `"midpoint"` (default) the velocity over the step before the state, as the
    /// state stores it; `"instant"` the velocity at the state's time, MuJoCo's convention (the
    /// midpoint velocity is found by the discrete Legendre transform, a few steps of the model
    /// under zero control: `engine/src/legendre.rs`).
    #[pyo3(signature = (qpos=None, qvel=None, key=None, velocity="midpoint"))]
    fn make_state(
        &self,
        py: Python<'_>,
        qpos: Option<Vec<f64>>,
        qvel: Option<Vec<f64>>,
        key: Option<String>,
        velocity: &str,
    ) -> PyResult<PyState> {
        let instant = match velocity {
            "midpoint" => false,
            "instant" => true,
            other => {
                return Err(crate::errors::InputError::new_err(format!(
                    "invalid input: `velocity` = {other:?}: must be \"midpoint\" or \"instant\""
                )));
            }
        };
        let mut state = self.make_state_midpoint(qpos, qvel, key)?;
        if instant {
            let m = &self.inner;
            let v = ukemi_engine::qvel(m, &state.inner);
            let zero = vec![0.0; m.nu()];
            let inner = &mut state.inner;
            guard(|| {
                py.detach(|| ukemi_engine::set_instant_velocity(m, inner, &v, &zero))
                    .py()
            })?;
        }
        Ok(state)
    }

    /// The state `state.snapshot()` wrote, for this model (a snapshot of another model's state
    /// has another length and is refused).
    fn state_from_snapshot(&self, snapshot: Vec<f64>) -> PyResult<PyState> {
        guard(|| {
            Ok(PyState {
                model: self.inner.clone(),
                inner: State::from_snapshot(&self.inner, &snapshot).py()?,
            })
        })
    }

    fn __repr__(&self) -> String {
        let m = &self.inner;
        format!(
            "ukemi.Model(nbody={}, njoint={}, nq={}, nv={}, nu={}, timestep={})",
            m.nbody(),
            m.njoint(),
            m.nq,
            m.nv,
            m.nu(),
            m.options.timestep
        )
    }
}

impl PyModel {
    /// [`PyModel::make_state`] with `qvel` as the stored midpoint velocity.
    fn make_state_midpoint(
        &self,
        qpos: Option<Vec<f64>>,
        qvel: Option<Vec<f64>>,
        key: Option<String>,
    ) -> PyResult<PyState> {
        guard(|| {
            let m = &self.inner;
            let (mut qpos, mut qvel) = (qpos, qvel);
            let mut time = 0.0;
            if let Some(k) = key {
                let names: Vec<&str> = m.keyframes.iter().map(|k| k.name.as_str()).collect();
                let frame = m.keyframes.iter().find(|f| f.name == k).ok_or_else(|| {
                    crate::errors::InputError::new_err(format!(
                        "invalid input: `key` = {k:?}: unknown keyframe (this model has {names:?})"
                    ))
                })?;
                qpos = Some(qpos.unwrap_or_else(|| frame.qpos.clone()));
                qvel = Some(qvel.unwrap_or_else(|| frame.qvel.clone()));
                time = frame.time;
            }
            let mut state = State::reference(m);
            state.time = time;
            if qpos.is_some() || qvel.is_some() {
                let q = qpos.unwrap_or_else(|| m.qpos0.clone());
                let v = qvel.unwrap_or_else(|| vec![0.0; m.nv]);
                ukemi_engine::set_minimal(m, &mut state, &q, &v).py()?;
            }
            Ok(PyState {
                model: self.inner.clone(),
                inner: state,
            })
        })
    }
}
