//! The document walk: one [`FileParser`] per XML file, sharing a [`Session`] across
//! `<include>`s (parameters, ids, the file resolver, the files read).
//!
//! Elements are handled in document order, so a `<default>` applies from where it is written,
//! an `<alias>` sees only ids defined before it, and a `<path>` affects what follows. Every
//! attribute of every element is substituted before the element is interpreted, as in Mitsuba.
//!
//! A scene may be hostile (docs/decisions/0015-limits-on-hostile-input.md), so the walk is
//! bounded: elements nest at most [`MAX_NESTING`] deep (the walk recurses, and so do the later
//! walks and the tree's drop), a scene has at most [`MAX_XML_BYTES`] of XML and
//! [`MAX_XML_NODES`] nodes across its files, at most [`MAX_INCLUDES`] includes and
//! [`MAX_SEARCH_PATHS`] `<path>`s, and every
//! location costs constant time ([`Positions`]).

use super::super::error::{Location, SceneError};
use super::super::resolver::FileResolver;
use super::element::Element;
use super::params::{MAX_TOTAL_BYTES, MAX_VALUE_BYTES, Params, SubstituteError};
use super::position::Positions;
use super::upgrade::upgrade_from_v1;
use std::collections::{HashMap, HashSet};
use std::path::{Path, PathBuf};
use std::sync::Arc;

/// Mitsuba's `max_include_depth`: the main file is depth 0, so includes nest 14 deep.
pub const MAX_INCLUDE_DEPTH: usize = 15;
/// The most XML a scene may have, its includes (each time included) counted. Mitsuba scenes
/// keep geometry in mesh files; the largest real ones have a few MiB of XML.
pub const MAX_XML_BYTES: usize = 64 << 20;
/// The most XML nodes (elements, attributes' text and whitespace) a scene may have across its
/// files: at this limit roxmltree holds about 95 MB.
pub const MAX_XML_NODES: u32 = 1_000_000;
/// How deep elements may nest, counting the root and objects of included files where they are
/// included. Real scenes nest about ten deep; every walk of the tree recurses this deep.
pub const MAX_NESTING: usize = 32;
/// The most `<path>` folders a scene may add: every file name is looked for in each.
pub const MAX_SEARCH_PATHS: usize = 64;
/// The most `<include>`s a scene may read, each time counted: three files of 60 includes of
/// the next one were 216 000 parses.
pub const MAX_INCLUDES: usize = 1024;

/// Tags of plugin objects (besides `<scene>` and `<spectrum type=..>`).
const OBJECT_TAGS: &[&str] = &[
    "bsdf",
    "emitter",
    "film",
    "integrator",
    "medium",
    "phase",
    "rfilter",
    "sampler",
    "sensor",
    "shape",
    "texture",
    "volume",
];

/// State shared by every file of one scene.
pub(super) struct Session {
    pub(super) params: Params,
    /// Every id and alias defined so far, with where.
    pub(super) ids: HashMap<String, Location>,
    /// Alias → the id it stands for.
    pub(super) aliases: HashMap<String, String>,
    /// The search list in force at this point of the document.
    pub(super) resolver: FileResolver,
    /// Included XML and spectrum files read, in order, without repeats.
    pub(super) files: Vec<PathBuf>,
    files_seen: HashSet<PathBuf>,
    /// Bytes of XML parsed so far.
    pub(super) xml_bytes: usize,
    /// XML nodes parsed so far.
    xml_nodes: u32,
    /// How deep the element being parsed is nested (the root is 1).
    nesting: usize,
    /// `<path>` folders added.
    search_paths: usize,
    /// `<include>`s read.
    includes: usize,
}

impl Session {
    pub(super) fn new(params: Params, resolver: FileResolver) -> Self {
        Session {
            params,
            ids: HashMap::new(),
            aliases: HashMap::new(),
            resolver,
            files: vec![],
            files_seen: HashSet::new(),
            xml_bytes: 0,
            xml_nodes: 0,
            nesting: 0,
            search_paths: 0,
            includes: 0,
        }
    }

