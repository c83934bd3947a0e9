//! URDF loader: a URDF robot → an MJCF document → [`crate::mjcf`] → [`Model`] (no physics here).
//!
//! The URDF is parsed and checked here (every error is an [`Error::Urdf`] naming the element
//! and its line), its fixed joints are merged, and the result is written as MJCF with one element
//! per line, so that any error of the MJCF stage is reported at the URDF line it came from. The
//! generated document is kept in [`UrdfModel::mjcf`].
//!
//! ## Mapping
//! * Link frame = its joint's frame (URDF). `<origin rpy>` is `Rz(yaw) Ry(pitch) Rx(roll)`.
//! * `<inertial>`: mass, COM and the full inertia (rotated by its `rpy`) of the link. A link
//!   without `<inertial>` has no mass (no inertia is computed from collision geometry).
//! * Joints: `revolute` → hinge with `range = (lower, upper)`; `continuous` → hinge without
//!   limits; `prismatic` → slide; `floating` → free joint; `planar` → three dofs in the plane
//!   normal to `axis`: two slides along `u`, `v` (`u`, `v`, `axis` right-handed, `u` the unit
//!   vector of the smallest-index world axis orthogonalised against `axis`) then a hinge about
//!   `axis` (as MoveIt's and Pinocchio's planar joints); `fixed` → merged (below). `<dynamics
//!   damping>` → joint damping, `<dynamics friction>` → dry joint friction (MuJoCo's
//!   `frictionloss`, as MuJoCo's URDF import maps it). A `<limit>` with `lower = upper` (URDF's default 0 for both)
//!   leaves the joint unlimited, with a warning.
//! * Fixed joints merge the child link into its parent (MuJoCo's `fusestatic`): masses add, the
//!   COM is the mass-weighted mean, inertias add with the parallel-axis term, and the child's
//!   collision geoms move onto the parent. The merged link keeps the parent's name.
//! * Base: `floating = true` gives the root link a free joint (`qpos` starts with
//!   `[x, y, z, qw, qx, qy, qz]`); `floating = false` welds it (and everything fixed to it) to the
//!   world, whose mass is then irrelevant. A root link named `world` (ROS's convention for a robot
//!   fixed in place) is the world whatever `floating` says.
//! * The axis of a fixed or floating joint is ignored (as the URDF spec says; robots carry zero
//!   ones there).
//! * Actuators: one motor per revolute, continuous and prismatic joint (but a `<mimic>` one),
//!   named after it, gear 1, so `ctrl` is the joint torque (N·m) or force (N);
//!   `ctrlrange = (-effort, effort)` when
//!   `<limit effort>` is given and positive, otherwise unclamped. Velocity limits are ignored
//!   (MuJoCo ignores them too).
//! * Collision primitives box, cylinder, sphere and capsule (`length` = the cylindrical part), and
//!   collision meshes (STL, OBJ; `scale`), which collide as their convex hulls (the MJCF mesh
//!   geom): `package://NAME/REST` is looked for as `NAME/REST` or `REST` beside the URDF file and
//!   up to three folders above it (no ROS needed), other names relative to the URDF's folder.
//!   Visual elements are skipped. Pairs follow MuJoCo's rules (no parent–child contact), and
//!   with a base welded to the world its jointed children do not collide with it either (MuJoCo
//!   lets the world collide with its children; jointed links overlap at their joints: a KUKA
//!   iiwa's first link sinks 1 cm into its base).
//! * Ignored with a warning: unknown top-level elements. Ignored silently:
//!   `material`, `transmission`, `gazebo`, `calibration`, `safety_controller`.
//! * `<mimic joint multiplier offset>`: the joint follows its leader, `q = multiplier q_leader +
//!   offset`, as a hard coupling (MJCF `equality/joint`); it gets no motor of its own.
//! * Options: MuJoCo's defaults (time step 0.002 s, gravity −9.81 z); change them with
//!   [`Model::with_options`].
mod parse;

