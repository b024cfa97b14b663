//! The pilot image and its guides at half resolution, for the guided filter of
//! [`super::denoise`]: the filter's cost is per pixel and tap, and Ī is box-filtered at full
//! resolution afterwards, so its finest level is not worth a full-resolution pass
//! (docs/decisions/0042-guided-filter-at-half-resolution.md).

use super::guides::Guides;
use rayon::prelude::*;

/// An image and its guides on a grid of ⌈w/2⌉ × ⌈h/2⌉ blocks of up to 2 × 2 pixels.
pub struct Halved {
    /// Blocks per row.
    pub width: usize,
    /// Rows of blocks.
    pub height: usize,
    /// The block's mean colour.
    pub color: Vec<[f32; 3]>,
    /// The block's mean albedo.
    pub albedo: Vec<[f32; 3]>,
    /// The normalised sum of the normals of the block's pixels whose camera ray hit; zero
    /// where every pixel's escaped.
    pub normal: Vec<[f32; 3]>,
    /// The mean distance of the pixels whose camera ray hit (0 where none did).
    pub depth: Vec<f32>,
}

impl Halved {
    /// Halves a `width × height` image with per-pixel albedo, normal (zero: escaped) and depth.
    pub fn new(
        width: usize,
        height: usize,
        color: &[[f32; 3]],
        albedo: &[[f32; 3]],
        normal: &[[f32; 3]],
        depth: &[f32],
    ) -> Self {
        let (hw, hh) = (width.div_ceil(2), height.div_ceil(2));
        let blocks: Vec<_> = (0..hw * hh)
            .into_par_iter()
            .map(|b| {
                let (bx, by) = (b % hw, b / hw);
                let (mut c, mut a, mut n, mut z) = ([0.0f32; 3], [0.0f32; 3], [0.0f32; 3], 0.0f32);
                let (mut count, mut hits) = (0.0f32, 0.0f32);
                for y in 2 * by..(2 * by + 2).min(height) {
                    for x in 2 * bx..(2 * bx + 2).min(width) {
                        let p = y * width + x;
                        for k in 0..3 {
                            c[k] += color[p][k];
                            a[k] += albedo[p][k];
                        }
                        count += 1.0;
                        if normal[p] != [0.0; 3] {
                            (0..3).for_each(|k| n[k] += normal[p][k]);
                            z += depth[p];
                            hits += 1.0;
                        }
                    }
                }
                let length = (n[0] * n[0] + n[1] * n[1] + n[2] * n[2]).sqrt();
                // opposite normals in one block: it counts as a hit facing nowhere in particular
                let n = if hits == 0.0 {
                    [0.0; 3]
                } else if length > 1e-6 {
                    n.map(|v| v / length)
                } else {
                    [0.0, 0.0, 1.0]
                };
                (c.map(|v| v / count), a.map(|v| v / count), n, if hits > 0.0 { z / hits } else { 0.0 })
            })
            .collect();
        Halved {
            width: hw,
            height: hh,
            color: blocks.iter().map(|b| b.0).collect(),
            albedo: blocks.iter().map(|b| b.1).collect(),
            normal: blocks.iter().map(|b| b.2).collect(),
            depth: blocks.iter().map(|b| b.3).collect(),
        }
    }

    /// The block of pixel `p` of the `width`-wide full-resolution image.
    pub fn block_of(&self, width: usize, p: usize) -> usize {
        (p / width / 2) * self.width + (p % width) / 2
    }

