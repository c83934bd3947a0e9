//! URDF elements → plain structs (links, joints), every value checked and every error located.
use std::path::{Path, PathBuf};

use nalgebra::{Matrix3, Rotation3, Vector3};
use roxmltree::{Document, Node};

use crate::{Error, Result};

/// A rigid transform `parent_from_child` (URDF `<origin xyz rpy>`).
#[derive(Clone, Copy, Debug)]
pub(super) struct Transform {
    pub pos: Vector3<f64>,
    pub rot: Matrix3<f64>,
}

impl Transform {
    pub fn identity() -> Self {
        Transform {
            pos: Vector3::zeros(),
            rot: Matrix3::identity(),
        }
    }
    /// `self ∘ other`: `a_from_c = a_from_b * b_from_c`.
    pub fn compose(&self, other: &Transform) -> Transform {
        Transform {
            pos: self.pos + self.rot * other.pos,
            rot: self.rot * other.rot,
        }
    }
}

/// Mass properties of a link: COM and inertia about it, both in the link frame.
#[derive(Clone, Debug)]
pub(super) struct Inertial {
    pub mass: f64,
    pub com: Vector3<f64>,
    pub inertia: Matrix3<f64>,
    pub line: usize,
}

/// A collision primitive, sizes in MJCF convention (half lengths).
#[derive(Clone, Debug)]
pub(super) enum Primitive {
    Box([f64; 3]),
    Cylinder {
        radius: f64,
        half_length: f64,
    },
    Sphere(f64),
    Capsule {
        radius: f64,
        half_length: f64,
    },
    /// A mesh file (resolved) and its scale: collides as its convex hull.
    Mesh {
        path: PathBuf,
        scale: [f64; 3],
    },
}

#[derive(Clone, Debug)]
pub(super) struct Collision {
    pub origin: Transform,
    pub shape: Primitive,
    pub line: usize,
}

#[derive(Clone, Debug)]
pub(super) struct Link {
    pub name: String,
    pub line: usize,
    pub inertial: Option<Inertial>,
    pub collisions: Vec<Collision>,
}

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(super) enum JointType {
    Revolute,
    Continuous,
    Prismatic,
    Fixed,
    Floating,
    Planar,
}

#[derive(Clone, Debug)]
pub(super) struct Joint {
    pub name: String,
    pub line: usize,
    pub kind: JointType,
    pub parent: String,
    pub child: String,
    /// Joint frame = child link frame, in the parent link frame.
    pub origin: Transform,
    /// Unit axis in the joint (child link) frame.
    pub axis: Vector3<f64>,
    pub range: Option<(f64, f64)>,
    pub effort: Option<f64>,
    pub damping: f64,
    /// `<dynamics friction>`: Coulomb (dry) joint friction, N·m or N.
    pub friction: f64,
    /// `<mimic>`: this joint follows another.
    pub mimic: Option<Mimic>,
}

/// `<mimic joint multiplier offset>`: `q = multiplier q_leader + offset`.
#[derive(Clone, Debug)]
pub(super) struct Mimic {
    pub leader: String,
    pub multiplier: f64,
    pub offset: f64,
    pub line: usize,
}

#[derive(Debug)]
pub(super) struct Robot {
    pub links: Vec<Link>,
    pub joints: Vec<Joint>,
    pub warnings: Vec<String>,
}

pub(super) struct Parser<'s> {
    pub source: &'s str,
    pub doc: &'s Document<'s>,
    /// The URDF file's folder (mesh files are found from it; none: the working directory).
    pub dir: Option<&'s Path>,
}

