//! Training runs in a folder: options resolved against the run being resumed and the defaults, the samples
//! prepared (and cached beside the dataset), hush-train's loop, and every epoch's logs and checkpoints
//! written so that a killed run resumes bit-identically.

mod blend;
mod folder;
mod options;
mod samples;

use std::ops::ControlFlow;

use anyhow::{Context, Result, bail};
use hush_dataset::{Manifest, Split};
use hush_train::{Start, TrainError, read_train_state, train};

pub use blend::blend;
pub use folder::{RunFolder, incompatibilities};
pub use options::{
    DEFAULT_DEVICE, DEFAULT_FEATURES, DEFAULT_FINETUNE_LR, DEFAULT_WIDTH, INIT_OIDN, RunConfig, TrainOptions, defaults,
    parse_aux, parse_features, parse_loss, read_init, resolve, resolve_with_init,
};

use crate::Observer;
use folder::{name_batch, save_epoch, write_file};
use samples::{Role, load_split};

/// Whether scene `name` is named by `pattern`: the same name, or a `prefix*` it starts with.
fn names(pattern: &str, name: &str) -> bool {
    match pattern.strip_suffix('*') {
        Some(prefix) => name.starts_with(prefix),
        None => pattern == name,
    }
}

/// The training split's views without those of the `validation` scenes and of the `exclude`d ones (names or
/// `prefix*` patterns), and the validation scenes' views: a name or pattern that no training scene answers
/// (an unknown name, or one of a test scene), or a scene both validated and excluded, is an error that lists
/// the training scenes.
fn split_scenes<'m>(
    manifest: &'m Manifest,
    validation: &[String],
    exclude: &[String],
    dataset: &std::path::Path,
) -> Result<(Vec<&'m hush_dataset::ViewRecord>, Vec<&'m hush_dataset::ViewRecord>)> {
    let mut scenes: Vec<&str> = manifest.split(Split::Train).map(|v| v.scene.as_str()).collect();
    scenes.dedup();
    let listed = || scenes.join(", ");
    for (flag, patterns) in [("validation", validation), ("exclude", exclude)] {
        if let Some(p) = patterns.iter().find(|p| !scenes.iter().any(|s| names(p, s))) {
            bail!("--{flag} {p}: no training scene of {} has that name; choose among {}", dataset.display(), listed());
        }
    }
    let named = |patterns: &[String], scene: &str| patterns.iter().any(|p| names(p, scene));
    if let Some(s) = scenes.iter().find(|s| named(validation, s) && named(exclude, s)) {
        bail!("--validation and --exclude both name {s}: a scene is either validated on or left out");
    }
    let (held, train): (Vec<_>, Vec<_>) =
        manifest.split(Split::Train).filter(|v| !named(exclude, &v.scene)).partition(|v| named(validation, &v.scene));
    Ok((train, held))
}

/// What a finished [`run`] did.
#[derive(Clone, Debug)]
pub struct TrainOutcome {
    pub folder: RunFolder,
    pub config: RunConfig,
    /// Optimizer steps taken by this call (a resumed run counts only its own).
    pub steps: usize,
    pub seconds: f64,
    /// The share of the time the loop waited for its batches.
    pub loader_share: f64,
    pub first_loss: f64,
    pub final_loss: f64,
    /// The epoch with the lowest test loss, and that loss.
    pub best: Option<(usize, f64)>,
}

