//! The BVH as the kernel walks it: four children per node, their boxes quantized to 8 bits per
//! plane against the node's own box, as compressed wide BVHs do (Ylitie, Karras and Laine 2017,
//! with four children instead of eight).
//!
//! On CPU drivers such as lavapipe, an invocation's loads from a storage buffer run one SIMD lane
//! at a time, word by word, and they took about two thirds of a BVH-bound render's kernel time; a
//! binary node step loaded 14 words for two child boxes. A wide node loads 12 words for up to four
//! boxes, and a ray takes about half as many steps. On a GPU the same layout is the one that
//! hardware-less traversal kernels use to save memory bandwidth.
//!
//! Layout of [`GpuWideNode`] (three `vec4<u32>`, read as `WideNode` in path.wgsl):
//! - `a.xyz`: the node box's lower corner (`f32` bits); `a.w`: per axis, the biased exponent `e` of
//!   the quantization step 2^(e − 127) in bits 0–7 (x), 8–15 (y) and 16–23 (z);
//! - `b`: per child c (byte c of each word), the lower planes x, y, z and the upper plane x;
//!   `c.x`, `c.y`: the upper planes y and z; a child's plane is `corner + q · step`, computed in
//!   `f32` exactly as the kernel does, and rounded outward, so a quantized box always holds the
//!   exact one;
//! - `c.z`: bits 0–25 the first interior child's node index (interior children are consecutive),
//!   bits 26–31 the kinds of children 0 and 1; `c.w`: bits 0–25 the first triangle of the leaf
//!   children (whose triangles are consecutive, in child order), bits 26–31 the kinds of children
//!   2 and 3. A kind is 0 for an empty slot, 1–4 for a leaf of that many triangles, 7 for an
//!   interior node.

use bytemuck::{Pod, Zeroable};
use hush_scene::{Bvh, BvhNode, MAX_LEAF_TRIANGLES};

/// Children per node.
pub(crate) const WIDTH: usize = 4;
/// Node and triangle indices must fit in this many bits (see the layout above).
const INDEX_BITS: u32 = 26;
const KIND_EMPTY: u32 = 0;
const KIND_INTERIOR: u32 = 7;

#[repr(C)]
#[derive(Clone, Copy, Debug, Pod, Zeroable, PartialEq)]
pub(crate) struct GpuWideNode {
    pub a: [u32; 4],
    pub b: [u32; 4],
    pub c: [u32; 4],
}

/// The wide BVH and the order of the triangles its leaves refer to.
#[derive(Debug)]
pub(crate) struct WideBvh {
    pub nodes: Vec<GpuWideNode>,
    /// `order[k]` is the position in the binary BVH's triangle order of the k-th triangle here.
    pub order: Vec<u32>,
    /// Entries the traversal stack needs at most (children pushed along the deepest path).
    pub stack: usize,
}

/// Whether a binary node is a leaf (it holds triangles).
fn is_leaf(n: &BvhNode) -> bool {
    n.count > 0
}

fn area(n: &BvhNode) -> f32 {
    let e = [n.max[0] - n.min[0], n.max[1] - n.min[1], n.max[2] - n.min[2]];
    2.0 * (e[0] * e[1] + e[1] * e[2] + e[2] * e[0])
}

/// The up to four binary nodes that become node `index`'s children: its two, then repeatedly the
/// interior one with the largest surface area opened into its two.
fn collapse(nodes: &[BvhNode], index: usize) -> Vec<usize> {
    let n = &nodes[index];
    if is_leaf(n) {
        return vec![index];
    }
    let mut children = vec![n.first as usize, n.first as usize + 1];
    while children.len() < WIDTH {
        let open = children
            .iter()
            .enumerate()
            .filter(|(_, c)| !is_leaf(&nodes[**c]))
            .max_by(|a, b| area(&nodes[*a.1]).total_cmp(&area(&nodes[*b.1])))
            .map(|(k, _)| k);
        let Some(k) = open else { break };
        let c = children.remove(k);
        children.insert(k, nodes[c].first as usize + 1);
        children.insert(k, nodes[c].first as usize);
    }
    children
}

/// The biased exponent of the smallest power-of-two step with which 255 steps from `lo` reach
/// `hi` in `f32`.
fn step_exponent(lo: f32, hi: f32) -> u32 {
    let extent = (hi - lo).max(0.0) as f64;
    let mut e = if extent > 0.0 { ((extent / 255.0).log2().ceil() as i32).clamp(-126, 127) } else { -126 };
    while e < 127 && lo + 255.0 * step_of_biased((e + 127) as u32) < hi {
        e += 1;
    }
    (e + 127) as u32
}

fn step_of_biased(biased: u32) -> f32 {
    f32::from_bits(biased << 23)
}

/// Quantizes `[lo, hi]` against `corner` with `step`, rounding outward as the kernel decodes it.
fn quantize(lo: f32, hi: f32, corner: f32, step: f32) -> (u32, u32) {
    let decode = |q: u32| corner + q as f32 * step;
    let mut qlo = (((lo - corner) / step).floor().max(0.0) as u32).min(255);
    while qlo > 0 && decode(qlo) > lo {
        qlo -= 1;
    }
    let mut qhi = (((hi - corner) / step).ceil().max(0.0) as u32).min(255);
    while qhi < 255 && decode(qhi) < hi {
        qhi += 1;
    }
    (qlo, qhi)
}

