//! Chooses which light a direct-lighting or light-path sample uses. Like Mitsuba, lights are
//! picked uniformly unless they set `sampling_weight`.

/// A discrete distribution over the scene's lights.
#[derive(Clone, Debug, Default)]
pub struct LightSampler {
    pmf: Vec<f32>,
    cdf: Vec<f32>,
}

impl LightSampler {
    /// From per-light weights (non-negative, at least one positive if any lights exist).
    pub fn new(weights: &[f32]) -> Self {
        let total: f32 = weights.iter().sum();
        if weights.is_empty() || total <= 0.0 {
            return LightSampler::default();
        }
        let pmf: Vec<f32> = weights.iter().map(|w| w / total).collect();
        let mut acc = 0.0;
        let cdf = pmf
            .iter()
            .map(|p| {
                acc += p;
                acc
            })
            .collect();
        LightSampler { pmf, cdf }
    }

    /// Picks a light with a uniform number; returns its index and probability, and the
    /// number rescaled to [0, 1) for reuse.
    #[inline]
    pub fn sample(&self, u: f32) -> Option<(usize, f32, f32)> {
        if self.pmf.is_empty() {
            return None;
        }
        let i = self.cdf.partition_point(|&c| c <= u).min(self.pmf.len() - 1);
        let lo = if i == 0 { 0.0 } else { self.cdf[i - 1] };
        let p = self.pmf[i];
        if p <= 0.0 {
            return None;
        }
        Some((i, p, ((u - lo) / p).clamp(0.0, 1.0 - f32::EPSILON)))
    }

    /// Probability of choosing light `i`.
    #[inline]
    pub fn pmf(&self, i: usize) -> f32 {
        self.pmf.get(i).copied().unwrap_or(0.0)
    }
}
