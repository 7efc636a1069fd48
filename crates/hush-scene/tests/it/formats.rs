//! OBJ+MTL and glTF scenes written here, with the material mappings documented in the loaders.

use glam::{Vec2, Vec3};
use hush_scene::{Material, Reflectance, Scene};

use crate::scratch;

/// A 2×1 PNG: left texel sRGB 128 grey, right texel pure red.
fn write_png(path: &std::path::Path) {
    let img = image::RgbImage::from_raw(2, 1, vec![128, 128, 128, 255, 0, 0]).unwrap();
    img.save(path).unwrap();
}

#[test]
fn obj_with_mtl_materials_emission_and_texture() {
    let dir = scratch("obj-mtl");
    write_png(&dir.join("tex.png"));
    std::fs::write(
        dir.join("s.mtl"),
        "newmtl matte\nKd 0.2 0.4 0.6\nillum 1\n\
         newmtl textured\nKd 1 1 1\nmap_Kd tex.png\n\
         newmtl plastic\nKd 0.5 0.5 0.5\nKs 0.04 0.04 0.04\nNs 98\nNi 1.4\nillum 2\n\
         newmtl metal\nKs 0.9 0.8 0.7\nNs 19998\nillum 3\n\
         newmtl glass\nNi 1.33\nillum 7\n\
         newmtl lamp\nKd 0 0 0\nKe 5 4 3\n",
    )
    .unwrap();
    let mut obj = String::from("mtllib s.mtl\n");
    for (k, m) in ["matte", "textured", "plastic", "metal", "glass", "lamp"].iter().enumerate() {
        let x = k as f32 * 2.0;
        obj += &format!(
            "o {m}\nv {x} 0 0\nv {} 0 0\nv {x} 1 0\nvt 0 0\nvt 1 0\nvt 0 1\nusemtl {m}\nf -3/-3 -2/-2 -1/-1\n",
            x + 1.0
        );
    }
    std::fs::write(dir.join("s.obj"), obj).unwrap();
    let s = Scene::load(&dir.join("s.obj")).unwrap();
    let by = |n: &str| s.meshes.iter().find(|m| m.name == n).unwrap_or_else(|| panic!("no mesh {n}"));
    assert_eq!(
        by("matte").material,
        Material::Diffuse { reflectance: Reflectance::Rgb(Vec3::new(0.2, 0.4, 0.6)), two_sided: true }
    );
    let Material::Diffuse { reflectance: Reflectance::Texture(id), .. } = by("textured").material else { panic!() };
    let tex = &s.textures[id.0 as usize];
    // sRGB 128/255 is linear 0.2159.
    assert!((tex.texel(0, 0).x - 0.21586).abs() < 1e-4, "{}", tex.texel(0, 0));
    assert_eq!(tex.texel(1, 0), Vec3::X);
    // OBJ's v is flipped: vt (0, 1) becomes (0, 0), the top of the image.
    assert_eq!(by("textured").uvs.as_ref().unwrap()[2], Vec2::new(0.0, 0.0));
    let Material::Plastic { alpha, int_ior, specular_reflectance, .. } = by("plastic").material else { panic!() };
    assert!((alpha - 0.1414).abs() < 1e-3 && int_ior == 1.4 && specular_reflectance == Vec3::splat(0.04));
    let Material::Conductor { alpha, ior: None, specular_reflectance, .. } = by("metal").material else { panic!() };
    assert!((alpha - 0.01).abs() < 1e-6 && specular_reflectance == Vec3::new(0.9, 0.8, 0.7));
    assert!(matches!(by("glass").material, Material::Dielectric { int_ior, thin: false, .. } if int_ior == 1.33));
    assert_eq!(by("lamp").emission, Some(Vec3::new(5.0, 4.0, 3.0)));
    assert!(by("matte").emission.is_none());
    assert!(s.camera.validate().is_ok());
}

#[test]
fn obj_scene_with_a_missing_mtl_warns() {
    let dir = scratch("obj-no-mtl");
    std::fs::write(dir.join("s.obj"), "mtllib nowhere.mtl\nv 0 0 0\nv 1 0 0\nv 0 1 0\nusemtl x\nf 1 2 3\n").unwrap();
    let s = Scene::load(&dir.join("s.obj")).unwrap();
    assert!(s.warnings.iter().any(|w| w.contains("nowhere.mtl") && w.contains("missing")), "{:?}", s.warnings);
    assert_eq!(s.meshes[0].material, Material::DEFAULT);
}

