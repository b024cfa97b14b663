//! The image level (docs/emis.md §6, steps 2–4): per image-level candidate, the mean relative
//! moment and the mean cost over the pixels, each pixel taking the full candidate its
//! pixel-level decisions name.
//!
//! A group is an image-level candidate: (ν, c) with per-pixel merging, ν alone with per-pixel
//! merging and connections, or every candidate with global merging. Where the pixel level
//! decides, merging is binary (χ > 0.1 merges) and connections take their class, the smallest
//! candidate count at least the pixel's expected count (docs/emis.md §6.2): each pixel is
//! priced and judged as the candidate whose moment it reads.

use super::{Candidate, CostTerms, Image, MergeScope, OptimizerInput, Planes};
use rayon::prelude::*;
use serde::Serialize;

/// One image-level candidate's score, for reports.
#[derive(Clone, Debug, Serialize, PartialEq)]
pub struct ImageLevelScore {
    /// Light paths per pixel (0: path tracing).
    pub nu: f32,
    /// Connections (`None`: per pixel, as the connection mask says).
    pub connections: Option<u32>,
    /// With [`MergeScope::Global`]: whether this candidate merges (everywhere).
    pub merge: Option<bool>,
    /// Mean relative second moment.
    pub relative_moment: f64,
    /// Mean pixel cost.
    pub cost: f64,
}

/// An image-level candidate.
pub(super) struct Group {
    pub(super) nu: f32,
    /// `Some`: the same count everywhere; `None`: per pixel, by connection class.
    pub(super) connections: Option<u32>,
    /// `Some`: merges everywhere or nowhere; `None`: where the pixel-level mask says.
    pub(super) merge: Option<bool>,
    /// Per connection class (one entry when the count is the group's own), the candidate a
    /// pixel uses where it does not merge and where it does.
    variants: Vec<[Option<usize>; 2]>,
}

impl Group {
    /// The candidate of a pixel that merges or not, in connection class `class` (ignored by
    /// a group with one count).
    pub(super) fn variant(&self, merge: bool, class: u8) -> Option<usize> {
        let v = if self.variants.len() == 1 { &self.variants[0] } else { &self.variants[class as usize] };
        v[merge as usize]
    }
}

/// The connection counts of the bidirectional candidates, ascending: the classes a per-pixel
/// expected count is judged in.
pub(super) fn connection_classes(candidates: &[Candidate]) -> Vec<u32> {
    let mut counts: Vec<u32> = candidates.iter().filter(|c| !c.is_path_tracing()).map(|c| c.connections).collect();
    counts.sort_unstable();
    counts.dedup();
    counts
}

/// The class of an expected count: the index of the smallest count in `classes` at least
/// `c` (within float noise, as a blurred constant may not stay exact), else the largest.
pub(super) fn class_of(classes: &[u32], c: f32) -> u8 {
    let c = c * (1.0 - 1e-5);
    classes.iter().position(|&k| k as f32 >= c).unwrap_or(classes.len().saturating_sub(1)) as u8
}

/// The image-level candidates: every candidate with global merging; with per-pixel merging,
/// one per distinct (ν, c), or per distinct ν when `classes` (per-pixel connections) is given.
pub(super) fn image_level_groups(candidates: &[Candidate], scope: MergeScope, classes: Option<&[u32]>) -> Vec<Group> {
    if scope == MergeScope::Global {
        return candidates
            .iter()
            .enumerate()
            .map(|(i, c)| Group {
                nu: c.nu,
                connections: Some(c.connections),
                merge: Some(c.merge),
                variants: vec![[Some(i); 2]],
            })
            .collect();
    }
    let position = |nu: f32, conn: u32, merge: bool| {
        candidates.iter().position(|c| c.nu == nu && c.connections == conn && (c.merge == merge || c.is_path_tracing()))
    };
    // a group without the variant a pixel needs falls back to its other one
    let pair = |nu: f32, conn: u32| {
        let (off, on) = (position(nu, conn, false), position(nu, conn, true));
        [off.or(on), on.or(off)]
    };
    let mut groups: Vec<Group> = Vec::new();
    for c in candidates {
        let per_pixel = classes.filter(|_| !c.is_path_tracing());
        let connections = if per_pixel.is_some() { None } else { Some(c.connections) };
        if groups.iter().any(|g| g.nu == c.nu && g.connections == connections) {
            continue;
        }
        let variants = match per_pixel {
            Some(classes) => classes.iter().map(|&k| pair(c.nu, k)).collect(),
            None => vec![pair(c.nu, c.connections)],
        };
        groups.push(Group { nu: c.nu, connections, merge: None, variants });
    }
    groups
}

/// Pixels `start..end`, which all merge or all do not, in one connection class.
struct Run {
    start: usize,
    end: usize,
    merge: bool,
    class: u8,
}

