//! The optimiser (docs/emis.md §6, checklist 11 and 12) as a pure function: filtered moments,
//! costs and the denoised image in; ν, c and the per-pixel merge mask χ out.
//!
//! 0. Filtering: each candidate's moments become relative moments M_j / (Ī_j² + 1e-4) with a
//!    radius-3 box filter, in the order [`MomentFilter`] says (default: per pixel first, then
//!    the filter; the reference filters M and Ī separately and divides after).
//! 1. Pixel level: per pixel, the candidate (ν, c, merge) minimising filtered M_j × C_j over
//!    all candidates; its merge bit goes into a binary image that is dilated (radius 16) and
//!    blurred (box radius 16) into χ, both radii for 640×480 and in proportion to the image's
//!    linear size otherwise (docs/decisions/0020-merge-mask-radii-scale.md). A pixel whose
//!    best value is 0 merges nothing.
//! 2. Image level: per image-level candidate g = (ν, c) (and path tracing), the mean over
//!    pixels of the relative moment M_j(g, merge_j) / (Ī_j² + 1e-4) with merge_j = χ_j > 0.1,
//!    after zeroing values above each candidate's 99.9 % quantile, times the mean cost; the
//!    argmin wins. Before step 0, [`OutlierStage::Shared`] (the default) takes out the outliers
//!    of the part of each pixel's moment that all candidates share.
//!
//! With [`MergeScope::Global`] (the path-tracing start's first decisions, docs/emis.md §1.2
//! and §4) there is no pixel level: every candidate (ν, c, merge) is an image-level candidate
//! that merges everywhere or nowhere, and χ is 1 or 0 in every pixel.
//!
//! Why relative first: the box filter would carry a small bright feature's huge absolute moment
//! into its dark neighbours, where dividing by their Ī² makes it a halo of relative moment
//! (docs/decisions/0003-moment-filter-order.md).
//!
//! Why the shared part's outliers go first: rare samples that every candidate receives alike
//! (δ = 1 for all) change no strategy, but once the filter spreads them a few escape the 0.1 %
//! rejection and hand the choice to the cheapest candidate
//! (docs/decisions/0008-shared-outliers-first.md).

use super::candidate::Candidate;
use super::cost::{CostConstants, CostTerms, PathStatistics};
use super::filter::Image;
use super::moments::MomentBuffer;
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

mod planes;

pub use planes::remove_shared_outliers;

/// Filter radii (docs/emis.md, decision 6).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct FilterSettings {
    /// Box passes on each candidate's moments.
    pub moment_box: usize,
    /// Dilation of the binary merge decisions at 640×480 (see [`FilterSettings::mask_radii`]).
    pub mask_dilate: usize,
    /// Box passes on the dilated mask at 640×480.
    pub mask_box: usize,
    /// Quantile above which pixel moments are zeroed in the image-level sums.
    pub outlier_quantile: f64,
    /// Whether moments are made relative before or after the box filter.
    pub order: MomentFilter,
    /// The outlier rule of the image-level sums.
    pub outliers: OutlierStage,
}

/// What the image-level outlier rejection takes out (docs/emis.md §5.5; why the default:
/// docs/decisions/0008-shared-outliers-first.md).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize, Default)]
#[serde(rename_all = "kebab-case")]
pub enum OutlierStage {
    /// The reference: per candidate, the box-filtered moments above their 99.9 % quantile
    /// (histogram).
    Filtered,
    /// First, before the box filter, the part of each pixel's relative moment that every
    /// candidate shares (their minimum), taken out of every candidate in the pixels where it
    /// is above its own 99.9 % quantile (exact); then as [`OutlierStage::Filtered`].
    #[default]
    Shared,
}

/// The order of the moment filter and the division by the image (docs/emis.md §5.2; why the
/// default: docs/decisions/0003-moment-filter-order.md).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize, Default)]
#[serde(rename_all = "kebab-case")]
pub enum MomentFilter {
    /// Box-filter M_j / (Ī_j² + 1e-4); the outlier quantile is taken on that image.
    #[default]
    Relative,
    /// The reference: box-filter M, divide by Ī² + 1e-4 (Ī box-filtered too); the outlier
    /// quantile is taken on the filtered M.
    Absolute,
}

