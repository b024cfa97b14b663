//! `pt`: unidirectional path tracing with next-event estimation, matching Mitsuba's `path`.
//!
//! Parameters (from the scene's `<integrator type="path">`, or the command line):
//! * `max_depth`: longest path in segments counting the camera ray (1 = emitters seen
//!   directly, 2 = direct lighting; unlimited when absent or -1);
//! * `rr_depth`: from this depth on, Russian roulette continues a path with probability
//!   min(max channel of throughput · η², 0.95);
//! * `hide_emitters`: camera rays pass through emitters and see no environment.
//!
//! Light sampling and BSDF sampling are combined with the power heuristic, as in Mitsuba;
//! light sampling happens only at BSDFs with a non-delta lobe, and an emitter reached right
//! after a delta bounce counts fully. Use it for anything that light reaches easily;
//! caustics and light through small openings converge slowly (bidirectional methods help).

use super::{Integrator, PathSettings, Stop, TileRequest};
use crate::bsdf::TransportMode;
use crate::film::{Rect, TileAccum};
use crate::geometry::{Ray, SurfaceInteraction};
use crate::light::Light;
use crate::math::{Rgb, max_component};
use crate::sampler::Sampler;
use crate::scene::Scene;
use glam::{Vec2, Vec3};
use std::borrow::Cow;
use std::ops::Range;

/// The path tracer.
#[derive(Clone, Debug)]
pub struct PathTracer {
    /// Depth and emitter settings.
    pub settings: PathSettings,
}

/// Power heuristic with exponent 2 for one sample from each of two strategies.
#[inline]
fn power_heuristic(pdf_a: f32, pdf_b: f32) -> f32 {
    let (a, b) = (pdf_a * pdf_a, pdf_b * pdf_b);
    let w = a / (a + b);
    if w.is_finite() { w } else { 0.0 }
}

impl PathTracer {
    /// Radiance arriving along `ray` (a camera ray).
    pub fn li(&self, scene: &Scene, ray: Ray, sampler: &mut Sampler) -> Rgb {
        if scene.is_untextured() {
            self.li_in::<false>(scene, ray, sampler)
        } else {
            self.li_in::<true>(scene, ray, sampler)
        }
    }

    /// [`PathTracer::li`] compiled for scenes that may have textures or masks (`TEXTURED`) or
    /// have none (see [`Scene::is_untextured`]), so that untextured scenes do not pay for them
    /// (`docs/decisions/0014-untextured-scenes-compile-their-own-path-tracer.md`).
    #[inline]
    fn li_in<const TEXTURED: bool>(&self, scene: &Scene, ray: Ray, sampler: &mut Sampler) -> Rgb {
        let s = self.settings;
        if s.max_depth == 0 {
            return Rgb::ZERO;
        }
        let ctx = scene.light_context();
        let mut ray = ray;
        let mut result = Rgb::ZERO;
        let mut throughput = Rgb::ONE;
        let mut eta = 1.0f32;
        let mut depth = 0u32;
        let mut prev_p = ray.o;
        let mut prev_pdf = 1.0f32;
        let mut prev_delta = true;
        let mut si = scene.intersect(&ray);
        if s.hide_emitters {
            // camera rays pass through emitting surfaces
            while let Some(hit) = si.filter(|h| scene.shapes[h.shape as usize].light.is_some()) {
                ray = hit.spawn_ray(ray.d);
                si = scene.intersect(&ray);
            }
        }
        loop {
            // ---- emission found by the previous bounce (or the camera ray) ----
            let emitted = match &si {
                None if !(s.hide_emitters && depth == 0) => {
                    self.environment(scene, ray.d, prev_p, prev_pdf, prev_delta)
                }
                None => Rgb::ZERO,
                Some(hit) => self.surface_emission::<TEXTURED>(scene, hit, prev_p, prev_pdf, prev_delta),
            };
            result += throughput * emitted;
            let Some(hit) = si else { break };
            if depth + 1 >= s.max_depth {
                break;
            }
            let material = if TEXTURED {
                scene.material_of_hit(&hit)
            } else {
                Cow::Borrowed(&scene.materials[scene.shapes[hit.shape as usize].material as usize])
            };
            let wo = hit.frame.to_local(hit.wo);

            // ---- next-event estimation ----
            if material.has_smooth_lobe() {
                let u_light = sampler.next_1d();
                let u_pos = sampler.next_2d();
                if let Some(contrib) = self.next_event::<TEXTURED>(scene, &ctx, &hit, &material, wo, u_light, u_pos) {
                    result += throughput * contrib;
                }
            }

            // ---- BSDF sampling ----
            let (uc, u) = (sampler.next_1d(), sampler.next_2d());
            let Some(bs) = material.sample_in::<TEXTURED>(wo, uc, u, TransportMode::Radiance) else { break };
            throughput *= bs.weight;
            eta *= bs.eta;
            prev_p = hit.p;
            prev_pdf = bs.pdf;
            prev_delta = bs.delta;
            ray = hit.spawn_ray(hit.frame.to_world(bs.wi));
            depth += 1;

            // ---- Russian roulette ----
            let t_max = max_component(throughput);
            if depth >= s.rr_depth {
                let q = (t_max * eta * eta).min(0.95);
                if sampler.next_1d() >= q {
                    break;
                }
                throughput /= q;
            }
            if t_max <= 0.0 || !throughput.is_finite() {
                break;
            }
            si = scene.intersect(&ray);
        }
        result
    }

