//! Scenes: loading Mitsuba 3 XML into an immutable [`Scene`] that integrators query.
//!
//! ```no_run
//! let scene = tessera_common::scene::Scene::load(std::path::Path::new("scenes/cornell-box/scene.xml")).unwrap();
//! println!("{} shapes, {}x{}", scene.shapes.len(), scene.camera.width, scene.camera.height);
//! ```

pub mod accel;
mod build;
mod build_bsdf;
mod build_settings;
pub mod error;
pub mod load;
mod primitive;
pub mod refused;
pub mod resolver;
mod sah;
pub mod shape;
pub mod xml;

use crate::bsdf::Material;
use crate::camera::PerspectiveCamera;
use crate::film::FilmSpec;
use crate::geometry::{Ray, SurfaceInteraction};
use crate::light::{Light, LightContext, LightSampler};
use crate::math::Frame;
use accel::Accel;
pub use error::{Location, SceneError};
use glam::Vec3;
pub use resolver::FileResolver;
use shape::{Mesh, Shape, ShapeGeometry};
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
}

/// An immutable, render-ready scene.
pub struct Scene {
    /// The file it came from.
    pub path: PathBuf,
    /// Shapes.
    pub shapes: Vec<Shape>,
    /// Triangle meshes referenced by shapes.
    pub meshes: Vec<Mesh>,
    /// Materials referenced by shapes.
    pub materials: Vec<Material>,
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
        let text =
            std::fs::read_to_string(path).map_err(|e| SceneError::file(path, format!("cannot read scene: {e}")))?;
        Self::from_xml(&text, path, defines)
    }

    /// Builds a scene from XML text; `path` names it in messages and anchors relative paths
    /// (includes, `<path>`, filenames).
    pub fn from_xml(text: &str, path: &Path, defines: &HashMap<String, String>) -> Result<Scene, SceneError> {
        let tree = xml::parse(text, path, defines)?;
        build::build(&tree, path)
    }

    /// Finishes a scene from its parts: builds the BVH, the light distribution and bounds.
    #[allow(clippy::too_many_arguments)]
    pub(crate) fn assemble(
        path: &Path,
        shapes: Vec<Shape>,
        meshes: Vec<Mesh>,
        materials: Vec<Material>,
        lights: Vec<Light>,
        light_weights: Vec<f32>,
        camera: PerspectiveCamera,
        film: FilmSpec,
        spp: u32,
        seed: u64,
        integrator: IntegratorSettings,
    ) -> Scene {
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
        let infinite_lights =
            lights.iter().enumerate().filter(|(_, l)| l.is_infinite()).map(|(i, _)| i as u32).collect();
        Scene {
            path: path.to_path_buf(),
            shapes,
            meshes,
            materials,
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
        Some(SurfaceInteraction {
            p,
            t: hit.t,
            n_geo: n_geo * flip,
            frame: Frame::from_normal(n_shading * flip),
            wo: -ray.d,
            shape: hit.shape,
            prim: hit.index,
            bary: glam::Vec2::from(hit.bary),
        })
    }

    /// The texture coordinates of a hit, in Mitsuba's parameterisation of the shape: a mesh's
    /// interpolated uvs (or its barycentrics when it has none), a sphere's (atan2(y, x)/2π,
    /// acos(z)/π) and a disk's (r, φ/2π) in object space. Computed on demand, so that scenes
    /// without textures do not pay for it.
    pub fn uv_at(&self, si: &SurfaceInteraction) -> glam::Vec2 {
        use std::f32::consts::PI;
        let shape = &self.shapes[si.shape as usize];
        let wrap = |a: f32| {
            let u = a / (2.0 * PI);
            if u < 0.0 { u + 1.0 } else { u }
        };
        match &shape.geometry {
            ShapeGeometry::Mesh(m) => {
                let mesh = &self.meshes[*m as usize];
                let Some(uvs) = &mesh.uvs else { return si.bary };
                let [i0, i1, i2] = mesh.triangles[si.prim as usize];
                let (b1, b2) = (si.bary.x, si.bary.y);
                uvs[i0 as usize] * (1.0 - b1 - b2) + uvs[i1 as usize] * b1 + uvs[i2 as usize] * b2
            }
            ShapeGeometry::Sphere { center, .. } => {
                let d = (shape.object_rotation * (si.p - *center)).normalize_or_zero();
                glam::Vec2::new(wrap(d.y.atan2(d.x)), d.z.clamp(-1.0, 1.0).acos() / PI)
            }
            ShapeGeometry::Disk { to_world, .. } => {
                let p = to_world.inv_point(si.p);
                glam::Vec2::new(glam::Vec2::new(p.x, p.y).length(), wrap(p.y.atan2(p.x)))
            }
        }
    }
}
