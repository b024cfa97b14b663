//! The optimiser (docs/emis.md §6, checklist 11 and 12) as a pure function: filtered moments,
//! costs and the denoised image in; ν, c and the per-pixel merge mask χ out.
//!
//! 0. Filtering: each candidate's moments become relative moments M_j / (Ī_j² + 1e-4) per pixel,
//!    then a radius-3 box filter ([`filter_moments`]; the reference filtered M and Ī separately
//!    and divided after).
//! 1. Pixel level: per pixel, the candidate (ν, c, merge) minimising filtered M_j × C_j over
//!    all candidates; its merge bit goes into a binary image that is dilated (radius 16) and
//!    blurred (box radius 16) into χ, both radii for 640×480 and in proportion to the image's
//!    linear size otherwise (docs/decisions/0020-merge-mask-radii-scale.md). A pixel whose
//!    best value is 0 merges nothing.
//! 2. Image level: per image-level candidate g = (ν, c) (and path tracing), the mean over
//!    pixels of the relative moment M_j(g, merge_j) / (Ī_j² + 1e-4) with merge_j = χ_j > 0.1,
//!    after zeroing values above each candidate's 99.9 % quantile, times the mean cost; the
//!    argmin wins, unless it is cheaper than the [`Incumbent`] and not better by its margin.
//!    Before step 0, [`OutlierStage::Shared`] (the default) takes out the outliers
//!    of the part of each pixel's moment that all candidates share.
//!
//! With [`ConnectionScope::PerPixel`] the pixel level also keeps the winner's c, dilated
//! (radius 3) and blurred (box radius 16) into an expected count per pixel, both radii for
//! 640×480 as the merge mask's; the image-level candidates are then ν alone, and each pixel is
//! judged with the smallest candidate count at least its expected one (docs/emis.md §5.6 and
//! §6, the reference's experimental per-pixel connections).
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

mod image_level;
mod planes;

pub use image_level::ImageLevelScore;
use image_level::{class_of, connection_classes, image_level_groups, image_level_scores};
use planes::Planes;
pub use planes::{remove_each_outliers, remove_shared_outliers};

/// Filter radii (docs/emis.md, D6).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct FilterSettings {
    /// Box passes on each candidate's moments.
    pub moment_box: usize,
    /// Dilation of the binary merge decisions at 640×480 (see [`FilterSettings::mask_radii`]).
    pub mask_dilate: usize,
    /// Box passes on the dilated mask at 640×480.
    pub mask_box: usize,
    /// Dilation of the per-pixel connection counts at 640×480.
    pub connection_dilate: usize,
    /// Box passes on the dilated connection counts at 640×480.
    pub connection_box: usize,
    /// Quantile above which pixel moments are zeroed in the image-level sums.
    pub outlier_quantile: f64,
    /// The outlier rule of the image-level sums.
    pub outliers: OutlierStage,
}

/// What the image-level outlier rejection takes out (docs/emis.md §5.5; why the default:
/// docs/decisions/0008-shared-outliers-first.md).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize, Default)]
#[serde(rename_all = "kebab-case")]
#[cfg_attr(feature = "clap", derive(clap::ValueEnum))]
pub enum OutlierStage {
    /// The reference's rule alone: per candidate, the box-filtered moments above their 99.9 %
    /// quantile (histogram), which every stage ends with. Retired as a setting (rare samples
    /// every candidate shares then decide, docs/decisions/0008-shared-outliers-first.md); the
    /// tests keep it as the baseline that shows why.
    #[cfg(test)]
    Filtered,
    /// First, before the box filter, the part of each pixel's relative moment that every
    /// candidate shares (their minimum), taken out of every candidate in the pixels where it
    /// is above its own 99.9 % quantile (exact); then the reference's rule: each candidate's
    /// box-filtered moments above their 99.9 % quantile.
    #[default]
    #[cfg_attr(
        feature = "clap",
        value(
            help = "First the outliers of the part every candidate shares, per pixel before the box filter; then the reference's rule"
        )
    )]
    Shared,
    /// First, before the box filter, each candidate's own per-pixel relative moments above
    /// its 99.9 % quantile (exact) are zeroed, as the error metric drops the worst pixels of
    /// each image; then the reference's rule.
    #[cfg_attr(
        feature = "clap",
        value(
            help = "First each candidate's own per-pixel outliers before the box filter (as the error metric drops each image's worst pixels); then the reference's rule"
        )
    )]
    Each,
}

