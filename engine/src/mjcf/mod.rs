//! MJCF loader: MuJoCo's XML model format → [`ModelBuilder`] → [`Model`] (no physics here).
//!
//! Supported: `include` (spliced in, paths beside the including file or the model file:
//! [`include`]), `compiler` (angle, eulerseq, inertiafromgeom, inertiagrouprange, autolimits,
//! settotalmass, meshdir, assetdir, strippath), `option` (timestep, gravity), nested `default` classes with
//! `class` and `childclass`, the body tree (of every `worldbody`; bodies' `gravcomp`) with every
//! orientation form, `inertial`, inertia from geoms (sphere, capsule, cylinder, box, ellipsoid,
//! mesh), `asset/mesh` from STL, OBJ or MSH files or inline `vertex` lists with `scale` (a mesh geom
//! collides and weighs as the convex hull of its vertices, as in MuJoCo,
//! [`crate::contact::hull::ConvexHull`]),
//! hinge/slide/ball/free joints (several joints of one body become one engine joint with MuJoCo's
//! dofs in MuJoCo's order, each hinge about its own anchor), geoms with contact bit masks and
//! `condim` 1 or 3, `contact/exclude` and `contact/pair` (friction and condim from the pair or its
//! class, as MuJoCo), `equality` connect/weld (loop joints) and joint (a polynomial coupling solved
//! with the joints), fixed tendons as actuator transmissions, when limited as hard tendon limits
//! (inequalities solved with the contacts) and with
//! `stiffness`/`damping`/`springlength`/`frictionloss` as passive springs, implicit dampers and dry
//! friction, `actuator` motor/position/velocity/general on joints, fixed tendons and sites (with
//! `forcerange`, and a position servo's `dampratio` turned into its velocity gain at qpos0 and its
//! `inheritrange` into its control range, as MuJoCo does), joint `frictionloss` (hard dry friction,
//! `solver::friction`), and `keyframe`.
//!
//! Anything else is an [`Error::Unsupported`] or an [`Error::Mjcf`] naming the element and its
//! line, or — where ignoring it only drops an effect ukemi does not model (solver settings,
//! fluid drag, spatial tendons, sensors) — a warning in
//! [`MjcfModel::warnings`]. Soft-contact parameters (`solref`, `solimp`, `margin`, `gap`,
//! `priority`) do not apply to hard contact and are ignored without a warning.
//!
//! ## Differences from MuJoCo
//! * A body without joints under the world is static and joins the world; a massless body
//!   without joints under a moving body is merged into it. Neither appears in `Model::bodies`.
//! * Joint names: the engine joint of a body with several MuJoCo joints is named by joining
//!   theirs with `+` (e.g. `rootx+rootz+rooty`); `qpos`/`qvel` are MuJoCo's.
//! * Geom pairs whose shapes have no collision kernel (e.g. capsule–cylinder, mesh–cylinder)
//!   never collide; each is reported as a warning. Mesh hulls touch other shapes at their
//!   vertices (and a box's corners): an edge crossing an edge is not a contact.
//! * A mesh's inertia is the solid convex hull's (MuJoCo's `inertia="convex"`; MuJoCo's default
//!   for a non-convex closed mesh is the mesh's own volume).
//! * Servos' position terms act at the current configuration (explicit), like springs; their
//!   velocity gains at the next velocity (implicit, as in MuJoCo's `implicitfast`).
//! * A joint's `actuatorfrcrange` (MuJoCo's clamp of its total actuator force) clamps the force
//!   of the one joint actuator that drives it (`Actuator::joint_forcerange`); where several
//!   actuators, or a tendon or site actuator, drive it, it is ignored with a warning.
//! * Joint `frictionloss` is hard dry friction: a joint held below its friction moves only by the
//!   solver's complementarity tolerance (MuJoCo's is soft and creeps: `solreffriction`,
//!   `solimpfriction`, ignored here).
//! * Fixed-tendon limits are hard inequalities (MuJoCo's are soft: `solreflimit`/`solimplimit`,
//!   `margin`), like joint limits; limits of spatial tendons are not enforced (a warning).
//! * `equality/joint` is a hard holonomic constraint (MuJoCo's is soft: `solref`/`solimp`).
mod actuator;
mod body;
mod defaults;
mod frame;
mod geom;
mod include;
mod inertia;
mod joint;
mod mesh;
mod parse;
mod tendon;

