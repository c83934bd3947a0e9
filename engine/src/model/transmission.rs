//! Actuator transmissions beyond one joint dof (fixed tendons, sites), joint couplings
//! (MuJoCo's `equality/joint`) and fixed-tendon limits: specs and their compilation against the
//! compiled joints.
use nalgebra::{Matrix3, Vector3};

use super::Body;
use crate::joints::Joint;
use crate::joints::coupling::Coupling;
use crate::joints::tendon::TendonLimit;
use crate::math::quat;
use crate::{Error, Result, ensure};

/// Where an actuator spec acts.
#[derive(Clone, Debug, Default)]
pub enum TransmissionSpec {
    /// Free dof `dof` of joint `joint` of the [`super::ActuatorSpec`].
    #[default]
    Joint,
    /// A fixed tendon: length `Σ coef · q` over `(joint name, free dof, coef)`.
    Tendon(Vec<(String, usize, f64)>),
    /// A wrench at a site of `body`: `gear[0..3]` force and `gear[3..6]` torque per unit of
    /// actuator force, in the site frame; `pos` (m) and `quat` `(w, x, y, z)` in the body frame.
    Site {
        /// Body name.
        body: String,
        /// Site position, body frame (m).
        pos: [f64; 3],
        /// Site orientation, body frame.
        quat: [f64; 4],
        /// Force then torque per unit actuator force, site frame.
        gear: [f64; 6],
    },
}

/// A compiled transmission.
#[derive(Clone, Debug)]
pub enum Transmission {
    /// Free dof `dof` of joint `joint`.
    Joint {
        /// Joint index.
        joint: usize,
        /// Free dof of that joint.
        dof: usize,
    },
    /// Fixed tendon terms `(joint, free dof, coef)`.
    Tendon(Vec<(usize, usize, f64)>),
    /// Site wrench on `body`: site at `pos` (body COM frame, m) with orientation `rot` (body
    /// frame); `gear` is force then torque per unit actuator force, site frame.
    Site {
        /// Body index.
        body: usize,
        /// Site position relative to the COM, body frame (m).
        pos: Vector3<f64>,
        /// Site to body rotation.
        rot: Matrix3<f64>,
        /// Force then torque per unit actuator force, site frame.
        gear: [f64; 6],
    },
}

impl Transmission {
    /// Coefficient of joint `ji`'s free dof `dof` in the transmission (0 if it does not act there).
    pub fn moment(&self, ji: usize, dof: usize) -> f64 {
        match self {
            Transmission::Joint { joint, dof: d } if *joint == ji && *d == dof => 1.0,
            Transmission::Tendon(terms) => terms
                .iter()
                .filter(|(j, d, _)| *j == ji && *d == dof)
                .map(|t| t.2)
                .sum(),
            _ => 0.0,
        }
    }
    /// Whether any term acts on joint `ji`.
    pub fn acts_on(&self, ji: usize) -> bool {
        match self {
            Transmission::Joint { joint, .. } => *joint == ji,
            Transmission::Tendon(terms) => terms.iter().any(|t| t.0 == ji),
            Transmission::Site { .. } => false,
        }
    }
}

/// A joint coupling to add (MuJoCo's `equality/joint`): `y - y₀ = Σ polycoef_i (x - x₀)^i`.
#[derive(Clone, Debug)]
pub struct CouplingSpec {
    /// Unique name.
    pub name: String,
    /// Joint name and free dof of `y`.
    pub joint1: (String, usize),
    /// Joint name and free dof of `x` (none: `y - y₀ = polycoef₀`).
    pub joint2: Option<(String, usize)>,
    /// Up to five polynomial coefficients.
    pub polycoef: Vec<f64>,
}

/// A fixed-tendon limit to add (MuJoCo's limited `<tendon><fixed>`): `lo ≤ Σ coef q ≤ hi`.
#[derive(Clone, Debug)]
pub struct TendonLimitSpec {
    /// Unique name.
    pub name: String,
    /// Terms `(joint name, free dof, coef)` over hinge or slide coordinates.
    pub terms: Vec<(String, usize, f64)>,
    /// Range `(lo, hi)` of the tendon length (m or rad).
    pub range: (f64, f64),
}