/// Trains the run `options` describe (its `config` file read first), in its folder (`out`, or `resume`):
/// a new run, or the one there continued exactly where it stopped.
pub fn run(options: TrainOptions, observer: &dyn Observer) -> Result<TrainOutcome> {
    let args = options.with_config_file()?;
    let out = args.resume.as_ref().or(args.out.as_ref()).context("--out is required (or --resume RUN)")?.clone();
    if let (Some(r), Some(o)) = (&args.resume, &args.out)
        && r != o
    {
        bail!("--resume {} and --out {} name different folders; give one", r.display(), o.display());
    }
    let folder = RunFolder::new(&out);
    // One `hush train` writes a run folder at a time: a second is refused rather than interleaved. A new
    // folder is locked once it is made, after the checks that write nothing.
    let lock_run = || hush_io::lock_folder(&out.join(".hush-train.lock"), "`hush train`");
    let early_lock = if out.is_dir() { Some(lock_run()?) } else { None };
    // With --resume the run folder's config.json supplies every option not given.
    let stored = folder.read_config()?;
    if stored.is_none()
        && let Some(run) = &args.resume
    {
        bail!("--resume {}: no config.json there; is it a run folder of `hush train`?", run.display());
    }
    let base = if args.resume.is_some() { stored.as_ref() } else { None };
    let dataset = args
        .dataset
        .clone()
        .or(base.map(|c| c.dataset.clone()))
        .context("--dataset is required (or `dataset = ...` in --config)")?;
    let manifest = Manifest::load(&dataset)?;
    let spp = args.spp.clone().or(base.map(|c| c.spp.clone())).unwrap_or_default();
    let validation = args.validation.clone().or(base.map(|c| c.validation.clone())).unwrap_or_default();
    let exclude = args.exclude.clone().or(base.map(|c| c.exclude.clone())).unwrap_or_default();
    let (train_views, validation_views) = split_scenes(&manifest, &validation, &exclude, &dataset)?;
    let train_images = train_views
        .iter()
        .map(|v| v.noisy.iter().filter(|r| spp.is_empty() || spp.contains(&r.spp)).count())
        .sum::<usize>();
    if train_views.is_empty() {
        bail!(
            "{}: no training images are left once the validation scenes ({}) and the excluded ones ({}) are set \
             aside; validate on or leave out fewer scenes",
            dataset.display(),
            validation.join(", "),
            exclude.join(", ")
        );
    }
    if train_images == 0 {
        bail!("{} has no training images at spp {spp:?}", dataset.display());
    }
    let (cfg, given_init) = resolve_with_init(&args, base, train_images)?;

    let last = folder.last_checkpoint();
    let resume_bytes = match &stored {
        Some(stored) if last.is_file() => {
            let problems = incompatibilities(stored, &cfg);
            if !problems.is_empty() {
                bail!(
                    "{} holds a run that this command cannot continue ({}); choose another --out, or delete the \
                     folder to start over",
                    out.display(),
                    problems.join("; ")
                );
            }
            Some(crate::read_weight_file(&last).with_context(|| format!("reading {}", last.display()))?)
        }
        _ if args.resume.is_some() => bail!("--resume {}: it has no checkpoints/last.safetensors yet", out.display()),
        _ => None,
    };
    // A run that starts from trained weights uses those `--init` named (read once, by `resolve`); one
    // configured with them before and killed before its first checkpoint reads them again from the file
    // the configuration recorded, which must still be those weights.
    let init = match (&cfg.train.init, &resume_bytes) {
        (Some(_), None) if given_init.is_some() => given_init,
        (Some(record), None) => {
            let (weights, now) = read_init(std::path::Path::new(&record.source), Some(&cfg.train.features))?;
            if now.fnv1a != record.fnv1a {
                bail!(
                    "{} changed since the run in {} was configured with it (FNV-1a {} then, {} now); restore it, \
                     or delete the run folder to start over",
                    record.source,
                    out.display(),
                    record.fnv1a,
                    now.fnv1a
                );
            }
            Some(weights)
        }
        _ => None,
    };
    if let Some(record) = &cfg.train.init {
        observer.note(&format!(
            "starting from {} ({}) at a learning rate of {}",
            record.source, record.features, cfg.train.lr
        ));
    }
    // The samples after the cheap checks above, before anything is written.
    let loading = std::time::Instant::now();
    let (samples, names) = load_split(&cfg, &train_views, Role::Train, observer)?;
    let (test, _) = match validation_views.is_empty() {
        true => load_split(&cfg, &manifest.split(Split::Test).collect::<Vec<_>>(), Role::Test, observer)?,
        false => load_split(&cfg, &validation_views, Role::Validation, observer)?,
    };
    let measured = if validation_views.is_empty() { "testing" } else { "validating" };
    let load_seconds = loading.elapsed().as_secs_f64();
    let checkpoints = folder.checkpoints();
    std::fs::create_dir_all(&checkpoints).with_context(|| format!("creating {}", checkpoints.display()))?;
    let _lock = match early_lock {
        Some(lock) => lock,
        None => lock_run()?,
    };
    // Temporary files of writes that a killed run of this folder left behind (this run holds its lock).
    for dir in [out.as_path(), checkpoints.as_path()] {
        for tmp in hush_dataset::temp_files(dir)? {
            if tmp.file_name().and_then(|n| n.to_str()).and_then(hush_dataset::temp_target).is_some() {
                std::fs::remove_file(&tmp).with_context(|| format!("removing {}", tmp.display()))?;
            }
        }
    }
    write_file(&folder.config(), serde_json::to_string_pretty(&cfg)?.as_bytes())?;

    let (mut log, mut metrics) = (Vec::new(), Vec::new());
    let mut start_step = 0;
    if let Some(bytes) = &resume_bytes {
        let state = read_train_state(bytes)?.context("checkpoints/last.safetensors carries no training state")?;
        (log, metrics) = folder.read_logs(state.step, state.epoch);
        start_step = state.step;
        observer.note(&format!("resuming {} at step {} (epoch {})", out.display(), state.step, state.epoch));
    }

    let t = &cfg.train;
    let epochs = t.steps.div_ceil(t.epoch_steps);
    if !cfg.exclude.is_empty() {
        observer.note(&format!("leaving out the training scenes {}", cfg.exclude.join(", ")));
    }
    observer.note(&format!(
        "training on {} images, {measured} on {} (ready in {load_seconds:.2} s), with {} ({} auxiliary images): {} \
         steps = {epochs} epochs of {} steps",
        samples.len(),
        test.len(),
        t.features,
        cfg.aux,
        t.steps,
        t.epoch_steps
    ));
    observer.task("train", "steps", t.steps as u64, start_step as u64);
    let mut write_error = None;
    let device = crate::device(Some(&cfg.device))?;
    let start = match (&resume_bytes, &init) {
        (Some(bytes), _) => Start::Resume(bytes),
        (None, Some(weights)) => Start::Init(weights),
        (None, None) => Start::Fresh,
    };
    let result = train(t, &samples, &test, &device, start, |report| {
        let r = &report.row;
        let rate = (r.step - start_step) as f64 / r.seconds.max(1e-9);
        observer.progress(r.step as u64, &format!("epoch {} loss {:.4}, {rate:.2} steps/s", r.epoch, r.loss));
        log.push(*r);
        if let Some((row, bytes)) = report.epoch {
            metrics.push(row);
            if let Err(e) = save_epoch(&folder, &log, &metrics, &row, &bytes) {
                write_error = Some(e);
                return ControlFlow::Break(());
            }
        }
        ControlFlow::Continue(())
    });
    observer.task_done();
    if let Some(e) = write_error {
        return Err(e.context("saving a checkpoint; training stopped"));
    }
    let trained = match result {
        Ok(t) => t,
        Err(TrainError::Diverged { step, batch, cause, last_good }) => {
            let path = folder.last_good();
            write_file(&path, &last_good.weights)?;
            folder.write_loss_csv(&log)?;
            let batch = name_batch(&batch, &names);
            bail!(
                "training diverged at step {step} on the batch [{batch}]: {cause}. The weights from before that \
                 step are in {}, the last epoch's checkpoint in {}; try a lower --lr (now {}) or --clip-grad-norm",
                path.display(),
                last.display(),
                t.lr
            );
        }
        Err(e) => return Err(e.into()),
    };
    write_file(&folder.model(), &trained.weights)?;
    let steps = trained.log.len();
    // The initial weights' test loss is measured when a run starts from them; a resumed run keeps what its
    // first call measured.
    let initial_test_loss = trained.initial_test_loss.or_else(|| {
        let previous: serde_json::Value = serde_json::from_slice(&std::fs::read(folder.summary()).ok()?).ok()?;
        previous["initial_test_loss"].as_f64()
    });
    if let (Some(loss), Some(_)) = (trained.initial_test_loss, &cfg.train.init) {
        let split = if cfg.validation.is_empty() { "test" } else { "validation" };
        observer.note(&format!("the initial weights' {split} loss: {loss:.5}"));
    }
    let best = metrics.iter().rev().find(|r| r.best);
    let summary = serde_json::json!({
        "steps": steps,
        "seconds": trained.seconds,
        "steps_per_second": steps as f64 / trained.seconds.max(1e-9),
        "loader_share": trained.loader_seconds / trained.seconds.max(1e-9),
        "final_loss": log.last().map(|r| r.loss),
        "best": best.map(|r| serde_json::json!({"epoch": r.epoch, "test_loss": r.test_loss})),
        "initial_test_loss": initial_test_loss,
        "threads": std::env::var("RAYON_NUM_THREADS").ok(),
        "load_seconds": load_seconds,
        "best_measured_on": if cfg.validation.is_empty() { "test split".to_string() } else { format!("validation scenes {}", cfg.validation.join(", ")) },
    });
    write_file(&folder.summary(), serde_json::to_string_pretty(&summary)?.as_bytes())?;
    Ok(TrainOutcome {
        best: best.map(|b| (b.epoch, b.test_loss.unwrap_or(f64::NAN))),
        first_loss: log.first().map(|r| r.loss).unwrap_or(f64::NAN),
        final_loss: log.last().map(|r| r.loss).unwrap_or(f64::NAN),
        loader_share: trained.loader_seconds / trained.seconds.max(1e-9),
        seconds: trained.seconds,
        steps,
        config: cfg,
        folder,
    })
}