use std::path::Path;

use roxmltree::{Document, Node};

use self::body::Tree;
use self::parse::{Compiler, Ctx, elements};
use crate::contact::geometry;
use crate::{Error, Model, ModelBuilder, Result};

/// A loaded model and the warnings about what was ignored.
#[derive(Clone, Debug)]
pub struct MjcfModel {
    /// The compiled model (with `keyframes`).
    pub model: Model,
    /// Features that were ignored, each naming the element and line.
    pub warnings: Vec<String>,
}

/// Load an MJCF file.
pub fn load_path(path: &Path) -> Result<MjcfModel> {
    let source = path.display().to_string();
    let xml = std::fs::read_to_string(path).map_err(|e| Error::Mjcf {
        source_name: source.clone(),
        line: 0,
        msg: format!("cannot read the file: {e}"),
    })?;
    load(&xml, &source, path.parent())
}

/// Load MJCF text; `source` names it in messages (a path or `<string>`).
///
/// ```
/// let xml = r#"<mujoco><worldbody><body pos="0 0 1"><joint type="hinge" axis="0 1 0"/>
///              <geom type="sphere" size="0.1"/></body></worldbody></mujoco>"#;
/// let m = ukemi_engine::mjcf::load_str(xml, "<string>").unwrap().model;
/// assert_eq!((m.nq, m.nv), (1, 1));
/// ```
pub fn load_str(xml: &str, source: &str) -> Result<MjcfModel> {
    load(xml, source, None)
}

