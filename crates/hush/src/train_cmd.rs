use std::ops::ControlFlow;
use std::path::Path;

use anyhow::{Context, Result, bail};
use hush_dataset::{Image, Manifest, Split, load_view, write_atomic};
use hush_net::transfer::Transfer;
use hush_net::{Features, Loss, UNetConfig, UNetKind};
use hush_train::{LossRow, Resume, TrainConfig, TrainError, TrainSample, train};
use indicatif::{ProgressBar, ProgressStyle};

use crate::cli::TrainArgs;
use crate::denoiser::{aux_of, device};

fn parse_loss(s: &str) -> Result<Loss> {
    Ok(match s {
        "l1" | "mae" => Loss::L1,
        "l2" | "mse" => Loss::Mse,
        "ssim" => Loss::Ssim,
        "msssim" | "ms-ssim" => Loss::MsSsim,
        "mix" | "l1_msssim" => Loss::Mix,
        _ => bail!("unknown loss '{s}': use l1, mse, ssim, msssim or mix"),
    })
}

fn write_file(path: &Path, bytes: &[u8]) -> Result<()> {
    write_atomic(path, |tmp| std::fs::write(tmp, bytes)).with_context(|| format!("writing {}", path.display()))
}

fn loss_csv(log: &[LossRow]) -> String {
    let mut csv = String::from("step,epoch,loss,seconds\n");
    for r in log {
        csv.push_str(&format!("{},{},{},{:.3}\n", r.step, r.epoch, r.loss, r.seconds));
    }
    csv
}

