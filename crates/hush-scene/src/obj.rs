use std::path::Path;

use glam::Vec3;

use crate::{Material, Mesh, SceneError};

/// Loads every object of a Wavefront OBJ file as one triangle mesh with the given material.
///
/// Polygons are triangulated; vertex normals are kept when every vertex has one.
/// Non-finite positions or normals, out-of-range indices and an empty file are errors
/// naming the file; degenerate (zero-area) triangles are dropped, since they can never be hit.
pub fn load_obj(path: &Path, material: Material) -> Result<Mesh, SceneError> {
    if !path.is_file() {
        return Err(SceneError::new(path, None, "mesh file not found: check the path in the scene file"));
    }
    let options = tobj::LoadOptions {
        single_index: true,
        triangulate: true,
        ignore_points: true,
        ignore_lines: true,
        ..Default::default()
    };
    // Materials of Mitsuba scenes live in the scene file, so the OBJ's own `mtllib` is not read.
    let (models, _materials) =
        tobj::load_obj(path, &options).map_err(|e| SceneError::new(path, None, format!("malformed OBJ: {e}")))?;

    let mut positions = Vec::new();
    let mut normals = Vec::new();
    let mut indices = Vec::new();
    let mut all_have_normals = true;
    for model in &models {
        let m = &model.mesh;
        let base = positions.len() as u32;
        let count = m.positions.len() / 3;
        for (k, p) in m.positions.chunks_exact(3).enumerate() {
            let v = Vec3::new(p[0], p[1], p[2]);
            if !v.is_finite() {
                return Err(SceneError::new(
                    path,
                    None,
                    format!(
                        "vertex {} of object '{}' is not finite ({v}): fix or re-export the mesh",
                        k + 1,
                        model.name
                    ),
                ));
            }
            positions.push(v);
        }
        if m.normals.len() == m.positions.len() {
            for n in m.normals.chunks_exact(3) {
                let v = Vec3::new(n[0], n[1], n[2]);
                if !v.is_finite() {
                    return Err(SceneError::new(
                        path,
                        None,
                        format!("object '{}' has a non-finite normal", model.name),
                    ));
                }
                normals.push(v);
            }
        } else {
            all_have_normals = false;
        }
        for t in m.indices.chunks_exact(3) {
            if t.iter().any(|&i| i as usize >= count) {
                return Err(SceneError::new(
                    path,
                    None,
                    format!("object '{}' has a face index out of range", model.name),
                ));
            }
            indices.push([base + t[0], base + t[1], base + t[2]]);
        }
    }
    indices.retain(|t| {
        let [a, b, c] = t.map(|i| positions[i as usize]);
        (b - a).cross(c - a).length_squared() > 0.0
    });
    if indices.is_empty() {
        return Err(SceneError::new(path, None, "OBJ file holds no (non-degenerate) triangles"));
    }
    Ok(Mesh {
        name: path.file_stem().map(|s| s.to_string_lossy().into_owned()).unwrap_or_default(),
        positions,
        normals: all_have_normals.then_some(normals),
        indices,
        material,
        emission: None,
    })
}
