//! Mitsuba 3 XML (format 3.0.0) → a tree of plugin elements with typed, located properties.
//!
//! This layer knows the XML syntax (`<default>`, `$name` substitution, property tags, `ref`,
//! nested `<transform>` chains composed in document order) but nothing about what a plugin
//! means: [`super::build`] interprets the tree. Every property records whether a plugin
//! consumed it, so that unknown parameters are reported instead of silently ignored.

use super::error::{Location, SceneError};
use crate::geometry::Transform;
use glam::{DMat4, DVec3, Vec3};
use std::cell::Cell;
use std::collections::HashMap;
use std::path::Path;

/// A typed property value.
#[derive(Clone, Debug)]
pub enum Value {
    /// `<integer>`
    Integer(i64),
    /// `<float>`
    Float(f64),
    /// `<boolean>`
    Boolean(bool),
    /// `<string>`
    String(String),
    /// `<rgb>` or a constant `<spectrum>`
    Rgb(Vec3),
    /// `<point>` or `<vector>`
    Vector(Vec3),
    /// `<transform>`
    Transform(Transform),
}

impl Value {
    fn type_name(&self) -> &'static str {
        match self {
            Value::Integer(_) => "integer",
            Value::Float(_) => "float",
            Value::Boolean(_) => "boolean",
            Value::String(_) => "string",
            Value::Rgb(_) => "rgb",
            Value::Vector(_) => "point",
            Value::Transform(_) => "transform",
        }
    }
}

/// A named property of a plugin element.
#[derive(Debug)]
pub struct Property {
    /// Its `name` attribute.
    pub name: String,
    /// Its value.
    pub value: Value,
    /// Where it is written.
    pub location: Location,
    used: Cell<bool>,
}

/// A plugin element (`shape`, `bsdf`, `emitter`, `sensor`, …) or a `ref` to one.
#[derive(Debug)]
pub struct Element {
    /// The tag: `shape`, `bsdf`, `emitter`, `sensor`, `film`, `sampler`, `rfilter`,
    /// `integrator`, `texture` or `ref`.
    pub tag: String,
    /// The `type` attribute (the referenced id for `ref`).
    pub plugin: String,
    /// The `id` attribute.
    pub id: Option<String>,
    /// The `name` attribute, for nested objects passed as a named parameter.
    pub name: Option<String>,
    /// Properties in document order.
    pub properties: Vec<Property>,
    /// Nested plugin elements and refs in document order.
    pub children: Vec<Element>,
    /// Where the element starts.
    pub location: Location,
}

const OBJECT_TAGS: &[&str] = &[
    "shape",
    "bsdf",
    "emitter",
    "sensor",
    "film",
    "sampler",
    "rfilter",
    "integrator",
    "texture",
    "medium",
    "phase",
    "volume",
    "spectrum_object",
];

impl Element {
    /// A short description for messages, e.g. `bsdf "diffuse"`.
    pub fn describe(&self) -> String {
        format!("{} \"{}\"", self.tag, self.plugin)
    }

    fn find(&self, name: &str) -> Option<&Property> {
        let p = self.properties.iter().find(|p| p.name == name)?;
        p.used.set(true);
        Some(p)
    }

    fn type_error(&self, p: &Property, expected: &str) -> SceneError {
        SceneError::at(
            &p.location,
            format!(
                "parameter \"{}\" of {} must be {}, found {}",
                p.name,
                self.describe(),
                expected,
                p.value.type_name()
            ),
        )
    }

    /// A float parameter (integers are accepted).
    pub fn float(&self, name: &str) -> Result<Option<f32>, SceneError> {
        match self.find(name) {
            None => Ok(None),
            Some(p) => match p.value {
                Value::Float(v) => Ok(Some(v as f32)),
                Value::Integer(v) => Ok(Some(v as f32)),
                _ => Err(self.type_error(p, "a float")),
            },
        }
    }

    /// A float parameter with a default.
    pub fn float_or(&self, name: &str, default: f32) -> Result<f32, SceneError> {
        Ok(self.float(name)?.unwrap_or(default))
    }

