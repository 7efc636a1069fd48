//! A bounding volume hierarchy over triangles, built on the CPU with the surface area heuristic
//! and laid out for traversal on the GPU.
//!
//! Nodes are stored depth-first in one array; the two children of an interior node are
//! adjacent (`left`, `left + 1`), so a node is 32 bytes: bounds and two integers.

use glam::Vec3;

/// Leaves hold at most this many triangles.
pub const MAX_LEAF_TRIANGLES: usize = 4;
/// SAH bins per axis. 32 instead of 12 took the rays of living-room (143k triangles, lavapipe, 384×216,
/// 8 spp) from 15.0 to 12.9 node steps each and rendered it 1.06× as fast (three alternating pairs).
const BINS: usize = 32;
/// The deepest node split by the SAH; deeper ones split their range in half (see `Builder::build`).
pub const MAX_SAH_DEPTH: usize = 48;
/// Cost of one ray-box test relative to one ray-triangle test, in the SAH.
const TRAVERSAL_COST: f32 = 1.0;

/// One node: a leaf when `count > 0` (triangles `first .. first + count` of [`Bvh::order`]),
/// otherwise an interior node whose children are `first` and `first + 1`.
#[derive(Clone, Copy, Debug, PartialEq)]
#[repr(C)]
pub struct BvhNode {
    pub min: [f32; 3],
    pub first: u32,
    pub max: [f32; 3],
    pub count: u32,
}

/// The hierarchy and the triangle order its leaves refer to.
#[derive(Clone, Debug, Default)]
pub struct Bvh {
    pub nodes: Vec<BvhNode>,
    /// `order[k]` is the index (into the input) of the k-th triangle in leaf order.
    pub order: Vec<u32>,
}

#[derive(Clone, Copy)]
struct Aabb {
    min: Vec3,
    max: Vec3,
}

impl Aabb {
    const EMPTY: Aabb = Aabb { min: Vec3::splat(f32::INFINITY), max: Vec3::splat(f32::NEG_INFINITY) };

    fn grow(&mut self, p: Vec3) {
        self.min = self.min.min(p);
        self.max = self.max.max(p);
    }

    fn union(&mut self, o: &Aabb) {
        self.min = self.min.min(o.min);
        self.max = self.max.max(o.max);
    }

    fn area(&self) -> f32 {
        let e = self.max - self.min;
        if e.min_element() < 0.0 {
            return 0.0;
        }
        2.0 * (e.x * e.y + e.y * e.z + e.z * e.x)
    }
}

impl Bvh {
    /// Builds the hierarchy over `triangles` (world-space corners). An empty input gives a single
    /// zero node, which must not be traversed.
    pub fn build(triangles: &[[Vec3; 3]]) -> Bvh {
        let bounds: Vec<(Vec3, Vec3)> =
            triangles.iter().map(|t| (t[0].min(t[1]).min(t[2]), t[0].max(t[1]).max(t[2]))).collect();
        let centroids: Vec<Vec3> = triangles.iter().map(|t| (t[0] + t[1] + t[2]) / 3.0).collect();
        Bvh::build_bounds(&bounds, &centroids)
    }

    /// Builds the hierarchy over primitives given by their bounds (min, max) and the points
    /// they are sorted by (a triangle's centroid, a shape's centre), for scenes that mix
    /// triangles with other primitives; each counts as one triangle in the SAH and the leaf size.
    pub fn build_bounds(bounds: &[(Vec3, Vec3)], centroids: &[Vec3]) -> Bvh {
        assert_eq!(bounds.len(), centroids.len(), "one centroid per primitive");
        let boxes: Vec<Aabb> = bounds.iter().map(|&(min, max)| Aabb { min, max }).collect();
        let mut order: Vec<u32> = (0..bounds.len() as u32).collect();
        let mut nodes = vec![BvhNode { min: [0.0; 3], first: 0, max: [0.0; 3], count: 0 }];
        let mut builder = Builder { boxes: &boxes, centroids, order: &mut order, nodes: &mut nodes };
        builder.build(0, 0, bounds.len(), 1);
        Bvh { nodes, order }
    }

    /// Depth of the deepest leaf (the root has depth 1), for sizing traversal stacks.
    pub fn depth(&self) -> usize {
        fn walk(nodes: &[BvhNode], i: usize) -> usize {
            let n = &nodes[i];
            if n.count > 0 || nodes.len() == 1 {
                // A leaf, or the zero node of an empty hierarchy.
                1
            } else {
                1 + walk(nodes, n.first as usize).max(walk(nodes, n.first as usize + 1))
            }
        }
        if self.nodes.is_empty() { 0 } else { walk(&self.nodes, 0) }
    }
}

struct Builder<'a> {
    boxes: &'a [Aabb],
    centroids: &'a [Vec3],
    order: &'a mut Vec<u32>,
    nodes: &'a mut Vec<BvhNode>,
}

