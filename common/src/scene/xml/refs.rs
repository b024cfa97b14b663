//! Resolving `<ref>`s once the whole document (with its includes) is parsed, so forward
//! references work: each `<ref id>` is replaced by a copy of the element with that id (or with
//! the id an `<alias>` maps it to), taking the ref's `name`. Plugin code therefore sees plain
//! nested elements; a copy keeps its target's `id`, which is how builders share one instance.
//! An unknown id or a cycle (an element reaching itself through refs or nesting) is an error.
//!
//! Copies multiply: a 1 MiB string referenced by a thousand shapes is a gigabyte. So the
//! expanded tree is counted in bytes ([`MAX_EXPANDED_BYTES`]), and in depth ([`MAX_DEPTH`]:
//! a ref puts its target's whole depth below it, and every later walk recurses that deep).

use super::super::error::SceneError;
use super::element::Element;
use super::parser::MAX_NESTING;
use std::collections::{HashMap, HashSet};

/// The most bytes the tree may hold once references are copied in.
pub const MAX_EXPANDED_BYTES: usize = 64 << 20;
/// How deep elements may nest once references are copied in.
pub const MAX_DEPTH: usize = 2 * MAX_NESTING;

/// Replaces every `<ref>` below `root` (at any depth) by the element it names. `aliases` maps an
/// alias to the id it stands for.
pub(super) fn resolve_refs(root: &mut Element, aliases: &HashMap<String, String>) -> Result<(), SceneError> {
    let mut referenced = HashSet::new();
    refs_below(root, aliases, &mut referenced);
    let mut resolver =
        Resolver { definitions: HashMap::new(), aliases, done: HashMap::new(), stack: vec![], bytes: 0, depth: 0 };
    // only referenced elements are kept aside: each copy of a subtree counts
    resolver.collect(root, &referenced)?;
    resolver.expand(root)
}

/// The ids `<ref>`s below `e` name (aliases followed).
fn refs_below(e: &Element, aliases: &HashMap<String, String>, out: &mut HashSet<String>) {
    for c in &e.children {
        if c.tag == "ref" {
            out.insert(aliases.get(&c.plugin).unwrap_or(&c.plugin).clone());
        } else {
            refs_below(c, aliases, out);
        }
    }
}

/// Bytes of `e` with its children.
fn bytes(e: &Element) -> usize {
    e.own_bytes() + e.children.iter().map(bytes).sum::<usize>()
}

/// How many levels `e` spans (1 for a leaf).
fn depth(e: &Element) -> usize {
    1 + e.children.iter().map(depth).max().unwrap_or(0)
}

struct Resolver<'a> {
    /// Every referenced element with an id, as parsed.
    definitions: HashMap<String, Element>,
    aliases: &'a HashMap<String, String>,
    /// Definitions with their refs resolved, with their bytes and depth.
    done: HashMap<String, (Element, usize, usize)>,
    /// Ids of the elements being expanded, outermost first.
    stack: Vec<String>,
    /// Bytes held so far: the tree, the definitions and their copies.
    bytes: usize,
    /// How deep the element being expanded is.
    depth: usize,
}

impl Resolver<'_> {
    fn grow(&mut self, bytes: usize, levels: usize, at: &Element) -> Result<(), SceneError> {
        self.bytes += bytes;
        if self.bytes > MAX_EXPANDED_BYTES {
            return Err(SceneError::at(
                &at.location,
                format!("references expand the scene past {} MiB", MAX_EXPANDED_BYTES >> 20),
            ));
        }
        if self.depth + levels > MAX_DEPTH {
            return Err(SceneError::at(&at.location, format!("references nest elements more than {MAX_DEPTH} deep")));
        }
        Ok(())
    }

    fn collect(&mut self, e: &Element, referenced: &HashSet<String>) -> Result<(), SceneError> {
        if let Some(id) = e.id.as_ref().filter(|id| referenced.contains(*id)) {
            self.grow(bytes(e), 0, e)?;
            self.definitions.insert(id.clone(), e.clone());
        }
        e.children.iter().try_for_each(|c| self.collect(c, referenced))
    }

    fn expand(&mut self, e: &mut Element) -> Result<(), SceneError> {
        self.grow(e.own_bytes(), 1, e)?;
        if let Some(id) = &e.id {
            self.stack.push(id.clone());
        }
        self.depth += 1;
        for child in &mut e.children {
            if child.tag == "ref" {
                *child = self.target(child)?;
            } else {
                self.expand(child)?;
            }
        }
        self.depth -= 1;
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
            Some((_, bytes, levels)) => {
                let (bytes, levels) = (*bytes, *levels);
                // counted before the copy is made
                self.grow(bytes, levels, r)?;
                self.done[&id].0.clone()
            }
            None => {
                let mut t =
                    self.definitions.get(&id).cloned().ok_or_else(|| {
                        SceneError::at(&r.location, format!("reference to unknown id \"{}\"", r.plugin))
                    })?;
                // placed here, so expanded at this depth; the copy kept for later refs counts too
                self.expand(&mut t)?;
                let (b, d) = (bytes(&t), depth(&t));
                self.grow(b, 0, r)?;
                self.done.insert(id, (t.clone(), b, d));
                t
            }
        };
        target.name = r.name.clone();
        target.reference = Some(r.location.clone());
        Ok(target)
    }
}
