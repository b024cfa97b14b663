//! Interprets the XML tree into a [`Scene`]: the sensor with its film and sampler, the
//! integrator settings, shapes (with their BSDFs and area emitters) and the other emitters.
//! Refused plugins ([`super::refused`]) fail first; every relative `filename` resolves through
//! the tree's [`super::FileResolver`].

use super::build_bsdf::build_material;
use super::build_emitter::build_emitter;
use super::build_mesh::MeshFiles;
use super::build_settings::{build_integrator, build_sampler};
use super::build_texture::Textures;
use super::error::{Location, SceneError};
use super::load::compute_smooth_normals;
use super::refused::check_supported;
use super::resolver::FileResolver;
use super::shape::{Mesh, Shape, ShapeGeometry};
use super::xml::{Element, SceneTree};
use super::{IntegratorSettings, Parts, Scene, SceneLimits};
use crate::bsdf::textured::MaterialTextures;
use crate::bsdf::{Bxdf, Diffuse, Material};
use crate::camera::PerspectiveCamera;
use crate::film::FilmSpec;
use crate::film::filter::{Filter, FilterKind, MAX_RADIUS};
use crate::light::Light;
use crate::math::{PI, Rgb};
use glam::Vec3;
use std::collections::HashMap;
use std::path::Path;

struct Builder<'a> {
    resolver: &'a FileResolver,
    textures: Textures<'a>,
    mesh_files: MeshFiles,
    shapes: Vec<Shape>,
    meshes: Vec<Mesh>,
    materials: Vec<Material>,
    material_textures: Vec<Option<MaterialTextures>>,
    /// Bsdf ids → material index, so a BSDF shared through `<ref>` is built once.
    material_ids: HashMap<String, u32>,
    /// Top-level area emitters' ids → the shape that references one (`<ref>` inside a
    /// `<shape>`, as Mitsuba allows): each may light one shape only.
    attached: HashMap<String, Location>,
    lights: Vec<Light>,
    light_weights: Vec<f32>,
}

struct SensorSettings {
    camera: PerspectiveCamera,
    film: FilmSpec,
    spp: u32,
    seed: u64,
}

/// Parameters of `<scene>` itself that only tune Mitsuba's acceleration structures.
const IGNORED_SCENE_PARAMETERS: &[&str] = &[
    "allow_thread_reordering",
    "compact_acceleration_structures",
    "embree_use_robust_intersections",
    "kd_intersection_cost",
    "kd_traversal_cost",
    "kd_empty_space_bonus",
    "kd_stop_prims",
    "kd_max_depth",
    "kd_min_max_bins",
    "kd_clip",
    "kd_retract_bad_splits",
    "kd_exact_primitive_threshold",
];

