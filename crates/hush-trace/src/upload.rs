//! Flattens a [`Scene`] into the arrays the kernel reads.

use std::collections::HashMap;

use bytemuck::{Pod, Zeroable};
use glam::{Mat3, Vec2, Vec3};
use hush_scene::{Bvh, Environment, Material, Microfacet, Reflectance, Scene, Texture, TextureId};

use crate::TraceError;
use crate::rough::plastic_tables;
use crate::wide::{GpuWideNode, WideBvh};

#[repr(C)]
#[derive(Clone, Copy, Pod, Zeroable)]
pub(crate) struct GpuTri {
    pub p0: [f32; 4],
    pub e1: [f32; 4],
    pub e2: [f32; 4],
}

/// An analytic shape for the kernel (mirrors `Shape` in shapes.wgsl): the rows of its world-to-object
/// and object-to-world affine maps, then kind, flip, area and (a sphere's) radius.
#[repr(C)]
#[derive(Clone, Copy, Pod, Zeroable)]
pub(crate) struct GpuShape {
    pub to_local: [[f32; 4]; 3],
    pub to_world: [[f32; 4]; 3],
    pub info: [f32; 4],
}

// Shape kinds; mirror SHAPE_* in shapes.wgsl.
pub(crate) const SHAPE_SPHERE: u32 = 0;
const SHAPE_DISK: u32 = 1;
const SHAPE_RECTANGLE: u32 = 2;
const SHAPE_CYLINDER: u32 = 3;

/// [`KernelFeatures::light_kinds`]' bit for emitting triangles; a shape kind's bit is `1 << SHAPE_*`.
pub(crate) const LIGHT_TRIANGLES: u8 = 1 << 4;
/// The shape kinds' bits of [`KernelFeatures::light_kinds`].
const LIGHT_SHAPES: u8 = 0b1111;

/// The kernel's kind of a shape: a cube is uploaded as its faces (`Analytic::cube_faces`), rectangles.
fn shape_kind(kind: hush_scene::ShapeKind) -> u32 {
    use hush_scene::ShapeKind;
    match kind {
        ShapeKind::Sphere => SHAPE_SPHERE,
        ShapeKind::Disk => SHAPE_DISK,
        ShapeKind::Rectangle | ShapeKind::Cube => SHAPE_RECTANGLE,
        ShapeKind::Cylinder => SHAPE_CYLINDER,
    }
}

impl GpuShape {
    fn new(a: &hush_scene::Analytic) -> GpuShape {
        let rows = |m: glam::Mat4| {
            let r = m.transpose();
            [r.x_axis.to_array(), r.y_axis.to_array(), r.z_axis.to_array()]
        };
        assert!(a.kind != hush_scene::ShapeKind::Cube, "a cube is uploaded as six rectangles");
        let kind = shape_kind(a.kind);
        GpuShape {
            to_local: rows(a.to_world.inverse()),
            to_world: rows(a.to_world),
            info: [f32::from_bits(kind), f32::from_bits(a.flip_normals as u32), a.area() as f32, a.sphere().1],
        }
    }

    pub fn kind(&self) -> u32 {
        self.info[0].to_bits()
    }
}

/// Shading normals (`w` = 1 when interpolated) and texture coordinates of a triangle's corners.
#[repr(C)]
#[derive(Clone, Copy, Pod, Zeroable)]
pub(crate) struct GpuNormals {
    pub n: [[f32; 4]; 3],
    pub uv01: [f32; 4],
    pub uv2: [f32; 4],
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
    pub e: [f32; 4],
}

// BSDF kinds and flags; mirror the constants in bsdf.wgsl.
const KIND_DIFFUSE: u32 = 0;
const KIND_CONDUCTOR: u32 = 1;
const KIND_DIELECTRIC: u32 = 2;
const KIND_THIN_DIELECTRIC: u32 = 3;
const KIND_PLASTIC: u32 = 4;
const FLAG_TWO_SIDED: u32 = 1;
const FLAG_NONLINEAR: u32 = 2;
const FLAG_BECKMANN: u32 = 4;

/// `e.x` of a material without a texture; mirrors `NO_TEXTURE` in the kernel.
pub(crate) const NO_TEXTURE: u32 = u32::MAX;

/// The kernel's auxiliary float array (`aux` in path.wgsl): images (textures, an environment
/// map) and tables, each at an offset that the records using it store as bits.
///
/// An environment map is its linear RGB texels, rows top to bottom, four floats each (the fourth 0) from a
/// multiple of four words ([`Aux::push_image`]; its size is in the environment's uniform), followed by its
/// sampling table, four words a cell ([`push_alias`]). A material's texture is its texels alone,
/// three halves in two words each, from an even offset (the kernel loads a texel's two words at once
/// and takes the size from the material; [`Aux::push_texture`]).
#[derive(Default)]
pub(crate) struct Aux {
    pub data: Vec<f32>,
    textures: HashMap<u32, u32>,
    plastic_tables: HashMap<(u32, u32, bool), (u32, f32)>,
}

