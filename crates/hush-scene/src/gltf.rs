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
use crate::{
    Camera, Film, Material, Mesh, Microfacet, PixelFilter, Reflectance, Scene, SceneError, Texture, TextureId,
};

const SUPPORTED_EXTENSIONS: &[&str] =
    &["KHR_materials_emissive_strength", "KHR_materials_transmission", "KHR_materials_ior"];

/// Film height for glTF cameras; the width follows the camera's `aspectRatio`.
const FILM_HEIGHT: u32 = 512;

struct Loader<'a> {
    path: &'a Path,
    buffers: Vec<Vec<u8>>,
    /// Each image, decoded when a material first uses it (`None`: not yet).
    images: Vec<Option<crate::texture::Pixels>>,
    document: &'a gltf::Document,
    textures: Vec<Texture>,
    texture_ids: HashMap<(usize, [u32; 3]), TextureId>,
    warnings: Vec<String>,
    meshes: Vec<Mesh>,
    camera: Option<(Camera, Option<f32>)>,
    /// The nodes walked so far: glTF gives a node one parent, so a second visit is a cycle or a shared child.
    visited: std::collections::HashSet<usize>,
}

/// The most elements of an accessor without a buffer view (whose zeros no file's length bounds).
const MAX_SPARSE_COUNT: usize = 1 << 24;

/// What a caught panic said.
fn panic_text(p: &Box<dyn std::any::Any + Send>) -> String {
    p.downcast_ref::<&str>().map(|s| s.to_string()).or_else(|| p.downcast_ref::<String>().cloned()).unwrap_or_default()
}

/// The file a relative URI of the glTF names, which must lie in the glTF's folder (or under
/// `HUSH_SCENE_ROOT` where that is set): a downloaded scene reads nothing else of the machine.
fn referenced_file(path: &Path, uri: &str) -> Result<std::path::PathBuf, String> {
    if uri.contains("://") || uri.starts_with('/') || uri.starts_with('\\') {
        return Err(format!("URI '{uri}' is not a relative path: hush reads only files beside the glTF"));
    }
    let decoded = percent_decode(uri).ok_or_else(|| format!("URI '{uri}' has a malformed %-escape"))?;
    let dir = path.parent().unwrap_or(Path::new("."));
    let file = dir.join(&decoded);
    crate::check_inside(&file, dir).map(|()| file)
}

fn percent_decode(s: &str) -> Option<String> {
    let b = s.as_bytes();
    let mut out = Vec::with_capacity(b.len());
    let mut i = 0;
    while i < b.len() {
        if b[i] == b'%' {
            let hex = std::str::from_utf8(b.get(i + 1..i + 3)?).ok()?;
            out.push(u8::from_str_radix(hex, 16).ok()?);
            i += 3;
        } else {
            out.push(b[i]);
            i += 1;
        }
    }
    String::from_utf8(out).ok()
}

/// The payload of a `data:` URI (base64 only, as glTF writes them).
fn data_uri(uri: &str) -> Option<Result<Vec<u8>, String>> {
    let rest = uri.strip_prefix("data:")?;
    Some(match rest.split_once(";base64,") {
        Some((_, payload)) => base64_decode(payload).ok_or_else(|| "a data URI is not valid base64".to_string()),
        None => Err("a data URI is not base64-encoded: glTF embeds buffers and images as base64".into()),
    })
}

fn base64_decode(s: &str) -> Option<Vec<u8>> {
    let value = |c: u8| match c {
        b'A'..=b'Z' => Some(c - b'A'),
        b'a'..=b'z' => Some(c - b'a' + 26),
        b'0'..=b'9' => Some(c - b'0' + 52),
        b'+' | b'-' => Some(62),
        b'/' | b'_' => Some(63),
        _ => None,
    };
    let digits: Vec<u8> = s.bytes().filter(|c| !c.is_ascii_whitespace()).collect();
    let digits = digits.strip_suffix(b"==").or_else(|| digits.strip_suffix(b"=")).unwrap_or(&digits);
    let mut out = Vec::with_capacity(digits.len() * 3 / 4);
    let (mut acc, mut bits) = (0u32, 0);
    for &c in digits {
        acc = (acc << 6) | u32::from(value(c)?);
        bits += 6;
        if bits >= 8 {
            bits -= 8;
            out.push((acc >> bits) as u8);
        }
    }
    Some(out)
}

