//! Datasets: scenes → views → noisy images along an spp ladder, clean features and supersampled,
//! firefly-filtered references, in Open Image Denoise's file layout with a `manifest.json`. Resumable (a
//! rerun keeps every finished, valid image) and shardable (`shard i/n` renders a deterministic share of the
//! views and writes its own manifest part).

mod procedural;
mod scenes;
mod views;

use std::path::PathBuf;

use anyhow::{Context, Result, bail};
use hush_dataset::{DatasetConfig, Layout, Manifest, SceneEntry, Split, temp_files, temp_target};
use hush_scene::procedural::{GeneratorOptions, Ingredients};
use hush_trace::{PixelSampler, Renderer};

pub use scenes::{collect_scene_files, scene_name};
pub use views::{jitter_camera, render_seed};

use crate::Observer;

/// What to render: every option of `hush dataset`. [`DatasetPlan::new`] gives the defaults.
#[derive(Clone, Debug, PartialEq)]
pub struct DatasetPlan {
    /// Scene files (Mitsuba XML, glTF, OBJ) or folders: a folder contributes every `scene.xml` below it
    /// (without looking further inside that scene's folder) and every `.gltf`, `.glb` and `.obj` elsewhere.
    pub scenes: Vec<PathBuf>,
    /// Procedural scenes to generate (seeded by `seed`) into `out/scenes/proc_<seed>_<i>/`.
    pub procedural: u32,
    /// What the procedural generator may use.
    pub ingredients: Ingredients,
    /// A folder whose `*/models/` OBJ meshes the generator may place as furniture.
    pub borrow_meshes: Option<PathBuf>,
    /// The dataset folder.
    pub out: PathBuf,
    /// Views per scene: v000 is the scene's own camera, the others are generated around it.
    pub views: u32,
    /// With a single scene, or with `split_views`: how many of each scene's views (the last) are test views.
    pub test_views: u32,
    /// With several scenes: hold out each scene's last `test_views` views instead of whole scenes.
    pub split_views: bool,
    /// Scenes (by name) whose views form the test split; empty: 5 in 13 of the scenes, spread over the names.
    pub test_scenes: Vec<String>,
    /// Noisy images per view, at these samples per pixel.
    pub spp: Vec<u32>,
    /// Samples per (sub)pixel of the reference (rendered with an independent seed).
    pub ref_spp: u32,
    /// Samples per (sub)pixel of the test split's references (`None`: `ref_spp`).
    pub test_ref_spp: Option<u32>,
    /// The reference is rendered at this many times the width and height, then box-downsampled (a film
    /// with a tent or Gaussian filter: at 1× with this factor² times the samples, which keeps its filter).
    pub ref_supersample: u32,
    /// A reference pixel brighter than this many times its brightest neighbour is clamped; 0 is off.
    pub firefly_factor: f32,
    /// Measure each reference's relMSE against an independent render at this spp (0: no check).
    pub ref_check_spp: u32,
    /// Samples per pixel of the clean auxiliary features.
    pub aux_spp: u32,
    /// Square image size in pixels (`None`: the scene files' sizes).
    pub size: Option<u32>,
    /// Seed of the generated views and of every render.
    pub seed: u64,
    /// Render only shard `i` of `n`.
    pub shard: Option<(u32, u32)>,
    /// Where each pixel's samples lie; a resume renders again what another sampler rendered.
    pub pixel_sampler: PixelSampler,
    /// Renders of each test view's spp ladder (at least 1): the noisy render and `test_repeats - 1` repeats
    /// with other seeds, which an evaluation averages over.
    pub test_repeats: u32,
}

/// How a manifest records `sampler`: by name, except independent positions (`None`), which every render
/// from before the sampler was recorded has.
pub(crate) fn sampler_record(sampler: PixelSampler) -> Option<String> {
    match sampler {
        PixelSampler::Independent => None,
        other => Some(other.name().to_string()),
    }
}

