//! Every scene in the shared folder loads, with the triangle count of its README row, the
//! camera its `scene_manifest.json` states, and the warnings its incomplete parts deserve.

use std::path::PathBuf;
use std::time::Instant;

use glam::Vec3;
use hush_scene::{Environment, Material, Microfacet, Reflectance, Scene};

use crate::shared;

fn scene_path(folder: &str, file: &str) -> PathBuf {
    shared().join("scenes").join(folder).join(file)
}

fn load(folder: &str, file: &str) -> Scene {
    let path = scene_path(folder, file);
    let start = Instant::now();
    let scene = Scene::load(&path).unwrap_or_else(|e| panic!("{folder} should load: {e}"));
    eprintln!(
        "{folder}: {} triangles, {} meshes, {} textures, {:.2} s, warnings:\n  {}",
        scene.triangle_count(),
        scene.meshes.len(),
        scene.textures.len(),
        start.elapsed().as_secs_f64(),
        scene.warnings.join("\n  ")
    );
    scene
}

/// The README's triangle count, less the degenerate triangles the warnings say were dropped.
fn assert_triangles(scene: &Scene, expect: usize) {
    let dropped: usize = scene
        .warnings
        .iter()
        .filter_map(|w| w.split("dropped ").nth(1)?.split(' ').next()?.parse::<usize>().ok())
        .sum();
    assert_eq!(scene.triangle_count() + dropped, expect, "{dropped} dropped; README says {expect}");
}

fn v3(j: &serde_json::Value) -> Vec3 {
    let a: Vec<f32> = j.as_array().unwrap().iter().map(|x| x.as_f64().unwrap() as f32).collect();
    Vec3::new(a[0], a[1], a[2])
}

/// The camera matches `scene_manifest.json`: position, view direction, up, and the field of
/// view converted from `fov_axis` x to vertical.
fn assert_manifest_camera(folder: &str, scene: &Scene) {
    let text = std::fs::read_to_string(scene_path(folder, "scene_manifest.json")).unwrap();
    let m: serde_json::Value = serde_json::from_str(&text).unwrap();
    let c = &m["camera"];
    let (pos, target, up) = (v3(&c["position"]), v3(&c["target"]), v3(&c["up"]));
    let cam = &scene.camera;
    assert!(cam.origin.abs_diff_eq(pos, 1e-4), "{folder}: origin {} vs {pos}", cam.origin);
    let dir = (cam.target - cam.origin).normalize();
    assert!(dir.abs_diff_eq((target - pos).normalize(), 1e-4), "{folder}: direction {dir}");
    assert!(cam.up.normalize().abs_diff_eq(up.normalize(), 1e-4), "{folder}: up {}", cam.up);
    let (w, h) = (c["width"].as_f64().unwrap(), c["height"].as_f64().unwrap());
    assert_eq!((scene.film.width as f64, scene.film.height as f64), (w, h), "{folder}: film");
    assert_eq!(c["fov_axis"], "x");
    let fx = c["fov_deg"].as_f64().unwrap().to_radians();
    let fy = 2.0 * ((fx / 2.0).tan() * h / w).atan();
    assert!((cam.fov_y_deg as f64 - fy.to_degrees()).abs() < 1e-3, "{folder}: fov {}", cam.fov_y_deg);
}

fn has_warning(scene: &Scene, words: &[&str]) -> bool {
    scene.warnings.iter().any(|w| words.iter().all(|k| w.contains(k)))
}

