//! The bidirectional techniques at one vertex: emitter hits, next-event estimation,
//! connections to a light vertex, and light tracing. Each evaluates the sample's contribution,
//! gathers the full path's densities ([`gather`]) and weighs it with [`mis`].
//!
//! Camera subpaths are in camera order (`camera[0]` is the pinhole); light subpaths in light
//! order (`light[0]` is on the light). Contributions follow Mitsuba's `path` integrand: BSDFs
//! with shading-normal cosines on camera vertices, and the adjoint shading correction on light
//! vertices, so that every technique estimates the same image.

use super::gather::{Join, gather};
use super::light_path::next_event_density;
use super::mis::{self, SampleCounts, Technique};
use super::vertex::{PathVertex, VertexKind, density_at_vertex, solid_angle_to_area};
use crate::bsdf::{Material, TransportMode};
use crate::camera::CameraSample;
use crate::geometry::{Ray, SurfaceRef, offset_ray_origin};
use crate::integrator::observer::{SampleObserver, SampleRecord};
use crate::light::Light;
use crate::math::{Rgb, SHADOW_EPSILON};
use crate::scene::Scene;
use glam::{Vec2, Vec3};
use std::borrow::Cow;
use std::cell::Cell;
use std::time::Instant;

/// Where a sample lands and who watches: the pixel, the observer and, on a timed path, the
/// clock of the observer's time.
#[derive(Clone, Copy)]
pub struct Report<'a, O: SampleObserver> {
    /// The observer.
    pub observer: &'a O,
    /// The camera path's pixel.
    pub pixel: u32,
    /// Where a timed path adds the observer's time (nanoseconds), so that the work's own
    /// time can leave it out.
    pub clock: Option<&'a Cell<u64>>,
}

impl<O: SampleObserver> Report<'_, O> {
    /// Hands `record` to the observer, timing the call on a timed path.
    #[inline(always)]
    pub fn observe(&self, record: &SampleRecord) {
        match self.clock {
            None => self.observer.on_sample(record),
            Some(clock) => {
                let start = Instant::now();
                self.observer.on_sample(record);
                clock.set(clock.get() + start.elapsed().as_nanos() as u64);
            }
        }
    }

    #[inline(always)]
    fn emit(
        &self,
        technique: Technique,
        pixel: u32,
        value: Rgb,
        weight: f32,
        (pdfs, ratios): (&mis::PathPdfs, &mis::PathRatios),
        counts: &SampleCounts,
        sequence: u32,
    ) {
        if value != Rgb::ZERO {
            self.observe(&SampleRecord {
                technique,
                pixel,
                value,
                weight,
                kernel: 1.0,
                sequence,
                pdfs,
                ratios,
                counts,
            });
        }
    }
}

/// A weighted contribution and the weight that was applied.
#[derive(Clone, Copy, Debug)]
pub struct Weighted {
    /// MIS-weighted contribution.
    pub value: Rgb,
    /// The MIS weight.
    pub weight: f32,
}

#[inline]
fn material_of<'a>(scene: &'a Scene, v: &PathVertex) -> Option<Cow<'a, Material>> {
    match v.kind {
        VertexKind::Surface { material, at } => Some(scene.material_at(material, at, v.p)),
        _ => None,
    }
}

/// Whether the segment between two vertices is unblocked.
pub fn visible(scene: &Scene, a: &PathVertex, b: &PathVertex) -> bool {
    let offset = |v: &PathVertex, d: Vec3| {
        if v.n_geo == Vec3::ZERO || v.kind == VertexKind::Camera { v.p } else { offset_ray_origin(v.p, v.n_geo, d) }
    };
    let d = b.p - a.p;
    let o = offset(a, d);
    let target = offset(b, -d);
    let delta = target - o;
    let len = delta.length();
    if len == 0.0 {
        return true;
    }
    !scene.occluded(&Ray { o, d: delta / len, tmax: len * (1.0 - SHADOW_EPSILON) })
}

/// Whether a light subpath starts on an infinite light.
#[inline]
fn path_on_infinite_light(scene: &Scene, light: &[PathVertex]) -> bool {
    matches!(light.first().map(|v| v.kind), Some(VertexKind::Light { light, .. }) if is_infinite(scene, light))
}

/// Whether light `li` is infinite.
#[inline]
fn is_infinite(scene: &Scene, li: u32) -> bool {
    scene.lights[li as usize].is_infinite()
}

