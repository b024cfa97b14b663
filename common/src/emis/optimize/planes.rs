//! Step 0 of the optimiser (see [`super`]): the moment buffer's per-pixel sums as one image per
//! candidate, the shared part's outliers taken out, each image box-filtered as relative
//! moments ([`super::filter_moments`]), and each candidate's outlier threshold for the
//! image-level sums.
//!
//! 51 candidates at 1920×1080 are 420 MB of moments, more than any cache, so each step is one
//! pass over them that keeps its working set small: the transposition goes by tiles of pixels
//! and also finds the part every candidate shares; the shared outliers, a thousandth of the
//! pixels, are visited by index; and the filter runs one plane per thread, in place, and
//! streams the values the plane's threshold is taken from as it writes them
//! (docs/decisions/0021-optimiser-at-1080p.md). Every value is computed by the same float
//! operations on the same operands as the definitions in [`super`]'s documentation.

use crate::emis::filter::{Image, PassScratch, STRIP, histogram_quantile_by_counts};
use crate::emis::moments::MomentBuffer;
use crate::emis::quantile::{QuantileStream, histogram_keep, selection_keep};
use rayon::prelude::*;

/// Pixels per task of the transposition.
const CHUNK: usize = 16 * 1024;
/// Pixels per tile of the transposition: 16 pixels' sums of 51 candidates (3 KB) stay in L1
/// while every candidate's 16 values are written out.
const TILE: usize = 16;

/// Every candidate's image of moments, in one allocation, plane after plane: a block this
/// large is always mapped afresh and returned when dropped, whatever the process allocated
/// before, where one block per plane was not (docs/decisions/0021-optimiser-at-1080p.md).
#[derive(Clone, Debug, PartialEq)]
pub(super) struct Planes {
    width: usize,
    height: usize,
    data: Vec<f32>,
}

impl Planes {
    /// `count` planes of `width × height` zeros.
    fn zeros(width: usize, height: usize, count: usize) -> Self {
        Planes { width, height, data: vec![0.0; width * height * count] }
    }

    /// The images as planes (for tests of the later steps on planes of their own).
    #[cfg(test)]
    pub(super) fn from_images(images: &[Image]) -> Self {
        let (width, height) = images.first().map_or((0, 0), |i| (i.width, i.height));
        Planes { width, height, data: images.iter().flat_map(|i| i.data.iter().copied()).collect() }
    }

    /// The planes as images.
    #[cfg(test)]
    pub(super) fn to_images(&self) -> Vec<Image> {
        self.slices().into_iter().map(|p| Image::from_data(self.width, self.height, p.to_vec())).collect()
    }

    fn pixels(&self) -> usize {
        self.width * self.height
    }

    #[cfg(test)]
    fn slices(&self) -> Vec<&[f32]> {
        match self.pixels() {
            0 => Vec::new(),
            n => self.data.chunks_exact(n).collect(),
        }
    }

    pub(super) fn slices_mut(&mut self) -> Vec<&mut [f32]> {
        match self.pixels() {
            0 => Vec::new(),
            n => self.data.chunks_exact_mut(n).collect(),
        }
    }
}

impl std::ops::Index<usize> for Planes {
    type Output = [f32];

    fn index(&self, c: usize) -> &[f32] {
        let n = self.pixels();
        &self.data[c * n..(c + 1) * n]
    }
}

