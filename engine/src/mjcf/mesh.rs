//! `<asset><mesh>`: meshes from STL, OBJ or MSH files (`compiler/@meshdir`, `@assetdir`) or inline
//! `vertex` lists, scaled by `scale`. A mesh geom collides as the convex hull of its vertices
//! and weighs as the solid hull, as MuJoCo's does (`inertia="convex"`; for a convex mesh every
//! MuJoCo inertia mode agrees). As in MuJoCo, a mesh is recentred on its hull's centre of
//! volume and principal axes, and a geom using it is placed there ([`MeshAsset::frame`]).
use std::collections::HashMap;
use std::path::{Path, PathBuf};
use std::sync::Arc;

use nalgebra::{Matrix3, Rotation3, UnitQuaternion, Vector3};
use roxmltree::Node;

use super::frame::Frame;
use super::parse::{Ctx, elements};
use crate::Result;
use crate::contact::hull::ConvexHull;

/// A compiled mesh asset.
#[derive(Clone, Debug)]
pub(super) struct MeshAsset {
    /// The hull in the mesh's principal frame (centred on its centre of volume).
    pub hull: Arc<ConvexHull>,
    /// Volume of the solid hull (m³).
    pub volume: f64,
    /// Principal moments of inertia per unit density (m⁵).
    pub moments: Vector3<f64>,
    /// The principal frame in the mesh's own coordinates: where a geom using the mesh sits
    /// within the geom's frame.
    pub frame: Frame,
}

/// The `<asset><mesh>` elements of the model by name (read when a geom first needs one:
/// visual meshes, often the largest, are never loaded).
pub(super) fn index_meshes<'a, 'i>(
    ctx: &Ctx<'a, 'i>,
    root: Node<'a, 'i>,
) -> Result<HashMap<String, roxmltree::NodeId>> {
    let mut out = HashMap::new();
    for asset in elements(root).filter(|n| n.tag_name().name() == "asset") {
        for node in elements(asset).filter(|n| n.tag_name().name() == "mesh") {
            let name = mesh_name(ctx, node)?;
            if out.insert(name.clone(), node.id()).is_some() {
                return Err(ctx.err(node, format!("duplicate mesh name {name:?}")));
            }
        }
    }
    Ok(out)
}

/// The mesh `name` (read and cached on first use), or an error at the geom `node`.
pub(super) fn mesh<'a, 'i>(
    ctx: &mut Ctx<'a, 'i>,
    node: Node<'a, 'i>,
    name: &str,
) -> Result<MeshAsset> {
    if let Some(m) = ctx.meshes.get(name) {
        return Ok(m.clone());
    }
    let Some(element) = ctx
        .mesh_nodes
        .get(name)
        .and_then(|&id| ctx.doc.get_node(id))
    else {
        return Err(ctx.err(node, format!("attribute `mesh` = {name:?}: unknown mesh")));
    };
    let dir = ctx.dir.clone();
    let mesh = read_mesh(ctx, element, dir.as_deref())?;
    ctx.meshes.insert(name.to_string(), mesh.clone());
    Ok(mesh)
}

/// A mesh's name: `name`, else its file's name without the extension (as MuJoCo names it).
fn mesh_name(ctx: &Ctx, node: Node) -> Result<String> {
    match (node.attribute("name"), node.attribute("file")) {
        (Some(n), _) => Ok(n.to_string()),
        (None, Some(f)) => Ok(Path::new(f)
            .file_stem()
            .map_or_else(String::new, |s| s.to_string_lossy().into_owned())),
        (None, None) => Err(ctx.err(node, "an inline mesh needs a `name`")),
    }
}

fn read_mesh<'a, 'i>(
    ctx: &mut Ctx<'a, 'i>,
    node: Node<'a, 'i>,
    dir: Option<&Path>,
) -> Result<MeshAsset> {
    let class = ctx.class_of(node, "main")?;
    for a in ["refpos", "refquat", "builtin", "plugin", "params"] {
        if node.attribute(a).is_some() {
            return Err(ctx.unsupported(node, format!("mesh attribute `{a}`")));
        }
    }
    if let Some(mode) = ctx.raw(node, &class, "inertia")
        && mode == "shell"
    {
        return Err(ctx.unsupported(node, "mesh inertia=\"shell\""));
    }
    if ctx
        .raw(node, &class, "maxhullvert")
        .is_some_and(|v| v.trim() != "-1")
    {
        ctx.warn(
            node,
            "`maxhullvert` is ignored: the whole convex hull is used",
        );
    }
    let scale = ctx.nums_padded(node, &class, "scale", &[1.0, 1.0, 1.0])?;
    let file = node.attribute("file");
    let mut points = match (file, node.attribute("vertex")) {
        (Some(_), Some(_)) => return Err(ctx.err(node, "mesh has both `file` and `vertex`")),
        (None, None) => return Err(ctx.err(node, "mesh needs a `file` or a `vertex` list")),
        (None, Some(text)) => {
            let v = ctx.floats(node, "vertex", text)?;
            if v.len() % 3 != 0 {
                return Err(ctx.err(
                    node,
                    format!(
                        "attribute `vertex`: {} numbers, not a multiple of 3",
                        v.len()
                    ),
                ));
            }
            v.chunks_exact(3)
                .map(|c| Vector3::new(c[0], c[1], c[2]))
                .collect()
        }
        (Some(f), None) => {
            let path = resolve(ctx, f, dir);
            load_points(&path).map_err(|e| {
                ctx.err(node, format!("mesh file {:?} ({}): {e}", f, path.display()))
            })?
        }
    };
    for p in &mut points {
        *p = p.component_mul(&Vector3::new(scale[0], scale[1], scale[2]));
    }
    let name = mesh_name(ctx, node)?;
    let hull =
        ConvexHull::new(&points).map_err(|e| ctx.err(node, format!("mesh {name:?}: {e}")))?;
    let (volume, com, inertia) = hull.mass_properties();
    if volume.is_nan() || volume <= 0.0 {
        return Err(ctx.err(node, format!("mesh {name:?}: its hull has no volume")));
    }
    // principal axes (a proper rotation: columns are the new frame's axes in mesh coordinates)
    let eig = inertia.symmetric_eigen();
    let mut axes: Matrix3<f64> = eig.eigenvectors;
    if axes.determinant() < 0.0 {
        axes.column_mut(2).neg_mut();
    }
    let rot = UnitQuaternion::from_rotation_matrix(&Rotation3::from_matrix_unchecked(axes));
    let hull = hull.transformed(&axes.transpose(), &com);
    let mesh = MeshAsset {
        hull: Arc::new(hull),
        volume,
        moments: eig.eigenvalues,
        frame: Frame {
            pos: com,
            quat: rot.into_inner(),
        },
    };
    Ok(mesh)
}

