//! What each fuzz target does with its input: exactly what `hush` does with such a file. The fuzzer
//! (`cargo xtask fuzz`, `src/bin/hush-fuzz.rs`) and the replay of kept inputs (the workspace's e2e tests,
//! `fuzz_corpus`) both compile this file, so a regression case is replayed through the same code that
//! found it. A target returns whether the input was accepted; an error is a fine outcome, a panic, an
//! abort, a hang or an allocation beyond the fuzzer's limit is a finding.
//!
//! The sweep TOML target lives with its parser in xtask (`xtask/src/sweep/spec.rs` replays its cases).

use std::path::{Path, PathBuf};

/// Every target: its name (the folder of its seeds and kept cases) and what it reads.
pub const TARGETS: &[(&str, &str)] = &[
    ("mitsuba", "a Mitsuba scene XML (beside it: mesh.obj, tex.png, env.exr)"),
    ("obj", "a Wavefront OBJ; the bytes after a line `#MTL` are its material library a.mtl"),
    ("gltf", "a glTF 2.0 file: binary .glb when it starts with `glTF`, JSON .gltf otherwise"),
    ("exr", "an OpenEXR image with its layers, as the dataset reads them"),
    ("weights", "a weight file: OIDN's TZA or a hush safetensors model with its metadata"),
    ("manifest", "a dataset's manifest.json"),
];

/// A private scratch folder for the files a target writes (one per process).
fn scratch() -> PathBuf {
    let dir = std::env::temp_dir().join(format!("hush-fuzz-{}", std::process::id()));
    if !dir.is_dir() {
        std::fs::create_dir_all(&dir).expect("scratch folder");
        write_fixtures(&dir);
    }
    dir
}

/// The files a fuzzed scene may reference by name.
fn write_fixtures(dir: &Path) {
    std::fs::write(dir.join("mesh.obj"), "v 0 0 0\nv 1 0 0\nv 0 1 0\nvt 0 0\nvt 1 0\nvt 0 1\nf 1/1 2/2 3/3\n").unwrap();
    std::fs::write(dir.join("tex.png"), PNG_2X2).unwrap();
    let env = hush_dataset::Image::new(2, 1, 3, vec![1.0, 0.5, 0.25, 0.1, 0.2, 0.3]).unwrap();
    hush_dataset::write_rgb(dir.join("env.exr"), &env).unwrap();
}

/// A 2×2 RGB8 PNG (red, green / blue, white).
const PNG_2X2: &[u8] = include_bytes!("fixtures/tex.png");

/// Runs target `name` on `data`. Panics on an unknown name.
pub fn run(name: &str, data: &[u8]) -> bool {
    match name {
        "mitsuba" => scene(data, "scene.xml"),
        "obj" => {
            let (obj, mtl) = split_at_line(data, b"#MTL");
            if let Some(mtl) = mtl {
                std::fs::write(scratch().join("a.mtl"), mtl).unwrap();
            } else {
                let _ = std::fs::remove_file(scratch().join("a.mtl"));
            }
            scene(obj, "a.obj")
        }
        "gltf" => scene(data, if data.starts_with(b"glTF") { "scene.glb" } else { "scene.gltf" }),
        "exr" => exr(data),
        "weights" => weights(data),
        "manifest" => manifest(data),
        other => {
            panic!("no fuzz target {other}; the targets are {:?}", TARGETS.iter().map(|t| t.0).collect::<Vec<_>>())
        }
    }
}

/// `data` up to a line that is exactly `marker`, and what follows that line.
fn split_at_line<'a>(data: &'a [u8], marker: &[u8]) -> (&'a [u8], Option<&'a [u8]>) {
    let mut start = 0;
    for line in data.split_inclusive(|&b| b == b'\n') {
        let end = start + line.len();
        if line.strip_suffix(b"\n").unwrap_or(line) == marker {
            return (&data[..start], Some(&data[end..]));
        }
        start = end;
    }
    (data, None)
}

/// Loads a scene file as `hush render` does, then builds its BVH.
fn scene(data: &[u8], file: &str) -> bool {
    let path = scratch().join(file);
    std::fs::write(&path, data).unwrap();
    let Ok(scene) = hush_scene::Scene::load(&path) else { return false };
    let triangles: Vec<[glam::Vec3; 3]> = scene
        .meshes
        .iter()
        .flat_map(|m| m.indices.iter().map(move |t| t.map(|i| m.positions[i as usize])))
        .take(1 << 16)
        .collect();
    let bvh = hush_scene::Bvh::build(&triangles);
    let _ = bvh.depth();
    true
}

fn exr(data: &[u8]) -> bool {
    let path = scratch().join("image.exr");
    std::fs::write(&path, data).unwrap();
    let Ok(image) = hush_dataset::read_exr(&path) else { return false };
    for prefix in ["", "albedo", "normal"] {
        let _ = image.layer(prefix);
    }
    true
}

/// As `hush denoise --model` and `hush train --init` read a weight file.
fn weights(data: &[u8]) -> bool {
    let device = candle_core::Device::Cpu;
    let Ok(pretrained) = hush_net::Pretrained::read(data, &device) else { return false };
    let varmap = candle_nn::VarMap::new();
    let vb = candle_nn::VarBuilder::from_varmap(&varmap, candle_core::DType::F32, &device);
    // A network of the declared shape is only built when the weights are small: the fuzzer's point is the
    // reader, and a valid file of a large network is not a finding.
    if pretrained.info.net.multiply_adds(16, 16) > 1 << 24 {
        return true;
    }
    if hush_net::Net::new(vb, &pretrained.info.net).is_ok() {
        let _ = pretrained.load_into(&varmap);
    }
    let _ = hush_net::load_model(data, &device);
    true
}

fn manifest(data: &[u8]) -> bool {
    let path = scratch().join("manifest.json");
    std::fs::write(&path, data).unwrap();
    let Ok(manifest) = hush_dataset::Manifest::load_file(&path) else { return false };
    for view in manifest.views.iter() {
        let _ = view.validate();
        let _ = hush_dataset::Manifest::files_of(view);
    }
    true
}