    pub(super) fn record_file(&mut self, path: &Path) {
        if self.files_seen.insert(path.to_path_buf()) {
            self.files.push(path.to_path_buf());
        }
    }

    /// Fails when `more` bytes of XML would pass [`MAX_XML_BYTES`]; `file` is what reads them.
    fn check_xml_bytes(&self, more: u64, loc: &Location) -> Result<(), SceneError> {
        if self.xml_bytes as u64 + more > MAX_XML_BYTES as u64 {
            return Err(SceneError::at(
                loc,
                format!("the scene's XML, includes counted each time, exceeds {} MiB", MAX_XML_BYTES >> 20),
            ));
        }
        Ok(())
    }
}

/// An element's attributes after `$name` substitution.
pub(super) struct Attrs {
    tag: String,
    pairs: Vec<(String, String)>,
}

impl Attrs {
    pub(super) fn get(&self, name: &str) -> Option<&str> {
        self.pairs.iter().find(|(n, _)| n == name).map(|(_, v)| v.as_str())
    }

    pub(super) fn required(&self, name: &str, loc: &Location) -> Result<&str, SceneError> {
        self.get(name)
            .ok_or_else(|| SceneError::at(loc, format!("<{}> is missing the \"{}\" attribute", self.tag, name)))
    }

    /// Fails on an attribute outside `allowed` or a missing one marked with a leading `!`.
    pub(super) fn check(&self, loc: &Location, allowed: &[&str]) -> Result<(), SceneError> {
        for (name, _) in &self.pairs {
            if !allowed.iter().any(|a| a.trim_start_matches('!') == name) {
                return Err(SceneError::at(loc, format!("unexpected attribute \"{name}\" in <{}>", self.tag)));
            }
        }
        for a in allowed.iter().filter_map(|a| a.strip_prefix('!')) {
            self.required(a, loc)?;
        }
        Ok(())
    }
}

/// Parses one file. Returns its root element, not yet upgraded, and whether the file's version
/// is below 2.0.0 (the caller upgrades the root unless it splices it away).
pub(super) fn parse_document(
    session: &mut Session,
    file: &Path,
    text: &str,
    depth: usize,
) -> Result<(Element, bool), SceneError> {
    let file: Arc<Path> = Arc::from(file);
    session.check_xml_bytes(text.len() as u64, &Location::shared(&file, 0, 0))?;
    session.xml_bytes += text.len();
    // roxmltree refuses DTDs (and so entity expansion) unless told otherwise
    let options = roxmltree::ParsingOptions { nodes_limit: MAX_XML_NODES - session.xml_nodes, ..Default::default() };
    let doc = roxmltree::Document::parse_with_options(text, options).map_err(|e| match e {
        roxmltree::Error::NodesLimitReached => SceneError::at(
            &Location::shared(&file, 0, 0),
            format!("the scene has more than {MAX_XML_NODES} XML nodes, its includes counted"),
        ),
        e => {
            let pos = e.pos();
            SceneError::at(&Location::shared(&file, pos.row, pos.col), format!("malformed xml: {e}"))
        }
    })?;
    session.xml_nodes += doc.descendants().count() as u32;
    let positions = Positions::new(text);
    let mut parser = FileParser { session, file: &file, positions: &positions, depth, old: false };
    let root = parser.root(doc.root_element())?;
    Ok((root, parser.old))
}

pub(super) struct FileParser<'a, 'i> {
    pub(super) session: &'a mut Session,
    pub(super) file: &'a Arc<Path>,
    positions: &'a Positions<'i>,
    /// Include depth of this file.
    depth: usize,
    /// The file's version is below 2.0.0.
    old: bool,
}

fn is_object(tag: &str, attrs: &Attrs) -> bool {
    OBJECT_TAGS.contains(&tag) || (tag == "spectrum" && attrs.get("type").is_some())
}

