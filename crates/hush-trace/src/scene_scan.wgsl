
// The flat scan of the generic source: every triangle of the buffer in order. A kernel
// specialized to a scene replaces this function with one that holds the scene's triangles as
// literals (see `scan.rs`), so that no invocation loads them.
fn scan_triangles(o: vec3<f32>, d: vec3<f32>, hit: ptr<function, Hit>) {
    for (var k = 0u; k < params.tri_count; k++) {
        test_triangle(k, o, d, hit);
    }
    finish_hit(hit);
}
