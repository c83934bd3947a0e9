//! The joints of one MJCF body become one engine joint whose free dofs are MuJoCo's dofs in
//! MuJoCo's order: slides first (explicit translation axes), then 1-3 hinges in sequence, each
//! about its own anchor (explicit hinge axes, possibly non-orthogonal), or a ball; or a free
//! joint alone.
use nalgebra::Vector3;
use roxmltree::Node;

use super::parse::Ctx;
use crate::{JointKind, JointSpec, Result};

/// One MuJoCo joint, parsed.
pub(super) struct JointDef<'a, 'i> {
    pub node: Node<'a, 'i>,
    pub name: String,
    pub kind: String,
    pub pos: Vector3<f64>,
    pub axis: Vector3<f64>,
    /// `(lower, upper)` if limited (radians for hinges).
    pub range: Option<(f64, f64)>,
    pub stiffness: f64,
    pub damping: f64,
    pub armature: f64,
    /// Dry friction (`frictionloss`, N or N·m).
    pub frictionloss: f64,
    pub springref: f64,
    pub qpos_ref: f64,
    /// Clamp of the total actuator force on the joint (`actuatorfrcrange`, when limited).
    pub actfrcrange: Option<(f64, f64)>,
}

/// Where a MuJoCo joint lives in the engine.
#[derive(Clone, Debug)]
pub(super) struct JointMap {
    pub name: String,
    pub kind: String,
    pub engine_joint: String,
    /// First free dof of this MuJoCo joint within the engine joint.
    pub dof: usize,
    /// `actuatorfrcrange` (when limited) and the joint element, for its warnings.
    pub actfrcrange: Option<((f64, f64), roxmltree::NodeId)>,
}

pub(super) fn parse_joint<'a, 'i>(
    ctx: &mut Ctx<'a, 'i>,
    node: Node<'a, 'i>,
    class: &str,
    default_name: String,
) -> Result<JointDef<'a, 'i>> {
    let free_elem = node.tag_name().name() == "freejoint";
    let kind = if free_elem {
        "free".to_string()
    } else {
        ctx.keyword(
            node,
            class,
            "type",
            &["hinge", "slide", "ball", "free"],
            "hinge",
        )?
    };
    let name = node.attribute("name").map_or(default_name, str::to_string);
    ctx.lines.insert(format!("joint[{name}]"), ctx.line(node));
    let v3 = |ctx: &Ctx<'a, 'i>, a: &str, d: [f64; 3]| -> Result<Vector3<f64>> {
        let v = if free_elem {
            None
        } else {
            ctx.nums(node, class, a, 3)?
        };
        Ok(Vector3::from_column_slice(&v.unwrap_or(d.to_vec())))
    };
    let pos = v3(ctx, "pos", [0.0; 3])?;
    let axis = v3(ctx, "axis", [0.0, 0.0, 1.0])?;
    if axis.norm() < 1e-12 {
        return Err(ctx.err(
            node,
            format!("attribute `axis` = {:?}: zero vector", axis.as_slice()),
        ));
    }
    let angular = kind == "hinge" || kind == "ball";
    let conv = |ctx: &Ctx, x: f64| if angular { ctx.angle(x) } else { x };
    let num = |ctx: &Ctx<'a, 'i>, a: &str| -> Result<f64> {
        if free_elem {
            Ok(0.0)
        } else {
            ctx.num(node, class, a, 0.0)
        }
    };
    let range_attr = if free_elem {
        None
    } else {
        ctx.nums(node, class, "range", 2)?
    };
    let limited = if free_elem {
        Some(false)
    } else {
        ctx.tristate(node, class, "limited")?
    };
    let limited = limited.unwrap_or(ctx.compiler.autolimits && range_attr.is_some());
    let range = match (limited, range_attr) {
        (false, _) => None,
        (true, None) => return Err(ctx.err(node, "limited=\"true\" needs a `range`")),
        (true, Some(r)) => {
            let (lo, hi) = (conv(ctx, r[0]), conv(ctx, r[1]));
            if lo >= hi && kind != "ball" {
                return Err(ctx.err(
                    node,
                    format!("attribute `range` = {r:?}: need lower < upper"),
                ));
            }
            Some((lo, hi))
        }
    };
    let def = JointDef {
        node,
        stiffness: num(ctx, "stiffness")?,
        damping: num(ctx, "damping")?,
        armature: num(ctx, "armature")?,
        frictionloss: num(ctx, "frictionloss")?,
        springref: conv(ctx, num(ctx, "springref")?),
        qpos_ref: conv(ctx, num(ctx, "ref")?),
        actfrcrange: actuator_force_range(ctx, node, class, free_elem)?,
        name,
        kind,
        pos,
        axis: axis.normalize(),
        range,
    };
    for (what, v) in [
        ("stiffness", def.stiffness),
        ("damping", def.damping),
        ("armature", def.armature),
        ("frictionloss", def.frictionloss),
    ] {
        if v < 0.0 {
            return Err(ctx.err(node, format!("attribute `{what}` = {v}: must be >= 0")));
        }
    }
    Ok(def)
}

