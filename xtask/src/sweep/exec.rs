//! Running a sweep: the scale's dataset once, then every run (`hush train`, then `hush eval`) in its
//! own folder on N local workers. A run is complete when its `done.json` exists (written atomically
//! last, with the command lines and exit codes); complete runs are skipped, and an unfinished
//! `hush train` continues from its last checkpoint, so a killed sweep re-does only what was unfinished.

use std::fs::File;
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::sync::Mutex;
use std::sync::atomic::{AtomicUsize, Ordering};
use std::time::Instant;

use serde_json::{Value, json};

use super::spec::{Run, Scale, flags};
use crate::util::{Result, project_root, read_json, write_json};

/// Where a sweep's files go: `<root>/data/<scale>` and `<root>/<sweep>/<scale>/<run>`.
#[derive(Clone, Debug)]
pub struct Layout {
    pub root: PathBuf,
}

impl Layout {
    pub fn dataset(&self, scale: &str) -> PathBuf {
        self.root.join("data").join(scale)
    }
    pub fn sweep(&self, sweep: &str, scale: &str) -> PathBuf {
        self.root.join(sweep).join(scale)
    }
    pub fn run(&self, run: &Run, scale: &str) -> PathBuf {
        self.sweep(&run.sweep, scale).join(&run.name)
    }
}

/// What happened to one run.
#[derive(Clone, Debug, PartialEq)]
pub enum Outcome {
    /// Complete before this sweep started.
    Skipped,
    /// Trained and evaluated now, in this many seconds.
    Done(f64),
    /// Linked to the run named here, which has the same settings.
    Same(String),
    Failed(String),
}

/// The `hush dataset` arguments of a scale.
pub fn dataset_args(scale: &Scale, out: &Path) -> Vec<String> {
    let mut args = vec!["dataset".to_string()];
    for scene in &scale.scenes {
        let p = Path::new(scene);
        args.push(if p.is_absolute() { p.to_path_buf() } else { project_root().join(p) }.display().to_string());
    }
    args.extend(["--out".to_string(), out.display().to_string()]);
    args.extend(flags(&scale.dataset));
    args
}

/// The `hush train` and `hush eval` arguments of a run in `dir`.
pub fn run_args(run: &Run, scale: &Scale, dataset: &Path, dir: &Path) -> (Vec<String>, Vec<String>) {
    let d = dataset.display().to_string();
    let train_dir = dir.join("train");
    let mut train =
        vec!["train".into(), "--dataset".into(), d.clone(), "--out".into(), train_dir.display().to_string()];
    train.extend(["--seed".into(), run.seed.to_string()]);
    train.extend(flags(&run.train));
    let mut eval = vec!["eval".into(), "--dataset".into(), d, "--model".into()];
    eval.push(train_dir.join("model.safetensors").display().to_string());
    eval.extend(["--out".into(), dir.join("eval").display().to_string()]);
    // The networks as they are, without `hush eval`'s step that keeps pixels whose samples all agreed: the
    // study compares networks, and the recorded runs, which a fresh clone restores beside new ones, were
    // evaluated before the step existed.
    eval.extend(["--keep-exact".into(), "false".into()]);
    eval.extend(flags(&scale.eval));
    if let Some(device) = &scale.device {
        for args in [&mut train, &mut eval] {
            args.extend(["--device".into(), device.clone()]);
        }
    }
    (train, eval)
}

/// Renders the scale's dataset unless a `done.json` there records the same arguments (`hush dataset`
/// itself resumes image by image, so an interrupted dataset continues where it stopped).
pub fn prepare_dataset(hush: &Path, scale: &Scale, layout: &Layout) -> Result<PathBuf> {
    let out = layout.dataset(&scale.name);
    let args = dataset_args(scale, &out);
    let done = out.join("done.json");
    if let Ok(d) = read_json(&done)
        && d["args"] == json!(args)
    {
        eprintln!("sweep: dataset {} is complete", out.display());
        return Ok(out);
    }
    let start = Instant::now();
    eprintln!("$ {} {}", hush.display(), args.join(" "));
    let status =
        Command::new(hush).args(&args).status().map_err(|e| format!("cannot start {}: {e}", hush.display()))?;
    if !status.success() {
        return Err(format!("`hush {}` failed ({status}); re-run the sweep to resume it", args.join(" ")));
    }
    let record = json!({"args": args, "exit": 0, "seconds": start.elapsed().as_secs_f64()});
    write_json(&done, &record)?;
    Ok(out)
}

