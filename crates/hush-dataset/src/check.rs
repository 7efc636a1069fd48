//! `hush dataset check`: is a dataset complete, are its files readable, of the right size and finite, and does
//! the manifest agree with itself?

use std::collections::BTreeSet;
use std::path::{Path, PathBuf};

use crate::{AuxKind, Layout, Manifest, ViewRecord, check_finite, manifest_files, read_rgb};

/// The outcome of [`check_dataset`]: every problem found, one line each, naming the file.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct CheckReport {
    pub views: usize,
    pub files_checked: usize,
    pub problems: Vec<String>,
}

impl CheckReport {
    pub fn ok(&self) -> bool {
        self.problems.is_empty()
    }
}

/// Checks the dataset at `root`:
///
/// * the manifest (`manifest.json` and shard parts) parses, and the parts agree on the settings (apart from
///   the scene paths, which differ between machines);
/// * completeness: every scene of the settings has every view, no view is left pending, every view has
///   the noisy render of every spp of the ladder, the reference and the four features;
/// * every file listed (with each noisy render's own features, or in older datasets the `.alb`/`.nrm` files
///   beside it) exists, reads as an RGB EXR of the camera's size and holds no NaN/Inf; in older datasets the
///   per-spp feature files equal the `_ref` ones;
/// * no temporary file (`.*.tmp`) of an interrupted write is left.
///
/// Only an unreadable manifest is an `Err`; everything else is a problem in the report.
pub fn check_dataset(root: &Path) -> crate::Result<CheckReport> {
    let manifest = Manifest::load(root)?;
    let layout = Layout::new(root);
    let mut report = CheckReport { views: manifest.views.len(), ..Default::default() };
    let problems = &mut report.problems;

    // The parts must have been rendered with the same settings.
    let mut configs = Vec::new();
    for file in manifest_files(root)? {
        let part = Manifest::load_file(&file)?;
        if let Some(mut c) = part.config {
            c.scenes.iter_mut().for_each(|s| s.path.clear());
            c.skipped.clear();
            configs.push((file, c));
        }
    }
    if let Some((first_file, first)) = configs.first() {
        for (file, c) in &configs[1..] {
            if c != first {
                problems.push(format!(
                    "{}: rendered with other settings than {} (seed, views, spp ladder, size or scenes differ); \
                     re-render that shard with the same flags",
                    file.display(),
                    first_file.display()
                ));
            }
        }
    }

    for p in &manifest.pending {
        problems.push(format!(
            "{}_{}: unfinished ({} noisy renders, reference {}, features {}); re-run `hush dataset` to finish it",
            p.scene,
            p.view,
            p.noisy.len(),
            if p.reference.is_some() { "done" } else { "missing" },
            if p.aux.is_some() { "done" } else { "missing" },
        ));
    }
    if let Some(config) = &manifest.config {
        let want: BTreeSet<u32> = config.spp.iter().copied().collect();
        for scene in &config.scenes {
            for v in 0..config.views {
                let view = format!("v{v:03}");
                match manifest.get(&scene.name, &view) {
                    None if manifest.pending.iter().any(|p| p.scene == scene.name && p.view == view) => {}
                    None => problems.push(format!(
                        "{}_{view}: missing from the manifest (scene {}); re-run `hush dataset` (with the same \
                         --shard if it was sharded) to render it",
                        scene.name, scene.path
                    )),
                    Some(rec) => {
                        let have: BTreeSet<u32> = rec.noisy.iter().map(|r| r.spp).collect();
                        if have != want {
                            problems.push(format!(
                                "{}_{view}: noisy renders at {have:?} spp but the ladder is {want:?}; re-run \
                                 `hush dataset` with the same --spp",
                                scene.name
                            ));
                        }
                        if config.ref_check_spp > 0 && rec.reference.check.is_none() {
                            problems.push(format!(
                                "{}_{view}: the reference has no relMSE check at {} spp; re-run `hush dataset`",
                                scene.name, config.ref_check_spp
                            ));
                        }
                    }
                }
            }
        }
    }

    for view in &manifest.views {
        check_view_files(&layout, view, &mut report.files_checked, problems);
    }
    for tmp in temp_files(root)? {
        problems.push(format!(
            "{}: temporary file of an interrupted write; re-run `hush dataset` (it removes them) or delete it",
            tmp.display()
        ));
    }
    Ok(report)
}

