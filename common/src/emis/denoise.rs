//! DENOISEIMAGE (docs/emis.md §5.4, D7 and checklist 10): the pilot image Ī the
//! relative moments are normalised by. Intel OIDN is not installable here, so this is an
//! edge-avoiding à-trous wavelet filter (Dammertz et al. 2010) guided by the pilot's albedo,
//! normal and depth AOVs, on the albedo-demodulated image, followed by the reference's channel
//! mean and radius-3 box. Colour is not an edge-stopping guide: at one sample per pixel it is
//! mostly noise.
//!
//! The default runs no level: Ī is then the pilot image's channel mean and box, which the
//! decisions agree with better (decision 0028). Where the filter runs, it runs on 2 × 2
//! blocks ([`super::halve`]; decision 0042).
//!
//! Edge stopping between pixels p and q at step s: normals max(0, n_p·n_q)^σn; albedo
//! exp(−|a_p − a_q|₁/σa); depth exp(−|z_p − z_q| / (σz·|∇z_p|·s·|offset| + ε)) as in SVGF, so
//! slanted planes stay connected while depth edges cut. Escaped pixels only mix with each
//! other.

use super::filter::Image;
pub use super::guides::Guides;
use super::halve::Halved;
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

/// Where Ī comes from (decision 0028).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize, Default)]
#[serde(rename_all = "kebab-case")]
#[cfg_attr(feature = "clap", derive(clap::ValueEnum))]
pub enum ImageEstimate {
    /// The pilot image's channel mean and box, not denoised. A path-tracing start's updates
    /// still use the guided filter ([`super::render::EmisConfig::start_denoise`]).
    #[default]
    #[cfg_attr(feature = "clap", value(help = "The pilot image, not denoised: its channel mean and radius-3 box"))]
    Pilot,
    /// The pilot image through the guided à-trous filter first (docs/emis.md, D7), on 2 × 2 blocks
    /// ([`DenoiseSettings::GUIDED_HALF`]).
    #[cfg_attr(
        feature = "clap",
        value(help = "The pilot image denoised by the guided filter (albedo, normal and depth guides) first")
    )]
    Guided,
}

impl ImageEstimate {
    /// The filter settings of this estimate.
    pub fn settings(self) -> DenoiseSettings {
        match self {
            ImageEstimate::Pilot => DenoiseSettings::default(),
            ImageEstimate::Guided => DenoiseSettings::GUIDED_HALF,
        }
    }
}

/// The filter's parameters.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct DenoiseSettings {
    /// À-trous levels (steps 1, 2, 4, …). With none, Ī is the pilot image's channel mean and
    /// box alone: the default, because the guided filter spreads small lights and caustics
    /// into their surroundings and misleads the optimiser (decision 0028).
    pub levels: u32,
    /// Exponent of the normal weight.
    pub normal_power: i32,
    /// Albedo difference scale.
    pub albedo_sigma: f32,
    /// Depth-gradient scale.
    pub depth_sigma: f32,
    /// Box passes on the channel mean afterwards (the reference's radius 3).
    pub final_box: usize,
    /// Run the levels on 2 × 2 blocks ([`super::halve`]) and modulate by each pixel's own
    /// albedo: a quarter of the pixels, with the first level's footprint in the blocks.
    pub half_resolution: bool,
}

impl DenoiseSettings {
    /// The guided à-trous filter of docs/emis.md, D7, five levels.
    pub const GUIDED: DenoiseSettings = DenoiseSettings {
        levels: 5,
        normal_power: 64,
        albedo_sigma: 0.2,
        depth_sigma: 1.0,
        final_box: 3,
        half_resolution: false,
    };

    /// The guided filter on 2 × 2 blocks: four levels there reach as far as five at full
    /// resolution, at a fifth of the cost (docs/decisions/0042-guided-filter-at-half-resolution.md).
    pub const GUIDED_HALF: DenoiseSettings = DenoiseSettings { levels: 4, half_resolution: true, ..Self::GUIDED };
}

impl Default for DenoiseSettings {
    fn default() -> Self {
        DenoiseSettings { levels: 0, ..Self::GUIDED }
    }
}

const B3: [f32; 5] = [1.0 / 16.0, 1.0 / 4.0, 3.0 / 8.0, 1.0 / 4.0, 1.0 / 16.0];

