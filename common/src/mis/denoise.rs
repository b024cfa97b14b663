//! DENOISEIMAGE (emis-spec §5 and checklist §10, decision 7): the pilot image Ī the relative
//! moments are normalised by. Intel OIDN is not installable here, so this is an edge-avoiding
//! à-trous wavelet filter (Dammertz et al. 2010) guided by the pilot's albedo, normal and depth
//! AOVs, on the albedo-demodulated image, followed by the reference's channel mean and radius-3
//! box. Colour is not an edge-stopping guide: at one sample per pixel it is mostly noise.
//!
//! Edge stopping between pixels p and q at step s: normals max(0, n_p·n_q)^σn; albedo
//! exp(−|a_p − a_q|₁/σa); depth exp(−|z_p − z_q| / (σz·|∇z_p|·s·|offset| + ε)) as in SVGF, so
//! slanted planes stay connected while depth edges cut. Escaped pixels only mix with each
//! other.

use super::filter::Image;
use rayon::prelude::*;

/// The filter's parameters.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct DenoiseSettings {
    /// À-trous levels (steps 1, 2, 4, …).
    pub levels: u32,
    /// Exponent of the normal weight.
    pub normal_power: i32,
    /// Albedo difference scale.
    pub albedo_sigma: f32,
    /// Depth-gradient scale.
    pub depth_sigma: f32,
    /// Box passes on the channel mean afterwards (the reference's radius 3).
    pub final_box: usize,
}

impl Default for DenoiseSettings {
    fn default() -> Self {
        DenoiseSettings { levels: 5, normal_power: 64, albedo_sigma: 0.2, depth_sigma: 1.0, final_box: 3 }
    }
}

/// Per-pixel guides (means over the pilot).
pub struct Guides<'a> {
    /// Albedo.
    pub albedo: &'a [[f32; 3]],
    /// Unit shading normal, zero where the camera ray escaped.
    pub normal: &'a [[f32; 3]],
    /// Distance to the primary hit.
    pub depth: &'a [f32],
}

const B3: [f32; 5] = [1.0 / 16.0, 1.0 / 4.0, 3.0 / 8.0, 1.0 / 4.0, 1.0 / 16.0];

/// Denoises a `width × height` RGB image.
pub fn denoise(width: usize, height: usize, color: &[[f32; 3]], guides: &Guides, s: &DenoiseSettings) -> Vec<[f32; 3]> {
    let n = width * height;
    assert!(
        color.len() == n && guides.albedo.len() == n && guides.normal.len() == n && guides.depth.len() == n,
        "invariant: image and guides have width × height pixels"
    );
    let modulation: Vec<[f32; 3]> = guides.albedo.iter().map(|a| a.map(|c| c.max(1e-3))).collect();
    let mut current: Vec<[f32; 3]> =
        color.iter().zip(&modulation).map(|(c, a)| [c[0] / a[0], c[1] / a[1], c[2] / a[2]]).collect();
    let mut next = vec![[0.0f32; 3]; n];
    let gradient = depth_gradient(width, height, guides);
    for level in 0..s.levels {
        let pass = Pass { width, height, step: 1 << level, guides, gradient: &gradient, settings: s };
        next.par_chunks_mut(width).enumerate().for_each(|(y, row)| {
            for (x, out) in row.iter_mut().enumerate() {
                *out = pass.filter_pixel(x, y, &current);
            }
        });
        std::mem::swap(&mut current, &mut next);
    }
    current.iter().zip(&modulation).map(|(c, a)| [c[0] * a[0], c[1] * a[1], c[2] * a[2]]).collect()
}

/// The scalar Ī of the optimiser: the denoised image's channel mean, box-filtered.
pub fn denoised_intensity(
    width: usize,
    height: usize,
    color: &[[f32; 3]],
    guides: &Guides,
    s: &DenoiseSettings,
) -> Image {
    let d = denoise(width, height, color, guides, s);
    Image::from_data(width, height, d.iter().map(|c| (c[0] + c[1] + c[2]) / 3.0).collect()).box_blur(s.final_box)
}

/// |∇z| per pixel by central differences within the same surface class.
fn depth_gradient(width: usize, height: usize, g: &Guides) -> Vec<f32> {
    let at = |x: usize, y: usize| g.depth[y * width + x];
    (0..height)
        .flat_map(|y| (0..width).map(move |x| (x, y)))
        .map(|(x, y)| {
            let dx = (at((x + 1).min(width - 1), y) - at(x.saturating_sub(1), y)).abs() * 0.5;
            let dy = (at(x, (y + 1).min(height - 1)) - at(x, y.saturating_sub(1))).abs() * 0.5;
            dx.max(dy)
        })
        .collect()
}

/// One à-trous level: what every pixel's filter at this step reads.
struct Pass<'a> {
    width: usize,
    height: usize,
    step: usize,
    guides: &'a Guides<'a>,
    gradient: &'a [f32],
    settings: &'a DenoiseSettings,
}