impl Parser<'_> {
    pub fn line(&self, node: Node) -> usize {
        self.doc.text_pos_at(node.range().start).row as usize
    }
    pub fn err(&self, node: Node, msg: impl Into<String>) -> Error {
        Error::Urdf {
            source_name: self.source.to_string(),
            line: self.line(node),
            msg: format!("<{}>: {}", node.tag_name().name(), msg.into()),
        }
    }
    fn nums(&self, node: Node, attr: &str, n: usize) -> Result<Option<Vec<f64>>> {
        let Some(text) = node.attribute(attr) else {
            return Ok(None);
        };
        let parsed: std::result::Result<Vec<f64>, _> =
            text.split_whitespace().map(str::parse::<f64>).collect();
        match parsed {
            Ok(v) if v.len() == n && v.iter().all(|x| x.is_finite()) => Ok(Some(v)),
            _ => Err(self.err(
                node,
                format!("attribute `{attr}` = {text:?}: expected {n} finite number(s)"),
            )),
        }
    }
    fn num(&self, node: Node, attr: &str) -> Result<Option<f64>> {
        Ok(self.nums(node, attr, 1)?.map(|v| v[0]))
    }
    fn required(&self, node: Node, attr: &str) -> Result<f64> {
        self.num(node, attr)?
            .ok_or_else(|| self.err(node, format!("attribute `{attr}` is required")))
    }
    fn positive(&self, node: Node, attr: &str) -> Result<f64> {
        let v = self.required(node, attr)?;
        if v > 0.0 {
            Ok(v)
        } else {
            Err(self.err(node, format!("attribute `{attr}` = {v}: must be > 0")))
        }
    }
    fn name<'a>(&self, node: Node<'a, '_>) -> Result<&'a str> {
        node.attribute("name")
            .filter(|n| !n.is_empty())
            .ok_or_else(|| self.err(node, "attribute `name` is required"))
    }

    /// `<origin xyz rpy>` of `node`'s child (identity when absent). rpy: fixed axes x, y, z,
    /// i.e. `R = Rz(yaw) Ry(pitch) Rx(roll)`.
    fn origin(&self, node: Node) -> Result<Transform> {
        let mut origins = children(node, "origin");
        let Some(o) = origins.next() else {
            return Ok(Transform::identity());
        };
        if let Some(extra) = origins.next() {
            return Err(self.err(extra, "more than one <origin>"));
        }
        let xyz = self.nums(o, "xyz", 3)?.unwrap_or(vec![0.0; 3]);
        let rpy = self.nums(o, "rpy", 3)?.unwrap_or(vec![0.0; 3]);
        Ok(Transform {
            pos: Vector3::from_column_slice(&xyz),
            rot: *Rotation3::from_euler_angles(rpy[0], rpy[1], rpy[2]).matrix(),
        })
    }

    pub fn robot(&self) -> Result<Robot> {
        let root = self.doc.root_element();
        if root.tag_name().name() != "robot" {
            return Err(self.err(root, "the root element must be <robot>"));
        }
        let mut robot = Robot {
            links: vec![],
            joints: vec![],
            warnings: vec![],
        };
        for node in root.children().filter(Node::is_element) {
            match node.tag_name().name() {
                "link" => {
                    let link = self.link(node)?;
                    if robot.links.iter().any(|l| l.name == link.name) {
                        return Err(self.err(node, format!("duplicate link name {:?}", link.name)));
                    }
                    robot.links.push(link);
                }
                "joint" => {
                    let joint = self.joint(node, &mut robot.warnings)?;
                    if robot.joints.iter().any(|j| j.name == joint.name) {
                        return Err(
                            self.err(node, format!("duplicate joint name {:?}", joint.name))
                        );
                    }
                    robot.joints.push(joint);
                }
                "material" | "transmission" | "gazebo" => {}
                other => robot.warnings.push(format!(
                    "URDF {}:{}: element <{other}> ignored",
                    self.source,
                    self.line(node)
                )),
            }
        }
        Ok(robot)
    }

    fn link(&self, node: Node) -> Result<Link> {
        let name = self.name(node)?.to_string();
        let mut inertial = None;
        let mut collisions = vec![];
        for child in node.children().filter(Node::is_element) {
            match child.tag_name().name() {
                "inertial" => {
                    if inertial.is_some() {
                        return Err(self.err(child, "more than one <inertial>"));
                    }
                    inertial = Some(self.inertial(child)?);
                }
                "collision" => collisions.push(self.collision(child, &name)?),
                _ => {} // visual (meshes included) is display only
            }
        }
        Ok(Link {
            name,
            line: self.line(node),
            inertial,
            collisions,
        })
    }

    fn inertial(&self, node: Node) -> Result<Inertial> {
        let frame = self.origin(node)?;
        let mass_node = children(node, "mass")
            .next()
            .ok_or_else(|| self.err(node, "<mass> is required"))?;
        let mass = self.required(mass_node, "value")?;
        if mass < 0.0 {
            return Err(self.err(
                mass_node,
                format!("attribute `value` = {mass}: must be >= 0"),
            ));
        }
        let i = children(node, "inertia")
            .next()
            .ok_or_else(|| self.err(node, "<inertia> is required"))?;
        let get = |a: &str| -> Result<f64> { Ok(self.num(i, a)?.unwrap_or(0.0)) };
        let (ixx, iyy, izz) = (get("ixx")?, get("iyy")?, get("izz")?);
        let (ixy, ixz, iyz) = (get("ixy")?, get("ixz")?, get("iyz")?);
        let local = Matrix3::new(ixx, ixy, ixz, ixy, iyy, iyz, ixz, iyz, izz);
        Ok(Inertial {
            mass,
            com: frame.pos,
            // inertia about the COM, re-expressed in the link frame: R I Rᵀ
            inertia: frame.rot * local * frame.rot.transpose(),
            line: self.line(node),
        })
    }

    fn collision(&self, node: Node, link: &str) -> Result<Collision> {
        let origin = self.origin(node)?;
        let geometry = children(node, "geometry")
            .next()
            .ok_or_else(|| self.err(node, "<geometry> is required"))?;
        let shape_node = geometry
            .children()
            .find(Node::is_element)
            .ok_or_else(|| self.err(geometry, "expected one of box, cylinder, sphere, capsule"))?;
        let shape = match shape_node.tag_name().name() {
            "box" => {
                let s = self
                    .nums(shape_node, "size", 3)?
                    .ok_or_else(|| self.err(shape_node, "attribute `size` is required"))?;
                if s.iter().any(|x| *x <= 0.0) {
                    return Err(
                        self.err(shape_node, format!("attribute `size` = {s:?}: must be > 0"))
                    );
                }
                Primitive::Box([s[0] / 2.0, s[1] / 2.0, s[2] / 2.0])
            }
            "cylinder" => Primitive::Cylinder {
                radius: self.positive(shape_node, "radius")?,
                half_length: self.positive(shape_node, "length")? / 2.0,
            },
            "capsule" => Primitive::Capsule {
                radius: self.positive(shape_node, "radius")?,
                half_length: self.positive(shape_node, "length")? / 2.0,
            },
            "sphere" => Primitive::Sphere(self.positive(shape_node, "radius")?),
            "mesh" => {
                let file = shape_node
                    .attribute("filename")
                    .ok_or_else(|| self.err(shape_node, "attribute `filename` is required"))?;
                let scale = self.nums(shape_node, "scale", 3)?.unwrap_or(vec![1.0; 3]);
                let path = resolve_mesh(file, self.dir)
                    .map_err(|e| self.err(shape_node, format!("link {link:?}: {e}")))?;
                Primitive::Mesh {
                    path,
                    scale: [scale[0], scale[1], scale[2]],
                }
            }
            other => {
                return Err(self.err(
                    shape_node,
                    format!(
                        "unknown geometry <{other}> (expected box, cylinder, sphere, capsule, mesh)"
                    ),
                ));
            }
        };
        Ok(Collision {
            origin,
            shape,
            line: self.line(node),
        })
    }

    fn joint(&self, node: Node, warnings: &mut Vec<String>) -> Result<Joint> {
        let name = self.name(node)?.to_string();
        let kind = match node.attribute("type") {
            Some("revolute") => JointType::Revolute,
            Some("continuous") => JointType::Continuous,
            Some("prismatic") => JointType::Prismatic,
            Some("fixed") => JointType::Fixed,
            Some("floating") => JointType::Floating,
            Some("planar") => JointType::Planar,
            other => {
                return Err(self.err(
                    node,
                    format!(
                        "joint {name:?}: attribute `type` = {other:?}: expected revolute, \
                         continuous, prismatic, fixed, floating or planar"
                    ),
                ));
            }
        };
        let link_of = |tag: &'static str| -> Result<String> {
            let n = children(node, tag)
                .next()
                .ok_or_else(|| self.err(node, format!("joint {name:?}: <{tag}> is required")))?;
            n.attribute("link")
                .map(str::to_string)
                .ok_or_else(|| self.err(n, "attribute `link` is required"))
        };
        let (parent, child) = (link_of("parent")?, link_of("child")?);
        let origin = self.origin(node)?;
        // (the URDF spec ignores the axis of fixed and floating joints: robots carry zero ones)
        let moves_along_axis = !matches!(kind, JointType::Fixed | JointType::Floating);
        let axis = match children(node, "axis").next().filter(|_| moves_along_axis) {
            Some(a) => {
                let v = self
                    .nums(a, "xyz", 3)?
                    .map_or(Vector3::x(), |v| Vector3::from_column_slice(&v));
                let n = v.norm();
                if n < 1e-12 {
                    return Err(self.err(a, format!("joint {name:?}: axis has zero length")));
                }
                v / n
            }
            None => Vector3::x(),
        };
        let mut range = None;
        let mut effort = None;
        let here = |n: Node| format!("URDF {}:{}", self.source, self.line(n));
        if let Some(l) = children(node, "limit").next() {
            effort = self.num(l, "effort")?;
            if effort.is_some_and(|e| e < 0.0) {
                return Err(self.err(l, format!("attribute `effort` = {effort:?}: must be >= 0")));
            }
            let (lo, hi) = (self.num(l, "lower")?, self.num(l, "upper")?);
            if matches!(kind, JointType::Revolute | JointType::Prismatic) {
                let (lo, hi) = (lo.unwrap_or(0.0), hi.unwrap_or(0.0));
                if lo > hi {
                    return Err(self.err(l, format!("joint {name:?}: lower = {lo} > upper = {hi}")));
                }
                if lo < hi {
                    range = Some((lo, hi));
                } else {
                    warnings.push(format!(
                        "{}: joint {name:?}: lower = upper = {lo}: the joint is left unlimited",
                        here(l)
                    ));
                }
            }
        } else if matches!(kind, JointType::Revolute | JointType::Prismatic) {
            warnings.push(format!(
                "{}: joint {name:?} has no <limit>: it is left unlimited",
                here(node)
            ));
        }
        let (mut damping, mut friction) = (0.0, 0.0);
        if let Some(d) = children(node, "dynamics").next() {
            damping = self.num(d, "damping")?.unwrap_or(0.0);
            if damping < 0.0 {
                return Err(self.err(d, format!("attribute `damping` = {damping}: must be >= 0")));
            }
            friction = self.num(d, "friction")?.unwrap_or(0.0);
            if friction < 0.0 || !friction.is_finite() {
                let msg = format!("attribute `friction` = {friction}: must be finite and >= 0");
                return Err(self.err(d, msg));
            }
        }
        // `q = multiplier q_leader + offset` (an MJCF joint equality)
        let mut mimic = None;
        if let Some(m) = children(node, "mimic").next() {
            let leader = m
                .attribute("joint")
                .ok_or_else(|| self.err(m, "attribute `joint` is required"))?;
            let multiplier = self.num(m, "multiplier")?.unwrap_or(1.0);
            let offset = self.num(m, "offset")?.unwrap_or(0.0);
            if !matches!(
                kind,
                JointType::Revolute | JointType::Continuous | JointType::Prismatic
            ) {
                return Err(self.err(
                    m,
                    format!("joint {name:?}: <mimic> on a joint that is not a hinge or a slide"),
                ));
            }
            mimic = Some(Mimic {
                leader: leader.to_string(),
                multiplier,
                offset,
                line: self.line(m),
            });
        }
        Ok(Joint {
            name,
            line: self.line(node),
            kind,
            parent,
            child,
            origin,
            axis,
            range,
            effort,
            damping,
            friction,
            mimic,
        })
    }
}