/// Whether a run is complete; warns when its `done.json` was made with other settings.
pub fn is_done(run: &Run, dir: &Path) -> bool {
    let Ok(done) = read_json(&dir.join("done.json")) else { return false };
    if done["train_flags"] != Value::Object(run.train.clone()) || done["seed"] != json!(run.seed) {
        eprintln!(
            "sweep: warning: {} was completed with other settings than the sweep file now gives; delete the folder to \
             re-run it",
            dir.display()
        );
    }
    true
}

/// The last lines of a log, to show why a command failed.
fn tail(path: &Path, lines: usize) -> String {
    let text = std::fs::read_to_string(path).unwrap_or_default();
    let all: Vec<&str> = text.lines().filter(|l| !l.trim().is_empty()).collect();
    all[all.len().saturating_sub(lines)..].join("\n    ")
}

/// Runs `hush <args>` with its output appended to `log`; returns the exit code and seconds.
fn exec(hush: &Path, args: &[String], log: &Path, threads: usize) -> Result<(i32, f64)> {
    let file = File::options().create(true).append(true).open(log).map_err(|e| format!("{}: {e}", log.display()))?;
    let err = file.try_clone().map_err(|e| format!("{}: {e}", log.display()))?;
    use std::io::Write;
    writeln!(&file, "$ {} {}", hush.display(), args.join(" ")).map_err(|e| format!("{}: {e}", log.display()))?;
    let start = Instant::now();
    let status = Command::new(hush)
        .args(args)
        .env("RAYON_NUM_THREADS", threads.to_string())
        .stdin(Stdio::null())
        .stdout(file)
        .stderr(err)
        .status()
        .map_err(|e| format!("cannot start {}: {e}", hush.display()))?;
    Ok((status.code().unwrap_or(-1), start.elapsed().as_secs_f64()))
}

/// Trains and evaluates one run in `dir` (skipping `hush train` when a previous attempt finished it),
/// then writes `done.json`.
/// A run that another process (a second sweep, a Slurm task) holds the lock of is left to it.
pub fn run_one(hush: &Path, run: &Run, scale: &Scale, dataset: &Path, dir: &Path, threads: usize) -> Outcome {
    if let Err(e) = restore(run, scale, dir) {
        return Outcome::Failed(e);
    }
    if is_done(run, dir) {
        return match record(run, scale, dir) {
            Ok(()) => Outcome::Skipped,
            Err(e) => Outcome::Failed(e),
        };
    }
    let lock = match lock(dir) {
        Ok(Some(lock)) => lock,
        Ok(None) => return Outcome::Failed(format!("another process is running it ({} is locked)", dir.display())),
        Err(e) => return Outcome::Failed(e),
    };
    // Whoever held the lock before may have finished it.
    if is_done(run, dir) {
        return Outcome::Skipped;
    }
    let outcome =
        match run_inner(hush, run, scale, dataset, dir, threads).and_then(|s| record(run, scale, dir).map(|()| s)) {
            Ok(s) => Outcome::Done(s),
            Err(e) => Outcome::Failed(e),
        };
    drop(lock);
    outcome
}

