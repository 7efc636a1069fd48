//! The procedural scenes of a dataset (`--procedural N`): generated once into the dataset folder, kept on a
//! rerun with the same settings.

use std::path::Path;

use anyhow::{Context, Result};
use hush_dataset::{ProceduralRecord, ProceduralScene};
use hush_trace::Renderer;

use super::DatasetPlan;
use crate::Observer;
use crate::procedural::{generate_into, summary_json};

/// The procedural scenes of a run: scene `i` lives in `scenes/proc_<seed>_<i>/scene.xml` beside its assets and
/// a `scene.json` that says how it was generated; a scene whose `scene.json` matches the run's settings is kept,
/// any other is generated (and probed) again.
pub(crate) fn generate_procedural(
    plan: &DatasetPlan,
    out: &Path,
    renderer: &Renderer,
    observer: &dyn Observer,
) -> Result<ProceduralRecord> {
    let size = plan.size.unwrap_or(DatasetPlan::DEFAULT_PROCEDURAL_SIZE);
    let options = plan.generator_options(size, size);
    let mut scenes = Vec::new();
    let (mut kept, start) = (0, std::time::Instant::now());
    for index in 0..plan.procedural as u64 {
        let rel = format!("scenes/proc_{}_{index}/scene.xml", plan.seed);
        let xml = out.join(&rel);
        let json = xml.with_file_name("scene.json");
        let want = serde_json::json!({
            "generator_version": hush_scene::procedural::GENERATOR_VERSION,
            "seed": plan.seed,
            "index": index,
            "features": options.ingredients.describe(),
            "width": size,
            "height": size,
            "borrow_meshes": options.borrow_meshes,
        });
        let previous = std::fs::read_to_string(&json)
            .ok()
            .and_then(|t| serde_json::from_str::<serde_json::Value>(&t).ok())
            .filter(|p| xml.is_file() && want.as_object().is_some_and(|w| w.iter().all(|(k, v)| &p[k] == v)));
        let summary = match previous {
            Some(p) => {
                kept += 1;
                p
            }
            None => {
                let written = generate_into(&xml, plan.seed, index, &options, Some(renderer))?;
                let mut s = summary_json(&written, plan.seed, index, &options);
                if let (Some(s), Some(w)) = (s.as_object_mut(), want.as_object()) {
                    s.extend(w.clone());
                }
                hush_dataset::write_atomic(&json, |tmp| std::fs::write(tmp, serde_json::to_string_pretty(&s)?))
                    .with_context(|| format!("writing {}", json.display()))?;
                s
            }
        };
        scenes.push(ProceduralScene {
            index,
            path: rel,
            scene_seed: summary["scene_seed"].as_u64().context("scene.json without scene_seed")?,
            attempt: summary["attempt"].as_u64().unwrap_or(0) as u32,
            style: summary["style"].as_str().unwrap_or_default().to_string(),
            probe_lit_fraction: summary["probe_lit_fraction"].as_f64(),
        });
    }
    observer.note(&format!(
        "procedural: {} scenes ({} generated, {kept} kept) in {:.1} s → {}",
        plan.procedural,
        plan.procedural as usize - kept,
        start.elapsed().as_secs_f64(),
        out.join("scenes").display()
    ));
    Ok(ProceduralRecord {
        count: plan.procedural,
        seed: plan.seed,
        generator_version: hush_scene::procedural::GENERATOR_VERSION,
        features: options.ingredients.describe(),
        scenes,
    })
}