/// `major.minor.patch`, as Mitsuba's `util::Version` reads it.
fn parse_version(s: &str) -> Option<(u32, u32, u32)> {
    let parts: Vec<u32> =
        s.split(['.', ' ']).filter(|p| !p.is_empty()).map(|p| p.parse().ok()).collect::<Option<_>>()?;
    match parts.as_slice() {
        [a, b, c] => Some((*a, *b, *c)),
        _ => None,
    }
}

impl FileParser<'_, '_> {
    pub(super) fn loc(&self, node: roxmltree::Node) -> Location {
        let (line, column) = self.positions.at(node.range().start);
        Location::shared(self.file, line, column)
    }

    /// Every attribute of `node`, substituted.
    pub(super) fn attrs(&mut self, node: roxmltree::Node) -> Result<Attrs, SceneError> {
        let mut pairs = Vec::new();
        for a in node.attributes() {
            let value = self.session.params.substitute(a.value()).map_err(|e| {
                let why = match e {
                    SubstituteError::Undefined(name) => format!(
                        "undefined parameter \"${name}\" (declare it with <default name=\"{name}\" value=\"...\"/>)"
                    ),
                    SubstituteError::TooLong => format!(
                        "attribute \"{}\" grows past {} KiB (or the scene's attributes past {} MiB) as its $parameters are substituted",
                        a.name(),
                        MAX_VALUE_BYTES >> 10,
                        MAX_TOTAL_BYTES >> 20
                    ),
                };
                SceneError::at(&self.loc(node), why)
            })?;
            pairs.push((a.name().to_string(), value));
        }
        Ok(Attrs { tag: node.tag_name().name().to_string(), pairs })
    }

    fn root(&mut self, node: roxmltree::Node) -> Result<Element, SceneError> {
        let loc = self.loc(node);
        let attrs = self.attrs(node)?;
        let tag = node.tag_name().name();
        if tag != "scene" && !is_object(tag, &attrs) {
            return Err(SceneError::at(&loc, format!("the root element must be <scene>, found <{tag}>")));
        }
        let version = attrs.get("version").ok_or_else(|| {
            SceneError::at(&loc, format!("<{tag}> needs a version attribute, e.g. version=\"3.0.0\""))
        })?;
        let (major, minor, patch) = parse_version(version).ok_or_else(|| {
            SceneError::at(&loc, format!("invalid version number \"{version}\" (expected three numbers such as 3.0.0)"))
        })?;
        self.old = (major, minor, patch) < (2, 0, 0);
        attrs.check(&loc, &["!version", "type", "id", "name"])?;
        // an untyped root is a scene, whatever its tag (Mitsuba's rule)
        let plugin = attrs.get("type").unwrap_or("scene").to_string();
        self.object_body(node, tag, plugin, &attrs, loc, true)
    }

    fn object(&mut self, node: roxmltree::Node, attrs: &Attrs, loc: Location) -> Result<Element, SceneError> {
        attrs.check(&loc, &["!type", "id", "name"])?;
        let plugin = attrs.required("type", &loc)?.to_string();
        let mut e = self.object_body(node, node.tag_name().name(), plugin, attrs, loc, false)?;
        if self.old {
            upgrade_from_v1(&mut e)?;
        }
        check_unique_names(&e)?;
        Ok(e)
    }

    fn object_body(
        &mut self,
        node: roxmltree::Node,
        tag: &str,
        plugin: String,
        attrs: &Attrs,
        loc: Location,
        is_root: bool,
    ) -> Result<Element, SceneError> {
        if self.session.nesting >= MAX_NESTING {
            return Err(SceneError::at(&loc, format!("elements nest more than {MAX_NESTING} deep")));
        }
        let mut e = Element::new(tag, plugin, loc);
        e.id = attrs.get("id").map(str::to_string);
        e.name = attrs.get("name").map(str::to_string);
        if let Some(id) = &e.id {
            self.register_id(id, &e.location)?;
        }
        self.session.nesting += 1;
        let children =
            node.children().filter(|n| n.is_element()).try_for_each(|child| self.child(child, &mut e, is_root));
        self.session.nesting -= 1;
        children.map(|()| e)
    }

