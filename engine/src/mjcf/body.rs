//! The `<worldbody>` tree: bodies, their mass properties, joints and geoms, added to the
//! [`ModelBuilder`].
//!
//! Body frames are MuJoCo's. A body without joints under the world is static: its geoms join the
//! world. A body without joints under a moving body is welded to it by a `fixed` joint when it
//! has mass, and merged into it (geoms only) when it has none.
use nalgebra::{Matrix3, Vector3};
use roxmltree::Node;

use super::frame::{Frame, local_frame, orientation};
use super::geom::{GeomDef, parse_geom};
use super::inertia::MassProps;
use super::joint::{JointDef, JointMap, group_joints, parse_joint};
use super::parse::{Ctx, elements};
use crate::contact::ContactModel;
use crate::math::quat;
use crate::{BodySpec, GeomSpec, JointKind, JointSpec, ModelBuilder, Result};

/// One MJCF body (index 0 is the world).
pub(super) struct BodyInfo {
    pub name: String,
    pub world: Frame,
    /// Engine body this MJCF body belongs to (0 = world).
    pub engine: usize,
    pub has_joints: bool,
    pub mass: f64,
}

/// A geom placed on an engine body (for pair checks).
pub(super) struct PlacedGeom {
    pub name: String,
    pub engine_body: usize,
    pub def: GeomDef,
}

/// What the tree walk produces.
#[derive(Default)]
pub(super) struct Tree {
    pub bodies: Vec<BodyInfo>,
    /// Engine bodies: (name, world frame); index 0 is the world.
    pub engine_bodies: Vec<(String, Frame)>,
    /// Engine parent of each engine body (through its tree joint).
    pub engine_parent: Vec<usize>,
    pub joints: Vec<JointMap>,
    pub geoms: Vec<PlacedGeom>,
    /// Sites: (name, MJCF body, frame in that body).
    pub sites: Vec<(String, usize, Frame)>,
    /// World geoms read so far (unnamed ones are numbered across every `<worldbody>`).
    world_geoms: usize,
}

impl Tree {
    pub fn engine_name(&self, body: usize) -> &str {
        &self.engine_bodies[self.bodies[body].engine].0
    }
    pub fn body_id(&self, name: &str) -> Option<usize> {
        self.bodies.iter().position(|b| b.name == name)
    }
}

/// The body tree of every `<worldbody>` (MuJoCo merges them: an included robot file and its
/// scene each bring one).
pub(super) fn read_worldbody<'a, 'i>(
    ctx: &mut Ctx<'a, 'i>,
    worlds: &[Node<'a, 'i>],
    b: &mut ModelBuilder,
) -> Result<Tree> {
    let mut tree = Tree::default();
    tree.bodies.push(BodyInfo {
        name: "world".into(),
        world: Frame::identity(),
        engine: 0,
        has_joints: false,
        mass: 0.0,
    });
    tree.engine_bodies.push(("world".into(), Frame::identity()));
    tree.engine_parent.push(0);
    for &world in worlds {
        let class = ctx.class_of(world, "main")?;
        read_children(ctx, world, 0, &class, &mut tree, b)?;
    }
    Ok(tree)
}

fn read_children<'a, 'i>(
    ctx: &mut Ctx<'a, 'i>,
    node: Node<'a, 'i>,
    body: usize,
    class: &str,
    tree: &mut Tree,
    b: &mut ModelBuilder,
) -> Result<()> {
    let mut geom_index = if body == 0 { tree.world_geoms } else { 0 };
    for child in elements(node) {
        match child.tag_name().name() {
            "body" => read_body(ctx, child, body, class, tree, b)?,
            "geom" if body == 0 => {
                let c = ctx.class_of(child, class)?;
                let g = parse_geom(ctx, child, &c, "world", geom_index)?;
                geom_index += 1;
                place_geom(ctx, child, tree, b, 0, g)?;
            }
            "geom" | "joint" | "freejoint" | "inertial" => {}
            "site" => {
                let c = ctx.class_of(child, class)?;
                let frame = local_frame(ctx, child, &c)?;
                let name = child.attribute("name").unwrap_or("").to_string();
                tree.sites.push((name, body, frame));
            }
            "camera" | "light" => {}
            "frame" | "composite" | "flexcomp" | "replicate" | "attach" | "plugin" => {
                return Err(
                    ctx.unsupported(child, "element is not supported by the ukemi MJCF loader")
                );
            }
            other => return Err(ctx.err(child, format!("unknown element <{other}> in a body"))),
        }
    }
    if body == 0 {
        tree.world_geoms = geom_index;
    }
    Ok(())
}