impl DatasetPlan {
    pub const DEFAULT_VIEWS: u32 = 4;
    pub const DEFAULT_TEST_VIEWS: u32 = 1;
    pub const DEFAULT_SPP: [u32; 9] = [1, 2, 4, 8, 16, 32, 64, 128, 256];
    pub const DEFAULT_REF_SPP: u32 = 1024;
    pub const DEFAULT_REF_SUPERSAMPLE: u32 = 2;
    pub const DEFAULT_AUX_SPP: u32 = 64;
    /// The square size of procedural scenes when no `size` is given.
    pub const DEFAULT_PROCEDURAL_SIZE: u32 = 256;

    /// A plan with every default, rendering `scenes` into `out`.
    pub fn new(out: impl Into<PathBuf>, scenes: Vec<PathBuf>) -> Self {
        DatasetPlan {
            scenes,
            procedural: 0,
            ingredients: Ingredients::KERNEL,
            borrow_meshes: None,
            out: out.into(),
            views: Self::DEFAULT_VIEWS,
            test_views: Self::DEFAULT_TEST_VIEWS,
            split_views: false,
            test_scenes: Vec::new(),
            spp: Self::DEFAULT_SPP.to_vec(),
            ref_spp: Self::DEFAULT_REF_SPP,
            test_ref_spp: None,
            ref_supersample: Self::DEFAULT_REF_SUPERSAMPLE,
            firefly_factor: hush_dataset::DEFAULT_FIREFLY_FACTOR,
            ref_check_spp: 0,
            aux_spp: Self::DEFAULT_AUX_SPP,
            size: None,
            seed: 0,
            shard: None,
            pixel_sampler: PixelSampler::default(),
            test_repeats: 1,
        }
    }

    /// The generator's options for scenes of `width` × `height`.
    pub fn generator_options(&self, width: u32, height: u32) -> GeneratorOptions {
        GeneratorOptions::rooms(self.ingredients, width, height, self.borrow_meshes.clone())
    }

    /// The spp ladder, sorted, without repeats.
    pub fn ladder(&self) -> Vec<u32> {
        let mut spps = self.spp.clone();
        spps.sort_unstable();
        spps.dedup();
        spps
    }

    /// Checks the options against each other.
    pub fn validate(&self) -> Result<()> {
        if self.scenes.is_empty() && self.procedural == 0 {
            bail!("no scenes: name scene files or folders, or generate --procedural N");
        }
        if self.spp.is_empty()
            || self.spp.contains(&0)
            || self.ref_spp == 0
            || self.test_ref_spp == Some(0)
            || self.aux_spp == 0
        {
            bail!("every spp (--spp, --ref-spp, --test-ref-spp, --aux-spp) must be at least 1");
        }
        if self.test_repeats == 0 {
            bail!("--test-repeats must be at least 1 (the noisy render itself)");
        }
        if self.views == 0 || self.test_views > self.views {
            bail!("--views must be at least 1 and --test-views at most --views");
        }
        if self.ref_supersample == 0 || !(self.firefly_factor == 0.0 || self.firefly_factor >= 1.0) {
            bail!("--ref-supersample must be at least 1 and --firefly-factor 0 (off) or at least 1");
        }
        if let Some((i, n)) = self.shard
            && (n == 0 || i >= n)
        {
            bail!("shard {i}/{n}: a shard is i/n with 0 <= i < n");
        }
        Ok(())
    }

    /// Samples per (sub)pixel of the references of `split`.
    pub fn ref_spp_of(&self, split: Split) -> u32 {
        match split {
            Split::Train => self.ref_spp,
            Split::Test => self.test_ref_spp.unwrap_or(self.ref_spp),
        }
    }

    /// Images rendered or kept per view of `split`: the ladder (and its repeats in a test view), the features,
    /// the reference and its check.
    fn images_per_view(&self, split: Split) -> u64 {
        let ladders = if split == Split::Test { u64::from(self.test_repeats.max(1)) } else { 1 };
        self.ladder().len() as u64 * ladders + 2 + u64::from(self.ref_check_spp > 0)
    }

    /// The split of view `v` of a scene whose split is `scene_split` (`None`: its last `test_views` views test).
    fn split_of(&self, scene_split: Option<Split>, v: u32) -> Split {
        scene_split.unwrap_or(if v >= self.views - self.test_views { Split::Test } else { Split::Train })
    }
}