    fn register_id(&mut self, id: &str, loc: &Location) -> Result<(), SceneError> {
        if let Some(first) = self.session.ids.get(id) {
            return Err(SceneError::at(loc, format!("duplicate id \"{id}\" (first defined at {first})")));
        }
        self.session.ids.insert(id.to_string(), loc.clone());
        Ok(())
    }

    fn child(&mut self, node: roxmltree::Node, parent: &mut Element, parent_is_root: bool) -> Result<(), SceneError> {
        let loc = self.loc(node);
        let attrs = self.attrs(node)?;
        let tag = node.tag_name().name();
        match tag {
            _ if is_object(tag, &attrs) => {
                let e = self.object(node, &attrs, loc)?;
                parent.children.push(e);
            }
            "ref" => {
                attrs.check(&loc, &["!id", "name"])?;
                let mut r = Element::new("ref", attrs.required("id", &loc)?.to_string(), loc);
                r.name = attrs.get("name").map(str::to_string);
                parent.children.push(r);
            }
            "include" => self.include(&attrs, &loc, parent)?,
            "alias" => self.alias(&attrs, &loc)?,
            "default" => {
                attrs.check(&loc, &["!name", "!value"])?;
                let name = attrs.required("name", &loc)?;
                if name.is_empty() {
                    return Err(SceneError::at(&loc, "<default> needs a non-empty name"));
                }
                self.session
                    .params
                    .add_default(name, attrs.required("value", &loc)?)
                    .map_err(|e| SceneError::at(&loc, e))?;
            }
            "path" => self.path(&attrs, &loc, parent_is_root)?,
            "translate" | "rotate" | "scale" | "lookat" | "matrix" => {
                return Err(SceneError::at(&loc, format!("<{tag}> can only appear inside a <transform>")));
            }
            "scene" => return Err(SceneError::at(&loc, "<scene> can only be the root element")),
            _ => {
                let property = self.property(node, tag, &attrs, loc)?;
                parent.properties.push(property);
            }
        }
        Ok(())
    }

    /// `<include>`: the file is found through the resolver with the including file's folder in
    /// front, for the duration of the include only.
    fn include(&mut self, attrs: &Attrs, loc: &Location, parent: &mut Element) -> Result<(), SceneError> {
        attrs.check(loc, &["!filename", "name"])?;
        let filename = attrs.required("filename", loc)?;
        self.session.includes += 1;
        if self.session.includes > MAX_INCLUDES {
            return Err(SceneError::at(loc, format!("a scene may read at most {MAX_INCLUDES} <include>s")));
        }
        if self.depth + 1 >= MAX_INCLUDE_DEPTH {
            return Err(SceneError::at(
                loc,
                format!("<include> of \"{filename}\" exceeds the maximum include depth of {MAX_INCLUDE_DEPTH}"),
            ));
        }
        let saved = self.session.resolver.clone();
        if let Some(dir) = self.file.parent().filter(|d| !d.as_os_str().is_empty()) {
            self.session.resolver.prepend(dir.to_path_buf());
        }
        let result = self.include_file(filename, loc);
        self.session.resolver = saved;
        let (mut root, old) = result?;
        if root.plugin == "scene" {
            if let Some(p) = root.properties.first() {
                tracing::warn!(file = %p.location, "parameters of an included <scene> are ignored, as in Mitsuba");
            }
            parent.children.append(&mut root.children);
        } else {
            if old {
                upgrade_from_v1(&mut root)?;
            }
            check_unique_names(&root)?;
            root.name = attrs.get("name").map(str::to_string);
            parent.children.push(root);
        }
        Ok(())
    }