impl WideBvh {
    /// Collapses `bvh` (built over `triangles` slots) into four-wide quantized nodes. An empty
    /// hierarchy gives one node with no children.
    pub fn build(bvh: &Bvh) -> Result<WideBvh, String> {
        let total: usize = bvh.nodes.iter().filter(|n| is_leaf(n)).map(|n| n.count as usize).sum();
        if bvh.nodes.len() >= 1 << INDEX_BITS || total >= 1 << INDEX_BITS {
            return Err(format!("the scene has {total} triangles and shapes; the kernel's BVH holds fewer than 2^26"));
        }
        let mut wide = WideBvh { nodes: vec![GpuWideNode::zeroed()], order: Vec::with_capacity(total), stack: 0 };
        if total > 0 {
            wide.stack = wide.fill(&bvh.nodes, 0, 0);
        }
        Ok(wide)
    }

    /// Writes wide node `slot` for binary node `index`; returns the stack entries its subtree needs.
    fn fill(&mut self, nodes: &[BvhNode], slot: usize, index: usize) -> usize {
        let children = collapse(nodes, index);
        let n = &nodes[index];
        let exps: [u32; 3] = std::array::from_fn(|k| step_exponent(n.min[k], n.max[k]));
        let interior: Vec<usize> = children.iter().copied().filter(|&c| !is_leaf(&nodes[c])).collect();
        let child_base = self.nodes.len();
        self.nodes.resize(child_base + interior.len(), GpuWideNode::zeroed());
        let tri_base = self.order.len();
        let mut node = GpuWideNode::zeroed();
        node.a = [n.min[0].to_bits(), n.min[1].to_bits(), n.min[2].to_bits(), exps[0] | exps[1] << 8 | exps[2] << 16];
        let mut kinds = [KIND_EMPTY; WIDTH];
        for (k, &c) in children.iter().enumerate() {
            let cn = &nodes[c];
            let q: [(u32, u32); 3] =
                std::array::from_fn(|a| quantize(cn.min[a], cn.max[a], n.min[a], step_of_biased(exps[a])));
            let shift = 8 * k as u32;
            node.b[0] |= q[0].0 << shift;
            node.b[1] |= q[1].0 << shift;
            node.b[2] |= q[2].0 << shift;
            node.b[3] |= q[0].1 << shift;
            node.c[0] |= q[1].1 << shift;
            node.c[1] |= q[2].1 << shift;
            if is_leaf(cn) {
                debug_assert!(cn.count as usize <= MAX_LEAF_TRIANGLES);
                kinds[k] = cn.count;
                self.order.extend(cn.first..cn.first + cn.count);
            } else {
                kinds[k] = KIND_INTERIOR;
            }
        }
        // An empty slot's box is inverted (lower planes 255, upper 0), so no ray enters it.
        for k in children.len()..WIDTH {
            let shift = 8 * k as u32;
            node.b[0] |= 255 << shift;
            node.b[1] |= 255 << shift;
            node.b[2] |= 255 << shift;
        }
        node.c[2] = child_base as u32 | kinds[0] << INDEX_BITS | kinds[1] << (INDEX_BITS + 3);
        node.c[3] = tri_base as u32 | kinds[2] << INDEX_BITS | kinds[3] << (INDEX_BITS + 3);
        self.nodes[slot] = node;
        let mut deepest = 0;
        for (k, &c) in interior.iter().enumerate() {
            deepest = deepest.max(self.fill(nodes, child_base + k, c));
        }
        // A step pushes every child but the nearest.
        children.len() - 1 + deepest
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::Vec3;

    /// Random triangles of varied sizes in a 10-unit cube, from a fixed LCG.
    fn soup(n: usize, seed: u64) -> Vec<[Vec3; 3]> {
        let mut s = seed;
        let mut r = move || {
            s = s.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
            (s >> 40) as f32 / (1u64 << 24) as f32
        };
        (0..n)
            .map(|_| {
                let c = Vec3::new(r(), r(), r()) * 10.0 - 5.0;
                let size = 0.01 + 2.0 * r() * r();
                [c, c + Vec3::new(r(), r(), r()) * size, c + Vec3::new(r(), -r(), r()) * size]
            })
            .collect()
    }

    struct Decoded {
        lo: Vec3,
        hi: Vec3,
        kind: u32,
        index: u32,
    }

    /// The children of wide node `i` as the kernel decodes them.
    fn decode(node: &GpuWideNode) -> Vec<Decoded> {
        let corner =
            Vec3::from_array(node.a[..3].iter().map(|&b| f32::from_bits(b)).collect::<Vec<_>>().try_into().unwrap());
        let step = Vec3::new(
            step_of_biased(node.a[3] & 0xff),
            step_of_biased((node.a[3] >> 8) & 0xff),
            step_of_biased((node.a[3] >> 16) & 0xff),
        );
        let kinds = [(node.c[2] >> 26) & 7, node.c[2] >> 29, (node.c[3] >> 26) & 7, node.c[3] >> 29];
        let (mut next_node, mut next_tri) = (node.c[2] & 0x3ff_ffff, node.c[3] & 0x3ff_ffff);
        (0..WIDTH)
            .map(|c| {
                let byte = |w: u32| ((w >> (8 * c)) & 0xff) as f32;
                let lo = corner + Vec3::new(byte(node.b[0]), byte(node.b[1]), byte(node.b[2])) * step;
                let hi = corner + Vec3::new(byte(node.b[3]), byte(node.c[0]), byte(node.c[1])) * step;
                let index = if kinds[c] == KIND_INTERIOR {
                    next_node += 1;
                    next_node - 1
                } else {
                    next_tri += kinds[c];
                    next_tri - kinds[c]
                };
                Decoded { lo, hi, kind: kinds[c], index }
            })
            .collect()
    }

    /// Every triangle reachable from wide node `i`, checking that each lies inside the decoded boxes
    /// on its way down.
    fn reach(wide: &WideBvh, tris: &[[Vec3; 3]], i: usize, seen: &mut Vec<u32>, depth: usize) -> usize {
        let mut deepest = depth;
        for ch in decode(&wide.nodes[i]) {
            let inside = |t: u32| {
                let tri = &tris[wide.order[t as usize] as usize];
                tri.iter().all(|p| p.cmpge(ch.lo).all() && p.cmple(ch.hi).all())
            };
            match ch.kind {
                KIND_EMPTY => assert!(ch.lo.cmpgt(ch.hi).any(), "an empty slot's box must be inverted"),
                KIND_INTERIOR => {
                    let mut below = Vec::new();
                    deepest = deepest.max(reach(wide, tris, ch.index as usize, &mut below, depth + 1));
                    assert!(below.iter().all(|&t| inside(t)), "an interior child's box must hold its triangles");
                    seen.extend(below);
                }
                count => {
                    assert!((1..=MAX_LEAF_TRIANGLES as u32).contains(&count));
                    for t in ch.index..ch.index + count {
                        assert!(inside(t), "a leaf's box must hold its triangles");
                        seen.push(t);
                    }
                }
            }
        }
        deepest
    }

    fn bvh_of(tris: &[[Vec3; 3]]) -> (Bvh, WideBvh) {
        let bvh = Bvh::build(tris);
        let wide = WideBvh::build(&bvh).unwrap();
        (bvh, wide)
    }

    #[test]
    fn every_triangle_is_in_exactly_one_leaf_inside_its_quantized_boxes() {
        for (n, seed) in [(1, 1), (2, 2), (3, 3), (5, 4), (17, 5), (1000, 6), (5000, 7)] {
            let tris = soup(n, seed);
            let (bvh, wide) = bvh_of(&tris);
            // The wide order is a permutation of the binary order's positions.
            let mut sorted = wide.order.clone();
            sorted.sort_unstable();
            assert_eq!(sorted, (0..n as u32).collect::<Vec<_>>(), "{n} triangles");
            // Map through the binary order so `reach` sees input indices.
            let composed = WideBvh {
                nodes: wide.nodes.clone(),
                order: wide.order.iter().map(|&k| bvh.order[k as usize]).collect(),
                stack: wide.stack,
            };
            let mut seen = Vec::new();
            let depth = reach(&composed, &tris, 0, &mut seen, 1);
            seen.sort_unstable();
            assert_eq!(seen, (0..n as u32).collect::<Vec<_>>(), "{n} triangles: each leaf slot once");
            assert!(wide.stack <= (WIDTH - 1) * depth, "stack bound {} for depth {depth}", wide.stack);
            if n > 64 {
                // Four-wide: about half the binary depth.
                assert!(depth * 3 <= bvh.depth() * 2 + 3, "wide depth {depth} against binary {}", bvh.depth());
            }
        }
    }

    #[test]
    fn quantization_rounds_outward_at_any_scale() {
        for (lo, hi, corner, top) in [
            (1.0f32, 2.0, 0.0, 10.0),
            (1000.3, 1000.31, 1000.0, 1001.0),
            (-5e6, 3.0, -5e6, 4e6),
            (0.1, 0.1, 0.1, 0.1),
            (1e-30, 2e-30, 0.0, 1e-29),
        ] {
            let e = step_exponent(corner, top);
            let step = step_of_biased(e);
            assert!(corner + 255.0 * step >= top, "255 steps from {corner} reach {top}");
            let (qlo, qhi) = quantize(lo, hi, corner, step);
            assert!(
                corner + qlo as f32 * step <= lo && corner + qhi as f32 * step >= hi,
                "[{lo}, {hi}] in {corner}..{top}"
            );
        }
    }

    #[test]
    fn an_empty_hierarchy_has_one_node_without_children() {
        let wide = WideBvh::build(&Bvh::build(&[])).unwrap();
        assert_eq!(wide.nodes.len(), 1);
        assert!(wide.order.is_empty());
        assert!(decode(&wide.nodes[0]).iter().all(|c| c.kind == KIND_EMPTY));
    }
}