    /// An integer parameter.
    pub fn integer(&self, name: &str) -> Result<Option<i64>, SceneError> {
        match self.find(name) {
            None => Ok(None),
            Some(p) => match p.value {
                Value::Integer(v) => Ok(Some(v)),
                _ => Err(self.type_error(p, "an integer")),
            },
        }
    }

    /// A boolean parameter with a default.
    pub fn boolean_or(&self, name: &str, default: bool) -> Result<bool, SceneError> {
        match self.find(name) {
            None => Ok(default),
            Some(p) => match p.value {
                Value::Boolean(v) => Ok(v),
                _ => Err(self.type_error(p, "a boolean")),
            },
        }
    }

    /// A string parameter.
    pub fn string(&self, name: &str) -> Result<Option<&str>, SceneError> {
        match self.find(name) {
            None => Ok(None),
            Some(p) => match &p.value {
                Value::String(s) => Ok(Some(s.as_str())),
                _ => Err(self.type_error(p, "a string")),
            },
        }
    }

    /// A colour parameter (`rgb`, constant `spectrum`, or a float meaning grey).
    pub fn rgb(&self, name: &str) -> Result<Option<Vec3>, SceneError> {
        match self.find(name) {
            None => Ok(None),
            Some(p) => match p.value {
                Value::Rgb(v) => Ok(Some(v)),
                Value::Float(v) => Ok(Some(Vec3::splat(v as f32))),
                Value::Integer(v) => Ok(Some(Vec3::splat(v as f32))),
                _ => Err(self.type_error(p, "an rgb colour")),
            },
        }
    }

    /// A point or vector parameter.
    pub fn vector(&self, name: &str) -> Result<Option<Vec3>, SceneError> {
        match self.find(name) {
            None => Ok(None),
            Some(p) => match p.value {
                Value::Vector(v) => Ok(Some(v)),
                _ => Err(self.type_error(p, "a point")),
            },
        }
    }

    /// A transform parameter; the identity when absent.
    pub fn transform(&self, name: &str) -> Result<Transform, SceneError> {
        match self.find(name) {
            None => Ok(Transform::IDENTITY),
            Some(p) => match p.value {
                Value::Transform(t) => Ok(t),
                _ => Err(self.type_error(p, "a transform")),
            },
        }
    }

    /// Location of a property, or of the element when the property is absent.
    pub fn location_of(&self, name: &str) -> &Location {
        self.properties.iter().find(|p| p.name == name).map(|p| &p.location).unwrap_or(&self.location)
    }

    /// Fails on the first property no plugin code asked for: unknown parameters are errors.
    pub fn check_all_used(&self) -> Result<(), SceneError> {
        match self.properties.iter().find(|p| !p.used.get()) {
            Some(p) => {
                Err(SceneError::at(&p.location, format!("unknown parameter \"{}\" of {}", p.name, self.describe())))
            }
            None => Ok(()),
        }
    }
}

/// The parsed `<scene>`: its top-level elements, plus every element that has an id.
#[derive(Debug)]
pub struct SceneTree {
    /// Top-level elements in document order.
    pub elements: Vec<Element>,
}

impl SceneTree {
    /// Finds a top-level element by id.
    pub fn by_id(&self, id: &str) -> Option<&Element> {
        self.elements.iter().find(|e| e.id.as_deref() == Some(id))
    }
}

struct Parser<'a> {
    file: &'a Path,
    doc: &'a roxmltree::Document<'a>,
    params: HashMap<String, String>,
}

