//! A top-down binned surface-area-heuristic (SAH) builder for a binary BVH over primitive
//! bounds. [`super::accel`] collapses its output into obvhs's wide BVH.
//!
//! Why our own rather than obvhs's PLOC builder: faster traversal on room-like scenes, and a
//! plain, dependency-free function of the boxes (docs/decisions/0010-sah-builder.md).

use glam::Vec3;

/// Bins per axis: with 16–32 bins the tree is within a few percent of a full sweep.
const BINS: usize = 32;

/// Beyond this depth ranges are halved without looking at the SAH, which bounds the recursion
/// on pathological inputs (centroids spaced so that every SAH split cuts off one primitive).
const MAX_SAH_DEPTH: u32 = 64;

/// An axis-aligned box.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Bounds {
    /// Minimum corner.
    pub lo: Vec3,
    /// Maximum corner.
    pub hi: Vec3,
}

impl Bounds {
    /// The empty box (the identity of [`Bounds::union`]).
    pub const EMPTY: Bounds = Bounds { lo: Vec3::splat(f32::INFINITY), hi: Vec3::splat(f32::NEG_INFINITY) };

    /// The smallest box holding both.
    #[inline]
    pub fn union(self, other: Bounds) -> Bounds {
        Bounds { lo: self.lo.min(other.lo), hi: self.hi.max(other.hi) }
    }

    /// Half the surface area; 0 for an empty box.
    #[inline]
    pub fn half_area(self) -> f32 {
        let d = (self.hi - self.lo).max(Vec3::ZERO);
        d.x * d.y + d.y * d.z + d.z * d.x
    }

    fn centroid(self) -> Vec3 {
        0.5 * (self.lo + self.hi)
    }
}

/// A node of the binary tree: a leaf holds exactly one primitive.
#[derive(Clone, Copy, Debug)]
pub struct BinaryNode {
    /// The node's box.
    pub bounds: Bounds,
    /// Leaf: position in [`BinaryBvh::order`]. Inner: index of the left child; the right child
    /// follows it.
    pub first: u32,
    /// Whether the node is a leaf.
    pub leaf: bool,
}

/// A binary BVH whose leaves hold one primitive each.
#[derive(Clone, Debug, Default)]
pub struct BinaryBvh {
    /// Nodes; the root is node 0.
    pub nodes: Vec<BinaryNode>,
    /// Primitive indices in leaf order.
    pub order: Vec<u32>,
}

/// Builds the tree over `bounds` (one box per primitive).
///
/// Serial, with an explicit work stack and the node array allocated once: for a million
/// triangles a tree of boxed halves (built on two threads) raised the load's peak memory by
/// about 90 MB for a second's gain.
pub fn build(bounds: &[Bounds]) -> BinaryBvh {
    if bounds.is_empty() {
        return BinaryBvh::default();
    }
    let mut order: Vec<u32> = (0..bounds.len() as u32).collect();
    let mut nodes = Vec::with_capacity(2 * bounds.len() - 1);
    nodes.push(BinaryNode { bounds: Bounds::EMPTY, first: 0, leaf: true });
    // (node, range of `order`, depth)
    let mut work = vec![(0usize, 0usize, bounds.len(), 0u32)];
    while let Some((node, start, end, depth)) = work.pop() {
        let range = &mut order[start..end];
        let node_bounds = range.iter().fold(Bounds::EMPTY, |b, &i| b.union(bounds[i as usize]));
        if range.len() == 1 {
            nodes[node] = BinaryNode { bounds: node_bounds, first: start as u32, leaf: true };
            continue;
        }
        let mid = start + if depth < MAX_SAH_DEPTH { split(bounds, range) } else { range.len() / 2 };
        let left = nodes.len();
        nodes.push(BinaryNode { bounds: Bounds::EMPTY, first: 0, leaf: true });
        nodes.push(BinaryNode { bounds: Bounds::EMPTY, first: 0, leaf: true });
        nodes[node] = BinaryNode { bounds: node_bounds, first: left as u32, leaf: false };
        work.push((left, start, mid, depth + 1));
        work.push((left + 1, mid, end, depth + 1));
    }
    BinaryBvh { nodes, order }
}

