//! `<tendon>`: fixed tendons as actuator transmissions, and the limits of limited fixed
//! tendons as [`TendonLimitSpec`]s (inequalities solved with the contacts).
use roxmltree::Node;

use super::body::Tree;
use super::parse::{Ctx, elements};
use crate::model::{PassiveTendonSpec, TendonLimitSpec};
use crate::{ModelBuilder, Result};

/// Fixed tendons by name: `(engine joint, free dof, coef)` per MJCF joint term.
pub(super) type Tendons = std::collections::HashMap<String, Vec<(String, usize, f64)>>;

/// Fixed tendons (for actuators), their limits, springs, dampers and dry friction (added to
/// `b`). Spring dead bands are unsupported; spatial tendons are ignored with a warning (a
/// limited one is reported as not enforced; one with stiffness, damping or friction is an
/// error).
pub(super) fn read_tendons<'a, 'i>(
    ctx: &mut Ctx<'a, 'i>,
    root: Node<'a, 'i>,
    tree: &Tree,
    b: &mut ModelBuilder,
) -> Result<Tendons> {
    let mut out = Tendons::new();
    let all = elements(root).filter(|n| n.tag_name().name() == "tendon");
    for (i, t) in all.flat_map(elements).enumerate() {
        let class = ctx.class_of(t, "main")?;
        let name = t.attribute("name").unwrap_or("").to_string();
        let set = |a: &str| {
            ctx.raw(t, &class, a)
                .is_some_and(|v| v.trim().parse::<f64>() != Ok(0.0))
        };
        let passive = set("stiffness") || set("damping") || set("frictionloss");
        if passive && t.tag_name().name() != "fixed" {
            return Err(ctx.unsupported(
                t,
                "spatial tendons with stiffness, damping or friction are not supported",
            ));
        }
        let limited = ctx.tristate(t, &class, "limited")?;
        let range = ctx.nums(t, &class, "range", 2)?;
        let limited = limited.unwrap_or(ctx.compiler.autolimits && range.is_some());
        if t.tag_name().name() != "fixed" {
            let what = if limited {
                format!(
                    "spatial tendon {name:?} ignored: its range {range:?} is NOT enforced (spatial tendons are not supported)"
                )
            } else {
                "spatial tendon ignored (no stiffness, damping or limits; actuators cannot use it)"
                    .to_string()
            };
            ctx.warn(t, what);
            continue;
        }
        let mut terms = Vec::new();
        for j in elements(t) {
            let jn = j.attribute("joint").unwrap_or("");
            let map =
                tree.joints.iter().find(|m| m.name == jn).ok_or_else(|| {
                    ctx.err(j, format!("attribute `joint` = {jn:?}: unknown joint"))
                })?;
            if map.kind != "hinge" && map.kind != "slide" {
                return Err(ctx.unsupported(j, format!("fixed tendon on a {} joint", map.kind)));
            }
            terms.push((
                map.engine_joint.clone(),
                map.dof,
                ctx.num(j, "", "coef", 0.0)?,
            ));
        }
        if limited {
            // MuJoCo: the range of a fixed tendon is in length units (coef · qpos, radians for
            // hinges), never converted by `compiler/@angle`
            let range = match range.as_deref() {
                Some(&[lo, hi]) if lo < hi => (lo, hi),
                _ => {
                    let got = ctx
                        .raw(t, &class, "range")
                        .unwrap_or_else(|| "(none)".into());
                    return Err(ctx.err(
                        t,
                        format!("limited tendon {name:?}: attribute `range` = {got:?}, need lower < upper"),
                    ));
                }
            };
            b.add_tendon_limit(TendonLimitSpec {
                name: if name.is_empty() {
                    format!("tendon{i}")
                } else {
                    name.clone()
                },
                terms: terms.clone(),
                range,
            });
        }
        if passive {
            let stiffness = ctx.num(t, &class, "stiffness", 0.0)?;
            let damping = ctx.num(t, &class, "damping", 0.0)?;
            let frictionloss = ctx.num(t, &class, "frictionloss", 0.0)?;
            if stiffness < 0.0 || damping < 0.0 || frictionloss < 0.0 {
                return Err(ctx.err(
                    t,
                    format!(
                        "stiffness {stiffness}, damping {damping} and frictionloss \
                         {frictionloss} must be >= 0"
                    ),
                ));
            }
            // MuJoCo's springlength: -1 (the default) is the length at qpos0; two different
            // values are a dead band
            let sl = ctx.nums_padded(t, &class, "springlength", &[-1.0, -1.0])?;
            let springlength = match (sl[0], sl[1]) {
                (a, b) if a == -1.0 && b == -1.0 => None,
                (a, b) if b == -1.0 || a == b => Some(a),
                _ => {
                    return Err(ctx.unsupported(t, format!("tendon springlength dead band {sl:?}")));
                }
            };
            b.add_passive_tendon(PassiveTendonSpec {
                name: if name.is_empty() {
                    format!("tendon{i}")
                } else {
                    name.clone()
                },
                terms: terms.clone(),
                stiffness,
                springlength,
                damping,
                frictionloss,
            });
        }
        out.insert(name, terms);
    }
    Ok(out)
}
