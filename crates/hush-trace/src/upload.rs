//! Flattens a [`Scene`] into the arrays the kernel reads.

use bytemuck::{Pod, Zeroable};
use glam::Vec3;
use hush_scene::{Bvh, BvhNode, Environment, Material, Reflectance, Scene};

use crate::TraceError;

#[repr(C)]
#[derive(Clone, Copy, Pod, Zeroable)]
pub(crate) struct GpuTri {
    pub p0: [f32; 4],
    pub e1: [f32; 4],
    pub e2: [f32; 4],
}

#[repr(C)]
#[derive(Clone, Copy, Pod, Zeroable)]
pub(crate) struct GpuNormals {
    pub n: [[f32; 4]; 3],
}

/// Mirrors `Material` in bsdf.wgsl, which documents each field.
#[repr(C)]
#[derive(Clone, Copy, Pod, Zeroable)]
pub(crate) struct GpuMaterial {
    pub a: [f32; 4],
    pub b: [f32; 4],
    pub c: [f32; 4],
    pub d: [f32; 4],
    pub emission: [f32; 4],
}

// BSDF kinds and flags; mirror the constants in bsdf.wgsl.
const KIND_DIFFUSE: u32 = 0;
const KIND_CONDUCTOR: u32 = 1;
const KIND_DIELECTRIC: u32 = 2;
const KIND_THIN_DIELECTRIC: u32 = 3;
const KIND_PLASTIC: u32 = 4;
const FLAG_TWO_SIDED: u32 = 1;
const FLAG_NONLINEAR: u32 = 2;

/// The kernel's record of a material, or why the kernel cannot render it yet.
pub(crate) fn gpu_material(m: &Material, emission: Vec3, shape: &str) -> Result<GpuMaterial, TraceError> {
    let unsupported = |what: &str| {
        Err(TraceError::Invalid(format!("material '{what}' of shape '{shape}' is not supported by the kernel yet")))
    };
    let rgb = |r: &Reflectance| match r {
        Reflectance::Rgb(v) => Ok(*v),
        Reflectance::Texture(_) => Err(()),
    };
    let bits = |kind: u32, flags: u32| f32::from_bits(kind | flags << 8);
    let two = |t: bool| if t { FLAG_TWO_SIDED } else { 0 };
    let zero = [0.0; 4];
    let emits = emission.max_element() > 0.0;
    let emission = v4(emission, emits as u32 as f32);
    Ok(match *m {
        Material::Diffuse { ref reflectance, two_sided } => {
            let Ok(r) = rgb(reflectance) else { return unsupported("textured diffuse") };
            GpuMaterial {
                a: v4(r, 0.0),
                b: zero,
                c: v4(Vec3::ZERO, bits(KIND_DIFFUSE, two(two_sided))),
                d: zero,
                emission,
            }
        }
        Material::Conductor { alpha, ior, specular_reflectance, two_sided } => {
            // Without an index of refraction, a perfect mirror (eta 0, k 1 gives F = 1).
            let ior = ior.unwrap_or(hush_scene::ComplexIor { eta: Vec3::ZERO, k: Vec3::ONE });
            GpuMaterial {
                a: v4(specular_reflectance, alpha),
                b: zero,
                c: v4(ior.eta, bits(KIND_CONDUCTOR, two(two_sided))),
                d: v4(ior.k, 0.0),
                emission,
            }
        }
        Material::Dielectric { alpha, int_ior, ext_ior, thin, specular_reflectance, specular_transmittance } => {
            if alpha > 0.0 && !thin {
                return unsupported("roughdielectric");
            }
            let kind = if thin { KIND_THIN_DIELECTRIC } else { KIND_DIELECTRIC };
            GpuMaterial {
                a: v4(specular_reflectance, 0.0),
                b: v4(specular_transmittance, int_ior / ext_ior),
                c: v4(Vec3::ZERO, bits(kind, FLAG_TWO_SIDED)),
                d: zero,
                emission,
            }
        }
        Material::Plastic {
            ref diffuse_reflectance,
            specular_reflectance,
            alpha,
            int_ior,
            ext_ior,
            nonlinear,
            two_sided,
        } => {
            if alpha > 0.0 {
                return unsupported("roughplastic");
            }
            let Ok(diffuse) = rgb(diffuse_reflectance) else { return unsupported("textured plastic") };
            // Mitsuba's plastic picks the coat with weight mean(ks) / (mean(kd) + mean(ks)).
            let (dm, sm) = (diffuse.element_sum() / 3.0, specular_reflectance.element_sum() / 3.0);
            let weight = if dm + sm > 0.0 { sm / (dm + sm) } else { 0.5 };
            let flags = two(two_sided) | if nonlinear { FLAG_NONLINEAR } else { 0 };
            GpuMaterial {
                a: v4(diffuse, 0.0),
                b: v4(specular_reflectance, int_ior / ext_ior),
                c: v4(Vec3::ZERO, bits(KIND_PLASTIC, flags)),
                d: v4(Vec3::ZERO, weight),
                emission,
            }
        }
    })
}

#[repr(C)]
#[derive(Clone, Copy, Pod, Zeroable)]
pub(crate) struct GpuLight {
    pub tri: u32,
    pub cdf: f32,
    pub pad: [u32; 2],
}

