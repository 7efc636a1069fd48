//! Procedural scenes written to disk: hush-scene's seeded generator, its assets written atomically, and the
//! probe that rejects a scene whose camera sees nothing lit (the next attempt drawn from the seed is tried).

use std::collections::BTreeMap;
use std::path::Path;

use anyhow::{Context, Result, bail};
use hush_dataset::write_atomic;
use hush_scene::Scene;
use hush_scene::procedural::{self, GENERATOR_VERSION, GeneratedScene, GeneratorOptions, Ingredients, MaterialClass};
use hush_trace::Renderer;

use crate::probe::{MAX_ATTEMPTS, MIN_LIT_FRACTION, PROBE_SEED, lit_fraction};

/// A written procedural scene.
#[derive(Debug)]
pub struct Written {
    pub scene: GeneratedScene,
    /// The attempt kept (attempts after the first follow rejected scenes).
    pub attempt: u32,
    /// Fraction of the probe's pixels that received light (`None` without a probe).
    pub lit_fraction: Option<f64>,
}

/// Generates scene `index` of a run seeded with `seed` into `xml` (with its assets beside it): attempts are
/// drawn until one loads without a warning and, with a renderer, its probe finds at least half of the
/// pixels lit. The scene file is written last, so an existing one is always complete.
///
/// ```
/// use hush_scene::procedural::GeneratorOptions;
///
/// let xml = std::env::temp_dir().join(format!("hush-procedural-doc-{}/scene.xml", std::process::id()));
/// let options = GeneratorOptions { width: 32, height: 32, ..Default::default() };
/// // Without a renderer there is no probe: the first attempt that loads without a warning is kept.
/// let written = hush_pipeline::procedural::generate_into(&xml, 7, 0, &options, None).unwrap();
/// assert_eq!((written.attempt, written.lit_fraction), (0, None));
/// assert_eq!(hush_scene::Scene::load(&xml).unwrap().film.width, 32);
/// # std::fs::remove_dir_all(xml.parent().unwrap()).unwrap();
/// ```
pub fn generate_into(
    xml: &Path,
    seed: u64,
    index: u64,
    options: &GeneratorOptions,
    renderer: Option<&Renderer>,
) -> Result<Written> {
    first_lit(xml, options.ingredients, renderer, |attempt| {
        procedural::generate(procedural::scene_seed(seed, index, attempt as u64), options)
    })
    .with_context(|| format!("procedural scene {index} of seed {seed}"))
}

/// Writes the first of the scenes `draw(0)`, `draw(1)`, … that loads without a warning and (with a renderer)
/// whose probe finds at least half of its pixels lit; the assets of rejected attempts are removed.
fn first_lit(
    xml: &Path,
    ingredients: Ingredients,
    renderer: Option<&Renderer>,
    mut draw: impl FnMut(u32) -> GeneratedScene,
) -> Result<Written> {
    let dir = xml.parent().filter(|d| !d.as_os_str().is_empty()).unwrap_or(Path::new("."));
    std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
    let mut stale: Vec<String> = Vec::new();
    let mut best: Option<(f64, u32)> = None;
    for attempt in 0..MAX_ATTEMPTS {
        let g = draw(attempt);
        for a in &g.assets {
            let path = dir.join(&a.file);
            write_atomic(&path, |tmp| std::fs::write(tmp, &a.bytes))
                .with_context(|| format!("writing {}", path.display()))?;
        }
        let scene = Scene::from_mitsuba_str(&g.xml, xml)
            .with_context(|| format!("the generated scene (attempt {attempt}) does not load: a generator bug"))?;
        if !scene.warnings.is_empty() {
            bail!("the generated scene (attempt {attempt}) loads with warnings: {:?}", scene.warnings);
        }
        let lit = match renderer {
            None => None,
            Some(r) => Some(lit_fraction(r, &scene, PROBE_SEED ^ attempt as u64).with_context(|| {
                format!(
                    "probing the generated scene (ingredients {}): the path tracer cannot render it; \
                     generate with --ingredients default, or with --no-probe to write it anyway",
                    ingredients.describe()
                )
            })?),
        };
        if let Some(f) = lit.filter(|f| *f < MIN_LIT_FRACTION) {
            best = best.filter(|b| b.0 >= f).or(Some((f, attempt)));
            stale.extend(g.assets.iter().map(|a| a.file.clone()));
            continue;
        }
        write_atomic(xml, |tmp| std::fs::write(tmp, &g.xml)).with_context(|| format!("writing {}", xml.display()))?;
        remove_stale(dir, &stale, &g.assets);
        return Ok(Written { scene: g, attempt, lit_fraction: lit });
    }
    remove_stale(dir, &stale, &[]);
    let (f, attempt) = best.unwrap_or((0.0, 0));
    bail!(
        "no attempt had {:.0} % of its probe pixels lit in {MAX_ATTEMPTS} attempts (best: attempt {attempt}, \
         {:.0} %): try another seed",
        MIN_LIT_FRACTION * 100.0,
        f * 100.0
    )
}

