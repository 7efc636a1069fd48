//! The kernel's access to the scene, specialized: a small scene's triangles, materials and lights
//! written into the source as literals.
//!
//! The generic kernel reads triangles, materials and lights from buffers. A read costs every
//! invocation a load, and CPU drivers run a load per SIMD lane unless they can prove its address
//! uniform (lavapipe: a scalar load with a bounds check for each of the 8 lanes and each float).
//! Written into the source, they are constants the shader compiler folds into the arithmetic.
//! - The flat scan ([`crate::KernelFeatures::flat_scan`]): one call per triangle with its corner,
//!   edges, material, normal and light density.
//! - Materials, when there are at most [`MAX_LITERAL_MATERIALS`]: a chain of selections.
//! - Triangle lights, when there are at most [`MAX_LITERAL_LIGHTS`]: a chain of selections on the
//!   cumulative distribution, which picks what the buffer's binary search picks.
//!
//! Each part the scene is too large for keeps the generic function (`scene_*.wgsl`).

use std::fmt::Write;

use glam::Vec3;

use crate::upload::{GpuMaterial, GpuScene};

/// The generic scene access, in the order the kernel source concatenates it.
pub(crate) const GENERIC_SCAN: &str = include_str!("scene_scan.wgsl");
pub(crate) const GENERIC_MATERIAL: &str = include_str!("scene_material.wgsl");
pub(crate) const GENERIC_LIGHT: &str = include_str!("scene_light.wgsl");

/// Scenes with at most this many materials get them as literals. A lookup then costs a selection
/// per material (on a CPU driver each runs in every lane) instead of a load per lane.
pub(crate) const MAX_LITERAL_MATERIALS: usize = 16;
/// The same for triangle lights.
pub(crate) const MAX_LITERAL_LIGHTS: usize = 16;

/// A WGSL `f32` literal that parses back to exactly `x` (Rust prints the shortest decimal that
/// round-trips, and the `f` suffix makes the WGSL compiler round it to `f32` directly).
fn literal(x: f32) -> String {
    debug_assert!(x.is_finite(), "scene data is finite");
    format!("{x:?}f")
}

fn vec3(v: &[f32]) -> String {
    format!("vec3<f32>({}, {}, {})", literal(v[0]), literal(v[1]), literal(v[2]))
}

/// Four floats by their bits: material records hold integers (kinds, flags, texture indices)
/// as float bits, which need not be finite or normal.
fn bits4(v: &[f32; 4]) -> String {
    let [a, b, c, d] = v.map(f32::to_bits);
    format!("bitcast<vec4<f32>>(vec4<u32>({a:#x}u, {b:#x}u, {c:#x}u, {d:#x}u))")
}

fn material_literal(m: &GpuMaterial) -> String {
    let fields = [&m.a, &m.b, &m.c, &m.d, &m.emission, &m.e].map(bits4);
    format!("Material({})", fields.join(", "))
}

/// The scene-access source for `flat` (the generic functions for the parts it is too large
/// for), or `None` when every part would be generic.
pub(crate) fn scene_source(flat: &GpuScene) -> Option<String> {
    let scan = flat.features.flat_scan.then(|| scan_source(flat));
    let material = (flat.materials.len() <= MAX_LITERAL_MATERIALS).then(|| material_source(&flat.materials));
    let light = (!flat.lights.is_empty() && flat.lights.len() <= MAX_LITERAL_LIGHTS).then(|| light_source(flat));
    if scan.is_none() && material.is_none() && light.is_none() {
        return None;
    }
    Some(format!(
        "{}{}{}",
        scan.as_deref().unwrap_or(GENERIC_SCAN),
        material.as_deref().unwrap_or(GENERIC_MATERIAL),
        light.as_deref().unwrap_or(GENERIC_LIGHT)
    ))
}

/// `scan_triangles` with the triangles in the order (and so with the indices) of the buffer.
fn scan_source(flat: &GpuScene) -> String {
    let mut s = String::with_capacity(400 * flat.tris.len() + 256);
    s.push_str("\n// The flat scan specialized to one scene: its triangles as literals.\n");
    s.push_str("fn scan_triangles(o: vec3<f32>, d: vec3<f32>, hit: ptr<function, Hit>) {\n");
    for (i, t) in flat.tris.iter().enumerate() {
        let ng = Vec3::from_slice(&t.e1[..3]).cross(Vec3::from_slice(&t.e2[..3]));
        let _ = writeln!(
            s,
            "    if test_triangle_at({i}u, {}, {}, {}, o, d, hit) {{\n        \
             (*hit).mat = {}u;\n        (*hit).ng = {};\n        (*hit).area_pdf = {};\n    }}",
            vec3(&t.p0),
            vec3(&t.e1),
            vec3(&t.e2),
            t.p0[3].to_bits(),
            vec3(&ng.to_array()),
            literal(t.e1[3]),
        );
    }
    s.push_str("}\n");
    s
}

/// `material` as a chain of selections.
fn material_source(materials: &[GpuMaterial]) -> String {
    let mut s = String::from("\n// The scene's materials as literals.\nfn material(i: u32) -> Material {\n");
    match materials.split_first() {
        None => s.push_str("    return materials[i];\n"),
        Some((first, rest)) => {
            let _ = writeln!(s, "    var m = {};", material_literal(first));
            for (k, m) in rest.iter().enumerate() {
                let _ = writeln!(s, "    if i == {}u {{\n        m = {};\n    }}", k + 1, material_literal(m));
            }
            s.push_str("    return m;\n");
        }
    }
    s.push_str("}\n");
    s
}

/// `light_triangle` as a chain of selections: light k is taken when u ≥ the CDF of light k − 1.
fn light_source(flat: &GpuScene) -> String {
    let mut s =
        String::from("\n// The scene's triangle lights as literals.\nfn light_triangle(u: f32) -> LightTri {\n");
    for (k, l) in flat.lights.iter().enumerate() {
        let t = &flat.tris[l.tri as usize];
        let emission = flat.materials[t.p0[3].to_bits() as usize].emission;
        let value = format!(
            "LightTri({}, {}, {}, {}, {})",
            vec3(&t.p0),
            vec3(&t.e1),
            vec3(&t.e2),
            literal(t.e1[3]),
            vec3(&emission)
        );
        if k == 0 {
            let _ = writeln!(s, "    var l = {value};");
        } else {
            let cdf = literal(flat.lights[k - 1].cdf);
            let _ = writeln!(s, "    if u >= {cdf} {{\n        l = {value};\n    }}");
        }
    }
    s.push_str("    return l;\n}\n");
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
        let nan_bits = f32::from_bits(0xffff_ffff);
        assert!(bits4(&[nan_bits, 1e-45, 0.0, 1.0]).contains("0xffffffffu, 0x1u, 0x0u, 0x3f800000u"));
    }
}
