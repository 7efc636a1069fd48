//! glTF 2.0 scenes (`.gltf` with embedded or external buffers, `.glb`).
//!
//! Read: the default scene's node hierarchy (each node's transform applied after its
//! children's), triangle primitives with positions, normals and the first UV set, the first
//! perspective camera (`yfov`, `aspectRatio`), and metallic-roughness materials mapped as:
//!
//! - `KHR_materials_transmission` factor > 0: a dielectric of `KHR_materials_ior` (default
//!   1.5), GGX alpha = roughness², transmittance = base color;
//! - metallic ≥ 0.5: a conductor reflecting the base color (Fresnel factor 1), alpha =
//!   roughness²;
//! - otherwise roughness 1: diffuse with the base color (or its texture, times its factor);
//!   roughness < 1: a rough plastic (base color under an IOR-1.5 coating, alpha = roughness²).
//!
//! `doubleSided` is `two_sided`; `emissiveFactor` × `KHR_materials_emissive_strength` is the
//! emitted radiance. Base color textures are sRGB and are decoded to linear. A mirroring node
//! transform flips the winding, as glTF specifies. Unsupported features (orthographic cameras,
//! other textures, alpha blending, other extensions) are warnings.

use std::collections::HashMap;
use std::path::Path;

use glam::{Mat4, Vec2, Vec3};

use crate::shapes::Geometry;
use crate::texture::srgb_to_linear;
use crate::{
    Camera, Film, Material, Mesh, Microfacet, PixelFilter, Reflectance, Scene, SceneError, Texture, TextureId,
};

const SUPPORTED_EXTENSIONS: &[&str] =
    &["KHR_materials_emissive_strength", "KHR_materials_transmission", "KHR_materials_ior"];

/// Film height for glTF cameras; the width follows the camera's `aspectRatio`.
const FILM_HEIGHT: u32 = 512;

struct Loader<'a> {
    path: &'a Path,
    buffers: Vec<gltf::buffer::Data>,
    images: Vec<gltf::image::Data>,
    textures: Vec<Texture>,
    texture_ids: HashMap<(usize, [u32; 3]), TextureId>,
    warnings: Vec<String>,
    meshes: Vec<Mesh>,
    camera: Option<(Camera, Option<f32>)>,
    /// The nodes walked so far: glTF gives a node one parent, so a second visit is a cycle or a shared child.
    visited: std::collections::HashSet<usize>,
}

/// The deepest node hierarchy walked (the walk recurses); real files nest a few dozen levels at most.
const MAX_NODE_DEPTH: usize = 256;

pub(crate) fn load_gltf(path: &Path) -> Result<Scene, SceneError> {
    if !path.is_file() {
        return Err(SceneError::new(path, None, "scene file not found: check the path"));
    }
    let (doc, buffers, images) =
        gltf::import(path).map_err(|e| SceneError::new(path, None, format!("cannot load glTF: {e}")))?;
    let mut loader = Loader {
        path,
        buffers,
        images,
        textures: Vec::new(),
        texture_ids: HashMap::new(),
        warnings: Vec::new(),
        meshes: Vec::new(),
        camera: None,
        visited: std::collections::HashSet::new(),
    };
    for ext in doc.extensions_used() {
        if !SUPPORTED_EXTENSIONS.contains(&ext) {
            loader.warn(format!("extension {ext} is not supported yet and is ignored"));
        }
    }
    let scene = doc
        .default_scene()
        .or_else(|| doc.scenes().next())
        .ok_or_else(|| SceneError::new(path, None, "the glTF file has no scene"))?;
    for node in scene.nodes() {
        loader.node(&node, Mat4::IDENTITY, 0)?;
    }
    if loader.meshes.is_empty() {
        return Err(SceneError::new(path, None, "the glTF scene holds no (non-degenerate) triangles"));
    }
    let (camera, aspect) = loader.camera.take().unzip();
    let aspect = aspect.flatten();
    let film = match aspect {
        Some(a) => Film {
            width: ((FILM_HEIGHT as f32 * a).round() as u32).max(1),
            height: FILM_HEIGHT,
            filter: PixelFilter::Box,
        },
        None => Film { width: 768, height: 576, filter: PixelFilter::Box },
    };
    let mut out = Scene {
        camera: Camera { origin: Vec3::Z, target: Vec3::ZERO, up: Vec3::Y, fov_y_deg: 40.0 },
        film,
        max_depth: u32::MAX,
        spp: None,
        meshes: std::mem::take(&mut loader.meshes),
        textures: std::mem::take(&mut loader.textures),
        environment: None,
        warnings: std::mem::take(&mut loader.warnings),
    };
    match camera {
        Some(c) => out.camera = c,
        None => {
            out.camera = crate::obj::framing_camera(&out, film, 40.0);
            out.warnings.push(format!(
                "{}: no perspective camera: hush looks at the geometry's centre from +z with a 40° vertical fov",
                path.display()
            ));
        }
    }
    out.camera.validate().map_err(|m| SceneError::new(path, None, format!("camera: {m}")))?;
    Ok(out)
}

