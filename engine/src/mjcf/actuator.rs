//! `<actuator>` (motor, position, velocity, general with a joint, fixed-tendon or site
//! transmission, `forcerange`), `<keyframe>`, `<equality>` (connect and weld as loop-closing
//! joints, joint as a coupling) and `<contact>` (exclude, pair).
use nalgebra::Vector3;
use roxmltree::Node;

use super::body::Tree;
use super::parse::{Ctx, elements};
use super::tendon::Tendons;
use crate::model::Keyframe;
use crate::model::{CouplingSpec, TransmissionSpec};
use crate::{ActuatorSpec, ContactModel, JointKind, JointSpec, ModelBuilder, PairSpec, Result};

/// A position servo whose control range its joint's or tendon's range gives
/// ([`resolve_inherited_ranges`]): the actuator's index, `inheritrange`, the tendon's name
/// (none for a joint), and the element (for errors).
pub(super) struct InheritRange<'a, 'i> {
    actuator: usize,
    scale: f64,
    tendon: Option<String>,
    node: Node<'a, 'i>,
}

pub(super) fn read_actuators<'a, 'i>(
    ctx: &mut Ctx<'a, 'i>,
    node: Node<'a, 'i>,
    tree: &Tree,
    tendons: &Tendons,
    b: &mut ModelBuilder,
    inherit: &mut Vec<InheritRange<'a, 'i>>,
) -> Result<()> {
    let first = b.actuator_count();
    for (i, a) in elements(node).enumerate() {
        let tag = a.tag_name().name();
        if !["motor", "position", "velocity", "general"].contains(&tag) {
            return Err(ctx.unsupported(a, format!("actuator type <{tag}> is not supported (motor, position, velocity, general are)")));
        }
        let class = ctx.class_of(a, "main")?;
        let name = a
            .attribute("name")
            .map_or_else(|| format!("actuator{i}"), str::to_string);
        ctx.lines.insert(format!("actuator[{name}]"), ctx.line(a));
        for t in [
            "body",
            "jointinparent",
            "cranksite",
            "slidersite",
            "refsite",
        ] {
            if a.attribute(t).is_some() {
                return Err(ctx.unsupported(
                    a,
                    format!("actuator {name:?}: `{t}` transmission is not supported (joint, tendon and site are)"),
                ));
            }
        }
        let gear6 = ctx.nums_padded(a, &class, "gear", &[1.0, 0.0, 0.0, 0.0, 0.0, 0.0])?;
        let (joint, dof, transmission) = transmission(ctx, a, &name, tree, tendons, &gear6)?;
        let gear = gear6[0];
        let range = |ctx: &Ctx<'a, 'i>, attr: &str, lim: &str| -> Result<Option<(f64, f64)>> {
            let r = ctx.nums(a, &class, attr, 2)?;
            let limited = ctx
                .tristate(a, &class, lim)?
                .unwrap_or(ctx.compiler.autolimits && r.is_some());
            match (limited, r) {
                (false, _) => Ok(None),
                (true, Some(r)) if r[0] < r[1] => Ok(Some((r[0], r[1]))),
                (true, r) => Err(ctx.err(
                    a,
                    format!("attribute `{attr}` = {r:?}: need lower < upper when {lim}"),
                )),
            }
        };
        let ctrlrange = range(ctx, "ctrlrange", "ctrllimited")?;
        let scale = match tag {
            "position" => ctx.num(a, &class, "inheritrange", 0.0)?,
            _ => 0.0,
        };
        if scale < 0.0 {
            return Err(ctx.err(
                a,
                format!("attribute `inheritrange` = {scale}: must be >= 0"),
            ));
        }
        if scale > 0.0 {
            if ctx.nums(a, &class, "ctrlrange", 2)?.is_some() {
                return Err(ctx.err(a, "ctrlrange and inheritrange cannot both be defined"));
            }
            inherit.push(InheritRange {
                actuator: first + i,
                scale,
                tendon: a.attribute("tendon").map(str::to_string),
                node: a,
            });
        }
        let forcerange = range(ctx, "forcerange", "forcelimited")?;
        let (gain, bias) = gain_bias(ctx, a, &class, tag)?;
        if matches!(transmission, TransmissionSpec::Site { .. })
            && (bias[1] != 0.0 || bias[2] != 0.0)
        {
            return Err(ctx.unsupported(
                a,
                format!("actuator {name:?}: a servo (length or velocity bias) on a site"),
            ));
        }
        let mut spec = ActuatorSpec::motor(&name, &joint, dof, gear);
        spec.ctrlrange = ctrlrange;
        spec.forcerange = forcerange;
        spec.gain = gain;
        spec.bias = bias;
        spec.transmission = transmission;
        b.add_actuator(spec);
    }
    Ok(())
}

