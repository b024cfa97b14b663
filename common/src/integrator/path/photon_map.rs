//! The photon map of an iteration: a hashed uniform grid over the light-vertex cache
//! (SmallVCM-style, cell size 2·r_max; a query visits the cells its bounding cube overlaps).
//! Built by counting sort in cache order, so photons are visited in a deterministic order
//! whatever the thread count.

use crate::integrator::path::vertex::PathVertex;
use glam::Vec3;

/// A hashed grid of photon indices.
pub struct PhotonMap {
    origin: Vec3,
    inv_cell: f32,
    mask: usize,
    /// `starts[b]..starts[b + 1]` are bucket b's photons in `photons`.
    starts: Vec<u32>,
    /// Photon (cache vertex) indices grouped by bucket, ascending within a bucket.
    photons: Vec<u32>,
    /// Their positions in the same order, so distance tests read contiguous memory.
    positions: Vec<Vec3>,
}

#[inline]
fn bucket_of(cell: [i32; 3], mask: usize) -> usize {
    // Teschner et al. 2003 spatial hash
    let h = (cell[0] as u32).wrapping_mul(73_856_093)
        ^ (cell[1] as u32).wrapping_mul(19_349_663)
        ^ (cell[2] as u32).wrapping_mul(83_492_791);
    h as usize & mask
}

impl PhotonMap {
    /// Builds the map over `vertices[i]` for every `i` in `candidates`, for queries of radius at
    /// most `max_radius`.
    pub fn build(vertices: &[PathVertex], candidates: &[u32], max_radius: f32) -> Self {
        // a hair over 2·r_max, so that rounding never stretches a query over three cells
        let cell = (2.0 * max_radius * 1.001).max(1e-12);
        let origin = candidates.iter().fold(Vec3::splat(f32::MAX), |m, &i| m.min(vertices[i as usize].p));
        let buckets = (2 * candidates.len()).max(16).next_power_of_two();
        let mut map = PhotonMap {
            origin,
            inv_cell: 1.0 / cell,
            mask: buckets - 1,
            starts: vec![0; buckets + 1],
            photons: vec![0; candidates.len()],
            positions: vec![Vec3::ZERO; candidates.len()],
        };
        let keys: Vec<usize> =
            candidates.iter().map(|&i| bucket_of(map.cell_of(vertices[i as usize].p), map.mask)).collect();
        for &b in &keys {
            map.starts[b + 1] += 1;
        }
        for b in 0..buckets {
            map.starts[b + 1] += map.starts[b];
        }
        let mut fill = map.starts.clone();
        for (&i, &b) in candidates.iter().zip(&keys) {
            map.photons[fill[b] as usize] = i;
            map.positions[fill[b] as usize] = vertices[i as usize].p;
            fill[b] += 1;
        }
        map
    }

    #[inline]
    fn cell_of(&self, p: Vec3) -> [i32; 3] {
        let c = ((p - self.origin) * self.inv_cell).floor();
        [c.x as i32, c.y as i32, c.z as i32]
    }

    /// Number of photons.
    pub fn len(&self) -> usize {
        self.photons.len()
    }

    /// Whether the map is empty.
    pub fn is_empty(&self) -> bool {
        self.photons.is_empty()
    }

    /// Calls `visit(index, distance²)` for every photon within `radius` (≤ the build's maximum)
    /// of `p`, in a deterministic order.
    #[inline]
    pub fn query(&self, p: Vec3, radius: f32, mut visit: impl FnMut(u32, f32)) {
        if self.photons.is_empty() {
            return;
        }
        // the cells the cube around the sphere overlaps: one or two per axis, as a cell is
        // more than twice the largest radius
        let lo = ((p - radius - self.origin) * self.inv_cell).floor();
        let hi = ((p + radius - self.origin) * self.inv_cell).floor();
        let lo = [lo.x as i32, lo.y as i32, lo.z as i32];
        let span = [(hi.x as i32 > lo[0]) as i32, (hi.y as i32 > lo[1]) as i32, (hi.z as i32 > lo[2]) as i32];
        // every bucket first, then their ranges, then their photons: the loads of one step do
        // not wait on each other (queries are bound by memory latency, not arithmetic)
        let mut buckets = [0usize; 8];
        let mut n = 0;
        for z in 0..=span[2] {
            for y in 0..=span[1] {
                for x in 0..=span[0] {
                    let b = bucket_of([lo[0] + x, lo[1] + y, lo[2] + z], self.mask);
                    // cells can collide in one bucket: visit each bucket once
                    if !buckets[..n].contains(&b) {
                        buckets[n] = b;
                        n += 1;
                    }
                }
            }
        }
        let mut ranges = [(0u32, 0u32); 8];
        for (range, &b) in ranges.iter_mut().zip(&buckets[..n]) {
            *range = (self.starts[b], self.starts[b + 1]);
        }
        let r2 = radius * radius;
        for &(start, end) in &ranges[..n] {
            let range = start as usize..end as usize;
            for (&i, q) in self.photons[range.clone()].iter().zip(&self.positions[range]) {
                let d2 = (*q - p).length_squared();
                if d2 <= r2 {
                    visit(i, d2);
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sampler::Sampler;

    fn vertex(p: Vec3) -> PathVertex {
        PathVertex::surface_at(p)
    }

    /// Builds a map over `photons` points in the cube [−extent, extent]³ for radius `max`,
    /// and checks `queries` queries of radius `min`…`max` (centres a little beyond the cube)
    /// against brute force: every photon within the radius exactly once.
    fn assert_queries_match_brute_force(photons: u32, extent: f32, max: f32, min: f32, queries: u32) {
        let point = |seed: u64, i: u32, half: f32| {
            let mut s = Sampler::for_pixel(seed, i, 0);
            (s.next_2d().extend(s.next_1d()) * 2.0 - 1.0) * half
        };
        let vertices: Vec<PathVertex> = (0..photons).map(|i| vertex(point(1, i, extent))).collect();
        let all: Vec<u32> = (0..photons).collect();
        let map = PhotonMap::build(&vertices, &all, max);
        for q in 0..queries {
            let p = point(2, q, 1.1 * extent + max);
            let r = min + (max - min) * Sampler::for_pixel(3, q, 0).next_1d();
            let mut found = vec![];
            map.query(p, r, |i, _| found.push(i));
            let mut expected: Vec<u32> =
                all.iter().copied().filter(|&i| (vertices[i as usize].p - p).length() <= r).collect();
            found.sort();
            expected.sort();
            assert_eq!(found, expected, "query {q}");
        }
    }

    #[test]
    fn queries_find_exactly_the_photons_within_the_radius() {
        assert_queries_match_brute_force(5000, 1.0, 0.1, 0.02, 200);
    }

    #[test]
    fn colliding_cells_are_visited_once() {
        // 24 photons hash into 64 buckets, so the cells a query overlaps often share one
        assert_queries_match_brute_force(24, 3.0, 0.5, 0.0, 2000);
    }
}