/// A candidate's filtered moment image in moment units: M / `norm` (`norm` = Ī² + 1e-4 per
/// pixel) box-filtered, then multiplied back by `norm`, so that a small bright feature's huge
/// absolute moment does not spread into its dark neighbours as a halo of relative moment (the
/// reference's order, filtering M and dividing after, lost and was retired: decision 0003).
/// Its outlier threshold applies to the relative value, filtered moment / `norm`.
pub fn filter_moments(moments: &Image, norm: &[f32], radius: usize) -> Image {
    let relative =
        Image::from_data(moments.width, moments.height, moments.data.iter().zip(norm).map(|(m, n)| m / n).collect());
    let mut filtered = relative.box_blur(radius);
    filtered.data.iter_mut().zip(norm).for_each(|(v, n)| *v *= n);
    filtered
}

impl FilterSettings {
    /// The mask's dilation and box radii for a `width`×`height` image: the configured ones
    /// (the reference's 16 px, chosen for 640×480) scaled with the image's linear size, the
    /// square root of its pixel count over 640×480's, so that χ covers the same part of the
    /// picture at any resolution (256²: 7 px; 1920×1080: 42 px). At least 1 where configured.
    pub fn mask_radii(&self, width: usize, height: usize) -> (usize, usize) {
        scaled_radii((self.mask_dilate, self.mask_box), width, height)
    }

    /// The connection mask's dilation and box radii for a `width`×`height` image, scaled as
    /// [`FilterSettings::mask_radii`] scales the merge mask's.
    pub fn connection_radii(&self, width: usize, height: usize) -> (usize, usize) {
        scaled_radii((self.connection_dilate, self.connection_box), width, height)
    }
}

/// Radii chosen for 640×480, scaled by the linear size of a `width`×`height` image, at least 1
/// where not 0.
fn scaled_radii((dilate, blur): (usize, usize), width: usize, height: usize) -> (usize, usize) {
    let scale = ((width * height) as f64 / (640.0 * 480.0)).sqrt();
    let radius = |r: usize| if r == 0 { 0 } else { ((r as f64 * scale).round() as usize).max(1) };
    (radius(dilate), radius(blur))
}

impl Default for FilterSettings {
    fn default() -> Self {
        FilterSettings {
            moment_box: 3,
            mask_dilate: 16,
            mask_box: 16,
            connection_dilate: 3,
            connection_box: 16,
            outlier_quantile: 0.999,
            outliers: OutlierStage::default(),
        }
    }
}

/// Where the merge decision is made.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum MergeScope {
    /// Per pixel: the merge mask χ of the pixel level (docs/emis.md, D1).
    PerPixel,
    /// For the whole image: merging everywhere and nowhere are separate image-level
    /// candidates (the path-tracing start's reduced set).
    Global,
}

/// Where the connection count is decided (docs/emis.md, D1; the reference's
/// experimental per-pixel connections, §1.1 and §5).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize, Default)]
#[serde(rename_all = "kebab-case")]
#[cfg_attr(feature = "clap", derive(clap::ValueEnum))]
pub enum ConnectionScope {
    /// One c for the image, an image-level parameter beside ν.
    #[default]
    #[cfg_attr(feature = "clap", value(help = "One count for the image, beside ν"))]
    Image,
    /// An expected c per pixel from the pixel level, filtered like the merge mask and rounded
    /// stochastically at each camera vertex; the image level chooses ν alone. Only with
    /// per-pixel merge decisions ([`MergeScope::PerPixel`]).
    #[cfg_attr(
        feature = "clap",
        value(help = "An expected count per pixel, rounded stochastically at each camera vertex")
    )]
    PerPixel,
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
    /// Image-level or per-pixel connection counts (per pixel only with per-pixel merging).
    pub connection_scope: ConnectionScope,
    /// The share of the render's iterations a bidirectional winner would discard (a
    /// path-tracing start restarts): such a winner must beat path tracing by more than the
    /// work it throws away, its image-level score being divided by 1 − share. 0 otherwise.
    pub restart_share: f64,
    /// The image-level strategy being rendered: a cheaper winner must beat it by a margin.
    pub incumbent: Option<Incumbent>,
}