/// Emission densities of a light vertex `y` (on light `li`) of emitting towards `to`:
/// (position density × selection, in `y`'s measure; density of the receiving vertex).
fn emission_densities(scene: &Scene, li: u32, y: &PathVertex, to: &PathVertex) -> (f32, f32) {
    let light = &scene.lights[li as usize];
    let ctx = scene.light_context();
    let pmf = scene.light_sampler.pmf(li as usize);
    let d = (to.p - y.p).normalize_or_zero();
    let (pdf_pos, pdf_dir) = light.pdf_emission(&ctx, y.n_geo, if light.is_infinite() { -y.n_geo } else { d });
    if light.is_infinite() {
        // position on the scene's disk, converted to area at the receiver
        (pmf * pdf_dir, if to.kind == VertexKind::Camera { 0.0 } else { pdf_pos * to.n_geo.dot(y.n_geo).abs() })
    } else {
        let pos = if light.is_delta() { pmf } else { pmf * pdf_pos };
        (pos, density_at_vertex(pdf_dir, y.p, to, false))
    }
}

/// The camera subpath ends on an emitter (or escaped to an infinite light, with `camera`'s
/// last vertex being the virtual light vertex) emitting `emitted` towards it: the weighted
/// contribution of the hit technique.
pub fn emitter_hit<O: SampleObserver>(
    scene: &Scene,
    camera: &[PathVertex],
    li: u32,
    emitted: Rgb,
    counts: &SampleCounts,
    report: &Report<O>,
) -> Rgb {
    let t = camera.len();
    let end = &camera[t - 1];
    let prev = &camera[t - 2];
    let (pos, next) = emission_densities(scene, li, end, prev);
    let at = match end.kind {
        VertexKind::Surface { at, .. } => at,
        _ => SurfaceRef::default(),
    };
    let light_vertex = PathVertex { kind: VertexKind::Light { light: li, at }, ..*end };
    let next_event0 =
        if prev.kind == VertexKind::Camera { 0.0 } else { next_event_density(scene, &light_vertex, prev) };
    let join = Join { camera_end_from_light: pos, camera_next_from_light: next, next_event0, ..Join::default() };
    let pdfs = gather(&[], camera, &join, is_infinite(scene, li));
    let ratios = mis::PathRatios::new(&pdfs, counts.merge.as_ref());
    let weight = mis::weight_with(&pdfs, &ratios, counts, Technique::EmitterHit);
    let value = camera[t - 1].beta * emitted * weight;
    report.emit(Technique::EmitterHit, report.pixel, value, weight, (&pdfs, &ratios), counts, 0);
    value
}

/// Next-event estimation from the camera subpath's last vertex, whose resolved material is
/// `material` (a textured one is resolved once per vertex, not once per technique), with
/// uniform numbers `u_light` and `u_pos`.
pub fn next_event<O: SampleObserver>(
    scene: &Scene,
    camera: &[PathVertex],
    material: &Material,
    u_light: f32,
    u_pos: Vec2,
    counts: &SampleCounts,
    report: &Report<O>,
) -> Option<Weighted> {
    let z = camera.last()?;
    let (li, pmf, _) = scene.light_sampler.sample(u_light)?;
    let light = &scene.lights[li];
    let ds = light.sample_direct(&scene.light_context(), z.p, u_pos)?;
    if ds.radiance == Rgb::ZERO {
        return None;
    }
    let frame = z.frame();
    let (wo, wi) = (frame.to_local(z.wo), frame.to_local(ds.wi));
    let f = material.eval(wo, wi, TransportMode::Radiance);
    if f == Rgb::ZERO {
        return None;
    }
    let infinite = light.is_infinite();
    let y0 = PathVertex {
        p: if infinite { z.p + ds.wi * (2.0 * scene.bounds_radius) } else { ds.p },
        n_geo: if infinite { -ds.wi } else { ds.n },
        n_shading: if infinite { -ds.wi } else { ds.n },
        tangent: Vec3::ZERO,
        wo: Vec3::ZERO,
        beta: Rgb::ONE,
        pdf_fwd: 0.0,
        pdf_rev: 0.0,
        pdf_next_event: 0.0,
        // only densities are read off this vertex, never its (possibly textured) radiance
        kind: VertexKind::Light { light: li as u32, at: SurfaceRef::default() },
        // on a light vertex: a delta light, which no camera path can hit
        delta: light.is_delta(),
        depth: 0,
    };
    let unoccluded = if infinite {
        !scene.occluded(&Ray::new(offset_ray_origin(z.p, z.n_geo, ds.wi), ds.wi))
    } else {
        visible(scene, z, &y0)
    };
    if !unoccluded {
        return None;
    }
    let (pos, next) = emission_densities(scene, li as u32, &y0, z);
    let light_vertex = PathVertex { pdf_fwd: pos, ..y0 };
    let prev = &camera[camera.len() - 2];
    let next_event0 = if light.is_delta() {
        pmf
    } else if infinite {
        pmf * ds.pdf
    } else {
        pmf * solid_angle_to_area(ds.pdf, z.p, ds.p, ds.n)
    };
    let join = Join {
        camera_end_from_light: next,
        camera_next_from_light: density_at_vertex(material.pdf(wi, wo), z.p, prev, false),
        light_end_from_camera: density_at_vertex(material.pdf(wo, wi), z.p, &light_vertex, infinite),
        light_next_from_camera: 0.0,
        next_event0,
        light_end_sampled: false,
    };
    let pdfs = gather(std::slice::from_ref(&light_vertex), camera, &join, infinite);
    let ratios = mis::PathRatios::new(&pdfs, counts.merge.as_ref());
    let weight = mis::weight_with(&pdfs, &ratios, counts, Technique::NextEvent);
    let value = z.beta * f * ds.radiance * (wi.z.abs() * weight / (pmf * ds.pdf));
    report.emit(Technique::NextEvent, report.pixel, value, weight, (&pdfs, &ratios), counts, 0);
    Some(Weighted { value, weight })
}

