//! The procedural generator: what it writes loads back without a warning and holds what the
//! generator says; seeds are reproducible and distinct; features stay off unless enabled.

use std::collections::BTreeSet;
use std::path::Path;

use glam::Vec3;
use hush_scene::procedural::{
    GENERATOR_VERSION, GeneratedScene, GeneratorOptions, Ingredients, LightKind, LightMaterial, MaterialClass, Style,
    generate,
};
use hush_scene::{Material, PixelFilter, Reflectance, Scene, ShapeKind};

use crate::{scratch, shared};

/// Writes a generated scene and its assets into `dir` and loads it.
fn write_and_load(dir: &Path, g: &GeneratedScene) -> Scene {
    std::fs::create_dir_all(dir).unwrap();
    for a in &g.assets {
        std::fs::write(dir.join(&a.file), &a.bytes).unwrap();
    }
    let path = dir.join("scene.xml");
    std::fs::write(&path, &g.xml).unwrap();
    Scene::load(&path).unwrap_or_else(|e| panic!("seed {}: {e}\n{}", g.seed, g.xml))
}

/// Generate → load → the same shapes, in order, with the same BSDF kinds and emitters, and no warning.
fn check_round_trip(dir: &Path, g: &GeneratedScene) -> Scene {
    let scene = write_and_load(dir, g);
    assert!(scene.warnings.is_empty(), "seed {}: {:?}", g.seed, scene.warnings);
    let loaded: Vec<(&str, &str, bool)> =
        scene.meshes.iter().map(|m| (m.name.as_str(), m.material.kind(), m.emission.is_some())).collect();
    let said: Vec<(&str, &str, bool)> = g.shapes.iter().map(|s| (s.id.as_str(), s.bsdf, s.emitter)).collect();
    assert_eq!(loaded, said, "seed {}", g.seed);
    let area_lights = g.lights.iter().filter(|l| !matches!(l, LightKind::Constant | LightKind::EnvMap)).count();
    assert_eq!(scene.meshes.iter().filter(|m| m.emission.is_some()).count(), area_lights, "seed {}", g.seed);
    assert_eq!(
        scene.environment.is_some(),
        g.lights.iter().any(|l| matches!(l, LightKind::Constant | LightKind::EnvMap))
    );
    assert!(!g.lights.is_empty(), "seed {}: no light", g.seed);
    if !matches!(g.style, "open" | "lamps") {
        // The camera stands inside the room, which bounds all geometry but the daylight panels.
        let (lo, hi) = scene.bounds();
        assert!(scene.camera.origin.cmpgt(lo).all() && scene.camera.origin.cmplt(hi).all(), "seed {}", g.seed);
    }
    scene
}

#[test]
fn generated_scenes_load_back_as_generated() {
    let dir = scratch("procedural");
    let options = GeneratorOptions { ingredients: Ingredients::BASIC, width: 40, height: 30, ..Default::default() };
    let mut styles = BTreeSet::new();
    let mut classes = BTreeSet::new();
    for seed in 0..40u64 {
        let g = generate(seed, &options);
        let scene = check_round_trip(&dir.join(format!("s{seed}")), &g);
        assert_eq!((scene.film.width, scene.film.height), (40, 30));
        // Only the basic features.
        for m in &scene.meshes {
            assert!(
                ["diffuse", "conductor", "roughconductor", "plastic", "dielectric", "thindielectric"]
                    .contains(&m.material.kind()),
                "seed {seed}: {}",
                m.material.kind()
            );
            assert!(m.material.texture().is_none());
        }
        assert!(scene.environment.is_none() && scene.textures.is_empty());
        styles.insert(g.style);
        classes.extend(g.material_classes());
    }
    // 40 seeds cover every style and every class but textures (not basic).
    assert_eq!(styles.len(), 4, "{styles:?}");
    let expect: BTreeSet<MaterialClass> =
        MaterialClass::ALL.into_iter().filter(|c| *c != MaterialClass::Textured).collect();
    assert_eq!(classes, expect);
}

#[test]
fn all_features_load_back_too() {
    let dir = scratch("procedural-all");
    let options = GeneratorOptions { ingredients: Ingredients::ALL, width: 32, height: 32, ..Default::default() };
    let mut kinds = BTreeSet::new();
    let mut lights = BTreeSet::new();
    for seed in 0..40u64 {
        let g = generate(seed, &options);
        let scene = check_round_trip(&dir.join(format!("s{seed}")), &g);
        kinds.extend(scene.meshes.iter().map(|m| m.material.kind()));
        lights.extend(g.lights.iter().copied());
        if g.material_classes().contains(&MaterialClass::Textured) {
            assert!(!scene.textures.is_empty(), "seed {seed}");
        }
    }
    for k in ["roughdielectric", "roughplastic"] {
        assert!(kinds.contains(k), "{k} never drawn in 40 seeds: {kinds:?}");
    }
    assert_eq!(lights.len(), LightKind::ALL.len(), "{lights:?}");
}

