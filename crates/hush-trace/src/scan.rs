//! The kernel's access to the scene, specialized: a small scene's triangles, materials and lights
//! written into the source as literals.
//!
//! The generic kernel reads triangles, materials and lights from buffers. A read costs every
//! invocation a load, and CPU drivers run a load per SIMD lane unless they can prove its address
//! uniform (lavapipe: a scalar load with a bounds check for each of the 8 lanes and each float).
//! Written into the source, they are constants the shader compiler folds into the arithmetic.
//! - The flat scan ([`crate::KernelFeatures::flat_scan`]): one call per slot: a triangle by the rows
//!   of its world-to-barycentric map (Baldwin and Weber's test, which takes half of Möller–Trumbore's
//!   arithmetic: the Cornell box ran 1.09–1.13 against 0.87–0.88 M paths per CPU-second with
//!   Möller–Trumbore, 256², 64 spp, lavapipe, 2 threads), or an analytic shape by its placement,
//!   each with its material, normal and light density.
//! - Materials, when there are at most [`MAX_LITERAL_MATERIALS`]: word by word, each word a chain of
//!   selections of the values that differ from its most common one.
//! - Triangle lights, when there are at most [`MAX_LITERAL_LIGHTS`]: a chain of selections on the
//!   cumulative distribution, which picks what the buffer's binary search picks.
//!
//! Each part the scene is too large for keeps the generic function (`scene_*.wgsl`). Literal
//! materials help BVH scenes too (veach-mis, 9 materials: 0.30 against 0.27–0.28 M paths per
//! CPU-second on lavapipe); the price is a compilation per scene (about a CPU-second there).

use std::fmt::Write;

use crate::upload::{GpuMaterial, GpuScene};

/// The generic scene access, in the order the kernel source concatenates it.
const GENERIC_SCAN: &str = include_str!("scene_scan.wgsl");
const GENERIC_MATERIAL: &str = include_str!("scene_material.wgsl");
const GENERIC_LIGHT: &str = include_str!("scene_light.wgsl");

/// Scenes with at most this many materials get them as literals. A lookup then costs a selection
/// per differing word (on a CPU driver each runs in every lane) instead of a load per lane: a gain
/// at 28 and 37 materials already when a lookup cost 24 selections a material (procedural rooms: 0.18
/// against 0.15 and 0.13–0.14 against 0.11–0.12 M paths per CPU-second with the limit at 16, 256²,
/// 32 spp, lavapipe).
pub(crate) const MAX_LITERAL_MATERIALS: usize = 64;
/// The same for triangle lights.
pub(crate) const MAX_LITERAL_LIGHTS: usize = 16;

/// A WGSL `f32` literal that parses back to exactly `x` (Rust prints the shortest decimal that
/// round-trips, and the `f` suffix makes the WGSL compiler round it to `f32` directly). Callers
/// check that `x` is finite ([`finite`]): WGSL has no literal for the others.
fn literal(x: f32) -> String {
    format!("{x:?}f")
}

fn finite<'a>(mut values: impl Iterator<Item = &'a [f32; 4]>) -> bool {
    values.all(|v| v.iter().all(|x| x.is_finite()))
}

fn vec4(v: &[f32; 4]) -> String {
    format!("vec4<f32>({}, {}, {}, {})", literal(v[0]), literal(v[1]), literal(v[2]), literal(v[3]))
}

/// The rows of the affine map from the world to a triangle's (u, v, s): the inverse of
/// [e1, e2, e1 × e2] with the corner p0 taken off (see `test_triangle_rows` in shapes.wgsl), in
/// double precision. A degenerate triangle gives non-finite rows, which leave the scene generic.
fn barycentric_rows(t: &crate::upload::GpuTri) -> [[f32; 4]; 3] {
    let v = |a: &[f32; 4]| glam::DVec3::new(a[0] as f64, a[1] as f64, a[2] as f64);
    let (p0, e1, e2) = (v(&t.p0), v(&t.e1), v(&t.e2));
    let inv = glam::DMat3::from_cols(e1, e2, e1.cross(e2)).inverse();
    let rows = [inv.row(0), inv.row(1), inv.row(2)];
    rows.map(|r| [r.x as f32, r.y as f32, r.z as f32, -r.dot(p0) as f32])
}

