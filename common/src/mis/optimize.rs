//! The optimiser (emis-spec §6, checklist 11–12) as a pure function: filtered moments, costs
//! and the denoised image in; ν, c and the per-pixel merge mask χ out.
//!
//! 0. Filtering: each candidate's moments become relative moments M_j / (Ī_j² + 1e-4) with a
//!    radius-3 box filter, in the order [`MomentFilter`] says (default: per pixel first, then
//!    the filter; the reference filters M and Ī separately and divides after).
//! 1. Pixel level: per pixel, the candidate (ν, c, merge) minimising filtered M_j × C_j over
//!    all candidates; its merge bit goes into a binary image that is dilated (radius 16) and
//!    blurred (box radius 16) into χ. A pixel whose best value is 0 merges nothing.
//! 2. Image level: per image-level candidate g = (ν, c) (and path tracing), the mean over
//!    pixels of the relative moment M_j(g, merge_j) / (Ī_j² + 1e-4) with merge_j = χ_j > 0.1,
//!    after zeroing values above each candidate's 99.9 % quantile, times the mean cost; the
//!    argmin wins.
//!
//! With [`MergeScope::Global`] (the path-tracing start's first decisions, emis-spec §1 and §4)
//! there is no pixel level: every candidate (ν, c, merge) is an image-level candidate that
//! merges everywhere or nowhere, and χ is 1 or 0 in every pixel.
//!
//! Why relative first (evidence, 2026-11-21): the box filter keeps each candidate's total
//! moment but moves it between pixels. Around a small, very bright feature (a visible light
//! source, its glossy reflection) it carries that feature's huge absolute moment M ≈ Ī² into
//! dark neighbours, where dividing by their Ī² makes it enormous: a halo of relative moment
//! around every light, far wider than the 0.1 % the outlier rejection drops, and largest for
//! the candidates that see the lights worst. On veach-mis this made path tracing look 10–16×
//! worse than ν = 0.25, c = 0 (mean relative moment 28–85 against 3.6 after the filter, 2.95
//! against 2.80 without it), while at equal time pt beats that choice by 1.3–1.7× in relMSE.
//! Filtering the per-pixel relative moment keeps the filter's noise reduction and leaves every
//! pixel's value on its own brightness scale, which is what relMSE measures. On the other five
//! scenes both orders make the same decisions (all four updates, emis-vcm and emis-bdpt).
//! `tessera bench --ground-truth 32` (truth: each candidate's relMSE × K; 2026-11-21):
//! geometric-mean regret 1.148 relative, 1.305 absolute over the six scenes. Absolute loses on
//! cornell-box (1.25), glossy-interreflection (1.44) and veach-mis (1.73; its predicted pt
//! figure is 6909 against 1.54 relative and 1.52 from pt's own samples); relative loses on
//! caustic-glass (2.21 against 1.60), where the pilot's merge moments are nearly flat in ν
//! (15.0–19.5 for every merging candidate after 4 iterations) and ν = 0.25 wins a near-tie.

use super::candidate::Candidate;
use super::cost::{CostConstants, CostTerms, PathStatistics};
use super::filter::Image;
use super::moments::MomentBuffer;
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

/// Filter radii (decision 6).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct FilterSettings {
    /// Box passes on each candidate's moments.
    pub moment_box: usize,
    /// Dilation of the binary merge decisions.
    pub mask_dilate: usize,
    /// Box passes on the dilated mask.
    pub mask_box: usize,
    /// Quantile above which pixel moments are zeroed in the image-level sums.
    pub outlier_quantile: f64,
    /// Whether moments are made relative before or after the box filter.
    pub order: MomentFilter,
}

/// The order of the moment filter and the division by the image (a Tessera decision; see the
/// module documentation for the evidence).
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

impl Default for FilterSettings {
    fn default() -> Self {
        FilterSettings {
            moment_box: 3,
            mask_dilate: 16,
            mask_box: 16,
            outlier_quantile: 0.999,
            order: MomentFilter::Relative,
        }
    }
}

/// Where the merge decision is made.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum MergeScope {
    /// Per pixel: the merge mask χ of the pixel level (decision 1).
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