/// Denoises a `width × height` RGB image.
pub fn denoise(width: usize, height: usize, color: &[[f32; 3]], guides: &Guides, s: &DenoiseSettings) -> Vec<[f32; 3]> {
    filtered(width, height, color, guides, s, |planes, modulation| {
        (0..width * height)
            .into_par_iter()
            .map(|p| std::array::from_fn(|c| planes[c][p] * modulation[c][p].max(1e-3)))
            .collect()
    })
}

/// The scalar Ī of the optimiser: the denoised image's channel mean, box-filtered.
pub fn denoised_intensity(
    width: usize,
    height: usize,
    color: &[[f32; 3]],
    guides: &Guides,
    s: &DenoiseSettings,
) -> Image {
    if s.levels == 0 {
        let mean = color.iter().map(|[r, g, b]| (r + g + b) / 3.0).collect();
        return Image::from_data(width, height, mean).box_blur(s.final_box);
    }
    if s.half_resolution {
        let half = Halved::new(width, height, color, guides.albedo, guides.normal, guides.depth);
        let half_guides = Guides { albedo: &half.albedo, normal: &half.normal, depth: &half.depth };
        let mean = filtered(half.width, half.height, &half.color, &half_guides, s, |planes, _| {
            half.upsampled_mean(width, guides, planes, s.normal_power)
        });
        return Image::from_data(width, height, mean).box_blur(s.final_box);
    }
    let mean = filtered(width, height, color, guides, s, |planes, modulation| {
        (0..width * height)
            .into_par_iter()
            .map(|p| {
                let [r, g, b]: [f32; 3] = std::array::from_fn(|c| planes[c][p] * modulation[c][p].max(1e-3));
                (r + g + b) / 3.0
            })
            .collect()
    });
    Image::from_data(width, height, mean).box_blur(s.final_box)
}

/// Planes of the guides and of the image at each level, one allocation for all.
const ARENA_PLANES: usize = 3 + 3 + 1 + 1 + 3 + 3;

/// Runs the filter's levels on the albedo-demodulated image and hands `finish` the result's
/// planes and the albedo planes (to modulate with, clamped to 1e-3 as they were divided by).
/// Every buffer is a part of one allocation, which the allocator always maps afresh and
/// returns when dropped, whatever the process allocated before
/// (docs/decisions/0021-optimiser-at-1080p.md).
fn filtered<R>(
    width: usize,
    height: usize,
    color: &[[f32; 3]],
    guides: &Guides,
    s: &DenoiseSettings,
    finish: impl FnOnce([&[f32]; 3], [&[f32]; 3]) -> R,
) -> R {
    let n = width * height;
    assert!(
        color.len() == n && guides.albedo.len() == n && guides.normal.len() == n && guides.depth.len() == n,
        "invariant: image and guides have width × height pixels"
    );
    let mut arena = vec![0.0f32; ARENA_PLANES * n];
    let mut parts = arena.chunks_mut(n.max(1));
    let mut take = || parts.next().unwrap_or_default();
    let guide_parts: [&mut [f32]; 8] = std::array::from_fn(|_| take());
    let mut current: [&mut [f32]; 3] = std::array::from_fn(|_| take());
    let mut next: [&mut [f32]; 3] = std::array::from_fn(|_| take());
    let planes = Planes::new(width, height, guides, guide_parts);
    for (c, plane) in current.iter_mut().enumerate() {
        plane.par_iter_mut().zip(color).zip(guides.albedo).for_each(|((o, v), a)| *o = v[c] / a[c].max(1e-3));
    }
    for level in 0..s.levels {
        let pass = Pass { planes: &planes, step: 1 << level, settings: s };
        let img: [&[f32]; 3] = current.each_ref().map(|v| &**v);
        let [r, g, b] = &mut next;
        r.par_chunks_mut(width).zip(g.par_chunks_mut(width)).zip(b.par_chunks_mut(width)).enumerate().for_each_init(
            || Scratch::new(width),
            |scratch, (y, ((r, g), b))| pass.filter_row(y, &img, [r, g, b], scratch),
        );
        std::mem::swap(&mut current, &mut next);
    }
    finish(current.each_ref().map(|v| &**v), planes.albedo)
}

