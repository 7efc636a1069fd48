//! End-to-end tests of the `hush` command line: bad input gets a clear error and no panic, and
//! the whole pipeline (dataset → train → denoise → eval) runs on a tiny Cornell box.

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

fn repo() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../..")
}

fn cbox() -> PathBuf {
    repo().join("data/scenes/cbox/scene.xml")
}

fn scratch(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("hush-e2e-{name}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

fn hush(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_hush")).args(args).output().expect("hush starts")
}

fn s(p: &Path) -> &str {
    p.to_str().unwrap()
}

/// Runs hush expecting failure; returns stderr after checking it is an error, not a panic.
fn expect_error(args: &[&str]) -> String {
    let out = hush(args);
    let stderr = String::from_utf8_lossy(&out.stderr).into_owned();
    assert_eq!(out.status.code(), Some(1), "hush {args:?} should fail with exit code 1; stderr:\n{stderr}");
    assert!(!stderr.contains("panicked"), "hush {args:?} panicked:\n{stderr}");
    assert!(stderr.contains("error: "), "{stderr}");
    stderr
}

fn expect_success(args: &[&str]) -> String {
    let out = hush(args);
    let stderr = String::from_utf8_lossy(&out.stderr).into_owned();
    assert!(out.status.success(), "hush {args:?} failed:\n{stderr}");
    stderr
}

#[test]
fn missing_scene_file_is_a_clear_error() {
    let dir = scratch("missing");
    let err = expect_error(&["render", "/nonexistent/scene.xml", "--spp", "1", "--out", s(&dir.join("o.exr"))]);
    assert!(err.contains("/nonexistent/scene.xml"), "{err}");
}

#[test]
fn malformed_xml_is_a_clear_error() {
    let dir = scratch("malformed");
    let scene = dir.join("scene.xml");
    std::fs::write(&scene, "<scene version=\"3.0.0\">\n  <shape type=\"obj\">\n</scene>\n").unwrap();
    let err = expect_error(&["render", s(&scene), "--spp", "1", "--out", s(&dir.join("o.exr"))]);
    assert!(err.contains("scene.xml:") && err.contains("malformed XML"), "{err}");
    assert!(!dir.join("o.exr").exists());
}

#[test]
fn nan_vertices_are_a_clear_error() {
    let dir = scratch("nan");
    std::fs::write(dir.join("bad.obj"), "v 0 0 0\nv 1 NaN 0\nv 0 1 0\nf 1 2 3\n").unwrap();
    let scene = dir.join("scene.xml");
    std::fs::write(
        &scene,
        r#"<scene version="3.0.0"><sensor type="perspective"><float name="fov" value="40"/>
        <transform name="to_world"><lookat origin="0,0,4" target="0,0,0" up="0,1,0"/></transform></sensor>
        <shape type="obj"><string name="filename" value="bad.obj"/></shape></scene>"#,
    )
    .unwrap();
    let err = expect_error(&["render", s(&scene), "--spp", "1", "--out", s(&dir.join("o.exr"))]);
    assert!(err.contains("bad.obj") && err.contains("not finite"), "{err}");
}

#[test]
fn zero_spp_is_a_clear_error() {
    let dir = scratch("spp0");
    let err = expect_error(&["render", s(&cbox()), "--spp", "0", "--out", s(&dir.join("o.exr"))]);
    assert!(err.contains("--spp must be at least 1"), "{err}");
}

#[test]
fn render_writes_every_layer() {
    let dir = scratch("render");
    let out = dir.join("box.exr");
    let stats = dir.join("stats.json");
    expect_success(&[
        "render",
        s(&cbox()),
        "--spp",
        "2",
        "--width",
        "24",
        "--height",
        "16",
        "--out",
        s(&out),
        "--stats",
        s(&stats),
    ]);
    let exr = hush_dataset::read_exr(&out).unwrap();
    let mut names: Vec<&str> = exr.channels.keys().map(String::as_str).collect();
    names.sort_unstable();
    let mut expect = vec![
        "B",
        "G",
        "R",
        "albedo.B",
        "albedo.G",
        "albedo.R",
        "diffuse.B",
        "diffuse.G",
        "diffuse.R",
        "normal.X",
        "normal.Y",
        "normal.Z",
        "specular.B",
        "specular.G",
        "specular.R",
    ];
    expect.sort_unstable();
    assert_eq!(names, expect);
    assert_eq!((exr.width, exr.height), (24, 16));
    let stats: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(&stats).unwrap()).unwrap();
    assert_eq!(stats["paths"].as_f64(), Some(24.0 * 16.0 * 2.0));
}

/// The whole pipeline on a 32² Cornell box: dataset (re-run resumes without re-rendering),
/// train, denoise (with a clear error for a missing feature), eval.
#[test]
fn pipeline_runs_end_to_end() {
    let dir = scratch("pipeline");
    let ds = dir.join("ds");
    let run = dir.join("run");
    let scene = cbox();
    let dataset_args = [
        "dataset",
        s(&scene),
        "--out",
        s(&ds),
        "--views",
        "2",
        "--test-views",
        "1",
        "--spp",
        "2",
        "--ref-spp",
        "16",
        "--aux-spp",
        "4",
        "--size",
        "32",
        "--seed",
        "3",
    ];
    expect_success(&dataset_args);
    let manifest = std::fs::read_to_string(ds.join("manifest.json")).unwrap();
    expect_success(&dataset_args);
    assert_eq!(
        manifest,
        std::fs::read_to_string(ds.join("manifest.json")).unwrap(),
        "a re-run must reuse every finished render"
    );

    expect_success(&[
        "train",
        "--dataset",
        s(&ds),
        "--out",
        s(&run),
        "--steps",
        "3",
        "--batch",
        "2",
        "--crop",
        "32",
        "--width",
        "0.125",
        "--checkpoint-every",
        "2",
    ]);
    assert!(run.join("model.safetensors").is_file() && run.join("config.json").is_file());
    assert!(run.join("checkpoints/step_000002.safetensors").is_file());
    let log = std::fs::read_to_string(run.join("loss.csv")).unwrap();
    assert_eq!(log.lines().count(), 4, "header and three steps:\n{log}");

    let model = run.join("model.safetensors");
    let out = dir.join("denoised.exr");
    expect_success(&[
        "denoise",
        "--model",
        s(&model),
        "--color",
        s(&ds.join("cbox_v001_000002.hdr.exr")),
        "--albedo",
        s(&ds.join("cbox_v001_ref.alb.exr")),
        "--normal",
        s(&ds.join("cbox_v001_ref.nrm.exr")),
        "--out",
        s(&out),
    ]);
    let denoised = hush_dataset::read_rgb(&out).unwrap();
    assert_eq!((denoised.width, denoised.height, denoised.count_non_finite()), (32, 32, 0));
    let err = expect_error(&[
        "denoise",
        "--model",
        s(&model),
        "--color",
        s(&ds.join("cbox_v001_000002.hdr.exr")),
        "--out",
        s(&out),
    ]);
    assert!(err.contains("--albedo"), "{err}");

    let report = dir.join("report");
    expect_success(&["eval", "--dataset", s(&ds), "--model", s(&model), "--out", s(&report), "--timing-runs", "1"]);
    let summary: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(report.join("summary.json")).unwrap()).unwrap();
    let methods: Vec<&str> =
        summary["rows"].as_array().unwrap().iter().map(|r| r["method"].as_str().unwrap()).collect();
    assert!(methods.contains(&"noisy") && methods.contains(&"run/model"), "{methods:?}");
    assert!(report.join("report.md").is_file());
}
