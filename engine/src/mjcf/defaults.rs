//! MJCF default classes: `<default class="...">` trees whose element attributes are inherited by
//! nested classes and used by elements that name the class (or sit in a body with `childclass`).
use std::collections::HashMap;

use roxmltree::Node;

use super::parse::default_group;

#[derive(Clone, Debug, Default)]
struct Class {
    parent: Option<String>,
    /// group (element name, actuators share "actuator") → attribute → value
    attrs: HashMap<String, HashMap<String, String>>,
}

/// All default classes by name; the root class is `main`.
#[derive(Clone, Debug, Default)]
pub(super) struct Defaults {
    classes: HashMap<String, Class>,
}

impl Defaults {
    /// Whether a class of this name exists.
    pub fn has(&self, name: &str) -> bool {
        self.classes.contains_key(name)
    }

    /// Attribute `attr` of element group `group` in `class` or its ancestors.
    pub fn lookup(&self, class: &str, group: &str, attr: &str) -> Option<String> {
        let mut cur = Some(class);
        let mut guard = 0;
        while let Some(c) = cur {
            let cls = self.classes.get(c)?;
            if let Some(v) = cls.attrs.get(group).and_then(|a| a.get(attr)) {
                return Some(v.clone());
            }
            cur = cls.parent.as_deref();
            guard += 1;
            if guard > 10_000 {
                return None;
            }
        }
        None
    }

    /// Read a `<default>` element (and its nested classes) under `parent`. Returns the names of
    /// classes that were defined twice or nested defaults without a class name (errors).
    pub fn read<'a, 'i>(
        &mut self,
        node: Node<'a, 'i>,
        parent: Option<&str>,
    ) -> Result<(), (Node<'a, 'i>, String)> {
        let name = match (node.attribute("class"), parent) {
            (Some(c), _) => c.to_string(),
            (None, None) => "main".to_string(),
            (None, Some(_)) => return Err((node, "nested <default> needs a `class`".into())),
        };
        if self.classes.contains_key(&name) && !(name == "main" && parent.is_none()) {
            return Err((node, format!("default class {name:?} defined twice")));
        }
        let mut class = self.classes.remove(&name).unwrap_or_default();
        class.parent = parent.map(str::to_string);
        for child in node.children().filter(|c| c.is_element()) {
            let tag = child.tag_name().name();
            if tag == "default" {
                continue;
            }
            let group = class
                .attrs
                .entry(default_group(tag).to_string())
                .or_default();
            for a in child.attributes() {
                group.insert(a.name().to_string(), a.value().to_string());
            }
        }
        self.classes.insert(name.clone(), class);
        for child in node
            .children()
            .filter(|c| c.is_element() && c.tag_name().name() == "default")
        {
            self.read(child, Some(&name))?;
        }
        Ok(())
    }

    /// Ensure the root class exists.
    pub fn ensure_main(&mut self) {
        self.classes.entry("main".into()).or_default();
    }
}
