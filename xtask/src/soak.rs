//! `cargo xtask soak`: dataset → training → a tiny sweep, SIGKILLed at random moments and resumed each time,
//! against the same jobs run without interruption.
//!
//! Each stage is first run whole (`target/soak/whole/`), which also measures it. The interrupted pipeline
//! (`target/soak/killed/`) runs each stage in a process group of its own and kills the group (the sweep's
//! `hush` workers with it) at a moment drawn uniformly from the first part of the stage's measured time,
//! then starts it again, until it finishes; the kills are spread over the stages. At the end the dataset must
//! pass `hush dataset check` and every image must equal the uninterrupted run's bit for bit (the renderer is
//! deterministic for a seed), the trained model must equal its twin bit for bit (a resumed run continues
//! exactly), every sweep run must be done with the same evaluation numbers (timings aside), and no
//! temporary file may be left anywhere. The outcome goes to `target/soak/summary.json`.

use std::os::unix::process::CommandExt;
use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::{Duration, Instant};

use serde_json::{Value, json};

use crate::args::{Flags, Takes};
use crate::util::{Result, build_hush, ensure_vulkan, project_root, target_dir};

pub const USAGE: &str = "cargo xtask soak [--kills N] [--seed S] [--release]";

/// Kills every stage gets at least, given 3 × stages kills or more.
const MIN_STAGE_KILLS: u32 = 3;

/// A stage's command line, given the folder the pipeline runs in.
type StageArgs = Box<dyn Fn(&Path) -> Vec<String>>;

/// One stage of the pipeline: its name, program and arguments.
struct Stage {
    name: &'static str,
    program: PathBuf,
    args: StageArgs,
}