/// The actuator's transmission: `(engine joint, dof, spec)`; joint and dof only for joints.
fn transmission<'a, 'i>(
    ctx: &Ctx<'a, 'i>,
    a: Node<'a, 'i>,
    name: &str,
    tree: &Tree,
    tendons: &Tendons,
    gear6: &[f64],
) -> Result<(String, usize, TransmissionSpec)> {
    if let Some(t) = a.attribute("tendon") {
        let terms = tendons.get(t).ok_or_else(|| {
            ctx.err(
                a,
                format!("attribute `tendon` = {t:?}: unknown fixed tendon"),
            )
        })?;
        return Ok((String::new(), 0, TransmissionSpec::Tendon(terms.clone())));
    }
    if let Some(s) = a.attribute("site") {
        let (_, body, local) = tree
            .sites
            .iter()
            .find(|x| x.0 == s)
            .ok_or_else(|| ctx.err(a, format!("attribute `site` = {s:?}: unknown site")))?;
        let engine = tree.bodies[*body].engine;
        if engine == 0 {
            return Err(
                ctx.unsupported(a, format!("actuator {name:?}: site {s:?} on a static body"))
            );
        }
        let on_body = tree.engine_bodies[engine]
            .1
            .relative(&tree.bodies[*body].world.compose(local));
        let mut gear = [0.0; 6];
        gear.copy_from_slice(&gear6[..6]);
        let spec = TransmissionSpec::Site {
            body: tree.engine_bodies[engine].0.clone(),
            pos: on_body.pos.into(),
            quat: on_body.wxyz(),
            gear,
        };
        return Ok((String::new(), 0, spec));
    }
    let joint = a.attribute("joint").ok_or_else(|| {
        ctx.err(
            a,
            format!("actuator {name:?} needs a `joint`, `tendon` or `site`"),
        )
    })?;
    let map = tree
        .joints
        .iter()
        .find(|j| j.name == joint)
        .ok_or_else(|| ctx.err(a, format!("attribute `joint` = {joint:?}: unknown joint")))?;
    if map.kind == "ball" || map.kind == "free" {
        return Err(ctx.unsupported(a, format!("actuator {name:?} on a {} joint", map.kind)));
    }
    Ok((map.engine_joint.clone(), map.dof, TransmissionSpec::Joint))
}

/// A joint's `actuatorfrcrange` clamps the total actuator force on its dof: where one joint
/// actuator alone drives the dof, that is a clamp of its generalized force
/// (`Actuator::joint_forcerange`). Where several actuators, or a tendon or site actuator (a
/// site's wrench reaches the dofs of the bodies above it), could drive it, the sum is not
/// modelled: ignored with a warning at the joint.
pub(super) fn resolve_joint_force_ranges(ctx: &mut Ctx, tree: &Tree, model: &mut crate::Model) {
    use crate::model::Transmission;
    let sites =
        (model.actuators.iter()).any(|a| matches!(a.transmission, Transmission::Site { .. }));
    for map in &tree.joints {
        let Some((range, node)) = map.actfrcrange else {
            continue;
        };
        let Some(ji) = model.joints.iter().position(|j| j.name == map.engine_joint) else {
            continue;
        };
        let on_dof = |a: &crate::model::Actuator| match &a.transmission {
            Transmission::Joint { joint, dof } => *joint == ji && *dof == map.dof,
            _ => false,
        };
        let drivers: Vec<usize> = (0..model.actuators.len())
            .filter(|&a| on_dof(&model.actuators[a]))
            .collect();
        let tendon = (model.actuators.iter()).any(|a| match &a.transmission {
            Transmission::Tendon(terms) => terms.iter().any(|t| t.0 == ji && t.1 == map.dof),
            _ => false,
        });
        match (drivers.as_slice(), tendon || sites) {
            ([], false) => {}
            ([a], false) => model.actuators[*a].joint_forcerange = Some(range),
            _ => {
                // (the id is of this document's joint element)
                let Some(node) = ctx.doc.get_node(node) else {
                    continue;
                };
                ctx.warn(
                    node,
                    "`actuatorfrcrange` is ignored: the joint's total actuator force is clamped \
                     only where one joint actuator alone drives it (each actuator's own \
                     `forcerange` is applied)",
                );
            }
        }
    }
}

