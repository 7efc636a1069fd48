//! `cargo xtask faults`: hush's jobs against faults other than a kill, on a small tmpfs that this command
//! mounts (it needs root, as CI and the developers' machines have):
//!
//! - the disk fills during a dataset, a training run and a report: each fails with an error that names the
//!   file and says the disk is full, leaves no temporary file, and, once there is room again, finishes by
//!   resuming, keeping every file that was complete before the fault (the same bytes, not rewritten);
//! - the output folder is read-only: each job fails at once with an error that names the folder.
//!
//! Each run first measures what the job writes on the ordinary disk, then gives it a tmpfs of half that.
//! The outcome of every step goes to `target/faults/summary.json`.

use std::path::{Path, PathBuf};
use std::process::Command;

use serde_json::json;

use crate::args::{Flags, Takes};
use crate::util::{Result, build_hush, ensure_vulkan, project_root, target_dir};

pub const USAGE: &str = "cargo xtask faults [--release]";

/// The training run's steps (a checkpoint every 10).
const TRAIN_STEPS: u64 = 30;

pub fn run(args: &[String]) -> Result<()> {
    let flags = Flags::parse(args, &[("--release", Takes::Nothing)], 0, USAGE)?;
    if !crate::util::is_root() {
        return Err("cargo xtask faults mounts a small tmpfs to fill: run it as root".into());
    }
    ensure_vulkan()?;
    let hush = build_hush(flags.has("--release"))?;
    let root = target_dir().join("faults");
    let mount = root.join("disk");
    unmount(&mount);
    if root.exists() {
        std::fs::remove_dir_all(&root).map_err(|e| format!("cannot clear {}: {e}", root.display()))?;
    }
    std::fs::create_dir_all(&mount).map_err(|e| format!("cannot create {}: {e}", mount.display()))?;
    let job = Jobs { hush: hush.clone(), root: root.clone() };
    let result = job.all(&mount);
    unmount(&mount);
    let steps = result?;
    let failed: Vec<&serde_json::Value> = steps.iter().filter(|s| s["ok"] != true).collect();
    crate::util::write_json(&root.join("summary.json"), &json!({ "steps": steps }))?;
    for s in &steps {
        eprintln!(
            "{:<34} {}  {}",
            s["step"].as_str().unwrap_or(""),
            if s["ok"] == true { "ok  " } else { "FAIL" },
            s["said"].as_str().unwrap_or("")
        );
    }
    if failed.is_empty() {
        eprintln!("xtask faults: {} steps, all handled; table in {}", steps.len(), root.join("summary.json").display());
        Ok(())
    } else {
        Err(format!(
            "xtask faults: {} of {} steps not handled:\n{}",
            failed.len(),
            steps.len(),
            serde_json::to_string_pretty(&failed).unwrap()
        ))
    }
}

struct Jobs {
    hush: PathBuf,
    root: PathBuf,
}

/// One job's command line, given its output folder.
type JobArgs = dyn Fn(&Path) -> Vec<String>;

/// What a job must keep of what it wrote before the disk filled.
#[derive(Clone, Copy, PartialEq)]
enum Keeps {
    /// Every image the manifest recorded (the same bytes: not rendered again).
    Recorded,
    /// Its last checkpoint: the resumed run takes fewer steps than the whole run.
    Checkpoint,
    /// Nothing but a complete result (a report is written anew).
    Result,
}

impl Jobs {
    fn all(&self, mount: &Path) -> Result<Vec<serde_json::Value>> {
        let cbox = project_root().join("data/scenes/cbox/scene.xml").display().to_string();
        let dataset = move |out: &Path| -> Vec<String> {
            let mut a: Vec<String> = vec!["dataset".into(), cbox.clone(), "--out".into(), out.display().to_string()];
            a.extend(
                [
                    "--views",
                    "4",
                    "--test-views",
                    "1",
                    "--spp",
                    "1,4",
                    "--ref-spp",
                    "16",
                    "--aux-spp",
                    "4",
                    "--size",
                    "48",
                ]
                .map(String::from),
            );
            a
        };
        // The dataset the training and the report read, on the ordinary disk.
        let ds = self.root.join("ds");
        self.expect_ok(&dataset(&ds))?;
        let ds_arg = ds.display().to_string();
        let train = {
            let ds_arg = ds_arg.clone();
            move |out: &Path| -> Vec<String> {
                let mut a: Vec<String> =
                    vec!["train".into(), "--dataset".into(), ds_arg.clone(), "--out".into(), out.display().to_string()];
                a.extend(
                    [
                        "--steps",
                        &TRAIN_STEPS.to_string(),
                        "--epoch-steps",
                        "10",
                        "--width",
                        "0.25",
                        "--crop",
                        "32",
                        "--seed",
                        "1",
                    ]
                    .map(String::from),
                );
                a
            }
        };
        let run = self.root.join("run");
        self.expect_ok(&train(&run))?;
        let model = run.join("model.safetensors").display().to_string();
        let eval = move |out: &Path| -> Vec<String> {
            [
                "eval",
                "--dataset",
                &ds_arg,
                "--model",
                &model,
                "--spp",
                "4",
                "--timing-runs",
                "1",
                "--no-official",
                "--out",
            ]
            .map(String::from)
            .into_iter()
            .chain([out.display().to_string()])
            .collect()
        };
        let mut steps = Vec::new();
        let resume_train = |out: &Path| vec!["train".into(), "--resume".into(), out.display().to_string()];
        for (name, job, resume, keeps) in [
            ("dataset", &dataset as &JobArgs, None, Keeps::Recorded),
            ("train", &train as &JobArgs, Some(&resume_train as &JobArgs), Keeps::Checkpoint),
            ("eval", &eval as &JobArgs, None, Keeps::Result),
        ] {
            steps.extend(self.disk_full(name, job, resume, keeps, mount)?);
            steps.push(self.read_only(name, job, mount)?);
        }
        Ok(steps)
    }

