//! The parsed tree's nodes: plugin [`Element`]s with typed, located [`Property`] values, and
//! the accessors plugin code reads them with. Every property (and every nested `<spectrum>`
//! object) records whether it was read, so that [`Element::check_all_used`] can report unknown
//! parameters instead of silently ignoring them, as Mitsuba does.

use super::super::error::{Location, SceneError};
use crate::geometry::Transform;
use crate::math::Rgb;
use crate::spectrum::{ColorUsage, Spectrum};
use glam::Vec3;
use std::cell::Cell;

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
    /// `<rgb>`, used as given.
    Rgb(Vec3),
    /// `<spectrum>` (a value, `wavelength:value` pairs or a file), converted when read
    /// because the conversion depends on how the plugin uses it.
    Spectrum(Spectrum),
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
            Value::Spectrum(_) => "spectrum",
            Value::Vector(_) => "point",
            Value::Transform(_) => "transform",
        }
    }
}

/// A named property of a plugin element.
#[derive(Clone, Debug)]
pub struct Property {
    /// Its `name` attribute.
    pub name: String,
    /// Its value.
    pub value: Value,
    /// Where it is written.
    pub location: Location,
    pub(super) used: Cell<bool>,
}

impl Property {
    pub(super) fn new(name: String, value: Value, location: Location) -> Self {
        Property { name, value, location, used: Cell::new(false) }
    }
}

/// A plugin element (`shape`, `bsdf`, `emitter`, `sensor`, …). After [`super::parse`], every
/// `<ref>` has been replaced by a copy of the element it names, so the tree holds no refs.
#[derive(Clone, Debug)]
pub struct Element {
    /// The tag: `shape`, `bsdf`, `emitter`, `sensor`, `film`, `sampler`, `rfilter`,
    /// `integrator`, `texture`, `spectrum`, `medium`, `phase` or `volume`.
    pub tag: String,
    /// The `type` attribute.
    pub plugin: String,
    /// The `id` attribute.
    pub id: Option<String>,
    /// The `name` attribute (or the referencing `<ref>`'s), for nested objects passed as a
    /// named parameter.
    pub name: Option<String>,
    /// Properties in document order.
    pub properties: Vec<Property>,
    /// Nested plugin elements in document order.
    pub children: Vec<Element>,
    /// Where the element starts.
    pub location: Location,
    /// Where the `<ref>` that placed this copy here is written, if it came by reference.
    pub reference: Option<Location>,
    pub(super) used: Cell<bool>,
}

/// Spectrum plugins, which may appear as `<spectrum type=..>` (or `<texture type=..>`) objects
/// and are read as constant colours.
const SPECTRUM_PLUGINS: &[&str] = &["d65", "blackbody", "uniform", "srgb", "regular", "irregular"];

impl Element {
    pub(super) fn new(tag: &str, plugin: String, location: Location) -> Self {
        Element {
            tag: tag.to_string(),
            plugin,
            id: None,
            name: None,
            properties: vec![],
            children: vec![],
            location,
            reference: None,
            used: Cell::new(false),
        }
    }

    /// Bytes this element holds besides its children, about: what copying it costs.
    pub(super) fn own_bytes(&self) -> usize {
        let strings = [Some(&self.tag), Some(&self.plugin), self.id.as_ref(), self.name.as_ref()];
        let properties: usize = self
            .properties
            .iter()
            .map(|p| {
                let value = match &p.value {
                    Value::String(s) => s.len(),
                    Value::Spectrum(Spectrum::Sampled { wavelengths, values }) => {
                        8 * (wavelengths.len() + values.len())
                    }
                    _ => 0,
                };
                std::mem::size_of::<Property>() + p.name.len() + value
            })
            .sum();
        std::mem::size_of::<Element>() + strings.iter().flatten().map(|s| s.len()).sum::<usize>() + properties
    }

    /// A short description for messages, e.g. `bsdf "diffuse"`.
    pub fn describe(&self) -> String {
        format!("{} \"{}\"", self.tag, self.plugin)
    }

    /// Whether this is a spectrum object (`<spectrum type="d65">` and the like), which colour
    /// accessors read as a constant.
    pub fn is_spectrum(&self) -> bool {
        matches!(self.tag.as_str(), "spectrum" | "texture") && SPECTRUM_PLUGINS.contains(&self.plugin.as_str())
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
        Ok(self.float64(name)?.map(|v| v as f32))
    }

