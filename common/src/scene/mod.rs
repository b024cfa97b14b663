//! Scenes: loading Mitsuba 3 XML into an immutable [`Scene`] that integrators query.
//!
//! ```no_run
//! let scene = tessera_common::scene::Scene::load(std::path::Path::new("scenes/cornell-box/scene.xml")).unwrap();
//! println!("{} shapes, {}x{}", scene.shapes.len(), scene.camera.width, scene.camera.height);
//! ```

pub mod accel;
mod build;
mod build_bsdf;
mod build_emitter;
mod build_mesh;
mod build_settings;
mod build_texture;
mod conductors;
pub mod error;
pub mod load;
mod primitive;
pub mod refused;
pub mod resolver;
mod sah;
pub mod shape;
pub mod xml;

use crate::bsdf::Material;
use crate::bsdf::textured::MaterialTextures;
use crate::camera::PerspectiveCamera;
use crate::film::FilmSpec;
use crate::geometry::{Ray, SurfaceInteraction, SurfaceRef};
use crate::light::{Light, LightContext, LightSampler};
use crate::math::Frame;
use crate::texture::TextureLimits;
use accel::Accel;
pub use error::{Location, SceneError};
use glam::Vec3;
pub use resolver::FileResolver;
use shape::{Mesh, Shape, ShapeGeometry};
use std::borrow::Cow;
use std::collections::HashMap;
use std::path::{Path, PathBuf};

/// Integrator settings from the scene file (Mitsuba's `path` parameters).
#[derive(Clone, Debug, PartialEq)]
pub struct IntegratorSettings {
    /// Plugin name in the file (`path`).
    pub kind: String,
    /// Longest path in segments, counting the camera ray; `None` = unlimited.
    pub max_depth: Option<u32>,
    /// Depth from which Russian roulette starts.
    pub rr_depth: u32,
    /// Hide directly visible emitters.
    pub hide_emitters: bool,
    /// What point, spot and directional lights' light is multiplied by: Mitsuba's `direct`
    /// weighs each of its `emitter_samples` samples of a delta light by 1, not by
    /// 1 / `emitter_samples` as other lights (`src/integrators/direct.cpp`), so their direct
    /// light is that many times their own (0: none). 1 for every other integrator.
    pub delta_light_factor: u32,
}

/// How much memory a scene may make its loader take.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct SceneLimits {
    /// What its images may take once decoded.
    pub textures: TextureLimits,
    /// The most triangles its shapes may hold together (every shape naming a mesh file holds
    /// its own copy, about 150 bytes a triangle with the BVH).
    pub max_triangles: u64,
}

/// [`SceneLimits::max_triangles`] unless configured. Loading takes up to about 440 bytes a
/// triangle at its peak (a million-triangle OBJ: 454 MB, `scripts/million-triangles.sh`), so
/// a few hundred bytes of XML naming one mesh many times stay under 1 GiB; larger scenes need
/// the limit raised where they are loaded (`--max-triangles`).
pub const DEFAULT_MAX_TRIANGLES: u64 = 2_000_000;

impl SceneLimits {
    /// The defaults.
    pub const DEFAULT: SceneLimits =
        SceneLimits { textures: TextureLimits::DEFAULT, max_triangles: DEFAULT_MAX_TRIANGLES };
}

impl Default for SceneLimits {
    fn default() -> Self {
        Self::DEFAULT
    }
}

/// How to load a scene.
#[derive(Clone, Debug, Default)]
pub struct LoadOptions {
    /// `$name` values overriding the file's `<default>`s (Mitsuba's `-D name=value`).
    pub defines: HashMap<String, String>,
    /// The memory its images and meshes may take.
    pub limits: SceneLimits,
    /// The folder every file the scene names must lie in (a farm job's bundle); `None` lets a
    /// local scene name any file.
    pub confine_to: Option<PathBuf>,
}

/// What the builder hands to [`Scene::assemble`].
pub(crate) struct Parts {
    pub shapes: Vec<Shape>,
    pub meshes: Vec<Mesh>,
    pub materials: Vec<Material>,
    pub material_textures: Vec<Option<MaterialTextures>>,
    pub texture_bytes: usize,
    pub lights: Vec<Light>,
    pub light_weights: Vec<f32>,
    pub camera: PerspectiveCamera,
    pub film: FilmSpec,
    pub spp: u32,
    pub seed: u64,
    pub integrator: IntegratorSettings,
}