impl Aux {
    /// Appends an environment map's texels as (r, g, b, 0) from a multiple of four words; returns
    /// its offset in texels of four words (`aux4` in the kernel: one load a texel, where CPU drivers
    /// load a storage buffer lane by lane, one load at a time).
    pub fn push_image(&mut self, texels: &[f32]) -> u32 {
        let offset = self.align4();
        self.data.extend(texels.chunks_exact(3).flat_map(|t| [t[0], t[1], t[2], 0.0]));
        offset
    }

    /// Pads the array to a multiple of four words; returns the offset in units of four words.
    pub fn align4(&mut self) -> u32 {
        while !self.data.len().is_multiple_of(4) {
            self.data.push(0.0);
        }
        self.offset() / 4
    }

    /// Appends a material's texture's texels as halves (`pack2x16float(r, g)`, `pack2x16float(b, 0)`:
    /// one load of two words a texel, where CPU drivers load a storage buffer lane by lane, one load
    /// at a time), from an even offset, which it returns. Values are clamped to [0, 65504], the halves'
    /// finite range (a reflectance is at most 1); a half keeps 11 significant bits, finer than an 8-bit
    /// image's steps.
    pub fn push_texture(&mut self, texels: &[f32]) -> u32 {
        if self.offset() % 2 == 1 {
            self.data.push(0.0);
        }
        let offset = self.offset();
        let half = |v: f32| {
            let v = if v.is_nan() { 0.0 } else { v.clamp(0.0, 65504.0) };
            u32::from(half::f16::from_f32(v).to_bits())
        };
        for t in texels.chunks_exact(3) {
            self.data.push(f32::from_bits(half(t[0]) | (half(t[1]) << 16)));
            self.data.push(f32::from_bits(half(t[2])));
        }
        offset
    }

    /// The offset of a scene texture, uploaded on first use, its size as the kernel reads it from a
    /// material (`width | height << 16`, bits) and its mean.
    fn texture(&mut self, id: TextureId, textures: &[Texture]) -> Result<(u32, f32, Vec3), TraceError> {
        let t = textures.get(id.0 as usize).ok_or_else(|| {
            TraceError::Invalid(format!("texture {} is referenced but the scene holds {}", id.0, textures.len()))
        })?;
        if t.width > 0xffff || t.height > 0xffff {
            return Err(TraceError::Invalid(format!(
                "texture {} is {}×{} texels; the kernel takes at most 65535 a side: use a smaller image",
                id.0, t.width, t.height
            )));
        }
        let size = f32::from_bits(t.width | t.height << 16);
        if let Some(&offset) = self.textures.get(&id.0) {
            return Ok((offset, size, t.mean()));
        }
        let offset = self.push_texture(&t.data);
        self.textures.insert(id.0, offset);
        Ok((offset, size, t.mean()))
    }

    /// The offset of a rough plastic's coat-transmittance table and its internal reflectance.
    fn plastic(&mut self, dist: Microfacet, alpha: f32, eta: f32) -> (u32, f32) {
        let key = (alpha.to_bits(), eta.to_bits(), dist == Microfacet::Beckmann);
        if let Some(&t) = self.plastic_tables.get(&key) {
            return t;
        }
        let (table, internal) = plastic_tables(dist, alpha, eta);
        let offset = self.offset();
        self.data.extend_from_slice(&table);
        self.plastic_tables.insert(key, (offset, internal));
        (offset, internal)
    }

    /// The next offset.
    pub fn offset(&self) -> u32 {
        self.data.len() as u32
    }
}