fn check_view_files(layout: &Layout, view: &ViewRecord, checked: &mut usize, problems: &mut Vec<String>) {
    let (w, h) = (view.camera.width as usize, view.camera.height as usize);
    for file in Manifest::files_of(view) {
        *checked += 1;
        if let Err(e) = check_image(&layout.path(&file), w, h) {
            problems.push(e);
        }
    }
    // Datasets from before the renders' own features were stored link the clean ones beside each render.
    for r in view.noisy.iter().filter(|r| r.aux.is_none()) {
        for kind in AuxKind::OIDN {
            let beside = layout.path(&Layout::noisy_aux_name(&view.scene, &view.view, r.spp, kind));
            let source = layout.path(view.aux.file(kind));
            if let (Ok(a), Ok(b)) = (std::fs::read(&beside), std::fs::read(&source))
                && a != b
            {
                problems.push(format!(
                    "{}: differs from {}; re-run `hush dataset` to re-link it",
                    beside.display(),
                    source.display()
                ));
            }
        }
    }
}

/// Ok if `path` reads as a 3-channel `w`×`h` EXR without NaN/Inf; else the problem, naming the file.
pub fn check_image(path: &Path, w: usize, h: usize) -> Result<(), String> {
    match hush_io::describe_unreadable(path) {
        None => {}
        Some(hush_io::Unreadable::Missing) => {
            return Err(format!("{}: missing; re-run `hush dataset` to render it", path.display()));
        }
        Some(why) => return Err(format!("{}: {why}; remove it and re-run `hush dataset`", path.display())),
    }
    let image = read_rgb(path).map_err(|e| format!("{e}; delete it and re-run `hush dataset`"))?;
    if (image.width, image.height, image.channels) != (w, h, 3) {
        return Err(format!(
            "{}: is {} but the camera is {w}x{h}x3; delete it and re-run `hush dataset`",
            path.display(),
            image.size_string()
        ));
    }
    check_finite(path, &image).map_err(|e| e.to_string())
}

/// Temporary files left by writes that were interrupted (`.<name>.<pid>.<n>.tmp`, see [`crate::write_atomic`]).
pub fn temp_files(root: &Path) -> crate::Result<Vec<PathBuf>> {
    let mut found = Vec::new();
    let entries = std::fs::read_dir(root).map_err(|e| crate::Error::file(root, "list the dataset folder", e))?;
    for entry in entries.flatten() {
        let name = entry.file_name().to_string_lossy().into_owned();
        if name.starts_with('.') && name.ends_with(".tmp") {
            found.push(entry.path());
        }
    }
    found.sort();
    Ok(found)
}

/// The file a temporary file of [`crate::write_atomic`] was going to become (`.<name>.<pid>.<n>.tmp` →
/// `<name>`), if the name has that form.
pub fn temp_target(tmp_name: &str) -> Option<&str> {
    let rest = tmp_name.strip_prefix('.')?.strip_suffix(".tmp")?;
    let (rest, n) = rest.rsplit_once('.')?;
    let (name, pid) = rest.rsplit_once('.')?;
    (n.bytes().all(|b| b.is_ascii_digit()) && pid.bytes().all(|b| b.is_ascii_digit()) && !name.is_empty())
        .then_some(name)
}

/// Makes `dst` the same file as `src`: a hard link, or a copy where the file system has none. Atomic like
/// every write of this crate: `dst` is either the old file or the new one.
pub fn link_or_copy(src: &Path, dst: &Path) -> crate::Result<()> {
    // Renaming a link over another link to the same file is a no-op that would leave the temporary behind.
    if let (Ok(a), Ok(b)) = (std::fs::read(src), std::fs::read(dst))
        && a == b
    {
        return Ok(());
    }
    crate::write_atomic(dst, |tmp| {
        std::fs::hard_link(src, tmp)
            .or_else(|_| std::fs::copy(src, tmp).map(|_| ()))
            .map_err(|e| crate::Error::file(src, "link or copy", e))
    })
}
