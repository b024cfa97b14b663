//! A path-tracing start's image after a restart: kept beside the bidirectional iterations
//! and combined with them by inverse-variance weights, rather than discarded
//! (docs/decisions/0032-light-probe-and-restart-share.md).
//!
//! Both parts estimate the same image without bias, so any fixed weighting of the two does
//! too. The weight of one start iteration against one later iteration is the ratio of their
//! predicted per-iteration relative variances, v_after / v_pt. It is only ever set by an
//! update of the full set after the restart: its moments come from the later iterations
//! alone (so the weight does not depend on the start's samples), and they see paths that
//! path tracing cannot sample (pt's moment is then infinite, and the start, which misses
//! them, gets weight 0). Until such an update has run the start is not used.

use super::optimize::ImageLevelScore;

/// The image of a path-tracing start that a restart ended.
#[derive(Clone, Debug, PartialEq)]
pub struct KeptStart {
    /// Per-pixel means of the start's iterations (row-major RGB).
    pub image: Vec<[f32; 3]>,
    /// Iterations the start rendered.
    pub iterations: u32,
    /// Weight of one start iteration against one iteration after the restart; `None` until
    /// an update of the full set estimated it.
    pub weight: Option<f64>,
}

impl KeptStart {
    /// The combined image, given the per-pixel means and sample counts of the iterations
    /// after the restart: per pixel the weighted mean α·start + (1 − α)·after with
    /// α = k·n_start / (k·n_start + n_after).
    pub fn combine(&self, after: &[[f32; 3]], after_counts: &[u32]) -> Vec<[f32; 3]> {
        let k = self.weight.unwrap_or(0.0);
        let start = k * self.iterations as f64;
        after
            .iter()
            .zip(after_counts)
            .zip(&self.image)
            .map(|((a, &n), s)| {
                let total = start + n as f64;
                let alpha = if total > 0.0 { start / total } else { 0.0 };
                // a start left out leaves the image as it is, bit for bit
                if alpha == 0.0 {
                    return *a;
                }
                std::array::from_fn(|c| (alpha * s[c] as f64 + (1.0 - alpha) * a[c] as f64) as f32)
            })
            .collect()
    }
}

/// Mean over the pixels of Ī² / (Ī² + 1e-4), black pixels counting 0: what a relative second
/// moment holds beyond the relative variance, the squared mean being the same for every
/// unbiased candidate.
pub fn relative_mean_square(image: &[f32]) -> f64 {
    let sum: f64 = image
        .iter()
        .map(|&i| {
            let i = i as f64;
            i * i / (i * i + 1e-4)
        })
        .sum();
    sum / image.len().max(1) as f64
}

/// The weight of a start iteration against one of `chosen` (an index into `scores`): the
/// ratio of their relative variances, each its relative moment less `mean_square` (floored at
/// a thousandth of the moment, as the two are close in an almost noise-free image). 0 when
/// path tracing cannot sample every path the pilot found (its moment is infinite).
pub fn start_weight(scores: &[ImageLevelScore], chosen: usize, mean_square: f64) -> f64 {
    let Some(pt) = scores.iter().find(|s| s.nu == 0.0) else { return 0.0 };
    let after = scores[chosen].relative_moment;
    if !pt.relative_moment.is_finite() || !after.is_finite() {
        return 0.0;
    }
    let variance = |m: f64| (m - mean_square).max(m * 1e-3);
    let (v_pt, v_after) = (variance(pt.relative_moment), variance(after));
    if v_pt > 0.0 { v_after / v_pt } else { 0.0 }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn score(nu: f32, relative_moment: f64) -> ImageLevelScore {
        ImageLevelScore { nu, connections: Some(1), merge: None, relative_moment, cost: 1.0 }
    }

    /// Two unbiased estimates of variance 4 and 1 per iteration: the weights that minimise the
    /// combination's variance are 1/4 and 1, and the combined mean lies where they put it.
    #[test]
    fn the_combination_weights_each_part_by_its_inverse_variance() {
        let scores = [score(0.0, 5.0), score(1.0, 2.0)];
        let k = start_weight(&scores, 1, 1.0);
        assert!((k - 0.25).abs() < 1e-12, "{k}");
        let start = KeptStart { image: vec![[2.0, 4.0, 0.0]], iterations: 8, weight: Some(k) };
        // α = 0.25·8 / (0.25·8 + 6) = 0.25
        let combined = start.combine(&[[6.0, 0.0, 1.0]], &[6]);
        assert_eq!(combined, vec![[5.0, 1.0, 0.75]]);
    }

    /// Without an estimate of the weight, or where path tracing misses paths the later pilot
    /// found, the start is left out.
    #[test]
    fn an_unconfirmed_or_biased_start_is_left_out() {
        let mut start = KeptStart { image: vec![[1.0; 3]], iterations: 4, weight: None };
        assert_eq!(start.combine(&[[3.0; 3]], &[2]), vec![[3.0; 3]]);
        start.weight = Some(start_weight(&[score(0.0, f64::INFINITY), score(1.0, 2.0)], 1, 0.5));
        assert_eq!(start.weight, Some(0.0));
        assert_eq!(start.combine(&[[3.0; 3]], &[2]), vec![[3.0; 3]]);
        start.image = vec![[f32::INFINITY; 3]];
        assert_eq!(start.combine(&[[3.0; 3]], &[2]), vec![[3.0; 3]], "weight 0 leaves the image alone");
        start.image = vec![[1.0; 3]];
        // a pixel no later iteration reached keeps the start
        start.weight = Some(1.0);
        assert_eq!(start.combine(&[[0.0; 3]], &[0]), vec![[1.0; 3]]);
    }

    #[test]
    fn the_mean_square_counts_black_pixels_as_zero() {
        let m = relative_mean_square(&[0.0, 1.0]);
        assert!((m - 0.5 / (1.0 + 1e-4)).abs() < 1e-12, "{m}");
    }
}
