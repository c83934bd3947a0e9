//! XML access for the MJCF loader: attribute lookup through default classes, typed parsing with
//! errors that name the element, attribute, bad value and line, and the warning list.
use std::collections::HashMap;

use roxmltree::{Document, Node};

use super::defaults::Defaults;
use crate::Error;

/// Compiler settings (`<compiler>`).
#[derive(Clone, Debug)]
pub(super) struct Compiler {
    /// Angles in degrees (`angle="degree"`, MuJoCo's default).
    pub degree: bool,
    /// `eulerseq`, three characters of `xyzXYZ`.
    pub eulerseq: [u8; 3],
    /// `inertiafromgeom`: Some(true) = always, Some(false) = never, None = auto.
    pub inertia_from_geom: Option<bool>,
    /// `autolimits`.
    pub autolimits: bool,
    /// `inertiagrouprange`.
    pub inertia_groups: (i64, i64),
    /// `settotalmass` (> 0 to rescale).
    pub total_mass: Option<f64>,
    /// `meshdir`: where mesh files are, relative to the model's folder.
    pub meshdir: Option<String>,
    /// `assetdir`: the same for every asset, where `meshdir` is not given.
    pub assetdir: Option<String>,
    /// `strippath`: asset files are named by their file names alone.
    pub strippath: bool,
}

impl Default for Compiler {
    fn default() -> Self {
        Compiler {
            degree: true,
            eulerseq: *b"xyz",
            inertia_from_geom: None,
            autolimits: true,
            inertia_groups: (0, 5),
            total_mass: None,
            meshdir: None,
            assetdir: None,
            strippath: false,
        }
    }
}

/// Parsing context: the document, defaults, compiler settings, warnings.
pub(super) struct Ctx<'a, 'input> {
    pub doc: &'a Document<'input>,
    pub source: String,
    pub defaults: Defaults,
    pub compiler: Compiler,
    pub warnings: Vec<String>,
    /// Line of each named entity, for errors the builder reports later.
    pub lines: HashMap<String, usize>,
    /// Scale of every body mass and inertia (`settotalmass`), 1 otherwise.
    pub mass_scale: f64,
    /// Geoms named by a `<contact><pair>`: kept even when their bit masks make them visual.
    pub paired: std::collections::HashSet<String>,
    /// Where each line came from when `<include>`s were spliced in (`None`: `source` alone).
    pub spliced: Option<super::include::Spliced>,
    /// The `<asset><mesh>` elements by name, and those read so far.
    pub mesh_nodes: std::collections::HashMap<String, roxmltree::NodeId>,
    pub meshes: std::collections::HashMap<String, super::mesh::MeshAsset>,
    /// The model file's folder (mesh files are found from it).
    pub dir: Option<std::path::PathBuf>,
}

/// Actuator element names share one default slot (as in MuJoCo).
pub(super) fn default_group(tag: &str) -> &str {
    match tag {
        "motor" | "position" | "velocity" | "general" | "intvelocity" | "damper" | "cylinder"
        | "muscle" | "adhesion" => "actuator",
        other => other,
    }
}

impl<'a, 'input> Ctx<'a, 'input> {
    pub fn line(&self, node: Node) -> usize {
        self.doc.text_pos_at(node.range().start).row as usize
    }

    /// The file and line that line `row` of the model text came from.
    pub fn origin(&self, row: usize) -> (String, usize) {
        match &self.spliced {
            Some(s) => s.origin(row),
            None => (self.source.clone(), row),
        }
    }

    /// An [`Error::Mjcf`] at `node`.
    pub fn err(&self, node: Node, msg: impl Into<String>) -> Error {
        let (source_name, line) = self.origin(self.line(node));
        Error::Mjcf {
            source_name,
            line,
            msg: format!("<{}>: {}", node.tag_name().name(), msg.into()),
        }
    }

    /// An [`Error::Unsupported`] naming the element and line.
    pub fn unsupported(&self, node: Node, msg: impl Into<String>) -> Error {
        let (source, line) = self.origin(self.line(node));
        Error::Unsupported(format!(
            "MJCF {}:{}: <{}{}>: {}",
            source,
            line,
            node.tag_name().name(),
            node.attribute("name")
                .map(|n| format!(" name=\"{n}\""))
                .unwrap_or_default(),
            msg.into()
        ))
    }

    /// Record a warning (once per distinct text).
    pub fn warn(&mut self, node: Node, msg: impl Into<String>) {
        let (source, line) = self.origin(self.line(node));
        let text = format!(
            "MJCF {}:{}: <{}>: {}",
            source,
            line,
            node.tag_name().name(),
            msg.into()
        );
        let key = text
            .split_once(": <")
            .map(|x| x.1)
            .unwrap_or(&text)
            .to_string();
        if !self
            .warnings
            .iter()
            .any(|w| w.split_once(": <").map(|x| x.1) == Some(key.as_str()))
        {
            self.warnings.push(text);
        }
    }

