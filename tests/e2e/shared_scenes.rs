//! The CI acceptance of `hush dataset` on the shared scenes: two scenes × two views at 64² pass
//! `hush dataset check`, and a run killed midway resumes without re-rendering finished images.

use std::path::PathBuf;

use crate::{expect_success, kill_once_recorded, manifest_of, rerun_keeps, s, scratch};

fn shared_scene(name: &str) -> PathBuf {
    let p = PathBuf::from(concat!(env!("CARGO_MANIFEST_DIR"), "/../../../shared/scenes")).join(name).join("scene.xml");
    assert!(p.is_file(), "the shared scenes are expected beside the repository: {} is missing", p.display());
    p
}

/// cornell-box and veach-mis (three very bright sphere lights, rough conductors), two views each at 64²
/// with tiny sample counts: killed (SIGKILL) once two images are recorded, then re-run to completion.
#[cfg(unix)]
#[test]
fn two_shared_scenes_two_views_resume_after_kill_and_pass_check() {
    let dir = scratch("shared-two");
    let ds = dir.join("ds");
    let (cbox, veach) = (shared_scene("cornell-box"), shared_scene("veach-mis"));
    let args = [
        "dataset",
        s(&cbox),
        s(&veach),
        "--out",
        s(&ds),
        "--views",
        "2",
        "--spp",
        "1,2",
        "--aux-spp",
        "1",
        "--ref-spp",
        "2",
        "--size",
        "64",
    ];
    let before = kill_once_recorded(&args, &ds, 2);
    assert!(manifest_of(&ds)["views"].as_array().unwrap().len() < 4, "killed before the end");

    rerun_keeps(&args, &ds, &before);
    let m = manifest_of(&ds);
    let views: Vec<String> =
        m["views"].as_array().unwrap().iter().map(|v| format!("{}_{}", v["scene"], v["view"])).collect();
    assert_eq!(views.len(), 4, "{views:?}");
    expect_success(&["dataset", "check", s(&ds)]);
}
