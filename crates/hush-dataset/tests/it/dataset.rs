use hush_dataset::{
    AuxFiles, AuxKind, AuxRecord, AuxSource, CameraRecord, DatasetConfig, FireflyRecord, Layout, Manifest, PendingView,
    ReferenceRecord, RenderRecord, SceneEntry, Split, ViewGeneration, ViewRecord, check_dataset, link_or_copy,
    load_render_with, load_view, load_view_with, temp_target, write_rgb,
};

use crate::{TempDir, ramp};

pub fn record(scene: &str, view: &str, spps: &[u32], size: u32) -> ViewRecord {
    let render = |spp: u32, file: String| RenderRecord {
        spp,
        seed: 7 + u64::from(spp),
        file,
        render_seconds: 0.5,
        aux: Some(AuxFiles::from_fn(|kind| Layout::noisy_aux_name(scene, view, spp, kind))),
        variance: None,
        pixel_sampler: None,
    };
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
        generation: ViewGeneration { kind: "scene".into(), seed: 0, attempt: 0, probe: None },
        noisy: spps.iter().map(|&s| render(s, Layout::noisy_name(scene, view, s))).collect(),
        reference: ReferenceRecord {
            spp: 4096,
            seed: 99,
            file: Layout::reference_name(scene, view),
            render_seconds: 2.0,
            supersample: 2,
            firefly: FireflyRecord { factor: 4.0, clamped_pixels: 0, energy_removed: 0.0 },
            check: None,
            pixel_sampler: None,
        },
        aux: AuxRecord {
            spp: 64,
            seed: 1,
            render_seconds: 0.25,
            max_depth: Some(8),
            files: AuxFiles::from_fn(|kind| Layout::aux_name(scene, view, kind)),
            pixel_sampler: None,
        },
        repeats: Vec::new(),
    }
}

