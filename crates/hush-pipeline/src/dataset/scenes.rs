//! The scenes of a dataset: files and folders expanded, loaded, named and split into training and test scenes.

use std::path::{Path, PathBuf};

use anyhow::{Context, Result, bail};
use hush_dataset::{SkippedScene, Split};
use hush_scene::Scene;

use super::DatasetPlan;
use crate::Observer;
use crate::scene::{ViewOverrides, load_scene};

/// The name of a scene file: its stem, or its folder's name for `scene.*`, made into a valid dataset name.
pub fn scene_name(path: &Path) -> String {
    let stem = match path.file_stem().and_then(|s| s.to_str()) {
        Some("scene") | None => path.parent().and_then(|p| p.file_name()).and_then(|s| s.to_str()).unwrap_or("scene"),
        Some(s) => s,
    };
    let name: String = stem.chars().map(|c| if c.is_ascii_alphanumeric() || c == '-' { c } else { '-' }).collect();
    if name.is_empty() { "scene".into() } else { name }
}

/// Scene files named on the command line, with folders expanded (sorted, so every shard sees one order).
pub fn collect_scene_files(inputs: &[PathBuf]) -> Result<Vec<PathBuf>> {
    fn walk(dir: &Path, out: &mut Vec<PathBuf>) -> Result<()> {
        let scene_xml = dir.join("scene.xml");
        if scene_xml.is_file() {
            out.push(scene_xml);
            return Ok(());
        }
        let mut entries: Vec<PathBuf> = std::fs::read_dir(dir)
            .with_context(|| format!("{}: cannot list the scene folder", dir.display()))?
            .filter_map(|e| e.ok().map(|e| e.path()))
            .collect();
        entries.sort();
        for path in entries {
            if path.is_dir() {
                walk(&path, out)?;
            } else if matches!(
                path.extension().and_then(|e| e.to_str()).map(str::to_ascii_lowercase).as_deref(),
                Some("gltf" | "glb" | "obj")
            ) {
                out.push(path);
            }
        }
        Ok(())
    }
    let mut files = Vec::new();
    for input in inputs {
        if input.is_dir() {
            let before = files.len();
            walk(input, &mut files)?;
            if files.len() == before {
                bail!("{}: no scene.xml, .gltf, .glb or .obj file below this folder", input.display());
            }
        } else {
            files.push(input.clone());
        }
    }
    Ok(files)
}

/// A loaded scene of the job.
pub(crate) struct JobScene {
    pub(crate) name: String,
    pub(crate) path: PathBuf,
    pub(crate) scene: Scene,
    pub(crate) split: Option<Split>,
}

/// Loads every scene (those named and the generated ones); failures are reported and recorded as skipped
/// unless none loads.
pub(crate) fn load_scenes(
    plan: &DatasetPlan,
    generated: &[PathBuf],
    observer: &dyn Observer,
) -> Result<(Vec<JobScene>, Vec<SkippedScene>)> {
    let overrides = ViewOverrides::square(plan.size);
    let mut loaded: Vec<JobScene> = Vec::new();
    let mut skipped = Vec::new();
    let mut files = collect_scene_files(&plan.scenes)?;
    files.extend(generated.iter().cloned());
    for path in files {
        match load_scene(&path, &overrides) {
            Ok(scene) => {
                for w in &scene.warnings {
                    observer.note(&format!("warning: {w}"));
                }
                let base = scene_name(&path);
                let mut name = base.clone();
                let mut k = 2;
                while loaded.iter().any(|s| s.name == name) {
                    name = format!("{base}-{k}");
                    k += 1;
                }
                loaded.push(JobScene { name, path, scene, split: None });
            }
            Err(e) => {
                observer.note(&format!("skipped {}: {e:#}", path.display()));
                skipped.push(SkippedScene { path: path.display().to_string(), reason: format!("{e:#}") });
            }
        }
    }
    if loaded.is_empty() {
        let reasons: Vec<String> = skipped.iter().map(|s| format!("  {}: {}", s.path, s.reason)).collect();
        bail!("no scene could be loaded:\n{}", reasons.join("\n"));
    }
    loaded.sort_by(|a, b| a.name.cmp(&b.name));
    for name in &plan.test_scenes {
        if !loaded.iter().any(|s| &s.name == name) {
            let names: Vec<&str> = loaded.iter().map(|s| s.name.as_str()).collect();
            bail!("--test-scenes names {name:?}, which is not a loaded scene; the scenes are {names:?}");
        }
    }
    let n = loaded.len();
    if !plan.test_scenes.is_empty() {
        for s in &mut loaded {
            s.split = Some(if plan.test_scenes.contains(&s.name) { Split::Test } else { Split::Train });
        }
    } else if n > 1 && !plan.split_views {
        // The thesis's proportion, 5 test scenes in 13, spread evenly over the sorted names.
        let tests = ((n * 5 + 6) / 13).max(1);
        for (i, s) in loaded.iter_mut().enumerate() {
            let test = (i + 1) * tests / n > i * tests / n;
            s.split = Some(if test { Split::Test } else { Split::Train });
        }
    }
    Ok((loaded, skipped))
}