use std::fmt::Write as _;
use std::path::Path;

use nalgebra::{Matrix3, UnitQuaternion, Vector3};
use roxmltree::Document;

use self::parse::{JointType, Parser, Primitive, Robot, Transform};
use crate::{Error, Model, Result};

/// A loaded URDF model.
#[derive(Clone, Debug)]
pub struct UrdfModel {
    /// The compiled model.
    pub model: Model,
    /// Features that were ignored, each naming the element and line.
    pub warnings: Vec<String>,
    /// The MJCF document the URDF was translated to.
    pub mjcf: String,
}

/// Load a URDF file; `floating` chooses a free base (else the root link is fixed to the world).
pub fn load_path(path: &Path, floating: bool) -> Result<UrdfModel> {
    let source = path.display().to_string();
    let xml = std::fs::read_to_string(path).map_err(|e| Error::Urdf {
        source_name: source.clone(),
        line: 0,
        msg: format!("cannot read the file: {e}"),
    })?;
    load(&xml, &source, floating, path.parent())
}

/// Load URDF text; `source` names it in messages (a path or `<string>`).
///
/// ```
/// let urdf = r#"<robot name="r">
///   <link name="base"/>
///   <link name="arm"><inertial><mass value="1"/>
///     <inertia ixx="0.1" iyy="0.1" izz="0.01"/></inertial></link>
///   <joint name="hinge" type="continuous"><parent link="base"/><child link="arm"/>
///     <origin xyz="0 0 1"/><axis xyz="0 1 0"/></joint>
/// </robot>"#;
/// let m = ukemi_engine::urdf::load_str(urdf, "<string>", false).unwrap().model;
/// assert_eq!((m.nq, m.nu()), (1, 1));
/// ```
pub fn load_str(xml: &str, source: &str, floating: bool) -> Result<UrdfModel> {
    load(xml, source, floating, None)
}

/// [`load_str`] with collision mesh files found from `dir` (none: the working directory).
fn load(xml: &str, source: &str, floating: bool, dir: Option<&Path>) -> Result<UrdfModel> {
    let doc = Document::parse(xml).map_err(|e| Error::Urdf {
        source_name: source.to_string(),
        line: e.pos().row as usize,
        msg: format!("malformed XML: {e}"),
    })?;
    let parser = Parser {
        source,
        doc: &doc,
        dir,
    };
    let mut robot = parser.robot()?;
    let (mjcf, lines) = Emitter::new(source, &robot, floating)?.emit()?;
    let loaded = crate::mjcf::load_str(&mjcf, source).map_err(|e| match e {
        Error::Mjcf { line, msg, .. } => Error::Urdf {
            source_name: source.to_string(),
            line: line
                .checked_sub(1)
                .and_then(|i| lines.get(i))
                .copied()
                .unwrap_or(0),
            msg,
        },
        other => other,
    })?;
    let at = |line: usize| {
        line.checked_sub(1)
            .and_then(|i| lines.get(i))
            .copied()
            .unwrap_or(0)
    };
    robot
        .warnings
        .extend(loaded.warnings.iter().map(|w| relocate(w, source, &at)));
    Ok(UrdfModel {
        model: loaded.model,
        warnings: robot.warnings,
        mjcf,
    })
}

/// A warning of the MJCF stage in URDF terms: `MJCF src:N:` → `URDF src:L:` and `(line N)` →
/// `(line L)`, with `L` the URDF line that MJCF line `N` came from.
fn relocate(warning: &str, source: &str, at: &dyn Fn(usize) -> usize) -> String {
    let mut out = warning.to_string();
    let head = format!("MJCF {source}:");
    if let Some(rest) = out.strip_prefix(&head) {
        let digits: String = rest.chars().take_while(char::is_ascii_digit).collect();
        if let Ok(n) = digits.parse::<usize>() {
            out = format!("URDF {source}:{}{}", at(n), &rest[digits.len()..]);
        }
    }
    let mut result = String::with_capacity(out.len());
    let mut rest = out.as_str();
    while let Some(i) = rest.find("(line ") {
        result.push_str(&rest[..i + 6]);
        rest = &rest[i + 6..];
        let digits: String = rest.chars().take_while(char::is_ascii_digit).collect();
        if let Ok(n) = digits.parse::<usize>() {
            result.push_str(&at(n).to_string());
            rest = &rest[digits.len()..];
        }
    }
    result.push_str(rest);
    result
}

