use hush_dataset::{
    AuxKind, AuxRecord, CameraRecord, Layout, Manifest, RenderRecord, Split, ViewRecord, load_view, write_rgb,
};

use crate::{TempDir, ramp};

fn record(scene: &str, view: &str, spps: &[u32], size: u32) -> ViewRecord {
    let render = |spp: u32, file: String| RenderRecord { spp, seed: 7 + u64::from(spp), file, render_seconds: 0.5 };
    ViewRecord {
        scene: scene.into(),
        view: view.into(),
        split: Split::Train,
        camera: CameraRecord {
            origin: [0.0, 0.0, 3.9],
            target: [0.0; 3],
            up: [0.0, 1.0, 0.0],
            fov_y_deg: 39.3077,
            width: size,
            height: size,
        },
        noisy: spps.iter().map(|&s| render(s, Layout::noisy_name(scene, view, s))).collect(),
        reference: render(4096, Layout::reference_name(scene, view)),
        aux: AuxRecord {
            spp: 64,
            seed: 1,
            render_seconds: 0.25,
            albedo: Layout::aux_name(scene, view, AuxKind::Albedo),
            normal: Layout::aux_name(scene, view, AuxKind::Normal),
            diffuse: Layout::aux_name(scene, view, AuxKind::Diffuse),
            specular: Layout::aux_name(scene, view, AuxKind::Specular),
        },
    }
}

/// Writes every file of `view` as a small ramp image.
fn write_files(root: &std::path::Path, view: &ViewRecord) {
    let n = view.camera.width as usize;
    let files = view.noisy.iter().map(|r| &r.file).chain([&view.reference.file]);
    let aux = AuxKind::ALL.map(|k| view.aux.file(k).to_string());
    for (i, file) in files.chain(aux.iter()).enumerate() {
        write_rgb(root.join(file), &ramp(n, n, 3, i as f32)).unwrap();
    }
}

#[test]
fn names_follow_oidn_conventions() {
    assert_eq!(Layout::noisy_name("cbox", "v03", 16), "cbox_v03_000016.hdr.exr");
    assert_eq!(Layout::reference_name("cbox", "v03"), "cbox_v03_ref.hdr.exr");
    let aux: Vec<String> = AuxKind::ALL.iter().map(|&k| Layout::aux_name("cbox", "v03", k)).collect();
    assert_eq!(aux, ["cbox_v03_ref.alb.exr", "cbox_v03_ref.nrm.exr", "cbox_v03_ref.diff.exr", "cbox_v03_ref.spec.exr"]);
    assert!(Layout::check_name("scene", "cornell-box").is_ok());
    let err = Layout::check_name("scene", "cornell_box").unwrap_err().to_string();
    assert!(err.contains("cornell_box") && err.contains("'-'"), "{err}");
}

#[test]
fn manifest_round_trip_and_upsert() {
    let dir = TempDir::new("manifest");
    assert_eq!(Manifest::load_or_default(dir.path()).unwrap(), Manifest::default());
    let err = Manifest::load(dir.path()).unwrap_err().to_string();
    assert!(err.contains("manifest.json"), "{err}");

    let mut m = Manifest::default();
    assert!(m.upsert(record("cbox", "v1", &[16, 4], 8)).unwrap().is_none());
    let mut test_view = record("sponza", "v0", &[4], 8);
    test_view.split = Split::Test;
    assert!(m.upsert(test_view).unwrap().is_none());
    let replaced = m.upsert(record("cbox", "v1", &[4, 16, 64], 8)).unwrap().expect("same scene+view is replaced");
    assert_eq!(replaced.noisy.len(), 2);
    assert_eq!(m.views.len(), 2);
    assert_eq!(m.get("cbox", "v1").unwrap().noisy.iter().map(|r| r.spp).collect::<Vec<_>>(), [4, 16, 64]);
    assert!(m.upsert(record("bad.scene", "v1", &[4], 8)).is_err());
    assert!(m.upsert(record("cbox", "v2", &[4, 4], 8)).is_err(), "duplicate spp");

    m.save(dir.path()).unwrap();
    assert_eq!(dir.files(), ["manifest.json"]);
    let back = Manifest::load(dir.path()).unwrap();
    assert_eq!(back, m);
    assert_eq!(back.split(Split::Test).map(|v| v.scene.as_str()).collect::<Vec<_>>(), ["sponza"]);
    let text = std::fs::read_to_string(dir.join("manifest.json")).unwrap();
    assert!(text.contains("\"split\": \"test\"") && text.contains("\"format_version\": 1"), "{text}");
}

#[test]
fn load_view_reads_all_images() {
    let dir = TempDir::new("load-view");
    let view = record("cbox", "v0", &[4, 16], 8);
    write_files(dir.path(), &view);
    let images = load_view(dir.path(), &view, 16).unwrap();
    assert_eq!(images.color, ramp(8, 8, 3, 1.0));
    assert_eq!(images.reference, ramp(8, 8, 3, 2.0));
    assert_eq!(images.albedo, ramp(8, 8, 3, 3.0));
    assert_eq!(images.specular, ramp(8, 8, 3, 6.0));

    let err = load_view(dir.path(), &view, 32).unwrap_err().to_string();
    assert!(err.contains("32 spp") && err.contains("[4, 16]"), "{err}");
}

#[test]
fn load_view_rejects_mismatched_sizes_and_nan() {
    let dir = TempDir::new("load-view-bad");
    let view = record("cbox", "v0", &[4], 8);
    write_files(dir.path(), &view);
    write_rgb(dir.join(&view.aux.normal), &ramp(8, 6, 3, 0.0)).unwrap();
    let err = load_view(dir.path(), &view, 4).unwrap_err().to_string();
    assert!(err.contains("cbox_v0_ref.nrm.exr: 8x6") && err.contains("camera is 8x8"), "{err}");

    write_rgb(dir.join(&view.aux.normal), &ramp(8, 8, 3, 0.0)).unwrap();
    let mut bad = ramp(8, 8, 3, 0.0);
    bad.pixel_mut(5, 2)[1] = f32::NAN;
    write_rgb(dir.join(&view.reference.file), &bad).unwrap();
    let err = load_view(dir.path(), &view, 4).unwrap_err().to_string();
    assert!(err.contains("cbox_v0_ref.hdr.exr") && err.contains("(x 5, y 2), channel 1"), "{err}");

    std::fs::remove_file(dir.join(&view.aux.diffuse)).unwrap();
    let err = load_view(dir.path(), &view, 4).unwrap_err().to_string();
    assert!(err.contains("cbox_v0_ref.diff.exr"), "{err}");
}