pub fn run(args: &[String]) -> Result<()> {
    let known = [("--kills", Takes::Number), ("--seed", Takes::Number), ("--release", Takes::Nothing)];
    let flags = Flags::parse(args, &known, 0, USAGE)?;
    let kills: u32 = flags.number("--kills", 20)?;
    let seed: u64 = flags.number("--seed", 1)?;
    ensure_vulkan()?;
    let hush = build_hush(flags.has("--release"))?;
    let xtask = std::env::current_exe().map_err(|e| format!("cannot find xtask's own binary: {e}"))?;
    let root = target_dir().join("soak");
    if root.exists() {
        std::fs::remove_dir_all(&root).map_err(|e| format!("cannot clear {}: {e}", root.display()))?;
    }
    let stages = stages(&hush, &xtask);

    // The uninterrupted pipeline, timed.
    let whole = root.join("whole");
    let mut seconds = Vec::new();
    for stage in &stages {
        let start = Instant::now();
        let status = command(stage, &whole).status().map_err(|e| format!("cannot start {}: {e}", stage.name))?;
        if !status.success() {
            return Err(format!("the uninterrupted {} failed ({status})", stage.name));
        }
        seconds.push(start.elapsed().as_secs_f64());
        eprintln!("xtask soak: {} uninterrupted in {:.1} s", stage.name, seconds[seconds.len() - 1]);
    }

    // The same pipeline, killed `kills` times: each stage at least MIN_STAGE_KILLS times where there are
    // kills enough (the sweep is the shortest stage, and its resumption is what the sweep's acceptance
    // asks about), the rest by each stage's measured time.
    let total: f64 = seconds.iter().sum();
    let floor = if kills as usize >= MIN_STAGE_KILLS as usize * seconds.len() { MIN_STAGE_KILLS } else { 0 };
    let rest = f64::from(kills - floor * seconds.len() as u32);
    let mut shares: Vec<u32> = seconds.iter().map(|s| floor + ((s / total) * rest).floor() as u32).collect();
    // The kills the floor left over, one each to the stages in turn.
    let given: u32 = shares.iter().sum();
    let n = shares.len();
    for k in 0..kills.saturating_sub(given) as usize {
        shares[k % n] += 1;
    }
    let killed = root.join("killed");
    let mut rng = hush_hash::SplitMix64(seed);
    let mut log = Vec::new();
    let mut done_kills = 0;
    let mut carried = 0;
    for ((stage, &share), &secs) in stages.iter().zip(&shares).zip(&seconds) {
        // A stage that finished before its kills landed passes them on to the next.
        let share = share + carried;
        let mut stage_kills = 0;
        let mut starts = 0;
        loop {
            starts += 1;
            let mut child = command(stage, &killed)
                .process_group(0)
                .stdout(std::process::Stdio::null())
                .stderr(std::process::Stdio::null())
                .spawn()
                .map_err(|e| format!("cannot start {}: {e}", stage.name))?;
            // Within the first 15 % of the stage's whole time, so that every start but the last is killed
            // before the stage can finish: a resumed stage has less left to do than the whole one.
            let at = (stage_kills < share).then(|| Duration::from_secs_f64(0.3 + secs * 0.15 * rng.next_f64()));
            let deadline = at.map(|a| Instant::now() + a);
            let status = loop {
                if let Some(status) = child.try_wait().map_err(|e| e.to_string())? {
                    break Some(status);
                }
                if deadline.is_some_and(|d| Instant::now() >= d) {
                    let group = format!("-{}", child.id());
                    let _ = Command::new("kill").args(["-KILL", "--", &group]).status();
                    let _ = child.wait();
                    break None;
                }
                std::thread::sleep(Duration::from_millis(10));
            };
            match status {
                None => {
                    stage_kills += 1;
                    log.push(json!({ "stage": stage.name, "killed_after_s": at.map(|a| a.as_secs_f64()) }));
                }
                Some(s) if s.success() => break,
                Some(s) => {
                    return Err(format!(
                        "{} failed after {stage_kills} kills ({s}); see {}",
                        stage.name,
                        killed.display()
                    ));
                }
            }
            if starts > 4 * kills as usize + 8 {
                return Err(format!("{} did not finish after {starts} starts", stage.name));
            }
        }
        eprintln!("xtask soak: {} finished after {stage_kills} kills", stage.name);
        done_kills += stage_kills;
        carried = share - stage_kills;
    }

    let mut problems = compare(&hush, &whole, &killed)?;
    if done_kills < kills {
        problems.push(format!("only {done_kills} of {kills} kills landed before their stage finished"));
    }
    let summary = json!({
        "kills": done_kills,
        "asked": kills,
        "seed": seed,
        "uninterrupted_seconds": stages.iter().zip(&seconds).map(|(s, t)| (s.name.to_string(), json!(t))).collect::<serde_json::Map<_, _>>(),
        "kills_log": log,
        "problems": problems,
    });
    crate::util::write_json(&root.join("summary.json"), &summary)?;
    if problems.is_empty() {
        eprintln!(
            "xtask soak: {done_kills} kills; every output complete and equal to the uninterrupted run's, no temporary file"
        );
        Ok(())
    } else {
        Err(format!("xtask soak: {}", problems.join("\n")))
    }
}

/// Dataset (two scenes, a ladder, references), a training run on it, and the tiny loss sweep.
fn stages(hush: &Path, xtask: &Path) -> Vec<Stage> {
    let cbox = project_root().join("data/scenes/cbox/scene.xml").display().to_string();
    let veach = project_root().join("data/scenes/veach-mis/scene.xml").display().to_string();
    let hush_arg = hush.display().to_string();
    vec![
        Stage {
            name: "dataset",
            program: hush.to_path_buf(),
            args: Box::new(move |dir| {
                let mut a = vec!["dataset".to_string(), cbox.clone(), veach.clone(), "--out".into()];
                a.push(dir.join("ds").display().to_string());
                a.extend(
                    ["--views", "4", "--test-views", "1", "--spp", "1,4,16,64", "--ref-spp", "128", "--aux-spp", "4"]
                        .map(String::from),
                );
                a.extend(["--size", "64", "--seed", "5"].map(String::from));
                a
            }),
        },
        Stage {
            name: "train",
            program: hush.to_path_buf(),
            args: Box::new(|dir| {
                let mut a = vec!["train".to_string(), "--dataset".into(), dir.join("ds").display().to_string()];
                a.extend(["--out".to_string(), dir.join("run").display().to_string()]);
                a.extend(
                    ["--steps", "400", "--epoch-steps", "10", "--width", "0.25", "--crop", "32", "--seed", "3"]
                        .map(String::from),
                );
                a
            }),
        },
        Stage {
            name: "sweep",
            program: xtask.to_path_buf(),
            args: Box::new(move |dir| {
                let mut a = ["sweep", "loss", "--scale", "tiny", "--hush", &hush_arg].map(String::from).to_vec();
                a.extend(["--out".to_string(), dir.join("sweep").display().to_string()]);
                a
            }),
        },
    ]
}