    /// A float parameter in double precision (integers are accepted).
    pub fn float64(&self, name: &str) -> Result<Option<f64>, SceneError> {
        match self.find(name) {
            None => Ok(None),
            Some(p) => match p.value {
                Value::Float(v) => Ok(Some(v)),
                Value::Integer(v) => Ok(Some(v as f64)),
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

    /// A colour parameter read the way Mitsuba reads it for `usage`: `<float>`/`<integer>` as
    /// grey, `<rgb>` as given (outside [0, 1] an error when bounded), `<spectrum>` converted
    /// (lists clipped with a warning), or a nested spectrum object (`d65`, `srgb`, `uniform`).
    pub fn color(&self, name: &str, usage: ColorUsage) -> Result<Option<Rgb>, SceneError> {
        if let Some(child) = self.children.iter().find(|c| c.name.as_deref() == Some(name)) {
            if !child.is_spectrum() {
                return Err(SceneError::at(
                    &child.location,
                    format!("parameter \"{name}\" of {} must be a colour, found {}", self.describe(), child.describe()),
                ));
            }
            child.used.set(true);
            return child.constant_color().map(Some);
        }
        let Some(p) = self.find(name) else { return Ok(None) };
        match &p.value {
            Value::Float(v) => Ok(Some(Rgb::splat(*v as f32))),
            Value::Integer(v) => Ok(Some(Rgb::splat(*v as f32))),
            Value::Rgb(c) => {
                if usage == ColorUsage::Bounded && (c.min_element() < 0.0 || c.max_element() > 1.0) {
                    return Err(SceneError::at(
                        &p.location,
                        format!("<rgb> \"{name}\" of {} must lie in [0, 1], found {c}", self.describe()),
                    ));
                }
                Ok(Some(*c))
            }
            Value::Spectrum(s) => {
                let converted = s.to_rgb(usage);
                if converted.clipped {
                    tracing::warn!(file = %p.location, parameter = name, "spectrum clipped into the valid range");
                }
                Ok(Some(converted.rgb))
            }
            _ => Err(self.type_error(p, "a colour (rgb, spectrum or float)")),
        }
    }

    /// [`Self::color`] with a grey default.
    pub fn color_or(&self, name: &str, usage: ColorUsage, default: f32) -> Result<Rgb, SceneError> {
        Ok(self.color(name, usage)?.unwrap_or(Rgb::splat(default)))
    }

    /// The nested object passed as parameter `name` (`<texture name=..>`, or what a named
    /// `<ref>` placed), marked as read.
    pub fn object(&self, name: &str) -> Option<&Element> {
        let c = self.children.iter().find(|c| c.name.as_deref() == Some(name))?;
        c.used.set(true);
        Some(c)
    }

    /// The constant colour of a spectrum object, as Mitsuba's RGB variants evaluate it.
    pub fn constant_color(&self) -> Result<Rgb, SceneError> {
        let rgb = match self.plugin.as_str() {
            "d65" => {
                let scale = self.float_or("scale", 1.0)?;
                // the white point of sRGB is D65, so in RGB it is the colour itself
                self.color("color", ColorUsage::Unbounded)?.unwrap_or(Rgb::ONE) * scale
            }
            "uniform" => {
                self.float("wavelength_min")?;
                self.float("wavelength_max")?;
                let v = self
                    .float("value")?
                    .ok_or_else(|| SceneError::at(&self.location, format!("{} needs \"value\"", self.describe())))?;
                Rgb::splat(v)
            }
            "srgb" => {
                let unbounded = self.boolean_or("unbounded", false)?;
                let usage = if unbounded { ColorUsage::Unbounded } else { ColorUsage::Bounded };
                self.color("color", usage)?
                    .ok_or_else(|| SceneError::at(&self.location, format!("{} needs \"color\"", self.describe())))?
            }
            other => {
                // Mitsuba's RGB variants load these but throw when they are evaluated
                return Err(SceneError::at(
                    &self.location,
                    format!("{other} is not available in RGB rendering (Mitsuba's RGB variants cannot evaluate it)"),
                ));
            }
        };
        self.check_all_used()?;
        Ok(rgb)
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

    /// Fails on the first property (or nested spectrum or texture object) no plugin code asked
    /// for: unknown parameters are errors.
    pub fn check_all_used(&self) -> Result<(), SceneError> {
        if let Some(p) = self.properties.iter().find(|p| !p.used.get()) {
            return Err(SceneError::at(
                &p.location,
                format!("unknown parameter \"{}\" of {}", p.name, self.describe()),
            ));
        }
        match self.children.iter().find(|c| (c.is_spectrum() || c.tag == "texture") && !c.used.get()) {
            Some(c) => Err(SceneError::at(
                &c.location,
                format!("unknown parameter \"{}\" of {}", c.name.as_deref().unwrap_or("(unnamed)"), self.describe()),
            )),
            None => Ok(()),
        }
    }
}
