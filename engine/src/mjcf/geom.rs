//! `<geom>`: shape, size, pose (with `fromto`), contact attributes and mass properties.
use std::sync::Arc;

use nalgebra::Vector3;
use roxmltree::Node;

use super::frame::{Frame, local_frame, z_to};
use super::inertia::unit_inertia;
use super::parse::Ctx;
use crate::contact::hull::ConvexHull;
use crate::{Result, Shape};

/// A parsed geom, posed in its MJCF body's frame.
pub(super) struct GeomDef {
    pub name: String,
    pub line: usize,
    pub kind: String,
    pub size: Vec<f64>,
    pub frame: Frame,
    pub contype: u32,
    pub conaffinity: u32,
    pub condim: i64,
    pub friction: f64,
    /// Mass and principal inertia (about the geom origin, geom axes), if it counts for inertia.
    pub mass: Option<(f64, Vector3<f64>)>,
    /// Would contribute mass, but its type has no inertia formula here (height fields).
    pub mass_unsupported: bool,
    /// A mesh geom's convex hull (in `frame`, the mesh's principal frame).
    pub hull: Option<Arc<ConvexHull>>,
}

impl GeomDef {
    /// Never collides (`contype = conaffinity = 0`).
    pub fn visual(&self) -> bool {
        self.contype == 0 && self.conaffinity == 0
    }

    /// Collision shape (MuJoCo sizes).
    pub fn shape(&self) -> Option<Shape> {
        let s = &self.size;
        Some(match self.kind.as_str() {
            "plane" => Shape::Plane,
            "sphere" => Shape::Sphere { radius: s[0] },
            "capsule" => Shape::Capsule {
                radius: s[0],
                half_length: s[1],
            },
            "cylinder" => Shape::Cylinder {
                radius: s[0],
                half_length: s[1],
            },
            "box" => Shape::Box {
                half_extents: Vector3::new(s[0], s[1], s[2]),
            },
            "ellipsoid" => Shape::Ellipsoid {
                radii: Vector3::new(s[0], s[1], s[2]),
            },
            "mesh" => Shape::Mesh {
                hull: self.hull.clone()?,
            },
            _ => return None,
        })
    }
}

const KINDS: [&str; 9] = [
    "plane",
    "hfield",
    "sphere",
    "capsule",
    "ellipsoid",
    "cylinder",
    "box",
    "mesh",
    "sdf",
];

