//! Mitsuba 3 scene XML → a tree of plugin elements with typed, located properties.
//!
//! This layer knows the scene language but nothing about what a plugin means (`scene/build.rs`
//! interprets the tree). It follows Mitsuba 3.9.1's `src/core/parser.cpp`:
//!
//! * `$name` parameters from the caller and `<default>`s, substituted textually into every
//!   attribute in document order (`params.rs`); a caller value nobody uses is an error;
//! * `<include filename name?>` found next to the including file, then through the resolver
//!   (at most [`MAX_INCLUDE_DEPTH`] deep); an included `<scene>` has its children spliced in,
//!   any other root becomes one child; every file keeps its own `version`;
//! * `<path value>` prepends a folder to the [`FileResolver`] that plugin filenames are later
//!   resolved with (the final list is [`SceneTree::resolver`]);
//! * ids unique across files, `<alias id as>`, and `<ref id>` anywhere an object may be,
//!   resolved after parsing so forward references work (`refs.rs`);
//! * files older than 2.0.0 upgraded as Mitsuba does (`upgrade.rs`);
//! * `<spectrum>` kept unconverted until a plugin reads it with a [`ColorUsage`].
//!
//! ```
//! use std::{collections::HashMap, path::Path};
//! let xml = r#"<scene version="3.0.0"><default name="r" value="0.5"/>
//!     <bsdf type="diffuse" id="white"><rgb name="reflectance" value="$r"/></bsdf>
//!     <shape type="sphere"><ref id="white"/></shape></scene>"#;
//! let tree = tessera_common::scene::xml::parse(xml, Path::new("scene.xml"), &HashMap::new()).unwrap();
//! // the ref is replaced by a copy of the bsdf it names
//! assert_eq!(tree.elements[1].children[0].id.as_deref(), Some("white"));
//! ```

mod element;
mod params;
mod parser;
mod position;
mod property;
mod refs;
#[cfg(test)]
mod tests;
mod upgrade;

pub use super::resolver::FileResolver;
pub use crate::spectrum::ColorUsage;
pub use element::{Element, Property, Value};
pub use parser::{MAX_INCLUDE_DEPTH, MAX_NESTING, MAX_XML_BYTES};

use super::error::SceneError;
use params::Params;
use parser::{Session, check_unique_names, parse_document};
use std::collections::HashMap;
use std::path::{Path, PathBuf};

/// The parsed `<scene>` with its includes, refs resolved.
#[derive(Debug)]
pub struct SceneTree {
    /// Top-level elements in document order (those of included scenes where the include was).
    pub elements: Vec<Element>,
    /// Parameters of the `<scene>` element itself.
    pub properties: Vec<Property>,
    /// The search list plugin filenames resolve through: the main scene's folder with every
    /// top-level `<path>` of the main scene in front.
    pub resolver: FileResolver,
    /// Every file read besides the main scene (included XML files, spectrum files), in the
    /// order they were read.
    pub files: Vec<PathBuf>,
}

impl SceneTree {
    /// The element with `id`, at any depth.
    pub fn by_id(&self, id: &str) -> Option<&Element> {
        fn find<'a>(e: &'a Element, id: &str) -> Option<&'a Element> {
            if e.id.as_deref() == Some(id) {
                return Some(e);
            }
            e.children.iter().find_map(|c| find(c, id))
        }
        self.elements.iter().find_map(|e| find(e, id))
    }
}

/// Parses a Mitsuba 3 XML document. `file` names it in messages and anchors relative paths
/// (includes, `<path>`, filenames); `defines` are the caller's `$name` values (Mitsuba's
/// `-D name=value`), which override `<default>`s.
pub fn parse(text: &str, file: &Path, defines: &HashMap<String, String>) -> Result<SceneTree, SceneError> {
    parse_confined(text, file, defines, None)
}

/// [`parse`], finding files only inside folder `root` when given (a farm job's bundle: see
/// [`FileResolver::confined`]).
pub fn parse_confined(
    text: &str,
    file: &Path,
    defines: &HashMap<String, String>,
    root: Option<&Path>,
) -> Result<SceneTree, SceneError> {
    let dir = file.parent().unwrap_or(Path::new(""));
    let resolver = match root {
        Some(root) => FileResolver::confined(dir, root),
        None => FileResolver::new(dir),
    };
    let params = Params::new(defines).map_err(|e| SceneError::file(file, e))?;
    let mut session = Session::new(params, resolver);
    let (mut root, old) = parse_document(&mut session, file, text, 0)?;
    if root.tag != "scene" {
        return Err(SceneError::at(&root.location, format!("the root element must be <scene>, found <{}>", root.tag)));
    }
    if old {
        upgrade::upgrade_from_v1(&mut root)?;
    }
    check_unique_names(&root)?;
    if let Some((name, value)) = session.params.unused().first() {
        return Err(SceneError::file(
            file,
            format!("parameter \"{name}\" (given as {name}={value}) is not used by the scene"),
        ));
    }
    refs::resolve_refs(&mut root, &session.aliases)?;
    Ok(SceneTree {
        elements: root.children,
        properties: root.properties,
        resolver: session.resolver,
        files: session.files,
    })
}