/// An exclusive lock on `dir/.lock` (released when the file closes, also when the process dies), or
/// `None` when another process holds it.
fn lock(dir: &Path) -> Result<Option<File>> {
    std::fs::create_dir_all(dir).map_err(|e| format!("{}: {e}", dir.display()))?;
    let path = dir.join(".lock");
    let file = File::options()
        .create(true)
        .truncate(false)
        .write(true)
        .open(&path)
        .map_err(|e| format!("{}: {e}", path.display()))?;
    // A child that another thread of this process is starting holds a copy of the descriptor (and so the
    // lock) until it executes its program; a lock still held after half a second belongs to a live holder.
    for _ in 0..50 {
        match file.try_lock() {
            Ok(()) => return Ok(Some(file)),
            Err(std::fs::TryLockError::WouldBlock) => std::thread::sleep(std::time::Duration::from_millis(10)),
            Err(std::fs::TryLockError::Error(e)) => return Err(format!("{}: {e}", path.display())),
        }
    }
    Ok(None)
}

fn run_inner(hush: &Path, run: &Run, scale: &Scale, dataset: &Path, dir: &Path, threads: usize) -> Result<f64> {
    std::fs::create_dir_all(dir).map_err(|e| format!("{}: {e}", dir.display()))?;
    let log = dir.join("run.log");
    let (train, eval) = run_args(run, scale, dataset, dir);
    let start = Instant::now();
    let mut commands = Vec::new();
    let trained = dir.join("train/summary.json").is_file() && dir.join("train/model.safetensors").is_file();
    for (args, skip) in [(&train, trained), (&eval, false)] {
        if skip {
            commands.push(json!({"args": args, "exit": 0, "seconds": null, "note": "finished by an earlier attempt"}));
            continue;
        }
        let (code, seconds) = exec(hush, args, &log, threads)?;
        commands.push(json!({"args": args, "exit": code, "seconds": seconds}));
        if code != 0 {
            return Err(format!("`hush {}` exited with {code}; {}:\n    {}", args[0], log.display(), tail(&log, 4)));
        }
    }
    let variants: serde_json::Map<String, Value> =
        run.variants.iter().map(|(a, v)| (a.clone(), Value::String(v.clone()))).collect();
    let done = json!({
        "sweep": run.sweep,
        "scale": scale.name,
        "run": run.name,
        "seed": run.seed,
        "variants": variants,
        "train_flags": run.train,
        "hush": hush.display().to_string(),
        "rayon_threads": threads,
        "load_average": crate::util::load_average(),
        "commands": commands,
        "seconds": start.elapsed().as_secs_f64(),
    });
    write_json(&dir.join("done.json"), &done)?;
    Ok(start.elapsed().as_secs_f64())
}

/// The files of a finished run that its record keeps: what `hush sweep-report` reads (`done.json` last).
const RECORDED: [&str; 4] = ["train/metrics.csv", "train/summary.json", "eval/summary.json", "done.json"];

/// What the scale's dataset is, as a record names it: its scenes as the scales file gives them (relative to the
/// repository) and its flags. A record is only used for a run of the same dataset.
fn dataset_identity(scale: &Scale) -> Value {
    json!({"scenes": scale.scenes, "flags": flags(&scale.dataset)})
}

/// Copies a finished run's results ([`RECORDED`]) into the scale's record folder ([`Scale::record_of`]),
/// unless they are there already: small files, meant to be committed, so that a fresh clone (or a machine
/// that lost `target/`) skips the run ([`restore`]). Paths in `done.json` are written relative to the
/// repository, or with the sweeps' folder as `<sweeps>`; the record is written into a temporary folder and
/// renamed into place, so a killed process leaves no half record.
pub fn record(run: &Run, scale: &Scale, dir: &Path) -> Result<()> {
    let Some(to) = scale.record_of(run) else { return Ok(()) };
    if to.join("done.json").is_file() {
        return Ok(());
    }
    let tmp = to.with_file_name(format!(".{}.tmp-{}", run.name, std::process::id()));
    let _ = std::fs::remove_dir_all(&tmp);
    for file in RECORDED {
        let from = dir.join(file);
        let dest = tmp.join(file);
        if let Some(parent) = dest.parent() {
            std::fs::create_dir_all(parent).map_err(|e| format!("{}: {e}", parent.display()))?;
        }
        if file == "done.json" {
            let mut done = read_json(&from)?;
            done["dataset"] = dataset_identity(scale);
            let text = serde_json::to_string_pretty(&done).map_err(|e| format!("{}: {e}", from.display()))?;
            let root = format!("{}/", project_root().display());
            let sweeps = dir.ancestors().nth(3).map(|p| p.display().to_string()).unwrap_or_default();
            let text = text.replace(&root, "");
            let text = if sweeps.is_empty() { text } else { text.replace(&sweeps, "<sweeps>") };
            std::fs::write(&dest, text + "\n").map_err(|e| format!("{}: {e}", dest.display()))?;
        } else if from.is_file() {
            std::fs::copy(&from, &dest).map_err(|e| format!("copying {}: {e}", from.display()))?;
        }
    }
    if let Some(parent) = to.parent() {
        std::fs::create_dir_all(parent).map_err(|e| format!("{}: {e}", parent.display()))?;
    }
    let _ = std::fs::remove_dir_all(&to);
    std::fs::rename(&tmp, &to).map_err(|e| format!("recording {} in {}: {e}", run.name, to.display()))
}