/// Every candidate's per-iteration moments as one image each (+∞ flags stay infinite; 0
/// iterations give 0 for finite sums) and, with `shared`, per pixel the minimum over the
/// candidates of the finite ones (+∞ where there is none).
pub(super) fn moment_planes(m: &MomentBuffer, shared: bool) -> (Planes, Option<Vec<f32>>) {
    let (w, h, k) = (m.width as usize, m.height as usize, m.candidates);
    let n = w * h;
    let scale = if m.iterations == 0 { 0.0 } else { 1.0 / m.iterations as f32 };
    let mut planes = Planes::zeros(w, h, k);
    let mut minimum = shared.then(|| vec![f32::INFINITY; n]);
    if k > 0 && n > 0 {
        // per task, its range of pixels in every plane
        let mut parts: Vec<Vec<&mut [f32]>> = (0..n.div_ceil(CHUNK)).map(|_| Vec::with_capacity(k)).collect();
        for plane in planes.slices_mut() {
            for (part, chunk) in parts.iter_mut().zip(plane.chunks_mut(CHUNK)) {
                part.push(chunk);
            }
        }
        let mins: Vec<Option<&mut [f32]>> = match &mut minimum {
            Some(v) => v.chunks_mut(CHUNK).map(Some).collect(),
            None => parts.iter().map(|_| None).collect(),
        };
        parts.into_par_iter().zip(mins).enumerate().for_each(|(t, (mut outs, mut mins))| {
            let len = outs[0].len();
            let sums = &m.sums[t * CHUNK * k..(t * CHUNK + len) * k];
            for t0 in (0..len).step_by(TILE) {
                let t1 = (t0 + TILE).min(len);
                let tile = &sums[t0 * k..t1 * k];
                for (c, out) in outs.iter_mut().enumerate() {
                    for (o, px) in out[t0..t1].iter_mut().zip(tile.chunks_exact(k)) {
                        let v = px[c];
                        *o = if v.is_finite() { v * scale } else { v };
                    }
                }
                if let Some(mins) = &mut mins {
                    // candidate by candidate, as the definition takes the minimum
                    for out in &outs {
                        for (s, &v) in mins[t0..t1].iter_mut().zip(&out[t0..t1]) {
                            if v.is_finite() && v < *s {
                                *s = v;
                            }
                        }
                    }
                }
            }
        });
    }
    (planes, minimum)
}

/// Takes out of every candidate's per-pixel moments, in the pixels where it is an outlier,
/// the part all candidates share: their minimum. It is what paths only the camera's own
/// techniques can sample contribute (δ = 1 for every candidate), which no strategy changes.
/// Outliers are pixels whose shared relative moment is above its `quantile`, taken before the
/// box filter spreads one rare sample over its neighbours.
pub fn remove_shared_outliers(planes: &mut [Image], norm: &[f32], quantile: f64) {
    let mut planes: Vec<&mut [f32]> = planes.iter_mut().map(|p| &mut p.data[..]).collect();
    // the minimum over the finite values, plane by plane over blocks of pixels (contiguous)
    const BLOCK: usize = 4096;
    let mut shared = vec![f32::INFINITY; norm.len()];
    shared.par_chunks_mut(BLOCK).enumerate().for_each(|(b, out)| {
        for plane in planes.iter() {
            for (s, &v) in out.iter_mut().zip(&plane[b * BLOCK..]) {
                if v.is_finite() && v < *s {
                    *s = v;
                }
            }
        }
    });
    subtract_shared_outliers(&mut planes, &shared, norm, quantile);
}

/// [`remove_shared_outliers`] with the per-pixel minimum `shared` already found.
pub(super) fn subtract_shared_outliers(planes: &mut [&mut [f32]], shared: &[f32], norm: &[f32], quantile: f64) {
    let threshold = relative_quantile(shared, norm, quantile);
    let outliers: Vec<usize> = (0..shared.len())
        .filter(|&p| {
            let s = shared[p];
            s.is_finite() && s / norm[p] > threshold
        })
        .collect();
    planes.par_iter_mut().for_each(|plane| {
        for &p in &outliers {
            let v = &mut plane[p];
            if v.is_finite() {
                *v = (*v - shared[p]).max(0.0);
            }
        }
    });
}

/// Zeroes, in every candidate's per-pixel moments, the finite values whose relative moment is
/// above that candidate's own `quantile`: before the box filter spreads a rare sample over its
/// neighbours, where the error metric would drop the pixel.
pub fn remove_each_outliers(planes: &mut [Image], norm: &[f32], quantile: f64) {
    let mut planes: Vec<&mut [f32]> = planes.iter_mut().map(|p| &mut p.data[..]).collect();
    remove_each_outliers_in(&mut planes, norm, quantile);
}

