//! The light-vertex cache of one iteration (Davidovič et al. 2014): N light subpaths traced in
//! parallel chunks and stored back to back, so that connections can pick any vertex uniformly
//! and merges can walk a photon's subpath. Shared by `bdpt` and `vcm`.

use super::light_path::{LIGHT_PATH_CHUNK, trace_light_path};
use super::prefetch::prefetch;
use super::vertex::PathVertex;
use crate::sampler::Sampler;
use crate::scene::Scene;
use rayon::prelude::*;

/// One iteration's light subpaths, stored back to back.
pub struct LightCache {
    /// All vertices; a vertex at depth d is preceded by its subpath's d earlier vertices.
    pub vertices: Vec<PathVertex>,
    /// Indices of the vertices connections may choose (depth ≥ 1).
    pub selectable: Vec<u32>,
    /// Number of light paths.
    pub paths: u32,
}

impl LightCache {
    /// Traces `paths` light paths of iteration `iteration`, in parallel chunks concatenated in
    /// order, so the cache does not depend on the thread count.
    pub fn trace(scene: &Scene, seed: u64, iteration: u32, paths: u32, max_edges: u32, rr_depth: u32) -> Self {
        let chunks: Vec<Vec<PathVertex>> = (0..paths.div_ceil(LIGHT_PATH_CHUNK))
            .into_par_iter()
            .map(|c| {
                let mut out = Vec::new();
                for index in c * LIGHT_PATH_CHUNK..((c + 1) * LIGHT_PATH_CHUNK).min(paths) {
                    trace_light_path(
                        scene,
                        &mut Sampler::for_light_path(seed, index, iteration),
                        max_edges,
                        rr_depth,
                        &mut out,
                    );
                }
                out
            })
            .collect();
        let vertices: Vec<PathVertex> = chunks.into_iter().flatten().collect();
        let selectable = vertices.iter().enumerate().filter(|(_, v)| v.depth >= 1).map(|(i, _)| i as u32).collect();
        LightCache { vertices, selectable, paths }
    }

    /// The vertex a connection's uniform number `u` picks among the selectable ones (`None`
    /// when there are none).
    #[inline]
    pub fn pick(&self, u: f32) -> Option<usize> {
        self.pick_slot(u).map(|slot| self.selectable[slot] as usize)
    }

    /// Starts loading the entry of `selectable` that [`LightCache::pick`] reads for `u`.
    #[inline]
    pub fn prefetch_pick(&self, u: f32) {
        if let Some(slot) = self.pick_slot(u) {
            prefetch(&self.selectable[slot]);
        }
    }

    /// Starts loading vertex `index` and the two before it: the end of the subpath
    /// [`LightCache::subpath`] returns, whose length is known only once the vertex is read.
    #[inline]
    pub fn prefetch_subpath(&self, index: usize) {
        for v in &self.vertices[index.saturating_sub(2)..=index] {
            prefetch(v);
        }
    }

    fn pick_slot(&self, u: f32) -> Option<usize> {
        let n = self.selectable.len();
        (n > 0).then(|| ((u * n as f32) as usize).min(n - 1))
    }

    /// The light subpath ending at vertex `index`.
    #[inline]
    pub fn subpath(&self, index: usize) -> &[PathVertex] {
        let depth = self.vertices[index].depth as usize;
        &self.vertices[index - depth..=index]
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::Vec3;

    /// Two subpaths (depths 0, 1, 2 twice): the four vertices of depth ≥ 1 are picked
    /// uniformly, each by a quarter of [0, 1), and an empty cache picks nothing.
    #[test]
    fn a_pick_is_uniform_over_the_selectable_vertices() {
        let vertex = |depth| PathVertex { depth, ..PathVertex::surface_at(Vec3::ZERO) };
        let vertices: Vec<PathVertex> = [0, 1, 2, 0, 1, 2].into_iter().map(vertex).collect();
        let selectable = vertices.iter().enumerate().filter(|(_, v)| v.depth >= 1).map(|(i, _)| i as u32).collect();
        let cache = LightCache { vertices, selectable, paths: 2 };
        let picks: Vec<Option<usize>> =
            [0.0, 0.2499, 0.25, 0.6, 0.76, 1.0 - f32::EPSILON / 2.0].into_iter().map(|u| cache.pick(u)).collect();
        assert_eq!(picks, [Some(1), Some(1), Some(2), Some(4), Some(5), Some(5)]);
        assert_eq!(cache.subpath(5).len(), 3);
        cache.prefetch_subpath(0);
        let empty = LightCache { vertices: Vec::new(), selectable: Vec::new(), paths: 0 };
        assert_eq!(empty.pick(0.5), None);
        empty.prefetch_pick(0.5);
    }
}