/// Mass accumulated on one engine body: `Σm`, `Σ m c`, and `Σ (I + m (|c|² E − c cᵀ))` about the
/// body origin (body frame).
#[derive(Clone, Default)]
struct MassSum {
    mass: f64,
    moment: Vector3<f64>,
    inertia_origin: Matrix3<f64>,
}

impl MassSum {
    fn add(&mut self, mass: f64, com: Vector3<f64>, inertia_com: Matrix3<f64>) {
        self.mass += mass;
        self.moment += mass * com;
        self.inertia_origin += inertia_com + steiner(mass, &com);
    }
    /// `(mass, com, inertia about com)`.
    fn result(&self) -> (f64, Vector3<f64>, Matrix3<f64>) {
        if self.mass <= 0.0 {
            return (0.0, Vector3::zeros(), Matrix3::zeros());
        }
        let com = self.moment / self.mass;
        (
            self.mass,
            com,
            self.inertia_origin - steiner(self.mass, &com),
        )
    }
}

/// Parallel-axis term `m (|c|² E − c cᵀ)`.
fn steiner(mass: f64, c: &Vector3<f64>) -> Matrix3<f64> {
    mass * (Matrix3::identity() * c.norm_squared() - c * c.transpose())
}

struct Emitter<'r> {
    source: &'r str,
    robot: &'r Robot,
    floating: bool,
    /// Parent joint of each link (index into `robot.joints`).
    parent_joint: Vec<Option<usize>>,
    /// Child joints of each link, in document order.
    child_joints: Vec<Vec<usize>>,
    /// Engine body (a link index; `None` = world) of each link, and `engine_from_link`.
    engine: Vec<Option<usize>>,
    engine_from_link: Vec<Transform>,
    root: usize,
    out: String,
    lines: Vec<usize>,
    indent: usize,
    /// `<mesh>` assets of the collision meshes: (URDF line, element).
    meshes: Vec<(usize, String)>,
    /// `<contact><exclude>` of the links jointed to a base welded to the world.
    excludes: Vec<(usize, String)>,
}

fn fmt3(v: &Vector3<f64>) -> String {
    format!("{} {} {}", v.x, v.y, v.z)
}

fn fmt_quat(r: &Matrix3<f64>) -> String {
    let q = UnitQuaternion::from_matrix(r);
    format!("{} {} {} {}", q.w, q.i, q.j, q.k)
}

/// XML attribute escaping for names.
fn esc(s: &str) -> String {
    s.replace('&', "&amp;")
        .replace('"', "&quot;")
        .replace('<', "&lt;")
        .replace('>', "&gt;")
}