/// A passive fixed tendon to add (MuJoCo's `<tendon><fixed stiffness damping springlength
/// frictionloss>`): a spring, a damper and dry friction on `L = Σ coef q`.
#[derive(Clone, Debug)]
pub struct PassiveTendonSpec {
    /// Unique name.
    pub name: String,
    /// Terms `(joint name, free dof, coef)` over hinge or slide coordinates.
    pub terms: Vec<(String, usize, f64)>,
    /// Spring stiffness (≥ 0).
    pub stiffness: f64,
    /// Spring rest length; `None`: the length at the joints' spring rest positions (MuJoCo's
    /// `springlength = -1`: `qpos_spring`, the joints' `springref`).
    pub springlength: Option<f64>,
    /// Damping (≥ 0), implicit.
    pub damping: f64,
    /// Dry friction (≥ 0, MuJoCo's `frictionloss`).
    pub frictionloss: f64,
}

/// Index of a named joint's scalar (hinge or slide) free dof.
fn scalar_dof(joints: &[Joint], name: &str, dof: usize, field: &str) -> Result<(usize, usize)> {
    let j = joints
        .iter()
        .position(|j| j.name == name)
        .ok_or_else(|| Error::model(field, name, "unknown joint"))?;
    let joint = &joints[j];
    ensure!(
        dof < joint.nfree() && !joint.is_loop,
        Error::model(field, dof, format!("joint has {} free dofs", joint.nfree()))
    );
    ensure!(
        joint.rot.nq() != 4 || dof < joint.ntrans,
        Error::model(
            field,
            (name, dof),
            "must be a hinge or slide coordinate (not a quaternion)"
        )
    );
    Ok((j, dof))
}

pub(super) fn compile_transmission(
    spec: &super::ActuatorSpec,
    joints: &[Joint],
    bodies: &[Body],
    field: &dyn Fn(&str) -> String,
) -> Result<Transmission> {
    Ok(match &spec.transmission {
        TransmissionSpec::Joint => {
            let joint = joints
                .iter()
                .position(|j| j.name == spec.joint)
                .ok_or_else(|| Error::model(field("joint"), &spec.joint, "unknown joint"))?;
            let nfree = joints[joint].nfree();
            ensure!(
                spec.dof < nfree,
                Error::model(
                    field("dof"),
                    spec.dof,
                    format!("joint has {nfree} free dofs")
                )
            );
            Transmission::Joint {
                joint,
                dof: spec.dof,
            }
        }
        TransmissionSpec::Tendon(terms) => {
            ensure!(
                !terms.is_empty(),
                Error::model(field("tendon"), "[]", "needs at least one joint")
            );
            let mut out = Vec::with_capacity(terms.len());
            for (name, dof, coef) in terms {
                ensure!(
                    coef.is_finite(),
                    Error::model(field("tendon.coef"), coef, "must be finite")
                );
                let (j, d) = scalar_dof(joints, name, *dof, &field("tendon"))?;
                out.push((j, d, *coef));
            }
            Transmission::Tendon(out)
        }
        TransmissionSpec::Site {
            body,
            pos,
            quat: q,
            gear,
        } => {
            let b = bodies
                .iter()
                .position(|x| &x.name == body)
                .filter(|&b| b > 0)
                .ok_or_else(|| Error::model(field("site.body"), body, "unknown moving body"))?;
            ensure!(
                pos.iter()
                    .chain(q.iter())
                    .chain(gear.iter())
                    .all(|x| x.is_finite())
                    && q.iter().map(|x| x * x).sum::<f64>() > 1e-18,
                Error::model(
                    field("site"),
                    (pos, q, gear),
                    "need finite values and a non-zero quaternion"
                )
            );
            Transmission::Site {
                body: b,
                pos: Vector3::from(*pos) - bodies[b].com,
                rot: quat::rotation(&quat::from_wxyz(q).normalize()),
                gear: *gear,
            }
        }
    })
}

pub(super) fn compile_couplings(specs: &[CouplingSpec], joints: &[Joint]) -> Result<Vec<Coupling>> {
    let mut out: Vec<Coupling> = Vec::with_capacity(specs.len());
    for spec in specs {
        let f = |field: &str| format!("coupling[{}].{field}", spec.name);
        ensure!(
            !out.iter().any(|c| c.name == spec.name),
            Error::model(f("name"), &spec.name, "duplicate coupling name")
        );
        ensure!(
            spec.polycoef.len() <= 5 && spec.polycoef.iter().all(|c| c.is_finite()),
            Error::model(
                f("polycoef"),
                &spec.polycoef,
                "need at most 5 finite coefficients"
            )
        );
        let mut polycoef = [0.0; 5];
        polycoef[..spec.polycoef.len()].copy_from_slice(&spec.polycoef);
        let joint1 = scalar_dof(joints, &spec.joint1.0, spec.joint1.1, &f("joint1"))?;
        let joint2 = match &spec.joint2 {
            Some((n, d)) => Some(scalar_dof(joints, n, *d, &f("joint2"))?),
            None => None,
        };
        ensure!(
            joint2 != Some(joint1),
            Error::model(f("joint2"), &spec.joint1.0, "must differ from joint1")
        );
        let reference = (
            joints[joint1.0].qpos_ref_at(joint1.1),
            joint2.map_or(0.0, |(j, d)| joints[j].qpos_ref_at(d)),
        );
        out.push(Coupling {
            name: spec.name.clone(),
            joint1,
            joint2,
            polycoef,
            reference,
        });
    }
    Ok(out)
}

