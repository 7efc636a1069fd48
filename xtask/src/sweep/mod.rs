//! `cargo xtask sweep <name|all>`: the thesis's hyperparameter study (chapter 7) as resumable runs of
//! `hush train` + `hush eval`, locally on N workers or as a Slurm job array, aggregated by
//! `hush sweep-report` (from the plan `plan.rs` writes) into `target/sweeps/<name>/<scale>/report.md` with each
//! thesis claim reproduced, refuted or inconclusive.
//!
//! Definitions: `data/sweeps/scales.toml` and one `data/sweeps/<name>.toml` per sweep (see `spec`).

mod exec;
mod plan;
mod slurm;
mod slurm_selftest;
mod spec;

use std::path::{Path, PathBuf};

use exec::{Layout, Outcome};
use spec::{Run, Scale};

use crate::args::{Flags, Takes};
use crate::util::{Result, build_hush, ensure_vulkan, target_dir, write_atomic, write_atomic_with};

pub const USAGE: &str =
    "  sweep <name|all> [--scale tiny|small|medium|thesis] [--jobs N] [--release] [--hush PATH] [--out DIR]
             [--device cpu|cuda] [--list | --prepare | --run I | --emit slurm [--cpus-per-task N] [--gres G]
             | --collect]
                             the thesis's hyperparameter sweeps (data/sweeps/<name>.toml): resumable runs of
                             hush train + hush eval on N workers, or a Slurm job array; the report is
                             target/sweeps/<name>/<scale>/report.md
  sweep slurm-selftest       a single-node Slurm on localhost (installs slurm-wlm) runs the tiny loss sweep";

/// `RAYON_NUM_THREADS` of one worker's `hush`, and so the default worker count (cores / this). On a
/// busy 2-core machine `sweep all --scale tiny` took 35 and 42 s with 2 workers of 1 thread against 75 and 95 s
/// with 1 worker of 2 threads: a run's process start, loading and evaluation are serial, and Candle's
/// threads gain little at these sizes.
const THREADS_PER_WORKER: usize = 1;

#[derive(Debug)]
struct Options {
    name: String,
    scale: String,
    jobs: Option<usize>,
    hush: Option<PathBuf>,
    /// The sweeps' root folder [default: target/sweeps].
    out: Option<PathBuf>,
    cpus_per_task: Option<usize>,
    /// `--device`: overrides the scale's `device`.
    device: Option<String>,
    /// `--gres`: the generic resources a Slurm task asks for [default: `gpu:1` on cuda, none on cpu].
    gres: Option<String>,
    release: bool,
    action: Action,
}

#[derive(Debug, PartialEq)]
enum Action {
    Sweep,
    List,
    Prepare,
    Run(usize),
    EmitSlurm,
    Collect,
}

/// The flags of `sweep`; the actions are exclusive.
const FLAGS: [(&str, Takes); 13] = [
    ("--scale", Takes::Value),
    ("--jobs", Takes::Number),
    ("--hush", Takes::Value),
    ("--out", Takes::Value),
    ("--cpus-per-task", Takes::Number),
    ("--device", Takes::Value),
    ("--gres", Takes::Value),
    ("--release", Takes::Nothing),
    ("--list", Takes::Nothing),
    ("--prepare", Takes::Nothing),
    ("--collect", Takes::Nothing),
    ("--run", Takes::Value),
    ("--emit", Takes::Value),
];
const ACTIONS: [&str; 5] = ["--list", "--prepare", "--run", "--emit", "--collect"];