/// One triangle (positions, UVs, indices) in `t.bin` and a glTF around it.
fn write_gltf(dir: &std::path::Path, material: &str, extensions: &str, node: &str) -> std::path::PathBuf {
    let mut bin = Vec::new();
    for v in [0.0f32, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 1.0] {
        bin.extend_from_slice(&v.to_le_bytes());
    }
    for i in [0u16, 1, 2, 0] {
        bin.extend_from_slice(&i.to_le_bytes());
    }
    std::fs::write(dir.join("t.bin"), &bin).unwrap();
    let json = format!(
        r#"{{"asset": {{"version": "2.0"}}, "extensionsUsed": [{extensions}], "scene": 0,
        "scenes": [{{"nodes": [0, 1]}}],
        "nodes": [{{"name": "parent", "translation": [0, 0, -2], "children": [2]}},
                  {{"camera": 0, "translation": [0, 0, 3]}},
                  {{"name": "tri", "mesh": 0, {node}}}],
        "cameras": [{{"type": "perspective", "perspective": {{"yfov": 0.5, "aspectRatio": 2.0, "znear": 0.1}}}}],
        "meshes": [{{"primitives": [{{"attributes": {{"POSITION": 0, "TEXCOORD_0": 1}}, "indices": 2, "material": 0}}]}}],
        "materials": [{material}],
        "images": [{{"uri": "tex.png"}}], "textures": [{{"source": 0}}],
        "buffers": [{{"uri": "t.bin", "byteLength": {len}}}],
        "bufferViews": [{{"buffer": 0, "byteOffset": 0, "byteLength": 36}}, {{"buffer": 0, "byteOffset": 36, "byteLength": 24}},
                        {{"buffer": 0, "byteOffset": 60, "byteLength": 6}}],
        "accessors": [{{"bufferView": 0, "componentType": 5126, "count": 3, "type": "VEC3", "min": [0,0,0], "max": [1,1,0]}},
                      {{"bufferView": 1, "componentType": 5126, "count": 3, "type": "VEC2"}},
                      {{"bufferView": 2, "componentType": 5123, "count": 3, "type": "SCALAR"}}]}}"#,
        len = bin.len()
    );
    write_png(&dir.join("tex.png"));
    let path = dir.join("t.gltf");
    std::fs::write(&path, json).unwrap();
    path
}

#[test]
fn gltf_node_hierarchy_camera_and_textured_plastic() {
    let dir = scratch("gltf-plastic");
    let material = r#"{"pbrMetallicRoughness": {"baseColorFactor": [0.5, 1, 1, 1], "baseColorTexture": {"index": 0},
        "metallicFactor": 0, "roughnessFactor": 0.5}, "emissiveFactor": [1, 0.5, 0],
        "extensions": {"KHR_materials_emissive_strength": {"emissiveStrength": 4}}}"#;
    let path = write_gltf(&dir, material, r#""KHR_materials_emissive_strength""#, r#""scale": [2, 2, 2]"#);
    let s = Scene::load(&path).unwrap();
    assert!(s.warnings.is_empty(), "{:?}", s.warnings);
    assert_eq!((s.film.width, s.film.height), (1024, 512));
    assert_eq!(s.camera.origin, Vec3::new(0.0, 0.0, 3.0));
    assert!((s.camera.fov_y_deg - 0.5f32.to_degrees()).abs() < 1e-4);
    let m = &s.meshes[0];
    // The child's scale applies first, then the parent's translation.
    assert_eq!(m.positions[1], Vec3::new(2.0, 0.0, -2.0));
    assert_eq!(m.emission, Some(Vec3::new(4.0, 2.0, 0.0)));
    let Material::Plastic { diffuse_reflectance: Reflectance::Texture(id), alpha, two_sided: false, .. } = m.material
    else {
        panic!("{:?}", m.material)
    };
    assert!((alpha - 0.25).abs() < 1e-6);
    // The base color factor multiplies the (linearized) texture.
    let t = s.textures[id.0 as usize].texel(0, 0);
    assert!((t - Vec3::new(0.5, 1.0, 1.0) * 0.21586).abs().max_element() < 1e-4, "{t}");
}

#[test]
fn gltf_transmission_with_ior_is_a_dielectric() {
    let dir = scratch("gltf-glass");
    let material = r#"{"pbrMetallicRoughness": {"metallicFactor": 0, "roughnessFactor": 0},
        "extensions": {"KHR_materials_transmission": {"transmissionFactor": 1}, "KHR_materials_ior": {"ior": 1.33}}}"#;
    let path = write_gltf(
        &dir,
        material,
        r#""KHR_materials_transmission", "KHR_materials_ior""#,
        r#""rotation": [0, 0, 0, 1]"#,
    );
    let s = Scene::load(&path).unwrap();
    assert!(
        matches!(s.meshes[0].material, Material::Dielectric { int_ior, alpha, .. } if int_ior == 1.33 && alpha == 0.0),
        "{:?}",
        s.meshes[0].material
    );
}

#[test]
fn gltf_metal_and_unsupported_extension() {
    let dir = scratch("gltf-metal");
    let material = r#"{"pbrMetallicRoughness": {"baseColorFactor": [0.9, 0.6, 0.2, 1], "metallicFactor": 1, "roughnessFactor": 0.3}, "doubleSided": true}"#;
    let path = write_gltf(&dir, material, r#""KHR_materials_sheen""#, r#""rotation": [0, 0, 0, 1]"#);
    let s = Scene::load(&path).unwrap();
    let Material::Conductor { alpha, ior: None, specular_reflectance, two_sided: true, .. } = s.meshes[0].material
    else {
        panic!()
    };
    assert!((alpha - 0.09).abs() < 1e-6 && specular_reflectance == Vec3::new(0.9, 0.6, 0.2));
    assert!(s.warnings.iter().any(|w| w.contains("KHR_materials_sheen")), "{:?}", s.warnings);
}

/// A node hierarchy with a cycle (a node its own child, or its parent's parent) is refused with the node,
/// instead of recursing until the stack overflows.
#[test]
fn gltf_node_cycles_are_refused() {
    let dir = scratch("gltf-cycle");
    let material = r#"{"pbrMetallicRoughness": {"baseColorFactor": [0.5, 0.5, 0.5, 1]}}"#;
    for children in [r#""children": [2]"#, r#""children": [0]"#] {
        let path = write_gltf(&dir, material, "", children);
        let err = Scene::load(&path).unwrap_err().to_string();
        assert!(err.contains("t.gltf") && err.contains("reached twice in the node hierarchy"), "{children}: {err}");
    }
}