#[test]
fn cornell_box_mitsuba3_with_defaults_and_matrices() {
    let s = load("cornell-box", "scene.xml");
    assert_triangles(&s, 36);
    assert_manifest_camera("cornell-box", &s);
    // `$max_depth` and `$spp` come from <default>.
    assert_eq!((s.max_depth, s.spp), (30, Some(64)));
    assert!(has_warning(&s, &["path_guiding_integrator", "path"]), "{:?}", s.warnings);
    assert_eq!(s.film.filter, hush_scene::PixelFilter::Tent { radius: 1.0 });
    assert!(!has_warning(&s, &["tent"]), "{:?}", s.warnings);
    let light = s.meshes.iter().find(|m| m.name == "Light").unwrap();
    assert_eq!(light.emission, Some(Vec3::new(17.0, 12.0, 4.0)));
    assert!(light.material.two_sided());
    // The light faces down into the box and has the area of its matrix (2·0.235 × 2·0.19).
    let [a, b, c] = light.indices[0].map(|i| light.positions[i as usize]);
    assert!((b - a).cross(c - a).normalize().y < -0.99);
    assert!((light.area() - 4.0 * 0.235 * 0.19).abs() < 1e-5, "{}", light.area());
    let left = s.meshes.iter().find(|m| m.name == "LeftWall").unwrap();
    assert_eq!(
        left.material,
        Material::Diffuse { reflectance: Reflectance::Rgb(Vec3::new(0.63, 0.065, 0.05)), two_sided: true }
    );
}

#[test]
fn veach_mis_spheres_and_rough_conductors() {
    let s = load("veach-mis", "scene.xml");
    assert_triangles(&s, 11_956);
    assert_manifest_camera("veach-mis", &s);
    assert!(!has_warning(&s, &["beckmann"]), "Beckmann is supported: {:?}", s.warnings);
    let mut alphas = Vec::new();
    for m in &s.meshes {
        if let Material::Conductor { alpha, ior: Some(ior), specular_reflectance, two_sided: true, distribution } =
            m.material
        {
            assert_eq!(distribution, Microfacet::Beckmann, "Mitsuba's default distribution");
            alphas.push(alpha);
            assert!((ior.eta - Vec3::new(0.200438, 0.924033, 1.10221)).abs().max_element() < 1e-6);
            assert_eq!(specular_reflectance, Vec3::splat(0.3));
        }
    }
    alphas.sort_by(f32::total_cmp);
    assert_eq!(alphas, [0.01, 0.05, 0.1, 0.25]);
    // Sphere lights: tessellated to their analytic area 4πr².
    let small = s.meshes.iter().find(|m| m.name == "Null_0003").unwrap();
    let r = 0.05f64;
    assert!((small.area() / (4.0 * std::f64::consts::PI * r * r) - 1.0).abs() < 1e-4, "{}", small.area());
    assert_eq!(small.emission, Some(Vec3::splat(3039.64)));
}

#[test]
fn staircase2_mitsuba06_textures_and_disk_lights() {
    let s = load("staircase2", "scene.xml");
    assert_triangles(&s, 31_247);
    assert_manifest_camera("staircase2", &s);
    assert_eq!((s.max_depth, s.spp), (65, Some(256)));
    assert_eq!(s.meshes.iter().filter(|m| m.emission.is_some()).count(), 13);
    assert_eq!(s.textures.len(), 3, "wood5, Tiles, Wallpaper, each read once");
    for t in &s.textures {
        assert_eq!(t.data.len(), 3 * (t.width * t.height) as usize);
        let mean = t.mean();
        assert!(mean.min_element() > 0.0 && mean.max_element() < 1.0, "{}: {mean}", t.path.display());
    }
    let wood = s
        .meshes
        .iter()
        .find(|m| matches!(m.material, Material::Plastic { diffuse_reflectance: Reflectance::Texture(_), alpha, .. } if alpha == 0.1))
        .expect("the rough-plastic wood");
    assert!(wood.uvs.is_some(), "{} has texture coordinates", wood.name);
    assert!(s.meshes.iter().any(|m| matches!(m.material, Material::Dielectric { int_ior, .. } if int_ior == 1.5)));
}

