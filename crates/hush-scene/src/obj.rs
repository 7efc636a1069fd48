//! Wavefront OBJ: meshes for Mitsuba's `obj` shape, and standalone `.obj` scenes with their
//! MTL materials.

use std::collections::HashMap;
use std::path::{Path, PathBuf};

use glam::{Vec2, Vec3};

use crate::shapes::Geometry;
use crate::texture::TextureCache;
use crate::{Film, Material, Mesh, Microfacet, PixelFilter, Reflectance, Scene, SceneError};

/// One object (or one material run of an object) of an OBJ file.
pub(crate) struct ObjObject {
    pub name: String,
    pub geometry: Geometry,
    pub material: Option<usize>,
}

pub(crate) struct ObjFile {
    pub objects: Vec<ObjObject>,
    pub materials: Vec<tobj::Material>,
    pub warnings: Vec<String>,
}

/// Reads an OBJ file: polygons triangulated, normals kept when every vertex of an object has
/// one, texture coordinates flipped to hush's v-down convention (Mitsuba's `flip_tex_coords`).
/// `mtl` reads the `mtllib` files; otherwise they are only checked for existence, since a
/// Mitsuba scene gives the materials itself. A missing material library is a warning.
pub(crate) fn read_obj(path: &Path, mtl: bool) -> Result<ObjFile, SceneError> {
    let bytes = hush_io::read_limited_bare(path, crate::max_file_bytes())
        .map_err(|e| SceneError::new(path, None, format!("mesh file: {e}: check the path in the scene file")))?;
    let options = tobj::LoadOptions { single_index: true, triangulate: true, ignore_points: true, ignore_lines: true };
    let dir = path.parent().map(Path::to_path_buf).unwrap_or_default();
    let warnings = std::cell::RefCell::new(Vec::new());
    let (models, materials) = tobj::load_obj_buf(&mut std::io::Cursor::new(bytes), &options, |lib| {
        let full = dir.join(lib);
        if let Some(why) = hush_io::describe_unreadable(&full) {
            let used = if mtl {
                "its objects get Mitsuba's default diffuse 0.5"
            } else {
                "not needed: the scene file gives the BSDF"
            };
            warnings.borrow_mut().push(format!(
                "{}: material library '{}' {} ({used})",
                path.display(),
                lib.display(),
                if why == hush_io::Unreadable::Missing { "is missing".to_string() } else { why.to_string() }
            ));
            return Ok((Vec::new(), Default::default()));
        }
        if !mtl {
            return Ok((Vec::new(), Default::default()));
        }
        match hush_io::read_limited_bare(&full, crate::max_file_bytes()) {
            Ok(text) => tobj::load_mtl_buf(&mut std::io::Cursor::new(text)),
            Err(e) => {
                warnings.borrow_mut().push(format!(
                    "{}: material library '{}' cannot be read: {e} (its objects get Mitsuba's default diffuse 0.5)",
                    path.display(),
                    lib.display()
                ));
                Ok((Vec::new(), Default::default()))
            }
        }
    })
    .map_err(|e| SceneError::new(path, None, format!("malformed OBJ: {e}")))?;
    let materials =
        materials.map_err(|e| SceneError::new(path, None, format!("malformed MTL material library: {e}")))?;

    let mut objects = Vec::with_capacity(models.len());
    for model in models {
        let m = model.mesh;
        let count = m.positions.len() / 3;
        let positions: Vec<Vec3> = m.positions.chunks_exact(3).map(|p| Vec3::new(p[0], p[1], p[2])).collect();
        let normals = (m.normals.len() == 3 * count && count > 0)
            .then(|| m.normals.chunks_exact(3).map(|n| Vec3::new(n[0], n[1], n[2])).collect());
        let uvs = (m.texcoords.len() == 2 * count && count > 0)
            .then(|| m.texcoords.chunks_exact(2).map(|t| Vec2::new(t[0], 1.0 - t[1])).collect());
        let indices = m.indices.chunks_exact(3).map(|t| [t[0], t[1], t[2]]).collect();
        objects.push(ObjObject {
            name: model.name,
            geometry: Geometry { positions, normals, uvs, indices },
            material: m.material_id,
        });
    }
    Ok(ObjFile { objects, materials, warnings: warnings.into_inner() })
}

