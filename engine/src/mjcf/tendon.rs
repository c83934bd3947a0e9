//! `<tendon>`: fixed tendons as actuator transmissions, and the limits of limited fixed
//! tendons as [`TendonLimitSpec`]s (inequalities solved with the contacts).
use roxmltree::Node;

use super::body::Tree;
use super::parse::{Ctx, elements};
use crate::model::TendonLimitSpec;
use crate::{ModelBuilder, Result};

/// Fixed tendons by name: `(engine joint, free dof, coef)` per MJCF joint term.
pub(super) type Tendons = std::collections::HashMap<String, Vec<(String, usize, f64)>>;

/// Fixed tendons (for actuators) and their limits (added to `b`). Stiffness, damping and
/// friction are unsupported; spatial tendons are ignored with a warning (a limited one is
/// reported as not enforced).
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
        let active = ["stiffness", "damping", "frictionloss"].iter().any(|a| {
            ctx.raw(t, &class, a)
                .is_some_and(|v| v.trim().parse::<f64>() != Ok(0.0))
        });
        if active {
            return Err(ctx.unsupported(
                t,
                "tendons with stiffness, damping or friction are not supported",
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
        out.insert(name, terms);
    }
    Ok(out)
}