/// An immutable, render-ready scene.
pub struct Scene {
    /// The file it came from.
    pub path: PathBuf,
    /// Shapes.
    pub shapes: Vec<Shape>,
    /// Triangle meshes referenced by shapes.
    pub meshes: Vec<Mesh>,
    /// Materials referenced by shapes; a textured one holds its constant parameters, and
    /// [`Scene::material_at`] resolves its textures at a point.
    pub materials: Vec<Material>,
    /// The textures of each material (`None` for untextured materials, most of them).
    pub material_textures: Vec<Option<MaterialTextures>>,
    /// Bytes of decoded image data the scene's textures hold (environment maps included).
    pub texture_bytes: usize,
    /// Lights.
    pub lights: Vec<Light>,
    /// Indices of the infinite lights (seen by escaping rays).
    pub infinite_lights: Vec<u32>,
    /// Distribution for choosing a light.
    pub light_sampler: LightSampler,
    /// The camera; its `width` and `height` are the rendered image's (the film's crop window).
    pub camera: PerspectiveCamera,
    /// The rendered image's size and reconstruction filter.
    pub film: FilmSpec,
    /// Samples per pixel from the file's sampler.
    pub spp: u32,
    /// Seed from the file's sampler (0 when absent).
    pub seed: u64,
    /// Integrator settings.
    pub integrator: IntegratorSettings,
    /// Centre of the bounding sphere of all geometry.
    pub bounds_center: Vec3,
    /// Radius of the bounding sphere of all geometry.
    pub bounds_radius: f32,
    accel: Accel,
    /// Per material: whether it is anisotropic, so that hits on it get Mitsuba's shading frame
    /// from ∂p/∂u rather than one built from the normal alone.
    needs_tangent: Vec<bool>,
    /// No material has textures or a mask and no emitter a texture, so integrators may use
    /// `materials` and the lights' constant radiance as they are.
    untextured: bool,
    /// Unit geometric normal of every triangle, per mesh (zero for degenerate triangles),
    /// computed once rather than at every hit.
    face_normals: Vec<Vec<Vec3>>,
}

impl Scene {
    /// Loads a Mitsuba 3 XML scene; relative filenames resolve from the file's folder (and the
    /// folders its `<path>` elements add).
    pub fn load(path: &Path) -> Result<Scene, SceneError> {
        Self::load_with(path, &HashMap::new())
    }

    /// Loads a scene with `$name` parameters overriding the file's `<default>`s.
    pub fn load_with(path: &Path, defines: &HashMap<String, String>) -> Result<Scene, SceneError> {
        Self::load_options(path, &LoadOptions { defines: defines.clone(), ..LoadOptions::default() })
    }

    /// Loads a scene with `$name` parameters and limits. Loaded confined to a folder (a
    /// job's bundle), its errors name files relative to that folder.
    pub fn load_options(path: &Path, options: &LoadOptions) -> Result<Scene, SceneError> {
        let load = || {
            let cannot = |e: std::io::Error| SceneError::file(path, format!("cannot read scene: {e}"));
            let len = std::fs::metadata(path).map_err(cannot)?.len();
            if len > xml::MAX_XML_BYTES as u64 {
                return Err(SceneError::file(path, format!("the scene file is over {} MiB", xml::MAX_XML_BYTES >> 20)));
            }
            let text = std::fs::read_to_string(path).map_err(cannot)?;
            let tree = xml::parse_confined(&text, path, &options.defines, options.confine_to.as_deref())?;
            build::build(&tree, path, options.limits)
        };
        // a job's scene names its own files, never the folder it is kept in
        match &options.confine_to {
            Some(root) => load().map_err(|e| e.within(root)),
            None => load(),
        }
    }

    /// Builds a scene from XML text; `path` names it in messages and anchors relative paths
    /// (includes, `<path>`, filenames).
    pub fn from_xml(text: &str, path: &Path, defines: &HashMap<String, String>) -> Result<Scene, SceneError> {
        let tree = xml::parse(text, path, defines)?;
        build::build(&tree, path, SceneLimits::default())
    }

    /// The same scene rendered at `width × height` pixels: the camera's view and the film's
    /// filter stay, the pixels are resized. `None` if that changes the image's proportions.
    pub fn with_resolution(mut self, width: u32, height: u32) -> Option<Scene> {
        self.camera = self.camera.with_resolution(width, height)?;
        self.film = FilmSpec::new(width, height, self.film.filter);
        Some(self)
    }

