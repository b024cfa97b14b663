//! Emitters: Mitsuba's `area` (on any shape), `point`, `spot`, `constant`, `envmap` and
//! `directional`.
//!
//! Each light offers direct-lighting samples towards a reference point (for next-event
//! estimation) with the matching solid-angle pdf, and emission samples (for light paths) with
//! their position pdf (area measure) and direction pdf (solid angle).

pub mod envmap;
pub mod sampler;

use crate::geometry::SurfaceRef;
use crate::math::{Frame, INV_PI, PI, Rgb, safe_sqrt, warp};
use crate::scene::shape::{Mesh, Shape, ShapeGeometry, SurfacePoint, texture_point};
use crate::texture::Texture;
use glam::{Vec2, Vec3};
use std::sync::Arc;

pub use envmap::Envmap;
pub use sampler::LightSampler;

/// The closed set of light types.
#[derive(Clone, Debug)]
pub enum Light {
    /// Emitting surface of a shape, one-sided (emits to the side its normal points to).
    Area {
        /// Index of the shape.
        shape: u32,
        /// Emitted radiance (when textured: the texture's mean, for reports only).
        radiance: Rgb,
        /// Radiance varying over the surface (Mitsuba's textured `radiance`).
        texture: Option<Arc<Texture>>,
    },
    /// Isotropic point light.
    Point {
        /// Position.
        position: Vec3,
        /// Radiant intensity (W/sr).
        intensity: Rgb,
    },
    /// Constant radiance arriving from every direction at infinity.
    Constant {
        /// Radiance.
        radiance: Rgb,
    },
    /// Radiance from infinity looked up in an image (Mitsuba's `envmap`).
    Envmap(Arc<Envmap>),
    /// Parallel light arriving from infinity along one direction (Mitsuba's `directional`).
    Directional {
        /// Unit direction the light travels in.
        direction: Vec3,
        /// Irradiance on a plane facing the light (W/m²).
        irradiance: Rgb,
    },
    /// A point light emitting into a cone with a smooth edge (Mitsuba's `spot`).
    Spot(Spot),
}

/// Mitsuba's `spot`: intensity along its axis, falling off linearly in the angle from the
/// beam width to the cutoff angle (`src/emitters/spot.cpp`).
#[derive(Clone, Debug)]
pub struct Spot {
    /// Position.
    pub position: Vec3,
    /// Frame whose z axis is the spot's axis.
    pub frame: Frame,
    /// Radiant intensity on the axis (W/sr).
    pub intensity: Rgb,
    /// Cutoff half-angle (radians).
    pub cutoff: f32,
    /// Half-angle of the full-intensity beam (radians).
    pub beam: f32,
    /// An image projected along the beam (Mitsuba's `texture`).
    pub projection: Option<Projection>,
}

/// A spot light's projected image: looked up at (½ + ½ x / (z tan cutoff), ½ + ½ y / (z tan
/// cutoff)) of the direction in the light's own frame, as Mitsuba's `direction_to_uv`.
#[derive(Clone, Debug)]
pub struct Projection {
    /// The image.
    pub texture: Arc<Texture>,
    /// World to the light's frame (its `to_world` rotation, transposed).
    pub to_local: glam::Mat3,
    /// tan(cutoff).
    pub uv_factor: f32,
}

impl Spot {
    /// Intensity emitted in world direction `d` (unit).
    #[inline]
    fn emitted(&self, d: Vec3) -> Rgb {
        let cos = self.frame.to_local(d).z;
        let falloff = if cos >= self.beam.cos() {
            1.0
        } else if cos > self.cutoff.cos() {
            (self.cutoff - cos.clamp(-1.0, 1.0).acos()) / (self.cutoff - self.beam)
        } else {
            0.0
        };
        match &self.projection {
            Some(p) if falloff > 0.0 => {
                let l = p.to_local * d;
                let scale = 0.5 / (l.z * p.uv_factor);
                let uv = Vec2::new(0.5 + l.x * scale, 0.5 + l.y * scale);
                self.intensity * falloff * p.texture.eval(&crate::texture::TexturePoint::uv(uv))
            }
            _ => self.intensity * falloff,
        }
    }
}