impl Pass<'_> {
    #[inline]
    fn filter_pixel(&self, x: usize, y: usize, img: &[[f32; 3]]) -> [f32; 3] {
        let (g, s, step) = (self.guides, self.settings, self.step);
        let p = y * self.width + x;
        let (np, ap, zp) = (g.normal[p], g.albedo[p], g.depth[p]);
        let escaped_p = np == [0.0; 3];
        // the depth term's denominator is σz·|∇z_p|·step·|offset| + ε: its per-pixel parts
        // once here, |offset| per tap below
        let depth_scale = s.depth_sigma * self.gradient[p] * step as f32;
        let depth_epsilon = 1e-4 * zp.max(1e-3);
        let inv_albedo_sigma = 1.0 / s.albedo_sigma;
        let (mut sum, mut wsum) = ([0.0f32; 3], 0.0f32);
        for (j, ky) in B3.iter().enumerate() {
            let Some(yy) = (y + 2 * step).checked_sub((4 - j) * step).filter(|&yy| yy < self.height) else {
                continue;
            };
            for (i, kx) in B3.iter().enumerate() {
                let Some(xx) = (x + 2 * step).checked_sub((4 - i) * step).filter(|&xx| xx < self.width) else {
                    continue;
                };
                let q = yy * self.width + xx;
                let nq = g.normal[q];
                let w = if escaped_p || nq == [0.0; 3] {
                    if escaped_p && nq == [0.0; 3] { 1.0 } else { 0.0 }
                } else {
                    let dot = np[0] * nq[0] + np[1] * nq[1] + np[2] * nq[2];
                    if dot <= 0.0 {
                        0.0
                    } else {
                        let aq = g.albedo[q];
                        let da = (ap[0] - aq[0]).abs() + (ap[1] - aq[1]).abs() + (ap[2] - aq[2]).abs();
                        let dz = (zp - g.depth[q]).abs() / (depth_scale * TAP_DISTANCE[j][i] + depth_epsilon);
                        power(dot, s.normal_power) * (-(da * inv_albedo_sigma + dz)).exp()
                    }
                };
                let k = kx * ky * w;
                if k > 0.0 {
                    let c = img[q];
                    sum = [sum[0] + k * c[0], sum[1] + k * c[1], sum[2] + k * c[2]];
                    wsum += k;
                }
            }
        }
        if wsum > 0.0 { sum.map(|v| v / wsum) } else { img[p] }
    }
}

/// |offset| of tap (i, j) in units of the step.
const TAP_DISTANCE: [[f32; 5]; 5] = {
    let mut d = [[0.0f32; 5]; 5];
    let mut j = 0;
    while j < 5 {
        let mut i = 0;
        while i < 5 {
            let (dx, dy) = (i as i32 - 2, j as i32 - 2);
            // the distances that occur: 0, 1, √2, 2, √5, √8
            d[j][i] = match dx * dx + dy * dy {
                0 => 0.0,
                1 => 1.0,
                2 => std::f32::consts::SQRT_2,
                4 => 2.0,
                5 => 2.236_068,
                _ => 2.0 * std::f32::consts::SQRT_2,
            };
            i += 1;
        }
        j += 1;
    }
    d
};

/// x^n for n ≥ 0 by squaring, inline: `powi` with an exponent known only at run time is a
/// library call per tap, the denoiser's largest single cost.
#[inline]
fn power(mut x: f32, mut n: i32) -> f32 {
    let mut result = 1.0;
    while n > 0 {
        if n & 1 == 1 {
            result *= x;
        }
        x *= x;
        n >>= 1;
    }
    result
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sampler::Sampler;

    /// Two flat regions (different normals) with noise: the filter removes most of the noise
    /// and does not blur across the edge.
    #[test]
    fn removes_noise_and_keeps_edges() {
        let (w, h) = (64usize, 64usize);
        let mut color = vec![[0.0f32; 3]; w * h];
        let mut normal = vec![[0.0f32; 3]; w * h];
        let albedo = vec![[0.5f32; 3]; w * h];
        let depth = vec![1.0f32; w * h];
        let truth = |x: usize| if x < 32 { 1.0f32 } else { 4.0 };
        for y in 0..h {
            for x in 0..w {
                let mut s = Sampler::for_pixel(3, (y * w + x) as u32, 0);
                // exponential noise with the right mean: a 1-spp-like image
                let v = -truth(x) * (1.0 - s.next_1d()).ln();
                color[y * w + x] = [v; 3];
                normal[y * w + x] = if x < 32 { [0.0, 0.0, 1.0] } else { [1.0, 0.0, 0.0] };
            }
        }
        let g = Guides { albedo: &albedo, normal: &normal, depth: &depth };
        let out = denoise(w, h, &color, &g, &DenoiseSettings::default());
        let rms = |img: &[[f32; 3]]| {
            let e: f32 = (0..w * h).map(|i| (img[i][0] - truth(i % w)).powi(2) / truth(i % w).powi(2)).sum();
            (e / (w * h) as f32).sqrt()
        };
        assert!(rms(&out) < 0.15 * rms(&color), "noise: {} → {}", rms(&color), rms(&out));
        // the columns next to the edge keep their own level
        let col = |x: usize| (0..h).map(|y| out[y * w + x][0]).sum::<f32>() / h as f32;
        assert!((col(31) - 1.0).abs() < 0.2 && (col(32) - 4.0).abs() < 0.8, "edge: {} | {}", col(31), col(32));
    }
}