/// Every candidate's per-iteration moments as one image each, transposed from the buffer's
/// pixel-major layout block by block (reading each candidate with a stride would touch every
/// cache line of the buffer once per candidate).
fn moment_planes(m: &MomentBuffer) -> Vec<Image> {
    let (w, h, k) = (m.width as usize, m.height as usize, m.candidates);
    let scale = if m.iterations == 0 { 0.0 } else { 1.0 / m.iterations as f32 };
    const BLOCK: usize = 4096;
    let blocks: Vec<Vec<f32>> = m
        .sums
        .par_chunks(BLOCK * k.max(1))
        .map(|s| {
            let n = s.len() / k.max(1);
            let mut out = vec![0.0f32; s.len()];
            for p in 0..n {
                for c in 0..k {
                    // +∞ flags stay infinite; 0 iterations give 0 for finite sums
                    let v = s[p * k + c];
                    out[c * n + p] = if v.is_finite() { v * scale } else { v };
                }
            }
            out
        })
        .collect();
    (0..k)
        .into_par_iter()
        .map(|c| {
            let mut data = Vec::with_capacity(w * h);
            for b in &blocks {
                let n = b.len() / k;
                data.extend_from_slice(&b[c * n..(c + 1) * n]);
            }
            Image::from_data(w, h, data)
        })
        .collect()
}