    /// Environment radiance for an escaped ray, MIS-weighted against light sampling.
    fn environment(&self, scene: &Scene, d: Vec3, prev_p: Vec3, prev_pdf: f32, prev_delta: bool) -> Rgb {
        let mut total = Rgb::ZERO;
        for &i in &scene.infinite_lights {
            let light = &scene.lights[i as usize];
            let radiance = light.eval_infinite(d);
            if radiance == Rgb::ZERO {
                continue;
            }
            let w = if prev_delta {
                1.0
            } else {
                let pdf_light = scene.light_sampler.pmf(i as usize)
                    * light.pdf_direct(&scene.light_context(), prev_p, prev_p + d, -d);
                power_heuristic(prev_pdf, pdf_light)
            };
            total += radiance * w;
        }
        total
    }

    /// Radiance emitted by a surface towards the path, MIS-weighted against light sampling.
    fn surface_emission<const TEXTURED: bool>(
        &self,
        scene: &Scene,
        hit: &SurfaceInteraction,
        prev_p: Vec3,
        prev_pdf: f32,
        prev_delta: bool,
    ) -> Rgb {
        let Some(li) = scene.shapes[hit.shape as usize].light else { return Rgb::ZERO };
        let light = &scene.lights[li as usize];
        let radiance = match light {
            Light::Area { radiance, .. } if !TEXTURED => *radiance,
            _ => light.area_radiance(&scene.light_context(), hit.surface(), hit.p),
        };
        let le = Light::eval_area(radiance, hit.frame.n, hit.wo);
        if le == Rgb::ZERO {
            return le;
        }
        if prev_delta {
            return le;
        }
        let pdf_light =
            scene.light_sampler.pmf(li as usize) * light.pdf_direct(&scene.light_context(), prev_p, hit.p, hit.n_geo);
        le * power_heuristic(prev_pdf, pdf_light)
    }

    /// One light sample at `hit`: unoccluded radiance × BSDF × cosine / pdf, MIS-weighted.
    #[allow(clippy::too_many_arguments)]
    fn next_event<const TEXTURED: bool>(
        &self,
        scene: &Scene,
        ctx: &crate::light::LightContext,
        hit: &SurfaceInteraction,
        material: &crate::bsdf::Material,
        wo: Vec3,
        u_light: f32,
        u_pos: Vec2,
    ) -> Option<Rgb> {
        let (li, pmf, _) = scene.light_sampler.sample(u_light)?;
        let light = &scene.lights[li];
        let ds = light.sample_direct_in::<TEXTURED>(ctx, hit.p, u_pos)?;
        if ds.radiance == Rgb::ZERO {
            return None;
        }
        let wi = hit.frame.to_local(ds.wi);
        let f = material.eval_in::<TEXTURED>(wo, wi, TransportMode::Radiance);
        if f == Rgb::ZERO {
            return None;
        }
        let shadow = if ds.dist.is_finite() { hit.shadow_ray_to(ds.p, ds.n) } else { hit.spawn_ray(ds.wi) };
        if scene.occluded(&shadow) {
            return None;
        }
        let pdf_light = pmf * ds.pdf;
        let w = if ds.delta { 1.0 } else { power_heuristic(pdf_light, material.pdf_in::<TEXTURED>(wo, wi)) };
        Some(f * ds.radiance * (wi.z.abs() * w / pdf_light))
    }
}