    /// Finishes a scene from its parts: builds the BVH, the light distribution and bounds.
    pub(crate) fn assemble(path: &Path, parts: Parts) -> Scene {
        let Parts {
            shapes,
            meshes,
            materials,
            material_textures,
            texture_bytes,
            lights,
            light_weights,
            camera,
            film,
            spp,
            seed,
            integrator,
        } = parts;
        let accel = Accel::build(&shapes, &meshes);
        let face_normals = meshes
            .iter()
            .map(|m| {
                (0..m.triangles.len())
                    .map(|i| {
                        let [a, b, c] = m.corners(i);
                        (b - a).cross(c - a).normalize_or_zero()
                    })
                    .collect()
            })
            .collect();
        let (mut lo, mut hi) = (Vec3::splat(f32::MAX), Vec3::splat(f32::MIN));
        for s in &shapes {
            match &s.geometry {
                ShapeGeometry::Mesh(m) => meshes[*m as usize].positions.iter().for_each(|p| {
                    lo = lo.min(*p);
                    hi = hi.max(*p);
                }),
                ShapeGeometry::Sphere { center, radius } => {
                    lo = lo.min(*center - *radius);
                    hi = hi.max(*center + *radius);
                }
                ShapeGeometry::Disk { to_world, .. } => {
                    for (x, y) in [(-1.0, -1.0), (1.0, 1.0), (-1.0, 1.0), (1.0, -1.0)] {
                        let p = to_world.point(Vec3::new(x, y, 0.0));
                        lo = lo.min(p);
                        hi = hi.max(p);
                    }
                }
            }
        }
        // the camera is inside the scene as far as environment emission is concerned
        lo = lo.min(camera.origin);
        hi = hi.max(camera.origin);
        let bounds_center = 0.5 * (lo + hi);
        let bounds_radius = (0.5 * (hi - lo).length()).max(1e-3) * 1.01;
        let needs_tangent = materials
            .iter()
            .zip(&material_textures)
            .map(|(m, t)| m.is_anisotropic() || t.as_ref().is_some_and(|t| t.is_anisotropic()))
            .collect();
        let untextured = material_textures.iter().all(Option::is_none)
            && materials.iter().all(|m| m.opacity == 1.0)
            && !lights.iter().any(Light::is_textured);
        let infinite_lights =
            lights.iter().enumerate().filter(|(_, l)| l.is_infinite()).map(|(i, _)| i as u32).collect();
        Scene {
            path: path.to_path_buf(),
            shapes,
            meshes,
            materials,
            material_textures,
            texture_bytes,
            lights,
            infinite_lights,
            light_sampler: LightSampler::new(&light_weights),
            camera,
            film,
            spp,
            seed,
            integrator,
            bounds_center,
            bounds_radius,
            accel,
            needs_tangent,
            untextured,
            face_normals,
        }
    }