#[repr(C)]
#[derive(Clone, Copy, Pod, Zeroable)]
pub(crate) struct GpuNode {
    pub min: [f32; 3],
    pub first: u32,
    pub max: [f32; 3],
    pub count: u32,
}

impl From<BvhNode> for GpuNode {
    fn from(n: BvhNode) -> Self {
        GpuNode { min: n.min, first: n.first, max: n.max, count: n.count }
    }
}

/// The kernel's traversal stack; mirrors `STACK_SIZE` in the kernel.
const STACK_SIZE: usize = 64;

pub(crate) struct GpuScene {
    pub nodes: Vec<GpuNode>,
    pub tris: Vec<GpuTri>,
    pub normals: Vec<GpuNormals>,
    pub materials: Vec<GpuMaterial>,
    pub lights: Vec<GpuLight>,
}

fn v4(v: Vec3, w: f32) -> [f32; 4] {
    [v.x, v.y, v.z, w]
}

/// Each mesh becomes one material record (its BSDF and emission). Emissive triangles are
/// picked in proportion to their power (area × summed RGB radiance); the kernel's per-area
/// density of a light point is that probability divided by the triangle's area, stored in `e1.w`.
/// Triangles are stored in the leaf order of a BVH built over them.
pub(crate) fn flatten(scene: &Scene) -> Result<GpuScene, TraceError> {
    let mut tris = Vec::with_capacity(scene.triangle_count());
    let mut normals = Vec::with_capacity(scene.triangle_count());
    let mut materials = Vec::with_capacity(scene.meshes.len());
    let mut light_weights = Vec::new();
    if let Some(env) = &scene.environment {
        let what = match env {
            Environment::Constant { .. } => "constant",
            Environment::Map(_) => "envmap",
        };
        return Err(TraceError::Invalid(format!("emitter '{what}' is not supported by the kernel yet")));
    }
    for (mi, mesh) in scene.meshes.iter().enumerate() {
        let emission = mesh.emission.unwrap_or(Vec3::ZERO);
        let emits = emission.max_element() > 0.0;
        materials.push(gpu_material(&mesh.material, emission, &mesh.name)?);
        for (ti, idx) in mesh.indices.iter().enumerate() {
            // Mitsuba takes a surface's front side (for one-sided BSDFs and emitters) from its
            // shading normal when the mesh has vertex normals: wind such triangles so that the
            // geometric normal agrees with their vertex normals.
            let mut idx = *idx;
            if let Some(n) = &mesh.normals {
                let [a, b, c] = idx.map(|k| mesh.positions[k as usize]);
                let shading = idx.iter().map(|&k| n[k as usize]).sum::<Vec3>();
                if (b - a).cross(c - a).dot(shading) < 0.0 {
                    idx.swap(1, 2);
                }
            }
            let [a, b, c] = idx.map(|k| mesh.positions[k as usize]);
            if emits {
                light_weights.push((tris.len() as u32, mesh.triangle_area(ti) * emission.element_sum()));
            }
            tris.push(GpuTri { p0: v4(a, f32::from_bits(mi as u32)), e1: v4(b - a, 0.0), e2: v4(c - a, 0.0) });
            normals.push(match &mesh.normals {
                Some(n) => GpuNormals { n: idx.map(|k| v4(n[k as usize], 1.0)) },
                None => GpuNormals { n: [[0.0; 4]; 3] },
            });
        }
    }
    // Reorder the triangles into the BVH's leaf order; lights follow their triangles.
    let corners: Vec<[Vec3; 3]> = tris
        .iter()
        .map(|t| {
            let p0 = Vec3::from_slice(&t.p0[..3]);
            [p0, p0 + Vec3::from_slice(&t.e1[..3]), p0 + Vec3::from_slice(&t.e2[..3])]
        })
        .collect();
    let bvh = Bvh::build(&corners);
    if bvh.depth() > STACK_SIZE {
        return Err(TraceError::Invalid(format!(
            "the scene's BVH is {} levels deep; the kernel's traversal stack holds {STACK_SIZE}",
            bvh.depth()
        )));
    }
    let mut new_index = vec![0u32; tris.len()];
    for (k, &old) in bvh.order.iter().enumerate() {
        new_index[old as usize] = k as u32;
    }
    let mut tris: Vec<GpuTri> = bvh.order.iter().map(|&i| tris[i as usize]).collect();
    let normals: Vec<GpuNormals> = bvh.order.iter().map(|&i| normals[i as usize]).collect();
    for (tri, _) in light_weights.iter_mut() {
        *tri = new_index[*tri as usize];
    }
    let total: f64 = light_weights.iter().map(|&(_, w)| w as f64).sum();
    let mut lights = Vec::with_capacity(light_weights.len());
    let mut running = 0.0f64;
    for &(tri, w) in &light_weights {
        running += w as f64;
        let t = &mut tris[tri as usize];
        let area = 0.5 * Vec3::from_slice(&t.e1[..3]).cross(Vec3::from_slice(&t.e2[..3])).length();
        t.e1[3] = (w as f64 / total / area as f64) as f32;
        lights.push(GpuLight { tri, cdf: (running / total) as f32, pad: [0; 2] });
    }
    if let Some(last) = lights.last_mut() {
        last.cdf = 1.0;
    }
    let nodes = bvh.nodes.into_iter().map(GpuNode::from).collect();
    Ok(GpuScene { nodes, tris, normals, materials, lights })
}