impl<'r> Emitter<'r> {
    fn new(source: &'r str, robot: &'r Robot, floating: bool) -> Result<Self> {
        let n = robot.links.len();
        let err = |line: usize, msg: String| Error::Urdf {
            source_name: source.to_string(),
            line,
            msg,
        };
        if n == 0 {
            return Err(err(1, "<robot>: no <link>".into()));
        }
        let link_id = |name: &str, j: &parse::Joint, role: &str| {
            robot
                .links
                .iter()
                .position(|l| l.name == name)
                .ok_or_else(|| {
                    err(
                        j.line,
                        format!("<joint>: joint {:?}: unknown {role} link {name:?}", j.name),
                    )
                })
        };
        let mut parent_joint = vec![None; n];
        let mut child_joints = vec![vec![]; n];
        for (ji, j) in robot.joints.iter().enumerate() {
            let (p, c) = (
                link_id(&j.parent, j, "parent")?,
                link_id(&j.child, j, "child")?,
            );
            if p == c {
                return Err(err(
                    j.line,
                    format!(
                        "<joint>: joint {:?}: parent and child are the same link",
                        j.name
                    ),
                ));
            }
            if let Some(other) = parent_joint[c] {
                let other: &parse::Joint = &robot.joints[other];
                return Err(err(
                    j.line,
                    format!(
                        "<joint>: joint {:?}: link {:?} already has the parent joint {:?} (URDF \
                         describes trees; close loops in MJCF with <equality>)",
                        j.name, j.child, other.name
                    ),
                ));
            }
            parent_joint[c] = Some(ji);
            child_joints[p].push(ji);
        }
        let roots: Vec<usize> = (0..n).filter(|&i| parent_joint[i].is_none()).collect();
        let root = match roots.as_slice() {
            [r] => *r,
            [] => {
                return Err(err(
                    robot.links[0].line,
                    "<robot>: every link has a parent joint (a kinematic loop): no root link"
                        .into(),
                ));
            }
            [a, b, ..] => {
                return Err(err(
                    robot.links[*b].line,
                    format!(
                        "<link>: links {:?} and {:?} both have no parent joint (a URDF has one root)",
                        robot.links[*a].name, robot.links[*b].name
                    ),
                ));
            }
        };
        // a root link named "world" is ROS's world frame: the robot is fixed to it
        let floating = floating && robot.links[root].name != "world";
        Ok(Emitter {
            source,
            robot,
            floating,
            parent_joint,
            child_joints,
            engine: vec![None; n],
            engine_from_link: vec![Transform::identity(); n],
            root,
            out: String::new(),
            lines: vec![],
            indent: 0,
            meshes: vec![],
            excludes: vec![],
        })
    }

    fn err(&self, line: usize, msg: String) -> Error {
        Error::Urdf {
            source_name: self.source.to_string(),
            line,
            msg,
        }
    }

    /// One generated line, remembered as coming from URDF line `src`.
    fn line(&mut self, src: usize, text: &str) {
        let _ = writeln!(self.out, "{}{}", "  ".repeat(self.indent), text);
        self.lines.push(src);
    }

    /// Assign each link its engine body (merging fixed joints) in a depth-first walk.
    fn assign(&mut self) -> Result<()> {
        let mut stack = vec![self.root];
        self.engine[self.root] = self.floating.then_some(self.root);
        let mut seen = 0;
        while let Some(l) = stack.pop() {
            seen += 1;
            for &ji in self.child_joints[l].iter().rev() {
                let j = &self.robot.joints[ji];
                let c = self
                    .robot
                    .links
                    .iter()
                    .position(|x| x.name == j.child)
                    .unwrap_or(0);
                if j.kind == JointType::Fixed {
                    self.engine[c] = self.engine[l];
                    self.engine_from_link[c] = self.engine_from_link[l].compose(&j.origin);
                } else {
                    self.engine[c] = Some(c);
                }
                stack.push(c);
            }
        }
        if seen != self.robot.links.len() {
            let lost = (0..self.robot.links.len())
                .find(|&i| i != self.root && self.engine_unreached(i))
                .unwrap_or(0);
            return Err(self.err(
                self.robot.links[lost].line,
                format!(
                    "<link>: link {:?} is not connected to the root link {:?} (a loop of joints)",
                    self.robot.links[lost].name, self.robot.links[self.root].name
                ),
            ));
        }
        Ok(())
    }