/// Parses a Mitsuba 3 XML document. `file` is used in messages and `defines` override
/// `<default>` values (like Mitsuba's `-D name=value`).
pub fn parse(text: &str, file: &Path, defines: &HashMap<String, String>) -> Result<SceneTree, SceneError> {
    let doc = roxmltree::Document::parse(text).map_err(|e| {
        let pos = e.pos();
        SceneError::at(&Location::new(file, pos.row, pos.col), format!("malformed xml: {e}"))
    })?;
    let mut parser = Parser { file, doc: &doc, params: defines.clone() };
    let root = doc.root_element();
    let loc = parser.loc(root);
    if root.tag_name().name() != "scene" {
        return Err(SceneError::at(
            &loc,
            format!("the root element must be <scene>, found <{}>", root.tag_name().name()),
        ));
    }
    match root.attribute("version") {
        Some(v) if v.starts_with("3.") || v.starts_with("2.") => {}
        Some(v) => return Err(SceneError::at(&loc, format!("unsupported scene version \"{v}\" (expected 3.x)"))),
        None => return Err(SceneError::at(&loc, "<scene> needs a version attribute, e.g. version=\"3.0.0\"")),
    }
    // defaults first: they may appear anywhere at the top level
    for node in root.children().filter(|n| n.is_element() && n.tag_name().name() == "default") {
        let name = parser.attr(node, "name")?.to_string();
        let value = parser.attr(node, "value")?.to_string();
        parser.params.entry(name).or_insert(value);
    }
    let mut elements = Vec::new();
    for node in root.children().filter(|n| n.is_element()) {
        match node.tag_name().name() {
            "default" => {}
            tag if OBJECT_TAGS.contains(&tag) || tag == "ref" => elements.push(parser.element(node)?),
            "include" | "alias" | "path" => {
                return Err(SceneError::at(
                    &parser.loc(node),
                    format!("<{}> is not supported", node.tag_name().name()),
                ));
            }
            other => {
                return Err(SceneError::at(
                    &parser.loc(node),
                    format!("unexpected <{other}> at the top level of <scene>"),
                ));
            }
        }
    }
    let mut seen: HashMap<&str, &Location> = HashMap::new();
    for e in &elements {
        if let Some(id) = e.id.as_deref() {
            if let Some(first) = seen.insert(id, &e.location) {
                return Err(SceneError::at(&e.location, format!("duplicate id \"{id}\" (first defined at {first})")));
            }
        }
    }
    Ok(SceneTree { elements })
}

impl<'a> Parser<'a> {
    fn loc(&self, node: roxmltree::Node) -> Location {
        let pos = self.doc.text_pos_at(node.range().start);
        Location::new(self.file, pos.row, pos.col)
    }

    /// An attribute with `$name` parameters substituted.
    fn attr(&self, node: roxmltree::Node, name: &str) -> Result<String, SceneError> {
        let raw = node.attribute(name).ok_or_else(|| {
            SceneError::at(
                &self.loc(node),
                format!("<{}> is missing the \"{}\" attribute", node.tag_name().name(), name),
            )
        })?;
        self.substitute(node, raw)
    }

    fn opt_attr(&self, node: roxmltree::Node, name: &str) -> Result<Option<String>, SceneError> {
        node.attribute(name).map(|raw| self.substitute(node, raw)).transpose()
    }

    fn substitute(&self, node: roxmltree::Node, raw: &str) -> Result<String, SceneError> {
        if !raw.contains('$') {
            return Ok(raw.to_string());
        }
        let mut out = String::with_capacity(raw.len());
        let mut rest = raw;
        while let Some(i) = rest.find('$') {
            out.push_str(&rest[..i]);
            let after = &rest[i + 1..];
            let len = after.find(|c: char| !(c.is_ascii_alphanumeric() || c == '_')).unwrap_or(after.len());
            let name = &after[..len];
            let value = self.params.get(name).ok_or_else(|| {
                SceneError::at(
                    &self.loc(node),
                    format!(
                        "undefined parameter \"${name}\" (declare it with <default name=\"{name}\" value=\"...\"/>)"
                    ),
                )
            })?;
            out.push_str(value);
            rest = &after[len..];
        }
        out.push_str(rest);
        Ok(out)
    }

    fn element(&mut self, node: roxmltree::Node) -> Result<Element, SceneError> {
        let tag = node.tag_name().name().to_string();
        let location = self.loc(node);
        if tag == "ref" {
            let id = self.attr(node, "id")?;
            return Ok(Element {
                tag,
                plugin: id,
                id: None,
                name: self.opt_attr(node, "name")?,
                properties: vec![],
                children: vec![],
                location,
            });
        }
        let plugin = self.attr(node, "type")?;
        let mut element = Element {
            tag,
            plugin,
            id: self.opt_attr(node, "id")?,
            name: self.opt_attr(node, "name")?,
            properties: vec![],
            children: vec![],
            location,
        };
        for child in node.children().filter(|n| n.is_element()) {
            let ctag = child.tag_name().name();
            if OBJECT_TAGS.contains(&ctag) || ctag == "ref" {
                element.children.push(self.element(child)?);
            } else {
                let property = self.property(child)?;
                if let Some(prev) = element.properties.iter().find(|p| p.name == property.name) {
                    return Err(SceneError::at(
                        &property.location,
                        format!(
                            "parameter \"{}\" of {} is given twice (first at {})",
                            property.name,
                            element.describe(),
                            prev.location
                        ),
                    ));
                }
                element.properties.push(property);
            }
        }
        Ok(element)
    }