/// Connects the camera subpath's last vertex (its resolved material `mz`) to the light subpath
/// `light` (whose last vertex is a surface vertex). `scale` is 1 / (effective connection
/// count), c·N/|cache|.
pub fn connect<O: SampleObserver>(
    scene: &Scene,
    camera: &[PathVertex],
    mz: &Material,
    light: &[PathVertex],
    scale: f32,
    counts: &SampleCounts,
    report: &Report<O>,
) -> Option<Weighted> {
    let (z, y) = (camera.last()?, light.last()?);
    let my = material_of(scene, y)?;
    let d = y.p - z.p;
    let dist2 = d.length_squared();
    if dist2 == 0.0 {
        return None;
    }
    let dir = d / dist2.sqrt();
    let (fz, fy) = (z.frame(), y.frame());
    let (z_wo, z_wi) = (fz.to_local(z.wo), fz.to_local(dir));
    let (y_wo, y_wi) = (fy.to_local(y.wo), fy.to_local(-dir));
    let f_cam = mz.eval(z_wo, z_wi, TransportMode::Radiance);
    let f_light = my.eval(y_wo, y_wi, TransportMode::Importance);
    if f_cam == Rgb::ZERO || f_light == Rgb::ZERO {
        return None;
    }
    // shading cosine at the camera vertex; at the light vertex the geometric cosine times the
    // adjoint shading correction |ns·wo| / |ng·wo| (importance_correction × |ns·(−dir)|)
    let g = z_wi.z.abs() * y.importance_correction(y.wo, -dir) * y.n_shading.dot(dir).abs() / dist2;
    if !(g > 0.0) || !visible(scene, z, y) {
        return None;
    }
    let (s, t) = (light.len(), camera.len());
    let join = Join {
        camera_end_from_light: solid_angle_to_area(my.pdf(y_wo, y_wi), y.p, z.p, z.n_geo),
        camera_next_from_light: density_at_vertex(mz.pdf(z_wi, z_wo), z.p, &camera[t - 2], false),
        light_end_from_camera: solid_angle_to_area(mz.pdf(z_wo, z_wi), z.p, y.p, y.n_geo),
        light_next_from_camera: density_at_vertex(
            my.pdf(y_wi, y_wo),
            y.p,
            &light[s - 2],
            s == 2 && path_on_infinite_light(scene, light),
        ),
        next_event0: light[1].pdf_next_event,
        light_end_sampled: false,
    };
    let pdfs = gather(light, camera, &join, path_on_infinite_light(scene, light));
    let ratios = mis::PathRatios::new(&pdfs, counts.merge.as_ref());
    let weight = mis::weight_with(&pdfs, &ratios, counts, Technique::Connect(s));
    let value = z.beta * f_cam * f_light * y.beta * (g * weight * scale);
    report.emit(Technique::Connect(s), report.pixel, value, weight, (&pdfs, &ratios), counts, 0);
    Some(Weighted { value, weight })
}

/// Contribution of light-path vertex `v` (whose predecessor on the path is `prev`, if any)
/// seen by the camera, and the raster position it lands on. Ignores MIS.
pub fn connect_to_camera(scene: &Scene, v: &PathVertex) -> Option<(Rgb, Vec2)> {
    let cs = scene.camera.sample_direct(v.p)?;
    camera_contribution(scene, v, material_of(scene, v).as_deref(), cs)
}