impl MomentFilter {
    /// Every order, for benchmarks that compare them.
    pub const ALL: [MomentFilter; 2] = [MomentFilter::Relative, MomentFilter::Absolute];

    /// A candidate's filtered moment image in moment units: the relative order filters
    /// M / `norm` (`norm` = Ī² + 1e-4 per pixel) and multiplies the result back by `norm`, so
    /// both orders feed the same pixel- and image-level steps. [`MomentFilter::outlier_basis`]
    /// says which value the outlier threshold applies to.
    pub fn filter(self, moments: &Image, norm: &[f32], radius: usize) -> Image {
        match self {
            MomentFilter::Absolute => moments.box_blur(radius),
            MomentFilter::Relative => {
                let relative = Image::from_data(
                    moments.width,
                    moments.height,
                    moments.data.iter().zip(norm).map(|(m, n)| m / n).collect(),
                );
                let mut filtered = relative.box_blur(radius);
                filtered.data.iter_mut().zip(norm).for_each(|(v, n)| *v *= n);
                filtered
            }
        }
    }

    /// The value of a filtered moment that is compared with the outlier threshold.
    #[inline]
    pub fn outlier_basis(self, filtered_moment: f32, norm: f32) -> f32 {
        match self {
            MomentFilter::Absolute => filtered_moment,
            MomentFilter::Relative => filtered_moment / norm,
        }
    }
}

impl FilterSettings {
    /// The mask's dilation and box radii for a `width`×`height` image: the configured ones
    /// (the reference's 16 px, chosen for 640×480) scaled with the image's linear size, the
    /// square root of its pixel count over 640×480's, so that χ covers the same part of the
    /// picture at any resolution (256²: 7 px; 1920×1080: 42 px). At least 1 where configured.
    pub fn mask_radii(&self, width: usize, height: usize) -> (usize, usize) {
        let scale = ((width * height) as f64 / (640.0 * 480.0)).sqrt();
        let radius = |r: usize| if r == 0 { 0 } else { ((r as f64 * scale).round() as usize).max(1) };
        (radius(self.mask_dilate), radius(self.mask_box))
    }
}

impl Default for FilterSettings {
    fn default() -> Self {
        FilterSettings {
            moment_box: 3,
            mask_dilate: 16,
            mask_box: 16,
            outlier_quantile: 0.999,
            order: MomentFilter::Relative,
            outliers: OutlierStage::default(),
        }
    }
}

/// Where the merge decision is made.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum MergeScope {
    /// Per pixel: the merge mask χ of the pixel level (docs/emis.md, decision 1).
    PerPixel,
    /// For the whole image: merging everywhere and nowhere are separate image-level
    /// candidates (the path-tracing start's reduced set).
    Global,
}

/// Everything the optimiser reads.
pub struct OptimizerInput<'a> {
    /// The candidates, in the moment buffer's order.
    pub candidates: &'a [Candidate],
    /// Merged pilot moments.
    pub moments: &'a MomentBuffer,
    /// The denoised pilot image as a scalar (Ī, already box-filtered).
    pub image: &'a Image,
    /// Pilot path statistics.
    pub statistics: PathStatistics,
    /// Cost constants.
    pub constants: CostConstants,
    /// Filter radii.
    pub filters: FilterSettings,
    /// Per-pixel or global merge decisions.
    pub merge_scope: MergeScope,
}

/// One image-level candidate's score, for reports.
#[derive(Clone, Debug, Serialize, PartialEq)]
pub struct ImageLevelScore {
    /// Light paths per pixel (0: path tracing).
    pub nu: f32,
    /// Connections.
    pub connections: u32,
    /// With [`MergeScope::Global`]: whether this candidate merges (everywhere).
    pub merge: Option<bool>,
    /// Mean relative second moment.
    pub relative_moment: f64,
    /// Mean pixel cost.
    pub cost: f64,
}