/// All objects of an OBJ file as one geometry. Normals (UVs) are kept only if every object has them.
pub(crate) fn merge(objects: Vec<ObjObject>) -> Geometry {
    let all_normals = objects.iter().all(|o| o.geometry.normals.is_some());
    let all_uvs = objects.iter().all(|o| o.geometry.uvs.is_some());
    let mut g = Geometry { normals: all_normals.then(Vec::new), uvs: all_uvs.then(Vec::new), ..Default::default() };
    for o in objects {
        let base = g.positions.len() as u32;
        g.positions.extend(o.geometry.positions);
        if let (Some(n), Some(src)) = (&mut g.normals, o.geometry.normals) {
            n.extend(src);
        }
        if let (Some(u), Some(src)) = (&mut g.uvs, o.geometry.uvs) {
            u.extend(src);
        }
        g.indices.extend(o.geometry.indices.iter().map(|t| t.map(|i| i + base)));
    }
    g
}

/// Loads every object of a Wavefront OBJ file as one triangle mesh with the given material.
///
/// Polygons are triangulated; vertex normals and texture coordinates are kept when every vertex
/// has one. Non-finite positions or normals, out-of-range indices and an empty file are errors
/// naming the file; degenerate (zero-area) triangles are dropped, since they can never be hit.
pub fn load_obj(path: &Path, material: Material) -> Result<Mesh, SceneError> {
    let file = read_obj(path, false)?;
    let mut geometry = merge(file.objects);
    geometry.check().map_err(|m| SceneError::new(path, None, m))?;
    if geometry.indices.is_empty() {
        return Err(SceneError::new(path, None, "OBJ file holds no (non-degenerate) triangles"));
    }
    Ok(Mesh {
        name: path.file_stem().map(|s| s.to_string_lossy().into_owned()).unwrap_or_default(),
        positions: geometry.positions,
        normals: geometry.normals,
        uvs: geometry.uvs,
        indices: geometry.indices,
        material,
        emission: None,
        analytic: None,
    })
}

/// A standalone `.obj` scene: one mesh per object and material, materials from the MTL files
/// (see [`mtl_material`]), and a default camera since OBJ has none.
pub(crate) fn load_obj_scene(path: &Path) -> Result<Scene, SceneError> {
    let file = read_obj(path, true)?;
    let dir = path.parent().map(Path::to_path_buf).unwrap_or_default();
    let mut warnings = file.warnings;
    let mut textures = TextureCache::default();
    let mut converted: HashMap<usize, (Material, Option<Vec3>)> = HashMap::new();
    let mut meshes = Vec::new();
    for object in file.objects {
        let (material, emission) = match object.material {
            Some(i) => match converted.get(&i) {
                Some(&m) => m,
                None => {
                    let m = mtl_material(&file.materials[i], &dir, &mut textures, &mut warnings, path);
                    converted.insert(i, m);
                    m
                }
            },
            None => (Material::DEFAULT, None),
        };
        let mut g = object.geometry;
        let dropped = g.check().map_err(|m| SceneError::new(path, None, format!("object '{}': {m}", object.name)))?;
        if dropped > 0 {
            warnings.push(format!(
                "{}: object '{}': dropped {dropped} degenerate triangles",
                path.display(),
                object.name
            ));
        }
        if g.indices.is_empty() {
            if emission.is_some() {
                return Err(SceneError::new(
                    path,
                    None,
                    format!("object '{}' emits light but has zero area: remove its Ke or fix the mesh", object.name),
                ));
            }
            warnings.push(format!("{}: object '{}' has no area and was dropped", path.display(), object.name));
            continue;
        }
        meshes.push(Mesh {
            name: object.name,
            positions: g.positions,
            normals: g.normals,
            uvs: g.uvs,
            indices: g.indices,
            material,
            emission,
            analytic: None,
        });
    }
    if meshes.is_empty() {
        return Err(SceneError::new(path, None, "OBJ file holds no (non-degenerate) triangles"));
    }
    let film = Film { width: 768, height: 576, filter: PixelFilter::Box };
    let mut scene = Scene {
        camera: crate::model::Camera { origin: Vec3::Z, target: Vec3::ZERO, up: Vec3::Y, fov_y_deg: 40.0 },
        film,
        max_depth: u32::MAX,
        spp: None,
        meshes,
        textures: textures.textures,
        environment: None,
        warnings,
    };
    scene.camera = framing_camera(&scene, film, 40.0);
    scene.warnings.push(format!(
        "{}: OBJ has no camera: hush looks at the geometry's centre from +z with a {}° vertical fov (override with --origin/--target/--fov)",
        path.display(),
        40
    ));
    Ok(scene)
}