/// Runs the optimisation.
pub fn optimize(input: &OptimizerInput) -> Decision {
    let m = input.moments;
    let (w, h) = (m.width as usize, m.height as usize);
    let pixels = (w * h) as u32;
    // ---- filtered moments, one image per candidate ----
    let order = input.filters.order;
    let norm: Vec<f32> = input.image.data.iter().map(|&i| i * i + 1e-4).collect();
    let filtered: Vec<Image> =
        moment_planes(m).into_par_iter().map(|plane| order.filter(&plane, &norm, input.filters.moment_box)).collect();
    let costs: Vec<CostTerms> = input
        .candidates
        .iter()
        .map(|c| CostTerms::new(&input.constants, &input.statistics, c, !c.is_path_tracing(), pixels))
        .collect();
    // ---- pixel level: the merge bit of the best full candidate ----
    let pixel_mask = match input.merge_scope {
        MergeScope::PerPixel => Some(pixel_level(input, &filtered, &costs)),
        MergeScope::Global => None,
    };
    // ---- image level ----
    let thresholds: Vec<f32> = filtered
        .par_iter()
        .map(|img| {
            let basis: Vec<f32> = img.data.iter().zip(&norm).map(|(&v, &n)| order.outlier_basis(v, n)).collect();
            Image::from_data(w, h, basis).histogram_quantile(input.filters.outlier_quantile)
        })
        .collect();
    let groups = image_level_groups(input.candidates, input.merge_scope);
    // χ_j of group `g` in pixel `p`
    let chi_at = |g: &Group, p: usize| match (g.merge, &pixel_mask) {
        (Some(merge), _) => merge as u8 as f32,
        (None, Some(mask)) => mask.data[p],
        (None, None) => unreachable!("invariant: per-pixel groups come with the pixel-level mask"),
    };
    let scores: Vec<ImageLevelScore> = groups
        .par_iter()
        .map(|g| {
            let (mut rel, mut total_cost) = (0.0f64, 0.0f64);
            for p in 0..w * h {
                let chi = chi_at(g, p) as f64;
                let Some(c) = g.variant(chi > 0.1) else { continue };
                total_cost += costs[c].at(if input.candidates[c].merge { chi } else { 0.0 }) / pixels as f64;
                let i = input.image.data[p] as f64;
                if i == 0.0 {
                    continue;
                }
                let mut moment = filtered[c].data[p];
                // outliers are zeroed, but an infinite moment (the candidate cannot sample this
                // pixel's paths) stays infinite, so that candidate cannot win (decision 4)
                if order.outlier_basis(moment, norm[p]) > thresholds[c] && moment.is_finite() {
                    moment = 0.0;
                }
                rel += moment as f64 / (i * i + 1e-4) / pixels as f64;
            }
            ImageLevelScore {
                nu: g.nu,
                connections: g.connections,
                merge: g.merge,
                relative_moment: rel,
                cost: total_cost,
            }
        })
        .collect();
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

/// The pixel level: per pixel, the merge bit of the candidate with the lowest filtered
/// moment × cost, dilated and blurred into χ.
fn pixel_level(input: &OptimizerInput, filtered: &[Image], terms: &[CostTerms]) -> Image {
    let (w, h) = (input.moments.width as usize, input.moments.height as usize);
    let costs: Vec<f64> =
        input.candidates.iter().zip(terms).map(|(c, t)| t.at(if c.merge { 1.0 } else { 0.0 })).collect();
    let bits: Vec<f32> = (0..w * h)
        .into_par_iter()
        .map(|p| {
            let mut best = (f64::INFINITY, None);
            for (c, cost) in costs.iter().enumerate() {
                let v = filtered[c].data[p] as f64 * cost;
                if v < best.0 {
                    best = (v, Some(c));
                }
            }
            match best {
                (v, Some(c)) if v > 0.0 && input.candidates[c].merge => 1.0,
                _ => 0.0,
            }
        })
        .collect();
    Image::from_data(w, h, bits).dilate(input.filters.mask_dilate).box_blur(input.filters.mask_box)
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
mod tests {
    use super::*;
    use crate::mis::candidate::CandidateConfig;
    use crate::mis::cost::pixel_cost;
    use crate::mis::delta::Delta;

    /// A moment buffer with `value(pixel, candidate)` as every candidate's per-iteration moment.
    fn buffer(w: u32, h: u32, candidates: &[Candidate], value: impl Fn(u32, &Candidate) -> f64) -> MomentBuffer {
        let mut b = MomentBuffer::new(w, h, candidates.len());
        for p in 0..w * h {
            for (c, cand) in candidates.iter().enumerate() {
                let v = value(p, cand);
                b.add(
                    p,
                    c,
                    if v.is_finite() { Delta::Finite(1.0) } else { Delta::Infinite },
                    if v.is_finite() { v } else { 0.0 },
                );
            }
        }
        b.iterations = 1;
        b
    }

    fn run(candidates: &[Candidate], moments: &MomentBuffer, image: &Image) -> Decision {
        run_in_order(candidates, moments, image, MomentFilter::default())
    }

    fn run_in_order(candidates: &[Candidate], moments: &MomentBuffer, image: &Image, order: MomentFilter) -> Decision {
        optimize(&OptimizerInput {
            candidates,
            moments,
            image,
            statistics: PathStatistics::default(),
            constants: CostConstants::default(),
            filters: FilterSettings { order, ..FilterSettings::default() },
            merge_scope: MergeScope::PerPixel,
        })
    }

    /// Every candidate's relative moment is 2 everywhere, including on a tiny feature 1000×
    /// brighter than the rest. Made relative before the filter, the image-level relative moment
    /// stays 2; filtered as absolute moments, the feature's M spreads into its dim surroundings
    /// and the mean explodes (the veach-mis failure the default order fixes).
    #[test]
    fn a_bright_feature_does_not_spread_relative_moment_into_its_surroundings() {
        let candidates = CandidateConfig::bdpt().candidates();
        let (w, h) = (64u32, 64u32);
        let intensity = |p: u32| if (30..32).contains(&(p % w)) && (30..32).contains(&(p / w)) { 1000.0 } else { 1.0 };
        let moments = buffer(w, h, &candidates, |p, _| 2.0 * intensity(p) * intensity(p));
        let image = Image::from_data(w as usize, h as usize, (0..w * h).map(|p| intensity(p) as f32).collect());
        let relative = run_in_order(&candidates, &moments, &image, MomentFilter::Relative);
        for s in &relative.scores {
            // the outlier rejection may zero up to 0.1 % of the (equal) pixels
            assert!((s.relative_moment - 2.0).abs() <= 2.0 * 0.0015, "{s:?}");
        }
        let absolute = run_in_order(&candidates, &moments, &image, MomentFilter::Absolute);
        for s in &absolute.scores {
            assert!(s.relative_moment > 100.0, "{s:?}");
        }
    }

    #[test]
    fn merging_that_wins_in_a_disk_gives_a_dilated_blurred_disk() {
        let candidates = CandidateConfig::vcm().candidates();
        let (w, h) = (96u32, 96u32);
        let in_disk = |p: u32| {
            let (x, y) = ((p % w) as f32 - 48.0, (p / w) as f32 - 48.0);
            x * x + y * y < 10.0 * 10.0
        };
        // merging is 1000x better inside the disk, useless (no better, more costly) outside
        let b = buffer(w, h, &candidates, |p, c| if c.merge && in_disk(p) { 0.001 } else { 1.0 });
        let d = run(&candidates, &b, &Image::filled(w as usize, h as usize, 1.0));
        let chi = |x: u32, y: u32| d.merge_mask.data[(y * w + x) as usize];
        assert_eq!(chi(48, 48), 1.0, "χ = 1 in the disk");
        assert!(chi(48 + 10 + 16, 48) > 0.4, "dilated by 16 px");
        assert!(chi(48 + 10 + 16 + 20, 48) == 0.0, "falls to 0 beyond dilation + blur");
        // smooth fall-off: monotone from the disk outwards over 32+ px
        let profile: Vec<f32> = (48..96).map(|x| chi(x, 48)).collect();
        assert!(profile.windows(2).all(|p| p[1] <= p[0] + 1e-6), "monotone");
        let transition = profile.iter().filter(|&&v| v > 0.0 && v < 1.0).count();
        assert!(transition >= 15, "a gradual edge, not a step: {transition} px");
    }

    #[test]
    fn a_two_times_lower_moment_at_equal_cost_wins_and_scaling_changes_nothing() {
        let candidates = CandidateConfig::bdpt().candidates();
        let target = Candidate { nu: 0.5, connections: 2, merge: false };
        let cost_target =
            pixel_cost(&CostConstants::default(), &PathStatistics::default(), &target, 0.0, true, 32 * 32);
        // every candidate's moment × cost equals 1, except the target's, which is 0.5
        let m = |_: u32, c: &Candidate| {
            let cc = pixel_cost(
                &CostConstants::default(),
                &PathStatistics::default(),
                c,
                0.0,
                !c.is_path_tracing(),
                32 * 32,
            );
            if *c == target { 0.5 / cost_target } else { 1.0 / cc }
        };
        let img = Image::filled(32, 32, 0.7);
        let d = run(&candidates, &buffer(32, 32, &candidates, m), &img);
        assert_eq!((d.nu, d.connections), (0.5, 2));
        let scaled = run(&candidates, &buffer(32, 32, &candidates, |p, c| 1e6 * m(p, c)), &img);
        assert_eq!((scaled.nu, scaled.connections), (d.nu, d.connections), "scaling all moments changes no decision");
        assert!(d.merge_mask.data.iter().all(|&v| v == 0.0), "bdpt never merges");
    }

    /// The path-tracing start's decisions: every reduced candidate is an image-level one, and
    /// the winner merges everywhere or nowhere, whatever the per-pixel picture.
    #[test]
    fn global_merge_scope_scores_every_candidate_and_gives_a_constant_mask() {
        let candidates = CandidateConfig::vcm().reduced().candidates();
        let (w, h) = (48u32, 48u32);
        let stats = PathStatistics::default();
        let cost = |c: &Candidate| {
            let chi = if c.merge { 1.0 } else { 0.0 };
            pixel_cost(&CostConstants::default(), &stats, c, chi, !c.is_path_tracing(), w * h)
        };
        let img = Image::filled(w as usize, h as usize, 0.5);
        for target in [
            Candidate { nu: 0.5, connections: 1, merge: true },
            Candidate { nu: 1.0, connections: 0, merge: false },
            Candidate::PATH_TRACING,
        ] {
            // the target's moment × cost is half everyone else's, varying over the image; in
            // a small corner merging is 10× worse (a per-pixel decision would not merge there)
            let b = buffer(w, h, &candidates, |p, c| {
                let corner = p % w < 4 && p / w < 4;
                let v = if *c == target { 0.5 } else { 1.0 } * (1.0 + (p % 7) as f64 * 0.1);
                if corner && c.merge { 10.0 * v / cost(c) } else { v / cost(c) }
            });
            let d = optimize(&OptimizerInput {
                candidates: &candidates,
                moments: &b,
                image: &img,
                statistics: stats,
                constants: CostConstants::default(),
                filters: FilterSettings::default(),
                merge_scope: MergeScope::Global,
            });
            assert_eq!((d.nu, d.connections), (target.nu, target.connections), "{target:?}");
            assert_eq!(d.scores.len(), 9);
            assert!(d.scores.iter().all(|s| s.merge.is_some()));
            let chi = if target.merge { 1.0 } else { 0.0 };
            assert!(d.merge_mask.data.iter().all(|&v| v == chi), "χ = {chi} everywhere for {target:?}");
        }
    }

    #[test]
    fn candidates_that_cannot_sample_never_win() {
        let candidates = CandidateConfig::bdpt().candidates();
        // path tracing looks cheapest and perfect, but cannot sample some paths: infinite
        let b = buffer(16, 16, &candidates, |p, c| {
            if c.is_path_tracing() { if p == 5 { f64::INFINITY } else { 0.0 } } else { 1.0 }
        });
        let d = run(&candidates, &b, &Image::filled(16, 16, 1.0));
        assert!(d.nu > 0.0, "a bidirectional candidate is chosen: {d:?}");
    }
}