/// What [`build`] did.
#[derive(Clone, Debug, PartialEq)]
pub struct BuildSummary {
    /// Views of this shard (all views without shards).
    pub views: usize,
    /// Images rendered by this run (the others were kept).
    pub rendered: usize,
    pub seconds: f64,
    /// The manifest this run wrote: `manifest.json`, or the shard's part.
    pub manifest: PathBuf,
}

/// Renders the dataset `plan` describes with `renderer`, keeping every image a previous run finished.
pub fn build(plan: &DatasetPlan, renderer: &Renderer, observer: &dyn Observer) -> Result<BuildSummary> {
    plan.validate()?;
    let out = &plan.out;
    std::fs::create_dir_all(out).with_context(|| format!("creating {}", out.display()))?;
    // One run writes a folder (or a shard of it) at a time; a second is refused rather than interleaved.
    let lock = match plan.shard {
        Some((i, n)) => out.join(format!(".hush-dataset-shard-{i}-of-{n}.lock")),
        None => out.join(".hush-dataset.lock"),
    };
    let _lock = hush_io::lock_folder(&lock, "`hush dataset`")?;
    let layout = Layout::new(out);
    let procedural = match plan.procedural {
        0 => None,
        _ => Some(procedural::generate_procedural(plan, out, renderer, observer)?),
    };
    let generated: Vec<PathBuf> = procedural.iter().flat_map(|p| p.scenes.iter().map(|s| out.join(&s.path))).collect();
    let (scenes, skipped) = scenes::load_scenes(plan, &generated, observer)?;

    // The jobs, one per (scene, view), dealt round-robin to the shards.
    let (shard, shards) = plan.shard.unwrap_or((0, 1));
    let jobs: Vec<(usize, u32)> = scenes
        .iter()
        .enumerate()
        .flat_map(|(s, _)| (0..plan.views).map(move |v| (s, v)))
        .enumerate()
        .filter(|(j, _)| *j as u32 % shards == shard)
        .map(|(_, job)| job)
        .collect();

    let config = DatasetConfig {
        seed: plan.seed,
        views: plan.views,
        spp: plan.ladder(),
        aux_spp: plan.aux_spp,
        ref_spp: plan.ref_spp,
        test_ref_spp: plan.test_ref_spp,
        ref_supersample: plan.ref_supersample,
        firefly_factor: plan.firefly_factor,
        ref_check_spp: plan.ref_check_spp,
        size: plan.size,
        scenes: scenes
            .iter()
            .map(|s| SceneEntry {
                name: s.name.clone(),
                path: s.path.display().to_string(),
                split: s.split,
                triangles: s.scene.triangle_count(),
            })
            .collect(),
        skipped,
        procedural,
        pixel_sampler: sampler_record(plan.pixel_sampler),
        test_repeats: (plan.test_repeats > 1).then_some(plan.test_repeats),
    };
    let known = Manifest::load_or_default(out)?;
    let (mut own, own_path) = match plan.shard {
        None => (known.clone(), layout.manifest_path()),
        Some((i, n)) => {
            let path = layout.shard_manifest_path(i, n);
            (if path.exists() { Manifest::load_file(&path)? } else { Manifest::default() }, path)
        }
    };
    own.config = Some(config);

    // Temporary files of writes a killed run of these jobs left behind.
    let own_name = own_path.file_name().map(|n| n.to_string_lossy().into_owned()).unwrap_or_default();
    let prefixes: Vec<String> = jobs.iter().map(|&(s, v)| format!("{}_v{v:03}_", scenes[s].name)).collect();
    let repeats = out.join(Layout::REPEATS);
    let in_repeats = if repeats.is_dir() { temp_files(&repeats)? } else { Vec::new() };
    for tmp in temp_files(out)?.into_iter().chain(in_repeats) {
        let file = tmp.file_name().map(|n| n.to_string_lossy().into_owned()).unwrap_or_default();
        if let Some(target) = temp_target(&file)
            && (target == own_name || prefixes.iter().any(|p| target.starts_with(p.as_str())))
        {
            std::fs::remove_file(&tmp).with_context(|| format!("removing {}", tmp.display()))?;
        }
    }

    let images = jobs.iter().map(|&(s, v)| plan.images_per_view(plan.split_of(scenes[s].split, v))).sum();
    observer.task("dataset", "images", images, 0);
    let mut ctx =
        views::Ctx { plan, layout, renderer, observer, own, own_path, rendered: 0, done: 0, message: String::new() };
    let start = std::time::Instant::now();
    let result = std::thread::scope(|threads| {
        // While a scene renders, the next scene's kernel compiles and its data (BVH, buffers) is built on another
        // thread (the driver compiles on one core; on lavapipe that was about a tenth of a dataset's time with
        // the other core idle). Only for a
        // scene this manifest has no view of yet: one with recorded views may need no render at all. An error
        // there is left to the scene's own render to report.
        let mut compiling: Option<(usize, std::thread::ScopedJoinHandle<'_, ()>)> = None;
        let result = jobs.iter().enumerate().try_for_each(|(k, &(s, v))| {
            if let Some((_, handle)) = compiling.take_if(|(next, _)| *next == s) {
                let _ = handle.join();
            }
            if compiling.is_none()
                && (k == 0 || jobs[k - 1].0 != s)
                && let Some(&(next, _)) = jobs[k..].iter().find(|&&(t, _)| t != s)
                && known.progress(&scenes[next].name, "v000").is_none()
            {
                let (renderer, scene) = (ctx.renderer, &scenes[next].scene);
                compiling = Some((next, threads.spawn(move || drop(renderer.prepare(scene)))));
            }
            let job = &scenes[s];
            ctx.message = format!("view {}/{}", k + 1, jobs.len());
            ctx.observer.progress(ctx.done, &ctx.message);
            let split = plan.split_of(job.split, v);
            views::render_view(&mut ctx, &known, job, v, split)
                .with_context(|| format!("{} v{v:03} (scene {})", job.name, job.path.display()))
        });
        // A compile still running after a failed view is waited for here, its outcome (even a panic) set
        // aside, so that the view's own error is what the run reports.
        if let Some((_, handle)) = compiling.take() {
            let _ = handle.join();
        }
        result
    });
    observer.task_done();
    result?;
    // Finish: make sure the manifest carries this run's settings even when nothing needed rendering.
    ctx.own.save_file(&ctx.own_path)?;
    Ok(BuildSummary {
        views: jobs.len(),
        rendered: ctx.rendered,
        seconds: start.elapsed().as_secs_f64(),
        manifest: ctx.own_path,
    })
}

#[cfg(test)]
mod tests {
    use std::path::Path;

    use hush_trace::{GpuContext, Renderer};

    use super::{DatasetPlan, build};
    use crate::observer::Quiet;

    /// The next scene's kernel, compiled while the current scene renders, is the one its renders then use:
    /// two scenes of different kernels (the box's triangles, the analytic test scene's shapes) cost two
    /// compilations, not three, and two uploads of scene data; both scenes' views are written.
    #[test]
    fn each_scene_kernel_compiles_once_with_the_next_one_prepared() {
        let gpu = GpuContext::new().expect("a Vulkan adapter (lavapipe: apt-get install mesa-vulkan-drivers)");
        let renderer = Renderer::new(&gpu).unwrap();
        let data = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../data");
        let scenes = vec![data.join("scenes/cbox/scene.xml"), data.join("tests/mitsuba/analytic/scene.xml")];
        let dir = std::env::temp_dir().join(format!("hush-prepare-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        let plan = DatasetPlan {
            views: 1,
            test_views: 0,
            spp: vec![1, 2],
            ref_spp: 2,
            ref_supersample: 1,
            aux_spp: 1,
            size: Some(16),
            ..DatasetPlan::new(&dir, scenes)
        };
        let summary = build(&plan, &renderer, &Quiet).unwrap();
        assert_eq!(summary.views, 2);
        assert_eq!(renderer.kernels_compiled(), 2, "a prepared kernel was compiled again by its scene's renders");
        // Its noisy images, features and reference (other spp, depth limits, film sizes) share one upload.
        assert_eq!(renderer.scenes_uploaded(), 2, "a scene was flattened and uploaded again by one of its renders");
        let _ = std::fs::remove_dir_all(&dir);
    }
}