/// [`load_str`] with `<include>` paths relative to `dir` (none: a model given as a string may
/// not include files).
fn load(xml: &str, source: &str, dir: Option<&Path>) -> Result<MjcfModel> {
    let mut spliced = include::splice(xml, source, dir)?;
    let text = spliced.as_mut().map(|s| std::mem::take(&mut s.xml));
    let xml = text.as_deref().unwrap_or(xml);
    let doc = Document::parse(xml).map_err(|e| Error::Mjcf {
        source_name: source.to_string(),
        line: e.pos().row as usize,
        msg: format!("malformed XML: {e}"),
    })?;
    let mut ctx = Ctx {
        doc: &doc,
        source: source.to_string(),
        defaults: Default::default(),
        compiler: Compiler::default(),
        warnings: vec![],
        lines: Default::default(),
        mass_scale: 1.0,
        paired: Default::default(),
        spliced,
        mesh_nodes: Default::default(),
        meshes: Default::default(),
        dir: dir.map(Path::to_path_buf),
    };
    let root = doc.root_element();
    if root.tag_name().name() != "mujoco" {
        return Err(ctx.err(root, "the root element must be <mujoco>"));
    }
    read_header(&mut ctx, root)?;
    ctx.mesh_nodes = mesh::index_meshes(&ctx, root)?;
    // geoms an explicit pair collides: kept whatever their bit masks
    for contact in elements(root).filter(|n| n.tag_name().name() == "contact") {
        for pair in elements(contact).filter(|n| n.tag_name().name() == "pair") {
            let names = ["geom1", "geom2"]
                .into_iter()
                .filter_map(|a| pair.attribute(a));
            ctx.paired.extend(names.map(str::to_string));
        }
    }
    // settotalmass: measure the total mass with a dry run, then scale
    if let Some(total) = ctx.compiler.total_mass {
        let mut scratch = ModelBuilder::new();
        let tree = read_tree(&mut ctx, root, &mut scratch)?;
        let sum: f64 = tree.bodies.iter().map(|b| b.mass).sum();
        if sum > 0.0 {
            ctx.mass_scale = total / sum;
        }
        ctx.warnings.clear();
    }
    let mut b = ModelBuilder::new();
    b.set_condim_max(true);
    read_option(&mut ctx, root, &mut b)?;
    let tree = read_tree(&mut ctx, root, &mut b)?;
    let tendons = tendon::read_tendons(&mut ctx, root, &tree, &mut b)?;
    let mut inherit = Vec::new();
    for node in elements(root) {
        match node.tag_name().name() {
            "actuator" => {
                actuator::read_actuators(&mut ctx, node, &tree, &tendons, &mut b, &mut inherit)?
            }
            "equality" => actuator::read_equality(&mut ctx, node, &tree, &mut b)?,
            "contact" => actuator::read_contact(&mut ctx, node, &tree, &mut b)?,
            "sensor" => ctx.warn(node, "sensors are not loaded"),
            "deformable" | "extension" => {
                return Err(ctx.unsupported(node, "element is not supported"));
            }
            _ => {}
        }
    }
    exclude_pairs(&mut ctx, &tree, &mut b);
    let mut model = b.compile().map_err(|e| locate(&ctx, e))?;
    actuator::resolve_dampratios(&mut model)
        .map_err(|e| crate::Error::model("actuator", "dampratio", e))?;
    actuator::resolve_inherited_ranges(&ctx, &mut model, &inherit)?;
    actuator::resolve_joint_force_ranges(&mut ctx, &tree, &mut model);
    if let Some(k) = elements(root).find(|n| n.tag_name().name() == "keyframe") {
        model.keyframes = actuator::read_keyframes(&ctx, k, &model.qpos0, model.nv, model.nu())?;
    }
    // `size/@nkey` reserves keyframes; unused ones hold qpos0 (as in MuJoCo)
    for node in elements(root).filter(|n| n.tag_name().name() == "size") {
        let nkey = ctx.int(node, "", "nkey", 0)?;
        let nkey = usize::try_from(nkey)
            .map_err(|_| ctx.err(node, format!("attribute `nkey` = {nkey}: must be >= 0")))?;
        while model.keyframes.len() < nkey.min(10_000) {
            model.keyframes.push(crate::Keyframe {
                qpos: model.qpos0.clone(),
                qvel: vec![0.0; model.nv],
                ctrl: vec![0.0; model.nu()],
                ..Default::default()
            });
        }
    }
    Ok(MjcfModel {
        model,
        warnings: ctx.warnings,
    })
}

fn read_tree<'a, 'i>(
    ctx: &mut Ctx<'a, 'i>,
    root: Node<'a, 'i>,
    b: &mut ModelBuilder,
) -> Result<Tree> {
    let worlds: Vec<_> = elements(root)
        .filter(|n| n.tag_name().name() == "worldbody")
        .collect();
    if worlds.is_empty() {
        return Err(ctx.err(root, "no <worldbody>"));
    }
    body::read_worldbody(ctx, &worlds, b)
}

/// `compiler` and `default` (they shape how everything else is read).
fn read_header<'a, 'i>(ctx: &mut Ctx<'a, 'i>, root: Node<'a, 'i>) -> Result<()> {
    for node in elements(root) {
        match node.tag_name().name() {
            "compiler" => read_compiler(ctx, node)?,
            "default" => {
                if let Err((n, msg)) = ctx.defaults.read(node, None) {
                    return Err(ctx.err(n, msg));
                }
            }
            _ => {}
        }
    }
    ctx.defaults.ensure_main();
    Ok(())
}