pub(super) fn children<'a, 'i>(
    node: Node<'a, 'i>,
    tag: &'static str,
) -> impl Iterator<Item = Node<'a, 'i>> {
    node.children()
        .filter(move |n| n.is_element() && n.tag_name().name() == tag)
}

/// A URDF mesh file name as a path: `package://NAME/REST` (ROS's package lookup, done without
/// ROS) is the first of `NAME/REST` and `REST` that exists beside the URDF file or up to three
/// folders above it; `file://PATH` is `PATH`; anything else is relative to the URDF's folder.
fn resolve_mesh(file: &str, dir: Option<&Path>) -> std::result::Result<PathBuf, String> {
    let base = dir.unwrap_or(Path::new(""));
    if let Some(rest) = file.strip_prefix("package://") {
        let (package, sub) = rest.split_once('/').unwrap_or((rest, ""));
        let mut tried = Vec::new();
        let mut folder = Some(base);
        for _ in 0..4 {
            let Some(d) = folder else { break };
            for candidate in [d.join(package).join(sub), d.join(sub)] {
                if candidate.is_file() {
                    return Ok(candidate);
                }
                tried.push(candidate.display().to_string());
            }
            folder = d.parent();
        }
        return Err(format!(
            "mesh {file:?}: package {package:?} not found (tried {})",
            tried.join(", ")
        ));
    }
    Ok(match file.strip_prefix("file://") {
        Some(path) => PathBuf::from(path),
        None => base.join(file),
    })
}