/// Every image-level group's relative moment (outliers above each candidate's `thresholds`
/// zeroed) and cost, each pixel taking the group's variant by its χ (`pixel_mask`, or the
/// group's own global choice) and its connection class (`classes`, per pixel).
#[allow(clippy::too_many_arguments)]
pub(super) fn image_level_scores(
    input: &OptimizerInput,
    groups: &[Group],
    filtered: &Planes,
    norm: &[f32],
    costs: &[CostTerms],
    pixel_mask: Option<&Image>,
    classes: Option<&[u8]>,
    thresholds: &[f32],
) -> Vec<ImageLevelScore> {
    // merging is accounted as binary, as its moment is: a pixel merging with χ = 0.2 is priced
    // and judged as merging always; runs of pixels that merge alike, in pixel order
    let n = input.image.data.len();
    let runs: Vec<Run> = match pixel_mask {
        Some(mask) => {
            let mut runs: Vec<Run> = Vec::new();
            for (p, &chi) in mask.data.iter().enumerate() {
                let (merge, class) = (chi as f64 > 0.1, classes.map_or(0, |c| c[p]));
                match runs.last_mut() {
                    Some(run) if run.merge == merge && run.class == class => run.end = p + 1,
                    _ => runs.push(Run { start: p, end: p + 1, merge, class }),
                }
            }
            runs
        }
        None => Vec::new(),
    };
    // a per-pixel group builds the photon map when its mask merges anywhere, and then pays
    // for it in every pixel, merging or not
    let map_built = pixel_mask.is_some_and(|mask| mask.data.iter().any(|&chi| chi > 0.1));
    let weights = relative_weights(&input.image.data);
    groups
        .par_iter()
        .map(|g| {
            let sums = |map_built: bool, runs: &[Run]| {
                group_sums(input, g, filtered, (norm, &weights), costs, thresholds, map_built, runs)
            };
            let (relative_moment, cost) = match (g.merge, pixel_mask) {
                (Some(merge), _) => sums(false, &[Run { start: 0, end: n, merge, class: 0 }]),
                (None, Some(_)) => sums(map_built, &runs),
                (None, None) => unreachable!("invariant: per-pixel groups come with the pixel-level mask"),
            };
            ImageLevelScore { nu: g.nu, connections: g.connections, merge: g.merge, relative_moment, cost }
        })
        .collect()
}

/// Per pixel, what a moment is multiplied by for its share of the image's mean relative moment,
/// 1 / ((Ī² + 1e-4) · pixels); 0 for a black pixel, which carries none. Computed once per
/// update rather than as two divisions per pixel in every group
/// (docs/decisions/0021-optimiser-at-1080p.md).
pub(super) fn relative_weights(image: &[f32]) -> Vec<f64> {
    let pixels = image.len() as f64;
    image
        .par_iter()
        .map(|&i| {
            let i = i as f64;
            if i == 0.0 { 0.0 } else { 1.0 / ((i * i + 1e-4) * pixels) }
        })
        .collect()
}

/// One group's image-level sums (relative moment, cost) over `runs`, which cover the image in
/// pixel order. Per block of pixels of a run, the terms are computed first without branches
/// (vector code), then added in pixel order, as one sum over the pixels.
#[allow(clippy::too_many_arguments)]
fn group_sums(
    input: &OptimizerInput,
    g: &Group,
    filtered: &Planes,
    (norm, weights): (&[f32], &[f64]),
    costs: &[CostTerms],
    thresholds: &[f32],
    map_built: bool,
    runs: &[Run],
) -> (f64, f64) {
    let pixels = weights.len() as f64;
    // the map's build depends on ν only, so every class's merging variant prices it alike
    let shared_build = match (map_built, g.variant(true, 0)) {
        (true, Some(on)) if input.candidates[on].merge => costs[on].build(),
        _ => 0.0,
    };
    const BLOCK: usize = 256;
    let (mut rel, mut total_cost) = (0.0f64, 0.0f64);
    let (mut rel_terms, mut cost_terms) = ([0.0f64; BLOCK], [0.0f64; BLOCK]);
    for run in runs {
        // a group without the variant a pixel needs leaves the pixel out (never, as groups
        // are built)
        let Some(c) = g.variant(run.merge, run.class) else { continue };
        let merges = input.candidates[c].merge;
        let cost = (costs[c].at(merges as u8 as f64) + if merges { 0.0 } else { shared_build }) / pixels;
        let (plane, threshold) = (&filtered[c], thresholds[c]);
        for start in (run.start..run.end).step_by(BLOCK) {
            let range = start..(start + BLOCK).min(run.end);
            let len = range.len();
            let pixels_in = plane[range.clone()].iter().zip(&norm[range.clone()]).zip(&weights[range]);
            for ((r, k), ((&moment, &n), &weight)) in rel_terms.iter_mut().zip(cost_terms.iter_mut()).zip(pixels_in) {
                // outliers are zeroed, but an infinite moment (the candidate cannot sample this
                // pixel's paths) stays infinite, so that candidate cannot win
                // (docs/emis.md, D4)
                let outlier = moment / n > threshold && moment.is_finite();
                let moment = if outlier { 0.0 } else { moment };
                // black pixels carry no relative moment, so they are left out of the cost too;
                // a pixel left out adds +0, which leaves a sum of non-negative terms as it is
                *r = if weight == 0.0 { 0.0 } else { moment as f64 * weight };
                *k = if weight == 0.0 { 0.0 } else { cost };
            }
            for (r, k) in rel_terms[..len].iter().zip(&cost_terms[..len]) {
                rel += r;
                total_cost += k;
            }
        }
    }
    (rel, total_cost)
}