/// Every buffer of the document: the GLB's binary chunk, a data URI or a file beside the glTF, each read
/// up to the scene limit and at least as long as its declared `byteLength`.
fn read_buffers(path: &Path, doc: &gltf::Document, mut blob: Option<Vec<u8>>) -> Result<Vec<Vec<u8>>, SceneError> {
    let mut out = Vec::new();
    for buffer in doc.buffers() {
        let fail = |m: String| SceneError::new(path, None, format!("buffer {}: {m}", buffer.index()));
        let data = match buffer.source() {
            gltf::buffer::Source::Bin => blob.take().ok_or_else(|| fail("the GLB has no binary chunk".into()))?,
            gltf::buffer::Source::Uri(uri) => match data_uri(uri) {
                Some(d) => d.map_err(fail)?,
                None => {
                    let file = referenced_file(path, uri).map_err(fail)?;
                    hush_io::read_limited_bare(&file, crate::max_file_bytes())
                        .map_err(|e| fail(format!("{}: {e}", file.display())))?
                }
            },
        };
        if data.len() < buffer.length() {
            return Err(fail(format!("holds {} bytes but declares byteLength {}", data.len(), buffer.length())));
        }
        out.push(data);
    }
    Ok(out)
}

/// A GLB's 12-byte header (magic, version, length) is whole and declares at least itself.
fn check_glb_header(bytes: &[u8]) -> Result<(), String> {
    if !bytes.starts_with(b"glTF") {
        return Ok(());
    }
    let declared = bytes.get(8..12).map(|b| u32::from_le_bytes([b[0], b[1], b[2], b[3]]));
    match declared {
        None => Err(format!("the GLB header is truncated ({} bytes of 12)", bytes.len())),
        Some(n) if n < 12 => Err(format!("the GLB header declares a length of {n} bytes, less than the header itself")),
        Some(_) => Ok(()),
    }
}

/// Every primitive's attributes and indices name accessors that exist.
fn check_attribute_accessors(root: &gltf::json::Root) -> Result<(), String> {
    let count = root.accessors.len();
    for (m, mesh) in root.meshes.iter().enumerate() {
        for (p, prim) in mesh.primitives.iter().enumerate() {
            let named = prim.attributes.values().map(|a| a.value()).chain(prim.indices.iter().map(|a| a.value()));
            if let Some(bad) = named.into_iter().find(|&i| i >= count) {
                return Err(format!("mesh {m} primitive {p} names accessor {bad}, but the file has {count} accessors"));
            }
        }
    }
    Ok(())
}

/// The deepest node hierarchy walked (the walk recurses); real files nest a few dozen levels at most.
const MAX_NODE_DEPTH: usize = 256;