/// Where a run has no finished folder but the scale's record has it, with the same `hush train` flags, seed
/// and dataset, copies the record back into the folder, so that the run counts as complete and the report
/// reads it; a record of other settings is left alone with a warning (the run is redone, and its new
/// results are not recorded over the old: delete the record to replace it).
pub fn restore(run: &Run, scale: &Scale, dir: &Path) -> Result<()> {
    let Some(from) = scale.record_of(run) else { return Ok(()) };
    if dir.join("done.json").is_file() || !from.join("done.json").is_file() {
        return Ok(());
    }
    let done = read_json(&from.join("done.json"))?;
    if done["train_flags"] != Value::Object(run.train.clone())
        || done["seed"] != json!(run.seed)
        || done["dataset"] != dataset_identity(scale)
    {
        eprintln!(
            "sweep: warning: the record {} has other settings than the sweep now gives; {}/{} is run again",
            from.display(),
            run.sweep,
            run.name
        );
        return Ok(());
    }
    // done.json last: until it is there the folder is an unfinished run.
    for file in RECORDED {
        let (src, dest) = (from.join(file), dir.join(file));
        if !src.is_file() {
            continue;
        }
        if let Some(parent) = dest.parent() {
            std::fs::create_dir_all(parent).map_err(|e| format!("{}: {e}", parent.display()))?;
        }
        crate::util::write_atomic_with(&dest, |tmp| std::fs::copy(&src, tmp).map(drop))
            .map_err(|e| format!("restoring {}: {e}", dest.display()))?;
    }
    eprintln!("sweep: {}/{} restored from its record {}", run.sweep, run.name, from.display());
    Ok(())
}

/// `to` relative to the folder `from` (both absolute, or both relative to the same folder).
fn relative(from: &Path, to: &Path) -> PathBuf {
    let (f, t): (Vec<_>, Vec<_>) = (from.components().collect(), to.components().collect());
    let common = f.iter().zip(&t).take_while(|(a, b)| a == b).count();
    let mut out: PathBuf = std::iter::repeat_n("..", f.len() - common).collect();
    out.extend(&t[common..]);
    out
}

/// Makes `alias` a relative symbolic link to the run folder `target`.
fn link(alias: &Path, target: &Path) -> Result<()> {
    let rel = relative(alias.parent().unwrap_or(Path::new("")), target);
    alias
        .parent()
        .map_or(Ok(()), std::fs::create_dir_all)
        .and_then(|()| symlink(&rel, alias))
        .map_err(|e| format!("cannot link {} to {}: {e}", alias.display(), rel.display()))
}