    /// What lights need to know about the scene.
    #[inline]
    pub fn light_context(&self) -> LightContext<'_> {
        LightContext {
            shapes: &self.shapes,
            meshes: &self.meshes,
            center: self.bounds_center,
            radius: self.bounds_radius,
        }
    }

    /// Total number of triangles.
    pub fn triangle_count(&self) -> usize {
        self.meshes.iter().map(|m| m.triangles.len()).sum()
    }

    /// Whether anything blocks `ray` before `ray.tmax`.
    #[inline]
    pub fn occluded(&self, ray: &Ray) -> bool {
        self.accel.occluded(ray)
    }

    /// The closest surface along `ray`.
    pub fn intersect(&self, ray: &Ray) -> Option<SurfaceInteraction> {
        let hit = self.accel.closest_hit(ray)?;
        let shape = &self.shapes[hit.shape as usize];
        let flip = if shape.flip_normals { -1.0 } else { 1.0 };
        let (p, n_geo, n_shading) = match &shape.geometry {
            ShapeGeometry::Mesh(m) => {
                let mesh = &self.meshes[*m as usize];
                let [a, b, c] = mesh.corners(hit.index as usize);
                let [b1, b2] = hit.bary;
                let b0 = 1.0 - b1 - b2;
                let p = a * b0 + b * b1 + c * b2;
                let ng = self.face_normals[*m as usize][hit.index as usize];
                let ns = match &mesh.normals {
                    Some(ns) => {
                        let [i0, i1, i2] = mesh.triangles[hit.index as usize];
                        (ns[i0 as usize] * b0 + ns[i1 as usize] * b1 + ns[i2 as usize] * b2)
                            .try_normalize()
                            .unwrap_or(ng)
                    }
                    None => ng,
                };
                (p, ng, ns)
            }
            ShapeGeometry::Sphere { center, radius } => {
                let n = (ray.at(hit.t) - *center).normalize_or_zero();
                // re-project onto the sphere to remove the intersection's rounding error
                (*center + n * *radius, n, n)
            }
            ShapeGeometry::Disk { normal, .. } => (ray.at(hit.t), *normal, *normal),
        };
        if n_geo == Vec3::ZERO {
            return None;
        }
        let n = n_shading * flip;
        let frame = if self.needs_tangent[shape.material as usize] {
            Frame::from_normal_tangent(n, self.dp_du(hit.shape, hit.index, p, n_geo))
        } else {
            Frame::from_normal(n)
        };
        Some(SurfaceInteraction {
            p,
            t: hit.t,
            n_geo: n_geo * flip,
            frame,
            wo: -ray.d,
            shape: hit.shape,
            prim: hit.index,
            bary: glam::Vec2::from(hit.bary),
        })
    }

    /// Mitsuba's ∂p/∂u at a hit (`compute_surface_interaction` of each shape): from the
    /// triangle's uvs (its first edge without uvs, a basis of the normal when the uvs are
    /// degenerate), around a sphere's object z axis, radially outward on a disk.
    #[inline(never)]
    fn dp_du(&self, shape: u32, prim: u32, p: Vec3, n_geo: Vec3) -> Vec3 {
        let shape = &self.shapes[shape as usize];
        match &shape.geometry {
            ShapeGeometry::Mesh(m) => {
                let mesh = &self.meshes[*m as usize];
                let [a, b, c] = mesh.corners(prim as usize);
                let (dp0, dp1) = (b - a, c - a);
                let Some(uvs) = &mesh.uvs else { return dp0 };
                let [i0, i1, i2] = mesh.triangles[prim as usize].map(|i| uvs[i as usize]);
                let (duv0, duv1) = (i1 - i0, i2 - i0);
                let det = duv0.x * duv1.y - duv0.y * duv1.x;
                if det == 0.0 {
                    return Frame::from_normal(n_geo).s;
                }
                (dp0 * duv1.y - dp1 * duv0.y) / det
            }
            ShapeGeometry::Sphere { center, .. } => {
                let d = shape.object_rotation * (p - *center);
                shape.object_rotation.transpose() * Vec3::new(-d.y, d.x, 0.0)
            }
            ShapeGeometry::Disk { to_world, .. } => {
                let q = to_world.inv_point(p);
                let phi = q.y.atan2(q.x);
                to_world.vector(Vec3::new(phi.cos(), phi.sin(), 0.0))
            }
        }
    }

    /// The tangent a path vertex keeps for the hit's shading frame (zero when the frame
    /// follows from the normal, see [`crate::integrator::path::vertex::PathVertex::tangent`]).
    #[inline]
    pub fn vertex_tangent(&self, si: &SurfaceInteraction) -> Vec3 {
        if self.needs_tangent[self.shapes[si.shape as usize].material as usize] { si.frame.s } else { Vec3::ZERO }
    }

    /// Material `index` at a surface point: the material itself when it has no textures
    /// (no copy), otherwise a copy with its textured parameters evaluated at the point.
    #[inline]
    pub fn material_at(&self, index: u32, at: SurfaceRef, p: Vec3) -> Cow<'_, Material> {
        let base = &self.materials[index as usize];
        match &self.material_textures[index as usize] {
            None => Cow::Borrowed(base),
            Some(t) => Cow::Owned(self.resolve_textured(base, t, at, p)),
        }
    }

    /// Out of line so that the integrators' hot loops stay small for untextured scenes.
    #[inline(never)]
    fn resolve_textured(&self, base: &Material, t: &MaterialTextures, at: SurfaceRef, p: Vec3) -> Material {
        let point = shape::texture_point(&self.shapes, &self.meshes, at, p, t.uses_mesh_attributes());
        t.resolve(base, &point)
    }

    /// Whether no material has textures or a mask and no emitter a texture: then
    /// [`Scene::material_of_hit`] is always the shape's material itself, opacities are 1 and
    /// area lights emit their constant radiance, and integrators can compile that case without
    /// the checks (see [`crate::bsdf::Material::sample_in`], [`Light::sample_direct_in`]).
    #[inline]
    pub fn is_untextured(&self) -> bool {
        self.untextured
    }

    /// The material of the shape a ray hit, at the hit.
    #[inline]
    pub fn material_of_hit(&self, si: &SurfaceInteraction) -> Cow<'_, Material> {
        self.material_at(self.shapes[si.shape as usize].material, si.surface(), si.p)
    }

    /// The texture coordinates of a hit; see [`Scene::uv_of`].
    pub fn uv_at(&self, si: &SurfaceInteraction) -> glam::Vec2 {
        self.uv_of(si.surface(), si.p)
    }

    /// The texture coordinates of a point on a shape; see [`shape::surface_uv`].
    pub fn uv_of(&self, at: SurfaceRef, p: Vec3) -> glam::Vec2 {
        shape::surface_uv(&self.shapes, &self.meshes, at, p)
    }
}