/// A camera on the +z side of the scene's bounds looking at their centre, far enough for the
/// bounding sphere to fit the vertical field of view.
pub(crate) fn framing_camera(scene: &Scene, film: Film, fov_y_deg: f32) -> crate::Camera {
    let (lo, hi) = scene.bounds();
    let center = (lo + hi) * 0.5;
    let radius = ((hi - lo).length() * 0.5).max(1e-3);
    let aspect = film.width as f32 / film.height as f32;
    let half = (fov_y_deg.to_radians() * 0.5).tan() * aspect.min(1.0);
    let distance = radius / half.atan().sin();
    crate::Camera { origin: center + Vec3::Z * distance, target: center, up: Vec3::Y, fov_y_deg }
}

/// MTL → hush material. OBJ has no notion of sides, so every material is two-sided; `Ke`
/// emits from the front.
///
/// - `illum` 4, 6, 7 or 9 (refraction): a dielectric of IOR `Ni` (default 1.5), rough with `Pr`.
/// - `illum` 3 or 5 (ray-traced reflection) or `Pm` ≥ 0.5: a conductor that reflects `Ks`
///   (Fresnel factor 1), GGX alpha from `Pr`, else from `Ns` as √(2 / (Ns + 2)).
/// - otherwise `Kd` (or `map_Kd`) alone is diffuse; with a non-zero `Ks` it is a rough plastic:
///   `Kd` under a coating of IOR `Ni` (default 1.5) scaled by `Ks`, alpha from `Ns` or `Pr`.
pub(crate) fn mtl_material(
    m: &tobj::Material,
    dir: &Path,
    textures: &mut TextureCache,
    warnings: &mut Vec<String>,
    obj: &Path,
) -> (Material, Option<Vec3>) {
    let at = |msg: String| format!("{}: material '{}': {msg}", obj.display(), m.name);
    let kd = m.diffuse.map(Vec3::from).unwrap_or(Vec3::splat(0.5));
    let ks = m.specular.map(Vec3::from).unwrap_or(Vec3::ZERO);
    let param = |k: &str| m.unknown_param.get(k).and_then(|v| v.trim().parse::<f32>().ok()).filter(|v| v.is_finite());
    let pr = param("Pr");
    let pm = param("Pm").unwrap_or(0.0);
    let alpha = match (pr, m.shininess) {
        (Some(r), _) => r.clamp(0.0, 1.0),
        (None, Some(ns)) if ns > 0.0 => (2.0 / (ns + 2.0)).sqrt(),
        _ => 0.0,
    };
    let mut diffuse: Reflectance = kd.clamp(Vec3::ZERO, Vec3::ONE).into();
    if let Some(t) = &m.diffuse_texture {
        let file: PathBuf = dir.join(t.trim());
        match crate::check_inside(&file, dir).and_then(|()| textures.get(&file, false)) {
            Ok(id) => diffuse = Reflectance::Texture(id),
            Err(e) => warnings.push(at(format!("{e}; Kd is used instead"))),
        }
    }
    if m.dissolve.is_some_and(|d| d < 1.0) {
        warnings.push(at("transparency (d < 1) is not supported yet: the surface is opaque".into()));
    }
    for t in [&m.specular_texture, &m.normal_texture, &m.shininess_texture, &m.dissolve_texture, &m.ambient_texture]
        .into_iter()
        .flatten()
    {
        warnings.push(at(format!("texture '{t}' is ignored (hush reads map_Kd only)")));
    }
    let emission = m.emissive.map(Vec3::from).filter(|e| e.max_element() > 0.0);
    let ior = m.optical_density.filter(|n| *n > 0.0).unwrap_or(1.5);
    let material = match m.illumination_model {
        Some(4 | 6 | 7 | 9) => Material::Dielectric {
            alpha: pr.unwrap_or(0.0),
            distribution: Microfacet::Ggx,
            int_ior: ior,
            ext_ior: 1.0,
            thin: false,
            specular_reflectance: Vec3::ONE,
            specular_transmittance: Vec3::ONE,
        },
        Some(3 | 5) => Material::Conductor {
            alpha,
            distribution: Microfacet::Ggx,
            ior: None,
            specular_reflectance: ks.min(Vec3::ONE),
            two_sided: true,
        },
        _ if pm >= 0.5 => Material::Conductor {
            alpha,
            distribution: Microfacet::Ggx,
            ior: None,
            specular_reflectance: if ks.max_element() > 0.0 { ks } else { kd }.min(Vec3::ONE),
            two_sided: true,
        },
        _ if ks.max_element() > 0.0 => Material::Plastic {
            diffuse_reflectance: diffuse,
            specular_reflectance: ks.min(Vec3::ONE),
            alpha,
            distribution: Microfacet::Ggx,
            int_ior: ior,
            ext_ior: 1.0,
            nonlinear: false,
            two_sided: true,
        },
        _ => Material::Diffuse { reflectance: diffuse, two_sided: true },
    };
    (material, emission)
}