/// `actuatorfrcrange` where it is limited (explicitly or by `autolimits`): MuJoCo clamps the
/// joint's total actuator force to it.
fn actuator_force_range<'a, 'i>(
    ctx: &Ctx<'a, 'i>,
    node: Node<'a, 'i>,
    class: &str,
    free_elem: bool,
) -> Result<Option<(f64, f64)>> {
    if free_elem {
        return Ok(None);
    }
    let range = ctx.nums(node, class, "actuatorfrcrange", 2)?;
    let limited = ctx.tristate(node, class, "actuatorfrclimited")?;
    match (
        limited.unwrap_or(ctx.compiler.autolimits && range.is_some()),
        range,
    ) {
        (false, _) => Ok(None),
        (true, Some(r)) if r[0] <= r[1] => Ok(Some((r[0], r[1]))),
        (true, r) => Err(ctx.err(
            node,
            format!("attribute `actuatorfrcrange` = {r:?}: need lower <= upper when limited"),
        )),
    }
}

/// The engine joint of one body's MuJoCo joints, and the map of each MuJoCo joint to its dofs.
/// `parent_anchor` maps a point of the child body frame to the parent body frame.
pub(super) fn group_joints(
    ctx: &Ctx,
    body_node: Node,
    body: &str,
    parent: &str,
    joints: &[JointDef],
    parent_anchor: impl Fn(&Vector3<f64>) -> Vector3<f64>,
) -> Result<(JointSpec, Vec<JointMap>)> {
    let unsupported = |msg: String| ctx.unsupported(body_node, msg);
    let n_free = joints.iter().filter(|j| j.kind == "free").count();
    let slides: Vec<&JointDef> = joints.iter().filter(|j| j.kind == "slide").collect();
    let rots: Vec<&JointDef> = joints.iter().filter(|j| j.kind != "slide").collect();
    if n_free > 0 && joints.len() > 1 {
        return Err(unsupported(format!(
            "body {body:?}: a free joint must be the body's only joint"
        )));
    }
    if let Some(i) = joints.iter().position(|j| j.kind != "slide")
        && joints[i..].iter().any(|j| j.kind == "slide")
    {
        return Err(unsupported(format!(
            "body {body:?}: a slide joint after a hinge/ball joint (its axis would turn with the hinge); put the slides first"
        )));
    }
    let nball = rots.iter().filter(|j| j.kind == "ball").count();
    if nball > 0 && rots.len() > 1 {
        return Err(unsupported(format!(
            "body {body:?}: a ball joint combined with other rotational joints"
        )));
    }
    if rots.len() > 3 {
        return Err(unsupported(format!(
            "body {body:?}: more than three hinge joints"
        )));
    }
    if nball > 0
        && let Some(other) = rots.iter().find(|j| (j.pos - rots[0].pos).norm() > 1e-9)
    {
        return Err(unsupported(format!(
            "body {body:?}: ball joint and {:?} have different positions",
            other.name
        )));
    }
    let names: Vec<&str> = joints.iter().map(|j| j.name.as_str()).collect();
    let name = names.join("+");
    let anchor = rots.first().map_or(joints[0].pos, |j| j.pos);
    let nrot = if nball > 0 { 3 } else { rots.len() };
    let kind = if n_free > 0 {
        JointKind::Floating
    } else {
        JointKind::ALL[4 * nrot + slides.len()]
    };
    let mut spec = JointSpec::new(&name, kind, parent, body);
    if n_free == 0 {
        spec = spec.anchors(parent_anchor(&anchor).into(), anchor.into());
        spec.trans_axes = slides.iter().map(|j| j.axis).collect();
        if nball == 0 {
            spec.rot_axes = rots.iter().map(|j| j.axis).collect();
            // each hinge turns about its own anchor, in sequence (joints::offsets)
            spec.hinge_offsets = rots.windows(2).map(|w| w[1].pos - w[0].pos).collect();
        }
    }
    // per free dof (MuJoCo order: slides, then hinges or the ball's three)
    let nfree = kind.ntrans() + kind.nrot();
    let per_dof: Vec<&JointDef> = joints
        .iter()
        .flat_map(|j| {
            let n = match j.kind.as_str() {
                "free" => 6,
                "ball" => 3,
                _ => 1,
            };
            std::iter::repeat_n(j, n)
        })
        .collect();
    debug_assert_eq!(per_dof.len(), nfree);
    spec.stiffness = per_dof.iter().map(|j| j.stiffness).collect();
    spec.damping = per_dof.iter().map(|j| j.damping).collect();
    spec.armature = per_dof.iter().map(|j| j.armature).collect();
    spec.frictionloss = per_dof.iter().map(|j| j.frictionloss).collect();
    if joints.iter().any(|j| j.range.is_some()) {
        if n_free + nball > 0 {
            let j = joints
                .iter()
                .find(|j| j.range.is_some())
                .map_or(body_node, |j| j.node);
            return Err(ctx.unsupported(
                j,
                "limits on ball or free joints (a cone on the rotation) are not supported",
            ));
        }
        spec.range = Some(
            per_dof
                .iter()
                .map(|j| j.range.unwrap_or((f64::NEG_INFINITY, f64::INFINITY)))
                .collect(),
        );
    }
    if n_free + nball == 0 {
        spec.qpos_ref = per_dof.iter().map(|j| j.qpos_ref).collect();
        // MuJoCo's qpos_spring, whether or not the joint has a spring: a passive tendon's
        // default rest length is measured there
        spec.spring_ref = Some(per_dof.iter().map(|j| j.springref).collect());
    } else if joints.iter().any(|j| j.stiffness != 0.0) {
        if n_free > 0 {
            return Err(unsupported(format!(
                "body {body:?}: stiffness on a free joint"
            )));
        }
        // a ball spring pulls towards the reference pose (MuJoCo's qpos_spring = qpos0)
        let mut r: Vec<f64> = slides.iter().map(|j| j.springref).collect();
        r.extend([1.0, 0.0, 0.0, 0.0]);
        spec.spring_ref = Some(r);
    }
    let mut maps = Vec::new();
    let mut dof = 0;
    for j in joints {
        maps.push(JointMap {
            name: j.name.clone(),
            kind: j.kind.clone(),
            engine_joint: name.clone(),
            dof,
            actfrcrange: j.actfrcrange.map(|r| (r, j.node.id())),
        });
        dof += match j.kind.as_str() {
            "free" => 6,
            "ball" => 3,
            _ => 1,
        };
    }
    Ok((spec, maps))
}