#[test]
fn lamps_scenes_show_their_lights_to_the_camera_above_plates() {
    let dir = scratch("procedural-lamps");
    let (mut spheres, mut disks, mut backdrops, mut skies) = (0, 0, 0, 0);
    for seed in 0..20u64 {
        let options = GeneratorOptions {
            width: 32,
            height: 32,
            style: Some(Style::Lamps),
            filter: if seed % 2 == 0 { PixelFilter::Box } else { PixelFilter::Tent { radius: 1.0 } },
            ..Default::default()
        };
        let g = generate(seed, &options);
        assert_eq!(generate(seed, &options).xml, g.xml, "seed {seed}: reproducible");
        let scene = check_round_trip(&dir.join(format!("s{seed}")), &g);
        assert_eq!(g.style, "lamps");
        let (forward, right, up) = scene.camera.basis();
        let reach = (0.5 * scene.camera.fov_y_deg.to_radians()).tan();
        let lamps: Vec<_> = scene.meshes.iter().filter(|m| m.name.starts_with("lamp")).collect();
        assert!((2..=5).contains(&lamps.len()), "seed {seed}: {} lamps", lamps.len());
        for m in &lamps {
            let e = m.emission.expect("a lamp emits");
            // The smaller, the brighter: radiance × radius² in [0.2, 8] for radii 0.005 to 0.6.
            assert!(e.max_element() > 0.5 && e.max_element() < 330_000.0, "seed {seed} {}: {e}", m.name);
            // In the frame, in front of the camera.
            let c = m.positions.iter().fold(Vec3::ZERO, |a, p| a + *p) / m.positions.len() as f32;
            let d = c - scene.camera.origin;
            let depth = d.dot(forward);
            assert!(depth > 0.0, "seed {seed} {}: behind the camera", m.name);
            let (x, y) = (d.dot(right) / depth, d.dot(up) / depth);
            assert!(x.abs() < reach && y.abs() < reach, "seed {seed} {}: ({x}, {y}) out of ±{reach}", m.name);
            match m.analytic.as_ref().map(|a| a.kind) {
                Some(ShapeKind::Sphere) => spheres += 1,
                Some(ShapeKind::Disk) => {
                    // A disk emits from its front, which faces the camera.
                    disks += 1;
                    let [a, b, k] = m.indices[0].map(|i| m.positions[i as usize]);
                    let front = (b - a).cross(k - a);
                    assert!(front.dot(scene.camera.origin - c) > 0.0, "seed {seed} {}: a disk turned away", m.name);
                }
                other => panic!("seed {seed} {}: a lamp is a sphere or a disk, not {other:?}", m.name),
            }
        }
        assert!(g.shapes.iter().any(|s| s.id.starts_with("plate")), "seed {seed}: no plate");
        backdrops += g.shapes.iter().filter(|s| s.id.starts_with("backdrop")).count();
        skies += usize::from(scene.environment.is_some());
    }
    assert!(spheres > 0 && disks > 0, "20 seeds drew {spheres} spherical and {disks} disk lamps");
    assert!(backdrops > 0 && skies > 0 && backdrops + skies < 20, "{backdrops} backdrops, {skies} skies of 20");
}

#[test]
fn open_scenes_stand_under_a_sky_and_rooms_keep_their_seeds() {
    let dir = scratch("procedural-open");
    let open = |ingredients| GeneratorOptions {
        ingredients,
        width: 32,
        height: 32,
        style: Some(Style::Open),
        ..Default::default()
    };
    let (mut suns, mut bulbs) = (0, 0);
    for seed in 0..20u64 {
        let g = generate(seed, &open(Ingredients::ALL));
        let scene = check_round_trip(&dir.join(format!("s{seed}")), &g);
        assert_eq!(g.style, "open");
        assert!(scene.environment.is_some(), "seed {seed}: an open scene has a sky");
        let names: Vec<&str> = g.shapes.iter().map(|s| s.id.as_str()).collect();
        assert!(names.iter().any(|n| n.starts_with("ground")), "seed {seed}: {names:?}");
        assert!(!names.iter().any(|n| n.starts_with("wall") || n.starts_with("ceiling")), "seed {seed}: {names:?}");
        suns += names.iter().filter(|n| n.starts_with("sun")).count();
        bulbs += names.iter().filter(|n| n.starts_with("bulb")).count();
        // Above the ground, below the sky.
        assert!(scene.camera.origin.y > 0.0, "seed {seed}");
    }
    assert!(suns > 0 && bulbs > 0, "20 seeds drew {suns} suns and {bulbs} bulbs");
    // Without environment emitters, an overcast panel high above lights the scene.
    let g = generate(3, &open(Ingredients::BASIC));
    let scene = check_round_trip(&dir.join("basic"), &g);
    assert!(scene.environment.is_none() && g.shapes.iter().any(|s| s.id.starts_with("overcast") && s.emitter));
    // The film's filter is the one asked for (rooms: box).
    for filter in [PixelFilter::Tent { radius: 1.0 }, PixelFilter::Gaussian { stddev: 0.5 }] {
        let g = generate(4, &GeneratorOptions { filter, ..open(Ingredients::ALL) });
        assert_eq!(write_and_load(&dir.join("filter"), &g).film.filter, filter);
    }
    assert_eq!(
        check_round_trip(&dir.join("room"), &generate(4, &GeneratorOptions::default())).film.filter,
        PixelFilter::Box
    );
    // A room asked for in the style its seed draws is that room, byte for byte.
    for seed in 0..8u64 {
        let drawn = generate(seed, &GeneratorOptions::default());
        let style = Style::parse(drawn.style).unwrap();
        let asked = generate(seed, &GeneratorOptions { style: Some(style), ..Default::default() });
        assert_eq!(drawn.xml, asked.xml, "seed {seed}");
    }
}