fn read_body<'a, 'i>(
    ctx: &mut Ctx<'a, 'i>,
    node: Node<'a, 'i>,
    parent: usize,
    parent_class: &str,
    tree: &mut Tree,
    b: &mut ModelBuilder,
) -> Result<()> {
    let idx = tree.bodies.len();
    let name = node
        .attribute("name")
        .map_or_else(|| format!("body{idx}"), str::to_string);
    if tree.body_id(&name).is_some() {
        return Err(ctx.err(node, format!("duplicate body name {name:?}")));
    }
    ctx.lines.insert(format!("body[{name}]"), ctx.line(node));
    let class = match node.attribute("childclass") {
        Some(c) if ctx.defaults.has(c) => c.to_string(),
        Some(c) => {
            return Err(ctx.err(
                node,
                format!("attribute `childclass` = {c:?}: unknown default class"),
            ));
        }
        None => parent_class.to_string(),
    };
    if node.attribute("mocap") == Some("true") {
        return Err(ctx.unsupported(node, "mocap bodies are not supported"));
    }
    let world = tree.bodies[parent]
        .world
        .compose(&local_frame(ctx, node, "")?);
    // joints and geoms of this body
    let mut joints: Vec<JointDef> = Vec::new();
    let mut geoms: Vec<(Node, GeomDef)> = Vec::new();
    let mut inertial = None;
    for child in elements(node) {
        let c = ctx.class_of(child, &class)?;
        match child.tag_name().name() {
            "joint" | "freejoint" => {
                let default_name = format!("{name}_joint{}", joints.len());
                joints.push(parse_joint(ctx, child, &c, default_name)?);
            }
            "geom" => {
                let g = parse_geom(ctx, child, &c, &name, geoms.len())?;
                geoms.push((child, g));
            }
            "inertial" => {
                if inertial.is_some() {
                    return Err(ctx.err(child, "more than one <inertial>"));
                }
                inertial = Some(child);
            }
            _ => {}
        }
    }
    let mut props = mass_props(ctx, node, inertial, &geoms)?;
    props.0 *= ctx.mass_scale;
    props.2 *= ctx.mass_scale;
    let parent_engine = tree.bodies[parent].engine;
    let has_joints = !joints.is_empty();
    let engine = if has_joints || (parent_engine != 0 && props.0 > 0.0) {
        add_engine_body(ctx, node, &name, &world, &props, tree, b)?;
        tree.engine_parent.push(parent_engine);
        tree.engine_bodies.len() - 1
    } else {
        parent_engine
    };
    tree.bodies.push(BodyInfo {
        name: name.clone(),
        world,
        engine,
        has_joints,
        mass: props.0,
    });
    if engine != parent_engine {
        let parent_frame = tree.engine_bodies[parent_engine].1;
        let pname = tree.engine_bodies[parent_engine].0.clone();
        if has_joints {
            let (spec, maps) = group_joints(ctx, node, &name, &pname, &joints, |p| {
                parent_frame.inverse_point(&world.point(p))
            })?;
            b.add_joint(spec);
            tree.joints.extend(maps);
        } else {
            let anchor = parent_frame.inverse_point(&world.pos);
            b.add_joint(
                JointSpec::new(&format!("{name}_weld"), JointKind::Fixed, &pname, &name)
                    .anchors(anchor.into(), [0.0; 3]),
            );
        }
    }
    for (child, g) in geoms {
        place_geom(ctx, child, tree, b, idx, g)?;
    }
    read_children(ctx, node, idx, &class, tree, b)
}