    fn engine_unreached(&self, link: usize) -> bool {
        // reached links have an engine body, or are fixed to a world root
        let mut l = link;
        for _ in 0..=self.robot.links.len() {
            match self.parent_joint[l] {
                None => return l != self.root,
                Some(j) => {
                    let p = &self.robot.joints[j].parent;
                    l = self
                        .robot
                        .links
                        .iter()
                        .position(|x| &x.name == p)
                        .unwrap_or(0);
                }
            }
        }
        true
    }

    fn emit(mut self) -> Result<(String, Vec<usize>)> {
        self.assign()?;
        self.line(1, "<mujoco model=\"urdf\">");
        self.indent += 1;
        self.line(
            1,
            "<compiler angle=\"radian\" inertiafromgeom=\"false\" autolimits=\"true\"/>",
        );
        self.line(1, "<worldbody>");
        self.indent += 1;
        if self.floating {
            self.body(self.root, &Transform::identity(), None)?;
        } else {
            self.geoms_of(None)?;
            for ji in self.child_joints[self.root].clone() {
                self.child(ji)?;
            }
        }
        self.indent -= 1;
        self.line(1, "</worldbody>");
        let excludes = std::mem::take(&mut self.excludes);
        self.section("contact", excludes);
        let meshes = std::mem::take(&mut self.meshes);
        self.section("asset", meshes);
        // a mimic joint follows its leader (an equality), driven by the leader's motor
        let mimics: Vec<(usize, String)> = (self.robot.joints.iter())
            .filter_map(|joint| {
                let m = joint.mimic.as_ref()?;
                let text = format!(
                    "<joint joint1=\"{}\" joint2=\"{}\" polycoef=\"{} {} 0 0 0\"/>",
                    esc(&joint.name),
                    esc(&m.leader),
                    m.offset,
                    m.multiplier
                );
                Some((m.line, text))
            })
            .collect();
        self.section("equality", mimics);
        let motors: Vec<usize> = (0..self.robot.joints.len())
            .filter(|&j| {
                matches!(
                    self.robot.joints[j].kind,
                    JointType::Revolute | JointType::Continuous | JointType::Prismatic
                ) && self.robot.joints[j].mimic.is_none()
            })
            .collect();
        if !motors.is_empty() {
            self.line(1, "<actuator>");
            self.indent += 1;
            for j in motors {
                let joint = &self.robot.joints[j];
                let range = match joint.effort {
                    Some(e) if e > 0.0 => format!(" ctrlrange=\"{} {}\"", -e, e),
                    _ => String::new(),
                };
                let text = format!(
                    "<motor name=\"{0}\" joint=\"{0}\" gear=\"1\"{range}/>",
                    esc(&joint.name)
                );
                self.line(joint.line, &text);
            }
            self.indent -= 1;
            self.line(1, "</actuator>");
        }
        self.indent -= 1;
        self.line(1, "</mujoco>");
        Ok((self.out, self.lines))
    }

    /// A moving child link, reached through joint `ji`, and its subtree.
    fn child(&mut self, ji: usize) -> Result<()> {
        let j = &self.robot.joints[ji];
        let parent = self
            .robot
            .links
            .iter()
            .position(|l| l.name == j.parent)
            .unwrap_or(0);
        let child = self
            .robot
            .links
            .iter()
            .position(|l| l.name == j.child)
            .unwrap_or(0);
        if j.kind == JointType::Fixed {
            // merged: its geoms and mass went to the engine body; walk on
            for cj in self.child_joints[child].clone() {
                self.child(cj)?;
            }
            return Ok(());
        }
        let pose = self.engine_from_link[parent].compose(&j.origin);
        // a link jointed to the base welded to the world: MuJoCo's pair rules let the world
        // collide with its children, but jointed URDF links overlap at their joints
        if self.engine[parent].is_none() {
            let text = format!(
                "<exclude body1=\"world\" body2=\"{}\"/>",
                esc(&self.robot.links[child].name)
            );
            self.excludes.push((j.line, text));
        }
        self.body(child, &pose, Some(ji))
    }