fn read_compiler<'a, 'i>(ctx: &mut Ctx<'a, 'i>, node: Node<'a, 'i>) -> Result<()> {
    let c = &mut ctx.compiler.clone();
    if let Some(a) = node.attribute("angle") {
        c.degree = match a {
            "degree" => true,
            "radian" => false,
            _ => {
                return Err(ctx.err(
                    node,
                    format!("attribute `angle` = {a:?}: expected \"degree\" or \"radian\""),
                ));
            }
        };
    }
    if let Some(s) = node.attribute("eulerseq") {
        let bytes = s.as_bytes();
        if bytes.len() != 3 || !bytes.iter().all(|c| b"xyzXYZ".contains(c)) {
            return Err(ctx.err(
                node,
                format!("attribute `eulerseq` = {s:?}: expected 3 of xyzXYZ"),
            ));
        }
        c.eulerseq = [bytes[0], bytes[1], bytes[2]];
    }
    c.inertia_from_geom = match ctx
        .keyword(
            node,
            "",
            "inertiafromgeom",
            &["true", "false", "auto"],
            "auto",
        )?
        .as_str()
    {
        "true" => Some(true),
        "false" => Some(false),
        _ => None,
    };
    c.autolimits = ctx.keyword(node, "", "autolimits", &["true", "false"], "true")? == "true";
    c.meshdir = node
        .attribute("meshdir")
        .map(str::to_string)
        .or(c.meshdir.take());
    c.assetdir = node
        .attribute("assetdir")
        .map(str::to_string)
        .or(c.assetdir.take());
    if node.attribute("strippath").is_some() {
        c.strippath = ctx.keyword(node, "", "strippath", &["true", "false"], "false")? == "true";
    }
    if ctx.keyword(node, "", "coordinate", &["local", "global"], "local")? == "global" {
        return Err(ctx.unsupported(
            node,
            "coordinate=\"global\" (removed from MuJoCo; use local coordinates)",
        ));
    }
    if let Some(r) = ctx.nums(node, "", "inertiagrouprange", 2)? {
        c.inertia_groups = (r[0] as i64, r[1] as i64);
    }
    if let Some(m) = ctx.nums(node, "", "settotalmass", 1)? {
        c.total_mass = (m[0] > 0.0).then_some(m[0]);
    }
    for a in [
        "boundmass",
        "boundinertia",
        "balanceinertia",
        "fusestatic",
        "discardvisual",
        "alignfree",
    ] {
        if node.attribute(a).is_some_and(|v| v != "0" && v != "false") {
            ctx.warn(node, format!("compiler attribute `{a}` is ignored"));
        }
    }
    if node.attribute("exactmeshinertia").is_some() || node.attribute("shellinertia").is_some() {
        ctx.warn(node, "mesh inertia settings are ignored");
    }
    ctx.compiler = c.clone();
    Ok(())
}

fn read_option<'a, 'i>(
    ctx: &mut Ctx<'a, 'i>,
    root: Node<'a, 'i>,
    b: &mut ModelBuilder,
) -> Result<()> {
    b.options.timestep = 0.002;
    for node in elements(root).filter(|n| n.tag_name().name() == "option") {
        for a in node.attributes() {
            match a.name() {
                "timestep" => {
                    let h = ctx.num(node, "", "timestep", 0.002)?;
                    if h <= 0.0 {
                        return Err(ctx.err(node, format!("attribute `timestep` = {h}: must be > 0")));
                    }
                    b.options.timestep = h;
                }
                "gravity" => {
                    let g = ctx.nums(node, "", "gravity", 3)?.unwrap_or_default();
                    b.options.gravity = nalgebra::Vector3::new(g[0], g[1], g[2]);
                }
                "density" | "viscosity" | "wind" if a.value().split_whitespace().any(|v| v.parse::<f64>() != Ok(0.0)) => {
                    ctx.warn(node, format!("option `{}` = {:?} ignored: ukemi has no fluid forces", a.name(), a.value()));
                }
                // (ukemi's variational integrator takes dampers and servos' velocity gains at
                // the next velocity, as MuJoCo's `implicitfast` does: the choice MJCF files
                // make for stiff servos, and a stable one for those that ask for Euler)
                "integrator" => ctx.warn(node, format!("option `integrator` = {:?} is ignored: ukemi's variational integrator is used (dampers and servo velocity gains implicit, as in MuJoCo's implicitfast)", a.value())),
                other => ctx.warn(node, format!("option `{other}` is ignored (ukemi's own integrator and interior-point solver are used)")),
            }
        }
        for child in elements(node) {
            ctx.warn(child, "option flags are ignored");
        }
    }
    Ok(())
}