#[test]
fn living_room_envmap_mirror_and_mask() {
    let s = load("living-room", "scene.xml");
    assert_triangles(&s, 143_163);
    assert_manifest_camera("living-room", &s);
    let Some(Environment::Map(env)) = &s.environment else { panic!("the envmap is the only light") };
    assert!(env.path.ends_with("Sky 19.exr"));
    assert_eq!(env.data.len(), 3 * (env.width * env.height) as usize);
    assert!(env.data.iter().any(|v| *v > 1.0), "an HDR sky");
    assert_eq!(env.scale, 1.0);
    // Its to_world is a rotation of 90° about y.
    assert!(env.to_world.transform_vector3(Vec3::X).abs_diff_eq(-Vec3::Z, 1e-6));
    assert!(s.meshes.iter().all(|m| m.emission.is_none()));
    assert!(has_warning(&s, &["mask", "opacity"]), "{:?}", s.warnings);
    // Mitsuba's material="none": a perfect mirror.
    assert!(
        s.meshes.iter().any(|m| matches!(m.material, Material::Conductor { ior: None, alpha, .. } if alpha == 0.0))
    );
}

#[test]
fn glass_of_water_loads_without_its_missing_parts() {
    let s = load("glass-of-water", "scene.xml");
    assert_manifest_camera("glass-of-water", &s);
    assert_eq!(s.max_depth, 33);
    assert!(has_warning(&s, &["Mesh000.obj", "not found"]), "{:?}", s.warnings);
    assert!(has_warning(&s, &["light_blender.mtl", "missing"]), "{:?}", s.warnings);
    assert!(has_warning(&s, &["pfm"]) || !has_warning(&s, &["file_format"]), "{:?}", s.warnings);
    // The README's count is that of the meshes present (the water surface is not).
    assert_triangles(&s, 150_594);
    assert!(s.meshes.iter().any(|m| matches!(m.material, Material::Dielectric { int_ior, .. } if int_ior == 1.33)));
    assert_eq!(s.meshes.iter().filter(|m| m.emission.is_some()).count(), 1);
}

#[test]
fn cornell_box_gltf() {
    let s = load("cornell-box-gltf", "cornell-box.gltf");
    assert_triangles(&s, 36);
    assert_eq!(s.camera.origin, Vec3::new(0.0, 1.0, 6.8));
    assert!((s.camera.target - s.camera.origin).normalize().abs_diff_eq(-Vec3::Z, 1e-6));
    assert!((s.camera.fov_y_deg - 19.5).abs() < 1e-4, "{}", s.camera.fov_y_deg);
    assert_eq!((s.film.width, s.film.height), (512, 512));
    let light = s.meshes.iter().find(|m| m.emission.is_some()).unwrap();
    assert!(light.emission.unwrap().abs_diff_eq(Vec3::new(17.0, 12.0, 4.0), 1e-4), "{:?}", light.emission);
    assert!(s.meshes.iter().all(|m| matches!(m.material, Material::Diffuse { two_sided: true, .. })));
    assert!(s.warnings.is_empty(), "{:?}", s.warnings);
}

#[test]
fn khronos_cameras_gltf() {
    let s = load("khronos-cameras", "Cameras.gltf");
    assert_triangles(&s, 2);
    assert_eq!(s.camera.origin, Vec3::new(0.5, 0.5, 3.0));
    assert!((s.camera.fov_y_deg - 0.7f32.to_degrees()).abs() < 1e-4);
    assert!(has_warning(&s, &["orthographic"]), "{:?}", s.warnings);
    // The quad's node rotation (-45° about x) is applied: its far edge tilts away.
    let (lo, hi) = s.bounds();
    assert!(hi.z - lo.z > 0.5 && lo.z < -0.5, "{lo} {hi}");
}

#[test]
fn generated_primitives_load_as_obj_scenes() {
    let s = load("veach-mis", "generated/primitives.obj");
    assert_triangles(&s, 11_956);
    assert!(has_warning(&s, &["no camera"]), "{:?}", s.warnings);
    let smooth = s.meshes.iter().find(|m| m.name == "Smooth_0").unwrap();
    assert_eq!(
        smooth.material,
        Material::Conductor {
            alpha: 0.01,
            distribution: Microfacet::Ggx,
            ior: None,
            specular_reflectance: Vec3::splat(0.3),
            two_sided: true
        }
    );
    assert_eq!(s.meshes.iter().filter(|m| m.emission.is_some()).count(), 3);
    let s = load("staircase2", "generated/primitives.obj");
    assert_triangles(&s, 336);
    assert_eq!(s.meshes.iter().filter(|m| m.emission.is_some()).count(), 13);
}