/// [`remove_each_outliers`] on planes as slices.
pub(super) fn remove_each_outliers_in(planes: &mut [&mut [f32]], norm: &[f32], quantile: f64) {
    planes.par_iter_mut().for_each(|plane| {
        let threshold = relative_quantile(plane, norm, quantile);
        for (v, &n) in plane.iter_mut().zip(norm) {
            if v.is_finite() && *v / n > threshold {
                *v = 0.0;
            }
        }
    });
}

/// The `quantile` of the finite per-pixel relative moments `moments / norm`, exact (a
/// selection, not a histogram: one rare sample can be 1e6 times the rest, and a histogram's
/// bins over [min, max] would then put every other pixel in its first bin); +∞ if none is
/// finite.
fn relative_quantile(moments: &[f32], norm: &[f32], quantile: f64) -> f32 {
    let mut stream = QuantileStream::new(selection_keep(quantile, moments.len()));
    let mut relative = [0.0f32; STRIP];
    for (m, n) in moments.chunks(STRIP).zip(norm.chunks(STRIP)) {
        let r = &mut relative[..m.len()];
        for ((r, &m), &n) in r.iter_mut().zip(m).zip(n) {
            *r = m / n;
        }
        stream.push_slice(r);
    }
    stream.selection_quantile(quantile).unwrap_or_else(|| {
        let mut v: Vec<f32> = moments.iter().zip(norm).map(|(&m, &n)| m / n).filter(|v| v.is_finite()).collect();
        let k = ((quantile * v.len() as f64).ceil() as usize).clamp(1, v.len()) - 1;
        *v.select_nth_unstable_by(k, |a, b| a.total_cmp(b)).1
    })
}

/// Filters every plane in place ([`super::filter_moments`] with `radius`) and returns each
/// one's outlier threshold: the histogram `quantile` of its relative moments.
pub(super) fn filter_planes(planes: &mut Planes, norm: &[f32], radius: usize, quantile: f64) -> Vec<f32> {
    let size = (planes.width, planes.height);
    planes
        .slices_mut()
        .into_par_iter()
        .map_init(PassScratch::default, |scratch, plane| filter_plane(plane, size, norm, radius, quantile, scratch))
        .collect()
}

fn filter_plane(
    plane: &mut [f32],
    (w, h): (usize, usize),
    norm: &[f32],
    radius: usize,
    quantile: f64,
    scratch: &mut PassScratch,
) -> f32 {
    let mut stream = QuantileStream::new(histogram_keep(quantile, w * h));
    let mut basis = [0.0f32; STRIP];
    scratch.box_blur_in_place(
        plane,
        (w, h),
        radius,
        |y, row| row.iter_mut().zip(&norm[y * w..]).for_each(|(v, &n)| *v /= n),
        |y, x0, seg| {
            let b = &mut basis[..seg.len()];
            for ((v, b), &n) in seg.iter_mut().zip(b.iter_mut()).zip(&norm[y * w + x0..]) {
                *v *= n;
                *b = *v / n;
            }
            stream.push_slice(b);
        },
    );
    stream.histogram_quantile(quantile).unwrap_or_else(|| {
        let basis: Vec<f32> = plane.iter().zip(norm).map(|(&v, &n)| v / n).collect();
        histogram_quantile_by_counts(&basis, quantile)
    })
}

/// The outlier thresholds of already filtered planes, by the definition (for tests of the
/// image-level sums on planes of their own).
#[cfg(test)]
pub(super) fn thresholds(filtered: &Planes, norm: &[f32], quantile: f64) -> Vec<f32> {
    filtered
        .slices()
        .into_iter()
        .map(|img| {
            let basis: Vec<f32> = img.iter().zip(norm).map(|(&v, &n)| v / n).collect();
            histogram_quantile_by_counts(&basis, quantile)
        })
        .collect()
}