/// MuJoCo's gain and affine bias of each actuator shortcut.
fn gain_bias<'a, 'i>(
    ctx: &Ctx<'a, 'i>,
    a: Node<'a, 'i>,
    class: &str,
    tag: &str,
) -> Result<(f64, [f64; 3])> {
    if a.attribute("timeconst").is_some_and(|v| v.trim() != "0") {
        return Err(ctx.unsupported(a, "actuator attribute `timeconst`"));
    }
    if tag != "position" && a.attribute("inheritrange").is_some_and(|v| v.trim() != "0") {
        return Err(ctx.unsupported(
            a,
            format!("`inheritrange` on <{tag}> (position servos have it)"),
        ));
    }
    Ok(match tag {
        "motor" => (1.0, [0.0; 3]),
        "position" => {
            let kp = ctx.num(a, class, "kp", 1.0)?;
            let kv = ctx.num(a, class, "kv", 0.0)?;
            let dampratio = ctx.num(a, class, "dampratio", 0.0)?;
            if kv != 0.0 && dampratio != 0.0 {
                return Err(ctx.err(a, "kv and dampratio cannot both be defined"));
            }
            if dampratio < 0.0 || kv < 0.0 {
                return Err(ctx.err(
                    a,
                    format!("kv = {kv}, dampratio = {dampratio}: must be >= 0"),
                ));
            }
            // a damping ratio is kept as a positive velocity bias until the model's inertia
            // at qpos0 turns it into a gain ([`resolve_dampratios`]), as MuJoCo keeps it
            (
                kp,
                [0.0, -kp, if dampratio > 0.0 { dampratio } else { -kv }],
            )
        }
        "velocity" => {
            let kv = ctx.num(a, class, "kv", 1.0)?;
            (kv, [0.0, 0.0, -kv])
        }
        _ => {
            let dyn_type = ctx.keyword(
                a,
                class,
                "dyntype",
                &[
                    "none",
                    "integrator",
                    "filter",
                    "filterexact",
                    "muscle",
                    "user",
                ],
                "none",
            )?;
            let gain_type = ctx.keyword(
                a,
                class,
                "gaintype",
                &["fixed", "affine", "muscle", "user"],
                "fixed",
            )?;
            let bias_type = ctx.keyword(
                a,
                class,
                "biastype",
                &["none", "affine", "muscle", "user"],
                "none",
            )?;
            if dyn_type != "none"
                || gain_type != "fixed"
                || !["none", "affine"].contains(&bias_type.as_str())
            {
                return Err(ctx.unsupported(
                    a,
                    format!("general actuator with dyntype={dyn_type:?} gaintype={gain_type:?} biastype={bias_type:?} (only none/fixed/affine)"),
                ));
            }
            let g = ctx.nums_padded(a, class, "gainprm", &[1.0; 10])?;
            let bp = ctx.nums_padded(a, class, "biasprm", &[0.0; 10])?;
            let bias = if bias_type == "affine" {
                [bp[0], bp[1], bp[2]]
            } else {
                [0.0; 3]
            };
            (g[0], bias)
        }
    })
}

