//! `<include file="...">`: MuJoCo splices the children of the included file's `<mujoco>` root
//! in place of the element, recursively (a robot's `scene.xml` includes the robot). A path is
//! looked up beside the including file, then beside the model file that was loaded (MuJoCo
//! 4.0.0 finds a nested include in either). The loader reads the
//! spliced text; every line of it remembers the file and line it came from, so messages name
//! those.
use std::ops::Range;
use std::path::Path;

use roxmltree::Document;

use crate::{Error, Result};

/// Deepest nesting of includes (a file including itself would never end).
const MAX_DEPTH: usize = 16;

/// The spliced model text and where each of its lines came from.
pub(super) struct Spliced {
    pub xml: String,
    /// File names, indexed by the first member of `lines`.
    pub sources: Vec<String>,
    /// Per line of `xml` (0-based): (source index, 1-based line in that source).
    pub lines: Vec<(usize, usize)>,
}

impl Spliced {
    /// The file and 1-based line that 1-based line `row` of the spliced text came from.
    pub fn origin(&self, row: usize) -> (String, usize) {
        match self.lines.get(row.wrapping_sub(1)) {
            Some(&(s, l)) => (self.sources[s].clone(), l),
            None => (self.sources[0].clone(), row),
        }
    }
}

/// `xml` (named `source`) with its `<include>` elements spliced in, or `None` when it has
/// none. `dir`: the directory include paths are relative to (`None` for a model given as a
/// string, which then may not include files).
pub(super) fn splice(xml: &str, source: &str, dir: Option<&Path>) -> Result<Option<Spliced>> {
    if !xml.contains("<include") {
        return Ok(None);
    }
    let mut sources = vec![source.to_string()];
    let identity: Vec<(usize, usize)> = (1..=xml.lines().count().max(1)).map(|l| (0, l)).collect();
    let (xml, lines) = expand(xml, &identity, 0, (dir, dir), &mut sources, 0)?;
    Ok(Some(Spliced {
        xml,
        sources,
        lines,
    }))
}

/// A malformed-XML error at the origin of spliced line `row`.
fn malformed(
    sources: &[String],
    map: &[(usize, usize)],
    row: usize,
    e: impl std::fmt::Display,
) -> Error {
    let (s, l) = map.get(row.wrapping_sub(1)).copied().unwrap_or((0, row));
    Error::Mjcf {
        source_name: sources[s].clone(),
        line: l,
        msg: format!("malformed XML: {e}"),
    }
}

/// `text` (whose lines come from `map`) with its includes spliced in, and its new line map.
/// `(dir, top)`: the directories of the including file and of the model file.
fn expand(
    text: &str,
    map: &[(usize, usize)],
    src: usize,
    (dir, top): (Option<&Path>, Option<&Path>),
    sources: &mut Vec<String>,
    depth: usize,
) -> Result<(String, Vec<(usize, usize)>)> {
    let doc =
        Document::parse(text).map_err(|e| malformed(sources, map, e.pos().row as usize, e))?;
    let at = |pos: usize| doc.text_pos_at(pos).row as usize;
    let includes: Vec<_> = doc
        .descendants()
        .filter(|n| n.is_element() && n.tag_name().name() == "include")
        .collect();
    let (mut out, mut out_map) = (String::with_capacity(text.len()), Vec::new());
    let mut cursor = 0;
    for node in includes {
        let (here, line) = map
            .get(at(node.range().start) - 1)
            .copied()
            .unwrap_or((src, 0));
        let here = sources[here].clone();
        let err = |msg: String| Error::Mjcf {
            source_name: here.clone(),
            line,
            msg: format!("<include>: {msg}"),
        };
        let file = node
            .attribute("file")
            .ok_or_else(|| err("`file` is required".into()))?;
        let dir = dir.ok_or_else(|| {
            err(format!(
                "cannot include {file:?} in a model given as a string: load it from its file"
            ))
        })?;
        if depth >= MAX_DEPTH {
            return Err(err(format!(
                "{file:?}: includes nested deeper than {MAX_DEPTH} (a file including itself?)"
            )));
        }
        let beside_top = top.map(|t| t.join(file)).filter(|p| p.exists());
        let path = match dir.join(file) {
            p if !p.exists() && beside_top.is_some() => beside_top.unwrap_or(p),
            p => p,
        };
        let inner = std::fs::read_to_string(&path)
            .map_err(|e| err(format!("cannot read {}: {e}", path.display())))?;
        sources.push(path.display().to_string());
        let isrc = sources.len() - 1;
        let imap: Vec<(usize, usize)> = (1..=inner.lines().count().max(1))
            .map(|l| (isrc, l))
            .collect();
        let idir = path.parent().unwrap_or(dir);
        let (inner, imap) = expand(&inner, &imap, isrc, (Some(idir), top), sources, depth + 1)?;
        let idoc = Document::parse(&inner)
            .map_err(|e| malformed(sources, &imap, e.pos().row as usize, e))?;
        let root = idoc.root_element();
        if root.tag_name().name() != "mujoco" {
            return Err(err(format!("{file:?}: its root element must be <mujoco>")));
        }
        append(
            &mut out,
            &mut out_map,
            text,
            map,
            cursor..node.range().start,
        );
        if let (Some(first), Some(last)) = (root.first_child(), root.last_child()) {
            let range = first.range().start..last.range().end;
            append(&mut out, &mut out_map, &inner, &imap, range);
        }
        cursor = node.range().end;
    }
    append(&mut out, &mut out_map, text, map, cursor..text.len());
    Ok((out, out_map))
}

/// Append `text[range]` (lines from `map`) to `out`, keeping `out_map` one entry per line of
/// `out` (a line's origin is the text that began it: a line that starts in one file and ends
/// in another, around a splice, is the first file's).
fn append(
    out: &mut String,
    out_map: &mut Vec<(usize, usize)>,
    text: &str,
    map: &[(usize, usize)],
    range: Range<usize>,
) {
    let origin = |line: usize| map.get(line).copied().unwrap_or((0, line + 1));
    let mut line = text[..range.start].matches('\n').count();
    if out_map.is_empty() {
        out_map.push(origin(line));
    }
    for c in text[range.clone()].chars() {
        out.push(c);
        if c == '\n' {
            line += 1;
            out_map.push(origin(line));
        }
    }
}