    fn property(&self, node: roxmltree::Node) -> Result<Property, SceneError> {
        let location = self.loc(node);
        let tag = node.tag_name().name();
        let name = self.attr(node, "name")?;
        let value = match tag {
            "integer" => {
                let s = self.attr(node, "value")?;
                Value::Integer(s.trim().parse::<i64>().map_err(|_| {
                    SceneError::at(&location, format!("\"{s}\" is not an integer (parameter \"{name}\")"))
                })?)
            }
            "float" => Value::Float(self.number(&location, &name, &self.attr(node, "value")?)?),
            "boolean" => match self.attr(node, "value")?.trim() {
                "true" => Value::Boolean(true),
                "false" => Value::Boolean(false),
                s => {
                    return Err(SceneError::at(
                        &location,
                        format!("\"{s}\" is not a boolean (parameter \"{name}\"; use true or false)"),
                    ));
                }
            },
            "string" => Value::String(self.attr(node, "value")?),
            "rgb" => {
                let v = self.numbers(&location, &name, &self.attr(node, "value")?)?;
                match v.as_slice() {
                    [g] => Value::Rgb(Vec3::splat(*g as f32)),
                    [r, g, b] => Value::Rgb(Vec3::new(*r as f32, *g as f32, *b as f32)),
                    _ => {
                        return Err(SceneError::at(
                            &location,
                            format!("<rgb> \"{name}\" needs 1 or 3 values, found {}", v.len()),
                        ));
                    }
                }
            }
            "spectrum" => {
                let s = self.attr(node, "value")?;
                if s.contains(':') {
                    return Err(SceneError::at(
                        &location,
                        format!(
                            "spectrum \"{name}\": wavelength-value pairs are not supported in rgb rendering; give a single value or use <rgb>"
                        ),
                    ));
                }
                match self.numbers(&location, &name, &s)?.as_slice() {
                    [g] => Value::Rgb(Vec3::splat(*g as f32)),
                    _ => return Err(SceneError::at(&location, format!("spectrum \"{name}\" needs exactly one value"))),
                }
            }
            "point" | "vector" => Value::Vector(self.point(node, &location, &name)?),
            "transform" => Value::Transform(self.transform(node)?),
            other => return Err(SceneError::at(&location, format!("unknown element <{other}>"))),
        };
        Ok(Property { name, value, location, used: Cell::new(false) })
    }

    fn number(&self, location: &Location, name: &str, s: &str) -> Result<f64, SceneError> {
        let v: f64 = s
            .trim()
            .parse()
            .map_err(|_| SceneError::at(location, format!("\"{s}\" is not a number (parameter \"{name}\")")))?;
        if !v.is_finite() {
            return Err(SceneError::at(location, format!("\"{s}\" is not a finite number (parameter \"{name}\")")));
        }
        Ok(v)
    }

    fn numbers(&self, location: &Location, name: &str, s: &str) -> Result<Vec<f64>, SceneError> {
        s.split(|c: char| c == ',' || c.is_whitespace())
            .filter(|t| !t.is_empty())
            .map(|t| self.number(location, name, t))
            .collect()
    }

    /// `value="x, y, z"` or separate `x`, `y`, `z` attributes (missing ones default to `default`).
    fn xyz(&self, node: roxmltree::Node, location: &Location, name: &str, default: f32) -> Result<Vec3, SceneError> {
        Ok(self.xyz64(node, location, name, default as f64)?.as_vec3())
    }