fn parse(args: &[String]) -> Result<Options> {
    let usage = format!("cargo xtask {}", USAGE.trim_start());
    let flags = Flags::parse(args, &FLAGS, 1, &usage)?;
    let name = flags.positional.first().cloned().ok_or_else(|| format!("usage: {usage}"))?;
    let positive = |flag: &str| -> Result<Option<usize>> {
        let Some(v) = flags.value(flag) else { return Ok(None) };
        v.parse().ok().filter(|&n| n > 0).map(Some).ok_or(format!("{flag} {v}: give a number ≥ 1"))
    };
    let actions = flags.given_of(&ACTIONS);
    if actions.len() > 1 {
        return Err(format!("give only one of {}\nusage: {usage}", ACTIONS.join(", ")));
    }
    let action = match actions.first().copied() {
        None => Action::Sweep,
        Some("--list") => Action::List,
        Some("--prepare") => Action::Prepare,
        Some("--collect") => Action::Collect,
        Some("--run") => {
            let v = flags.value("--run").expect("given");
            Action::Run(v.parse().map_err(|_| format!("--run {v}: give a run index (see --list)"))?)
        }
        Some(_) => match flags.value("--emit").expect("given") {
            "slurm" => Action::EmitSlurm,
            other => return Err(format!("--emit {other}: only `slurm` is supported")),
        },
    };
    let device = flags.value("--device").map(String::from);
    if let Some(d) = device.as_deref().filter(|d| !spec::is_device(d)) {
        return Err(format!("--device {d}: use cpu or cuda"));
    }
    let gres = flags.value("--gres").map(String::from);
    if gres.is_some() && action != Action::EmitSlurm {
        return Err("--gres is a Slurm request: give it with --emit slurm".into());
    }
    Ok(Options {
        name,
        scale: flags.value("--scale").unwrap_or("tiny").into(),
        jobs: positive("--jobs")?,
        hush: flags.value("--hush").map(PathBuf::from),
        out: flags.value("--out").map(PathBuf::from),
        cpus_per_task: positive("--cpus-per-task")?,
        device,
        gres,
        release: flags.has("--release"),
        action,
    })
}

/// Copies `exe` to `bin/<name>` atomically, so that rebuilding the workspace while a sweep runs never swaps
/// the binary under its workers.
fn stable_copy(exe: &Path, bin: &Path, name: &str) -> Result<PathBuf> {
    let dest = bin.join(name);
    write_atomic_with(&dest, |tmp| std::fs::copy(exe, tmp).map(drop))
        .map_err(|e| format!("copying {}: {e}", exe.display()))?;
    Ok(dest)
}

/// The hush the runs use: `--hush`, else this workspace's, built with `cuda` (always `--release`) where the
/// scale's networks run on CUDA.
fn hush(o: &Options, scale: &Scale, layout: &Layout) -> Result<PathBuf> {
    match &o.hush {
        Some(p) if p.is_file() => Ok(p.clone()),
        Some(p) => Err(format!("--hush {}: no such file", p.display())),
        None if is_cuda(scale) => {
            let exe = crate::gpu_check::compute_cap()
                .and_then(|cap| crate::gpu_check::build_cuda(&cap))
                .map_err(|e| format!("--device cuda needs hush built with CUDA (or give one with --hush): {e}"))?;
            // Beside the CPU build, which `--collect` makes: a running array must keep finding its CUDA one.
            stable_copy(&exe, &layout.root.join("bin"), "hush-cuda")
        }
        None => stable_copy(&build_hush(o.release)?, &layout.root.join("bin"), "hush"),
    }
}

fn is_cuda(scale: &Scale) -> bool {
    scale.device.as_deref() == Some("cuda")
}

/// A Slurm task's default CPUs on a GPU: its data loading, evaluation metrics and process start run there.
const CPUS_PER_GPU_TASK: usize = 4;

/// Writes the Slurm job-array script of the sweep and returns its path.
fn emit_slurm(o: &Options, scale: &Scale, runs: usize, layout: &Layout, hush: &Path) -> Result<PathBuf> {
    let exe = std::env::current_exe().map_err(|e| format!("cannot find the xtask executable: {e}"))?;
    let xtask = stable_copy(&exe, &layout.root.join("bin"), "xtask")?;
    let dir = layout.sweep(&o.name, &scale.name).join("slurm");
    std::fs::create_dir_all(&dir).map_err(|e| format!("{}: {e}", dir.display()))?;
    // flock creates the lock file but not its folder.
    let data = layout.root.join("data");
    std::fs::create_dir_all(&data).map_err(|e| format!("{}: {e}", data.display()))?;
    let lock = data.join(format!("{}.lock", scale.name));
    let script = slurm::sbatch(&slurm::Job {
        sweep: &o.name,
        scale: &scale.name,
        runs,
        xtask: &xtask,
        hush,
        dir: &dir,
        cpus_per_task: o.cpus_per_task.unwrap_or(if is_cuda(scale) { CPUS_PER_GPU_TASK } else { THREADS_PER_WORKER }),
        gres: o.gres.clone().or_else(|| is_cuda(scale).then(|| "gpu:1".to_string())),
        device: o.device.as_deref(),
        data_lock: &lock,
        out: &layout.root,
    });
    let path = dir.join("sweep.sbatch");
    write_atomic(&path, &script)?;
    Ok(path)
}

