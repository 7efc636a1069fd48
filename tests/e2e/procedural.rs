//! Procedural scenes end to end: `hush scene generate` writes a scene hush loads back, and
//! `hush dataset --procedural` generates, records and renders distinct scenes without NaN or Inf,
//! and keeps them on a re-run.

use std::path::Path;

use crate::{expect_error, expect_success, hush, manifest_of, s, scratch};

#[test]
fn scene_generate_writes_a_scene_that_loads_back() {
    let dir = scratch("scene-generate");
    let xml = dir.join("room/scene.xml");
    let summary = dir.join("summary.json");
    let log = expect_success(&["scene", "generate", "--seed", "11", "--out", s(&xml), "--summary", s(&summary)]);
    assert!(log.contains("probe") && log.contains("% lit"), "{log}");
    let scene = hush_scene::Scene::load(&xml).unwrap();
    assert!(scene.warnings.is_empty(), "{:?}", scene.warnings);
    let sum: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(&summary).unwrap()).unwrap();
    assert_eq!(sum["shapes"].as_u64(), Some(scene.meshes.len() as u64));
    assert!(sum["probe_lit_fraction"].as_f64().unwrap() >= 0.5, "{sum}");
    // The same seed writes the same bytes.
    let again = dir.join("again/scene.xml");
    expect_success(&["scene", "generate", "--seed", "11", "--out", s(&again), "--no-probe"]);
    assert_eq!(std::fs::read(&xml).unwrap(), std::fs::read(&again).unwrap());

    // A bad flag value is clap's usage error (exit code 2).
    let out = hush(&["scene", "generate", "--out", s(&dir.join("x.xml")), "--ingredients", "sparkles"]);
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(2), "{err}");
    assert!(err.contains("sparkles") && err.contains("roughdielectric") && !err.contains("panicked"), "{err}");
    let err = expect_error(&["scene", "generate", "--out", s(&dir.join("x.obj"))]);
    assert!(err.contains("x.obj") && err.contains("*.xml"), "{err}");
}

/// Mean luminance of an RGB EXR.
fn mean_luminance(file: &Path) -> f64 {
    let image = hush_dataset::read_rgb(file).unwrap();
    let sum: f64 = image.data.chunks_exact(3).map(|p| hush_dataset::luminance(p) as f64).sum();
    sum / (image.width * image.height) as f64
}

/// Three procedural scenes at 32², 1 spp: recorded in the manifest, `check` passes (no NaN/Inf, complete),
/// the scenes and their images differ, and a re-run keeps scenes and images.
#[test]
fn dataset_renders_distinct_procedural_scenes() {
    let dir = scratch("dataset-procedural");
    let ds = dir.join("ds");
    let args = [
        "dataset",
        "--procedural",
        "3",
        "--seed",
        "5",
        "--out",
        s(&ds),
        "--views",
        "1",
        "--spp",
        "1",
        "--aux-spp",
        "1",
        "--ref-spp",
        "1",
        "--ref-supersample",
        "1",
        "--size",
        "32",
    ];
    let log = expect_success(&args);
    assert!(log.contains("procedural: 3 scenes (3 generated, 0 kept)"), "{log}");
    expect_success(&["dataset", "check", s(&ds)]);
    let m = manifest_of(&ds);
    let p = &m["config"]["procedural"];
    assert_eq!((p["count"].as_u64(), p["seed"].as_u64(), p["features"].as_str()), (Some(3), Some(5), Some("default")));
    assert!(p["generator_version"].as_u64().unwrap() >= 1);
    let scenes = p["scenes"].as_array().unwrap();
    let xmls: std::collections::BTreeSet<String> =
        scenes.iter().map(|sc| std::fs::read_to_string(ds.join(sc["path"].as_str().unwrap())).unwrap()).collect();
    assert_eq!(xmls.len(), 3, "the three scenes must differ");
    assert_eq!(m["views"].as_array().unwrap().len(), 3);
    let mut lum: Vec<f64> = ["proc-5-0", "proc-5-1", "proc-5-2"]
        .iter()
        .map(|n| mean_luminance(&ds.join(format!("{n}_v000_000001.hdr.exr"))))
        .collect();
    assert!(lum.iter().all(|l| l.is_finite() && *l > 0.0), "{lum:?}");
    lum.sort_by(f64::total_cmp);
    assert!(lum.windows(2).all(|w| w[0] < w[1]), "three scenes, three different mean luminances: {lum:?}");

    let manifest = std::fs::read_to_string(ds.join("manifest.json")).unwrap();
    let log = expect_success(&args);
    assert!(log.contains("procedural: 3 scenes (0 generated, 3 kept)") && log.contains("0 images rendered"), "{log}");
    assert_eq!(manifest, std::fs::read_to_string(ds.join("manifest.json")).unwrap());
}