/// The kernel's record of a material. Textures and tables it reads are appended to `aux`.
pub(crate) fn gpu_material(
    m: &Material,
    emission: Vec3,
    textures: &[Texture],
    aux: &mut Aux,
) -> Result<GpuMaterial, TraceError> {
    // A reflectance as (constant color or texture mean, texture offset or NO_TEXTURE, texture size).
    let mut reflectance = |r: &Reflectance| match *r {
        Reflectance::Rgb(v) => Ok((v, NO_TEXTURE, 0.0)),
        Reflectance::Texture(id) => aux.texture(id, textures).map(|(offset, size, mean)| (mean, offset, size)),
    };
    let bits = |kind: u32, flags: u32| f32::from_bits(kind | flags << 8);
    let two = |t: bool| if t { FLAG_TWO_SIDED } else { 0 };
    let beckmann = |d: Microfacet| if d == Microfacet::Beckmann { FLAG_BECKMANN } else { 0 };
    let zero = [0.0; 4];
    let emits = emission.max_element() > 0.0;
    let emission = v4(emission, emits as u32 as f32);
    let no_texture = [f32::from_bits(NO_TEXTURE), 0.0, 0.0, 0.0];
    Ok(match *m {
        Material::Diffuse { reflectance: ref r, two_sided } => {
            let (r, tex, size) = reflectance(r)?;
            GpuMaterial {
                a: v4(r, 0.0),
                b: zero,
                c: v4(Vec3::ZERO, bits(KIND_DIFFUSE, two(two_sided))),
                d: zero,
                emission,
                e: [f32::from_bits(tex), 0.0, 0.0, size],
            }
        }
        Material::Conductor { alpha, distribution, ior, specular_reflectance, two_sided } => {
            // Without an index of refraction, a perfect mirror (eta 0, k 1 gives F = 1).
            let ior = ior.unwrap_or(hush_scene::ComplexIor { eta: Vec3::ZERO, k: Vec3::ONE });
            GpuMaterial {
                a: v4(specular_reflectance, alpha),
                b: zero,
                c: v4(ior.eta, bits(KIND_CONDUCTOR, two(two_sided) | beckmann(distribution))),
                d: v4(ior.k, 0.0),
                emission,
                e: no_texture,
            }
        }
        Material::Dielectric {
            alpha,
            distribution,
            int_ior,
            ext_ior,
            thin,
            specular_reflectance,
            specular_transmittance,
        } => {
            let kind = if thin { KIND_THIN_DIELECTRIC } else { KIND_DIELECTRIC };
            GpuMaterial {
                a: v4(specular_reflectance, if thin { 0.0 } else { alpha }),
                b: v4(specular_transmittance, int_ior / ext_ior),
                c: v4(Vec3::ZERO, bits(kind, FLAG_TWO_SIDED | beckmann(distribution))),
                d: zero,
                emission,
                e: no_texture,
            }
        }
        Material::Plastic {
            ref diffuse_reflectance,
            specular_reflectance,
            alpha,
            distribution,
            int_ior,
            ext_ior,
            nonlinear,
            two_sided,
        } => {
            let (diffuse, tex, size) = reflectance(diffuse_reflectance)?;
            let eta = int_ior / ext_ior;
            let (table, internal) = if alpha > 0.0 { aux.plastic(distribution, alpha, eta) } else { (0, 0.0) };
            // Mitsuba's plastic picks the coat with weight mean(ks) / (mean(kd) + mean(ks)),
            // a texture's mean standing for kd.
            let (dm, sm) = (diffuse.element_sum() / 3.0, specular_reflectance.element_sum() / 3.0);
            let weight = if dm + sm > 0.0 { sm / (dm + sm) } else { 0.5 };
            let flags = two(two_sided) | if nonlinear { FLAG_NONLINEAR } else { 0 } | beckmann(distribution);
            GpuMaterial {
                a: v4(diffuse, alpha),
                b: v4(specular_reflectance, eta),
                c: v4(Vec3::ZERO, bits(KIND_PLASTIC, flags)),
                d: v4(Vec3::ZERO, weight),
                emission,
                e: [f32::from_bits(tex), f32::from_bits(table), internal, size],
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

// Environment kinds; mirror ENV_* in path.wgsl.
pub(crate) const ENV_NONE: u32 = 0;
pub(crate) const ENV_CONSTANT: u32 = 1;
pub(crate) const ENV_MAP: u32 = 2;

/// The environment as the kernel sees it (fields of `Params`).
#[derive(Clone, Copy, Debug)]
pub(crate) struct GpuEnv {
    pub kind: u32,
    /// Offset of the map's image in `aux`, in units of four words.
    pub image: u32,
    /// Offset of its sampling table in `aux`, in units of four words: per interpolation cell (row-major,
    /// width × (height − 1)) the alias method's threshold, alias (bits) and probability ([`push_alias`]).
    pub dist: u32,
    /// The map's width | height << 16.
    pub size: u32,
    /// Constant radiance, or the map's scale on every channel.
    pub radiance: Vec3,
    /// Probability that next-event estimation samples the environment rather than a triangle.
    pub pick: f32,
    pub to_world: Mat3,
    pub to_local: Mat3,
}

/// Mirrors `Env` in env.wgsl.
#[repr(C)]
#[derive(Clone, Copy, Pod, Zeroable)]
pub(crate) struct GpuEnvUniform {
    pub kind: u32,
    pub image: u32,
    pub dist: u32,
    pub size: u32,
    pub radiance: [f32; 4],
    pub to_world: [[f32; 4]; 3],
    pub to_local: [[f32; 4]; 3],
}

impl GpuEnv {
    pub fn uniform(&self) -> GpuEnvUniform {
        let columns = |m: Mat3| [m.x_axis, m.y_axis, m.z_axis].map(|c| v4(c, 0.0));
        GpuEnvUniform {
            kind: self.kind,
            image: self.image,
            dist: self.dist,
            size: self.size,
            radiance: v4(self.radiance, self.pick),
            to_world: columns(self.to_world),
            to_local: columns(self.to_local),
        }
    }
}

/// Mitsuba's luminance weights for linear sRGB.
fn luminance(rgb: &[f32]) -> f64 {
    0.212671 * rgb[0] as f64 + 0.715160 * rgb[1] as f64 + 0.072169 * rgb[2] as f64
}

/// Appends Walker's alias table of `weights` (normalized; uniform if they are all 0), per cell the
/// probability of keeping it, its alias (bits) and its probability, and returns their sum.
fn push_alias(aux: &mut Vec<f32>, weights: &[f64]) -> f64 {
    debug_assert!(aux.len().is_multiple_of(4), "the table is read four words a cell");
    let n = weights.len();
    let total: f64 = weights.iter().sum();
    let prob: Vec<f64> = weights.iter().map(|&w| if total > 0.0 { w / total } else { 1.0 / n as f64 }).collect();
    // Vose's construction: each cell's share scaled to 1 on average; a cell below 1 is topped up
    // by its alias, taken from a cell above 1.
    let mut scaled: Vec<f64> = prob.iter().map(|p| p * n as f64).collect();
    let mut keep = vec![1.0f64; n];
    let mut alias: Vec<u32> = (0..n as u32).collect();
    let (mut small, mut large): (Vec<usize>, Vec<usize>) = (0..n).partition(|&i| scaled[i] < 1.0);
    while let (Some(s), Some(&l)) = (small.pop(), large.last()) {
        keep[s] = scaled[s];
        alias[s] = l as u32;
        scaled[l] -= 1.0 - scaled[s];
        if scaled[l] < 1.0 {
            large.pop();
            small.push(l);
        }
    }
    // What is left (rounding) keeps itself.
    for i in 0..n {
        aux.extend([keep[i] as f32, f32::from_bits(alias[i]), prob[i] as f32, 0.0]);
    }
    total
}

/// Uploads the scene's environment. An environment map is sampled in proportion to the
/// luminance of its interpolation cells (the mean of their four corner texels) times sin θ at
/// the cell centre; the kernel's pdf follows the same cells, so any weighting is unbiased. The
/// cells are drawn by Walker's alias method (`push_alias`): two loads where a search of the
/// marginal and conditional CDFs loaded about log2 of the cell count, each lane by lane on CPU
/// drivers.
pub(crate) fn environment(
    environment: Option<&Environment>,
    aux: &mut Aux,
    has_lights: bool,
) -> Result<GpuEnv, TraceError> {
    let mut env = GpuEnv {
        kind: ENV_NONE,
        image: 0,
        dist: 0,
        size: 0,
        radiance: Vec3::ZERO,
        pick: 0.0,
        to_world: Mat3::IDENTITY,
        to_local: Mat3::IDENTITY,
    };
    let pick = if has_lights { 0.5 } else { 1.0 };
    match environment {
        None => {}
        Some(Environment::Constant { radiance }) => {
            env.kind = ENV_CONSTANT;
            env.radiance = *radiance;
            env.pick = if radiance.max_element() > 0.0 { pick } else { 0.0 };
        }
        Some(Environment::Map(map)) => {
            let (w, h) = (map.width as usize, map.height as usize);
            if w < 1 || h < 2 || w > 0xffff || h > 0xffff || map.data.len() != w * h * 3 {
                return Err(TraceError::Invalid(format!(
                    "environment map {} is {w}×{h}: it needs at least 2 rows of RGB pixels and at most 65535 a side",
                    map.path.display()
                )));
            }
            let linear = Mat3::from_mat4(map.to_world);
            if linear.determinant().abs() < 1e-12 || !linear.is_finite() {
                return Err(TraceError::Invalid(format!(
                    "environment map {}: its to_world transform is singular",
                    map.path.display()
                )));
            }
            env.kind = ENV_MAP;
            env.radiance = Vec3::splat(map.scale);
            env.to_world = linear;
            env.to_local = linear.inverse();
            env.image = aux.push_image(&map.data);
            env.size = map.width | map.height << 16;
            let lum: Vec<f64> = map.data.chunks_exact(3).map(luminance).collect();
            let ny = h - 1;
            let mut cells = Vec::with_capacity(ny * w);
            for y in 0..ny {
                let sin_theta = (std::f64::consts::PI * (y as f64 + 0.5) / ny as f64).sin();
                for x in 0..w {
                    let x1 = (x + 1) % w;
                    let l = lum[y * w + x] + lum[y * w + x1] + lum[(y + 1) * w + x] + lum[(y + 1) * w + x1];
                    cells.push(0.25 * l * sin_theta);
                }
            }
            env.dist = aux.align4();
            let total = push_alias(&mut aux.data, &cells);
            env.pick = if total > 0.0 && map.scale > 0.0 { pick } else { 0.0 };
        }
    }
    Ok(env)
}

/// The kernel's traversal stack; mirrors `STACK_SIZE` in the kernel.
const STACK_SIZE: usize = 96;

pub(crate) struct GpuScene {
    pub nodes: Vec<GpuWideNode>,
    /// Triangles and, in slots of their own, analytic shapes (`e2.w` holds the bits of the shape's
    /// index + 1; 0 for a triangle), in the BVH's leaf order.
    pub tris: Vec<GpuTri>,
    pub shapes: Vec<GpuShape>,
    pub normals: Vec<GpuNormals>,
    pub materials: Vec<GpuMaterial>,
    pub lights: Vec<GpuLight>,
    pub aux: Vec<f32>,
    pub env: GpuEnv,
    pub features: KernelFeatures,
}

/// What of the kernel a scene uses; the renderer compiles the rest out.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct KernelFeatures {
    pub textures: bool,
    pub environment: bool,
    /// The environment is an image (Mitsuba's `envmap`), not a constant.
    pub environment_map: bool,
    /// Which emitters: bit k for an analytic shape of the kernel's kind k (sphere 0, disk 1,
    /// rectangle 2 (a cube's faces too), cylinder 3), bit 4 for a triangle; light sampling runs
    /// only their code (a sphere's cone sampling, for one, costs every lane of every bounce). None:
    /// next-event estimation samples the environment alone ([`KernelFeatures::lights`]).
    pub light_kinds: u8,
    pub rough_dielectric: bool,
    pub rough_plastic: bool,
    pub beckmann: bool,
    /// A mirror (a conductor of alpha 0).
    pub smooth_conductor: bool,
    /// A conductor with a microfacet distribution (alpha > 0).
    pub rough_conductor: bool,
    /// Smooth glass (a dielectric of alpha 0 that is not thin).
    pub dielectric: bool,
    pub thin_dielectric: bool,
    /// A plastic with a smooth coat (alpha 0).
    pub plastic: bool,
    /// Few enough triangles and shapes ([`FLAT_SCAN_MAX_TRIANGLES`], a shape counting as
    /// [`flat_scan_cost`] triangles) that rays test them all instead of walking the BVH.
    pub flat_scan: bool,
    /// Some mesh is an analytic shape.
    pub shapes: bool,
    /// More analytic shapes than the kernel's uniform buffer of shapes holds (`UNIFORM_SHAPES`):
    /// the rest are read from a storage buffer.
    pub many_shapes: bool,
    /// Some mesh has vertex normals (interpolated shading normals).
    pub shading_normals: bool,
    /// The film's pixel filter is a tent or a gaussian (sampled in a loop; the box is one draw).
    pub wide_filter: bool,
}

/// Scenes with at most this many triangles are intersected by a flat scan: every ray tests every
/// triangle, which the specialized kernel holds as literals (`scan.rs`), so no invocation loads
/// one, where a BVH walk loads nodes and triangles per invocation (per SIMD lane on CPU drivers).
/// Measured on lavapipe, 2 threads, `hush render SCENE --spp 16 --width 256 --height 256`, the
/// second run of each (the first compiles the kernel), against the same binary with the threshold
/// at 100,000: the Cornell box with a UV sphere of 98, 288 or 968 triangles added (134, 324 and
/// 1,004 in all) ran 0.40, 0.17 and 0.04 M paths per CPU-second with the scan against 0.20, 0.19
/// and 0.15 with the BVH walk: the scan's cost grows with the triangle count and crosses the
/// walk's near 275 triangles. The box alone (36) runs 2.9 M (512², 64 spp).
pub const FLAT_SCAN_MAX_TRIANGLES: usize = 192;

/// What one analytic shape costs a flat scan, in triangles (see [`FLAT_SCAN_MAX_TRIANGLES`]), rounded
/// up. Measured on lavapipe, 2 threads, 256², 128 spp, max_depth 1 (one ray a path), a grid of
/// shapes seen by the camera against an empty scene: 192 triangles (16 cubes) added 3.6 ns per
/// triangle to each path, 32 rectangles 1.9 ns each, 32 spheres 7.9 ns, 32 cylinders 8.2 ns.
pub fn flat_scan_cost(kind: hush_scene::ShapeKind) -> usize {
    use hush_scene::ShapeKind::*;
    match kind {
        Disk | Rectangle => 1,
        Sphere => 3,
        Cylinder => 3,
        // Six rectangles, where its twelve triangles would cost twelve.
        Cube => 6,
    }
}

impl KernelFeatures {
    /// The generic kernel.
    pub const ALL: KernelFeatures = KernelFeatures {
        textures: true,
        environment: true,
        environment_map: true,
        light_kinds: LIGHT_TRIANGLES | LIGHT_SHAPES,
        rough_dielectric: true,
        rough_plastic: true,
        beckmann: true,
        smooth_conductor: true,
        rough_conductor: true,
        dielectric: true,
        thin_dielectric: true,
        plastic: true,
        flat_scan: false,
        shapes: true,
        many_shapes: true,
        shading_normals: true,
        wide_filter: true,
    };
    /// None of the optional features (diffuse, smooth and GGX-rough conductors, smooth and
    /// thin glass, smooth plastic, triangle lights, flat face normals, the box filter remain).
    pub const NONE: KernelFeatures = KernelFeatures {
        textures: false,
        environment: false,
        environment_map: false,
        light_kinds: 0,
        rough_dielectric: false,
        rough_plastic: false,
        beckmann: false,
        smooth_conductor: false,
        rough_conductor: false,
        dielectric: false,
        thin_dielectric: false,
        plastic: false,
        flat_scan: false,
        shapes: false,
        many_shapes: false,
        shading_normals: false,
        wide_filter: false,
    };

    /// Some triangle or shape emits: next-event estimation samples lights as well as the environment.
    pub fn lights(&self) -> bool {
        self.light_kinds != 0
    }

    /// The features `scene` uses.
    pub fn of(scene: &Scene) -> KernelFeatures {
        let mut f = KernelFeatures {
            environment: scene.environment.is_some(),
            environment_map: matches!(scene.environment, Some(Environment::Map(_))),
            light_kinds: scene
                .meshes
                .iter()
                .filter(|m| m.emission.is_some_and(|e| e.max_element() > 0.0))
                .map(|m| match &m.analytic {
                    Some(a) => 1 << shape_kind(a.kind),
                    None if !m.indices.is_empty() => LIGHT_TRIANGLES,
                    None => 0,
                })
                .fold(0, |kinds, k| kinds | k),
            flat_scan: scene.mesh_triangle_count()
                + scene.meshes.iter().filter_map(|m| m.analytic).map(|a| flat_scan_cost(a.kind)).sum::<usize>()
                <= FLAT_SCAN_MAX_TRIANGLES,
            shapes: scene.analytic_count() > 0,
            many_shapes: scene
                .meshes
                .iter()
                .filter_map(|m| m.analytic)
                .map(|a| if a.kind == hush_scene::ShapeKind::Cube { a.cube_faces().len() } else { 1 })
                .sum::<usize>()
                > crate::render::UNIFORM_SHAPES,
            ..KernelFeatures::NONE
        };
        f.shading_normals = scene.meshes.iter().any(|m| m.normals.is_some() && m.analytic.is_none());
        f.wide_filter = scene.film.filter != hush_scene::PixelFilter::Box;
        for m in scene.meshes.iter().map(|m| &m.material) {
            f.textures |= m.texture().is_some();
            let (alpha, distribution) = match *m {
                Material::Conductor { alpha, distribution, .. } => {
                    f.smooth_conductor |= alpha == 0.0;
                    f.rough_conductor |= alpha > 0.0;
                    (alpha, distribution)
                }
                Material::Dielectric { thin: true, .. } => {
                    f.thin_dielectric = true;
                    continue;
                }
                Material::Dielectric { alpha, distribution, thin: false, .. } => {
                    f.rough_dielectric |= alpha > 0.0;
                    f.dielectric |= alpha == 0.0;
                    (alpha, distribution)
                }
                Material::Plastic { alpha, distribution, .. } => {
                    f.rough_plastic |= alpha > 0.0;
                    f.plastic |= alpha == 0.0;
                    (alpha, distribution)
                }
                _ => continue,
            };
            f.beckmann |= alpha > 0.0 && distribution == Microfacet::Beckmann;
        }
        f
    }
}

fn v4(v: Vec3, w: f32) -> [f32; 4] {
    [v.x, v.y, v.z, w]
}

/// Each mesh becomes one material record (its BSDF and emission) and its triangles, or, for an
/// analytic shape, one slot that names its [`GpuShape`]. Emissive slots are picked in proportion to
/// their power (area × summed RGB radiance); the kernel's per-area density of a light point is
/// that probability divided by the slot's area, stored in `e1.w`. Slots are stored in the leaf
/// order of a BVH built over them.
pub(crate) fn flatten(scene: &Scene) -> Result<GpuScene, TraceError> {
    let mut tris = Vec::with_capacity(scene.triangle_count());
    let mut normals = Vec::with_capacity(scene.triangle_count());
    let mut materials = Vec::with_capacity(scene.meshes.len());
    let mut light_weights = Vec::new();
    let mut aux = Aux::default();
    let mut shapes = Vec::new();
    // Each slot's bounds, the point the BVH sorts it by, and its area.
    let mut slots: Vec<((Vec3, Vec3), Vec3, f32)> = Vec::with_capacity(scene.triangle_count());
    for (mi, mesh) in scene.meshes.iter().enumerate() {
        let emission = mesh.emission.unwrap_or(Vec3::ZERO);
        let emits = emission.max_element() > 0.0;
        materials.push(gpu_material(&mesh.material, emission, &scene.textures, &mut aux)?);
        if let Some(analytic) = &mesh.analytic {
            let parts =
                if analytic.kind == hush_scene::ShapeKind::Cube { analytic.cube_faces() } else { vec![*analytic] };
            for part in &parts {
                let shape = GpuShape::new(part);
                if !bytemuck::cast_slice::<GpuShape, f32>(std::slice::from_ref(&shape)).iter().all(|x| x.is_finite())
                    || shape.info[2] <= 0.0
                {
                    return Err(TraceError::Invalid(format!(
                        "shape '{}' ({}) has a degenerate or non-finite placement: fix its to_world",
                        mesh.name,
                        analytic.kind.name()
                    )));
                }
                let area = shape.info[2];
                if emits {
                    light_weights.push((tris.len() as u32, area * emission.element_sum()));
                }
                let tag = f32::from_bits(shapes.len() as u32 + 1);
                let mi = f32::from_bits(mi as u32);
                tris.push(GpuTri { p0: [0.0, 0.0, 0.0, mi], e1: [0.0; 4], e2: [0.0, 0.0, 0.0, tag] });
                normals.push(GpuNormals::zeroed());
                let (lo, hi) = part.bounds();
                slots.push(((lo, hi), (lo + hi) * 0.5, area));
                shapes.push(shape);
            }
            continue;
        }
        let uv = |k: u32| mesh.uvs.as_ref().map_or(Vec2::ZERO, |u| u[k as usize]);
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
            let area = 0.5 * (b - a).cross(c - a).length();
            slots.push(((a.min(b).min(c), a.max(b).max(c)), (a + b + c) / 3.0, area));
            let [t0, t1, t2] = idx.map(uv);
            normals.push(GpuNormals {
                n: match &mesh.normals {
                    Some(n) => idx.map(|k| v4(n[k as usize], 1.0)),
                    None => [[0.0; 4]; 3],
                },
                uv01: [t0.x, t0.y, t1.x, t1.y],
                uv2: [t2.x, t2.y, 0.0, 0.0],
            });
        }
    }
    // Reorder the slots into the BVH's leaf order; lights follow their slots.
    let bounds: Vec<(Vec3, Vec3)> = slots.iter().map(|s| s.0).collect();
    let centroids: Vec<Vec3> = slots.iter().map(|s| s.1).collect();
    let bvh = Bvh::build_bounds(&bounds, &centroids);
    let wide = WideBvh::build(&bvh).map_err(TraceError::Invalid)?;
    if wide.stack > STACK_SIZE {
        return Err(TraceError::Invalid(format!(
            "the scene's BVH needs {} traversal stack entries; the kernel's stack holds {STACK_SIZE}",
            wide.stack
        )));
    }
    // The slots in the order the wide nodes' leaves refer to them.
    let order: Vec<u32> = wide.order.iter().map(|&k| bvh.order[k as usize]).collect();
    let mut new_index = vec![0u32; tris.len()];
    for (k, &old) in order.iter().enumerate() {
        new_index[old as usize] = k as u32;
    }
    let mut tris: Vec<GpuTri> = order.iter().map(|&i| tris[i as usize]).collect();
    let normals: Vec<GpuNormals> = order.iter().map(|&i| normals[i as usize]).collect();
    let areas: Vec<f32> = order.iter().map(|&i| slots[i as usize].2).collect();
    for (tri, _) in light_weights.iter_mut() {
        *tri = new_index[*tri as usize];
    }
    let total: f64 = light_weights.iter().map(|&(_, w)| w as f64).sum();
    let mut lights = Vec::with_capacity(light_weights.len());
    let mut running = 0.0f64;
    for &(tri, w) in &light_weights {
        running += w as f64;
        let t = &mut tris[tri as usize];
        t.e1[3] = (w as f64 / total / areas[tri as usize] as f64) as f32;
        lights.push(GpuLight { tri, cdf: (running / total) as f32, pad: [0; 2] });
    }
    if let Some(last) = lights.last_mut() {
        last.cdf = 1.0;
    }
    let nodes = wide.nodes;
    let env = environment(scene.environment.as_ref(), &mut aux, !lights.is_empty())?;
    let features = KernelFeatures::of(scene);
    debug_assert_eq!(features.many_shapes, shapes.len() > crate::render::UNIFORM_SHAPES, "shapes counted as flattened");
    debug_assert_eq!(features.lights(), !lights.is_empty(), "emitters counted as flattened");
    // A whole number of four-word texels, for the kernel's four-word view of the array.
    aux.align4();
    Ok(GpuScene { nodes, tris, shapes, normals, materials, lights, aux: aux.data, env, features })
}

#[cfg(test)]
mod tests {
    use super::push_alias;

    /// A texture's texels as the kernel's `texture_texel` reads them: from an even offset, per texel
    /// `pack2x16float(r, g)` and `pack2x16float(b, 0)`; values rounded to the nearest half, clamped to
    /// [0, 65504], NaN as 0.
    #[test]
    fn textures_are_stored_as_halves_two_words_a_texel_from_an_even_offset() {
        let mut aux = super::Aux::default();
        aux.data.push(7.0); // something before it: the texture starts at the next even offset
        let offset = aux.push_texture(&[0.5, 0.1, 1.0, 7e4, f32::NAN, -1.0]) as usize;
        assert_eq!(offset, 2);
        assert_eq!(aux.data.len(), 2 + 2 * 2);
        assert_eq!(aux.push_texture(&[1.0, 1.0, 1.0]), 6, "already even: no padding");
        let halves = |w: f32| {
            let b = w.to_bits();
            [half::f16::from_bits(b as u16).to_f32(), half::f16::from_bits((b >> 16) as u16).to_f32()]
        };
        let texel = |i: usize| {
            let (rg, b) = (halves(aux.data[offset + 2 * i]), halves(aux.data[offset + 1 + 2 * i]));
            assert_eq!(b[1], 0.0, "the fourth half is zero");
            [rg[0], rg[1], b[0]]
        };
        assert_eq!(texel(0), [0.5, half::f16::from_f32(0.1).to_f32(), 1.0]);
        assert!((texel(0)[1] - 0.1).abs() < 0.1 / 2048.0, "a half keeps 11 significant bits");
        assert_eq!(texel(1), [65504.0, 0.0, 0.0]);
    }

    /// A material carries its texture's size for the kernel (`width | height << 16`); a texture wider or
    /// taller than that holds is an error naming it, not a wrapped size.
    #[test]
    fn a_material_carries_its_texture_size_and_refuses_one_too_large() {
        use hush_scene::{Material, Reflectance, Texture, TextureId};
        let texture = |width: u32, height: u32| Texture {
            path: "t.png".into(),
            width,
            height,
            data: vec![0.5; 3 * (width * height) as usize],
        };
        let diffuse = Material::Diffuse { reflectance: Reflectance::Texture(TextureId(1)), two_sided: false };
        let mut aux = super::Aux::default();
        let textures = [texture(1, 1), texture(3, 5)];
        let m = super::gpu_material(&diffuse, glam::Vec3::ZERO, &textures, &mut aux).unwrap();
        assert_eq!(m.e[3].to_bits(), 3 | 5 << 16);
        assert_eq!(m.e[0].to_bits() % 2, 0, "an even offset");
        let e = super::gpu_material(&diffuse, glam::Vec3::ZERO, &[texture(1, 1), texture(65536, 1)], &mut aux)
            .err()
            .expect("too wide");
        assert!(e.to_string().contains("texture 1 is 65536×1") && e.to_string().contains("65535"), "{e}");
    }

    /// Drawing a cell uniformly, keeping it with its threshold and otherwise taking its alias picks
    /// each cell with exactly its stored probability (up to `f32` rounding), for skewed, sparse and
    /// all-zero weights.
    #[test]
    fn alias_table_reproduces_its_probabilities() {
        let skewed: Vec<f64> =
            (0..1000).map(|i| ((i * 7919) % 1000) as f64 * if i % 97 == 0 { 1e4 } else { 1.0 }).collect();
        let sparse: Vec<f64> = (0..64).map(|i| if i == 5 || i == 40 { 3.0 } else { 0.0 }).collect();
        for weights in [skewed, sparse, vec![0.0; 8], vec![2.5]] {
            let mut aux = Vec::new();
            let total = push_alias(&mut aux, &weights);
            assert_eq!(total, weights.iter().sum::<f64>());
            let n = weights.len();
            let mut picked = vec![0.0f64; n];
            for i in 0..n {
                let (keep, alias) = (aux[4 * i] as f64, aux[4 * i + 1].to_bits() as usize);
                assert!((0.0..=1.0).contains(&keep) && alias < n);
                picked[i] += keep / n as f64;
                picked[alias] += (1.0 - keep) / n as f64;
            }
            for i in 0..n {
                let want = if total > 0.0 { weights[i] / total } else { 1.0 / n as f64 };
                assert!((aux[4 * i + 2] as f64 - want).abs() <= 1e-7 * want.max(1e-30) + 1e-12);
                assert!((picked[i] - want).abs() <= 1e-6 * want + 1e-9, "cell {i}: picked {} want {want}", picked[i]);
                if want == 0.0 {
                    assert_eq!(picked[i], 0.0, "cell {i} has no weight and must never be picked");
                }
            }
        }
    }
}