/// The guides as planes, one value per pixel each, so that a tap's loop over a row reads
/// contiguous memory and compiles to vector code.
struct Planes<'a> {
    width: usize,
    height: usize,
    normal: [&'a [f32]; 3],
    albedo: [&'a [f32]; 3],
    depth: &'a [f32],
    /// |∇z| by central differences.
    gradient: &'a [f32],
    /// 1 where the camera ray escaped (zero normal), else 0.
    escaped: &'a [f32],
}

impl<'a> Planes<'a> {
    /// The guides' planes, written into `parts` (normal, albedo, gradient, escaped).
    fn new(width: usize, height: usize, g: &Guides<'a>, parts: [&'a mut [f32]; 8]) -> Self {
        let [n0, n1, n2, a0, a1, a2, gradient, escaped] = parts;
        let at = |x: usize, y: usize| g.depth[y * width + x];
        gradient.par_iter_mut().enumerate().for_each(|(p, out)| {
            let (x, y) = (p % width, p / width);
            let dx = (at((x + 1).min(width - 1), y) - at(x.saturating_sub(1), y)).abs() * 0.5;
            let dy = (at(x, (y + 1).min(height - 1)) - at(x, y.saturating_sub(1))).abs() * 0.5;
            *out = dx.max(dy);
        });
        let normal = [n0, n1, n2];
        let albedo = [a0, a1, a2];
        for c in 0..3 {
            normal[c].par_iter_mut().zip(g.normal).for_each(|(o, v)| *o = v[c]);
            albedo[c].par_iter_mut().zip(g.albedo).for_each(|(o, v)| *o = v[c]);
        }
        escaped.par_iter_mut().zip(g.normal).for_each(|(o, &v)| *o = (v == [0.0; 3]) as u8 as f32);
        Planes {
            width,
            height,
            normal: normal.map(|v| &*v),
            albedo: albedo.map(|v| &*v),
            depth: g.depth,
            gradient,
            escaped,
        }
    }
}

/// Per-thread row buffers.
struct Scratch {
    sum: [Vec<f32>; 3],
    weight_sum: Vec<f32>,
    cosine: Vec<f32>,
    exponent: Vec<f32>,
    weight: Vec<f32>,
}

impl Scratch {
    fn new(width: usize) -> Self {
        Scratch {
            sum: std::array::from_fn(|_| vec![0.0; width]),
            weight_sum: vec![0.0; width],
            cosine: vec![0.0; width],
            exponent: vec![0.0; width],
            weight: vec![0.0; width],
        }
    }
}

/// One à-trous level.
struct Pass<'a> {
    planes: &'a Planes<'a>,
    step: usize,
    settings: &'a DenoiseSettings,
}