pub(super) fn read_keyframes<'a, 'i>(
    ctx: &Ctx<'a, 'i>,
    node: Node<'a, 'i>,
    qpos0: &[f64],
    nv: usize,
    nu: usize,
) -> Result<Vec<Keyframe>> {
    let mut out = Vec::new();
    for k in elements(node) {
        if k.tag_name().name() != "key" {
            return Err(ctx.err(k, "expected <key>"));
        }
        for t in ["act", "mpos", "mquat"] {
            if k.attribute(t).is_some() {
                return Err(ctx.unsupported(k, format!("keyframe attribute `{t}`")));
            }
        }
        let vec = |name: &str, n: usize, default: Vec<f64>| -> Result<Vec<f64>> {
            match ctx.nums(k, "", name, 0)? {
                None => Ok(default),
                Some(v) if v.len() == n => Ok(v),
                Some(v) => Err(ctx.err(
                    k,
                    format!(
                        "attribute `{name}` has {} numbers, the model needs {n}",
                        v.len()
                    ),
                )),
            }
        };
        out.push(Keyframe {
            name: k.attribute("name").unwrap_or("").to_string(),
            time: ctx.num(k, "", "time", 0.0)?,
            qpos: vec("qpos", qpos0.len(), qpos0.to_vec())?,
            qvel: vec("qvel", nv, vec![0.0; nv])?,
            ctrl: vec("ctrl", nu, vec![0.0; nu])?,
        });
    }
    Ok(out)
}

pub(super) fn read_equality<'a, 'i>(
    ctx: &mut Ctx<'a, 'i>,
    node: Node<'a, 'i>,
    tree: &Tree,
    b: &mut ModelBuilder,
) -> Result<()> {
    for (i, e) in elements(node).enumerate() {
        let tag = e.tag_name().name();
        if !["connect", "weld", "joint"].contains(&tag) {
            return Err(ctx.unsupported(
                e,
                format!("equality <{tag}> is not supported (connect, weld and joint are)"),
            ));
        }
        if e.attribute("active") == Some("false") {
            ctx.warn(e, "inactive equality constraint skipped");
            continue;
        }
        if tag == "joint" {
            read_joint_coupling(ctx, e, i, tree, b)?;
            continue;
        }
        if e.attribute("site1").is_some() || e.attribute("site2").is_some() {
            return Err(ctx.unsupported(e, "equality between sites"));
        }
        let body = |attr: &str| -> Result<usize> {
            let n = e.attribute(attr).unwrap_or("world");
            tree.body_id(n)
                .ok_or_else(|| ctx.err(e, format!("attribute `{attr}` = {n:?}: unknown body")))
        };
        let (b1, b2) = (body("body1")?, body("body2")?);
        let (e1, e2) = (tree.bodies[b1].engine, tree.bodies[b2].engine);
        if e1 == e2 {
            return Err(ctx.err(e, "equality between two parts of the same rigid body"));
        }
        let name = e
            .attribute("name")
            .map_or_else(|| format!("equality{i}"), str::to_string);
        ctx.lines.insert(format!("joint[{name}]"), ctx.line(e));
        let (f1, f2) = (tree.engine_bodies[e1].1, tree.engine_bodies[e2].1);
        let (kind, point) = if tag == "connect" {
            let a = ctx
                .nums(e, "", "anchor", 3)?
                .ok_or_else(|| ctx.err(e, "`anchor` is required"))?;
            (
                JointKind::Spherical,
                tree.bodies[b1].world.point(&Vector3::from_column_slice(&a)),
            )
        } else {
            let relpose = ctx.nums(e, "", "relpose", 7)?;
            if relpose.is_some_and(|rp| rp[3..].iter().any(|x| *x != 0.0)) {
                return Err(ctx.unsupported(
                    e,
                    "weld with an explicit `relpose` (the reference pose is used when it is omitted)",
                ));
            }
            (JointKind::Fixed, tree.bodies[b1].world.pos)
        };
        let (parent, child) = (
            tree.engine_bodies[e1].0.clone(),
            tree.engine_bodies[e2].0.clone(),
        );
        b.add_joint(
            JointSpec::new(&name, kind, &parent, &child)
                .anchors(
                    f1.inverse_point(&point).into(),
                    f2.inverse_point(&point).into(),
                )
                .closing_loop(),
        );
    }
    Ok(())
}