    /// Like [`Self::xyz`] in double precision, for transforms.
    fn xyz64(&self, node: roxmltree::Node, location: &Location, name: &str, default: f64) -> Result<DVec3, SceneError> {
        if let Some(s) = self.opt_attr(node, "value")? {
            return match self.numbers(location, name, &s)?.as_slice() {
                [x, y, z] => Ok(DVec3::new(*x, *y, *z)),
                [v] => Ok(DVec3::splat(*v)),
                v => Err(SceneError::at(
                    location,
                    format!("\"value\" of <{}> needs 3 values, found {}", node.tag_name().name(), v.len()),
                )),
            };
        }
        let mut out = DVec3::splat(default);
        for (i, a) in ["x", "y", "z"].iter().enumerate() {
            if let Some(s) = self.opt_attr(node, a)? {
                out[i] = self.number(location, name, &s)?;
            }
        }
        Ok(out)
    }

    fn dvec3_attr(
        &self,
        node: roxmltree::Node,
        location: &Location,
        name: &str,
        attr: &str,
    ) -> Result<Option<DVec3>, SceneError> {
        let Some(s) = self.opt_attr(node, attr)? else { return Ok(None) };
        match self.numbers(location, name, &s)?.as_slice() {
            [x, y, z] => Ok(Some(DVec3::new(*x, *y, *z))),
            v => Err(SceneError::at(
                location,
                format!("\"{attr}\" of <{}> needs 3 values, found {}", node.tag_name().name(), v.len()),
            )),
        }
    }

    fn point(&self, node: roxmltree::Node, location: &Location, name: &str) -> Result<Vec3, SceneError> {
        self.xyz(node, location, name, 0.0)
    }

    fn transform(&self, node: roxmltree::Node) -> Result<Transform, SceneError> {
        let mut acc = Transform::IDENTITY;
        for child in node.children().filter(|n| n.is_element()) {
            let loc = self.loc(child);
            let tag = child.tag_name().name();
            let step = match tag {
                "translate" => Some(Transform::translate(self.xyz64(child, &loc, tag, 0.0)?)),
                "scale" => {
                    let s = match self.opt_attr(child, "value")? {
                        Some(v) => match self.numbers(&loc, tag, &v)?.as_slice() {
                            [u] => DVec3::splat(*u),
                            [x, y, z] => DVec3::new(*x, *y, *z),
                            _ => return Err(SceneError::at(&loc, "<scale value> needs 1 or 3 values")),
                        },
                        None => self.xyz64(child, &loc, tag, 1.0)?,
                    };
                    Transform::scale(s)
                }
                "rotate" => {
                    let axis = self.xyz64(child, &loc, tag, 0.0)?;
                    let angle = self.number(&loc, tag, &self.attr(child, "angle")?)?;
                    if axis.length_squared() == 0.0 {
                        return Err(SceneError::at(&loc, "<rotate> needs a non-zero axis (x, y, z or value)"));
                    }
                    Transform::rotate(axis, angle)
                }
                "matrix" => {
                    let v = self.numbers(&loc, tag, &self.attr(child, "value")?)?;
                    let m = match v.len() {
                        16 => DMat4::from_cols_array(&std::array::from_fn(|i| v[i])).transpose(),
                        9 => DMat4::from_mat3(glam::DMat3::from_cols_array(&std::array::from_fn(|i| v[i])).transpose()),
                        n => return Err(SceneError::at(&loc, format!("<matrix> needs 16 or 9 values, found {n}"))),
                    };
                    Transform::from_matrix(m)
                }
                "lookat" => {
                    let origin = self
                        .dvec3_attr(child, &loc, tag, "origin")?
                        .ok_or_else(|| SceneError::at(&loc, "<lookat> is missing \"origin\""))?;
                    let target = self
                        .dvec3_attr(child, &loc, tag, "target")?
                        .ok_or_else(|| SceneError::at(&loc, "<lookat> is missing \"target\""))?;
                    let up = self.dvec3_attr(child, &loc, tag, "up")?.unwrap_or(DVec3::Y);
                    Transform::look_at(origin, target, up)
                }
                other => return Err(SceneError::at(&loc, format!("unknown transform operation <{other}>"))),
            };
            let step = step.ok_or_else(|| {
                SceneError::at(&loc, format!("<{tag}> gives a degenerate (non-invertible) transform"))
            })?;
            acc = step.after(&acc);
        }
        Ok(acc)
    }
}