fn vec3(v: &[f32]) -> String {
    format!("vec3<f32>({}, {}, {})", literal(v[0]), literal(v[1]), literal(v[2]))
}

/// What of a scene its specialized kernel holds as literals (0: read from the buffer).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct SceneLiterals {
    pub triangles: usize,
    pub shapes: usize,
    pub materials: usize,
    pub light_triangles: usize,
}

impl std::fmt::Display for SceneLiterals {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let parts: Vec<String> = [
            (self.triangles, "triangles"),
            (self.shapes, "shapes"),
            (self.materials, "materials"),
            (self.light_triangles, "light triangles"),
        ]
        .iter()
        .filter(|(n, _)| *n > 0)
        .map(|(n, what)| format!("{n} {what}"))
        .collect();
        if parts.is_empty() { write!(f, "nothing") } else { write!(f, "{}", parts.join(", ")) }
    }
}

/// Which parts of `flat` are written in.
pub(crate) fn literals(flat: &GpuScene) -> SceneLiterals {
    let tris = || flat.tris.iter().flat_map(|t| [&t.p0, &t.e1, &t.e2]);
    let emissions = || flat.materials.iter().map(|m| &m.emission);
    let shapes = || flat.shapes.iter().flat_map(|s| s.to_local.iter().chain(&s.to_world).chain([&s.info]));
    let rows: Vec<[f32; 4]> = flat.tris.iter().filter(|t| tag(t) == 0).flat_map(barycentric_rows).collect();
    let scan = flat.features.flat_scan && finite(tris()) && finite(shapes()) && finite(rows.iter());
    let material = flat.materials.len() <= MAX_LITERAL_MATERIALS;
    let light = !flat.lights.is_empty()
        && flat.lights.len() <= MAX_LITERAL_LIGHTS
        && finite(emissions())
        && flat.lights.iter().all(|l| l.cdf.is_finite());
    SceneLiterals {
        triangles: if scan { flat.tris.len() - flat.shapes.len() } else { 0 },
        shapes: if scan { flat.shapes.len() } else { 0 },
        materials: if material { flat.materials.len() } else { 0 },
        light_triangles: if light { flat.lights.len() } else { 0 },
    }
}