pub(crate) fn load_gltf(path: &Path) -> Result<Scene, SceneError> {
    let bytes = hush_io::read_limited_bare(path, crate::max_file_bytes())
        .map_err(|e| SceneError::new(path, None, format!("cannot read the scene file: {e}")))?;
    let fail = |m: String| SceneError::new(path, None, m);
    // gltf 1.4 panics on two kinds of malformed file that fuzzing found: a GLB header whose length is
    // below its own 12 bytes (an underflow), and a POSITION attribute naming an accessor that does not
    // exist (an index in its validation). Both are refused here first; any other panic of the crate is
    // still this file's error, not the process's end.
    check_glb_header(&bytes).map_err(fail)?;
    let loaded = std::panic::catch_unwind(|| -> Result<(gltf::Document, Option<Vec<u8>>), String> {
        let invalid = |e: gltf::Error| format!("cannot load glTF: {e}");
        let parsed = gltf::Gltf::from_slice_without_validation(&bytes).map_err(invalid)?;
        check_attribute_accessors(parsed.document.as_json())?;
        let blob = parsed.blob;
        Ok((gltf::Document::from_json(parsed.document.into_json()).map_err(invalid)?, blob))
    });
    let (doc, blob) = loaded.map_err(|p| fail(format!("malformed glTF ({})", panic_text(&p))))?.map_err(fail)?;
    let buffers = read_buffers(path, &doc, blob)?;
    let images = doc.images().map(|_| None).collect();
    let mut loader = Loader {
        path,
        buffers,
        images,
        document: &doc,
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

/// The accessors hush reads, checked against what glTF requires of them (the reader of the gltf crate
/// assumes it): POSITION and NORMAL are float VEC3, TEXCOORD_0 a float or normalized VEC2, indices
/// unsigned SCALARs, each wholly inside its buffer view.
fn check_accessors(prim: &gltf::Primitive) -> Result<(), String> {
    use gltf::accessor::{DataType as D, Dimensions as Dim};
    use gltf::mesh::Semantic;
    let check = |what: &str, a: &gltf::Accessor, dims: Dim, types: &[D]| -> Result<(), String> {
        if a.dimensions() != dims || !types.contains(&a.data_type()) {
            return Err(format!(
                "{what} accessor {} is {:?} of {:?}; glTF requires {dims:?} of {types:?}",
                a.index(),
                a.dimensions(),
                a.data_type()
            ));
        }
        // A sparse accessor without a buffer view starts from `count` zeros: bounded, as a file's length
        // bounds every other accessor.
        if a.view().is_none() && a.count() > MAX_SPARSE_COUNT {
            return Err(format!(
                "{what} accessor {} declares {} elements without a buffer view (the limit is {MAX_SPARSE_COUNT})",
                a.index(),
                a.count()
            ));
        }
        if let Some(view) = a.view() {
            let stride = view.stride().unwrap_or(a.size());
            let needed = match a.count() {
                0 => 0,
                n => (n - 1).checked_mul(stride).and_then(|b| b.checked_add(a.size())).ok_or("too large")?,
            };
            if a.offset().checked_add(needed).is_none_or(|end| end > view.length()) || stride < a.size() {
                return Err(format!("{what} accessor {} does not fit in its buffer view {}", a.index(), view.index()));
            }
        }
        Ok(())
    };
    for (semantic, a) in prim.attributes() {
        match semantic {
            Semantic::Positions => check("POSITION", &a, Dim::Vec3, &[D::F32])?,
            Semantic::Normals => check("NORMAL", &a, Dim::Vec3, &[D::F32])?,
            Semantic::TexCoords(0) => check("TEXCOORD_0", &a, Dim::Vec2, &[D::F32, D::U8, D::U16])?,
            _ => {}
        }
    }
    if let Some(a) = prim.indices() {
        check("indices", &a, Dim::Scalar, &[D::U8, D::U16, D::U32])?;
    }
    Ok(())
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
        check_accessors(prim).map_err(|m| SceneError::new(self.path, None, format!("primitive '{name}': {m}")))?;
        let reader = prim.reader(|b| buffers.get(b.index()).map(|d| &d[..]));
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

    /// Image `index` decoded (PNG or JPEG, sRGB to linear) from its buffer view, data URI or file.
    fn decode(&self, index: usize) -> Result<crate::texture::Pixels, String> {
        let image = self.document.images().nth(index).ok_or_else(|| format!("image {index} is missing"))?;
        let label = format!("{index} of {}", self.path.display());
        match image.source() {
            gltf::image::Source::View { view, .. } => {
                let buffer = self.buffers.get(view.buffer().index()).ok_or("its buffer is missing")?;
                let bytes = buffer
                    .get(view.offset()..view.offset().saturating_add(view.length()))
                    .ok_or_else(|| format!("image {label}: its buffer view lies outside its buffer"))?;
                crate::texture::decode_image(bytes, &label, false)
            }
            gltf::image::Source::Uri { uri, .. } => match data_uri(uri) {
                Some(bytes) => crate::texture::decode_image(&bytes?, &label, false),
                None => crate::texture::read_image(&referenced_file(self.path, uri)?, false),
            },
        }
    }

    /// The base color texture `image` (sRGB, decoded to linear) times `factor`, made once.
    fn texture(&mut self, image: usize, factor: Vec3) -> Result<TextureId, String> {
        let key = (image, factor.to_array().map(f32::to_bits));
        if let Some(&id) = self.texture_ids.get(&key) {
            return Ok(id);
        }
        if self.images.get(image).is_none() {
            return Err(format!("image {image} is missing"));
        }
        if self.images[image].is_none() {
            self.images[image] = Some(self.decode(image)?);
        }
        let img = self.images[image].as_ref().expect("decoded");
        let data: Vec<f32> =
            img.data.chunks_exact(3).flat_map(|t| [t[0] * factor.x, t[1] * factor.y, t[2] * factor.z]).collect();
        let (width, height) = (img.width, img.height);
        let id = TextureId(self.textures.len() as u32);
        self.textures.push(Texture {
            path: self.path.with_extension(format!("gltf#image{image}")),
            width,
            height,
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