/// The image-level strategy the pilot is rendering, and how much better a cheaper candidate
/// must score to replace it: moments of a short pilot understate the heavy tails of cheaper,
/// noisier strategies most, which shows as small predicted gains of theirs
/// (docs/decisions/0046-incumbent-margin.md). A dearer candidate needs no margin.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Incumbent {
    /// Light paths per pixel.
    pub nu: f32,
    /// Connections (`None`: per pixel).
    pub connections: Option<u32>,
    /// A cheaper challenger's score × (1 + margin) must be below the incumbent's.
    pub margin: f64,
}

impl Incumbent {
    /// The margin after `recorded` pilot iterations: `scale` / √recorded, as the standard
    /// error of a mean over that many iterations.
    pub fn margin_after(scale: f64, recorded: u32) -> f64 {
        scale / (recorded.max(1) as f64).sqrt()
    }
}

/// The optimiser's decision.
#[derive(Clone, Debug, PartialEq)]
pub struct Decision {
    /// Light paths per pixel (0: path tracing).
    pub nu: f32,
    /// Connections per camera vertex (0 where [`Decision::connection_mask`] is given).
    pub connections: u32,
    /// With [`ConnectionScope::PerPixel`] and a bidirectional winner: the expected
    /// connections per camera vertex of each pixel.
    pub connection_mask: Option<Image>,
    /// Per-pixel merge probability χ.
    pub merge_mask: Image,
    /// Scores of every image-level candidate.
    pub scores: Vec<ImageLevelScore>,
    /// The index in [`Decision::scores`] of the chosen candidate (`None`: nothing was finite).
    pub chosen: Option<usize>,
    /// Per pixel, the filtered relative moment M_j / (Ī_j² + 1e-4) of the chosen strategy.
    pub relative_moment: Image,
}

/// Runs the optimisation.
pub fn optimize(input: &OptimizerInput) -> Decision {
    let m = input.moments;
    let (w, h) = (m.width as usize, m.height as usize);
    let pixels = (w * h) as u32;
    // ---- filtered moments, one image per candidate ----
    let norm: Vec<f32> = input.image.data.iter().map(|&i| i * i + 1e-4).collect();
    let quantile = input.filters.outlier_quantile;
    let shared = input.filters.outliers == OutlierStage::Shared;
    let (mut filtered, minimum) = planes::moment_planes(m, shared);
    if let Some(minimum) = minimum {
        planes::subtract_shared_outliers(&mut filtered.slices_mut(), &minimum, &norm, quantile);
    }
    if input.filters.outliers == OutlierStage::Each {
        planes::remove_each_outliers_in(&mut filtered.slices_mut(), &norm, quantile);
    }
    let thresholds = planes::filter_planes(&mut filtered, &norm, input.filters.moment_box, quantile);
    let costs = CostTerms::of_candidates(&input.constants, &input.statistics, input.candidates, pixels);
    // ---- pixel level: the merge bit (and c) of the best full candidate ----
    let per_pixel_c = input.merge_scope == MergeScope::PerPixel && input.connection_scope == ConnectionScope::PerPixel;
    let (pixel_mask, connection_mask) = match input.merge_scope {
        MergeScope::PerPixel => {
            let (merge, connections) = pixel_level(input, &filtered, &costs, per_pixel_c);
            (Some(merge), connections)
        }
        MergeScope::Global => (None, None),
    };
    let class_counts = connection_classes(input.candidates);
    let classes: Option<Vec<u8>> =
        connection_mask.as_ref().map(|m| m.data.iter().map(|&c| class_of(&class_counts, c)).collect());
    // ---- image level ----
    let groups = image_level_groups(input.candidates, input.merge_scope, classes.as_ref().map(|_| &class_counts[..]));
    let scores = image_level_scores(
        input,
        &groups,
        &filtered,
        &norm,
        &costs,
        pixel_mask.as_ref(),
        classes.as_deref(),
        &thresholds,
    );
    let kept = 1.0 - input.restart_share.clamp(0.0, 1.0);
    let discount = |g: usize| if groups[g].nu > 0.0 { kept } else { 1.0 };
    let score = |g: usize| scores[g].relative_moment * scores[g].cost / discount(g);
    let finite = |g: &usize| scores[*g].relative_moment.is_finite();
    let best = (0..groups.len()).filter(finite).min_by(|&a, &b| score(a).total_cmp(&score(b)));
    let incumbent = input.incumbent.and_then(|inc| {
        let g = groups.iter().position(|g| g.merge.is_none() && g.nu == inc.nu && g.connections == inc.connections);
        g.filter(finite).map(|g| (g, inc.margin))
    });
    let best = match (best, incumbent) {
        // only a cheaper challenger's moments are understated by the pilot's shortness
        (Some(b), Some((i, margin))) if scores[b].cost < scores[i].cost && score(b) * (1.0 + margin) >= score(i) => {
            Some(i)
        }
        _ => best,
    };
    // nothing finite: path tracing (as every candidate, it cannot sample some pixel's paths)
    let chosen = best.or_else(|| groups.iter().position(|g| g.nu == 0.0));
    let (nu, connections) = chosen.map_or((0.0, Some(0)), |g| (groups[g].nu, groups[g].connections));
    // a per-pixel group (never path tracing) renders with the mask
    let connection_mask = connection_mask.filter(|_| connections.is_none());
    let connections = connections.unwrap_or(0);
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
                let class = classes.as_ref().map_or(0, |c| c[p]);
                let i = input.image.data[p] as f64;
                chosen
                    .and_then(|g| groups[g].variant(merge, class))
                    .map_or(0.0, |c| (filtered[c][p] as f64 / (i * i + 1e-4)) as f32)
            })
            .collect(),
    );
    Decision { nu, connections, connection_mask, merge_mask, scores, chosen, relative_moment }
}