/// A direct-lighting sample.
#[derive(Clone, Copy, Debug)]
pub struct DirectSample {
    /// Point on the light (for infinite lights: unused, see `dist`).
    pub p: Vec3,
    /// Surface normal at `p` (zero for point and infinite lights).
    pub n: Vec3,
    /// Unit direction from the reference point to the light.
    pub wi: Vec3,
    /// Distance to `p` (infinite for infinite lights).
    pub dist: f32,
    /// Radiance arriving at the reference point (before visibility).
    pub radiance: Rgb,
    /// Solid-angle pdf at the reference point (1 for delta lights).
    pub pdf: f32,
    /// The light is a delta light (no BSDF sampling can hit it).
    pub delta: bool,
}

/// An emission sample: a ray leaving the light.
#[derive(Clone, Copy, Debug)]
pub struct EmissionSample {
    /// Origin.
    pub p: Vec3,
    /// Surface normal at the origin (zero for point lights; the direction for infinite lights).
    pub n: Vec3,
    /// Where on its shape an area light's origin lies (zero for other lights).
    pub at: SurfaceRef,
    /// Direction of travel.
    pub d: Vec3,
    /// Emitted radiance along `d`.
    pub radiance: Rgb,
    /// Position pdf, area measure (1 for delta positions).
    pub pdf_pos: f32,
    /// Direction pdf, solid angle.
    pub pdf_dir: f32,
    /// The position is a delta distribution (point lights).
    pub delta_pos: bool,
}

/// Scene data lights need: shapes, meshes and the bounding sphere.
pub struct LightContext<'a> {
    /// All shapes.
    pub shapes: &'a [Shape],
    /// All meshes.
    pub meshes: &'a [Mesh],
    /// Centre of the scene's bounding sphere.
    pub center: Vec3,
    /// Radius of the scene's bounding sphere.
    pub radius: f32,
}

/// A textured area light's radiance; out of line so that untextured lights keep the
/// integrators' hot loops small.
#[inline(never)]
fn textured_radiance(ctx: &LightContext, t: &Texture, at: SurfaceRef, p: Vec3) -> Rgb {
    t.eval(&texture_point(ctx.shapes, ctx.meshes, at, p, t.uses_mesh_attributes()))
}

/// Cone of directions a sphere subtends from outside: `(1 − cos θmax, sin² θmax)`, with a
/// Taylor expansion for tiny spheres where `1 − cos` would cancel catastrophically.
fn sphere_cone(dist2: f32, radius: f32) -> (f32, f32) {
    let sin2_max = radius * radius / dist2;
    let one_minus_cos = if sin2_max < 0.000_685_23 { 0.5 * sin2_max } else { 1.0 - safe_sqrt(1.0 - sin2_max) };
    (one_minus_cos, sin2_max)
}

impl Light {
    /// Multiplies a point, spot or directional light's emission by `factor`; other lights are
    /// left as they are (see `IntegratorSettings::delta_light_factor`).
    pub fn scale_delta(&mut self, factor: f32) {
        match self {
            Light::Point { intensity, .. } => *intensity = *intensity * factor,
            Light::Spot(spot) => spot.intensity = spot.intensity * factor,
            Light::Directional { irradiance, .. } => *irradiance = *irradiance * factor,
            Light::Area { .. } | Light::Constant { .. } | Light::Envmap(_) => {}
        }
    }

    /// Whether the light is a delta light (a point or one direction: cannot be hit by rays).
    pub fn is_delta(&self) -> bool {
        matches!(self, Light::Point { .. } | Light::Spot(_) | Light::Directional { .. })
    }

    /// Whether the light is at infinity.
    pub fn is_infinite(&self) -> bool {
        matches!(self, Light::Constant { .. } | Light::Envmap(_) | Light::Directional { .. })
    }

    /// Radiance an escaped ray travelling along `d` sees from this light (zero but for
    /// infinite lights that rays can hit).
    #[inline]
    pub fn eval_infinite(&self, d: Vec3) -> Rgb {
        match self {
            Light::Constant { radiance } => *radiance,
            Light::Envmap(map) => map.eval(d),
            _ => Rgb::ZERO,
        }
    }

    /// Radiance an area light emits at point `p` (at `at` on its shape), either side; zero
    /// for other lights.
    #[inline]
    pub fn area_radiance(&self, ctx: &LightContext, at: SurfaceRef, p: Vec3) -> Rgb {
        match self {
            Light::Area { radiance, texture: None, .. } => *radiance,
            Light::Area { texture: Some(t), .. } => textured_radiance(ctx, t, at, p),
            _ => Rgb::ZERO,
        }
    }

