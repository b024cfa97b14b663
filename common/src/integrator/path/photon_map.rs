//! The photon map of an iteration: a hashed uniform grid over the light-vertex cache
//! (SmallVCM-style, cell size 2·r_max, 8-cell lookups). Built by counting sort in cache order,
//! so photons are visited in a deterministic order whatever the thread count.

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
        let cell = (2.0 * max_radius).max(1e-12);
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
        let c = (p - self.origin) * self.inv_cell;
        let f = c.floor();
        // the 2 × 2 × 2 cells nearest to p cover the sphere of radius cell / 2
        let lo = [
            if c.x - f.x < 0.5 { f.x as i32 - 1 } else { f.x as i32 },
            if c.y - f.y < 0.5 { f.y as i32 - 1 } else { f.y as i32 },
            if c.z - f.z < 0.5 { f.z as i32 - 1 } else { f.z as i32 },
        ];
        let mut seen = [usize::MAX; 8];
        let r2 = radius * radius;
        for k in 0..8 {
            let b = bucket_of(
                [lo[0] + (k & 1) as i32, lo[1] + ((k >> 1) & 1) as i32, lo[2] + ((k >> 2) & 1) as i32],
                self.mask,
            );
            // cells can collide in one bucket: visit each bucket once
            if seen[..k].contains(&b) {
                continue;
            }
            seen[k] = b;
            let range = self.starts[b] as usize..self.starts[b + 1] as usize;
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

    #[test]
    fn queries_find_exactly_the_photons_within_the_radius() {
        let vertices: Vec<PathVertex> = (0..5000)
            .map(|i| {
                let mut s = Sampler::for_pixel(1, i, 0);
                vertex(s.next_2d().extend(s.next_1d()) * 2.0 - 1.0)
            })
            .collect();
        let all: Vec<u32> = (0..vertices.len() as u32).collect();
        let map = PhotonMap::build(&vertices, &all, 0.1);
        for q in 0..200 {
            let mut s = Sampler::for_pixel(2, q, 0);
            let p = s.next_2d().extend(s.next_1d()) * 2.2 - 1.1;
            let r = 0.02 + 0.08 * s.next_1d();
            let mut found = vec![];
            map.query(p, r, |i, _| found.push(i));
            let mut expected: Vec<u32> =
                all.iter().copied().filter(|&i| (vertices[i as usize].p - p).length() <= r).collect();
            found.sort();
            expected.sort();
            assert_eq!(found, expected, "query {q}");
        }
    }
}