/// Parse a geom of body `body_name` (the `index`-th geom of it, for a default name).
pub(super) fn parse_geom<'a, 'i>(
    ctx: &mut Ctx<'a, 'i>,
    node: Node<'a, 'i>,
    class: &str,
    body_name: &str,
    index: usize,
) -> Result<GeomDef> {
    let kind = ctx.keyword(node, class, "type", &KINDS, "sphere")?;
    let name = node
        .attribute("name")
        .map_or_else(|| format!("{body_name}_geom{index}"), str::to_string);
    let line = ctx.line(node);
    ctx.lines.insert(format!("geom[{name}]"), line);
    let mut size = ctx.nums_padded(node, class, "size", &[0.0; 3])?;
    let mut frame = local_frame(ctx, node, class)?;
    if let Some(ft) = ctx.nums(node, class, "fromto", 6)? {
        if !["capsule", "cylinder", "box", "ellipsoid"].contains(&kind.as_str()) {
            return Err(ctx.err(node, format!("`fromto` does not apply to type {kind:?}")));
        }
        let (a, b) = (
            Vector3::new(ft[0], ft[1], ft[2]),
            Vector3::new(ft[3], ft[4], ft[5]),
        );
        let d = b - a;
        if d.norm() < 1e-12 {
            return Err(ctx.err(node, format!("attribute `fromto` = {ft:?}: zero length")));
        }
        frame = Frame {
            pos: (a + b) * 0.5,
            quat: z_to(&d),
        };
        let half = 0.5 * d.norm();
        match kind.as_str() {
            "capsule" | "cylinder" => size[1] = half,
            _ => size[2] = half,
        }
    }
    let contype = bits(ctx, node, class, "contype")?;
    let conaffinity = bits(ctx, node, class, "conaffinity")?;
    let condim = ctx.int(node, class, "condim", 3)?;
    if ![1, 3, 4, 6].contains(&condim) {
        return Err(ctx.err(
            node,
            format!("attribute `condim` = {condim}: expected 1, 3, 4 or 6"),
        ));
    }
    let friction = ctx.nums_padded(node, class, "friction", &[1.0, 0.005, 0.0001])?[0];
    if friction < 0.0 {
        return Err(ctx.err(
            node,
            format!("attribute `friction` = {friction}: must be >= 0"),
        ));
    }
    let group = ctx.int(node, class, "group", 0)?;
    let (lo, hi) = ctx.compiler.inertia_groups;
    let counts = group >= lo && group <= hi;
    let mass_attr = ctx.nums(node, class, "mass", 1)?.map(|v| v[0]);
    let density = ctx.num(node, class, "density", 1000.0)?;
    if mass_attr.is_some_and(|m| m < 0.0) || density < 0.0 {
        return Err(ctx.err(node, "`mass` and `density` must be >= 0"));
    }
    let wants_mass = counts && mass_attr.map_or(density > 0.0, |m| m > 0.0);
    // a mesh: its hull, placed at the mesh's principal frame, and the solid hull's mass (read
    // only where the geom collides or its mass sets its body's: visual meshes, often large
    // files, are not read)
    let (mut hull, mut mesh_mass) = (None, None);
    let collides = !(contype == 0 && conaffinity == 0) || ctx.paired.contains(&name);
    let weighs = wants_mass
        && match ctx.compiler.inertia_from_geom {
            Some(always) => always,
            None => node.parent().is_some_and(|body| {
                body.tag_name().name() == "body"
                    && !super::parse::elements(body).any(|c| c.tag_name().name() == "inertial")
            }),
        };
    if kind == "mesh" && (collides || weighs) {
        let Some(mesh_name) = ctx.raw(node, class, "mesh") else {
            return Err(ctx.err(node, "a mesh geom needs a `mesh`"));
        };
        let mesh = super::mesh::mesh(ctx, node, &mesh_name)?;
        frame = frame.compose(&mesh.frame);
        hull = Some(mesh.hull.clone());
        if weighs {
            let rho = mass_attr.map_or(density, |m| m / mesh.volume);
            mesh_mass = Some((rho * mesh.volume, mesh.moments * rho));
        }
    }
    let mass = match unit_inertia(&kind, &size) {
        _ if mesh_mass.is_some() => mesh_mass,
        Some((vol, unit)) if wants_mass => {
            if size.iter().take(size_count(&kind)).any(|s| *s <= 0.0) {
                return Err(ctx.err(
                    node,
                    format!("attribute `size` = {size:?}: sizes of a {kind} must be > 0"),
                ));
            }
            let rho = mass_attr.map_or(density, |m| m / vol);
            Some((rho * vol, unit * rho))
        }
        _ => None,
    };
    let mass_unsupported = wants_mass && mass.is_none() && kind != "plane";
    Ok(GeomDef {
        mass_unsupported,
        name,
        line,
        kind,
        size,
        frame,
        contype,
        conaffinity,
        condim,
        friction,
        mass,
        hull,
    })
}

fn size_count(kind: &str) -> usize {
    match kind {
        "sphere" => 1,
        "capsule" | "cylinder" => 2,
        _ => 3,
    }
}

fn bits<'a, 'i>(ctx: &Ctx<'a, 'i>, node: Node<'a, 'i>, class: &str, name: &str) -> Result<u32> {
    let v = ctx.int(node, class, name, 1)?;
    u32::try_from(v).map_err(|_| {
        ctx.err(
            node,
            format!("attribute `{name}` = {v}: expected a bit mask in [0, 2^32)"),
        )
    })
}