/// Mass, COM and full inertia (body frame) from `<inertial>` or from the geoms.
fn mass_props<'a, 'i>(
    ctx: &Ctx<'a, 'i>,
    body: Node<'a, 'i>,
    inertial: Option<Node<'a, 'i>>,
    geoms: &[(Node<'a, 'i>, GeomDef)],
) -> Result<(f64, Vector3<f64>, Matrix3<f64>)> {
    let from_geoms = match ctx.compiler.inertia_from_geom {
        Some(v) => v,
        None => inertial.is_none(),
    };
    if !from_geoms {
        let Some(n) = inertial else {
            return Ok((0.0, Vector3::zeros(), Matrix3::zeros()));
        };
        let mass = ctx
            .nums(n, "", "mass", 1)?
            .ok_or_else(|| ctx.err(n, "`mass` is required"))?[0];
        let pos = ctx
            .nums(n, "", "pos", 3)?
            .ok_or_else(|| ctx.err(n, "`pos` is required"))?;
        let q = orientation(ctx, n, "")?;
        let inertia = match (
            ctx.nums(n, "", "diaginertia", 3)?,
            ctx.nums(n, "", "fullinertia", 6)?,
        ) {
            (Some(d), None) => {
                let r = quat::rotation(&q);
                r * Matrix3::from_diagonal(&Vector3::from_column_slice(&d)) * r.transpose()
            }
            (None, Some(f)) => {
                let r = quat::rotation(&q);
                let m = Matrix3::new(f[0], f[3], f[4], f[3], f[1], f[5], f[4], f[5], f[2]);
                r * m * r.transpose()
            }
            _ => return Err(ctx.err(n, "need exactly one of `diaginertia` and `fullinertia`")),
        };
        if mass < 0.0 {
            return Err(ctx.err(n, format!("attribute `mass` = {mass}: must be >= 0")));
        }
        return Ok((mass, Vector3::from_column_slice(&pos), inertia));
    }
    let mut acc = MassProps::default();
    for (n, g) in geoms {
        if g.mass_unsupported {
            return Err(ctx.unsupported(
                *n,
                format!(
                    "geom {:?} of type {:?} would set the inertia of body {:?}; give the body an <inertial> or the geom mass=\"0\"",
                    g.name, g.kind, body.attribute("name").unwrap_or("")
                ),
            ));
        }
        if let Some((m, i)) = &g.mass {
            acc.add(*m, i, &g.frame.pos, &g.frame.quat);
        }
    }
    let (c, i) = acc.com_inertia();
    Ok((acc.mass, c, i))
}

fn add_engine_body<'a, 'i>(
    ctx: &Ctx<'a, 'i>,
    node: Node<'a, 'i>,
    name: &str,
    world: &Frame,
    props: &(f64, Vector3<f64>, Matrix3<f64>),
    tree: &mut Tree,
    b: &mut ModelBuilder,
) -> Result<()> {
    let (mass, com, inertia) = props;
    if *mass <= 0.0 {
        return Err(ctx.err(
            node,
            format!(
                "body {name:?} moves but has mass {mass}: give it an <inertial> or geoms with mass"
            ),
        ));
    }
    // MuJoCo's gravity compensation (a passive force: `actuatorgravcomp` would route it through
    // the joints' actuator force limits, which ukemi does not model)
    let gravcomp = ctx.num(node, "", "gravcomp", 0.0)?;
    b.add_body(
        BodySpec::new(name, *mass, [1.0; 3])
            .inertia_matrix(*inertia)
            .com((*com).into())
            .pos(world.pos.into())
            .quat(world.wxyz())
            .gravcomp(gravcomp),
    );
    tree.engine_bodies.push((name.to_string(), *world));
    Ok(())
}

/// Add a collision geom to the engine body of MJCF body `body` (visual geoms are skipped).
fn place_geom<'a, 'i>(
    ctx: &mut Ctx<'a, 'i>,
    node: Node<'a, 'i>,
    tree: &mut Tree,
    b: &mut ModelBuilder,
    body: usize,
    g: GeomDef,
) -> Result<()> {
    if g.visual() && !ctx.paired.contains(&g.name) {
        return Ok(());
    }
    let Some(shape) = g.shape() else {
        return Err(ctx.unsupported(
            node,
            format!("collision with geom {:?} of type {:?} (set contype=\"0\" conaffinity=\"0\" to keep it visual)", g.name, g.kind),
        ));
    };
    let engine = tree.bodies[body].engine;
    if engine != 0 && g.kind == "plane" {
        return Err(ctx.unsupported(node, format!("plane geom {:?} on a moving body", g.name)));
    }
    let on_body = tree.engine_bodies[engine]
        .1
        .relative(&tree.bodies[body].world.compose(&g.frame));
    let model = if g.condim == 1 {
        ContactModel::Impact
    } else {
        ContactModel::Nonlinear
    };
    if g.condim > 3 {
        ctx.warn(
            node,
            format!(
                "condim {} (torsional/rolling friction) is treated as condim 3",
                g.condim
            ),
        );
    }
    let mut spec = GeomSpec::new(&g.name, &tree.engine_bodies[engine].0, shape)
        .pos(on_body.pos.into())
        .quat(on_body.wxyz())
        .friction(g.friction)
        .model(Some(model));
    spec.contype = g.contype;
    spec.conaffinity = g.conaffinity;
    b.add_geom(spec);
    tree.geoms.push(PlacedGeom {
        name: g.name.clone(),
        engine_body: engine,
        def: g,
    });
    Ok(())
}