/// `equality/joint`: `joint1 - qpos0₁ = Σ polycoef_i (joint2 - qpos0₂)^i` as a coupling.
fn read_joint_coupling<'a, 'i>(
    ctx: &mut Ctx<'a, 'i>,
    e: Node<'a, 'i>,
    index: usize,
    tree: &Tree,
    b: &mut ModelBuilder,
) -> Result<()> {
    let class = ctx.class_of(e, "main")?;
    let name = e
        .attribute("name")
        .map_or_else(|| format!("equality{index}"), str::to_string);
    ctx.lines.insert(format!("coupling[{name}]"), ctx.line(e));
    let joint = |attr: &str| -> Result<Option<(String, usize)>> {
        let Some(n) = e.attribute(attr) else {
            return Ok(None);
        };
        let map = tree
            .joints
            .iter()
            .find(|j| j.name == n)
            .ok_or_else(|| ctx.err(e, format!("attribute `{attr}` = {n:?}: unknown joint")))?;
        if map.kind != "hinge" && map.kind != "slide" {
            return Err(ctx.unsupported(
                e,
                format!(
                    "equality <joint> on {} joint {n:?} (hinge and slide only)",
                    map.kind
                ),
            ));
        }
        Ok(Some((map.engine_joint.clone(), map.dof)))
    };
    let joint1 = joint("joint1")?.ok_or_else(|| ctx.err(e, "`joint1` is required"))?;
    let joint2 = joint("joint2")?;
    let polycoef = ctx.nums_padded(e, &class, "polycoef", &[0.0, 1.0, 0.0, 0.0, 0.0])?;
    // the coefficients as written (the padding supplies MuJoCo's default polycoef[1] = 1)
    let written = match ctx.raw(e, &class, "polycoef") {
        Some(v) => ctx.floats(e, "polycoef", &v)?,
        None => Vec::new(),
    };
    if joint2.is_none() && written.iter().skip(1).any(|&c| c != 0.0) {
        // MuJoCo's semantics: without joint2 the constraint is joint1 = qpos0 + polycoef[0]
        ctx.warn(
            e,
            "equality <joint> without `joint2`: only polycoef[0] is used (joint1 held at its \
             qpos0 + polycoef[0]); the higher coefficients are ignored, as in MuJoCo",
        );
    }
    b.add_coupling(CouplingSpec {
        name,
        joint1,
        joint2,
        polycoef,
    });
    Ok(())
}

pub(super) fn read_contact<'a, 'i>(
    ctx: &mut Ctx<'a, 'i>,
    node: Node<'a, 'i>,
    tree: &Tree,
    b: &mut ModelBuilder,
) -> Result<()> {
    for e in elements(node) {
        match e.tag_name().name() {
            "exclude" => {}
            "pair" => {
                read_pair(ctx, e, b)?;
                continue;
            }
            _ => return Err(ctx.unsupported(e, "element is not supported (pair, exclude are)")),
        }
        let body = |attr: &str| -> Result<usize> {
            let n = e
                .attribute(attr)
                .ok_or_else(|| ctx.err(e, format!("`{attr}` is required")))?;
            tree.body_id(n)
                .ok_or_else(|| ctx.err(e, format!("attribute `{attr}` = {n:?}: unknown body")))
        };
        let (b1, b2) = (body("body1")?, body("body2")?);
        let (n1, n2) = (
            tree.engine_name(b1).to_string(),
            tree.engine_name(b2).to_string(),
        );
        if n1 != n2 {
            b.add_exclude(&n1, &n2);
        }
    }
    Ok(())
}