    fn command(&self, args: &[String]) -> Command {
        let mut cmd = Command::new(&self.hush);
        cmd.args(args).env("NODEVICE_SELECT", "1").env_remove("RUST_BACKTRACE");
        cmd
    }

    fn expect_ok(&self, args: &[String]) -> Result<()> {
        let out = self.command(args).output().map_err(|e| format!("cannot start hush: {e}"))?;
        if out.status.success() {
            Ok(())
        } else {
            Err(format!("hush {} failed:\n{}", args.join(" "), String::from_utf8_lossy(&out.stderr)))
        }
    }

    /// `job` on a tmpfs of half the bytes it writes: an error naming a file and the full disk, no temporary
    /// file left; then, with room again, `resume` (or the same command) finishes it, and every file that was
    /// complete at the fault is kept as it was.
    fn disk_full(
        &self,
        name: &str,
        job: &JobArgs,
        resume: Option<&JobArgs>,
        keeps: Keeps,
        mount: &Path,
    ) -> Result<Vec<serde_json::Value>> {
        let measure = self.root.join(format!("measure-{name}"));
        self.expect_ok(&job(&measure))?;
        let needed = du(&measure);
        let size = (needed / 2).max(64 * 1024);
        mount_tmpfs(mount, size, false)?;
        let out = mount.join(name);
        let first = self.command(&job(&out)).output().map_err(|e| format!("cannot start hush: {e}"))?;
        let stderr = String::from_utf8_lossy(&first.stderr).into_owned();
        let said = stderr.lines().find(|l| l.starts_with("error:")).unwrap_or("").to_string();
        let mut problems = Vec::new();
        if first.status.code() != Some(1) {
            problems.push(format!("exit {:?}, not 1", first.status.code()));
        }
        if stderr.contains("panicked") {
            problems.push("a panic".into());
        }
        if !said.contains("No space left on device") || !said.contains(&mount.display().to_string()) {
            problems.push("the error does not name a file on the full disk and say it is full".into());
        }
        let temps = temporaries(&out);
        if !temps.is_empty() {
            problems.push(format!("temporary files left: {temps:?}"));
        }
        let before = snapshot(&out);
        let recorded = recorded_images(&out);
        let full = json!({
            "step": format!("{name}: disk full ({size} of {needed} bytes)"),
            "ok": problems.is_empty(),
            "said": said,
            "problems": problems,
            "files_before_fault": before.len(),
        });
        // Room again: the same disk, larger; the job resumes.
        mount_tmpfs(mount, needed * 4, true)?;
        let again = resume.unwrap_or(job)(&out);
        let second = self.command(&again).output().map_err(|e| format!("cannot start hush: {e}"))?;
        let mut problems = Vec::new();
        if !second.status.success() {
            problems.push(format!("the resumed job failed:\n{}", String::from_utf8_lossy(&second.stderr)));
        }
        let after = snapshot(&out);
        let kept = match keeps {
            Keeps::Recorded => {
                let changed: Vec<&String> = recorded.iter().filter(|f| after.get(*f) != before.get(*f)).collect();
                if !changed.is_empty() {
                    problems.push(format!("images recorded before the fault were rendered again or lost: {changed:?}"));
                }
                format!("{} recorded images kept", recorded.len() - changed.len())
            }
            Keeps::Checkpoint => {
                let steps = crate::util::read_json(&out.join("summary.json")).ok().and_then(|s| s["steps"].as_u64());
                let had = before.contains_key("checkpoints/last.safetensors");
                if had && steps.is_none_or(|s| s >= TRAIN_STEPS) {
                    problems.push(format!(
                        "a checkpoint was written before the fault, but the resume took {steps:?} steps"
                    ));
                }
                format!(
                    "resumed {} a checkpoint: {steps:?} of {TRAIN_STEPS} steps",
                    if had { "from" } else { "without" }
                )
            }
            Keeps::Result => {
                if !out.join("report.html").is_file() {
                    problems.push("the rerun wrote no report.html".into());
                }
                format!("report rewritten: {} files", after.len())
            }
        };
        if name == "dataset" && second.status.success() {
            let check = self.command(&["dataset".into(), "check".into(), out.display().to_string()]).output();
            if !check.is_ok_and(|o| o.status.success()) {
                problems.push("hush dataset check fails on the resumed dataset".into());
            }
        }
        let temps = temporaries(&out);
        if !temps.is_empty() {
            problems.push(format!("temporary files left after the resume: {temps:?}"));
        }
        let resumed = json!({
            "step": format!("{name}: resumed with room"),
            "ok": problems.is_empty(),
            "said": kept,
            "problems": problems,
        });
        unmount(mount);
        Ok(vec![full, resumed])
    }