impl<'a> Pass<'a> {
    /// Filters row `y` of `img` into `out`: per tap, the edge-stopping weights of the whole
    /// row, then their products with the kernel summed per pixel (in the same tap order for
    /// every pixel, so the result does not depend on how rows are split among threads).
    fn filter_row(&self, y: usize, img: &[&[f32]; 3], out: [&mut [f32]; 3], scratch: &mut Scratch) {
        let (g, s, step) = (self.planes, self.settings, self.step);
        let width = g.width;
        let inv_albedo_sigma = 1.0 / s.albedo_sigma;
        for v in scratch.sum.iter_mut().chain([&mut scratch.weight_sum]) {
            v.fill(0.0);
        }
        for (j, ky) in B3.iter().enumerate() {
            let Some(yy) = (y + 2 * step).checked_sub((4 - j) * step).filter(|&yy| yy < g.height) else {
                continue;
            };
            for (i, kx) in B3.iter().enumerate() {
                // pixels x of this row whose tap x + dx lies inside the image
                let dx = (i as isize - 2) * step as isize;
                let (x0, x1) = ((-dx).max(0) as usize, (width as isize - dx).clamp(0, width as isize) as usize);
                if x0 >= x1 {
                    continue;
                }
                let len = x1 - x0;
                let p = y * width + x0..y * width + x1;
                let q0 = (yy * width + x0).wrapping_add_signed(dx);
                let q = q0..q0 + len;
                let depth_scale = s.depth_sigma * step as f32 * TAP_DISTANCE[j][i];
                let (cosine, exponent, weight) =
                    (&mut scratch.cosine[..len], &mut scratch.exponent[..len], &mut scratch.weight[..len]);
                {
                    // every slice exactly `len` long, so the loop needs no bounds checks and
                    // compiles to vector code
                    let at_p = |v: &'a [f32]| &v[p.start..][..len];
                    let at_q = |v: &'a [f32]| &v[q.start..][..len];
                    let (zp, zq, grad) = (at_p(g.depth), at_q(g.depth), at_p(g.gradient));
                    let np = g.normal.each_ref().map(|v| at_p(v));
                    let nq = g.normal.each_ref().map(|v| at_q(v));
                    let ap = g.albedo.each_ref().map(|v| at_p(v));
                    let aq = g.albedo.each_ref().map(|v| at_q(v));
                    for x in 0..len {
                        let dot = np[0][x] * nq[0][x] + np[1][x] * nq[1][x] + np[2][x] * nq[2][x];
                        let da =
                            (ap[0][x] - aq[0][x]).abs() + (ap[1][x] - aq[1][x]).abs() + (ap[2][x] - aq[2][x]).abs();
                        let dz = (zp[x] - zq[x]).abs() / (depth_scale * grad[x] + 1e-4 * zp[x].max(1e-3));
                        cosine[x] = dot.max(0.0);
                        // a normal at 90° or more cuts the tap whatever the power
                        exponent[x] = if dot > 0.0 { -(da * inv_albedo_sigma + dz) } else { f32::NEG_INFINITY };
                    }
                }
                power(cosine, s.normal_power, weight);
                let (ep, eq) = (&g.escaped[p.clone()][..len], &g.escaped[q.clone()][..len]);
                for (w, &e) in weight.iter_mut().zip(exponent.iter()) {
                    *w *= exp_nonpositive(e);
                }
                let kernel = kx * ky;
                let c = img.each_ref().map(|v| &v[q.clone()][..len]);
                let [sr, sg, sb] = &mut scratch.sum;
                let (sr, sg, sb) = (&mut sr[x0..x1][..len], &mut sg[x0..x1][..len], &mut sb[x0..x1][..len]);
                let sw = &mut scratch.weight_sum[x0..x1][..len];
                for x in 0..len {
                    // escaped pixels mix with escaped pixels only
                    let w = blend(ep[x] + eq[x] > 0.0, ep[x] * eq[x], weight[x]);
                    let k = kernel * w;
                    let add = k > 0.0;
                    sr[x] = blend(add, sr[x] + k * c[0][x], sr[x]);
                    sg[x] = blend(add, sg[x] + k * c[1][x], sg[x]);
                    sb[x] = blend(add, sb[x] + k * c[2][x], sb[x]);
                    sw[x] = blend(add, sw[x] + k, sw[x]);
                }
            }
        }
        let [or, og, ob] = out;
        let row = y * width..(y + 1) * width;
        let own = [&img[0][row.clone()], &img[1][row.clone()], &img[2][row]];
        for x in 0..width {
            let w = scratch.weight_sum[x];
            let [r, g, b] = if w > 0.0 { scratch.sum.each_ref().map(|s| s[x] / w) } else { own.map(|c| c[x]) };
            (or[x], og[x], ob[x]) = (r, g, b);
        }
    }
}

/// `a` where `pick`, else `b`, by bit masks: a branch-free select that keeps the loops it is
/// in vector code (an `if` there becomes a branch per pixel).
#[inline(always)]
fn blend(pick: bool, a: f32, b: f32) -> f32 {
    let mask = 0u32.wrapping_sub(pick as u32);
    f32::from_bits((a.to_bits() & mask) | (b.to_bits() & !mask))
}