/// Removes the assets of rejected attempts that the kept scene does not use.
fn remove_stale(dir: &Path, stale: &[String], kept: &[procedural::Asset]) {
    for file in stale.iter().filter(|f| !kept.iter().any(|a| &a.file == *f)) {
        let _ = std::fs::remove_file(dir.join(file));
    }
}

/// What a generated scene holds, as JSON (for `--summary` and the dataset manifest's checks).
pub fn summary_json(w: &Written, seed: u64, index: u64, options: &GeneratorOptions) -> serde_json::Value {
    let mut classes: BTreeMap<&str, usize> = MaterialClass::ALL.iter().map(|c| (c.name(), 0)).collect();
    for c in w.scene.material_classes() {
        *classes.entry(c.name()).or_default() += 1;
    }
    let mut bsdfs: BTreeMap<&str, usize> = BTreeMap::new();
    for s in w.scene.shapes.iter().filter(|s| !s.emitter) {
        *bsdfs.entry(s.bsdf).or_default() += 1;
    }
    serde_json::json!({
        "generator_version": GENERATOR_VERSION,
        "seed": seed,
        "index": index,
        "attempt": w.attempt,
        "scene_seed": w.scene.seed,
        "features": options.ingredients.describe(),
        "light_material": options.light_material.name(),
        "style": w.scene.style,
        "shapes": w.scene.shapes.len(),
        "materials": classes,
        "bsdfs": bsdfs,
        "lights": w.scene.lights.iter().map(|l| l.name()).collect::<Vec<_>>(),
        "probe_lit_fraction": w.lit_fraction,
    })
}

#[cfg(test)]
mod tests {
    use hush_scene::procedural::{self, GeneratorOptions};
    use hush_trace::{GpuContext, Renderer};

    use super::first_lit;
    use crate::probe::MIN_LIT_FRACTION;

    /// The XML without its area emitters (the generator writes each on one line, inside its shape).
    fn without_emitters(xml: &str) -> String {
        let mut out = xml.to_string();
        while let Some(i) = out.find("<emitter type=\"area\">") {
            let end = i + out[i..].find("</emitter>").expect("closed emitter") + "</emitter>".len();
            out.replace_range(i..end, "");
        }
        out
    }

    /// A scene whose camera sees nothing lit is never written: an attempt without lights is rejected by the
    /// probe and the next one is kept; when every attempt is unlit, nothing is written and the error says why.
    #[test]
    fn unlit_scenes_are_rejected() {
        let gpu = GpuContext::new().expect("a Vulkan adapter (lavapipe: apt-get install mesa-vulkan-drivers)");
        let renderer = Renderer::new(&gpu).unwrap();
        let options = GeneratorOptions { width: 32, height: 32, ..Default::default() };
        let lit = procedural::generate(1, &options);
        let mut dark = lit.clone();
        dark.xml = without_emitters(&lit.xml);
        assert!(!dark.xml.contains("<emitter") && dark.xml.len() < lit.xml.len());
        let dir = std::env::temp_dir().join(format!("hush-unlit-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);

        let xml = dir.join("a/scene.xml");
        let w =
            first_lit(&xml, options.ingredients, Some(&renderer), |a| if a == 0 { dark.clone() } else { lit.clone() })
                .unwrap();
        assert_eq!(w.attempt, 1);
        assert!(w.lit_fraction.unwrap() >= MIN_LIT_FRACTION);
        assert_eq!(std::fs::read_to_string(&xml).unwrap(), lit.xml);

        let xml = dir.join("b/scene.xml");
        let err = first_lit(&xml, options.ingredients, Some(&renderer), |_| dark.clone()).unwrap_err().to_string();
        assert!(err.contains("probe pixels lit") && err.contains("best: attempt 0, 0 %"), "{err}");
        assert!(std::fs::read_dir(dir.join("b")).map_or(true, |mut files| files.next().is_none()), "nothing written");
        let _ = std::fs::remove_dir_all(&dir);
    }
}