/// MuJoCo's damping ratios (`<position dampratio>`, or a `general` servo whose `biasprm[2]` is
/// positive and whose gain is its position gain, `gainprm[0] = -biasprm[1]`): each such
/// actuator's velocity gain becomes `kv = 2 · dampratio · sqrt(kp · m)`, with `m = 1 / (J M⁻¹
/// Jᵀ)` the inertia its transmission `J` (gear times each dof's coefficient) reflects at
/// `qpos0`, `M` the joint-space inertia there with armature (MuJoCo's `set0`). Critical
/// damping of the servo's dof at 1 when it alone moves.
pub(super) fn resolve_dampratios(model: &mut crate::Model) -> std::result::Result<(), String> {
    use crate::model::Transmission;
    let dampratio = |a: &crate::model::Actuator| a.bias[2] > 0.0 && a.gain == -a.bias[1];
    if !model.actuators.iter().any(dampratio) {
        return Ok(());
    }
    let inertia = joint_space_inertia(model)?;
    let lu = inertia.clone().lu();
    for a in 0..model.actuators.len() {
        let act = &model.actuators[a];
        if !dampratio(act) {
            continue;
        }
        let mut moment = nalgebra::DVector::zeros(model.nv);
        let mut add = |j: usize, dof: usize, coef: f64| {
            moment[model.joints[j].qvel_adr + dof] += act.gear * coef;
        };
        match &act.transmission {
            Transmission::Joint { joint, dof } => add(*joint, *dof, 1.0),
            Transmission::Tendon(terms) => terms.iter().for_each(|t| add(t.0, t.1, t.2)),
            Transmission::Site { .. } => {
                return Err(format!(
                    "actuator {:?}: a damping ratio on a site",
                    act.name
                ));
            }
        }
        let reflected = lu
            .solve(&moment)
            .map(|x| moment.dot(&x))
            .filter(|w| w.is_finite() && *w > 0.0)
            .ok_or_else(|| format!("actuator {:?}: no inertia reflected through its transmission at qpos0 for its dampratio", act.name))?;
        let (kp, ratio) = (act.gain, act.bias[2]);
        model.actuators[a].bias[2] = -2.0 * ratio * (kp / reflected).sqrt();
    }
    Ok(())
}

/// The joint-space inertia `M` (nv × nv) at `qpos0`, armature on its diagonal: `qvelᵀ M qvel`
/// is twice the kinetic energy of the bodies moving at `qvel`, so `M` follows from the energies
/// of the unit rates and of their pairwise sums.
fn joint_space_inertia(
    model: &crate::Model,
) -> std::result::Result<nalgebra::DMatrix<f64>, String> {
    use crate::mechanics::kinetic_energy;
    let nv = model.nv;
    let mut state = crate::State::reference(model);
    let mut energy = |qvel: &[f64]| -> std::result::Result<f64, String> {
        crate::set_minimal(model, &mut state, &model.qpos0, qvel).map_err(|e| e.to_string())?;
        Ok(kinetic_energy(model, &state))
    };
    let mut unit = vec![0.0; nv];
    let mut single = vec![0.0; nv];
    for (i, e) in single.iter_mut().enumerate() {
        unit[i] = 1.0;
        *e = energy(&unit)?;
        unit[i] = 0.0;
    }
    let mut m = nalgebra::DMatrix::zeros(nv, nv);
    for i in 0..nv {
        m[(i, i)] = 2.0 * single[i];
        for j in 0..i {
            unit[i] = 1.0;
            unit[j] = 1.0;
            let both = energy(&unit)?;
            unit[i] = 0.0;
            unit[j] = 0.0;
            let mij = both - single[i] - single[j];
            m[(i, j)] = mij;
            m[(j, i)] = mij;
        }
    }
    for joint in model.joints.iter().filter(|j| !j.is_loop) {
        for (r, arm) in joint.armature.iter().enumerate() {
            m[(joint.qvel_adr + r, joint.qvel_adr + r)] += arm;
        }
    }
    Ok(m)
}

