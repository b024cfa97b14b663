//! Resolving `<ref>`s once the whole document (with its includes) is parsed, so forward
//! references work: each `<ref id>` is replaced by a copy of the element with that id (or with
//! the id an `<alias>` maps it to), taking the ref's `name`. Plugin code therefore sees plain
//! nested elements; a copy keeps its target's `id`, which is how builders share one instance.
//! An unknown id or a cycle (an element reaching itself through refs or nesting) is an error.

use super::super::error::SceneError;
use super::element::Element;
use std::collections::HashMap;

/// More element copies than this means references multiply out of proportion (a reference
/// bomb); real scenes stay far below.
const MAX_ELEMENTS: usize = 1_000_000;

/// Replaces every `<ref>` below `root` (at any depth) by the element it names. `aliases` maps an
/// alias to the id it stands for.
pub(super) fn resolve_refs(root: &mut Element, aliases: &HashMap<String, String>) -> Result<(), SceneError> {
    let mut definitions = HashMap::new();
    collect(root, &mut definitions);
    let mut resolver = Resolver { definitions, aliases, done: HashMap::new(), stack: vec![], count: 0 };
    resolver.expand(root)
}

fn collect(e: &Element, out: &mut HashMap<String, Element>) {
    if let Some(id) = &e.id {
        out.insert(id.clone(), e.clone());
    }
    for c in &e.children {
        collect(c, out);
    }
}

fn size(e: &Element) -> usize {
    1 + e.children.iter().map(size).sum::<usize>()
}

struct Resolver<'a> {
    /// Every element with an id, as parsed.
    definitions: HashMap<String, Element>,
    aliases: &'a HashMap<String, String>,
    /// Definitions with their refs resolved, and how many elements each holds.
    done: HashMap<String, (Element, usize)>,
    /// Ids of the elements being expanded, outermost first.
    stack: Vec<String>,
    count: usize,
}

impl Resolver<'_> {
    fn grow(&mut self, n: usize, at: &Element) -> Result<(), SceneError> {
        self.count += n;
        if self.count > MAX_ELEMENTS {
            return Err(SceneError::at(&at.location, "references expand to more than a million elements"));
        }
        Ok(())
    }

    fn expand(&mut self, e: &mut Element) -> Result<(), SceneError> {
        self.grow(1, e)?;
        if let Some(id) = &e.id {
            self.stack.push(id.clone());
        }
        for child in &mut e.children {
            if child.tag == "ref" {
                *child = self.target(child)?;
            } else {
                self.expand(child)?;
            }
        }
        if e.id.is_some() {
            self.stack.pop();
        }
        Ok(())
    }

    /// A resolved copy of the element `r` refers to.
    fn target(&mut self, r: &Element) -> Result<Element, SceneError> {
        let id = self.aliases.get(&r.plugin).unwrap_or(&r.plugin).clone();
        if let Some(start) = self.stack.iter().position(|s| *s == id) {
            let mut cycle = self.stack[start..].to_vec();
            cycle.push(id);
            return Err(SceneError::at(&r.location, format!("circular reference: {}", cycle.join(" -> "))));
        }
        let mut target = match self.done.get(&id) {
            Some((t, size)) => {
                let (t, size) = (t.clone(), *size);
                self.grow(size, r)?;
                t
            }
            None => {
                let mut t =
                    self.definitions.get(&id).cloned().ok_or_else(|| {
                        SceneError::at(&r.location, format!("reference to unknown id \"{}\"", r.plugin))
                    })?;
                self.expand(&mut t)?;
                self.done.insert(id, (t.clone(), size(&t)));
                t
            }
        };
        target.name = r.name.clone();
        target.reference = Some(r.location.clone());
        Ok(target)
    }
}