    /// Radiance (area lights, times the cosine) or intensity (point and spot lights) leaving a
    /// light vertex at `p` (at `at`) with normal `n` towards direction `d`; zero for lights at
    /// infinity.
    #[inline]
    pub fn emitted_towards(&self, ctx: &LightContext, at: SurfaceRef, p: Vec3, n: Vec3, d: Vec3) -> Rgb {
        match self {
            Light::Area { .. } => Self::eval_area(self.area_radiance(ctx, at, p), n, d) * n.dot(d).abs(),
            Light::Point { intensity, .. } => *intensity,
            Light::Spot(spot) => spot.emitted(d),
            Light::Constant { .. } | Light::Envmap(_) | Light::Directional { .. } => Rgb::ZERO,
        }
    }

    /// Radiance leaving an area light at a surface point with normal `n` in direction `w`.
    #[inline]
    pub fn eval_area(radiance: Rgb, n: Vec3, w: Vec3) -> Rgb {
        if n.dot(w) > 0.0 { radiance } else { Rgb::ZERO }
    }

    /// Samples a direction from `p_ref` towards the light.
    #[inline]
    pub fn sample_direct(&self, ctx: &LightContext, p_ref: Vec3, u: Vec2) -> Option<DirectSample> {
        self.sample_direct_in::<true>(ctx, p_ref, u)
    }

    /// Whether the light's emission varies over its surface (a textured area light).
    pub fn is_textured(&self) -> bool {
        matches!(self, Light::Area { texture: Some(_), .. })
    }

    /// [`Light::sample_direct`] for a light that may be textured (`TEXTURED`) or is known not to
    /// be, so that integrators can compile the untextured case without texture lookups.
    pub fn sample_direct_in<const TEXTURED: bool>(
        &self,
        ctx: &LightContext,
        p_ref: Vec3,
        u: Vec2,
    ) -> Option<DirectSample> {
        debug_assert!(TEXTURED || !self.is_textured(), "a textured light in a scene declared without textures");
        match self {
            Light::Point { position, intensity } => {
                let delta = *position - p_ref;
                let dist2 = delta.length_squared();
                let dist = dist2.sqrt();
                (dist > 0.0).then(|| DirectSample {
                    p: *position,
                    n: Vec3::ZERO,
                    wi: delta / dist,
                    dist,
                    radiance: *intensity / dist2,
                    pdf: 1.0,
                    delta: true,
                })
            }
            Light::Spot(spot) => {
                let delta = spot.position - p_ref;
                let dist2 = delta.length_squared();
                let dist = dist2.sqrt();
                (dist > 0.0).then(|| DirectSample {
                    p: spot.position,
                    n: Vec3::ZERO,
                    wi: delta / dist,
                    dist,
                    radiance: spot.emitted(-delta / dist) / dist2,
                    pdf: 1.0,
                    delta: true,
                })
            }
            Light::Constant { radiance } => {
                let wi = warp::square_to_uniform_sphere(u);
                Some(infinite_sample(ctx, p_ref, wi, *radiance, warp::uniform_sphere_pdf(), false))
            }
            Light::Envmap(map) => {
                let (wi, pdf) = map.sample(u)?;
                Some(infinite_sample(ctx, p_ref, wi, map.eval(wi), pdf, false))
            }
            Light::Directional { direction, irradiance } => {
                Some(infinite_sample(ctx, p_ref, -*direction, *irradiance, 1.0, true))
            }
            Light::Area { shape: index, texture, radiance } => {
                let shape = &ctx.shapes[*index as usize];
                let textured = TEXTURED && texture.is_some();
                let (sp, pdf) = match &shape.geometry {
                    ShapeGeometry::Sphere { center, radius }
                        if (p_ref - *center).length_squared() > radius * radius * 1.0001 =>
                    {
                        sample_sphere_cone(p_ref, *center, *radius, shape.flip_normals, u)?
                    }
                    _ => {
                        let sp = shape.sample_area(ctx.meshes, u, textured);
                        let d = sp.p - p_ref;
                        let dist2 = d.length_squared();
                        let cos = sp.n.dot(-d).abs() / dist2.sqrt();
                        if cos <= 0.0 || dist2 == 0.0 {
                            return None;
                        }
                        (sp, dist2 / (cos * shape.area))
                    }
                };
                let delta = sp.p - p_ref;
                let dist = delta.length();
                if !(dist > 0.0) || !pdf.is_finite() || pdf <= 0.0 {
                    return None;
                }
                let wi = delta / dist;
                let le = if textured {
                    self.area_radiance(ctx, SurfaceRef { shape: *index, prim: sp.prim, bary: sp.bary }, sp.p)
                } else {
                    *radiance
                };
                Some(DirectSample {
                    p: sp.p,
                    n: sp.n,
                    wi,
                    dist,
                    radiance: Self::eval_area(le, sp.n, -wi),
                    pdf,
                    delta: false,
                })
            }
        }
    }