/// The pixel level: per pixel, the merge bit of the candidate with the lowest filtered
/// moment × cost, dilated and blurred into χ; with `connections`, also its c, dilated and
/// blurred into an expected count.
fn pixel_level(
    input: &OptimizerInput,
    filtered: &Planes,
    terms: &[CostTerms],
    connections: bool,
) -> (Image, Option<Image>) {
    let (w, h) = (input.moments.width as usize, input.moments.height as usize);
    let winners = pixel_winners(input, filtered, terms);
    let (dilate, blur) = input.filters.mask_radii(w, h);
    let bits = winners.iter().map(|w| w.is_some_and(|c| input.candidates[c].merge) as u8 as f32).collect();
    let merge = Image::from_data(w, h, bits).dilate(dilate).box_blur(blur);
    let connections = connections.then(|| {
        let (dilate, blur) = input.filters.connection_radii(w, h);
        let counts = winners.iter().map(|w| w.map_or(0.0, |c| input.candidates[c].connections as f32)).collect();
        Image::from_data(w, h, counts).dilate(dilate).box_blur(blur)
    });
    (merge, connections)
}

/// Per pixel, the first candidate with the lowest filtered moment × cost, where that value is
/// above 0 (a pixel whose best is 0 gets nothing: no merging, no connections).
fn pixel_winners(input: &OptimizerInput, filtered: &Planes, terms: &[CostTerms]) -> Vec<Option<usize>> {
    let (w, h) = (input.moments.width as usize, input.moments.height as usize);
    let costs: Vec<f64> =
        input.candidates.iter().zip(terms).map(|(c, t)| t.at(if c.merge { 1.0 } else { 0.0 })).collect();
    // per block of pixels, candidate by candidate, the first candidate with the lowest value
    const BLOCK: usize = 256;
    const NONE: usize = usize::MAX;
    let mut winners = vec![None; w * h];
    winners.par_chunks_mut(BLOCK).enumerate().for_each(|(b, out)| {
        let start = b * BLOCK;
        let (mut best, mut which) = ([f64::INFINITY; BLOCK], [NONE; BLOCK]);
        let (best, which) = (&mut best[..out.len()], &mut which[..out.len()]);
        for (c, &cost) in costs.iter().enumerate() {
            for ((v, i), &m) in best.iter_mut().zip(which.iter_mut()).zip(&filtered[c][start..]) {
                let value = m as f64 * cost;
                let lower = value < *v;
                *v = if lower { value } else { *v };
                *i = if lower { c } else { *i };
            }
        }
        for ((winner, &v), &c) in out.iter_mut().zip(best.iter()).zip(which.iter()) {
            *winner = (c != NONE && v > 0.0).then_some(c);
        }
    });
    winners
}

#[cfg(test)]
mod tests;
