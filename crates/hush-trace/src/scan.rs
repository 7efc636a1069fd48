//! The flat scan specialized to a scene: its triangles written into the kernel as literals.
//!
//! A scene with few triangles is intersected by testing all of them ([`crate::KernelFeatures::flat_scan`]).
//! Read from a buffer, a triangle costs every invocation a load, and CPU drivers run a load per
//! SIMD lane unless they can prove its address uniform, which a loop counter inside the path loop
//! is not to them (lavapipe: a scalar load with a bounds check for each of the 8 lanes and each of
//! the 12 floats). Written into the source, the triangles are constants the shader compiler folds
//! into the arithmetic: no loads at all, on any device.

use std::fmt::Write;

use crate::upload::GpuTri;

/// A WGSL `f32` literal that parses back to exactly `x` (Rust prints the shortest decimal that
/// round-trips, and the `f` suffix makes the WGSL compiler round it to `f32` directly).
fn literal(x: f32) -> String {
    debug_assert!(x.is_finite(), "scene vertices are finite");
    format!("{x:?}f")
}

fn vec3(v: &[f32; 4]) -> String {
    format!("vec3<f32>({}, {}, {})", literal(v[0]), literal(v[1]), literal(v[2]))
}

/// `scan_triangles` with `tris` as literals, in the order (and so with the indices) of the
/// triangle buffer, replacing the generic source's loop over that buffer.
pub(crate) fn scan_source(tris: &[GpuTri]) -> String {
    let mut s = String::with_capacity(160 * tris.len() + 256);
    s.push_str("\n// The flat scan specialized to one scene: its triangles as literals.\n");
    s.push_str("fn scan_triangles(o: vec3<f32>, d: vec3<f32>, hit: ptr<function, Hit>) {\n");
    for (i, t) in tris.iter().enumerate() {
        let _ =
            writeln!(s, "    test_triangle_at({i}u, {}, {}, {}, o, d, hit);", vec3(&t.p0), vec3(&t.e1), vec3(&t.e2));
    }
    s.push_str("}\n");
    s
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn literals_round_trip_exactly() {
        for x in [0.1f32, -1.5, 1e-20, 3.0e38, -0.0, 123456.79, f32::MIN_POSITIVE, 1.0 / 3.0] {
            let text = literal(x);
            let back: f32 = text.trim_end_matches('f').parse().unwrap();
            assert_eq!(back.to_bits(), x.to_bits(), "{x} printed as {text}");
        }
    }

    #[test]
    fn one_call_per_triangle_with_its_index() {
        let t = |x: f32| GpuTri { p0: [x, 0.0, 0.0, 0.0], e1: [0.0, 1.0, 0.0, 0.0], e2: [0.0, 0.0, 1.0, 0.0] };
        let src = scan_source(&[t(0.5), t(-2.0)]);
        assert_eq!(src.matches("test_triangle_at(").count(), 2);
        assert!(src.contains("test_triangle_at(0u, vec3<f32>(0.5f, 0.0f, 0.0f)"), "{src}");
        assert!(src.contains("test_triangle_at(1u, vec3<f32>(-2.0f, 0.0f, 0.0f)"), "{src}");
    }
}