/// Writes every file of `view` as a small ramp image: the noisy renders, the reference, the clean features and
/// each render's own (at offsets 1, 2, 3–6 and 10 + 4 × render + feature); a render recorded without its own
/// features (an older dataset) gets OIDN's feature files beside it as links to the clean ones.
fn write_files(root: &std::path::Path, view: &ViewRecord) {
    let n = view.camera.width as usize;
    let files = view.noisy.iter().map(|r| &r.file).chain([&view.reference.file]);
    let aux = AuxKind::ALL.map(|k| view.aux.file(k).to_string());
    for (i, file) in files.chain(aux.iter()).enumerate() {
        write_rgb(root.join(file), &ramp(n, n, 3, i as f32)).unwrap();
    }
    for (i, r) in view.noisy.iter().enumerate() {
        match &r.aux {
            Some(own) => {
                for (j, kind) in AuxKind::ALL.into_iter().enumerate() {
                    write_rgb(root.join(own.file(kind)), &ramp(n, n, 3, (10 + 4 * i + j) as f32)).unwrap();
                }
            }
            None => {
                for kind in AuxKind::OIDN {
                    let beside = root.join(Layout::noisy_aux_name(&view.scene, &view.view, r.spp, kind));
                    link_or_copy(&root.join(view.aux.file(kind)), &beside).unwrap();
                }
            }
        }
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
    let mut test_view = record("sponza", "v0", &[4, 16], 8);
    test_view.split = Split::Test;
    // A repeat's ladder is validated and sorted as the noisy ladder is.
    test_view.repeats = vec![record("sponza", "v0", &[4, 4], 8).noisy];
    assert!(m.upsert(test_view.clone()).is_err(), "duplicate spp in a repeat");
    test_view.repeats = vec![record("sponza", "v0", &[16, 4], 8).noisy];
    assert!(m.upsert(test_view).unwrap().is_none());
    let spps = |v: &ViewRecord| v.repeats[0].iter().map(|r| r.spp).collect::<Vec<_>>();
    assert_eq!(spps(m.get("sponza", "v0").unwrap()), [4, 16]);
    assert_eq!(m.get("sponza", "v0").unwrap().renders_at(16).len(), 2);
    let replaced = m.upsert(record("cbox", "v1", &[4, 16, 64], 8)).unwrap().expect("same scene+view is replaced");
    assert_eq!(replaced.noisy.len(), 2);
    assert_eq!(m.views.len(), 2);
    assert_eq!(m.get("cbox", "v1").unwrap().noisy.iter().map(|r| r.spp).collect::<Vec<_>>(), [4, 16, 64]);
    assert!(m.upsert(record("bad.scene", "v1", &[4], 8)).is_err());
    assert!(m.upsert(record("cbox", "v2", &[4, 4], 8)).is_err(), "duplicate spp");

    // Timings are arbitrary f64s: the one below came back one ulp off (1.510183935) before JSON
    // parsing was made exact, and a re-run that rewrites the manifest then differed from the first.
    let timed = m.views.iter_mut().find(|v| v.scene == "cbox").unwrap();
    timed.noisy[0].render_seconds = 1.510_183_935_000_000_1;
    timed.reference.render_seconds = 0.1 + 0.2;
    m.save(dir.path()).unwrap();
    assert_eq!(dir.files(), ["manifest.json"]);
    let back = Manifest::load(dir.path()).unwrap();
    assert_eq!(back, m);
    assert_eq!(back.split(Split::Test).map(|v| v.scene.as_str()).collect::<Vec<_>>(), ["sponza"]);
    let text = std::fs::read_to_string(dir.join("manifest.json")).unwrap();
    assert!(text.contains("\"split\": \"test\"") && text.contains("\"format_version\": 2"), "{text}");
}

#[test]
fn load_view_reads_all_images() {
    let dir = TempDir::new("load-view");
    let view = record("cbox", "v0", &[4, 16], 8);
    write_files(dir.path(), &view);
    let images = load_view(dir.path(), &view, 16, AuxSource::Clean).unwrap();
    assert_eq!(images.color, ramp(8, 8, 3, 1.0));
    assert_eq!(images.reference, ramp(8, 8, 3, 2.0));
    assert_eq!(images.albedo, ramp(8, 8, 3, 3.0));
    assert_eq!(images.specular, ramp(8, 8, 3, 6.0));
    // The 16-spp render's own features (the second render: 10 + 4 + feature).
    let own = load_view(dir.path(), &view, 16, AuxSource::Noisy).unwrap();
    assert_eq!((own.color, own.reference), (images.color, images.reference));
    assert_eq!(own.albedo, ramp(8, 8, 3, 14.0));
    assert_eq!(own.specular, ramp(8, 8, 3, 17.0));

    let err = load_view(dir.path(), &view, 32, AuxSource::Noisy).unwrap_err().to_string();
    assert!(err.contains("32 spp") && err.contains("[4, 16]"), "{err}");

    // A render with the reference an earlier load returned: that image, its file not read again (here gone),
    // its size checked with the files'.
    std::fs::remove_file(dir.join(&view.reference.file)).unwrap();
    let err = load_render_with(dir.path(), &view, &view.noisy[0], AuxSource::Noisy, false, None).unwrap_err();
    assert!(err.to_string().contains("cbox_v0_ref.hdr.exr"), "{err}");
    let given = ramp(8, 8, 3, 30.0);
    let images =
        load_render_with(dir.path(), &view, &view.noisy[0], AuxSource::Noisy, false, Some(given.clone())).unwrap();
    assert_eq!((images.color, images.reference, images.albedo), (ramp(8, 8, 3, 0.0), given, ramp(8, 8, 3, 10.0)));
    let err = load_render_with(dir.path(), &view, &view.noisy[0], AuxSource::Noisy, false, Some(ramp(8, 6, 3, 0.0)))
        .unwrap_err()
        .to_string();
    assert!(err.contains("cbox_v0_ref.hdr.exr: 8x6") && err.contains("camera is 8x8"), "{err}");
    write_rgb(dir.join(&view.reference.file), &ramp(8, 8, 3, 2.0)).unwrap();

    // A render's variance is read where the manifest records one and it is asked for, with either auxiliary
    // source; not asked for, a lost variance file stops nothing.
    assert_eq!(own.variance, None);
    let mut with_variance = view.clone();
    let name = Layout::noisy_variance_name("cbox", "v0", 16);
    write_rgb(dir.join(&name), &ramp(8, 8, 3, 21.0)).unwrap();
    with_variance.noisy[1].variance = Some(name.clone());
    for aux in [AuxSource::Noisy, AuxSource::Clean] {
        let images = load_view_with(dir.path(), &with_variance, 16, aux, true).unwrap();
        assert_eq!(images.variance, Some(ramp(8, 8, 3, 21.0)));
        assert_eq!(load_view(dir.path(), &with_variance, 16, aux).unwrap().variance, None);
    }
    std::fs::remove_file(dir.join(&name)).unwrap();
    let err = load_view_with(dir.path(), &with_variance, 16, AuxSource::Noisy, true).unwrap_err().to_string();
    assert!(err.contains(&name), "{err}");
    assert!(load_view(dir.path(), &with_variance, 16, AuxSource::Noisy).is_ok());

    // A dataset from before the renders' own features were stored: clean ones only, and a clear error.
    let mut old = view.clone();
    old.noisy.iter_mut().for_each(|r| r.aux = None);
    assert!(load_view(dir.path(), &old, 4, AuxSource::Clean).is_ok());
    let err = load_view(dir.path(), &old, 4, AuxSource::Noisy).unwrap_err().to_string();
    assert!(
        err.contains("cbox_v0 at 4 spp") && err.contains("run `hush dataset` again") && err.contains("--aux clean"),
        "{err}"
    );
}

#[test]
fn load_view_rejects_mismatched_sizes_and_nan() {
    let dir = TempDir::new("load-view-bad");
    let view = record("cbox", "v0", &[4], 8);
    write_files(dir.path(), &view);
    write_rgb(dir.join(&view.aux.files.normal), &ramp(8, 6, 3, 0.0)).unwrap();
    let err = load_view(dir.path(), &view, 4, AuxSource::Clean).unwrap_err().to_string();
    assert!(err.contains("cbox_v0_ref.nrm.exr: 8x6") && err.contains("camera is 8x8"), "{err}");

    write_rgb(dir.join(&view.aux.files.normal), &ramp(8, 8, 3, 0.0)).unwrap();
    let mut bad = ramp(8, 8, 3, 0.0);
    bad.pixel_mut(5, 2)[1] = f32::NAN;
    write_rgb(dir.join(&view.reference.file), &bad).unwrap();
    let err = load_view(dir.path(), &view, 4, AuxSource::Clean).unwrap_err().to_string();
    assert!(err.contains("cbox_v0_ref.hdr.exr") && err.contains("(x 5, y 2), channel 1"), "{err}");

    std::fs::remove_file(dir.join(&view.aux.files.diffuse)).unwrap();
    let err = load_view(dir.path(), &view, 4, AuxSource::Clean).unwrap_err().to_string();
    assert!(err.contains("cbox_v0_ref.diff.exr"), "{err}");
}

fn config(scenes: &[&str], views: u32, spp: &[u32]) -> DatasetConfig {
    DatasetConfig {
        seed: 0,
        views,
        spp: spp.to_vec(),
        aux_spp: 4,
        ref_spp: 16,
        test_ref_spp: None,
        ref_supersample: 2,
        firefly_factor: 4.0,
        ref_check_spp: 0,
        size: Some(8),
        scenes: scenes
            .iter()
            .map(|s| SceneEntry { name: s.to_string(), path: format!("{s}/scene.xml"), split: None, triangles: 2 })
            .collect(),
        skipped: Vec::new(),
        procedural: None,
        pixel_sampler: None,
        test_repeats: None,
    }
}

#[test]
fn oidn_feature_names_beside_noisy_renders() {
    assert_eq!(Layout::noisy_aux_name("cbox", "v003", 4, AuxKind::Albedo), "cbox_v003_000004.alb.exr");
    assert_eq!(Layout::noisy_aux_name("cbox", "v003", 256, AuxKind::Normal), "cbox_v003_000256.nrm.exr");
    assert_eq!(Layout::new("/d").shard_manifest_path(2, 8), std::path::Path::new("/d/manifest.shard-2-of-8.json"));
}

#[test]
fn progress_moves_from_pending_to_views() {
    let mut m = Manifest::default();
    let full = record("cbox", "v000", &[1, 2], 8);
    let mut progress = PendingView::from(full.clone());
    progress.reference = None;
    progress.noisy.truncate(1);
    m.upsert_progress(progress.clone()).unwrap();
    assert!(m.views.is_empty() && m.pending.len() == 1);
    assert_eq!(m.progress("cbox", "v000"), Some(progress));
    m.upsert_progress(PendingView::from(full.clone())).unwrap();
    assert!(m.pending.is_empty());
    assert_eq!(m.get("cbox", "v000"), Some(&full));
}

#[test]
fn shard_parts_merge_on_load() {
    let dir = TempDir::new("shards");
    let layout = Layout::new(dir.path());
    let mut a = Manifest { config: Some(config(&["cbox"], 3, &[1, 2])), ..Default::default() };
    a.upsert(record("cbox", "v000", &[1, 2], 8)).unwrap();
    a.upsert(record("cbox", "v002", &[1, 2], 8)).unwrap();
    let mut b = Manifest { config: Some(config(&["cbox"], 3, &[1, 2])), ..Default::default() };
    let mut pending = PendingView::from(record("cbox", "v001", &[1], 8));
    pending.aux = None;
    b.upsert_progress(pending).unwrap();
    a.save_file(&layout.shard_manifest_path(0, 2)).unwrap();
    b.save_file(&layout.shard_manifest_path(1, 2)).unwrap();

    let merged = Manifest::load(dir.path()).unwrap();
    assert_eq!(merged.views.iter().map(|v| v.view.as_str()).collect::<Vec<_>>(), ["v000", "v002"]);
    assert_eq!(merged.pending.len(), 1);
    assert_eq!(merged.config, a.config);

    // Finishing v001 in shard 1 completes the merged manifest; a stale manifest.json is overridden.
    let mut stale = Manifest::default();
    let mut old = record("cbox", "v001", &[1, 2], 8);
    old.reference.spp = 7;
    stale.upsert(old).unwrap();
    stale.save(dir.path()).unwrap();
    b.upsert_progress(PendingView::from(record("cbox", "v001", &[1, 2], 8))).unwrap();
    b.save_file(&layout.shard_manifest_path(1, 2)).unwrap();
    let merged = Manifest::load(dir.path()).unwrap();
    assert_eq!(merged.views.len(), 3);
    assert!(merged.pending.is_empty());
    assert_eq!(merged.get("cbox", "v001").unwrap().reference.spp, 4096);
}

#[test]
fn check_passes_a_complete_dataset_and_lists_every_problem() {
    let dir = TempDir::new("check");
    let mut m = Manifest { config: Some(config(&["cbox", "room"], 2, &[1, 2])), ..Default::default() };
    // The room's views are from an older dataset: links to the clean features beside each render instead of
    // the renders' own.
    let legacy = |mut r: ViewRecord| {
        r.noisy.iter_mut().for_each(|n| n.aux = None);
        r
    };
    for (scene, view) in [("cbox", "v000"), ("cbox", "v001"), ("room", "v000"), ("room", "v001")] {
        let r = record(scene, view, &[1, 2], 8);
        let r = if scene == "room" { legacy(r) } else { r };
        write_files(dir.path(), &r);
        m.upsert(r).unwrap();
    }
    m.save(dir.path()).unwrap();
    let report = check_dataset(dir.path()).unwrap();
    assert!(report.ok(), "{:?}", report.problems);
    // Per view 5 files of its own (reference, 4 clean features), per render the image and 4 own features, or
    // in the older views 2 links.
    assert_eq!((report.views, report.files_checked), (4, 2 * (2 * 5 + 5) + 2 * (2 * 3 + 5)));

    // Break it in every way check looks for.
    let mut nan = ramp(8, 8, 3, 0.0);
    nan.pixel_mut(1, 1)[0] = f32::INFINITY;
    write_rgb(dir.join("cbox_v000_000001.hdr.exr"), &nan).unwrap();
    write_rgb(dir.join("cbox_v001_ref.hdr.exr"), &ramp(8, 4, 3, 0.0)).unwrap();
    std::fs::remove_file(dir.join("room_v000_000002.nrm.exr")).unwrap();
    std::fs::remove_file(dir.join("cbox_v000_000002.diff.exr")).unwrap();
    std::fs::write(dir.join("room_v000_ref.spec.exr"), b"not an exr").unwrap();
    write_rgb(dir.join("room_v000_000002.alb.exr"), &ramp(8, 8, 3, 9.0)).unwrap();
    std::fs::write(dir.join(".room_v001_000001.hdr.exr.123.0.tmp"), b"partial").unwrap();
    m.views.retain(|v| !(v.scene == "room" && v.view == "v001"));
    let mut pending = PendingView::from(legacy(record("room", "v001", &[1], 8)));
    pending.reference = None;
    m.upsert_progress(pending).unwrap();
    let mut short = record("cbox", "v001", &[1], 8);
    short.reference.file = "cbox_v001_ref.hdr.exr".into();
    m.upsert(short).unwrap();
    m.save(dir.path()).unwrap();

    let report = check_dataset(dir.path()).unwrap();
    let all = report.problems.join("\n");
    for needle in [
        "cbox_v000_000001.hdr.exr: 1 non-finite",
        "cbox_v001_ref.hdr.exr: is 8x4x3 but the camera is 8x8x3",
        "room_v000_000002.nrm.exr: missing",
        "cbox_v000_000002.diff.exr: missing",
        "room_v001: unfinished",
        "cbox_v001: noisy renders at {1} spp but the ladder is {1, 2}",
        ".room_v001_000001.hdr.exr.123.0.tmp: temporary file",
        "room_v000_ref.spec.exr",
        "room_v000_000002.alb.exr: differs from",
    ] {
        assert!(all.contains(needle), "no problem mentions {needle:?}:\n{all}");
    }
    assert_eq!(report.problems.len(), 9, "{all}");
}

#[test]
fn temporary_names_map_to_their_targets() {
    assert_eq!(temp_target(".cbox_v000_000001.hdr.exr.4242.17.tmp"), Some("cbox_v000_000001.hdr.exr"));
    assert_eq!(temp_target(".manifest.json.1.0.tmp"), Some("manifest.json"));
    assert_eq!(temp_target("cbox.tmp"), None);
    assert_eq!(temp_target(".x.y.tmp"), None);
}

#[test]
fn link_or_copy_makes_equal_files_and_is_idempotent() {
    let dir = TempDir::new("link");
    write_rgb(dir.join("a.exr"), &ramp(4, 4, 3, 0.0)).unwrap();
    link_or_copy(&dir.join("a.exr"), &dir.join("b.exr")).unwrap();
    link_or_copy(&dir.join("a.exr"), &dir.join("b.exr")).unwrap();
    assert_eq!(std::fs::read(dir.join("a.exr")).unwrap(), std::fs::read(dir.join("b.exr")).unwrap());
    assert_eq!(dir.files(), ["a.exr", "b.exr"], "no temporary file is left");
}
