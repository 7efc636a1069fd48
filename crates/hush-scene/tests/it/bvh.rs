//! The BVH finds the same nearest hit as testing every triangle.

use glam::Vec3;
use hush_scene::{Bvh, MAX_LEAF_TRIANGLES, Scene};

/// Möller–Trumbore; the nearest t in (0, t_max).
fn hit(o: Vec3, d: Vec3, t: &[Vec3; 3]) -> Option<f32> {
    let (e1, e2) = (t[1] - t[0], t[2] - t[0]);
    let p = d.cross(e2);
    let det = e1.dot(p);
    if det.abs() < 1e-20 {
        return None;
    }
    let inv = 1.0 / det;
    let s = o - t[0];
    let u = s.dot(p) * inv;
    let q = s.cross(e1);
    let v = d.dot(q) * inv;
    let dist = e2.dot(q) * inv;
    (u >= 0.0 && v >= 0.0 && u + v <= 1.0 && dist > 0.0).then_some(dist)
}

fn slab(o: Vec3, inv_d: Vec3, min: Vec3, max: Vec3, t_max: f32) -> bool {
    let t0 = (min - o) * inv_d;
    let t1 = (max - o) * inv_d;
    let near = t0.min(t1).max_element().max(0.0);
    let far = t0.max(t1).min_element().min(t_max);
    near <= far
}

/// Nearest hit through the BVH, as the kernel traverses it.
fn traverse(bvh: &Bvh, tris: &[[Vec3; 3]], o: Vec3, d: Vec3) -> Option<(f32, u32)> {
    let inv_d = d.recip();
    let mut best: Option<(f32, u32)> = None;
    let mut stack = vec![0usize];
    while let Some(i) = stack.pop() {
        let n = &bvh.nodes[i];
        let t_max = best.map_or(f32::INFINITY, |b| b.0);
        if !slab(o, inv_d, Vec3::from(n.min), Vec3::from(n.max), t_max) {
            continue;
        }
        if n.count > 0 {
            for k in n.first..n.first + n.count {
                let tri = bvh.order[k as usize];
                if let Some(t) = hit(o, d, &tris[tri as usize])
                    && best.is_none_or(|b| t < b.0)
                {
                    best = Some((t, tri));
                }
            }
        } else {
            stack.push(n.first as usize);
            stack.push(n.first as usize + 1);
        }
    }
    best
}

fn brute(tris: &[[Vec3; 3]], o: Vec3, d: Vec3) -> Option<(f32, u32)> {
    let mut best: Option<(f32, u32)> = None;
    for (i, t) in tris.iter().enumerate() {
        if let Some(dist) = hit(o, d, t)
            && best.is_none_or(|b| dist < b.0)
        {
            best = Some((dist, i as u32));
        }
    }
    best
}

/// A deterministic pseudo-random stream for test geometry.
fn lcg(state: &mut u64) -> f32 {
    *state = state.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
    (*state >> 40) as f32 / (1u64 << 24) as f32
}

fn check(tris: &[[Vec3; 3]], rays: usize, seed: u64) {
    let bvh = Bvh::build(tris);
    // Every triangle sits in exactly one leaf, and leaves respect the size limit when splits exist.
    let mut seen = vec![0u32; tris.len()];
    for n in bvh.nodes.iter().filter(|n| n.count > 0) {
        for k in n.first..n.first + n.count {
            seen[bvh.order[k as usize] as usize] += 1;
        }
    }
    assert!(seen.iter().all(|&c| c == 1), "every triangle must be in exactly one leaf");
    let mut s = seed;
    let mut hits = 0;
    for _ in 0..rays {
        let o = Vec3::new(lcg(&mut s), lcg(&mut s), lcg(&mut s)) * 4.0 - 2.0;
        // Aim near a random triangle so that most rays hit something.
        let t = &tris[(lcg(&mut s) * tris.len() as f32) as usize % tris.len()];
        let aim = (t[0] + t[1] + t[2]) / 3.0 + (Vec3::new(lcg(&mut s), lcg(&mut s), lcg(&mut s)) - 0.5) * 0.1;
        let d = (aim - o).normalize();
        let (a, b) = (traverse(&bvh, tris, o, d), brute(tris, o, d));
        // The same nearest distance (coincident triangles tie, so indices may differ).
        assert_eq!(a.map(|h| h.0), b.map(|h| h.0), "ray {o} → {d}");
        hits += a.is_some() as usize;
    }
    assert!(hits > rays / 2, "most test rays should hit something ({hits} of {rays})");
}

#[test]
fn bvh_matches_brute_force_on_random_triangles() {
    let mut s = 7u64;
    let tris: Vec<[Vec3; 3]> = (0..2000)
        .map(|_| {
            let c = Vec3::new(lcg(&mut s), lcg(&mut s), lcg(&mut s)) * 2.0 - 1.0;
            let mut corner = || c + (Vec3::new(lcg(&mut s), lcg(&mut s), lcg(&mut s)) - 0.5) * 0.2;
            [corner(), corner(), corner()]
        })
        .collect();
    check(&tris, 2000, 1);
    let bvh = Bvh::build(&tris);
    assert!(bvh.nodes.iter().filter(|n| n.count > 0).all(|n| n.count as usize <= MAX_LEAF_TRIANGLES));
    assert!(bvh.depth() < 40, "depth {}", bvh.depth());
}

#[test]
fn bvh_handles_coincident_and_tiny_inputs() {
    let t = [Vec3::ZERO, Vec3::X, Vec3::Y];
    check(&vec![t; 50], 200, 2);
    check(&[t], 200, 3);
    let empty = Bvh::build(&[]);
    assert_eq!(empty.nodes.len(), 1);
}

#[test]
fn bvh_matches_brute_force_on_the_cornell_box() {
    let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../../data/scenes/cbox/scene.xml");
    let scene = Scene::load(&path).unwrap();
    let tris: Vec<[Vec3; 3]> =
        scene.meshes.iter().flat_map(|m| m.indices.iter().map(|t| t.map(|i| m.positions[i as usize]))).collect();
    check(&tris, 2000, 4);
}

/// Centroids spaced ever more widely along each axis (each 16× the last, on both sides) make the SAH
/// peel one triangle at a time; the builder then splits ranges in half from `MAX_SAH_DEPTH` on, so the
/// tree (and the recursion that builds it) stays shallow. Without that bound this input is 126 deep.
#[test]
fn bvh_depth_is_bounded_on_ever_wider_spacing() {
    let mut tris = Vec::new();
    for axis in [Vec3::X, Vec3::Y, Vec3::Z] {
        for sign in [1.0f32, -1.0] {
            for k in 0..31 {
                let c = axis * sign * 16f32.powi(k);
                tris.push([c, c + Vec3::X * 0.01, c + Vec3::Y * 0.01]);
            }
        }
    }
    let bvh = Bvh::build(&tris);
    // MAX_SAH_DEPTH (48) levels, then halving 186 triangles into leaves of up to 4: at most 48 + 6.
    assert_eq!(hush_scene::MAX_SAH_DEPTH, 48);
    assert!(bvh.depth() <= 54, "depth {}", bvh.depth());
    let in_leaves: u32 = bvh.nodes.iter().map(|n| n.count).sum();
    assert_eq!(in_leaves as usize, tris.len(), "every triangle in one leaf");
}