    /// `job` into a folder on a read-only file system: an error naming it, at once.
    fn read_only(&self, name: &str, job: &JobArgs, mount: &Path) -> Result<serde_json::Value> {
        mount_tmpfs(mount, 1 << 20, false)?;
        let out = mount.join(name);
        std::fs::create_dir_all(&out).map_err(|e| format!("cannot create {}: {e}", out.display()))?;
        remount_read_only(mount)?;
        let result = self.command(&job(&out)).output().map_err(|e| format!("cannot start hush: {e}"))?;
        let stderr = String::from_utf8_lossy(&result.stderr).into_owned();
        let said = stderr.lines().find(|l| l.starts_with("error:")).unwrap_or("").to_string();
        let mut problems = Vec::new();
        if result.status.code() != Some(1) || stderr.contains("panicked") {
            problems.push(format!("exit {:?}, not 1 with an error", result.status.code()));
        }
        if !said.contains("Read-only file system") || !said.contains(&out.display().to_string()) {
            problems.push("the error does not name the folder and say it is read-only".into());
        }
        unmount(mount);
        Ok(
            json!({ "step": format!("{name}: read-only folder"), "ok": problems.is_empty(), "said": said, "problems": problems }),
        )
    }
}

/// The image files a dataset's manifest records as written.
fn recorded_images(dir: &Path) -> Vec<String> {
    let Ok(m) = crate::util::read_json(&dir.join("manifest.json")) else { return Vec::new() };
    let mut files = Vec::new();
    for v in m["views"].as_array().into_iter().flatten().chain(m["pending"].as_array().into_iter().flatten()) {
        files.extend(v["noisy"].as_array().into_iter().flatten().filter_map(|r| r["file"].as_str().map(String::from)));
        files.extend(v["reference"]["file"].as_str().map(String::from));
        if let Some(aux) = v["aux"].as_object() {
            files.extend(aux.values().filter_map(|f| f.as_str().map(String::from)));
        }
    }
    files
}

fn mount_tmpfs(at: &Path, bytes: u64, remount: bool) -> Result<()> {
    let mut options = format!("size={bytes}");
    if remount {
        options = format!("remount,{options}");
    }
    let mut cmd = Command::new("mount");
    if remount {
        cmd.args(["-o", &options]).arg(at);
    } else {
        cmd.args(["-t", "tmpfs", "-o", &options, "tmpfs"]).arg(at);
    }
    let status = cmd.status().map_err(|e| format!("cannot run mount: {e}"))?;
    if status.success() { Ok(()) } else { Err(format!("mount -o {options} {} failed ({status})", at.display())) }
}

fn remount_read_only(at: &Path) -> Result<()> {
    let status = Command::new("mount")
        .args(["-o", "remount,ro"])
        .arg(at)
        .status()
        .map_err(|e| format!("cannot run mount: {e}"))?;
    if status.success() { Ok(()) } else { Err(format!("mount -o remount,ro {} failed", at.display())) }
}

fn unmount(at: &Path) {
    while Command::new("umount").arg(at).stderr(std::process::Stdio::null()).status().is_ok_and(|s| s.success()) {}
}

/// Every file below `dir` (relative path) with its size and modification time.
fn snapshot(dir: &Path) -> std::collections::BTreeMap<String, (u64, std::time::SystemTime)> {
    crate::util::files_below(dir)
        .into_iter()
        .filter_map(|p| {
            let m = std::fs::metadata(&p).ok()?;
            Some((crate::util::relative(&p, dir), (m.len(), m.modified().unwrap_or(std::time::UNIX_EPOCH))))
        })
        .collect()
}

/// The bytes of the files below `dir`.
fn du(dir: &Path) -> u64 {
    snapshot(dir).values().map(|(len, _)| len).sum()
}

/// Temporary files of an interrupted atomic write below `dir`.
fn temporaries(dir: &Path) -> Vec<String> {
    snapshot(dir).into_keys().filter(|f| crate::util::is_temporary(f)).collect()
}