/// `sweep slurm-selftest`: the tiny `loss` sweep as a job array on a single-node Slurm started here.
fn slurm_selftest(mut o: Options) -> Result<()> {
    let root = o.out.clone().unwrap_or_else(|| target_dir().join("sweeps").join("slurm-selftest"));
    let layout = Layout { root: root.join("sweeps") };
    (o.name, o.scale) = ("loss".into(), "tiny".into());
    let defs = spec::sweeps_dir();
    let scale = spec::load_scale(&defs, &o.scale)?;
    let sweeps = spec::load_sweeps(&defs, &o.name)?;
    let runs: Vec<Run> = sweeps.iter().flat_map(|s| s.runs(&scale)).collect();
    ensure_vulkan()?;
    let hush = hush(&o, &scale, &layout)?;
    // Start from no runs, so that the array really trains and evaluates them all (the dataset stays).
    let sweep_dir = layout.root.join(&o.name);
    if sweep_dir.exists() {
        std::fs::remove_dir_all(&sweep_dir).map_err(|e| format!("cannot clear {}: {e}", sweep_dir.display()))?;
    }
    let script = emit_slurm(&o, &scale, runs.len(), &layout, &hush)?;
    let (daemons, conf) = slurm_selftest::start(&root.join("slurm"))?;
    let start = std::time::Instant::now();
    crate::util::spawn(std::process::Command::new("sbatch").arg("--wait").arg(&script).env("SLURM_CONF", &conf))?;
    let seconds = start.elapsed().as_secs_f64();
    drop(daemons);
    let missing: Vec<&str> = runs
        .iter()
        .filter(|r| !layout.run(r, &scale.name).join("done.json").is_file())
        .map(|r| r.name.as_str())
        .collect();
    if !missing.is_empty() {
        return Err(format!(
            "the Slurm array left runs unfinished: {}; see {}",
            missing.join(", "),
            script.with_file_name("slurm-*.out").display()
        ));
    }
    plan::report(&hush, &sweeps, &scale, &runs, &layout)?;
    println!("slurm-selftest: {} array tasks completed every run in {seconds:.1} s", runs.len());
    Ok(())
}