pub fn run(args: TrainArgs) -> Result<()> {
    let features = Features::parse(&args.features)?;
    let loss = parse_loss(&args.loss)?;
    let manifest = Manifest::load(&args.dataset)?;
    let views: Vec<_> = manifest.split(Split::Train).collect();
    if views.is_empty() {
        bail!("{} has no training views", args.dataset.display());
    }

    let mut samples = Vec::new();
    for view in &views {
        for record in view.noisy.iter().filter(|r| args.spp.is_empty() || args.spp.contains(&r.spp)) {
            let images = load_view(&args.dataset, view, record.spp)?;
            let aux: Vec<&Image> = features.aux.iter().map(|&f| aux_of(&images, f)).collect();
            if images.color.width.min(images.color.height) < args.crop {
                bail!(
                    "{}_{} is {}×{}, smaller than --crop {}: use a smaller crop or a larger dataset --size",
                    view.scene,
                    view.view,
                    images.color.width,
                    images.color.height,
                    args.crop
                );
            }
            samples.push(TrainSample::from_linear(&features, Transfer::Pu, &images.color, &aux, &images.reference)?);
        }
    }
    if samples.is_empty() {
        bail!("no training images at spp {:?} in {}", args.spp, args.dataset.display());
    }

    let cfg = TrainConfig {
        net: UNetConfig {
            kind: UNetKind::Unet,
            in_channels: features.in_channels(),
            out_channels: 3,
            width: args.width,
        },
        features,
        transfer: Transfer::Pu,
        loss,
        lr: args.lr,
        steps: args.steps,
        batch: args.batch,
        crop: args.crop,
        seed: args.seed,
        checkpoint_every: args.checkpoint_every,
        augment: true,
    };
    cfg.validate()?;
    let checkpoints = args.out.join("checkpoints");
    std::fs::create_dir_all(&checkpoints).with_context(|| format!("creating {}", checkpoints.display()))?;
    let config_path = args.out.join("config.json");
    let config_json = serde_json::to_string_pretty(&cfg)?;

    // Resume from the latest checkpoint of the same configuration.
    let latest = checkpoints.join("latest.safetensors");
    let mut resume_from = None;
    if config_path.is_file() && latest.is_file() {
        let stored = std::fs::read_to_string(&config_path)?;
        if stored != config_json {
            bail!(
                "{} holds a run with another configuration: choose another --out, or delete the folder to start over",
                args.out.display()
            );
        }
        let step: usize = std::fs::read_to_string(checkpoints.join("latest.step"))
            .context("reading checkpoints/latest.step")?
            .trim()
            .parse()
            .context("checkpoints/latest.step is not a step number")?;
        resume_from = Some((std::fs::read(&latest)?, step));
    }
    write_file(&config_path, config_json.as_bytes())?;
    let mut log: Vec<LossRow> = match &resume_from {
        Some(_) => parse_log(&std::fs::read_to_string(args.out.join("loss.csv")).unwrap_or_default()),
        None => Vec::new(),
    };
    if let Some((_, step)) = &resume_from {
        log.retain(|r| r.step <= *step);
        eprintln!("resuming at step {step} from {} (Adam's moment estimates restart from zero)", latest.display());
    }

    eprintln!("training on {} images ({} views) with {}", samples.len(), views.len(), cfg.features);
    let bar = ProgressBar::new(cfg.steps as u64);
    bar.set_style(
        ProgressStyle::with_template("train [{bar:30}] {pos}/{len} steps {msg} eta {eta}")
            .expect("valid template")
            .progress_chars("=> "),
    );
    let resume = resume_from.as_ref().map(|(w, step)| Resume { weights: w, step: *step });
    bar.set_position(resume.as_ref().map_or(0, |r| r.step as u64));
    let mut write_error = None;
    let result = train(&cfg, &samples, &device()?, resume, |report| {
        let r = &report.row;
        bar.set_position(r.step as u64);
        bar.set_message(format!("loss {:.4}, {:.2} steps/s", r.loss, r.step as f64 / r.seconds.max(1e-9)));
        log.push(r.clone());
        if let Some(bytes) = report.checkpoint {
            let saved = write_file(&checkpoints.join(format!("step_{:06}.safetensors", r.step)), &bytes)
                .and_then(|_| write_file(&latest, &bytes))
                .and_then(|_| write_file(&checkpoints.join("latest.step"), r.step.to_string().as_bytes()))
                .and_then(|_| write_file(&args.out.join("loss.csv"), loss_csv(&log).as_bytes()));
            if let Err(e) = saved {
                write_error = Some(e);
                return ControlFlow::Break(());
            }
        }
        ControlFlow::Continue(())
    });
    bar.finish_and_clear();
    if let Some(e) = write_error {
        return Err(e.context("saving a checkpoint; training stopped"));
    }
    let trained = match result {
        Ok(t) => t,
        Err(TrainError::Diverged { step, cause, last_good }) => {
            let path = args.out.join("last_good.safetensors");
            write_file(&path, &last_good.weights)?;
            write_file(&args.out.join("loss.csv"), loss_csv(&log).as_bytes())?;
            bail!(
                "training diverged at step {step}: {cause}. The weights from before it are in {}; \
                 try a lower --lr (now {})",
                path.display(),
                cfg.lr
            );
        }
        Err(e) => return Err(e.into()),
    };
    let model = args.out.join("model.safetensors");
    write_file(&model, &trained.weights)?;
    write_file(&args.out.join("loss.csv"), loss_csv(&log).as_bytes())?;
    let first = log.first().map(|r| r.loss).unwrap_or(f64::NAN);
    let last = log.last().map(|r| r.loss).unwrap_or(f64::NAN);
    eprintln!("trained {} steps: loss {first:.4} → {last:.4}; model {}", cfg.steps, model.display());
    Ok(())
}

fn parse_log(csv: &str) -> Vec<LossRow> {
    csv.lines()
        .skip(1)
        .filter_map(|l| {
            let f: Vec<&str> = l.split(',').collect();
            Some(LossRow {
                step: f.first()?.parse().ok()?,
                epoch: f.get(1)?.parse().ok()?,
                loss: f.get(2)?.parse().ok()?,
                seconds: f.get(3)?.parse().ok()?,
            })
        })
        .collect()
}