/// Runs every `(run, scale, dataset, dir)` on `workers` threads, each `hush` with `RAYON_NUM_THREADS =
/// threads`; prints a line per run and returns the outcomes in order. A run whose folder does not exist yet
/// and whose settings, seed, scale and dataset equal those of an earlier run here or of a complete run in
/// `elsewhere` (other sweeps' runs and folders: the baseline recurs across sweeps) is not trained again: its
/// folder becomes a symbolic link to that run's.
pub fn run_all(
    hush: &Path,
    runs: &[(Run, &Scale, PathBuf, PathBuf)],
    elsewhere: &[(Run, PathBuf)],
    workers: usize,
    threads: usize,
) -> Vec<Outcome> {
    let key = |run: &Run, scale: &Scale, dataset: &Path| {
        format!("{}|{}|{}|{}", Value::Object(run.train.clone()), run.seed, scale.name, dataset.display())
    };
    let mut first: std::collections::HashMap<String, usize> = std::collections::HashMap::new();
    let mut order = Vec::new();
    let mut aliases: Vec<(usize, PathBuf, String, Option<usize>)> = Vec::new();
    for (i, (run, scale, dataset, dir)) in runs.iter().enumerate() {
        let k = key(run, scale, dataset);
        if std::fs::symlink_metadata(dir).is_err() {
            if let Some(&p) = first.get(&k) {
                aliases.push((i, runs[p].3.clone(), format!("{}/{}", runs[p].0.sweep, runs[p].0.name), Some(p)));
                continue;
            }
            let done = elsewhere.iter().find(|(r, d)| {
                key(r, scale, dataset) == k
                    && d != dir
                    && d.join("done.json").is_file()
                    && !runs.iter().any(|j| &j.3 == d)
            });
            if let Some((r, d)) = done {
                aliases.push((i, d.clone(), format!("{}/{}", r.sweep, r.name), None));
                continue;
            }
        }
        first.entry(k).or_insert(i);
        order.push(i);
    }
    let next = AtomicUsize::new(0);
    let outcomes = Mutex::new(vec![Outcome::Skipped; runs.len()]);
    let finished = AtomicUsize::new(0);
    let report = |i: usize, outcome: &Outcome| {
        let k = finished.fetch_add(1, Ordering::SeqCst) + 1;
        let what = match outcome {
            Outcome::Skipped => "complete already".to_string(),
            Outcome::Done(s) => format!("done in {s:.1} s"),
            Outcome::Same(other) => format!("same settings as {other}: linked to it"),
            Outcome::Failed(e) => format!("FAILED: {e}"),
        };
        eprintln!("sweep: [{k}/{}] {}/{}: {what}", runs.len(), runs[i].0.sweep, runs[i].0.name);
    };
    std::thread::scope(|s| {
        for _ in 0..workers.max(1) {
            s.spawn(|| {
                while let Some(&i) = order.get(next.fetch_add(1, Ordering::SeqCst)) {
                    let (run, scale, dataset, dir) = &runs[i];
                    let outcome = run_one(hush, run, scale, dataset, dir, threads);
                    report(i, &outcome);
                    outcomes.lock().expect("no worker panics holding it")[i] = outcome;
                }
            });
        }
    });
    let mut outcomes = outcomes.into_inner().expect("no worker panicked");
    for (i, target, name, primary) in aliases {
        let outcome = match primary.map(|p| &outcomes[p]) {
            Some(Outcome::Failed(e)) => Outcome::Failed(e.clone()),
            _ => match link(&runs[i].3, &target) {
                Ok(()) => Outcome::Same(name),
                Err(e) => Outcome::Failed(e),
            },
        };
        report(i, &outcome);
        outcomes[i] = outcome;
    }
    outcomes
}

#[cfg(unix)]
fn symlink(target: &Path, link: &Path) -> std::io::Result<()> {
    std::os::unix::fs::symlink(target, link)
}