impl Integrator for PathTracer {
    fn name(&self) -> &'static str {
        "pt"
    }

    fn render_tile(&self, scene: &Scene, tile: &TileRequest, accum: &mut TileAccum) {
        let runs = std::slice::from_ref(&tile.samples);
        self.render_runs(scene, tile.rect, tile.seed, runs, &tile.stop, std::slice::from_mut(accum));
    }
}

impl PathTracer {
    /// Renders `rect` for the sample ranges `runs`, run `k` into `accums[k]`: each
    /// accumulator receives the samples [`Integrator::render_tile`] would give it for its run
    /// alone, in the same order, so its sums are bit for bit the same. A pixel's samples of
    /// all runs are traced in a row, which reuses the caches its rays warmed.
    pub fn render_runs(
        &self,
        scene: &Scene,
        rect: Rect,
        seed: u64,
        runs: &[Range<u32>],
        stop: &Stop,
        accums: &mut [TileAccum],
    ) {
        assert_eq!(runs.len(), accums.len(), "invariant: one accumulator per run");
        let width = scene.camera.width;
        let untextured = scene.is_untextured();
        for y in rect.y0..rect.y1 {
            for x in rect.x0..rect.x1 {
                // per pixel: at thousands of samples per pixel a row takes seconds
                if stop.requested() {
                    return;
                }
                let pixel = y * width + x;
                for (run, accum) in runs.iter().zip(accums.iter_mut()) {
                    for s in run.clone() {
                        let mut sampler = Sampler::for_pixel(seed, pixel, s);
                        let raster = Vec2::new(x as f32, y as f32) + sampler.next_2d();
                        let ray = scene.camera.generate_ray(raster);
                        let l = if untextured {
                            self.li_in::<false>(scene, ray, &mut sampler)
                        } else {
                            self.li_in::<true>(scene, ray, &mut sampler)
                        };
                        accum.add_sample(x, y, raster, l);
                    }
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::integrator::PathSettings;
    use std::path::Path;

    fn scene(name: &str) -> Scene {
        let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("../scenes").join(name).join("scene.xml");
        Scene::load(&path).expect("scene loads")
    }

    /// The untextured specialisation is an optimisation only: on an untextured scene it gives
    /// the same radiance, bit for bit, as the general code; scenes with textures, masks or
    /// textured emitters are never given it.
    #[test]
    fn untextured_path_equals_the_general_one() {
        for (name, untextured) in
            [("cornell-box", true), ("env-lit", true), ("masked-leaves", false), ("textured-emitters", false)]
        {
            assert_eq!(scene(name).is_untextured(), untextured, "{name}");
        }
        let scene = scene("env-lit");
        let pt = PathTracer { settings: PathSettings::from_scene(&scene, None) };
        let (w, h) = (scene.camera.width, scene.camera.height);
        let mut nonzero = 0;
        for pixel in (0..w * h).step_by(97) {
            for s in 0..4 {
                let raster = Vec2::new((pixel % w) as f32 + 0.5, (pixel / w) as f32 + 0.5);
                let ray = scene.camera.generate_ray(raster);
                let a = pt.li_in::<false>(&scene, ray, &mut Sampler::for_pixel(7, pixel, s));
                let b = pt.li_in::<true>(&scene, ray, &mut Sampler::for_pixel(7, pixel, s));
                assert_eq!(a.to_array().map(f32::to_bits), b.to_array().map(f32::to_bits), "pixel {pixel} sample {s}");
                nonzero += usize::from(a != Rgb::ZERO);
            }
        }
        assert!(nonzero > 100, "the comparison saw light: {nonzero}");
    }
}