    /// Channel `planes` of the blocks brought back to the full-resolution pixels of the
    /// guides' image: per pixel, the blocks of its own and the four next to it, weighted by
    /// how alike their geometry is to the pixel's (a block across an edge mixes both sides,
    /// and its pixels take their own side's neighbour). Gives the channels' mean after
    /// modulating each by the pixel's own albedo.
    pub fn upsampled_mean(&self, width: usize, guides: &Guides, planes: [&[f32]; 3], normal_power: i32) -> Vec<f32> {
        let n = guides.albedo.len();
        (0..n)
            .into_par_iter()
            .map(|p| {
                let (bx, by) = (((p % width) / 2) as isize, ((p / width) / 2) as isize);
                let (np, zp) = (guides.normal[p], guides.depth[p]);
                let escaped = np == [0.0; 3];
                let (mut sum, mut weight_sum) = ([0.0f32; 3], 0.0f32);
                for (dx, dy) in [(0, 0), (-1, 0), (1, 0), (0, -1), (0, 1)] {
                    let (x, y) = (bx + dx, by + dy);
                    if x < 0 || y < 0 || x >= self.width as isize || y >= self.height as isize {
                        continue;
                    }
                    let b = y as usize * self.width + x as usize;
                    let (nq, zq) = (self.normal[b], self.depth[b]);
                    let w = match (escaped, nq == [0.0; 3]) {
                        (true, true) => 1.0,
                        (false, false) => {
                            let dot = (np[0] * nq[0] + np[1] * nq[1] + np[2] * nq[2]).max(0.0);
                            dot.powi(normal_power) * (-(zp - zq).abs() / (0.1 * zp + 1e-4)).exp()
                        }
                        _ => 0.0,
                    };
                    // the pixel's own block counts a little whatever its geometry
                    let w = if (dx, dy) == (0, 0) { w.max(1e-6) } else { w };
                    (0..3).for_each(|c| sum[c] += w * planes[c][b]);
                    weight_sum += w;
                }
                let a = guides.albedo[p];
                (0..3).map(|c| sum[c] / weight_sum * a[c].max(1e-3)).sum::<f32>() / 3.0
            })
            .collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::emis::denoise::{DenoiseSettings, denoised_intensity};
    use crate::emis::filter::Image;
    use crate::sampler::Sampler;

    /// A 3 × 3 image halves into 2 × 2 blocks of 4, 2, 2 and 1 pixels; escaped pixels leave
    /// a block's normal and depth to the pixels that hit.
    #[test]
    fn blocks_average_their_pixels_and_ignore_escaped_ones_for_geometry() {
        let (w, h) = (3, 3);
        let color: Vec<[f32; 3]> = (0..9).map(|p| [p as f32, 1.0, 2.0]).collect();
        let albedo = vec![[0.5f32; 3]; 9];
        let mut normal = vec![[0.0f32, 0.0, 1.0]; 9];
        let mut depth: Vec<f32> = (0..9).map(|p| 10.0 + p as f32).collect();
        normal[0] = [0.0; 3];
        depth[0] = 0.0;
        normal[1] = [1.0, 0.0, 0.0];
        normal[8] = [0.0; 3];
        let half = Halved::new(w, h, &color, &albedo, &normal, &depth);
        assert_eq!((half.width, half.height), (2, 2));
        // block 0 holds pixels 0, 1, 3, 4
        assert_eq!(half.color[0], [2.0, 1.0, 2.0]);
        assert_eq!(half.color[1], [(2.0 + 5.0) / 2.0, 1.0, 2.0]);
        assert_eq!(half.color[3], [8.0, 1.0, 2.0]);
        assert_eq!(half.albedo[3], [0.5; 3]);
        assert_eq!(half.depth[0], (11.0 + 13.0 + 14.0) / 3.0);
        let n = half.normal[0];
        assert!((n[0] - 1.0 / 5f32.sqrt()).abs() < 1e-6 && (n[2] - 2.0 / 5f32.sqrt()).abs() < 1e-6, "{n:?}");
        assert_eq!((half.normal[3], half.depth[3]), ([0.0; 3], 0.0), "the escaped corner");
        assert_eq!([0, 1, 2, 3, 4, 5, 6, 7, 8].map(|p| half.block_of(w, p)), [0, 0, 1, 0, 0, 1, 2, 2, 3]);
    }

    /// On 2 × 2 blocks the filter's Ī is as close to the noise-free one as the full-resolution
    /// filter's: two noisy regions of different normals (the edge at an odd column, inside a
    /// block) under striped albedo, which each pixel's own albedo restores.
    #[test]
    fn half_resolution_estimate_is_close_to_the_full_one() {
        let (w, h) = (66usize, 40usize);
        let (mut color, mut normal, mut albedo) =
            (vec![[0.0f32; 3]; w * h], vec![[0.0f32; 3]; w * h], vec![[0.0; 3]; w * h]);
        let depth = vec![2.0f32; w * h];
        let truth = |x: usize| if x < 33 { 1.0f32 } else { 4.0 };
        for p in 0..w * h {
            let x = p % w;
            let mut s = Sampler::for_pixel(5, p as u32, 0);
            albedo[p] = if x % 3 == 0 { [0.8, 0.6, 0.4] } else { [0.2; 3] };
            let v = -truth(x) * (1.0 - s.next_1d()).ln();
            color[p] = albedo[p].map(|a| a * v);
            normal[p] = if x < 33 { [0.0, 0.0, 1.0] } else { [1.0, 0.0, 0.0] };
        }
        let g = Guides { albedo: &albedo, normal: &normal, depth: &depth };
        let full = denoised_intensity(w, h, &color, &g, &DenoiseSettings::GUIDED);
        let half = denoised_intensity(w, h, &color, &g, &DenoiseSettings::GUIDED_HALF);
        let column = |img: &Image, x: usize| (0..h).map(|y| img.data[y * w + x]).sum::<f32>() / h as f32;
        // the noise-free image's Ī: the striped albedo survives, spread by the final box
        let exact = (0..w * h).map(|p| truth(p % w) * albedo[p].iter().sum::<f32>() / 3.0).collect();
        let exact = Image::from_data(w, h, exact).box_blur(DenoiseSettings::GUIDED.final_box);
        let error = |img: &Image| {
            let columns = (0..w).map(|x| (column(img, x) / column(&exact, x) - 1.0).abs());
            (columns.clone().sum::<f32>() / w as f32, columns.fold(0.0, f32::max))
        };
        let ((half_mean, half_worst), (full_mean, full_worst)) = (error(&half), error(&full));
        // the edge's block mixes both sides: upsampled by its own block alone the worst column
        // next to the edge was 0.17 off, more than the full filter's noise anywhere (0.12)
        let report = format!("half {half_mean} (worst {half_worst}), full {full_mean} (worst {full_worst})");
        assert!(half_mean < 1.25 * full_mean && half_worst < full_worst, "{report}");
    }
}