/// Partitions `order` (two or more primitives) by the cheapest binned SAH plane and returns
/// the size of the left part, which is in `1..order.len()`.
fn split(bounds: &[Bounds], order: &mut [u32]) -> usize {
    let centroids = order.iter().fold(Bounds::EMPTY, |b, &i| {
        let c = bounds[i as usize].centroid();
        b.union(Bounds { lo: c, hi: c })
    });
    let extent = centroids.hi - centroids.lo;
    let mut best: Option<(f32, usize, usize)> = None; // (cost, axis, bins left of the plane)
    for axis in 0..3 {
        if !(extent[axis] > 0.0) {
            continue;
        }
        let scale = BINS as f32 / extent[axis];
        let bin_of = |i: u32| -> usize {
            let c = bounds[i as usize].centroid()[axis];
            (((c - centroids.lo[axis]) * scale) as usize).min(BINS - 1)
        };
        let mut bin_bounds = [Bounds::EMPTY; BINS];
        let mut bin_counts = [0usize; BINS];
        for &i in order.iter() {
            let b = bin_of(i);
            bin_bounds[b] = bin_bounds[b].union(bounds[i as usize]);
            bin_counts[b] += 1;
        }
        // sweep from the right, then from the left
        let mut right_cost = [0.0f32; BINS];
        let (mut acc, mut count) = (Bounds::EMPTY, 0usize);
        for b in (1..BINS).rev() {
            acc = acc.union(bin_bounds[b]);
            count += bin_counts[b];
            right_cost[b] = acc.half_area() * count as f32;
        }
        let (mut acc, mut count) = (Bounds::EMPTY, 0usize);
        for b in 1..BINS {
            acc = acc.union(bin_bounds[b - 1]);
            count += bin_counts[b - 1];
            if count == 0 || count == order.len() {
                continue;
            }
            let cost = acc.half_area() * count as f32 + right_cost[b];
            if best.is_none_or(|(c, _, _)| cost < c) {
                best = Some((cost, axis, b));
            }
        }
    }
    let Some((_, axis, plane)) = best else {
        // every centroid coincides: any split is as good as another
        return order.len() / 2;
    };
    let scale = BINS as f32 / extent[axis];
    let lo = centroids.lo[axis];
    let left_of = |i: &u32| (((bounds[*i as usize].centroid()[axis] - lo) * scale) as usize).min(BINS - 1) < plane;
    partition(order, left_of)
}

/// Moves the elements satisfying `pred` to the front; returns how many there are.
fn partition(order: &mut [u32], pred: impl Fn(&u32) -> bool) -> usize {
    let mut first = 0;
    for i in 0..order.len() {
        if pred(&order[i]) {
            order.swap(first, i);
            first += 1;
        }
    }
    first
}

#[cfg(test)]
mod tests {
    use super::*;

    fn point_box(x: f32, y: f32, z: f32) -> Bounds {
        let p = Vec3::new(x, y, z);
        Bounds { lo: p - 0.1, hi: p + 0.1 }
    }

    /// Every primitive is in exactly one leaf, every inner box contains its children's boxes.
    fn check(tree: &BinaryBvh, bounds: &[Bounds]) {
        let mut seen = vec![0; bounds.len()];
        let mut stack = vec![0usize];
        while let Some(n) = stack.pop() {
            let node = tree.nodes[n];
            if node.leaf {
                let prim = tree.order[node.first as usize] as usize;
                seen[prim] += 1;
                assert_eq!(node.bounds, bounds[prim]);
            } else {
                for c in [node.first as usize, node.first as usize + 1] {
                    let child = tree.nodes[c].bounds;
                    assert_eq!(node.bounds.union(child), node.bounds);
                    stack.push(c);
                }
            }
        }
        assert!(seen.iter().all(|&s| s == 1), "each primitive in one leaf: {seen:?}");
        assert_eq!(tree.nodes.len(), 2 * bounds.len() - 1);
    }

    #[test]
    fn separates_two_clusters_at_the_root() {
        let mut bounds: Vec<Bounds> = (0..10).map(|i| point_box(i as f32 * 0.01, 0.0, 0.0)).collect();
        bounds.extend((0..10).map(|i| point_box(100.0 + i as f32 * 0.01, 0.0, 0.0)));
        let tree = build(&bounds);
        check(&tree, &bounds);
        let root = tree.nodes[0];
        let left = tree.nodes[root.first as usize].bounds;
        let right = tree.nodes[root.first as usize + 1].bounds;
        assert!(left.hi.x < 50.0 && right.lo.x > 50.0 || right.hi.x < 50.0 && left.lo.x > 50.0);
    }

    #[test]
    fn handles_one_primitive_coincident_centroids_and_many() {
        let one = [point_box(1.0, 2.0, 3.0)];
        check(&build(&one), &one);
        let same = vec![point_box(1.0, 1.0, 1.0); 7];
        check(&build(&same), &same);
        let many: Vec<Bounds> =
            (0..40_000).map(|i| point_box((i % 37) as f32, (i % 101) as f32 * 0.5, (i / 1000) as f32)).collect();
        check(&build(&many), &many);
        assert!(build(&[]).nodes.is_empty());
    }
}