/// The optimiser's decision.
#[derive(Clone, Debug, PartialEq)]
pub struct Decision {
    /// Light paths per pixel (0: path tracing).
    pub nu: f32,
    /// Connections per camera vertex.
    pub connections: u32,
    /// Per-pixel merge probability χ.
    pub merge_mask: Image,
    /// Scores of every image-level candidate.
    pub scores: Vec<ImageLevelScore>,
    /// Per pixel, the filtered relative moment M_j / (Ī_j² + 1e-4) of the chosen strategy.
    pub relative_moment: Image,
}

/// Runs the optimisation.
pub fn optimize(input: &OptimizerInput) -> Decision {
    let m = input.moments;
    let (w, h) = (m.width as usize, m.height as usize);
    let pixels = (w * h) as u32;
    // ---- filtered moments, one image per candidate ----
    let order = input.filters.order;
    let norm: Vec<f32> = input.image.data.iter().map(|&i| i * i + 1e-4).collect();
    let quantile = input.filters.outlier_quantile;
    let shared = input.filters.outliers == OutlierStage::Shared;
    let (mut filtered, minimum) = planes::moment_planes(m, shared);
    if let Some(minimum) = minimum {
        planes::subtract_shared_outliers(&mut filtered, &minimum, &norm, quantile);
    }
    let thresholds = planes::filter_planes(&mut filtered, &norm, order, input.filters.moment_box, quantile);
    let costs = CostTerms::of_candidates(&input.constants, &input.statistics, input.candidates, pixels);
    // ---- pixel level: the merge bit of the best full candidate ----
    let pixel_mask = match input.merge_scope {
        MergeScope::PerPixel => Some(pixel_level(input, &filtered, &costs)),
        MergeScope::Global => None,
    };
    // ---- image level ----
    let groups = image_level_groups(input.candidates, input.merge_scope);
    let scores = image_level_scores(input, &groups, &filtered, &norm, &costs, pixel_mask.as_ref(), &thresholds);
    let best = (0..groups.len()).filter(|&g| scores[g].relative_moment.is_finite()).min_by(|&a, &b| {
        let score = |g: usize| scores[g].relative_moment * scores[g].cost;
        score(a).total_cmp(&score(b))
    });
    // nothing finite: path tracing (as every candidate, it cannot sample some pixel's paths)
    let chosen = best.or_else(|| groups.iter().position(|g| g.nu == 0.0));
    let (nu, connections) = chosen.map_or((0.0, 0), |g| (groups[g].nu, groups[g].connections));
    let merge_mask = match pixel_mask {
        Some(mask) => mask,
        None => Image::filled(w, h, chosen.is_some_and(|g| groups[g].merge == Some(true)) as u8 as f32),
    };
    let relative_moment = Image::from_data(
        w,
        h,
        (0..w * h)
            .into_par_iter()
            .map(|p| {
                let merge = merge_mask.data[p] > 0.1;
                let i = input.image.data[p] as f64;
                chosen
                    .and_then(|g| groups[g].variant(merge))
                    .map_or(0.0, |c| (filtered[c].data[p] as f64 / (i * i + 1e-4)) as f32)
            })
            .collect(),
    );
    Decision { nu, connections, merge_mask, scores, relative_moment }
}