/// MuJoCo's `inheritrange` of position servos: the control range is the centre of the joint's
/// (or fixed tendon's) range ± `inheritrange` times its half-width, in the servo's units (the
/// compiled joint limits, radians for hinges). A joint or tendon without a range is an error.
pub(super) fn resolve_inherited_ranges(
    ctx: &Ctx,
    model: &mut crate::Model,
    inherit: &[InheritRange],
) -> Result<()> {
    use crate::model::Transmission;
    for r in inherit {
        let act = &model.actuators[r.actuator];
        let range = match (&act.transmission, &r.tendon) {
            (Transmission::Joint { joint, dof }, _) => model.joints[*joint]
                .limits
                .iter()
                .find(|l| l.0 == *dof)
                .map(|l| (l.1, l.2)),
            (Transmission::Tendon(_), Some(name)) => model
                .tendon_limits
                .iter()
                .find(|t| &t.name == name)
                .map(|t| t.range),
            _ => None,
        };
        let Some((lo, hi)) = range else {
            return Err(ctx.err(
                r.node,
                format!(
                    "actuator {:?}: `inheritrange` needs a limited joint or tendon range",
                    act.name
                ),
            ));
        };
        let (centre, half) = (0.5 * (lo + hi), 0.5 * (hi - lo) * r.scale);
        model.actuators[r.actuator].ctrlrange = Some((centre - half, centre + half));
    }
    Ok(())
}

/// `<contact><pair>`: two named geoms that collide whatever their bit masks, bodies and
/// exclusions, in place of the pair MuJoCo's rules would make. Its `friction` and `condim`
/// come from the element or its class's `<pair>` defaults (MuJoCo's: 1 and 3), not from the
/// geoms. The soft-contact attributes (`solref`, `solimp`, `margin`, `gap`) are ignored, as on
/// geoms.
fn read_pair<'a, 'i>(ctx: &mut Ctx<'a, 'i>, e: Node<'a, 'i>, b: &mut ModelBuilder) -> Result<()> {
    let class = ctx.class_of(e, "main")?;
    let geom = |attr: &str| -> Result<String> {
        let n = e
            .attribute(attr)
            .ok_or_else(|| ctx.err(e, format!("`{attr}` is required")))?;
        if !b.has_geom(n) {
            return Err(ctx.err(e, format!("attribute `{attr}` = {n:?}: unknown geom")));
        }
        Ok(n.to_string())
    };
    let (geom_a, geom_b) = (geom("geom1")?, geom("geom2")?);
    let condim = ctx.int(e, &class, "condim", 3)?;
    if ![1, 3, 4, 6].contains(&condim) {
        return Err(ctx.err(
            e,
            format!("attribute `condim` = {condim}: expected 1, 3, 4 or 6"),
        ));
    }
    if condim > 3 {
        ctx.warn(
            e,
            format!("condim {condim} (torsional/rolling friction) is treated as condim 3"),
        );
    }
    // the element's numbers over its class's, over MuJoCo's (as MuJoCo reads a partial vector)
    let mut f = vec![1.0, 1.0, 0.005, 0.0001, 0.0001];
    let layers = [
        ctx.defaults.lookup(&class, "pair", "friction"),
        e.attribute("friction").map(str::to_string),
    ];
    for v in layers.into_iter().flatten() {
        let x = ctx.floats(e, "friction", &v)?;
        if x.is_empty() || x.len() > 5 {
            return Err(ctx.err(
                e,
                format!("attribute `friction` = {v:?}: need 1 to 5 numbers"),
            ));
        }
        f[..x.len()].copy_from_slice(&x);
    }
    if f[0] < 0.0 || f[1] < 0.0 {
        return Err(ctx.err(e, format!("attribute `friction` = {f:?}: must be >= 0")));
    }
    if f[1] != f[0] {
        ctx.warn(
            e,
            format!(
                "anisotropic friction {} / {} is simulated as {} (ukemi's cones are isotropic)",
                f[0], f[1], f[0]
            ),
        );
    }
    b.add_pair(PairSpec {
        geom_a,
        geom_b,
        friction: f[0],
        model: if condim == 1 {
            ContactModel::Impact
        } else {
            ContactModel::Nonlinear
        },
    });
    Ok(())
}