    /// The engine body of link `link` at `pose` (in its MJCF parent), its joint, mass, geoms and
    /// children.
    fn body(&mut self, link: usize, pose: &Transform, joint: Option<usize>) -> Result<()> {
        let robot = self.robot;
        let l = &robot.links[link];
        let text = format!(
            "<body name=\"{}\" pos=\"{}\" quat=\"{}\">",
            esc(&l.name),
            fmt3(&pose.pos),
            fmt_quat(&pose.rot)
        );
        self.line(l.line, &text);
        self.indent += 1;
        match joint {
            None => {
                let text = "<freejoint name=\"root\"/>".to_string();
                self.line(l.line, &text);
            }
            Some(ji) => self.joint(ji),
        }
        // mass of every link merged into this body
        let mut sum = MassSum::default();
        let mut inertial_line = l.line;
        for (i, other) in robot.links.iter().enumerate() {
            if self.engine[i] != Some(link) {
                continue;
            }
            if let Some(m) = &other.inertial {
                let t = &self.engine_from_link[i];
                sum.add(
                    m.mass,
                    t.pos + t.rot * m.com,
                    t.rot * m.inertia * t.rot.transpose(),
                );
                inertial_line = m.line;
            }
        }
        let (mass, com, i) = sum.result();
        if mass <= 0.0 {
            let why = match joint {
                Some(ji) => format!("joint {:?}", robot.joints[ji].name),
                None => "the floating base".to_string(),
            };
            return Err(self.err(
                l.line,
                format!(
                    "<link>: link {:?} moves ({why}) but has no mass: give it (or a link fixed \
                     to it) an <inertial> with mass > 0",
                    l.name
                ),
            ));
        }
        let text = format!(
            "<inertial pos=\"{}\" mass=\"{}\" fullinertia=\"{} {} {} {} {} {}\"/>",
            fmt3(&com),
            mass,
            i[(0, 0)],
            i[(1, 1)],
            i[(2, 2)],
            i[(0, 1)],
            i[(0, 2)],
            i[(1, 2)]
        );
        self.line(inertial_line, &text);
        self.geoms_of(Some(link))?;
        // children: moving links directly below this body, through merged links
        let merged: Vec<usize> = (0..robot.links.len())
            .filter(|&i| self.engine[i] == Some(link))
            .collect();
        for i in merged {
            for cj in self.child_joints[i].clone() {
                if robot.joints[cj].kind != JointType::Fixed {
                    self.child(cj)?;
                }
            }
        }
        self.indent -= 1;
        self.line(l.line, "</body>");
        Ok(())
    }

    fn joint(&mut self, ji: usize) {
        let j = &self.robot.joints[ji];
        let name = esc(&j.name);
        let mut extra = String::new();
        if j.damping > 0.0 {
            let _ = write!(extra, " damping=\"{}\"", j.damping);
        }
        if j.friction > 0.0 {
            let _ = write!(extra, " frictionloss=\"{}\"", j.friction);
        }
        if let Some((lo, hi)) = j.range {
            let _ = write!(extra, " range=\"{lo} {hi}\"");
        }
        let axis = fmt3(&j.axis);
        match j.kind {
            JointType::Revolute | JointType::Continuous => {
                let t = format!("<joint name=\"{name}\" type=\"hinge\" axis=\"{axis}\"{extra}/>");
                self.line(j.line, &t);
            }
            JointType::Prismatic => {
                let t = format!("<joint name=\"{name}\" type=\"slide\" axis=\"{axis}\"{extra}/>");
                self.line(j.line, &t);
            }
            JointType::Floating => {
                let t = format!("<freejoint name=\"{name}\"/>");
                self.line(j.line, &t);
            }
            JointType::Planar => {
                let (u, v) = plane_basis(&j.axis);
                let mut damping = String::new();
                if j.damping > 0.0 {
                    let _ = write!(damping, " damping=\"{}\"", j.damping);
                }
                if j.friction > 0.0 {
                    let _ = write!(damping, " frictionloss=\"{}\"", j.friction);
                }
                for (suffix, kind, a) in [
                    ("x", "slide", u),
                    ("y", "slide", v),
                    ("rot", "hinge", j.axis),
                ] {
                    let t = format!(
                        "<joint name=\"{name}_{suffix}\" type=\"{kind}\" axis=\"{}\"{damping}/>",
                        fmt3(&a)
                    );
                    self.line(j.line, &t);
                }
            }
            JointType::Fixed => {}
        }
    }