pub(super) fn build(tree: &SceneTree, path: &Path, limits: SceneLimits) -> Result<Scene, SceneError> {
    check_supported(&tree.elements)?;
    if let Some(p) = tree.properties.iter().find(|p| !IGNORED_SCENE_PARAMETERS.contains(&p.name.as_str())) {
        return Err(SceneError::at(&p.location, format!("unknown parameter \"{}\" of the scene", p.name)));
    }
    let mut b = Builder {
        resolver: &tree.resolver,
        textures: Textures::new(&tree.resolver, limits.textures),
        mesh_files: MeshFiles::new(limits.max_triangles),
        shapes: vec![],
        meshes: vec![],
        materials: vec![],
        material_textures: vec![],
        material_ids: HashMap::new(),
        attached: HashMap::new(),
        lights: vec![],
        light_weights: vec![],
    };
    let mut sensor: Option<(SensorSettings, &Location)> = None;
    let mut integrator: Option<IntegratorSettings> = None;
    let mut area_ids = Vec::new();
    for e in &tree.elements {
        match e.tag.as_str() {
            "bsdf" => {
                b.material_of(e)?;
            }
            "shape" => b.shape(e)?,
            "texture" => {
                // built (and its file read) even when unused, as Mitsuba does
                b.textures.texture(e)?;
            }
            // built by the shape that references it
            "emitter" if e.plugin == "area" && e.id.is_some() => area_ids.push(e),
            "emitter" => {
                let (light, w) = build_emitter(e, None, &mut b.textures)?;
                b.lights.push(light);
                b.light_weights.push(w);
            }
            "sensor" => {
                if let Some((_, first)) = &sensor {
                    return Err(SceneError::at(
                        &e.location,
                        format!("only one <sensor> is supported (first at {first})"),
                    ));
                }
                sensor = Some((build_sensor(e)?, &e.location));
            }
            "integrator" => {
                if integrator.is_some() {
                    return Err(SceneError::at(&e.location, "only one <integrator> is allowed"));
                }
                integrator = Some(build_integrator(e)?);
            }
            // spectra are read where they are referenced
            _ if e.is_spectrum() => {}
            other => return Err(SceneError::at(&e.location, format!("<{other}> is not supported"))),
        }
    }
    for e in area_ids.iter().filter(|e| e.id.as_ref().is_some_and(|id| !b.attached.contains_key(id))) {
        // Mitsuba loads it and leaves it out of the scene's emitters
        tracing::warn!(file = %e.location, id = e.id.as_deref(), "an area emitter no shape references lights nothing");
    }
    let (sensor, _) = sensor.ok_or_else(|| SceneError::file(path, "the scene has no <sensor>"))?;
    let integrator = integrator.unwrap_or(IntegratorSettings {
        kind: "path".into(),
        max_depth: None,
        rr_depth: 5,
        hide_emitters: false,
        delta_light_factor: 1,
    });
    if integrator.delta_light_factor != 1 {
        let factor = integrator.delta_light_factor as f32;
        b.lights.iter_mut().for_each(|light| light.scale_delta(factor));
    }
    Ok(Scene::assemble(
        path,
        Parts {
            shapes: b.shapes,
            meshes: b.meshes,
            materials: b.materials,
            material_textures: b.material_textures,
            texture_bytes: b.textures.decoded_bytes(),
            lights: b.lights,
            light_weights: b.light_weights,
            camera: sensor.camera,
            film: sensor.film,
            spp: sensor.spp,
            seed: sensor.seed,
            integrator,
        },
    ))
}

fn build_sensor(e: &Element) -> Result<SensorSettings, SceneError> {
    if e.plugin != "perspective" {
        return Err(SceneError::at(
            &e.location,
            format!("unsupported sensor \"{}\" (supported: perspective)", e.plugin),
        ));
    }
    let mut film: Option<FilmSettings> = None;
    let (mut spp, mut seed) = (4u32, 0u64);
    for c in &e.children {
        match (c.tag.as_str(), c.plugin.as_str()) {
            ("film", "hdrfilm") => film = Some(build_film(c)?),
            ("film", other) => {
                return Err(SceneError::at(&c.location, format!("unsupported film \"{other}\" (supported: hdrfilm)")));
            }
            ("sampler", _) => (spp, seed) = build_sampler(c)?,
            (tag, _) => return Err(SceneError::at(&c.location, format!("a sensor cannot contain <{tag}>"))),
        }
    }
    let film = film.unwrap_or_else(|| {
        tracing::warn!(file = %e.location, "sensor has no film: using Mitsuba's default 768x576");
        FilmSettings { width: 768, height: 576, crop: (0, 0, 768, 576), filter: Filter::new(FilterKind::DEFAULT) }
    });
    let aspect = film.width as f64 / film.height as f64;
    let fov_x = fov_x_degrees(e, aspect)?;
    let to_world = e.transform("to_world")?;
    if to_world.uniform_scale(1e-3).is_none_or(|s| (s - 1.0).abs() > 1e-3) {
        return Err(SceneError::at(
            e.location_of("to_world"),
            "the sensor's to_world must be a rigid transform (no scale or shear)",
        ));
    }
    // a pinhole has no focus, and a static scene no motion: these do not change the image
    e.float("focus_distance")?;
    e.float("shutter_open")?;
    e.float("shutter_close")?;
    let near_clip = e.float_or("near_clip", 1e-2)?;
    let far_clip = e.float_or("far_clip", 1e4)?;
    if !(near_clip > 0.0 && far_clip > near_clip) {
        return Err(SceneError::at(
            e.location_of("near_clip"),
            format!("need 0 < near_clip < far_clip, found {near_clip} and {far_clip}"),
        ));
    }
    e.check_all_used()?;
    let camera = PerspectiveCamera::new(to_world, fov_x as f32, film.width, film.height, near_clip, far_clip)
        .with_crop(film.crop.0, film.crop.1, film.crop.2, film.crop.3);
    let film = FilmSpec::new(film.crop.2, film.crop.3, film.filter);
    Ok(SensorSettings { camera, film, spp, seed })
}

