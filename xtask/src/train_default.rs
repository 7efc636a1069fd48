//! `cargo xtask train-default`: hush's shipped models, retrained by one resumable command.
//!
//! Renders a dataset of the bundled scenes and procedural ones (with the scenes held out that no model
//! trains on), fine-tunes OIDN's official weights on it for each shipped feature set (color + albedo +
//! normal, and color only), evaluates each against official OIDN on the held-out scenes, and writes the
//! model with its card into `data/models/`: `<name>.safetensors`, `<name>.tza` (OIDN's format, for OIDN's own
//! runtime) and `<name>.md` (the commands, the dataset's manifest hash, the held-out numbers).
//!
//! Every stage resumes: `hush dataset` keeps what is rendered, `hush train` continues its run folder from
//! the last checkpoint, and a model already in `data/models/` with the same recipe is not trained again.
//! Commit `data/models/` as soon as a model is written; the rest is under `target/train-default/`.

use std::path::Path;
use std::process::Command;

use crate::args::{Flags, Takes};
use crate::util::{Result, build_hush, ensure_vulkan, load_average, project_root, read_json, spawn, target_dir};

/// The bundled scenes; procedural ones are added by `--procedural`.
const SCENES: [&str; 2] = ["data/scenes/cbox/scene.xml", "data/scenes/veach-mis/scene.xml"];
/// Procedural scenes generated from seed 1 (`proc-1-0`, ...).
const PROCEDURAL: u32 = 6;
/// The scenes no model trains on: a different kind each (glossy plates under four lights; two generated
/// rooms of other layouts, materials and lights than the training rooms).
pub const TEST_SCENES: [&str; 3] = ["veach-mis", "proc-1-4", "proc-1-5"];
/// The dataset: 3 views per scene at 96², the spp ladder, references of 2×2 × 512 paths per pixel.
const DATASET_ARGS: [&str; 14] = [
    "--views",
    "3",
    "--size",
    "96",
    "--spp",
    "1,4,16,64,256",
    "--ref-spp",
    "512",
    "--aux-spp",
    "32",
    "--seed",
    "1",
    "--ingredients",
    "default",
];
/// The evaluated spp (the issue's ladder).
const EVAL_SPP: &str = "4,16,64,256";
/// Fine-tuning steps per model.
const STEPS: u32 = 2000;

/// One shipped model.
struct Shipped {
    /// File stem in `data/models/`.
    name: &'static str,
    /// `hush train --features`.
    features: &'static str,
    /// What the card says the model takes.
    takes: &'static str,
    /// The official OIDN weights of the same features, which `hush eval` shows beside it.
    oidn: &'static str,
}

const MODELS: [Shipped; 2] = [
    Shipped {
        name: "hush_alb_nrm",
        features: "color,albedo,normal",
        takes: "color + albedo + normal",
        oidn: "rt_hdr_alb_nrm",
    },
    Shipped { name: "hush_color", features: "color", takes: "color only", oidn: "rt_hdr" },
];