    /// A top-level `<tag>` holding `elements` (URDF line, text), or nothing when there are none.
    fn section(&mut self, tag: &str, elements: Vec<(usize, String)>) {
        if elements.is_empty() {
            return;
        }
        self.line(1, &format!("<{tag}>"));
        self.indent += 1;
        for (line, text) in elements {
            self.line(line, &text);
        }
        self.indent -= 1;
        self.line(1, &format!("</{tag}>"));
    }

    /// Collision geoms of every link merged into `engine` (`None`: the world).
    fn geoms_of(&mut self, engine: Option<usize>) -> Result<()> {
        let robot = self.robot;
        for (i, l) in robot.links.iter().enumerate() {
            if self.engine[i] != engine {
                continue;
            }
            for (k, c) in l.collisions.iter().enumerate() {
                let t = self.engine_from_link[i].compose(&c.origin);
                let (kind, size) = match c.shape {
                    Primitive::Box(h) => ("box", format!("{} {} {}", h[0], h[1], h[2])),
                    Primitive::Cylinder {
                        radius,
                        half_length,
                    } => ("cylinder", format!("{radius} {half_length}")),
                    Primitive::Capsule {
                        radius,
                        half_length,
                    } => ("capsule", format!("{radius} {half_length}")),
                    Primitive::Sphere(r) => ("sphere", format!("{r}")),
                    Primitive::Mesh {
                        ref path,
                        scale: [x, y, z],
                    } => {
                        let name = esc(&format!("{}_collision{k}", l.name));
                        let file = esc(&path.display().to_string());
                        let text = format!(
                            "<mesh name=\"{name}\" file=\"{file}\" scale=\"{x} {y} {z}\"/>"
                        );
                        self.meshes.push((c.line, text));
                        ("mesh", String::new())
                    }
                };
                let shape = match kind {
                    "mesh" => format!("mesh=\"{}\"", esc(&format!("{}_collision{k}", l.name))),
                    _ => format!("size=\"{size}\""),
                };
                let text = format!(
                    "<geom name=\"{}\" type=\"{kind}\" {shape} pos=\"{}\" quat=\"{}\"/>",
                    esc(&format!("{}_collision{k}", l.name)),
                    fmt3(&t.pos),
                    fmt_quat(&t.rot)
                );
                self.line(c.line, &text);
            }
        }
        Ok(())
    }
}

/// Unit vectors `u`, `v` with `(u, v, n)` right-handed: `u` from the first world axis least
/// aligned with `n`, orthogonalised.
fn plane_basis(n: &Vector3<f64>) -> (Vector3<f64>, Vector3<f64>) {
    let pick = [Vector3::x(), Vector3::y(), Vector3::z()]
        .into_iter()
        .min_by(|a, b| a.dot(n).abs().total_cmp(&b.dot(n).abs()))
        .unwrap_or(Vector3::x());
    let u = (pick - n * n.dot(&pick)).normalize();
    (u, n.cross(&u))
}

#[cfg(test)]
mod tests {
    use super::*;

