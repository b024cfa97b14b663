//! The document walk: one [`FileParser`] per XML file, sharing a [`Session`] across
//! `<include>`s (parameters, ids, the file resolver, the files read).
//!
//! Elements are handled in document order, so a `<default>` applies from where it is written,
//! an `<alias>` sees only ids defined before it, and a `<path>` affects what follows. Every
//! attribute of every element is substituted before the element is interpreted, as in Mitsuba.

use super::super::error::{Location, SceneError};
use super::super::resolver::FileResolver;
use super::element::Element;
use super::params::{MAX_TOTAL_BYTES, MAX_VALUE_BYTES, Params, SubstituteError};
use super::upgrade::upgrade_from_v1;
use std::collections::HashMap;
use std::path::{Path, PathBuf};

/// Mitsuba's `max_include_depth`: the main file is depth 0, so includes nest 14 deep.
pub const MAX_INCLUDE_DEPTH: usize = 15;
/// The most XML a scene may have, its includes (each time included) counted.
pub const MAX_XML_BYTES: usize = 256 << 20;
/// The most XML nodes (elements, attributes' text and whitespace) one file may have.
pub const MAX_XML_NODES: u32 = 1_000_000;

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
    /// Bytes of XML parsed so far.
    pub(super) xml_bytes: usize,
}

impl Session {
    pub(super) fn new(params: Params, resolver: FileResolver) -> Self {
        Session { params, ids: HashMap::new(), aliases: HashMap::new(), resolver, files: vec![], xml_bytes: 0 }
    }

    pub(super) fn record_file(&mut self, path: &Path) {
        if !self.files.iter().any(|f| f == path) {
            self.files.push(path.to_path_buf());
        }
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
    session.xml_bytes += text.len();
    if session.xml_bytes > MAX_XML_BYTES {
        return Err(SceneError::file(
            file,
            format!("the scene's XML, includes counted each time, exceeds {} MiB", MAX_XML_BYTES >> 20),
        ));
    }
    let options = roxmltree::ParsingOptions { nodes_limit: MAX_XML_NODES, ..Default::default() };
    let doc = roxmltree::Document::parse_with_options(text, options).map_err(|e| match e {
        roxmltree::Error::NodesLimitReached => {
            SceneError::file(file, format!("more than {MAX_XML_NODES} XML nodes in one file"))
        }
        e => {
            let pos = e.pos();
            SceneError::at(&Location::new(file, pos.row, pos.col), format!("malformed xml: {e}"))
        }
    })?;
    let mut parser = FileParser { session, file, doc: &doc, depth, old: false };
    let root = parser.root(doc.root_element())?;
    Ok((root, parser.old))
}

pub(super) struct FileParser<'a, 'd, 'i> {
    pub(super) session: &'a mut Session,
    pub(super) file: &'a Path,
    pub(super) doc: &'d roxmltree::Document<'i>,
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

impl FileParser<'_, '_, '_> {
    pub(super) fn loc(&self, node: roxmltree::Node) -> Location {
        let pos = self.doc.text_pos_at(node.range().start);
        Location::new(self.file, pos.row, pos.col)
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
        let mut e = Element::new(tag, plugin, loc);
        e.id = attrs.get("id").map(str::to_string);
        e.name = attrs.get("name").map(str::to_string);
        if let Some(id) = &e.id {
            self.register_id(id, &e.location)?;
        }
        for child in node.children().filter(|n| n.is_element()) {
            self.child(child, &mut e, is_root)?;
        }
        Ok(e)
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
                self.session.params.add_default(name, attrs.required("value", &loc)?);
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
        let text = std::fs::read_to_string(&path)
            .map_err(|e| SceneError::at(loc, format!("cannot read included file {}: {e}", path.display())))?;
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