/// Every image-level group's relative moment (outliers above each candidate's `thresholds`
/// zeroed) and cost, each pixel taking the group's merging or non-merging variant by its χ
/// (`pixel_mask`, or the group's own global choice).
fn image_level_scores(
    input: &OptimizerInput,
    groups: &[Group],
    filtered: &[Image],
    norm: &[f32],
    costs: &[CostTerms],
    pixel_mask: Option<&Image>,
    thresholds: &[f32],
) -> Vec<ImageLevelScore> {
    // merging is accounted as binary, as its moment is: a pixel merging with χ = 0.2 is priced
    // and judged as merging always; runs of pixels that merge alike, in pixel order
    let n = input.image.data.len();
    let runs: Vec<Run> = match pixel_mask {
        Some(mask) => {
            let mut runs: Vec<Run> = Vec::new();
            for (p, &chi) in mask.data.iter().enumerate() {
                let merge = chi as f64 > 0.1;
                match runs.last_mut() {
                    Some(run) if run.merge == merge => run.end = p + 1,
                    _ => runs.push(Run { start: p, end: p + 1, merge }),
                }
            }
            runs
        }
        None => Vec::new(),
    };
    // a per-pixel group builds the photon map when its mask merges anywhere, and then pays
    // for it in every pixel, merging or not
    let map_built = pixel_mask.is_some_and(|mask| mask.data.iter().any(|&chi| chi > 0.1));
    groups
        .par_iter()
        .map(|g| {
            let sums = |map_built: bool, runs: &[Run]| {
                group_sums(input, g, filtered, norm, costs, thresholds, map_built, runs)
            };
            let (relative_moment, cost) = match (g.merge, pixel_mask) {
                (Some(merge), _) => sums(false, &[Run { start: 0, end: n, merge }]),
                (None, Some(_)) => sums(map_built, &runs),
                (None, None) => unreachable!("invariant: per-pixel groups come with the pixel-level mask"),
            };
            ImageLevelScore { nu: g.nu, connections: g.connections, merge: g.merge, relative_moment, cost }
        })
        .collect()
}

/// Pixels `start..end`, which all merge or all do not.
struct Run {
    start: usize,
    end: usize,
    merge: bool,
}

/// One group's image-level sums (relative moment, cost) over `runs`, which cover the image in
/// pixel order. Per block of pixels of a run, the terms are computed first without branches
/// (vector code), then added in pixel order, as one sum over the pixels.
#[allow(clippy::too_many_arguments)]
fn group_sums(
    input: &OptimizerInput,
    g: &Group,
    filtered: &[Image],
    norm: &[f32],
    costs: &[CostTerms],
    thresholds: &[f32],
    map_built: bool,
    runs: &[Run],
) -> (f64, f64) {
    let image = &input.image.data;
    let pixels = image.len() as f64;
    let order = input.filters.order;
    let shared_build = match (map_built, g.variant(true)) {
        (true, Some(on)) if input.candidates[on].merge => costs[on].build(),
        _ => 0.0,
    };
    const BLOCK: usize = 256;
    let (mut rel, mut total_cost) = (0.0f64, 0.0f64);
    let (mut rel_terms, mut cost_terms) = ([0.0f64; BLOCK], [0.0f64; BLOCK]);
    for run in runs {
        // a group without the variant a pixel needs leaves the pixel out (never, as groups
        // are built)
        let Some(c) = g.variant(run.merge) else { continue };
        let merges = input.candidates[c].merge;
        let cost = (costs[c].at(merges as u8 as f64) + if merges { 0.0 } else { shared_build }) / pixels;
        let (plane, threshold) = (&filtered[c].data, thresholds[c]);
        for start in (run.start..run.end).step_by(BLOCK) {
            let range = start..(start + BLOCK).min(run.end);
            let len = range.len();
            let pixels_in = plane[range.clone()].iter().zip(&norm[range.clone()]).zip(&image[range]);
            for ((r, k), ((&moment, &n), &i)) in rel_terms.iter_mut().zip(cost_terms.iter_mut()).zip(pixels_in) {
                // outliers are zeroed, but an infinite moment (the candidate cannot sample this
                // pixel's paths) stays infinite, so that candidate cannot win
                // (docs/emis.md, decision 4)
                let outlier = order.outlier_basis(moment, n) > threshold && moment.is_finite();
                let moment = if outlier { 0.0 } else { moment };
                // black pixels carry no relative moment, so they are left out of the cost too;
                // a pixel left out adds +0, which leaves a sum of non-negative terms as it is
                let i = i as f64;
                *r = if i == 0.0 { 0.0 } else { moment as f64 / (i * i + 1e-4) / pixels };
                *k = if i == 0.0 { 0.0 } else { cost };
            }
            for (r, k) in rel_terms[..len].iter().zip(&cost_terms[..len]) {
                rel += r;
                total_cost += k;
            }
        }
    }
    (rel, total_cost)
}