/// The scene-access source for `flat` with `parts` ([`literals`]) written in (the generic
/// functions for the others), or `None` when every part would be generic.
pub(crate) fn scene_source(flat: &GpuScene, parts: SceneLiterals) -> Option<String> {
    let scan = (parts.triangles + parts.shapes > 0).then(|| scan_source(flat));
    let material = (parts.materials > 0 && !flat.materials.is_empty()).then(|| material_source(&flat.materials));
    let light = (parts.light_triangles > 0).then(|| light_source(flat));
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

/// The tag of a slot: 0 for a triangle, a shape's index + 1 (see `GpuScene::tris`).
fn tag(t: &crate::upload::GpuTri) -> u32 {
    t.e2[3].to_bits()
}

/// `scan_triangles` with the triangles and shapes written in, in the order (and so with the indices)
/// of the buffer. (Nesting them in the BVH's boxes, literals too, made the scan slower on lavapipe:
/// a box is skipped only when all 8 SIMD lanes miss it; 0.13 against 0.15 M paths per CPU-second on
/// a procedural room of 39 slots, 0.52 against 0.87 on the Cornell box.)
fn scan_source(flat: &GpuScene) -> String {
    let mut s = String::with_capacity(450 * flat.tris.len() + 256);
    s.push_str("\n// The flat scan specialized to one scene: its triangles and shapes as literals.\n");
    s.push_str("fn scan_triangles(o: vec3<f32>, d: vec3<f32>, hit: ptr<function, Hit>) {\n");
    for i in 0..flat.tris.len() {
        scan_slot(&mut s, flat, i);
    }
    s.push_str("}\n");
    s
}

/// The test of slot `i`: a triangle, or the analytic shape it names.
fn scan_slot(s: &mut String, flat: &GpuScene, i: usize) {
    let t = &flat.tris[i];
    if tag(t) != 0 {
        let k = tag(t) - 1;
        let shape = &flat.shapes[k as usize];
        let mut rows = shape.to_local;
        if shape.kind() == crate::upload::SHAPE_SPHERE {
            // A sphere is tested in the world: its centre and radius.
            rows =
                [[shape.to_world[0][3], shape.to_world[1][3], shape.to_world[2][3], shape.info[3]], [0.0; 4], [0.0; 4]];
        }
        let [l0, l1, l2] = rows.map(|r| vec4(&r));
        let _ = writeln!(
            s,
            "    if test_shape_at({i}u, {}u, {l0}, {l1}, {l2}, o, d, hit) {{\n        \
             (*hit).mat = {}u;\n        (*hit).area_pdf = {};\n        (*hit).shape = {k}u;\n    }}",
            shape.kind(),
            t.p0[3].to_bits(),
            literal(t.e1[3]),
        );
        return;
    }
    let (e1, e2) = (vec3(&t.e1), vec3(&t.e2));
    let [r0, r1, r2] = barycentric_rows(t).map(|r| vec4(&r));
    // The normal as the buffer path computes it (cross on the device), so both agree to the bit.
    let _ = writeln!(
        s,
        "    if test_triangle_rows({i}u, {r0}, {r1}, {r2}, o, d, hit) {{\n        \
         (*hit).mat = {}u;\n        (*hit).ng = cross({e1}, {e2});\n        (*hit).area_pdf = {};\n        \
         (*hit).shape = NO_SHAPE;\n    }}",
        t.p0[3].to_bits(),
        literal(t.e1[3]),
    );
}

/// `material` written word by word: each of its 24 words is the value most materials share, replaced
/// by a selection for each other value, under the comparisons of `i` with the materials that have it
/// (computed once for all words). On CPU drivers every selection runs in every lane, so a word that all
/// materials share costs nothing and the others cost one selection a differing material; a chain of
/// whole records (`if i == k { m = record k }`) cost 24 selections a material.
fn material_source(materials: &[GpuMaterial]) -> String {
    let words: Vec<[u32; 24]> = materials
        .iter()
        .map(|m| {
            let mut w = [0u32; 24];
            for (f, field) in [&m.a, &m.b, &m.c, &m.d, &m.emission, &m.e].into_iter().enumerate() {
                for (c, x) in field.iter().enumerate() {
                    w[4 * f + c] = x.to_bits();
                }
            }
            w
        })
        .collect();
    let mut s =
        String::from("\n// The scene's materials as literals, word by word.\nfn material(i: u32) -> Material {\n");
    let mut compared = vec![false; materials.len()];
    let mut body = String::new();
    for j in 0..24 {
        // The values of word j with the materials that have each, in order of first use.
        let mut values: Vec<(u32, Vec<usize>)> = Vec::new();
        for (k, w) in words.iter().enumerate() {
            match values.iter_mut().find(|(v, _)| *v == w[j]) {
                Some((_, ks)) => ks.push(k),
                None => values.push((w[j], vec![k])),
            }
        }
        let common = (0..values.len()).max_by_key(|&v| (values[v].1.len(), usize::MAX - v)).unwrap_or(0);
        let _ = writeln!(body, "    var w{j} = {:#x}u;", values.get(common).map_or(0, |v| v.0));
        for (v, (value, ks)) in values.iter().enumerate() {
            if v == common {
                continue;
            }
            for &k in ks {
                compared[k] = true;
            }
            let cond: Vec<String> = ks.iter().map(|k| format!("is{k}")).collect();
            let _ = writeln!(body, "    w{j} = select(w{j}, {value:#x}u, {});", cond.join(" | "));
        }
    }
    for (k, used) in compared.iter().enumerate() {
        if *used {
            let _ = writeln!(s, "    let is{k} = i == {k}u;");
        }
    }
    s.push_str(&body);
    let fields: Vec<String> = (0..6)
        .map(|f| format!("bitcast<vec4<f32>>(vec4<u32>(w{}, w{}, w{}, w{}))", 4 * f, 4 * f + 1, 4 * f + 2, 4 * f + 3))
        .collect();
    let _ = writeln!(s, "    return Material({});\n}}", fields.join(", "));
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
            "LightTri({}, {}, {}, {}, {}, {:#x}u, {})",
            vec3(&t.p0),
            vec3(&t.e1),
            vec3(&t.e2),
            literal(t.e1[3]),
            vec3(&emission),
            tag(t).wrapping_sub(1),
            shape_record(flat, t)
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

/// The record of the shape a light slot names, as a `Shape` literal (zeros for a triangle); its kind and
/// flip are integers as float bits, so they are written as bitcasts.
fn shape_record(flat: &GpuScene, t: &crate::upload::GpuTri) -> String {
    let Some(shape) = tag(t).checked_sub(1).map(|k| &flat.shapes[k as usize]) else {
        return "Shape(vec4<f32>(), vec4<f32>(), vec4<f32>(), vec4<f32>(), vec4<f32>(), vec4<f32>(), vec4<f32>())"
            .to_string();
    };
    let rows: Vec<String> = shape.to_local.iter().chain(&shape.to_world).map(vec4).collect();
    let [kind, flip, area, radius] = shape.info;
    format!(
        "Shape({}, vec4<f32>(bitcast<f32>({:#x}u), bitcast<f32>({:#x}u), {}, {}))",
        rows.join(", "),
        kind.to_bits(),
        flip.to_bits(),
        literal(area),
        literal(radius)
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    /// `material`'s source, read back by a small interpreter of its three kinds of lines, gives every
    /// material's record word for word: shared words, words that only some materials share, a material
    /// equal to another, and words whose bits are not finite floats.
    #[test]
    fn material_source_selects_each_material_word_by_word() {
        let record = |k: u32, x: f32| GpuMaterial {
            a: [0.5, x, 0.25, 0.0],
            b: [f32::from_bits(0xffff_ffff), 0.0, 0.0, k as f32],
            c: [0.0, 0.0, 0.0, f32::from_bits(k % 3)],
            d: [0.0; 4],
            emission: [x * x, 0.0, 0.0, 0.0],
            e: [f32::from_bits(u32::MAX - k % 2), 1.0, 2.0, 3.0],
        };
        let materials: Vec<GpuMaterial> =
            [(0, 0.1), (1, 0.2), (2, 0.1), (2, 0.1), (4, 7.0)].iter().map(|&(k, x)| record(k, x)).collect();
        let source = material_source(&materials);
        let hex = |t: &str| u32::from_str_radix(t.trim().trim_start_matches("0x").trim_end_matches('u'), 16).unwrap();
        for (i, m) in materials.iter().enumerate() {
            let mut w = [None::<u32>; 24];
            for line in source.lines().map(str::trim) {
                if let Some(rest) = line.strip_prefix("var w") {
                    let (j, v) = rest.trim_end_matches(';').split_once(" = ").unwrap();
                    w[j.parse::<usize>().unwrap()] = Some(hex(v));
                } else if let Some(rest) = line.strip_prefix('w')
                    && let Some((j, sel)) = rest.split_once(" = select(")
                {
                    let (_, rest) = sel.split_once(", ").unwrap();
                    let (v, cond) = rest.trim_end_matches(");").split_once(", ").unwrap();
                    if cond.split(" | ").any(|c| c.trim_start_matches("is").parse::<usize>().unwrap() == i) {
                        w[j.parse::<usize>().unwrap()] = Some(hex(v));
                    }
                }
            }
            let expect: Vec<u32> =
                [m.a, m.b, m.c, m.d, m.emission, m.e].iter().flatten().map(|x| x.to_bits()).collect();
            let got: Vec<u32> = w.iter().map(|x| x.expect("every word is declared")).collect();
            assert_eq!(got, expect, "material {i}");
        }
        // One selection per word and value other than its most common one: words 1 and 16 (x, x²) have
        // three values, 7 (k) four, 11 (k mod 3) three and 20 (k odd) two; materials that share a value
        // share its selection.
        assert_eq!(source.matches("select(").count(), 2 + 2 + 3 + 2 + 1, "{source}");
        assert!(source.contains("w11 = select(w11, 0x2u, is2 | is3);"), "{source}");
    }

    #[test]
    fn literals_round_trip_exactly() {
        for x in [0.1f32, -1.5, 1e-20, 3.0e38, -0.0, 123456.79, f32::MIN_POSITIVE, 1.0 / 3.0] {
            let text = literal(x);
            let back: f32 = text.trim_end_matches('f').parse().unwrap();
            assert_eq!(back.to_bits(), x.to_bits(), "{x} printed as {text}");
        }
        assert!(!finite([&[0.0, f32::NAN, 1.0, 2.0]].into_iter()));
        assert!(finite([&[0.0, -0.0, 1.0, 3e38]].into_iter()));
    }
}