/// `LightMaterial::Ceiling` gives a room's ceiling panels and lamps the ceiling's material and changes
/// nothing else: the same shapes, where they were, emitting what they did; bulbs stay black.
#[test]
fn ceiling_lights_wear_the_ceiling_and_the_room_is_the_same() {
    let dir = scratch("procedural-light-material");
    let (mut panels, mut bulbs) = (0, 0);
    for seed in 0..12u64 {
        let black = generate(seed, &GeneratorOptions::default());
        let ceiling =
            generate(seed, &GeneratorOptions { light_material: LightMaterial::Ceiling, ..Default::default() });
        assert!(!black.xml.contains("lights ceiling") && ceiling.xml.contains(", lights ceiling -->"), "seed {seed}");
        let (a, b) = (
            check_round_trip(&dir.join(format!("b{seed}")), &black),
            check_round_trip(&dir.join(format!("c{seed}")), &ceiling),
        );
        assert_eq!(a.meshes.len(), b.meshes.len(), "seed {seed}");
        let room_ceiling = b.meshes.iter().find(|m| m.name.starts_with("ceiling")).expect("a room has a ceiling");
        for (m, n) in a.meshes.iter().zip(&b.meshes) {
            assert_eq!((&m.name, &m.positions, m.emission), (&n.name, &n.positions, n.emission), "seed {seed}");
            if n.name.starts_with("panel") || n.name.starts_with("lamp") {
                panels += 1;
                assert_eq!(n.material, room_ceiling.material, "seed {seed}: {}", n.name);
                let black =
                    matches!(m.material, Material::Diffuse { reflectance: Reflectance::Rgb(c), .. } if c == Vec3::ZERO);
                assert!(black, "seed {seed}: {} is {:?}", m.name, m.material);
            } else {
                bulbs += usize::from(n.name.starts_with("bulb"));
                assert_eq!(m.material, n.material, "seed {seed}: {}", n.name);
            }
        }
    }
    assert!(panels > 0 && bulbs > 0, "12 seeds drew {panels} panels and lamps and {bulbs} bulbs");
}

#[test]
fn same_seed_same_bytes_other_seed_other_scene() {
    let options = GeneratorOptions { ingredients: Ingredients::ALL, ..Default::default() };
    let (a, b, c) = (generate(7, &options), generate(7, &options), generate(8, &options));
    assert_eq!(a.xml, b.xml);
    assert_eq!(a.assets, b.assets);
    assert_ne!(a.xml, c.xml);
    assert!(a.xml.contains(&format!("generator {GENERATOR_VERSION}, seed 7")), "{}", &a.xml[..200]);
}

#[test]
fn meshes_are_borrowed_from_shared_scenes() {
    let dir = scratch("procedural-borrow");
    let options = GeneratorOptions { borrow_meshes: Some(shared().join("scenes")), ..Default::default() };
    let borrowed = (0..30u64)
        .map(|seed| generate(seed, &options))
        .filter(|g| g.shapes.iter().any(|s| s.id.starts_with("borrowed")))
        .take(2)
        .map(|g| check_round_trip(&dir.join(format!("s{}", g.seed)), &g))
        .count();
    assert_eq!(borrowed, 2, "no borrowed mesh in 30 seeds");
}

#[test]
fn feature_names_parse_and_unknown_ones_are_errors() {
    assert_eq!(Ingredients::parse("default"), Ok(Ingredients::KERNEL));
    assert_eq!(Ingredients::parse("all"), Ok(Ingredients::ALL));
    let f = Ingredients::parse("textures,environment").unwrap();
    assert!(f.textures && f.environment && !f.rough_plastic);
    assert_eq!(Ingredients::parse(&f.describe()), Ok(f));
    let err = Ingredients::parse("textures,sparkles").unwrap_err();
    assert!(err.contains("sparkles") && err.contains("roughdielectric"), "{err}");
}