pub fn run(args: &[String]) -> Result<()> {
    let known = [("--release", Takes::Nothing), ("--steps", Takes::Number), ("--only", Takes::Value)];
    let usage = "cargo xtask train-default [--release] [--steps N] [--only hush_alb_nrm|hush_color]";
    let flags = Flags::parse(args, &known, 0, usage)?;
    let steps = flags.number("--steps", STEPS)?;
    let only = flags.value("--only");
    if let Some(name) = only
        && !MODELS.iter().any(|m| m.name == name)
    {
        return Err(format!("--only {name}: the shipped models are hush_alb_nrm and hush_color"));
    }
    ensure_vulkan()?;
    let hush = build_hush(flags.has("--release"))?;
    let root = project_root();
    let dir = target_dir().join("train-default");
    let dataset = dir.join("dataset");
    let models_dir = root.join("data/models");
    std::fs::create_dir_all(&models_dir).map_err(|e| format!("creating {}: {e}", models_dir.display()))?;

    let start = std::time::Instant::now();
    spawn(&mut dataset_command(&hush, &root, &dataset))?;
    let dataset_seconds = start.elapsed().as_secs_f64();
    let manifest = std::fs::read(dataset.join("manifest.json"))
        .map_err(|e| format!("reading {}: {e}", dataset.join("manifest.json").display()))?;
    let manifest_hash = format!("{:016x}", hush_hash::fnv1a(&manifest));

    for model in MODELS.iter().filter(|m| only.is_none_or(|o| o == m.name)) {
        let run_dir = dir.join(model.name);
        let (mut train, shown) = train_command(&hush, &dataset, &run_dir, model, steps);
        let started = std::time::Instant::now();
        let load_before = load_average();
        spawn(&mut train)?;
        let train_seconds = started.elapsed().as_secs_f64();
        let trained = run_dir.join("model.safetensors");
        let eval_dir = dir.join(format!("eval-{}", model.name));
        spawn(
            Command::new(&hush)
                .arg("eval")
                .arg("--dataset")
                .arg(&dataset)
                .arg("--model")
                .arg(&trained)
                .args(["--spp", EVAL_SPP, "--timing-runs", "1", "--out"])
                .arg(&eval_dir),
        )?;
        let rows = held_out_rows(&eval_dir, &format!("{}/model", model.name), &format!("oidn-2.5.1 {}", model.oidn))?;
        let card = model_card(model, &shown, &manifest_hash, &rows, train_seconds, &load_before, dataset_seconds);
        let target = models_dir.join(format!("{}.safetensors", model.name));
        copy(&trained, &target)?;
        spawn(
            Command::new(&hush)
                .arg("export")
                .arg("--model")
                .arg(&target)
                .arg("--out")
                .arg(models_dir.join(format!("{}.tza", model.name))),
        )?;
        crate::util::write_atomic(&models_dir.join(format!("{}.md", model.name)), &card)?;
        println!("{}: {} and its card written; commit data/models/", model.name, target.display());
        println!("{}", summary_line(&rows));
    }
    Ok(())
}

/// `hush dataset` of the shipped models' scenes.
fn dataset_command(hush: &Path, root: &Path, dataset: &Path) -> Command {
    let mut cmd = Command::new(hush);
    cmd.arg("dataset").args(SCENES.iter().map(|s| root.join(s))).arg("--out").arg(dataset);
    cmd.args(["--procedural", &PROCEDURAL.to_string(), "--test-scenes", &TEST_SCENES.join(",")]);
    cmd.args(DATASET_ARGS);
    cmd
}

/// `hush train` of one shipped model, and the command as the card shows it.
fn train_command(hush: &Path, dataset: &Path, run: &Path, model: &Shipped, steps: u32) -> (Command, String) {
    let args: Vec<String> = [
        "train",
        "--init",
        "oidn",
        "--features",
        model.features,
        "--aux",
        "noisy",
        "--batch",
        "4",
        "--crop",
        "64",
        "--loss",
        "mix",
        "--lr",
        "1e-4",
        "--eval-every",
        "25",
        "--seed",
        "1",
    ]
    .iter()
    .map(|s| s.to_string())
    .chain(["--steps".to_string(), steps.to_string()])
    .collect();
    let mut cmd = Command::new(hush);
    cmd.args(&args).arg("--dataset").arg(dataset).arg("--out").arg(run);
    let shown = format!(
        "hush {} --dataset target/train-default/dataset --out target/train-default/{}",
        args.join(" "),
        model.name
    );
    (cmd, shown)
}

/// One held-out case: a view at one spp, with the PSNR of the noisy input, official OIDN and the model.
struct Case {
    view: String,
    spp: u64,
    noisy: f64,
    oidn: f64,
    model: f64,
}