/// MuJoCo's filters the builder does not know (welded bodies count as one), and geom pairs whose
/// shapes have no collision kernel (each reported).
fn exclude_pairs(ctx: &mut Ctx, tree: &Tree, b: &mut ModelBuilder) {
    let n = tree.engine_bodies.len();
    // weld id of each engine body: itself if it has joints, else its parent's
    let mut weld = vec![0; n];
    for e in 1..n {
        let has_joints = tree.bodies.iter().any(|bd| bd.engine == e && bd.has_joints);
        weld[e] = if has_joints {
            e
        } else {
            weld[tree.engine_parent[e]]
        };
    }
    for a in 1..n {
        for c in a + 1..n {
            let (wa, wc) = (weld[a], weld[c]);
            let pa = weld[tree.engine_parent[wa]];
            let pc = weld[tree.engine_parent[wc]];
            let filtered = wa == wc || (wa != 0 && wc != 0 && (pa == wc || pc == wa));
            let linked = tree.engine_parent[a] == c || tree.engine_parent[c] == a;
            if filtered && !linked {
                b.add_exclude(&tree.engine_bodies[a].0, &tree.engine_bodies[c].0);
            }
        }
    }
    let mut skipped: std::collections::BTreeMap<String, (usize, String)> = Default::default();
    for (i, ga) in tree.geoms.iter().enumerate() {
        for gb in &tree.geoms[i + 1..] {
            let (a, c) = (ga.engine_body, gb.engine_body);
            let affinity = (ga.def.contype & gb.def.conaffinity) != 0
                || (gb.def.contype & ga.def.conaffinity) != 0;
            let (wa, wc) = (weld[a], weld[c]);
            let skip = a == c
                || !affinity
                || (a == 0 && c == 0)
                || wa == wc
                || (wa != 0
                    && wc != 0
                    && (weld[tree.engine_parent[wa]] == wc || weld[tree.engine_parent[wc]] == wa));
            if skip {
                continue;
            }
            let (Some(sa), Some(sb)) = (ga.def.shape(), gb.def.shape()) else {
                continue;
            };
            if let Err(why) = geometry::candidates(&sa, &sb) {
                b.add_geom_exclude(&ga.name, &gb.name);
                let entry = skipped.entry(why).or_insert((0, String::new()));
                entry.0 += 1;
                if entry.1.is_empty() {
                    entry.1 = format!(
                        "{:?} (line {}) and {:?} (line {})",
                        ga.name,
                        ctx.origin(ga.def.line).1,
                        gb.name,
                        ctx.origin(gb.def.line).1
                    );
                }
            }
        }
    }
    // one warning per kind of unsupported shape pair
    for (why, (count, example)) in skipped {
        let root = ctx.doc.root_element();
        ctx.warn(
            root,
            format!("{count} geom pair(s) will never collide, e.g. {example}: {why}"),
        );
    }
}

/// Give a builder error the line of the element it names.
fn locate(ctx: &Ctx, e: Error) -> Error {
    let (field, msg) = match &e {
        Error::InvalidModel { field, .. } => (field.clone(), e.to_string()),
        _ => return e,
    };
    let key = field.split('.').next().unwrap_or("");
    match ctx.lines.get(key) {
        Some(&line) => {
            let (source_name, line) = ctx.origin(line);
            Error::Mjcf {
                source_name,
                line,
                msg,
            }
        }
        None => Error::Mjcf {
            source_name: ctx.source.clone(),
            line: 0,
            msg,
        },
    }
}