#[cfg(not(unix))]
fn symlink(_: &Path, _: &Path) -> std::io::Result<()> {
    Err(std::io::Error::other("symbolic links need unix; run the sweeps one by one"))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sweep::spec::{parse_scales, parse_sweep};

    fn fixture() -> (Scale, Vec<Run>) {
        let scales = "[tiny]\nscenes = [\"s.xml\"]\neval = { timing-runs = 1 }\n[small]\nscenes = [\"s\"]\n[medium]\nscenes = [\"s\"]\n[thesis]\n\
                      scenes = [\"s\"]\n";
        let scale = parse_scales(scales, Path::new("scales.toml")).unwrap().remove(0);
        let sweep = "[base]\nsteps = 2\n[[axis]]\nname = \"loss\"\nvariants = [{ name = \"a\", loss = \"l1\" }, \
                     { name = \"b\", loss = \"mse\" }]\n";
        let runs = parse_sweep("t", sweep, Path::new("t.toml")).unwrap().runs(&scale);
        (scale, runs)
    }

    fn scratch(name: &str) -> PathBuf {
        let dir = std::env::temp_dir().join(format!("xtask-sweep-{name}-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        std::fs::create_dir_all(&dir).unwrap();
        dir
    }

    /// A stand-in for `hush` that logs its subcommands, leaves a trained model behind `train`, and fails
    /// `eval` while a `fail` file exists.
    #[cfg(unix)]
    fn fake_hush(dir: &Path) -> PathBuf {
        use std::os::unix::fs::PermissionsExt;
        let exe = dir.join("fake-hush");
        let script = format!(
            "#!/bin/sh\n[ \"$1\" = probe ] && exit 0\necho \"$1\" >> {calls}\n\
             if [ \"$1\" = train ]; then mkdir -p \"$5\" && touch \"$5/summary.json\" \"$5/model.safetensors\"; fi\nif [ \"$1\" = eval ] && [ -e {fail} ]; then echo boom >&2; exit 3; fi\n\
             if [ \"$1\" = eval ]; then mkdir -p \"$7\" && echo '{{\"rows\": []}}' > \"$7/summary.json\"; fi\n\
             exit 0\n",
            calls = dir.join("calls").display(),
            fail = dir.join("fail").display()
        );
        std::fs::write(&exe, script).unwrap();
        std::fs::set_permissions(&exe, std::fs::Permissions::from_mode(0o755)).unwrap();
        // A child forked by another test thread may still hold the write descriptor of the script for a
        // moment, and Linux refuses to execute a file open for writing (ETXTBSY). Once one execution
        // succeeds, no descriptor is left to copy.
        for _ in 0..500 {
            match Command::new(&exe).arg("probe").status() {
                Err(e) if e.raw_os_error() == Some(26) => std::thread::sleep(std::time::Duration::from_millis(10)),
                other => {
                    assert!(other.expect("the fake hush runs").success());
                    break;
                }
            }
        }
        exe
    }

    #[test]
    fn a_locked_run_is_left_to_the_process_holding_the_lock() {
        let dir = scratch("lock");
        let (scale, runs) = fixture();
        let run_dir = dir.join("r");
        let held = lock(&run_dir).unwrap().expect("free");
        assert!(lock(&run_dir).unwrap().is_none());
        let out = run_one(Path::new("/nonexistent/hush"), &runs[0], &scale, &dir, &run_dir, 1);
        let Outcome::Failed(e) = out else { panic!("{out:?}") };
        assert!(e.contains("another process is running it"), "{e}");
        drop(held);
        assert!(lock(&run_dir).unwrap().is_some());
        let _ = std::fs::remove_dir_all(&dir);
    }

    /// A scale that records its runs keeps each finished run's results in its record folder, with no path of
    /// the machine in them; with the sweeps' folder gone (a fresh clone), the runs are restored from the record
    /// instead of being trained again, and a record of other settings is not used.
    #[cfg(unix)]
    #[test]
    fn recorded_runs_are_restored_instead_of_rerun() {
        let dir = scratch("record");
        let hush = fake_hush(&dir);
        let (mut scale, runs) = fixture();
        scale.record = Some(dir.join("record"));
        let layout = Layout { root: dir.join("sweeps") };
        let jobs: Vec<_> =
            runs.iter().map(|r| (r.clone(), &scale, dir.join("data"), layout.run(r, &scale.name))).collect();
        let calls = || std::fs::read_to_string(dir.join("calls")).unwrap_or_default();
        assert!(run_all(&hush, &jobs, &[], 2, 1).iter().all(|o| matches!(o, Outcome::Done(_))));
        let rec = dir.join("record/t/b");
        let done = std::fs::read_to_string(rec.join("done.json")).unwrap();
        assert!(rec.join("eval/summary.json").is_file() && rec.join("train/summary.json").is_file());
        assert!(!done.contains(&dir.join("sweeps").display().to_string()) && done.contains("<sweeps>/"), "{done}");
        assert!(!rec.join("train/model.safetensors").exists(), "weights are not recorded");

        // A fresh clone: no sweeps folder, the record committed. Nothing is trained or evaluated.
        std::fs::remove_dir_all(dir.join("sweeps")).unwrap();
        std::fs::write(dir.join("calls"), "").unwrap();
        assert_eq!(run_all(&hush, &jobs, &[], 2, 1), [Outcome::Skipped, Outcome::Skipped]);
        assert_eq!(calls(), "");
        assert!(jobs[1].3.join("done.json").is_file() && jobs[1].3.join("eval/summary.json").is_file());

        // A record of other settings (here another dataset) is not used: the run is done again.
        std::fs::remove_dir_all(dir.join("sweeps")).unwrap();
        scale.dataset.insert("size".into(), json!(48));
        let jobs: Vec<_> =
            runs.iter().map(|r| (r.clone(), &scale, dir.join("data"), layout.run(r, &scale.name))).collect();
        assert!(run_all(&hush, &jobs, &[], 1, 1).iter().all(|o| matches!(o, Outcome::Done(_))));
        assert_eq!(calls(), "train\neval\ntrain\neval\n");
        let _ = std::fs::remove_dir_all(&dir);
    }

    #[test]
    fn relative_paths() {
        assert_eq!(
            relative(Path::new("/s/loss/tiny"), Path::new("/s/features/tiny/dsnn")),
            Path::new("../../features/tiny/dsnn")
        );
        assert_eq!(relative(Path::new("/s/a"), Path::new("/s/a/b")), Path::new("b"));
    }

    #[cfg(unix)]
    #[test]
    fn a_run_with_the_settings_of_an_earlier_one_is_linked_to_it() {
        let dir = scratch("same");
        let hush = fake_hush(&dir);
        let (scale, runs) = fixture();
        let layout = Layout { root: dir.join("sweeps") };
        let mut copy = runs[1].clone();
        copy.sweep = "u".into();
        let jobs: Vec<_> = [runs[0].clone(), runs[1].clone(), copy]
            .into_iter()
            .map(|r| {
                let d = layout.run(&r, &scale.name);
                (r, &scale, dir.join("data"), d)
            })
            .collect();
        let out = run_all(&hush, &jobs, &[], 2, 1);
        assert!(matches!(out[1], Outcome::Done(_)));
        assert_eq!(out[2], Outcome::Same("t/b".into()));
        // Two runs trained and evaluated, in any order; the third not.
        let mut calls: Vec<String> =
            std::fs::read_to_string(dir.join("calls")).unwrap().lines().map(String::from).collect();
        calls.sort();
        assert_eq!(calls, ["eval", "eval", "train", "train"]);
        assert_eq!(std::fs::read_link(&jobs[2].3).unwrap(), Path::new("../../t/tiny/b"));
        assert!(jobs[2].3.join("done.json").is_file());
        // Next time the link is a complete run.
        assert_eq!(run_all(&hush, &jobs, &[], 1, 1), [Outcome::Skipped, Outcome::Skipped, Outcome::Skipped]);
        // A later invocation of another sweep links to the complete run of an earlier one.
        let mut other = runs[0].clone();
        other.sweep = "v".into();
        let dir_v = layout.run(&other, &scale.name);
        let elsewhere = vec![(runs[0].clone(), jobs[0].3.clone())];
        let out = run_all(&hush, &[(other, &scale, dir.join("data"), dir_v.clone())], &elsewhere, 1, 1);
        assert_eq!(out, [Outcome::Same("t/a".into())]);
        assert_eq!(std::fs::read_link(&dir_v).unwrap(), Path::new("../../t/tiny/a"));
        let _ = std::fs::remove_dir_all(&dir);
    }

    #[test]
    fn arguments_of_a_run() {
        let (scale, runs) = fixture();
        let (train, eval) = run_args(&runs[1], &scale, Path::new("/d"), Path::new("/r/b"));
        assert_eq!(
            train,
            ["train", "--dataset", "/d", "--out", "/r/b/train", "--seed", "0", "--loss", "mse", "--steps", "2"]
        );
        assert_eq!(
            eval,
            [
                "eval",
                "--dataset",
                "/d",
                "--model",
                "/r/b/train/model.safetensors",
                "--out",
                "/r/b/eval",
                "--keep-exact",
                "false",
                "--timing-runs",
                "1"
            ]
        );
        // A scale's device goes to both commands, after everything else.
        let cuda = Scale { device: Some("cuda".into()), ..scale.clone() };
        let (train_cuda, eval_cuda) = run_args(&runs[1], &cuda, Path::new("/d"), Path::new("/r/b"));
        assert_eq!(
            (&train_cuda[..train.len()], &train_cuda[train.len()..]),
            (&train[..], &["--device".to_string(), "cuda".into()][..])
        );
        assert_eq!(
            (&eval_cuda[..eval.len()], &eval_cuda[eval.len()..]),
            (&eval[..], &["--device".to_string(), "cuda".into()][..])
        );
        let ds = dataset_args(&scale, Path::new("/o"));
        assert_eq!(ds[0], "dataset");
        assert!(ds[1].ends_with("/s.xml") && Path::new(&ds[1]).is_absolute());
        assert_eq!(&ds[2..], ["--out", "/o"]);
    }

    #[cfg(unix)]
    #[test]
    fn completed_runs_are_skipped_and_failed_ones_redone() {
        let dir = scratch("resume");
        let hush = fake_hush(&dir);
        let (scale, runs) = fixture();
        let layout = Layout { root: dir.join("sweeps") };
        let jobs: Vec<_> =
            runs.iter().map(|r| (r.clone(), &scale, dir.join("data"), layout.run(r, &scale.name))).collect();
        let calls = || std::fs::read_to_string(dir.join("calls")).unwrap_or_default();

        // Run `a` was completed by an earlier sweep; `b` fails in eval.
        std::fs::write(dir.join("fail"), "").unwrap();
        let a = &jobs[0];
        assert!(matches!(run_one(&hush, &a.0, a.1, &a.2, &a.3, 1), Outcome::Failed(_)));
        std::fs::remove_file(dir.join("fail")).unwrap();
        assert!(matches!(run_one(&hush, &a.0, a.1, &a.2, &a.3, 1), Outcome::Done(_)));
        std::fs::write(dir.join("calls"), "").unwrap();
        std::fs::write(dir.join("fail"), "").unwrap();
        let out = run_all(&hush, &jobs, &[], 2, 1);
        assert_eq!(out[0], Outcome::Skipped);
        let Outcome::Failed(e) = &out[1] else { panic!("{out:?}") };
        assert!(e.contains("`hush eval` exited with 3") && e.contains("boom"), "{e}");
        assert!(!jobs[1].3.join("done.json").exists());
        assert_eq!(calls(), "train\neval\n");

        // Re-running re-does only `b`, and only its evaluation: its training had finished.
        std::fs::remove_file(dir.join("fail")).unwrap();
        std::fs::write(dir.join("calls"), "").unwrap();
        let out = run_all(&hush, &jobs, &[], 1, 1);
        assert_eq!(out[0], Outcome::Skipped);
        assert!(matches!(out[1], Outcome::Done(_)));
        assert_eq!(calls(), "eval\n");
        let done = read_json(&jobs[1].3.join("done.json")).unwrap();
        assert_eq!(done["commands"][1]["exit"], 0);
        assert_eq!(done["commands"][0]["args"][0], "train");
        assert_eq!(done["variants"]["loss"], "b");
        std::fs::write(dir.join("calls"), "").unwrap();
        assert_eq!(run_all(&hush, &jobs, &[], 2, 1), [Outcome::Skipped, Outcome::Skipped]);
        assert_eq!(calls(), "");
        let _ = std::fs::remove_dir_all(&dir);
    }
}