impl Loader<'_> {
    fn warn(&mut self, msg: impl AsRef<str>) {
        self.warnings.push(format!("{}: {}", self.path.display(), msg.as_ref()));
    }

    fn node(&mut self, node: &gltf::Node, parent: Mat4, depth: usize) -> Result<(), SceneError> {
        if !self.visited.insert(node.index()) {
            return Err(SceneError::new(
                self.path,
                None,
                format!(
                    "node {} is reached twice in the node hierarchy (a cycle, or a second parent: glTF allows one)",
                    node.index()
                ),
            ));
        }
        if depth > MAX_NODE_DEPTH {
            return Err(SceneError::new(
                self.path,
                None,
                format!("the node hierarchy is deeper than {MAX_NODE_DEPTH} levels at node {}", node.index()),
            ));
        }
        let world = parent * Mat4::from_cols_array_2d(&node.transform().matrix());
        if !world.is_finite() {
            return Err(SceneError::new(self.path, None, format!("node {} has a non-finite transform", node.index())));
        }
        let label = node.name().map(str::to_string).unwrap_or_else(|| format!("node {}", node.index()));
        if let Some(cam) = node.camera() {
            match cam.projection() {
                gltf::camera::Projection::Perspective(p) if self.camera.is_none() => {
                    // glTF cameras look along local -z with +y up.
                    let origin = world.transform_point3(Vec3::ZERO);
                    let forward = world.transform_vector3(-Vec3::Z).normalize_or_zero();
                    let up = world.transform_vector3(Vec3::Y).normalize_or_zero();
                    let camera = Camera { origin, target: origin + forward, up, fov_y_deg: p.yfov().to_degrees() };
                    self.camera = Some((camera, p.aspect_ratio()));
                }
                gltf::camera::Projection::Perspective(_) => {
                    self.warn(format!("camera of '{label}' is ignored: hush renders the first perspective camera"))
                }
                gltf::camera::Projection::Orthographic(_) => {
                    self.warn(format!("orthographic camera of '{label}' is not supported yet and is ignored"))
                }
            }
        }
        if let Some(mesh) = node.mesh() {
            for prim in mesh.primitives() {
                self.primitive(&prim, &world, &label, mesh.name())?;
            }
        }
        for child in node.children() {
            self.node(&child, world, depth + 1)?;
        }
        Ok(())
    }

    fn primitive(
        &mut self,
        prim: &gltf::Primitive,
        world: &Mat4,
        node: &str,
        mesh: Option<&str>,
    ) -> Result<(), SceneError> {
        let name = format!("{}/{}#{}", node, mesh.unwrap_or("mesh"), prim.index());
        if prim.mode() != gltf::mesh::Mode::Triangles {
            self.warn(format!(
                "primitive '{name}' has mode {:?}: only triangle lists are supported, it is skipped",
                prim.mode()
            ));
            return Ok(());
        }
        let buffers = &self.buffers;
        let reader = prim.reader(|b| buffers.get(b.index()).map(|d| &d.0[..]));
        let positions: Vec<Vec3> = reader
            .read_positions()
            .ok_or_else(|| SceneError::new(self.path, None, format!("primitive '{name}' has no POSITION")))?
            .map(Vec3::from)
            .collect();
        let normals = reader.read_normals().map(|n| n.map(Vec3::from).collect::<Vec<_>>());
        let uvs = reader.read_tex_coords(0).map(|t| t.into_f32().map(Vec2::from).collect::<Vec<_>>());
        let flat: Vec<u32> = match reader.read_indices() {
            Some(i) => i.into_u32().collect(),
            None => (0..positions.len() as u32).collect(),
        };
        let indices = flat.chunks_exact(3).map(|t| [t[0], t[1], t[2]]).collect();
        let normals = normals.filter(|n| n.len() == positions.len());
        let uvs = uvs.filter(|u| u.len() == positions.len());
        let mut g = Geometry { positions, normals, uvs, indices };
        g.transform(world, true);
        let dropped = g.check().map_err(|m| SceneError::new(self.path, None, format!("primitive '{name}': {m}")))?;
        if dropped > 0 {
            self.warn(format!("primitive '{name}': dropped {dropped} degenerate triangles"));
        }
        let (material, emission) = self.material(&prim.material(), &name);
        if g.indices.is_empty() {
            if emission.is_some() {
                return Err(SceneError::new(
                    self.path,
                    None,
                    format!("primitive '{name}' is emissive but has zero area: fix the mesh or its material"),
                ));
            }
            self.warn(format!("primitive '{name}' has no area and is skipped"));
            return Ok(());
        }
        self.meshes.push(Mesh {
            name: prim.material().name().map(str::to_string).unwrap_or(name),
            positions: g.positions,
            normals: g.normals,
            uvs: g.uvs,
            indices: g.indices,
            material,
            emission,
            analytic: None,
        });
        Ok(())
    }

    /// The base color texture `image` (sRGB, decoded to linear) times `factor`, made once.
    fn texture(&mut self, image: usize, factor: Vec3) -> Result<TextureId, String> {
        let key = (image, factor.to_array().map(f32::to_bits));
        if let Some(&id) = self.texture_ids.get(&key) {
            return Ok(id);
        }
        let img = self.images.get(image).ok_or_else(|| format!("image {image} is missing"))?;
        use gltf::image::Format as F;
        let lut: Vec<f32> = (0..256).map(|i| srgb_to_linear(i as f32 / 255.0)).collect();
        let (channels, bytes) = match img.format {
            F::R8 => (1, 1),
            F::R8G8 => (2, 1),
            F::R8G8B8 => (3, 1),
            F::R8G8B8A8 => (4, 1),
            F::R16 => (1, 2),
            F::R16G16 => (2, 2),
            F::R16G16B16 => (3, 2),
            F::R16G16B16A16 => (4, 2),
            F::R32G32B32FLOAT => (3, 4),
            F::R32G32B32A32FLOAT => (4, 4),
        };
        let texel = |i: usize, c: usize| -> f32 {
            let c = if channels < 3 { 0 } else { c };
            let o = (i * channels + c) * bytes;
            let p = &img.pixels;
            match bytes {
                1 => lut[p[o] as usize],
                2 => srgb_to_linear(u16::from_le_bytes([p[o], p[o + 1]]) as f32 / 65535.0),
                _ => f32::from_le_bytes([p[o], p[o + 1], p[o + 2], p[o + 3]]),
            }
        };
        let n = img.width as usize * img.height as usize;
        if img.pixels.len() < n * channels * bytes {
            return Err(format!("image {image} is truncated"));
        }
        let mut data = Vec::with_capacity(n * 3);
        for i in 0..n {
            for c in 0..3 {
                data.push(texel(i, c) * factor[c]);
            }
        }
        let id = TextureId(self.textures.len() as u32);
        self.textures.push(Texture {
            path: self.path.with_extension(format!("gltf#image{image}")),
            width: img.width,
            height: img.height,
            data,
        });
        self.texture_ids.insert(key, id);
        Ok(id)
    }

    fn material(&mut self, m: &gltf::Material, prim: &str) -> (Material, Option<Vec3>) {
        let label = m.name().map(str::to_string).unwrap_or_else(|| format!("material of '{prim}'"));
        let pbr = m.pbr_metallic_roughness();
        let [r, g, b, _a] = pbr.base_color_factor();
        let base_factor = Vec3::new(r, g, b);
        let mut base = Reflectance::Rgb(base_factor);
        if let Some(info) = pbr.base_color_texture() {
            if info.tex_coord() != 0 {
                self.warn(format!("'{label}': base color texture uses UV set {}: hush reads set 0", info.tex_coord()));
            }
            match self.texture(info.texture().source().index(), base_factor) {
                Ok(id) => base = Reflectance::Texture(id),
                Err(e) => self.warn(format!("'{label}': {e}: the base color factor is used")),
            }
        }
        if pbr.metallic_roughness_texture().is_some() {
            self.warn(format!("'{label}': metallic-roughness texture is not supported yet: the factors are used"));
        }
        if m.normal_texture().is_some() || m.occlusion_texture().is_some() || m.emissive_texture().is_some() {
            self.warn(format!(
                "'{label}': normal, occlusion and emissive textures are not supported yet and are ignored"
            ));
        }
        if m.alpha_mode() != gltf::material::AlphaMode::Opaque {
            self.warn(format!(
                "'{label}': alpha mode {:?} is not supported yet: the surface is opaque",
                m.alpha_mode()
            ));
        }
        let metallic = pbr.metallic_factor();
        let roughness = pbr.roughness_factor().clamp(0.0, 1.0);
        let alpha = roughness * roughness;
        let ior = m.ior().unwrap_or(1.5);
        let transmission = m.transmission().map(|t| t.transmission_factor()).unwrap_or(0.0);
        let two_sided = m.double_sided();
        let constant = |base: Reflectance, textures: &[Texture]| match base {
            Reflectance::Rgb(c) => c,
            Reflectance::Texture(id) => textures[id.0 as usize].mean(),
        };
        let material = if transmission > 0.0 {
            if transmission < 1.0 {
                self.warn(format!(
                    "'{label}': partial transmission {transmission} is not supported yet: fully transmissive"
                ));
            }
            if matches!(base, Reflectance::Texture(_)) {
                self.warn(format!(
                    "'{label}': a textured transmittance is not supported yet: the texture's mean is used"
                ));
            }
            Material::Dielectric {
                alpha,
                distribution: Microfacet::Ggx,
                int_ior: ior,
                ext_ior: 1.0,
                thin: false,
                specular_reflectance: Vec3::ONE,
                specular_transmittance: constant(base, &self.textures),
            }
        } else if metallic >= 0.5 {
            if metallic < 1.0 {
                self.warn(format!("'{label}': metallic {metallic} is not supported: taken as a metal (1)"));
            }
            if matches!(base, Reflectance::Texture(_)) {
                self.warn(format!(
                    "'{label}': a textured metal color is not supported yet: the texture's mean is used"
                ));
            }
            Material::Conductor {
                alpha,
                distribution: Microfacet::Ggx,
                ior: None,
                specular_reflectance: constant(base, &self.textures),
                two_sided,
            }
        } else {
            if metallic > 0.0 {
                self.warn(format!("'{label}': metallic {metallic} is not supported: taken as a dielectric (0)"));
            }
            if roughness >= 1.0 {
                Material::Diffuse { reflectance: base, two_sided }
            } else {
                Material::Plastic {
                    diffuse_reflectance: base,
                    specular_reflectance: Vec3::ONE,
                    alpha,
                    distribution: Microfacet::Ggx,
                    int_ior: ior,
                    ext_ior: 1.0,
                    nonlinear: false,
                    two_sided,
                }
            }
        };
        let emission = Vec3::from(m.emissive_factor()) * m.emissive_strength().unwrap_or(1.0);
        (material, (emission.max_element() > 0.0).then_some(emission))
    }
}
