//! The light-vertex cache of one iteration (Davidovič et al. 2014): N light subpaths traced in
//! parallel chunks and stored back to back, so that connections can pick any vertex uniformly
//! and merges can walk a photon's subpath. Shared by `bdpt` and `vcm`.

use super::light_path::{LIGHT_PATH_CHUNK, trace_light_path};
use super::prefetch::prefetch;
use super::vertex::PathVertex;
use crate::sampler::Sampler;
use crate::scene::Scene;
use rayon::prelude::*;
use std::sync::Mutex;

/// One iteration's light subpaths, stored back to back.
#[derive(Default)]
pub struct LightCache {
    /// All vertices; a vertex at depth d is preceded by its subpath's d earlier vertices.
    pub vertices: Vec<PathVertex>,
    /// Indices of the vertices connections may choose (depth ≥ 1).
    pub selectable: Vec<u32>,
    /// Number of light paths.
    pub paths: u32,
    /// Per chunk of light paths, the vertices traced in parallel before they are joined: kept
    /// with their capacity, as `vertices` and `selectable` are, for [`LightCache::retrace`].
    chunks: Vec<Vec<PathVertex>>,
}

impl LightCache {
    /// Traces `paths` light paths of iteration `iteration`, in parallel chunks concatenated in
    /// order, so the cache does not depend on the thread count.
    pub fn trace(scene: &Scene, seed: u64, iteration: u32, paths: u32, max_edges: u32, rr_depth: u32) -> Self {
        let mut cache = LightCache::default();
        cache.retrace(scene, seed, iteration, paths, max_edges, rr_depth);
        cache
    }

    /// As [`LightCache::trace`], into this cache's memory: a cache is tens of megabytes, and
    /// memory allocated anew every iteration comes from the kernel as fresh pages, whose faults
    /// cost a tenth of a `vcm` iteration (docs/decisions/0049-light-caches-reuse-memory.md).
    pub fn retrace(&mut self, scene: &Scene, seed: u64, iteration: u32, paths: u32, max_edges: u32, rr_depth: u32) {
        let count = paths.div_ceil(LIGHT_PATH_CHUNK) as usize;
        self.chunks.resize_with(count.max(self.chunks.len()), Vec::new);
        self.chunks[..count].par_iter_mut().enumerate().for_each(|(c, out)| {
            out.clear();
            let c = c as u32;
            for index in c * LIGHT_PATH_CHUNK..((c + 1) * LIGHT_PATH_CHUNK).min(paths) {
                trace_light_path(scene, &mut Sampler::for_light_path(seed, index, iteration), max_edges, rr_depth, out);
            }
        });
        self.vertices.clear();
        self.vertices.reserve_exact(self.chunks[..count].iter().map(Vec::len).sum());
        for chunk in &self.chunks[..count] {
            self.vertices.extend_from_slice(chunk);
        }
        self.selectable.clear();
        let selectable = self.vertices.iter().enumerate().filter(|(_, v)| v.depth >= 1).map(|(i, _)| i as u32);
        self.selectable.extend(selectable);
        self.paths = paths;
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

/// The light-vertex caches (an iteration's and a light probe's) one `render_tile` call of an
/// integrator leaves for the next, which may be another integrator's (an EMIS render builds one
/// per call): `render` calls it once per iteration, and a cache allocated anew each time comes
/// from the kernel as fresh pages. It holds the largest iteration's cache and per-chunk
/// vectors until it is dropped, at the end of a render or a worker's batch.
#[derive(Default)]
pub struct CacheMemory(Mutex<(LightCache, LightCache)>);

impl CacheMemory {
    /// The caches left by the last call (empty ones while another call holds them).
    pub fn take(&self) -> (LightCache, LightCache) {
        std::mem::take(&mut *self.0.lock().unwrap_or_else(|poisoned| poisoned.into_inner()))
    }

    /// Keeps `cache` and `probe` for the next call.
    pub fn put(&self, cache: LightCache, probe: LightCache) {
        *self.0.lock().unwrap_or_else(|poisoned| poisoned.into_inner()) = (cache, probe);
    }
}

impl std::fmt::Debug for CacheMemory {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str("CacheMemory")
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
        let cache = LightCache { vertices, selectable, paths: 2, chunks: Vec::new() };
        let picks: Vec<Option<usize>> =
            [0.0, 0.2499, 0.25, 0.6, 0.76, 1.0 - f32::EPSILON / 2.0].into_iter().map(|u| cache.pick(u)).collect();
        assert_eq!(picks, [Some(1), Some(1), Some(2), Some(4), Some(5), Some(5)]);
        assert_eq!(cache.subpath(5).len(), 3);
        cache.prefetch_subpath(0);
        let empty = LightCache::default();
        assert_eq!(empty.pick(0.5), None);
        empty.prefetch_pick(0.5);
    }

    /// A cache traced into the memory of a larger one, and then of a smaller one, holds what a
    /// fresh cache of that iteration holds, vertex for vertex.
    #[test]
    fn a_retraced_cache_equals_a_fresh_one() {
        let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../scenes/cornell-box/scene.xml");
        let scene = Scene::load(&path).expect("scene loads");
        let fresh = |iteration, paths| LightCache::trace(&scene, 7, iteration, paths, 8, 5);
        let key = |c: &LightCache| {
            let v: Vec<_> =
                c.vertices.iter().map(|v| (v.p.to_array(), v.beta, v.pdf_fwd, v.pdf_rev, v.depth)).collect();
            (v, c.selectable.clone(), c.paths)
        };
        let mut reused = fresh(0, 3000);
        for (iteration, paths) in [(1, 700), (2, 2000), (3, 0)] {
            reused.retrace(&scene, 7, iteration, paths, 8, 5);
            assert_eq!(key(&reused), key(&fresh(iteration, paths)), "iteration {iteration}");
        }
        assert!(reused.vertices.is_empty() && reused.selectable.is_empty());
    }
}