/// [`connect_to_camera`] once the camera sample `cs` exists (a vertex out of view never gets
/// its material resolved), with the vertex's material (`None` off surfaces).
fn camera_contribution(
    scene: &Scene,
    v: &PathVertex,
    material: Option<&Material>,
    cs: CameraSample,
) -> Option<(Rgb, Vec2)> {
    let value = match v.kind {
        VertexKind::Light { light, at } => {
            let light = &scene.lights[light as usize];
            // a point or spot light has no area the camera could see, so Mitsuba's ptracer
            // does not connect it to the sensor: splatted, it would be one pixel's spike
            if light.is_infinite() || light.is_delta() {
                return None;
            }
            light.emitted_towards(&scene.light_context(), at, v.p, v.n_geo, cs.wi) * v.beta.x
        }
        VertexKind::Camera => return None,
        VertexKind::Surface { .. } => {
            let frame = v.frame();
            let f = material?.eval(frame.to_local(v.wo), frame.to_local(cs.wi), TransportMode::Importance);
            v.beta * f * (v.importance_correction(v.wo, cs.wi) * v.n_shading.dot(cs.wi).abs())
        }
    };
    if value == Rgb::ZERO {
        return None;
    }
    if !visible(scene, v, &camera_vertex(scene)) {
        return None;
    }
    Some((value * cs.weight, cs.raster))
}

/// Light tracing: connects the light subpath's last vertex to the camera. Returns the weighted
/// contribution, multiplied by `scale` (P/N), and the raster position. `sequence` identifies
/// the sample to observers (the light vertex's cache index).
pub fn light_trace<O: SampleObserver>(
    scene: &Scene,
    light: &[PathVertex],
    counts: &SampleCounts,
    scale: f32,
    observer: &O,
    sequence: u32,
) -> Option<(Weighted, Vec2)> {
    let y = light.last()?;
    let cs = scene.camera.sample_direct(y.p)?;
    let my = material_of(scene, y);
    let (raw, raster) = camera_contribution(scene, y, my.as_deref(), cs)?;
    let cam = &scene.camera;
    let to_camera = (cam.origin - y.p).normalize_or_zero();
    let camera_vertex = camera_vertex(scene);
    let pixels = (cam.width * cam.height) as f32;
    let s = light.len();
    let light_next_from_camera = match (s >= 2, my) {
        (true, Some(m)) => {
            let f = y.frame();
            let infinite = s == 2 && path_on_infinite_light(scene, light);
            density_at_vertex(m.pdf(f.to_local(to_camera), f.to_local(y.wo)), y.p, &light[s - 2], infinite)
        }
        _ => 0.0,
    };
    let join = Join {
        camera_end_from_light: 0.0,
        camera_next_from_light: 0.0,
        light_end_from_camera: density_at_vertex(pixels * cam.pdf_ray(-to_camera).1, cam.origin, y, false),
        light_next_from_camera,
        next_event0: if s >= 2 { light[1].pdf_next_event } else { 0.0 },
        light_end_sampled: false,
    };
    let pdfs = gather(light, std::slice::from_ref(&camera_vertex), &join, path_on_infinite_light(scene, light));
    let ratios = mis::PathRatios::new(&pdfs, counts.merge.as_ref());
    let weight = mis::weight_with(&pdfs, &ratios, counts, Technique::LightTrace);
    let value = raw * (weight * scale);
    let pixel = raster.y as u32 * cam.width + raster.x as u32;
    Report { observer, pixel, clock: None }.emit(
        Technique::LightTrace,
        pixel,
        value,
        weight,
        (&pdfs, &ratios),
        counts,
        sequence,
    );
    Some((Weighted { value, weight }, raster))
}

/// The pinhole as the first camera-path vertex.
pub fn camera_vertex(scene: &Scene) -> PathVertex {
    let cam = &scene.camera;
    PathVertex {
        p: cam.origin,
        n_geo: cam.forward,
        n_shading: cam.forward,
        tangent: Vec3::ZERO,
        wo: Vec3::ZERO,
        beta: Rgb::ONE,
        pdf_fwd: 1.0,
        pdf_rev: 0.0,
        pdf_next_event: 0.0,
        kind: VertexKind::Camera,
        delta: false,
        depth: 0,
    }
}

/// Radiance of an area light seen at surface vertex `v` of shape light `li`.
pub fn area_emission(scene: &Scene, li: u32, v: &PathVertex) -> Rgb {
    match &scene.lights[li as usize] {
        l @ Light::Area { .. } => match v.kind {
            VertexKind::Surface { at, .. } => {
                Light::eval_area(l.area_radiance(&scene.light_context(), at, v.p), v.n_shading, v.wo)
            }
            _ => Rgb::ZERO,
        },
        _ => Rgb::ZERO,
    }
}