    /// Raw attribute: on the element, else from its default class chain.
    pub fn raw(&self, node: Node<'a, 'input>, class: &str, name: &str) -> Option<String> {
        if let Some(v) = node.attribute(name) {
            return Some(v.to_string());
        }
        self.defaults
            .lookup(class, default_group(node.tag_name().name()), name)
    }

    /// Whitespace-separated finite numbers.
    pub fn floats(&self, node: Node, name: &str, value: &str) -> crate::Result<Vec<f64>> {
        value
            .split_whitespace()
            .map(|t| {
                t.parse::<f64>()
                    .ok()
                    .filter(|x| x.is_finite())
                    .ok_or_else(|| {
                        self.err(
                            node,
                            format!("attribute `{name}` = {value:?}: {t:?} is not a finite number"),
                        )
                    })
            })
            .collect()
    }

    /// Numbers of attribute `name` (with defaults); exactly `n` of them unless `n == 0`.
    pub fn nums(
        &self,
        node: Node<'a, 'input>,
        class: &str,
        name: &str,
        n: usize,
    ) -> crate::Result<Option<Vec<f64>>> {
        let Some(v) = self.raw(node, class, name) else {
            return Ok(None);
        };
        let x = self.floats(node, name, &v)?;
        if n > 0 && x.len() != n {
            return Err(self.err(
                node,
                format!(
                    "attribute `{name}` = {v:?}: need {n} numbers, got {}",
                    x.len()
                ),
            ));
        }
        Ok(Some(x))
    }

    /// Up to `n` numbers (at least one), padded with `default`.
    pub fn nums_padded(
        &self,
        node: Node<'a, 'input>,
        class: &str,
        name: &str,
        default: &[f64],
    ) -> crate::Result<Vec<f64>> {
        let Some(v) = self.raw(node, class, name) else {
            return Ok(default.to_vec());
        };
        let x = self.floats(node, name, &v)?;
        if x.is_empty() || x.len() > default.len() {
            return Err(self.err(
                node,
                format!(
                    "attribute `{name}` = {v:?}: need 1 to {} numbers, got {}",
                    default.len(),
                    x.len()
                ),
            ));
        }
        let mut out = default.to_vec();
        out[..x.len()].copy_from_slice(&x);
        Ok(out)
    }

    /// One number with a default.
    pub fn num(
        &self,
        node: Node<'a, 'input>,
        class: &str,
        name: &str,
        default: f64,
    ) -> crate::Result<f64> {
        Ok(self.nums(node, class, name, 1)?.map_or(default, |v| v[0]))
    }

    /// One of `allowed` keywords, or `default`.
    pub fn keyword(
        &self,
        node: Node<'a, 'input>,
        class: &str,
        name: &str,
        allowed: &[&str],
        default: &str,
    ) -> crate::Result<String> {
        let v = self
            .raw(node, class, name)
            .unwrap_or_else(|| default.into());
        if allowed.contains(&v.as_str()) {
            Ok(v)
        } else {
            Err(self.err(
                node,
                format!("attribute `{name}` = {v:?}: expected one of {allowed:?}"),
            ))
        }
    }

    /// `true` / `false` / `auto` (None).
    pub fn tristate(
        &self,
        node: Node<'a, 'input>,
        class: &str,
        name: &str,
    ) -> crate::Result<Option<bool>> {
        Ok(
            match self
                .keyword(node, class, name, &["true", "false", "auto"], "auto")?
                .as_str()
            {
                "true" => Some(true),
                "false" => Some(false),
                _ => None,
            },
        )
    }

    /// Non-negative integer (bit masks, condim, group).
    pub fn int(
        &self,
        node: Node<'a, 'input>,
        class: &str,
        name: &str,
        default: i64,
    ) -> crate::Result<i64> {
        let Some(v) = self.raw(node, class, name) else {
            return Ok(default);
        };
        v.trim().parse::<i64>().map_err(|_| {
            self.err(
                node,
                format!("attribute `{name}` = {v:?}: expected an integer"),
            )
        })
    }

    /// Element's class: its `class` attribute, else the inherited `childclass`.
    pub fn class_of(&self, node: Node, inherited: &str) -> crate::Result<String> {
        match node.attribute("class") {
            Some(c) if self.defaults.has(c) => Ok(c.to_string()),
            Some(c) => Err(self.err(
                node,
                format!("attribute `class` = {c:?}: unknown default class"),
            )),
            None => Ok(inherited.to_string()),
        }
    }

    /// Angle in radians (converts degrees when `compiler/@angle` is degree).
    pub fn angle(&self, x: f64) -> f64 {
        if self.compiler.degree {
            x.to_radians()
        } else {
            x
        }
    }
}

/// Element children of `node` (no text or comments).
pub(super) fn elements<'a, 'input>(
    node: Node<'a, 'input>,
) -> impl Iterator<Item = Node<'a, 'input>> {
    node.children().filter(|c| c.is_element())
}