/// Mitsuba's `parse_fov`: the horizontal field of view from `fov` + `fov_axis` or `focal_length`.
fn fov_x_degrees(e: &Element, aspect: f64) -> Result<f64, SceneError> {
    let (fov, axis) = match (e.float("fov")?, e.string("focal_length")?) {
        (Some(_), Some(_)) => {
            return Err(SceneError::at(e.location_of("fov"), "give either \"fov\" or \"focal_length\", not both"));
        }
        (Some(fov), None) => {
            let axis = e.string("fov_axis")?.unwrap_or("x").to_ascii_lowercase();
            let axis = match axis.as_str() {
                "smaller" => {
                    if aspect > 1.0 {
                        "y".to_string()
                    } else {
                        "x".to_string()
                    }
                }
                "larger" => {
                    if aspect > 1.0 {
                        "x".to_string()
                    } else {
                        "y".to_string()
                    }
                }
                _ => axis,
            };
            (fov as f64, axis)
        }
        (None, focal) => {
            let f = focal.unwrap_or("50mm");
            let value: f64 = f.trim_end_matches("mm").parse().map_err(|_| {
                SceneError::at(e.location_of("focal_length"), format!("focal length \"{f}\" must look like \"50mm\""))
            })?;
            (
                (2.0 * ((36.0f64 * 36.0 + 24.0 * 24.0).sqrt() / (2.0 * value)).atan()).to_degrees(),
                "diagonal".to_string(),
            )
        }
    };
    let half = |deg: f64| (0.5 * deg.to_radians()).tan();
    let fov_x = match axis.as_str() {
        "x" => fov,
        "y" => (2.0 * (half(fov) * aspect).atan()).to_degrees(),
        "diagonal" => {
            let diagonal = 2.0 * half(fov);
            let width = diagonal / (1.0 + 1.0 / (aspect * aspect)).sqrt();
            (2.0 * (0.5 * width).atan()).to_degrees()
        }
        other => {
            return Err(SceneError::at(
                e.location_of("fov_axis"),
                format!("\"fov_axis\" must be one of x, y, diagonal, smaller, larger; found \"{other}\""),
            ));
        }
    };
    if !(fov_x > 0.0 && fov_x < 180.0) {
        return Err(SceneError::at(
            e.location_of("fov"),
            format!("the field of view must lie in (0, 180) degrees, found {fov_x}"),
        ));
    }
    Ok(fov_x)
}

/// The film's size, crop window and reconstruction filter.
struct FilmSettings {
    /// The full film.
    width: u32,
    height: u32,
    /// The rendered window: offset and size within the full film.
    crop: (u32, u32, u32, u32),
    filter: Filter,
}