fn command(stage: &Stage, dir: &Path) -> Command {
    let mut cmd = Command::new(&stage.program);
    cmd.args((stage.args)(dir)).env("NODEVICE_SELECT", "1");
    cmd
}

/// What differs between the uninterrupted pipeline in `whole` and the killed one in `killed`.
fn compare(hush: &Path, whole: &Path, killed: &Path) -> Result<Vec<String>> {
    let mut problems = Vec::new();
    let check = Command::new(hush)
        .args(["dataset", "check"])
        .arg(killed.join("ds"))
        .env("NODEVICE_SELECT", "1")
        .output()
        .map_err(|e| format!("cannot start hush: {e}"))?;
    if !check.status.success() {
        problems.push(format!("hush dataset check fails:\n{}", String::from_utf8_lossy(&check.stderr)));
    }
    let (a, b) = (files(whole), files(killed));
    let temps: Vec<&String> = b.keys().filter(|f| crate::util::is_temporary(f)).collect();
    if !temps.is_empty() {
        problems.push(format!("temporary files left: {temps:?}"));
    }
    // Every image (the datasets', the sweep's denoised pictures) and every trained model: bit for bit.
    for (file, bytes) in &a {
        let exact = file.ends_with(".exr") || file.ends_with("model.safetensors");
        if exact && b.get(file) != Some(bytes) {
            problems.push(format!("{file} differs from the uninterrupted run's"));
        }
    }
    let images = a.keys().filter(|f| f.starts_with("ds/") && f.ends_with(".exr")).count();
    if images == 0 || !a.contains_key("run/model.safetensors") {
        problems.push("the uninterrupted run wrote no images or no model".into());
    }
    // Every sweep run done, with the same evaluation numbers.
    let evals: Vec<&String> =
        a.keys().filter(|f| f.starts_with("sweep/") && f.ends_with("eval/summary.json")).collect();
    if evals.is_empty() {
        problems.push("the uninterrupted sweep wrote no evaluation".into());
    }
    for file in evals {
        match b.get(file) {
            None => problems.push(format!("{file} is missing")),
            Some(other) => {
                let (x, y) = (metrics(&a[file]), metrics(other));
                if x != y {
                    problems.push(format!("{file}: the evaluation differs from the uninterrupted run's"));
                }
            }
        }
    }
    for (file, _) in a.iter().filter(|(f, _)| f.ends_with("done.json")) {
        if !b.contains_key(file) {
            problems.push(format!("{file} is missing: a sweep run never finished"));
        }
    }
    Ok(problems)
}

/// The rows of an evaluation's `summary.json` without their timings (which differ between any two runs, as
/// does everything derived from them: the trade-off against raw path tracing's time).
fn metrics(bytes: &[u8]) -> Value {
    let rows = serde_json::from_slice::<Value>(bytes).map(|v| v["rows"].clone()).unwrap_or(Value::Null);
    match rows {
        Value::Array(rows) => Value::Array(
            rows.iter()
                .map(|r| match r {
                    Value::Object(m) => Value::Object(
                        m.iter()
                            .filter(|(k, _)| !k.ends_with("seconds"))
                            .map(|(k, v)| (k.clone(), v.clone()))
                            .collect(),
                    ),
                    other => other.clone(),
                })
                .collect(),
        ),
        other => other,
    }
}

/// Every file below `dir` (relative path) with its bytes.
fn files(dir: &Path) -> std::collections::BTreeMap<String, Vec<u8>> {
    crate::util::files_below(dir)
        .into_iter()
        .filter_map(|p| Some((crate::util::relative(&p, dir), std::fs::read(&p).ok()?)))
        .collect()
}