/// The pixel level: per pixel, the merge bit of the candidate with the lowest filtered
/// moment × cost, dilated and blurred into χ.
fn pixel_level(input: &OptimizerInput, filtered: &[Image], terms: &[CostTerms]) -> Image {
    let (w, h) = (input.moments.width as usize, input.moments.height as usize);
    let (dilate, blur) = input.filters.mask_radii(w, h);
    Image::from_data(w, h, merge_bits(input, filtered, terms)).dilate(dilate).box_blur(blur)
}

/// Per pixel, 1 where the first candidate with the lowest filtered moment × cost merges and
/// that value is above 0, else 0.
fn merge_bits(input: &OptimizerInput, filtered: &[Image], terms: &[CostTerms]) -> Vec<f32> {
    let (w, h) = (input.moments.width as usize, input.moments.height as usize);
    let costs: Vec<f64> =
        input.candidates.iter().zip(terms).map(|(c, t)| t.at(if c.merge { 1.0 } else { 0.0 })).collect();
    // per block of pixels, candidate by candidate, the first candidate with the lowest value
    const BLOCK: usize = 256;
    const NONE: usize = usize::MAX;
    let mut bits = vec![0.0f32; w * h];
    bits.par_chunks_mut(BLOCK).enumerate().for_each(|(b, out)| {
        let start = b * BLOCK;
        let (mut best, mut which) = ([f64::INFINITY; BLOCK], [NONE; BLOCK]);
        let (best, which) = (&mut best[..out.len()], &mut which[..out.len()]);
        for (c, &cost) in costs.iter().enumerate() {
            for ((v, i), &m) in best.iter_mut().zip(which.iter_mut()).zip(&filtered[c].data[start..]) {
                let value = m as f64 * cost;
                let lower = value < *v;
                *v = if lower { value } else { *v };
                *i = if lower { c } else { *i };
            }
        }
        for ((bit, &v), &c) in out.iter_mut().zip(best.iter()).zip(which.iter()) {
            *bit = if c != NONE && v > 0.0 && input.candidates[c].merge { 1.0 } else { 0.0 };
        }
    });
    bits
}

/// An image-level candidate.
struct Group {
    nu: f32,
    connections: u32,
    /// `Some`: merges everywhere or nowhere; `None`: where the pixel-level mask says.
    merge: Option<bool>,
    /// The candidate a pixel uses where it does not merge and where it does.
    variants: [Option<usize>; 2],
}

impl Group {
    fn variant(&self, merge: bool) -> Option<usize> {
        self.variants[merge as usize]
    }
}

/// The image-level candidates: per distinct (ν, c) with per-pixel merging, or every candidate
/// with global merging.
fn image_level_groups(candidates: &[Candidate], scope: MergeScope) -> Vec<Group> {
    if scope == MergeScope::Global {
        return candidates
            .iter()
            .enumerate()
            .map(|(i, c)| Group { nu: c.nu, connections: c.connections, merge: Some(c.merge), variants: [Some(i); 2] })
            .collect();
    }
    let position = |nu: f32, conn: u32, merge: bool| {
        candidates.iter().position(|c| c.nu == nu && c.connections == conn && (c.merge == merge || c.is_path_tracing()))
    };
    let mut groups: Vec<Group> = Vec::new();
    for c in candidates {
        if groups.iter().any(|g| (g.nu, g.connections) == (c.nu, c.connections)) {
            continue;
        }
        // a group without the variant a pixel needs falls back to its other one
        let (off, on) = (position(c.nu, c.connections, false), position(c.nu, c.connections, true));
        groups.push(Group { nu: c.nu, connections: c.connections, merge: None, variants: [off.or(on), on.or(off)] });
    }
    groups
}

#[cfg(test)]
mod tests;