fn build_film(c: &Element) -> Result<FilmSettings, SceneError> {
    let dim = |name: &str, default: i64| -> Result<u32, SceneError> {
        match c.integer(name)?.unwrap_or(default) {
            v if v > 0 && v <= 65_536 => Ok(v as u32),
            v => Err(SceneError::at(c.location_of(name), format!("film \"{name}\" must lie in 1..=65536, found {v}"))),
        }
    };
    let (w, h) = (dim("width", 768)?, dim("height", 576)?);
    if let Some(f) = c.string("pixel_format")? {
        if !matches!(f, "rgb" | "rgba") {
            return Err(SceneError::at(
                c.location_of("pixel_format"),
                format!("unsupported pixel_format \"{f}\" (rgb or rgba; Tessera writes RGB)"),
            ));
        }
    }
    if let Some(f) = c.string("component_format")? {
        if !matches!(f, "float16" | "float32") {
            return Err(SceneError::at(
                c.location_of("component_format"),
                format!("unsupported component_format \"{f}\" (float16 or float32; Tessera writes float32)"),
            ));
        }
    }
    match c.string("file_format")?.unwrap_or("openexr") {
        "openexr" | "exr" => {}
        other => {
            tracing::warn!(file = %c.location_of("file_format"), "file_format \"{other}\" ignored: Tessera writes OpenEXR and a PNG preview")
        }
    }
    if c.boolean_or("sample_border", false)? {
        return Err(SceneError::at(c.location_of("sample_border"), "sample_border = true is not supported"));
    }
    let crop = crop_window(c, w, h)?;
    let filter = match c.children.as_slice() {
        // Mitsuba's default
        [] => Filter::new(FilterKind::DEFAULT),
        [f] if f.tag == "rfilter" => build_rfilter(f)?,
        [f, ..] => {
            return Err(SceneError::at(&f.location, format!("a film can contain one <rfilter>, found <{}>", f.tag)));
        }
    };
    c.check_all_used()?;
    Ok(FilmSettings { width: w, height: h, crop, filter })
}

/// `crop_offset_x/y` and `crop_width/height` (default: the whole film), checked to lie inside.
fn crop_window(c: &Element, w: u32, h: u32) -> Result<(u32, u32, u32, u32), SceneError> {
    let get = |name: &str, default: u32| -> Result<u32, SceneError> {
        match c.integer(name)? {
            None => Ok(default),
            Some(v) if v >= 0 && v <= 65_536 => Ok(v as u32),
            Some(v) => Err(SceneError::at(c.location_of(name), format!("\"{name}\" must lie in 0..=65536, found {v}"))),
        }
    };
    let (x, y) = (get("crop_offset_x", 0)?, get("crop_offset_y", 0)?);
    let (cw, ch) = (get("crop_width", w.saturating_sub(x))?, get("crop_height", h.saturating_sub(y))?);
    if cw == 0 || ch == 0 || x + cw > w || y + ch > h {
        return Err(SceneError::at(
            c.location_of("crop_width"),
            format!("the crop window {cw}x{ch} at ({x}, {y}) does not fit the {w}x{h} film"),
        ));
    }
    Ok((x, y, cw, ch))
}

/// An `<rfilter>` with Mitsuba's parameters and defaults.
fn build_rfilter(f: &Element) -> Result<Filter, SceneError> {
    // a radius of at most MAX_RADIUS bounds the border a tile's sums carry
    let positive = |name: &str, default: f32, max: f32| -> Result<f32, SceneError> {
        match f.float_or(name, default)? {
            v if v > 0.0 && v <= max => Ok(v),
            v => Err(SceneError::at(f.location_of(name), format!("\"{name}\" must lie in (0, {max}], found {v}"))),
        }
    };
    let kind = match f.plugin.as_str() {
        "box" => FilterKind::Box,
        "tent" => FilterKind::Tent { radius: positive("radius", 1.0, MAX_RADIUS)? },
        "gaussian" => FilterKind::Gaussian { stddev: positive("stddev", 0.5, MAX_RADIUS / 4.0)? },
        "mitchell" => FilterKind::Mitchell { b: f.float_or("B", 1.0 / 3.0)?, c: f.float_or("C", 1.0 / 3.0)? },
        "catmullrom" => FilterKind::CatmullRom,
        "lanczos" => match f.integer("lobes")?.unwrap_or(3) {
            l if (1..=16).contains(&l) => FilterKind::Lanczos { lobes: l as u32 },
            l => {
                return Err(SceneError::at(f.location_of("lobes"), format!("\"lobes\" must lie in 1..=16, found {l}")));
            }
        },
        other => {
            return Err(SceneError::at(
                &f.location,
                format!("rfilter \"{other}\" is not supported (box, tent, gaussian, mitchell, catmullrom, lanczos)"),
            ));
        }
    };
    f.check_all_used()?;
    Ok(Filter::new(kind))
}

