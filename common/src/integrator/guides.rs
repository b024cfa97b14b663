//! Denoiser guides (emis-spec §5, decision 7): per pixel, the albedo and shading normal at the
//! primary hit and its distance, averaged over the pilot iterations. Albedo is a one-sample
//! estimate of the directional albedo (the weight of one BSDF sample), which works for every
//! material, delta lobes included. Sums with a sample count, so buffers from workers add up.

use crate::bsdf::TransportMode;
use crate::math::Rgb;
use crate::sampler::Sampler;
use crate::scene::Scene;
use glam::Vec2;
use rayon::prelude::*;
use std::ops::Range;

/// Guide sums of a full frame.
#[derive(Clone, Debug, PartialEq)]
pub struct GuideBuffer {
    /// Width.
    pub width: u32,
    /// Height.
    pub height: u32,
    /// Σ albedo per pixel.
    pub albedo: Vec<[f32; 3]>,
    /// Σ world-space shading normal per pixel (zero where the ray escaped).
    pub normal: Vec<[f32; 3]>,
    /// Σ distance to the primary hit (0 where the ray escaped).
    pub depth: Vec<f32>,
    /// Samples per pixel summed.
    pub samples: u32,
}

impl GuideBuffer {
    /// Empty sums.
    pub fn new(width: u32, height: u32) -> Self {
        let n = (width * height) as usize;
        GuideBuffer {
            width,
            height,
            albedo: vec![[0.0; 3]; n],
            normal: vec![[0.0; 3]; n],
            depth: vec![0.0; n],
            samples: 0,
        }
    }

    /// Renders one guide sample per pixel for each iteration in `iterations`.
    pub fn render(scene: &Scene, seed: u64, iterations: Range<u32>) -> Self {
        let (w, h) = (scene.camera.width, scene.camera.height);
        let mut out = GuideBuffer::new(w, h);
        let rows: Vec<Vec<([f32; 3], [f32; 3], f32)>> = (0..h)
            .into_par_iter()
            .map(|y| (0..w).map(|x| pixel_guides(scene, seed, y * w + x, x, y, iterations.clone())).collect())
            .collect();
        for (i, (a, n, d)) in rows.into_iter().flatten().enumerate() {
            out.albedo[i] = a;
            out.normal[i] = n;
            out.depth[i] = d;
        }
        out.samples = iterations.len() as u32;
        out
    }

    /// Adds another buffer of the same size.
    pub fn merge(&mut self, o: &GuideBuffer) -> Result<(), String> {
        if (self.width, self.height) != (o.width, o.height) {
            return Err(format!(
                "guide buffers differ in size: {}x{} vs {}x{}",
                self.width, self.height, o.width, o.height
            ));
        }
        for (a, b) in self.albedo.iter_mut().zip(&o.albedo) {
            *a = [a[0] + b[0], a[1] + b[1], a[2] + b[2]];
        }
        for (a, b) in self.normal.iter_mut().zip(&o.normal) {
            *a = [a[0] + b[0], a[1] + b[1], a[2] + b[2]];
        }
        for (a, b) in self.depth.iter_mut().zip(&o.depth) {
            *a += b;
        }
        self.samples += o.samples;
        Ok(())
    }

    /// Per-pixel means: (albedo, unit normal or zero, depth).
    pub fn means(&self) -> (Vec<[f32; 3]>, Vec<[f32; 3]>, Vec<f32>) {
        let k = self.samples.max(1) as f32;
        let albedo = self.albedo.iter().map(|a| [a[0] / k, a[1] / k, a[2] / k]).collect();
        let normal = self
            .normal
            .iter()
            .map(|n| {
                let v = glam::Vec3::from_array(*n).normalize_or_zero();
                v.to_array()
            })
            .collect();
        let depth = self.depth.iter().map(|d| d / k).collect();
        (albedo, normal, depth)
    }
}

fn pixel_guides(
    scene: &Scene,
    seed: u64,
    pixel: u32,
    x: u32,
    y: u32,
    iterations: Range<u32>,
) -> ([f32; 3], [f32; 3], f32) {
    let (mut albedo, mut normal, mut depth) = (Rgb::ZERO, glam::Vec3::ZERO, 0.0f32);
    for it in iterations {
        let mut s = Sampler::for_guide(seed, pixel, it);
        let ray = scene.camera.generate_ray(Vec2::new(x as f32, y as f32) + s.next_2d());
        let Some(hit) = scene.intersect(&ray) else { continue };
        let material = &scene.materials[scene.shapes[hit.shape as usize].material as usize];
        let wo = hit.frame.to_local(hit.wo);
        let (uc, u) = (s.next_1d(), s.next_2d());
        if let Some(bs) = material.sample(wo, uc, u, TransportMode::Radiance) {
            if bs.weight.is_finite() {
                albedo += bs.weight;
            }
        }
        normal += hit.frame.n;
        depth += hit.t;
    }
    (albedo.to_array(), normal.to_array(), depth)
}