    const ARM: &str = r#"<robot name="arm">
  <link name="base"/>
  <link name="upper">
    <inertial><origin xyz="0 0 0.25" rpy="0.1 0.2 0.3"/><mass value="2"/>
      <inertia ixx="0.05" iyy="0.04" izz="0.01" ixy="0.001" ixz="0.002" iyz="0.003"/></inertial>
    <collision><origin xyz="0 0 0.25"/><geometry><capsule radius="0.05" length="0.4"/></geometry></collision>
  </link>
  <link name="tool">
    <inertial><mass value="0.5"/><inertia ixx="0.001" iyy="0.001" izz="0.001"/></inertial>
  </link>
  <joint name="shoulder" type="revolute"><parent link="base"/><child link="upper"/>
    <origin xyz="0 0 1"/><axis xyz="0 1 0"/><limit lower="-1" upper="2" effort="10"/>
    <dynamics damping="0.5"/></joint>
  <joint name="mount" type="fixed"><parent link="upper"/><child link="tool"/>
    <origin xyz="0 0 0.5" rpy="0 0 1.5707963267948966"/></joint>
</robot>"#;

    #[test]
    fn fixed_joint_merges_mass() {
        let m = load_str(ARM, "<arm>", false).unwrap();
        let model = &m.model;
        assert_eq!(model.nbody(), 2, "{}", m.mjcf);
        let b = &model.bodies[1];
        assert!((b.mass - 2.5).abs() < 1e-12);
        // COM: (2·0.25 + 0.5·0.5) / 2.5 along z
        assert!((b.com - Vector3::new(0.0, 0.0, 0.3)).norm() < 1e-12);
        assert_eq!(model.nu(), 1);
        assert_eq!(model.actuators[0].ctrlrange, Some((-10.0, 10.0)));
    }

    #[test]
    fn mass_sum_parallel_axis() {
        let mut s = MassSum::default();
        s.add(1.0, Vector3::new(1.0, 0.0, 0.0), Matrix3::zeros());
        s.add(1.0, Vector3::new(-1.0, 0.0, 0.0), Matrix3::zeros());
        let (m, c, i) = s.result();
        assert_eq!(m, 2.0);
        assert!(c.norm() < 1e-15);
        assert!((i - Matrix3::from_diagonal(&Vector3::new(0.0, 2.0, 2.0))).norm() < 1e-12);
    }

    #[test]
    fn errors_name_element_and_line() {
        let bad = ARM.replace("type=\"fixed\"", "type=\"weird\"");
        let e = load_str(&bad, "<arm>", false).unwrap_err().to_string();
        assert!(e.contains("<arm>:14") && e.contains("weird"), "{e}");
        // a collision mesh's package not found: the link, the file and where it was looked for
        let mesh = ARM.replace(
            "<capsule radius=\"0.05\" length=\"0.4\"/>",
            "<mesh filename=\"package://arm_description/meshes/x.stl\"/>",
        );
        let e = load_str(&mesh, "<arm>", false).unwrap_err().to_string();
        assert!(
            e.contains("\"upper\"") && e.contains("arm_description") && e.contains("tried"),
            "{e}"
        );
        let massless = ARM
            .replace("<mass value=\"2\"/>", "<mass value=\"0\"/>")
            .replace("<mass value=\"0.5\"/>", "<mass value=\"0\"/>");
        let e = load_str(&massless, "<arm>", false).unwrap_err().to_string();
        assert!(e.contains("<arm>:3") && e.contains("no mass"), "{e}");
    }

    #[test]
    fn warnings_point_at_urdf_lines() {
        let at = |n: usize| n * 10;
        assert_eq!(
            relocate("MJCF a.urdf:3: x (line 4) and y (line 5)", "a.urdf", &at),
            "URDF a.urdf:30: x (line 40) and y (line 50)"
        );
    }

    #[test]
    fn plane_basis_is_right_handed() {
        for n in [Vector3::z(), Vector3::new(1.0, 2.0, 3.0).normalize()] {
            let (u, v) = plane_basis(&n);
            assert!((u.cross(&v) - n).norm() < 1e-12);
            assert!(u.dot(&n).abs() < 1e-12);
        }
    }
}