/// A `serialized` shape's `shape_index` (default 0).
fn shape_index(e: &Element) -> Result<u32, SceneError> {
    match e.integer("shape_index")?.unwrap_or(0) {
        i if (0..=u32::MAX as i64).contains(&i) => Ok(i as u32),
        i => Err(SceneError::at(
            e.location_of("shape_index"),
            format!("\"shape_index\" must not be negative, found {i}"),
        )),
    }
}

impl Builder<'_> {
    /// The material of a `<bsdf>` (or a copy of one placed by `<ref>`), built once per id.
    fn material_of(&mut self, e: &Element) -> Result<u32, SceneError> {
        if let Some(&m) = e.id.as_ref().and_then(|id| self.material_ids.get(id)) {
            return Ok(m);
        }
        let (material, textures) = build_material(e, &mut self.textures)?;
        self.materials.push(material);
        self.material_textures.push(textures);
        let m = self.materials.len() as u32 - 1;
        if let Some(id) = &e.id {
            self.material_ids.insert(id.clone(), m);
        }
        Ok(m)
    }

    /// Records that a shape references the top-level area emitter `c` (a copy placed by
    /// `<ref>`); a second shape doing so is refused, as Mitsuba refuses it.
    fn attach(&mut self, c: &Element) -> Result<(), SceneError> {
        let (Some(id), Some(at)) = (&c.id, &c.reference) else { return Ok(()) };
        if let Some(first) = self.attached.insert(id.clone(), at.clone()) {
            let why = format!("area emitter \"{id}\" already lights the shape at {first}: an emitter lights one shape");
            return Err(SceneError::at(at, why));
        }
        Ok(())
    }

    fn shape(&mut self, e: &Element) -> Result<(), SceneError> {
        let mut material = None;
        let mut emitter = None;
        for c in &e.children {
            let at = c.reference.as_ref().unwrap_or(&c.location);
            match c.tag.as_str() {
                "bsdf" if material.is_none() => material = Some(self.material_of(c)?),
                "bsdf" => return Err(SceneError::at(at, "a shape can have only one bsdf")),
                "emitter" if emitter.is_none() => {
                    self.attach(c)?;
                    emitter = Some(c)
                }
                "emitter" => return Err(SceneError::at(at, "a shape can have only one nested emitter")),
                other => return Err(SceneError::at(at, format!("a shape cannot contain <{other}>"))),
            }
        }
        let to_world = e.transform("to_world")?;
        let flip_normals = e.boolean_or("flip_normals", false)?;
        let mut object_rotation = glam::Mat3::IDENTITY;
        let geometry = match e.plugin.as_str() {
            "rectangle" | "cube" => {
                let mut mesh = if e.plugin == "rectangle" { Mesh::rectangle() } else { Mesh::cube() };
                self.mesh_files.count(mesh.triangles.len(), &e.location)?;
                mesh.transform(&to_world);
                self.add_mesh(mesh)
            }
            "obj" | "ply" | "serialized" => {
                let file = e
                    .string("filename")?
                    .ok_or_else(|| SceneError::at(&e.location, format!("{} needs \"filename\"", e.describe())))?;
                let path = self
                    .resolver
                    .resolve_checked(Path::new(file))
                    .map_err(|why| SceneError::at(e.location_of("filename"), format!("\"{file}\" {why}")))?;
                let index = if e.plugin == "serialized" { shape_index(e)? } else { 0 };
                let shared = self.mesh_files.load(&path, &e.plugin, index)?;
                // counted before this shape's own copy is made
                self.mesh_files.count(shared.triangles.len(), &e.location)?;
                let mut mesh = Mesh::clone(&shared);
                let face_normals = e.boolean_or("face_normals", false)?;
                // Mitsuba flips an OBJ's v by default, a PLY's only on request; serialized never
                let flip_default = e.plugin == "obj";
                let flip = e.plugin != "serialized" && e.boolean_or("flip_tex_coords", flip_default)?;
                if let (true, Some(uvs)) = (flip, &mut mesh.uvs) {
                    uvs.iter_mut().for_each(|uv| uv.y = 1.0 - uv.y);
                }
                mesh.transform(&to_world);
                if face_normals {
                    mesh.normals = None;
                } else if mesh.normals.is_none() {
                    compute_smooth_normals(&mut mesh);
                }
                self.add_mesh(mesh)
            }
            "sphere" => {
                let center = e.vector("center")?.unwrap_or(Vec3::ZERO);
                let radius = e.float_or("radius", 1.0)?;
                if !(radius > 0.0) {
                    return Err(SceneError::at(
                        e.location_of("radius"),
                        format!("sphere radius must be positive, found {radius}"),
                    ));
                }
                let scale = to_world.uniform_scale(1e-4).ok_or_else(|| {
                    SceneError::at(e.location_of("to_world"), "a sphere's to_world must not scale non-uniformly")
                })?;
                object_rotation = glam::Mat3::from_mat4(to_world.inv_f32()) * scale;
                ShapeGeometry::Sphere { center: to_world.point(center), radius: radius * scale }
            }
            "disk" => ShapeGeometry::Disk { to_world, normal: to_world.normal(Vec3::Z).normalize() },
            other => {
                return Err(SceneError::at(
                    &e.location,
                    format!(
                        "unsupported shape \"{other}\" (supported: rectangle, cube, disk, sphere, obj, ply, serialized)"
                    ),
                ));
            }
        };
        e.check_all_used()?;
        let area = match &geometry {
            ShapeGeometry::Mesh(m) => {
                let m = &self.meshes[*m as usize];
                (0..m.triangles.len()).map(|i| m.triangle_area(i)).sum()
            }
            ShapeGeometry::Sphere { radius, .. } => 4.0 * PI * radius * radius,
            ShapeGeometry::Disk { to_world, .. } => {
                PI * to_world.vector(Vec3::X).cross(to_world.vector(Vec3::Y)).length()
            }
        };
        if !(area > 0.0) || !area.is_finite() {
            return Err(SceneError::at(&e.location, format!("{} has no surface area", e.describe())));
        }
        let material = match material {
            Some(m) => m,
            None => {
                // Mitsuba: a shape without a bsdf is diffuse 0.5, an emitting one is black
                let r = if emitter.is_some() { Rgb::ZERO } else { Rgb::splat(0.5) };
                self.materials.push(Material::one_sided(Bxdf::Diffuse(Diffuse { reflectance: r })));
                self.material_textures.push(None);
                self.materials.len() as u32 - 1
            }
        };
        if let Some(textures) = &self.material_textures[material as usize] {
            let attributes = match &geometry {
                ShapeGeometry::Mesh(m) => self.meshes[*m as usize].attributes.as_slice(),
                _ => &[],
            };
            textures
                .check_attributes(attributes)
                .map_err(|err| SceneError::at(&e.location, format!("{} cannot use its bsdf: {err}", e.describe())))?;
        }
        let index = self.shapes.len() as u32;
        let light = match emitter {
            Some(em) => {
                let (light, w) = build_emitter(em, Some(index), &mut self.textures)?;
                self.lights.push(light);
                self.light_weights.push(w);
                Some(self.lights.len() as u32 - 1)
            }
            None => None,
        };
        let mut shape = Shape {
            geometry,
            material,
            light,
            flip_normals,
            area,
            area_sampling: Default::default(),
            id: e.id.clone(),
            object_rotation,
        };
        if light.is_some() {
            let mesh = match &shape.geometry {
                ShapeGeometry::Mesh(m) => Some(&self.meshes[*m as usize]),
                _ => None,
            };
            shape.prepare_area_sampling(mesh);
        }
        self.shapes.push(shape);
        Ok(())
    }

    fn add_mesh(&mut self, mesh: Mesh) -> ShapeGeometry {
        self.meshes.push(mesh);
        ShapeGeometry::Mesh(self.meshes.len() as u32 - 1)
    }
}