    fn include_file(&mut self, filename: &str, loc: &Location) -> Result<(Element, bool), SceneError> {
        if let Some(why) = self.session.resolver.refusal(Path::new(filename)) {
            return Err(SceneError::at(loc, format!("included file \"{filename}\" {why}")));
        }
        let path = self
            .session
            .resolver
            .find(Path::new(filename))
            .ok_or_else(|| SceneError::at(loc, format!("included file \"{filename}\" not found")))?;
        let cannot = |e: std::io::Error| SceneError::at(loc, format!("cannot read included file \"{filename}\": {e}"));
        // refused before it is read: the file may be large
        self.session.check_xml_bytes(std::fs::metadata(&path).map_err(cannot)?.len(), loc)?;
        let text = std::fs::read_to_string(&path).map_err(cannot)?;
        self.session.record_file(&path);
        parse_document(self.session, &path, &text, self.depth + 1)
    }

    fn alias(&mut self, attrs: &Attrs, loc: &Location) -> Result<(), SceneError> {
        attrs.check(loc, &["!id", "!as"])?;
        let (src, dst) = (attrs.required("id", loc)?, attrs.required("as", loc)?);
        if let Some(first) = self.session.ids.get(dst) {
            return Err(SceneError::at(loc, format!("alias \"{dst}\" is already an id (defined at {first})")));
        }
        if !self.session.ids.contains_key(src) {
            return Err(SceneError::at(loc, format!("alias source id \"{src}\" is not defined before this <alias>")));
        }
        let target = self.session.aliases.get(src).cloned().unwrap_or_else(|| src.to_string());
        self.session.ids.insert(dst.to_string(), loc.clone());
        self.session.aliases.insert(dst.to_string(), target);
        Ok(())
    }

    /// `<path>`: a relative folder is tried next to this XML file, then through the resolver;
    /// it must exist, and is searched first from here on.
    fn path(&mut self, attrs: &Attrs, loc: &Location, parent_is_root: bool) -> Result<(), SceneError> {
        attrs.check(loc, &["!value"])?;
        if !parent_is_root {
            return Err(SceneError::at(loc, "<path> can only be a direct child of the root element"));
        }
        if self.session.search_paths >= MAX_SEARCH_PATHS {
            return Err(SceneError::at(loc, format!("a scene may add at most {MAX_SEARCH_PATHS} <path> folders")));
        }
        self.session.search_paths += 1;
        let value = attrs.required("value", loc)?;
        let p = Path::new(value);
        let dir = if p.is_absolute() {
            p.to_path_buf()
        } else {
            let local = self.file.parent().unwrap_or(Path::new("")).join(p);
            if local.exists() { local } else { self.session.resolver.find(p).unwrap_or(local) }
        };
        if let Some(why) = self.session.resolver.refusal_of_folder(&dir) {
            return Err(SceneError::at(loc, format!("<path>: folder \"{value}\" {why}")));
        }
        // a bundle holds files only, so a folder the client found empty does not arrive
        if !dir.exists() && !self.session.resolver.is_confined() {
            return Err(SceneError::at(loc, format!("<path>: folder \"{value}\" not found")));
        }
        self.session.resolver.prepend(dir);
        Ok(())
    }
}

/// Mitsuba keeps parameters and nested objects in one name table: a name given twice is an
/// error.
pub(super) fn check_unique_names(e: &Element) -> Result<(), SceneError> {
    let mut seen: HashMap<&str, &Location> = HashMap::new();
    let named = e.properties.iter().map(|p| (p.name.as_str(), &p.location));
    let children = e.children.iter().filter_map(|c| c.name.as_deref().map(|n| (n, &c.location)));
    for (name, loc) in named.chain(children) {
        if let Some(first) = seen.insert(name, loc) {
            return Err(SceneError::at(
                loc,
                format!("parameter \"{name}\" of {} is given twice (first at {first})", e.describe()),
            ));
        }
    }
    Ok(())
}