    /// Solid-angle pdf that [`Light::sample_direct`] from `p_ref` produces the point `p` with
    /// normal `n` (for infinite lights: the direction `p - p_ref`).
    pub fn pdf_direct(&self, ctx: &LightContext, p_ref: Vec3, p: Vec3, n: Vec3) -> f32 {
        match self {
            Light::Point { .. } | Light::Spot(_) | Light::Directional { .. } => 0.0,
            Light::Constant { .. } => warp::uniform_sphere_pdf(),
            Light::Envmap(map) => map.pdf((p - p_ref).normalize_or_zero()),
            Light::Area { shape, .. } => {
                let shape = &ctx.shapes[*shape as usize];
                if let ShapeGeometry::Sphere { center, radius } = &shape.geometry {
                    let dist2 = (p_ref - *center).length_squared();
                    if dist2 > radius * radius * 1.0001 {
                        return 1.0 / (2.0 * PI * sphere_cone(dist2, *radius).0);
                    }
                }
                let d = p - p_ref;
                let dist2 = d.length_squared();
                let cos = n.dot(d).abs() / dist2.sqrt();
                if cos <= 0.0 { 0.0 } else { dist2 / (cos * shape.area) }
            }
        }
    }

    /// Samples a ray leaving the light, with `u_pos` choosing the origin and `u_dir` the direction.
    pub fn sample_emission(&self, ctx: &LightContext, u_pos: Vec2, u_dir: Vec2) -> Option<EmissionSample> {
        match self {
            Light::Point { position, intensity } => {
                let d = warp::square_to_uniform_sphere(u_dir);
                Some(EmissionSample {
                    p: *position,
                    n: Vec3::ZERO,
                    at: SurfaceRef::default(),
                    d,
                    radiance: *intensity,
                    pdf_pos: 1.0,
                    pdf_dir: warp::uniform_sphere_pdf(),
                    delta_pos: true,
                })
            }
            Light::Spot(spot) => {
                let local = warp::square_to_uniform_cone(u_dir, spot.cutoff.cos());
                let d = spot.frame.to_world(local);
                Some(EmissionSample {
                    p: spot.position,
                    n: Vec3::ZERO,
                    at: SurfaceRef::default(),
                    d,
                    radiance: spot.emitted(d),
                    pdf_pos: 1.0,
                    pdf_dir: warp::uniform_cone_pdf(spot.cutoff.cos()),
                    delta_pos: true,
                })
            }
            Light::Constant { radiance } => {
                let d = -warp::square_to_uniform_sphere(u_dir);
                Some(infinite_emission(ctx, d, *radiance, warp::uniform_sphere_pdf(), u_pos))
            }
            Light::Envmap(map) => {
                let (to_map, pdf) = map.sample(u_dir)?;
                Some(infinite_emission(ctx, -to_map, map.eval(to_map), pdf, u_pos))
            }
            Light::Directional { direction, irradiance } => {
                Some(infinite_emission(ctx, *direction, *irradiance, 1.0, u_pos))
            }
            Light::Area { shape: index, texture, .. } => {
                let shape = &ctx.shapes[*index as usize];
                let sp = shape.sample_area(ctx.meshes, u_pos, texture.is_some());
                let local = warp::square_to_cosine_hemisphere(u_dir);
                let d = Frame::from_normal(sp.n).to_world(local);
                let at = SurfaceRef { shape: *index, prim: sp.prim, bary: sp.bary };
                Some(EmissionSample {
                    p: sp.p,
                    n: sp.n,
                    at,
                    d,
                    radiance: self.area_radiance(ctx, at, sp.p),
                    pdf_pos: 1.0 / shape.area,
                    pdf_dir: local.z * INV_PI,
                    delta_pos: false,
                })
            }
        }
    }

