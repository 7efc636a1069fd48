
// Index of the light whose CDF interval holds u (binary search).
fn pick_light(u: f32) -> u32 {
    var lo = 0u;
    var hi = params.light_count - 1u;
    while lo < hi {
        let mid = (lo + hi) / 2u;
        if lights[mid].cdf <= u {
            lo = mid + 1u;
        } else {
            hi = mid;
        }
    }
    return lo;
}

// The light slot (a triangle or a shape) picked by power with u in [0, 1), from the buffers. A kernel specialized
// to a scene with few light triangles holds them as literals instead (see `scan.rs`).
fn light_triangle(u: f32) -> LightTri {
    let t = tris[lights[pick_light(u)].tri];
    let emission = materials[bitcast<u32>(t.p0.w)].emission.xyz;
    // A triangle's tag is 0, so its shape is 0 − 1 = NO_SHAPE (whose record is never read).
    let shape = bitcast<u32>(t.e2.w) - 1u;
    return LightTri(t.p0.xyz, t.e1.xyz, t.e2.xyz, t.e1.w, emission, shape, shape_at(select(0u, shape, shape != NO_SHAPE)));
}
