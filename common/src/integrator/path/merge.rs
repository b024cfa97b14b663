//! Vertex merging, the technique `vcm` adds to `bdpt` (Georgiev et al. 2012, "Light transport simulation with vertex
//! connection and merging"), with SeeSharp's choices (docs/emis.md §7):
//!
//! * radius: a global maximum r_max = 0.75·√(mean pixel footprint area), measured with 5
//!   primary rays at fixed image positions (scene radius / 300 if none hits); per camera path
//!   r = min(d₁·tan 0.1°, r_max), d₁ the distance to the primary hit; constant over iterations;
//! * kernel: Epanechnikov, 2(r² − d²)/(π r⁴); photons arriving within 1e-4 of grazing are
//!   rejected; no merging at the primary camera vertex;
//! * MIS: a merge at vertex i has density p_light(i)·π r² with count N·χ_j·c_i (c_i the
//!   optional correlation-aware factor), in the same balance heuristic as every technique.

use super::gather::{Join, gather};
use super::light_cache::LightCache;
use super::light_path::next_event_density;
use super::mis::{self, SampleCounts, Technique};
use super::photon_map::PhotonMap;
use super::techniques::Report;
use super::vertex::{PathVertex, VertexKind, density_at_vertex};
use crate::bsdf::{Material, TransportMode};
use crate::integrator::observer::{SampleObserver, SampleRecord};
use crate::math::{PI, Rgb};
use crate::scene::Scene;
use glam::Vec2;
use std::sync::Arc;

/// Per-pixel merge probability χ.
#[derive(Clone, Debug, PartialEq)]
pub enum MergeMask {
    /// The same χ everywhere.
    Constant(f32),
    /// One χ per pixel (row-major).
    PerPixel(Arc<Vec<f32>>),
}

impl MergeMask {
    /// χ of `pixel`.
    #[inline]
    pub fn at(&self, pixel: u32) -> f32 {
        match self {
            MergeMask::Constant(c) => *c,
            MergeMask::PerPixel(m) => m.get(pixel as usize).copied().unwrap_or(0.0),
        }
    }

    /// Whether any pixel merges (χ > 0 somewhere).
    pub fn may_merge(&self) -> bool {
        match self {
            MergeMask::Constant(c) => *c > 0.0,
            MergeMask::PerPixel(m) => m.iter().any(|&c| c > 0.0),
        }
    }
}

/// Merging settings.
#[derive(Clone, Debug, PartialEq)]
pub struct MergeConfig {
    /// Merge probability per pixel.
    pub mask: MergeMask,
    /// Use the correlation-aware factor in the MIS weights of merges.
    pub correlation_aware: bool,
}

/// The largest merge radius of a scene: 0.75·√(mean pixel footprint) over 5 fixed primary rays.
pub fn merge_radius_max(scene: &Scene) -> f32 {
    let cam = &scene.camera;
    let pixels = (cam.width * cam.height) as f32;
    let mut sum = 0.0f32;
    let mut hits = 0;
    for (u, v) in [(0.5, 0.5), (0.25, 0.25), (0.75, 0.25), (0.25, 0.75), (0.75, 0.75)] {
        let ray = cam.generate_ray(Vec2::new(u * cam.width as f32, v * cam.height as f32));
        if let Some(hit) = scene.intersect(&ray) {
            let d = (hit.p - cam.origin).length();
            let cos = hit.n_geo.dot(ray.d).abs().max(1e-3);
            // a pixel's solid angle times d² / cos: its footprint on the surface
            let pixel_solid_angle = 1.0 / (pixels * cam.pdf_ray(ray.d).1);
            sum += pixel_solid_angle * d * d / cos;
            hits += 1;
        }
    }
    if hits == 0 { scene.bounds_radius / 300.0 } else { 0.75 * (sum / hits as f32).sqrt() }
}

/// The merge radius of a camera path whose primary hit is `d1` away.
#[inline]
pub fn path_radius(d1: f32, radius_max: f32) -> f32 {
    (d1 * (0.1f32).to_radians().tan()).min(radius_max)
}

/// Merges the camera subpath's last vertex (its material resolved, `mz`) with the photons
/// within `radius`, which happens with probability `chi`: the sum of the MIS-weighted
/// contributions, including the 1/χ, and the number of photons found within the radius.
#[allow(clippy::too_many_arguments)]
pub fn merge<O: SampleObserver>(
    scene: &Scene,
    camera: &[PathVertex],
    mz: &Material,
    cache: &LightCache,
    photons: &PhotonMap,
    radius: f32,
    chi: f32,
    counts: &SampleCounts,
    max_edges: u32,
    report: &Report<O>,
) -> (Rgb, u32) {
    // never at the primary vertex: camera = [pinhole, primary, ..., z]
    if camera.len() < 3 {
        return (Rgb::ZERO, 0);
    }
    let Some(z) = camera.last() else { return (Rgb::ZERO, 0) };
    if !matches!(z.kind, VertexKind::Surface { .. }) {
        return (Rgb::ZERO, 0);
    }
    let frame = z.frame();
    let z_wo = frame.to_local(z.wo);
    let t = camera.len();
    let n_paths = cache.paths as f32;
    let r2 = radius * radius;
    let mut total = Rgb::ZERO;
    let mut found = 0u32;
    photons.query(z.p, radius, |index, d2| {
        found += 1;
        let y = &cache.vertices[index as usize];
        if z.depth + y.depth > max_edges || z.n_geo.dot(y.wo).abs() < 1e-4 {
            return;
        }
        let wi = frame.to_local(y.wo);
        let f = mz.eval(z_wo, wi, TransportMode::Radiance);
        if f == Rgb::ZERO {
            return;
        }
        let light = cache.subpath(index as usize);
        let s = light.len() - 1; // the photon itself is replaced by z
        let infinite =
            matches!(light[0].kind, VertexKind::Light { light, .. } if scene.lights[light as usize].is_infinite());
        let join = Join {
            camera_end_from_light: y.pdf_fwd,
            camera_next_from_light: density_at_vertex(mz.pdf(wi, z_wo), z.p, &camera[t - 2], false),
            light_end_from_camera: density_at_vertex(mz.pdf(z_wo, wi), z.p, &light[s - 1], infinite && s == 1),
            light_next_from_camera: if s >= 2 { light[s - 2].pdf_rev } else { 0.0 },
            next_event0: if s >= 2 { light[1].pdf_next_event } else { next_event_density(scene, &light[0], z) },
            light_end_sampled: true,
        };
        let pdfs = gather(&light[..s], camera, &join, infinite);
        let ratios = mis::PathRatios::new(&pdfs, counts.merge.as_ref());
        let weight = mis::weight_with(&pdfs, &ratios, counts, Technique::Merge(s));
        if weight == 0.0 {
            return;
        }
        let kernel = 2.0 * (r2 - d2) / (PI * r2 * r2);
        // shading correction at the merge vertex: |ns·wi| / |ng·wi|
        let correction = wi.z.abs() / z.n_geo.dot(y.wo).abs();
        let value = z.beta * f * y.beta * (correction * kernel * weight / (n_paths * chi));
        if value != Rgb::ZERO {
            report.observe(&SampleRecord {
                technique: Technique::Merge(s),
                pixel: report.pixel,
                value,
                weight,
                kernel,
                sequence: 0,
                pdfs: &pdfs,
                ratios: &ratios,
                counts,
            });
        }
        total += value;
    });
    (total, found)
}
