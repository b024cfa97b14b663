//! Interprets `<texture>` elements (`bitmap`, `checkerboard`, `mesh_attribute`, and spectra
//! used as textures) into shared [`Texture`]s, and reads plugin parameters that may be either a
//! constant or a texture, as Mitsuba's `Properties::get_texture` does.
//!
//! Every image file is decoded once per set of options, however many `<ref>`s or copies name
//! it, and counted once in [`Textures::decoded_bytes`]; all decoding stays within the
//! [`TextureLimits`] the scene is loaded with.

use super::error::{Location, SceneError};
use super::resolver::FileResolver;
use super::xml::{ColorUsage, Element};
use crate::bsdf::CoatingKey;
use crate::math::Rgb;
use crate::texture::{
    Bitmap, BitmapOptions, Checkerboard, FilterType, MeshAttributeTexture, Texture, TextureError, TextureLimits,
    UvTransform, WrapMode,
};
use std::collections::{HashMap, HashSet};
use std::path::{Path, PathBuf};
use std::sync::Arc;

/// A parameter that is a constant or varies over the surface.
#[derive(Clone, Debug)]
pub(super) enum Param {
    /// The same everywhere.
    Constant(Rgb),
    /// Looked up at each point.
    Texture(Arc<Texture>),
}

/// The scene's textures while it is built.
pub(super) struct Textures<'a> {
    resolver: &'a FileResolver,
    limits: TextureLimits,
    by_id: HashMap<String, Arc<Texture>>,
    /// Bitmaps by resolved file and options (formatted, as the options hold floats).
    by_file: HashMap<(PathBuf, String), Arc<Texture>>,
    bytes: usize,
    /// The distinct rough plastic coatings the scene's materials tabulate.
    coatings: HashSet<CoatingKey>,
}

/// The most distinct rough plastic coatings (distribution, α, η) a scene may have: each is a
/// table of about a million quadrature evaluations (0.15 s), and 150 of them in 10 KB of XML
/// took 23 s to load.
pub const MAX_COATINGS_PER_SCENE: usize = 32;

/// The texture plugins Tessera reads (spectrum plugins besides).
const SUPPORTED: &str =
    "bitmap, checkerboard, mesh_attribute, rawconstant, and the constant spectra srgb, d65, uniform";

impl<'a> Textures<'a> {
    pub(super) fn new(resolver: &'a FileResolver, limits: TextureLimits) -> Self {
        Textures {
            resolver,
            limits,
            by_id: HashMap::new(),
            by_file: HashMap::new(),
            bytes: 0,
            coatings: HashSet::new(),
        }
    }

    /// Counts a rough plastic coating the scene tabulates; fails past
    /// [`MAX_COATINGS_PER_SCENE`] distinct ones.
    pub(super) fn count_coating(&mut self, key: CoatingKey, at: &Location) -> Result<(), SceneError> {
        if self.coatings.insert(key) && self.coatings.len() > MAX_COATINGS_PER_SCENE {
            return Err(SceneError::at(
                at,
                format!(
                    "a scene may have at most {MAX_COATINGS_PER_SCENE} distinct rough plastic coatings (distribution, alpha, int_ior/ext_ior)"
                ),
            ));
        }
        Ok(())
    }

    /// The budget the next image is decoded within: the per-image limit, or what is left of
    /// the scene's total if that is less.
    pub(super) fn limits(&self) -> TextureLimits {
        let left = self.limits.max_total_bytes.saturating_sub(self.bytes as u64);
        TextureLimits { max_decoded_bytes: self.limits.max_decoded_bytes.min(left), ..self.limits }
    }

    /// A load error, saying so when the scene's total budget rather than the image's own
    /// size was exceeded.
    pub(super) fn load_error(&self, e: &Element, err: TextureError) -> SceneError {
        let message = match &err {
            TextureError::OverBudget { needed, .. } if *needed <= self.limits.max_decoded_bytes => format!(
                "{err} (the scene's textures may take {} bytes in all; {} are used)",
                self.limits.max_total_bytes, self.bytes
            ),
            _ => err.to_string(),
        };
        SceneError::at(e.location_of("filename"), message)
    }

    /// The file resolver, for plugins that read images themselves (`envmap`).
    pub(super) fn resolver(&self) -> &FileResolver {
        self.resolver
    }

    /// Bytes of decoded image data held by distinct textures, plus what [`Self::add_bytes`]
    /// recorded.
    pub(super) fn decoded_bytes(&self) -> usize {
        self.bytes
    }

    /// Records image memory held outside textures (an environment map's texels and tables).
    pub(super) fn add_bytes(&mut self, bytes: usize) {
        self.bytes += bytes;
    }

    /// Builds a `<texture>` element (or a copy a `<ref>` placed), once per id.
    pub(super) fn texture(&mut self, e: &Element) -> Result<Arc<Texture>, SceneError> {
        if let Some(t) = e.id.as_ref().and_then(|id| self.by_id.get(id)) {
            return Ok(t.clone());
        }
        let t = self.build(e)?;
        if let Some(id) = &e.id {
            self.by_id.insert(id.clone(), t.clone());
        }
        Ok(t)
    }