/// The held-out cases of an evaluation, from its `summary.json`.
fn held_out_rows(eval_dir: &Path, model_method: &str, oidn_method: &str) -> Result<Vec<Case>> {
    let path = eval_dir.join("summary.json");
    let summary = read_json(&path)?;
    let rows = summary["rows"].as_array().ok_or_else(|| format!("{} has no rows", path.display()))?;
    let psnr = |view: &str, spp: u64, pick: &dyn Fn(&str) -> bool| {
        rows.iter()
            .find(|r| r["view"] == view && r["spp"].as_u64() == Some(spp) && r["method"].as_str().is_some_and(pick))
            .and_then(|r| r["psnr"].as_f64())
    };
    let mut cases = Vec::new();
    for r in rows.iter().filter(|r| r["method"] == "noisy") {
        let (Some(view), Some(spp)) = (r["view"].as_str(), r["spp"].as_u64()) else { continue };
        let noisy = psnr(view, spp, &|m| m == "noisy");
        let oidn = psnr(view, spp, &|m| m == oidn_method);
        let model = psnr(view, spp, &|m| m == model_method);
        match (noisy, oidn, model) {
            (Some(noisy), Some(oidn), Some(model)) => cases.push(Case { view: view.into(), spp, noisy, oidn, model }),
            _ => return Err(format!("{}: {view} at {spp} spp lacks the noisy, OIDN or model row", path.display())),
        }
    }
    if cases.is_empty() {
        return Err(format!("{}: no held-out case", path.display()));
    }
    Ok(cases)
}

/// The mean gain over OIDN at 4, 16 and 64 spp, the worst case, and the count.
fn summary_line(cases: &[Case]) -> String {
    let low: Vec<&Case> = cases.iter().filter(|c| c.spp <= 64).collect();
    let mean = low.iter().map(|c| c.model - c.oidn).sum::<f64>() / low.len().max(1) as f64;
    let worst = cases.iter().map(|c| c.model - c.oidn).fold(f64::INFINITY, f64::min);
    format!(
        "held out ({} cases at 4-64 spp): {mean:+.2} dB over official OIDN on average; worst case at any spp {worst:+.2} dB",
        low.len()
    )
}

fn model_card(
    model: &Shipped,
    train_command: &str,
    manifest_hash: &str,
    cases: &[Case],
    train_seconds: f64,
    load_before: &serde_json::Value,
    dataset_seconds: f64,
) -> String {
    let mut md = format!(
        "# {name}\n\nhush's shipped denoiser for {takes}: OIDN 2.5.1's official `unet` weights (Apache-2.0) fine-tuned \
         on hush's own renders, each noisy input with its own auxiliary images. `{name}.safetensors` is what \
         `hush denoise` runs; `{name}.tza` is the same weights in OIDN's format, for OIDN's own runtime \
         (`oidnDenoise -w {name}.tza`).\n\n\
         ## How it was made\n\n```sh\ncargo xtask train-default --only {name}\n```\n\nwhich runs\n\n```sh\n\
         hush dataset data/scenes/cbox/scene.xml data/scenes/veach-mis/scene.xml --out target/train-default/dataset \
         --procedural {PROCEDURAL} --test-scenes {tests} {dataset}\n{train_command}\n\
         hush eval --dataset target/train-default/dataset --model target/train-default/{name}/model.safetensors \
         --spp {EVAL_SPP} --timing-runs 1 --out target/train-default/eval-{name}\n```\n\n\
         Dataset manifest FNV-1a: `{manifest_hash}`. Training scenes: the Cornell box and the generated rooms \
         proc-1-0 to proc-1-3; held out (never trained on): {tests}. Training took {train_seconds:.0} s \
         (load average before: {load_before}); the dataset {dataset_seconds:.0} s in the run that wrote this card \
         (0 when it was already rendered).\n\n\
         ## Held-out views\n\nPSNR in dB after OIDN's tonemap, against references of 2×2 × 512 paths per pixel (so \
         values above about 40 dB partly measure the reference's own noise).\n\n\
         | view | spp | noisy | official OIDN `{oidn}` | {name} | {name} − OIDN |\n|---|---|---|---|---|---|\n",
        name = model.name,
        takes = model.takes,
        oidn = model.oidn,
        tests = TEST_SCENES.join(","),
        dataset = DATASET_ARGS.join(" "),
    );
    for c in cases {
        md.push_str(&format!(
            "| {} | {} | {:.2} | {:.2} | {:.2} | {:+.2} |\n",
            c.view,
            c.spp,
            c.noisy,
            c.oidn,
            c.model,
            c.model - c.oidn
        ));
    }
    md.push_str(&format!("\n{}.\n", summary_line(cases)));
    md
}

fn copy(from: &Path, to: &Path) -> Result<()> {
    let bytes = std::fs::read(from).map_err(|e| format!("reading {}: {e}", from.display()))?;
    crate::util::write_atomic_with(to, |tmp| std::fs::write(tmp, &bytes))
}