    /// Position (area) and direction (solid angle) pdfs of emitting along `d` from a point with
    /// normal `n`; for lights at infinity `d` is the direction towards the light (the opposite
    /// of travel) and the position pdf is that of the scene's disk. A delta direction
    /// (`directional`) has pdf 1, as its emission samples report.
    pub fn pdf_emission(&self, ctx: &LightContext, n: Vec3, d: Vec3) -> (f32, f32) {
        let disk = 1.0 / (PI * ctx.radius * ctx.radius);
        match self {
            Light::Point { .. } => (0.0, warp::uniform_sphere_pdf()),
            Light::Spot(spot) => {
                let inside = spot.frame.to_local(d).z > spot.cutoff.cos();
                (0.0, if inside { warp::uniform_cone_pdf(spot.cutoff.cos()) } else { 0.0 })
            }
            Light::Constant { .. } => (disk, warp::uniform_sphere_pdf()),
            Light::Envmap(map) => (disk, map.pdf(d)),
            Light::Directional { .. } => (disk, 1.0),
            Light::Area { shape, .. } => (1.0 / ctx.shapes[*shape as usize].area, n.dot(d).max(0.0) * INV_PI),
        }
    }
}

/// A direct sample of a light at infinity seen from `p_ref` along `wi`.
fn infinite_sample(ctx: &LightContext, p_ref: Vec3, wi: Vec3, radiance: Rgb, pdf: f32, delta: bool) -> DirectSample {
    DirectSample { p: p_ref + wi * (2.0 * ctx.radius), n: -wi, wi, dist: f32::INFINITY, radiance, pdf, delta }
}

/// An emission sample of a light at infinity travelling along `d`: the origin uniform on the
/// disk of the scene's bounding sphere facing `d`.
fn infinite_emission(ctx: &LightContext, d: Vec3, radiance: Rgb, pdf_dir: f32, u_pos: Vec2) -> EmissionSample {
    let frame = Frame::from_normal(d);
    let disk = warp::square_to_disk_concentric(u_pos) * ctx.radius;
    let p = ctx.center - d * ctx.radius + frame.s * disk.x + frame.t * disk.y;
    EmissionSample {
        p,
        n: d,
        at: SurfaceRef::default(),
        d,
        radiance,
        pdf_pos: 1.0 / (PI * ctx.radius * ctx.radius),
        pdf_dir,
        delta_pos: false,
    }
}

/// Samples the cone a sphere subtends from `p_ref` uniformly and returns the point where the
/// sampled direction meets the sphere, with the solid-angle pdf (pbrt-v4's construction).
fn sample_sphere_cone(p_ref: Vec3, center: Vec3, radius: f32, flip: bool, u: Vec2) -> Option<(SurfacePoint, f32)> {
    let to_center = center - p_ref;
    let dist2 = to_center.length_squared();
    let dist = dist2.sqrt();
    let (one_minus_cos_max, sin2_max) = sphere_cone(dist2, radius);
    let sin_max = sin2_max.sqrt();
    let (cos_theta, sin2_theta) = if sin2_max < 0.000_685_23 {
        let s2 = sin2_max * u.x;
        ((1.0 - s2).sqrt(), s2)
    } else {
        let c = 1.0 - u.x * one_minus_cos_max;
        (c, (1.0 - c * c).max(0.0))
    };
    // angle at the sphere centre between -to_center and the sampled surface point
    let cos_alpha = sin2_theta / sin_max + cos_theta * safe_sqrt(1.0 - sin2_theta / sin2_max);
    let sin_alpha = safe_sqrt(1.0 - cos_alpha * cos_alpha);
    let phi = 2.0 * PI * u.y;
    let frame = Frame::from_normal(-to_center / dist);
    let n = frame.to_world(Vec3::new(sin_alpha * phi.cos(), sin_alpha * phi.sin(), cos_alpha));
    let p = center + n * radius;
    let pdf = 1.0 / (2.0 * PI * one_minus_cos_max);
    Some((SurfacePoint::analytic(p, if flip { -n } else { n }), pdf))
}

#[cfg(test)]
mod tests;
