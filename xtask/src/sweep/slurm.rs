//! `--emit slurm`: a Slurm job-array script with one array task per run on a shared file system.
//! Every task first makes sure the scale's dataset exists (under `flock`, so exactly one task renders
//! it and the others wait), then runs its own run; `--collect` aggregates afterwards.

use std::path::Path;

/// What the script needs to know.
#[derive(Debug)]
pub struct Job<'a> {
    /// `all` or a sweep's name.
    pub sweep: &'a str,
    pub scale: &'a str,
    pub runs: usize,
    /// The xtask and hush executables, on the shared file system.
    pub xtask: &'a Path,
    pub hush: &'a Path,
    /// Where the logs go (`slurm-<job>_<task>.out`).
    pub dir: &'a Path,
    pub cpus_per_task: usize,
    /// `--gres` of each task (`gpu:1`), if any.
    pub gres: Option<String>,
    /// `--device` given to the sweep, passed on to each task (else the scale's own applies).
    pub device: Option<&'a str>,
    pub data_lock: &'a Path,
    /// The sweeps' root folder (`--out`).
    pub out: &'a Path,
}

/// The sbatch script.
pub fn sbatch(job: &Job) -> String {
    let Job { sweep, scale, runs, xtask, hush, dir, cpus_per_task, gres, device, data_lock, out } = job;
    let (x, h, d, l, o) = (xtask.display(), hush.display(), dir.display(), data_lock.display(), out.display());
    let last = runs.saturating_sub(1);
    let gres = gres.as_ref().map(|g| format!("#SBATCH --gres={g}\n")).unwrap_or_default();
    let device = device.map(|d| format!(" --device {d}")).unwrap_or_default();
    format!(
        "#!/bin/bash
# `cargo xtask sweep {sweep} --scale {scale}` as a Slurm job array: one task per run ({runs} runs).
# Submit:   sbatch {d}/sweep.sbatch
# Collect:  cargo xtask sweep {sweep} --scale {scale} --collect
# Tasks skip runs that are complete (done.json), so re-submitting the array re-does only unfinished runs.
#SBATCH --job-name=hush-{sweep}-{scale}
#SBATCH --array=0-{last}
#SBATCH --cpus-per-task={cpus_per_task}
#SBATCH --output={d}/slurm-%A_%a.out
{gres}set -euo pipefail
export RAYON_NUM_THREADS=\"${{SLURM_CPUS_PER_TASK:-{cpus_per_task}}}\"
# The first task renders the scale's dataset; the others wait for it on the lock, then find it complete.
flock {l} {x} sweep {sweep} --scale {scale} --out {o} --prepare --hush {h}{device}
exec {x} sweep {sweep} --scale {scale} --out {o} --run \"$SLURM_ARRAY_TASK_ID\" --hush {h}{device}
"
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn one_array_task_per_run_after_the_dataset() {
        let script = sbatch(&Job {
            sweep: "loss",
            scale: "tiny",
            runs: 5,
            xtask: Path::new("/s/bin/xtask"),
            hush: Path::new("/s/bin/hush"),
            dir: Path::new("/s/loss/tiny/slurm"),
            cpus_per_task: 2,
            gres: None,
            device: None,
            data_lock: Path::new("/s/data/tiny.lock"),
            out: Path::new("/s"),
        });
        assert!(script.starts_with("#!/bin/bash\n"));
        for line in [
            "#SBATCH --array=0-4\n",
            "#SBATCH --cpus-per-task=2\n",
            "#SBATCH --output=/s/loss/tiny/slurm/slurm-%A_%a.out\n",
            "flock /s/data/tiny.lock /s/bin/xtask sweep loss --scale tiny --out /s --prepare --hush /s/bin/hush\n",
            "exec /s/bin/xtask sweep loss --scale tiny --out /s --run \"$SLURM_ARRAY_TASK_ID\" --hush /s/bin/hush\n",
            "export RAYON_NUM_THREADS=\"${SLURM_CPUS_PER_TASK:-2}\"\n",
        ] {
            assert!(script.contains(line), "missing {line:?} in\n{script}");
        }
        // The dataset comes before the run, and every #SBATCH line before the first command.
        assert!(script.find("--prepare").unwrap() < script.find("--run").unwrap());
        assert!(script.rfind("#SBATCH").unwrap() < script.find("set -euo").unwrap());
        assert!(!script.contains("--gres") && !script.contains("--device"));
    }

    #[test]
    fn gpu_tasks_ask_for_a_gpu_and_pass_the_device_on() {
        let script = sbatch(&Job {
            sweep: "all",
            scale: "thesis",
            runs: 3,
            xtask: Path::new("/s/bin/xtask"),
            hush: Path::new("/s/bin/hush-cuda"),
            dir: Path::new("/s/all/thesis/slurm"),
            cpus_per_task: 4,
            gres: Some("gpu:a100:1".into()),
            device: Some("cuda"),
            data_lock: Path::new("/s/data/thesis.lock"),
            out: Path::new("/s"),
        });
        assert!(script.contains("#SBATCH --gres=gpu:a100:1\n"), "{script}");
        assert!(script.rfind("#SBATCH").unwrap() < script.find("set -euo").unwrap());
        for command in ["--prepare", "--run"] {
            let line = script.lines().find(|l| l.contains(command)).unwrap();
            assert!(line.ends_with("--hush /s/bin/hush-cuda --device cuda"), "{line}");
        }
    }
}
