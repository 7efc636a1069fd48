
// Material i of the buffer. A kernel specialized to a scene with few materials holds them as
// literals instead (see `scan.rs`).
fn material(i: u32) -> Material {
    return materials[i];
}