    fn build(&mut self, e: &Element) -> Result<Arc<Texture>, SceneError> {
        if e.tag != "texture" && !e.is_spectrum() {
            let at = e.reference.as_ref().unwrap_or(&e.location);
            return Err(SceneError::at(at, format!("expected a <texture>, found {}", e.describe())));
        }
        if e.is_spectrum() {
            return Ok(Arc::new(Texture::rgb(e.constant_color()?)));
        }
        let t = match e.plugin.as_str() {
            "bitmap" => return self.bitmap(e),
            "checkerboard" => {
                let color0 = self.param_texture(e, "color0", ColorUsage::Bounded, 0.4)?;
                let color1 = self.param_texture(e, "color1", ColorUsage::Bounded, 0.2)?;
                let to_uv = to_uv(e)?;
                Texture::from(Checkerboard::new(color0, color1, to_uv))
            }
            // a constant used as given, without the checks and conversions of `srgb`
            "rawconstant" => match (e.float("value"), e.vector("value")) {
                (Ok(Some(v)), _) => Texture::uniform(v),
                (_, Ok(Some(v))) => Texture::rgb(v),
                _ => {
                    return Err(SceneError::at(
                        e.location_of("value"),
                        "rawconstant needs \"value\": a float or a vector of three",
                    ));
                }
            },
            "mesh_attribute" => {
                let name = e
                    .string("name")?
                    .ok_or_else(|| SceneError::at(&e.location, "mesh_attribute needs \"name\" (e.g. vertex_color)"))?;
                let scale = e.float_or("scale", 1.0)?;
                MeshAttributeTexture::new(name, scale)
                    .map(Texture::from)
                    .map_err(|err| SceneError::at(e.location_of("name"), err.to_string()))?
            }
            other => {
                return Err(SceneError::at(
                    &e.location,
                    format!("unsupported texture \"{other}\" (supported: {SUPPORTED})"),
                ));
            }
        };
        e.check_all_used()?;
        Ok(Arc::new(t))
    }

    fn bitmap(&mut self, e: &Element) -> Result<Arc<Texture>, SceneError> {
        let file = e.string("filename")?.ok_or_else(|| {
            SceneError::at(&e.location, "bitmap needs \"filename\" (Tessera reads textures from files)")
        })?;
        let filter = match e.string("filter_type")?.unwrap_or("bilinear") {
            "bilinear" => FilterType::Bilinear,
            "nearest" => FilterType::Nearest,
            other => return Err(choice_error(e, "filter_type", other, "bilinear, nearest")),
        };
        let wrap = match e.string("wrap_mode")?.unwrap_or("repeat") {
            "repeat" => WrapMode::Repeat,
            "mirror" => WrapMode::Mirror,
            "clamp" => WrapMode::Clamp,
            other => return Err(choice_error(e, "wrap_mode", other, "repeat, mirror, clamp")),
        };
        // "variant" stores floats where "auto" keeps bytes: the values agree to float rounding
        match e.string("format")?.unwrap_or("auto") {
            "auto" | "variant" => {}
            other => {
                return Err(SceneError::at(
                    e.location_of("format"),
                    format!("bitmap format \"{other}\" is not supported (auto or variant)"),
                ));
            }
        }
        // `accel` only chooses Dr.Jit's texture path on GPUs
        e.boolean_or("accel", true)?;
        let options = BitmapOptions { raw: e.boolean_or("raw", false)?, filter, wrap, to_uv: to_uv(e)? };
        e.check_all_used()?;
        let path = self
            .resolver
            .resolve_checked(Path::new(file))
            .map_err(|why| SceneError::at(e.location_of("filename"), format!("\"{file}\" {why}")))?;
        let key = (path.clone(), format!("{options:?}"));
        if let Some(t) = self.by_file.get(&key) {
            return Ok(t.clone());
        }
        let bitmap = Bitmap::load(&path, options, &self.limits()).map_err(|err| self.load_error(e, err))?;
        self.bytes += bitmap.decoded_bytes();
        let t = Arc::new(Texture::from(bitmap));
        self.by_file.insert(key, t.clone());
        Ok(t)
    }

    /// Parameter `name` of `e`: a nested (or referenced) texture, or a constant read with
    /// `usage`; `None` when absent.
    pub(super) fn param(&mut self, e: &Element, name: &str, usage: ColorUsage) -> Result<Option<Param>, SceneError> {
        if let Some(child) = e.object(name) {
            if child.tag == "texture" && !child.is_spectrum() {
                let t = self.texture(child)?;
                // a texture that cannot vary is a constant: keep the fast path
                return Ok(Some(match t.is_constant() {
                    Some(c) => Param::Constant(c),
                    None => Param::Texture(t),
                }));
            }
        }
        Ok(e.color(name, usage)?.map(Param::Constant))
    }

    /// [`Self::param`] as a texture, with a grey default (checkerboard colours).
    fn param_texture(
        &mut self,
        e: &Element,
        name: &str,
        usage: ColorUsage,
        default: f32,
    ) -> Result<Texture, SceneError> {
        Ok(match self.param(e, name, usage)? {
            None => Texture::uniform(default),
            Some(Param::Constant(c)) if c.x == c.y && c.y == c.z => Texture::uniform(c.x),
            Some(Param::Constant(c)) => Texture::rgb(c),
            Some(Param::Texture(t)) => {
                // the checkerboard owns its colours: a shared image is copied, and counted
                self.bytes += t.decoded_bytes();
                (*t).clone()
            }
        })
    }
}

fn to_uv(e: &Element) -> Result<UvTransform, SceneError> {
    Ok(UvTransform::from_mat4(e.transform("to_uv")?.m.as_mat4()))
}

fn choice_error(e: &Element, name: &str, found: &str, choices: &str) -> SceneError {
    SceneError::at(
        e.location_of(name),
        format!("\"{name}\" of {} must be one of {choices}, found \"{found}\"", e.describe()),
    )
}