impl Builder<'_> {
    fn bounds(&self, start: usize, end: usize) -> (Aabb, Aabb) {
        let mut b = Aabb::EMPTY;
        let mut c = Aabb::EMPTY;
        for &t in &self.order[start..end] {
            b.union(&self.boxes[t as usize]);
            c.grow(self.centroids[t as usize]);
        }
        (b, c)
    }

    /// Fills node `index` (at `depth`, the root's is 1) with triangles `order[start..end]`, recursing into
    /// children. From [`MAX_SAH_DEPTH`] on, every split halves the range, so no input (say, centroids spaced
    /// ever more widely, which the SAH peels one at a time) makes the tree deeper than that plus log2 of the
    /// triangle count.
    fn build(&mut self, index: usize, start: usize, end: usize, depth: usize) {
        let (bounds, cbounds) = self.bounds(start, end);
        let count = end - start;
        let leaf = |nodes: &mut Vec<BvhNode>| {
            nodes[index] = BvhNode {
                min: bounds.min.to_array(),
                first: start as u32,
                max: bounds.max.to_array(),
                count: count as u32,
            };
        };
        // Only an empty input reaches a node with no triangles: it stays a zero node, and
        // traversal never starts on a scene without triangles.
        if count <= 1 {
            if count == 1 {
                leaf(self.nodes);
            }
            return;
        }
        let split = if depth < MAX_SAH_DEPTH { self.best_split(start, end, &bounds, &cbounds) } else { None };
        let Some((axis, position)) = split else {
            if count <= MAX_LEAF_TRIANGLES {
                leaf(self.nodes);
                return;
            }
            // No useful SAH split (e.g. identical centroids), or too deep for one: split the range in half.
            let mid = start + count / 2;
            self.split_children(index, &bounds, start, mid, end, depth);
            return;
        };
        let (mut i, mut j) = (start, end);
        while i < j {
            if self.centroids[self.order[i] as usize][axis] < position {
                i += 1;
            } else {
                j -= 1;
                self.order.swap(i, j);
            }
        }
        let mid = if i == start || i == end { start + count / 2 } else { i };
        self.split_children(index, &bounds, start, mid, end, depth);
    }

    fn split_children(&mut self, index: usize, bounds: &Aabb, start: usize, mid: usize, end: usize, depth: usize) {
        let left = self.nodes.len();
        let empty = BvhNode { min: [0.0; 3], first: 0, max: [0.0; 3], count: 0 };
        self.nodes.push(empty);
        self.nodes.push(empty);
        self.nodes[index] =
            BvhNode { min: bounds.min.to_array(), first: left as u32, max: bounds.max.to_array(), count: 0 };
        self.build(left, start, mid, depth + 1);
        self.build(left + 1, mid, end, depth + 1);
    }

    /// The binned SAH split (axis, centroid threshold), or `None` when a leaf is cheaper.
    fn best_split(&self, start: usize, end: usize, bounds: &Aabb, cbounds: &Aabb) -> Option<(usize, f32)> {
        let count = end - start;
        let leaf_cost = count as f32;
        let mut best: Option<(f32, usize, f32)> = None;
        for axis in 0..3 {
            let (lo, hi) = (cbounds.min[axis], cbounds.max[axis]);
            if hi - lo <= 0.0 {
                continue;
            }
            let scale = BINS as f32 / (hi - lo);
            let mut bins = [(Aabb::EMPTY, 0usize); BINS];
            for &t in &self.order[start..end] {
                let b = (((self.centroids[t as usize][axis] - lo) * scale) as usize).min(BINS - 1);
                bins[b].0.union(&self.boxes[t as usize]);
                bins[b].1 += 1;
            }
            // Sweep from the left and from the right.
            let mut left_area = [0.0f32; BINS - 1];
            let mut left_count = [0usize; BINS - 1];
            let (mut acc, mut n) = (Aabb::EMPTY, 0);
            for k in 0..BINS - 1 {
                acc.union(&bins[k].0);
                n += bins[k].1;
                left_area[k] = acc.area();
                left_count[k] = n;
            }
            let (mut acc, mut n) = (Aabb::EMPTY, 0);
            for k in (1..BINS).rev() {
                acc.union(&bins[k].0);
                n += bins[k].1;
                let (nl, nr) = (left_count[k - 1], n);
                if nl == 0 || nr == 0 {
                    continue;
                }
                let cost =
                    TRAVERSAL_COST + (left_area[k - 1] * nl as f32 + acc.area() * nr as f32) / bounds.area().max(1e-30);
                if best.is_none_or(|(c, _, _)| cost < c) {
                    best = Some((cost, axis, lo + k as f32 / scale));
                }
            }
        }
        match best {
            Some((cost, axis, pos)) if cost < leaf_cost || count > MAX_LEAF_TRIANGLES => Some((axis, pos)),
            _ => None,
        }
    }
}