pub fn run(args: &[String]) -> Result<()> {
    let o = parse(args)?;
    if o.name == "slurm-selftest" {
        return slurm_selftest(o);
    }
    let defs = spec::sweeps_dir();
    let mut scale = spec::load_scale(&defs, &o.scale)?;
    if o.device.is_some() {
        scale.device = o.device.clone();
    }
    let sweeps = spec::load_sweeps(&defs, &o.name)?;
    let runs: Vec<Run> = sweeps.iter().flat_map(|s| s.runs(&scale)).collect();
    let layout = Layout { root: o.out.clone().unwrap_or_else(|| target_dir().join("sweeps")) };
    let cores = std::thread::available_parallelism().map_or(1, |n| n.get());
    // One worker per GPU-less core, or one for the GPU (`--jobs` for a machine with several).
    let workers = o.jobs.unwrap_or(if is_cuda(&scale) { 1 } else { (cores / THREADS_PER_WORKER).max(1) });
    let threads = (cores / workers).max(1);

    match o.action {
        Action::List => {
            for (i, r) in runs.iter().enumerate() {
                println!("{i:4}  {}/{}  {}", r.sweep, r.name, spec::flags(&r.train).join(" "));
            }
            Ok(())
        }
        Action::Collect => {
            // The report needs no GPU: a plain build, also on a cluster's login node.
            let cpu = Scale { device: None, ..scale.clone() };
            plan::report(&hush(&o, &cpu, &layout)?, &sweeps, &scale, &runs, &layout)
        }
        Action::Prepare => {
            ensure_vulkan()?;
            exec::prepare_dataset(&hush(&o, &scale, &layout)?, &scale, &layout).map(drop)
        }
        Action::EmitSlurm => {
            let script = emit_slurm(&o, &scale, runs.len(), &layout, &hush(&o, &scale, &layout)?)?;
            println!("{}\nsubmit: sbatch {}", script.display(), script.display());
            println!("then:   cargo xtask sweep {} --scale {} --collect", o.name, scale.name);
            Ok(())
        }
        Action::Run(i) => {
            let run = runs.get(i).ok_or_else(|| {
                format!(
                    "--run {i}: `{}` has {} runs (0 to {}); see --list",
                    o.name,
                    runs.len(),
                    runs.len().saturating_sub(1)
                )
            })?;
            let hush = hush(&o, &scale, &layout)?;
            let dataset = exec::prepare_dataset(&hush, &scale, &layout)?;
            let dir = layout.run(run, &scale.name);
            let threads = std::env::var("RAYON_NUM_THREADS").ok().and_then(|t| t.parse().ok()).unwrap_or(cores);
            match exec::run_one(&hush, run, &scale, &dataset, &dir, threads) {
                Outcome::Skipped | Outcome::Same(_) => {
                    eprintln!("sweep: {}/{} is complete already", run.sweep, run.name)
                }
                Outcome::Done(s) => eprintln!("sweep: {}/{} done in {s:.1} s", run.sweep, run.name),
                Outcome::Failed(e) => return Err(format!("{}/{}: {e}", run.sweep, run.name)),
            }
            Ok(())
        }
        Action::Sweep => {
            ensure_vulkan()?;
            let hush = hush(&o, &scale, &layout)?;
            let start = std::time::Instant::now();
            let dataset = exec::prepare_dataset(&hush, &scale, &layout)?;
            eprintln!(
                "sweep: {} runs of `{}` at scale {} on {workers} worker(s), RAYON_NUM_THREADS={threads}",
                runs.len(),
                o.name,
                scale.name
            );
            let jobs: Vec<_> =
                runs.iter().map(|r| (r.clone(), &scale, dataset.clone(), layout.run(r, &scale.name))).collect();
            // Complete runs of every sweep at this scale, to link runs with the same settings to.
            let elsewhere: Vec<(Run, PathBuf)> = spec::load_sweeps(&defs, "all")?
                .iter()
                .flat_map(|s| s.runs(&scale))
                .map(|r| {
                    let dir = layout.run(&r, &scale.name);
                    (r, dir)
                })
                .collect();
            let outcomes = exec::run_all(&hush, &jobs, &elsewhere, workers, threads);
            plan::report(&hush, &sweeps, &scale, &runs, &layout)?;
            let failed: Vec<String> = runs
                .iter()
                .zip(&outcomes)
                .filter_map(|(r, o)| match o {
                    Outcome::Failed(e) => Some(format!("{}/{}: {e}", r.sweep, r.name)),
                    _ => None,
                })
                .collect();
            eprintln!("sweep: {:.1} s in all", start.elapsed().as_secs_f64());
            if failed.is_empty() {
                Ok(())
            } else {
                Err(format!("{} run(s) failed; re-run to retry them:\n  {}", failed.len(), failed.join("\n  ")))
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn args(s: &str) -> Vec<String> {
        s.split_whitespace().map(String::from).collect()
    }

    #[test]
    fn options() {
        let o = parse(&args("loss --scale small --jobs 2 --run 3")).unwrap();
        assert_eq!((o.name.as_str(), o.scale.as_str(), o.jobs, o.action), ("loss", "small", Some(2), Action::Run(3)));
        assert_eq!(parse(&args("all --emit slurm")).unwrap().action, Action::EmitSlurm);
        assert!(parse(&args("all --collect --list")).unwrap_err().contains("only one of"));
        assert!(parse(&args("all --jobs 0")).unwrap_err().contains("≥ 1"));
        assert!(parse(&args("--scale tiny")).unwrap_err().contains("usage"));
        assert!(parse(&args("all --emit pbs")).unwrap_err().contains("only `slurm`"));
        let o = parse(&args("all --scale thesis --emit slurm --device cuda --gres gpu:a100:1")).unwrap();
        assert_eq!((o.device.as_deref(), o.gres.as_deref()), (Some("cuda"), Some("gpu:a100:1")));
        assert!(parse(&args("all --device tpu")).unwrap_err().contains("--device tpu: use cpu or cuda"));
        assert!(parse(&args("all --gres gpu:1")).unwrap_err().contains("with --emit slurm"));
    }
}