/// A mesh file's path: absolute as given, else under `meshdir` (or `assetdir`), themselves
/// relative to the model's folder (the working directory for a model given as a string);
/// with `compiler/@strippath`, the file's name alone.
fn resolve(ctx: &Ctx, file: &str, dir: Option<&Path>) -> PathBuf {
    let mut file = Path::new(file);
    if ctx.compiler.strippath
        && let Some(name) = file.file_name()
    {
        file = Path::new(name);
    }
    if file.is_absolute() {
        return file.to_path_buf();
    }
    let base = dir.map_or_else(PathBuf::new, Path::to_path_buf);
    let sub = ctx
        .compiler
        .meshdir
        .as_deref()
        .or(ctx.compiler.assetdir.as_deref());
    match sub {
        Some(s) if Path::new(s).is_absolute() => Path::new(s).join(file),
        Some(s) => base.join(s).join(file),
        None => base.join(file),
    }
}

/// The vertices of MuJoCo's own binary mesh format: four little-endian `i32` counts
/// (vertices, normals, texture coordinates, faces), then the vertices as `f32` triples (the
/// normals, texture coordinates and faces that follow are not needed for the hull).
fn read_msh(bytes: &[u8]) -> std::result::Result<Vec<Vector3<f64>>, String> {
    let word = |k: usize| -> Option<[u8; 4]> { bytes.get(4 * k..4 * k + 4)?.try_into().ok() };
    let count = |k: usize| word(k).map(i32::from_le_bytes);
    let (Some(nv), Some(nn), Some(nt), Some(nf)) = (count(0), count(1), count(2), count(3)) else {
        return Err("an MSH file starts with four counts".to_string());
    };
    let size = |n: i32, per: i64| i64::from(n) * per;
    let expected = 16 + 4 * (size(nv, 3) + size(nn, 3) + size(nt, 2) + size(nf, 3));
    if nv < 0 || nn < 0 || nt < 0 || nf < 0 || expected != bytes.len() as i64 {
        return Err(format!(
            "MSH counts {nv} vertices, {nn} normals, {nt} texture coordinates, {nf} faces do \
             not match its {} bytes",
            bytes.len()
        ));
    }
    let float = |k: usize| word(k).map_or(0.0, |w| f64::from(f32::from_le_bytes(w)));
    Ok((0..nv as usize)
        .map(|i| Vector3::new(float(4 + 3 * i), float(5 + 3 * i), float(6 + 3 * i)))
        .collect())
}

/// The vertices of an STL (binary or ASCII) or OBJ file.
fn load_points(path: &Path) -> std::result::Result<Vec<Vector3<f64>>, String> {
    let ext = path
        .extension()
        .map(|e| e.to_string_lossy().to_ascii_lowercase())
        .unwrap_or_default();
    match ext.as_str() {
        "stl" => {
            let mut f = std::fs::File::open(path).map_err(|e| e.to_string())?;
            let mesh = stl_io::read_stl(&mut f).map_err(|e| e.to_string())?;
            Ok(mesh
                .vertices
                .iter()
                .map(|v| Vector3::new(f64::from(v[0]), f64::from(v[1]), f64::from(v[2])))
                .collect())
        }
        "obj" => {
            let (models, _) =
                tobj::load_obj(path, &tobj::LoadOptions::default()).map_err(|e| e.to_string())?;
            Ok(models
                .iter()
                .flat_map(|m| m.mesh.positions.chunks_exact(3))
                .map(|p| Vector3::new(f64::from(p[0]), f64::from(p[1]), f64::from(p[2])))
                .collect())
        }
        "msh" => read_msh(&std::fs::read(path).map_err(|e| e.to_string())?),
        other => Err(format!(
            "unsupported mesh format {other:?} (STL, OBJ and MSH are read)"
        )),
    }
}