/// A fixed tendon's terms `(joint, free dof, coef)`: hinge or slide coordinates, finite
/// coefficients, at least one non-zero; `f` names the fields.
fn compile_terms(
    terms: &[(String, usize, f64)],
    joints: &[Joint],
    f: &dyn Fn(&str) -> String,
) -> Result<Vec<(usize, usize, f64)>> {
    ensure!(
        terms.iter().any(|t| t.2 != 0.0),
        Error::model(
            f("terms"),
            terms,
            "need at least one joint with a non-zero coef"
        )
    );
    let mut out = Vec::with_capacity(terms.len());
    for (name, dof, coef) in terms {
        ensure!(
            coef.is_finite(),
            Error::model(f("terms.coef"), coef, "must be finite")
        );
        let (j, d) = scalar_dof(joints, name, *dof, &f("terms.joint"))?;
        out.push((j, d, *coef));
    }
    Ok(out)
}

pub(super) fn compile_tendon_limits(
    specs: &[TendonLimitSpec],
    joints: &[Joint],
) -> Result<Vec<TendonLimit>> {
    let mut out: Vec<TendonLimit> = Vec::with_capacity(specs.len());
    for spec in specs {
        let f = |field: &str| format!("tendon_limit[{}].{field}", spec.name);
        ensure!(
            !out.iter().any(|t| t.name == spec.name),
            Error::model(f("name"), &spec.name, "duplicate tendon limit name")
        );
        let (lo, hi) = spec.range;
        ensure!(
            lo.is_finite() && hi.is_finite() && lo < hi,
            Error::model(f("range"), spec.range, "need finite lower < upper")
        );
        let terms = compile_terms(&spec.terms, joints, &f)?;
        out.push(TendonLimit {
            name: spec.name.clone(),
            terms,
            range: spec.range,
        });
    }
    Ok(out)
}

pub(super) fn compile_passive_tendons(
    specs: &[PassiveTendonSpec],
    joints: &[Joint],
) -> Result<Vec<crate::joints::tendon::PassiveTendon>> {
    let mut out: Vec<crate::joints::tendon::PassiveTendon> = Vec::with_capacity(specs.len());
    for spec in specs {
        let f = |field: &str| format!("passive_tendon[{}].{field}", spec.name);
        ensure!(
            !out.iter().any(|t| t.name == spec.name),
            Error::model(f("name"), &spec.name, "duplicate passive tendon name")
        );
        for (what, v) in [
            ("stiffness", spec.stiffness),
            ("damping", spec.damping),
            ("frictionloss", spec.frictionloss),
        ] {
            ensure!(
                v.is_finite() && v >= 0.0,
                Error::model(f(what), v, "must be finite and >= 0")
            );
        }
        if let Some(l) = spec.springlength {
            ensure!(
                l.is_finite(),
                Error::model(f("springlength"), l, "must be finite")
            );
        }
        let terms = compile_terms(&spec.terms, joints, &f)?;
        // MuJoCo's springlength -1: the length at the joints' spring rest positions
        // (`springref`; the reference configuration where a joint has none)
        let at_rest: f64 = terms
            .iter()
            .map(|&(j, d, c)| {
                let joint = &joints[j];
                c * joint
                    .spring_ref
                    .get(d)
                    .copied()
                    .unwrap_or(joint.qpos_ref_at(d))
            })
            .sum();
        out.push(crate::joints::tendon::PassiveTendon {
            name: spec.name.clone(),
            terms,
            stiffness: spec.stiffness,
            springlength: spec.springlength.unwrap_or(at_rest),
            damping: spec.damping,
            frictionloss: spec.frictionloss,
        });
    }
    Ok(out)
}
