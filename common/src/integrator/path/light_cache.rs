//! The light-vertex cache of one iteration (Davidovič et al. 2014): N light subpaths traced in
//! parallel chunks and stored back to back, so that connections can pick any vertex uniformly
//! and merges can walk a photon's subpath. Shared by `bdpt` and `vcm`.

use super::light_path::{LIGHT_PATH_CHUNK, trace_light_path};
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

    /// The light subpath ending at vertex `index`.
    #[inline]
    pub fn subpath(&self, index: usize) -> &[PathVertex] {
        let depth = self.vertices[index].depth as usize;
        &self.vertices[index - depth..=index]
    }
}