/// e^x for x ≤ 0 (larger x count as 0; NaN stays NaN) in arithmetic alone, so that the loop
/// over a row's taps compiles to vector code (`f32::exp` is a library call per value;
/// docs/decisions/0021-optimiser-at-1080p.md). Relative error below 2e-7·(1 + |x|), far
/// inside the weights' purpose, and the same on every host, as it does not depend on the C
/// library's `expf`.
#[inline(always)]
fn exp_nonpositive(x: f32) -> f32 {
    // e^x = 2^n · e^(r·ln 2), n the nearest integer to x·log2(e), |r| ≤ ½; `max` sends NaN to
    // −126 (restored below), so every lane stays finite
    #[allow(clippy::manual_clamp)] // `clamp` keeps NaN, which the integer step must not see
    let t = (x * std::f32::consts::LOG2_E).max(-126.0).min(0.0);
    // adding 1.5·2^23 rounds t to an integer held in the low mantissa bits: exact and
    // branch-free, where `as i32` would saturate lane by lane in scalar code
    const ROUND: f32 = 12_582_912.0;
    let k = t + ROUND;
    let n = k - ROUND;
    let f = (t - n) * std::f32::consts::LN_2;
    // Taylor to degree 6: the remainder at |f| ≤ ln 2 / 2 is below 1.2e-7
    let p = 1.0 + f * (1.0 + f * (0.5 + f * (1.0 / 6.0 + f * (1.0 / 24.0 + f * (1.0 / 120.0 + f * (1.0 / 720.0))))));
    let exponent = k.to_bits().wrapping_sub(ROUND.to_bits()).wrapping_add(127);
    let scale = f32::from_bits(exponent << 23);
    // below 2^-126 the result would be subnormal: a weight of 0
    let r = blend(t > -126.0, p * scale, 0.0);
    blend(x.is_nan(), x, r)
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

/// `out[x] = base[x]^n` for n ≥ 0 by squaring, a pass over the row per bit of n (`powi` with
/// an exponent known only at run time is a library call per tap). Consumes `base`.
fn power(base: &mut [f32], mut n: i32, out: &mut [f32]) {
    out.fill(1.0);
    while n > 0 {
        if n & 1 == 1 {
            for (o, b) in out.iter_mut().zip(base.iter()) {
                *o *= b;
            }
        }
        n >>= 1;
        if n > 0 {
            for b in base.iter_mut() {
                *b *= *b;
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sampler::Sampler;

    /// The default estimate is the pilot image's channel mean and box: a two-pixel light in
    /// front of a wall with its albedo, normal and depth keeps its brightness, which the guided
    /// filter spreads over the wall.
    #[test]
    fn default_estimate_is_the_boxed_channel_mean() {
        let (w, h) = (32, 32);
        let mut color = vec![[0.5f32, 0.4, 0.3]; w * h];
        for p in [16 * w + 16, 16 * w + 17] {
            color[p] = [120.0, 120.0, 120.0];
        }
        let albedo = vec![[0.1f32; 3]; w * h];
        let normal = vec![[0.0f32, 0.0, 1.0]; w * h];
        let depth = vec![23.5f32; w * h];
        let g = Guides { albedo: &albedo, normal: &normal, depth: &depth };
        let pilot = denoised_intensity(w, h, &color, &g, &ImageEstimate::Pilot.settings());
        let expected = Image::from_data(w, h, color.iter().map(|[r, g, b]| (r + g + b) / 3.0).collect()).box_blur(3);
        assert_eq!(pilot.data, expected.data);
        let guided = denoised_intensity(w, h, &color, &g, &ImageEstimate::Guided.settings());
        let at = 16 * w + 16;
        assert!(guided.data[at] < 0.5 * pilot.data[at], "guided {} pilot {}", guided.data[at], pilot.data[at]);
    }

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
        let out = denoise(w, h, &color, &g, &DenoiseSettings::GUIDED);
        let rms = |img: &[[f32; 3]]| {
            let e: f32 = (0..w * h).map(|i| (img[i][0] - truth(i % w)).powi(2) / truth(i % w).powi(2)).sum();
            (e / (w * h) as f32).sqrt()
        };
        assert!(rms(&out) < 0.15 * rms(&color), "noise: {} → {}", rms(&color), rms(&out));
        // the columns next to the edge keep their own level
        let col = |x: usize| (0..h).map(|y| out[y * w + x][0]).sum::<f32>() / h as f32;
        assert!((col(31) - 1.0).abs() < 0.2 && (col(32) - 4.0).abs() < 0.8, "edge: {} | {}", col(31), col(32));
    }

    /// The row-wise filter equals the definition in the module documentation, evaluated per
    /// pixel and per tap, on random guides with escaped pixels, normals facing away from each
    /// other and image borders closer than the largest step.
    #[test]
    fn exp_nonpositive_is_exp_to_float_precision() {
        let mut worst = 0.0f64;
        for i in 0..=200_000 {
            let x = -(i as f32) * 1e-3 * (1.0 + (i % 7) as f32 * 1e-4);
            let exact = (x as f64).exp();
            let got = exp_nonpositive(x) as f64;
            if exact < f32::MIN_POSITIVE as f64 * 2.0 {
                assert!(got <= f32::MIN_POSITIVE as f64 * 2.0, "e^{x} = {exact}, got {got}");
                continue;
            }
            let error = (got - exact).abs() / exact / (1.0 + x.abs() as f64);
            worst = worst.max(error);
        }
        assert!(worst < 2e-7, "relative error / (1 + |x|) up to {worst}");
        assert_eq!(exp_nonpositive(0.0), 1.0);
        assert_eq!(exp_nonpositive(-0.0), 1.0);
        assert_eq!(exp_nonpositive(f32::NEG_INFINITY), 0.0);
        assert_eq!(exp_nonpositive(-1e30), 0.0);
        assert!(exp_nonpositive(f32::NAN).is_nan());
    }

    #[test]
    fn row_wise_filter_equals_the_per_pixel_definition() {
        let (w, h) = (37usize, 23usize);
        let mut s = Sampler::for_pixel(11, 0, 0);
        let mut color = vec![[0.0f32; 3]; w * h];
        let mut normal = vec![[0.0f32; 3]; w * h];
        let mut albedo = vec![[0.0f32; 3]; w * h];
        let mut depth = vec![0.0f32; w * h];
        for p in 0..w * h {
            color[p] = [s.next_1d() * 4.0, s.next_1d(), s.next_1d() * 0.5];
            if s.next_1d() < 0.1 {
                continue; // escaped: zero normal, albedo and depth
            }
            let n = glam::Vec3::new(s.next_1d() - 0.5, s.next_1d() - 0.5, s.next_1d()).normalize();
            normal[p] = n.to_array();
            albedo[p] = [0.2 + 0.1 * s.next_1d(), 0.5, 0.3 + 0.4 * (p % 3) as f32 / 2.0];
            depth[p] = 1.0 + (p % w) as f32 * 0.05 + s.next_1d() * 0.2;
        }
        let guides = Guides { albedo: &albedo, normal: &normal, depth: &depth };
        let settings = DenoiseSettings { levels: 4, ..DenoiseSettings::GUIDED };
        let out = denoise(w, h, &color, &guides, &settings);
        // the definition, per pixel
        let mut storage = vec![vec![0.0f32; w * h]; 8];
        let parts: Vec<&mut [f32]> = storage.iter_mut().map(|v| &mut v[..]).collect();
        let gradient = Planes::new(w, h, &guides, parts.try_into().expect("eight planes")).gradient;
        let modulation: Vec<[f32; 3]> = albedo.iter().map(|a| a.map(|c| c.max(1e-3))).collect();
        let mut img: Vec<[f32; 3]> =
            (0..w * h).map(|p| std::array::from_fn(|c| color[p][c] / modulation[p][c])).collect();
        for level in 0..settings.levels {
            let step = 1i64 << level;
            img = (0..w * h)
                .map(|p| {
                    let (x, y) = ((p % w) as i64, (p / w) as i64);
                    let (mut sum, mut wsum) = ([0.0f64; 3], 0.0f64);
                    for (j, ky) in B3.iter().enumerate() {
                        for (i, kx) in B3.iter().enumerate() {
                            let (dx, dy) = ((i as i64 - 2) * step, (j as i64 - 2) * step);
                            let (xx, yy) = (x + dx, y + dy);
                            if xx < 0 || yy < 0 || xx >= w as i64 || yy >= h as i64 {
                                continue;
                            }
                            let q = yy as usize * w + xx as usize;
                            let (ep, eq) = (normal[p] == [0.0; 3], normal[q] == [0.0; 3]);
                            let weight = if ep || eq {
                                (ep && eq) as u8 as f64
                            } else {
                                let dot: f32 = (0..3).map(|c| normal[p][c] * normal[q][c]).sum();
                                let da: f32 = (0..3).map(|c| (albedo[p][c] - albedo[q][c]).abs()).sum();
                                let offset = (((dx * dx + dy * dy) as f32).sqrt()) as f64;
                                let dz = ((depth[p] - depth[q]).abs() as f64)
                                    / (settings.depth_sigma as f64 * gradient[p] as f64 * offset
                                        + 1e-4 * depth[p].max(1e-3) as f64);
                                if dot <= 0.0 {
                                    0.0
                                } else {
                                    (dot as f64).powi(settings.normal_power)
                                        * (-(da as f64 / settings.albedo_sigma as f64 + dz)).exp()
                                }
                            };
                            let k = (kx * ky) as f64 * weight;
                            for c in 0..3 {
                                sum[c] += k * img[q][c] as f64;
                            }
                            wsum += k;
                        }
                    }
                    if wsum > 0.0 { sum.map(|v| (v / wsum) as f32) } else { img[p] }
                })
                .collect();
        }
        for p in 0..w * h {
            for c in 0..3 {
                let expected = img[p][c] * modulation[p][c];
                assert!(
                    (out[p][c] - expected).abs() <= 1e-4 * expected.abs().max(1.0),
                    "pixel {p} channel {c}: {} against {expected}",
                    out[p][c]
                );
            }
        }
    }
}
