//! `cargo xtask fuzz`: coverage-guided fuzzing of hush's loaders with libFuzzer on stable Rust.
//!
//! The package `tests/fuzz` is built with LLVM's sanitizer-coverage passes (the flags cargo-fuzz passes,
//! without AddressSanitizer, which needs nightly; safe Rust needs it little) for the host triple, so that
//! build scripts and proc macros stay uninstrumented. Each target then runs in libFuzzer's fork mode (a
//! crash, an out-of-memory or a hang is recorded and fuzzing goes on) from a corpus of its seeds
//! (`tests/fuzz/seeds/<target>/`, where the EXR and weight files are those `HUSH_FUZZ_WRITE_SEEDS=<dir>
//! hush-fuzz` writes; the matching files under `data/`; every kept case of `tests/fuzz/regressions/<target>/`). Findings land in
//! `target/fuzz/artifacts/<target>/`; once fixed, a finding is copied into the regressions folder, which
//! the e2e test `fuzz_corpus` replays on every `cargo test`. A summary per target (executions, seconds,
//! coverage, findings) is written to `target/fuzz/summary.json`.
//!
//! The sweep TOML target compiles xtask's own parser (`sweep/spec.rs`) into the fuzz binary; its kept cases
//! are replayed by that file's unit tests.

use std::path::{Path, PathBuf};
use std::process::Command;

use serde_json::{Value, json};

use crate::args::{Flags, Known, Takes};
use crate::util::{Result, cargo, project_root, target_dir};

pub const USAGE: &str = "cargo xtask fuzz [TARGET ...] [--minutes N] [--max-len BYTES]";

/// The targets of `tests/fuzz/targets.rs`, and the files of `data/` each takes as seeds.
const TARGETS: &[(&str, &[&str])] = &[
    ("mitsuba", &["xml"]),
    ("obj", &["obj"]),
    ("gltf", &["gltf", "glb"]),
    ("exr", &["exr"]),
    ("weights", &[]),
    ("manifest", &[]),
    ("sweep", &["toml"]),
];

/// The sanitizer-coverage flags of cargo-fuzz (inline 8-bit counters, the PC table, comparison tracing).
const COVERAGE_FLAGS: &str = "-Cpasses=sancov-module -Cllvm-args=-sanitizer-coverage-level=4 \
     -Cllvm-args=-sanitizer-coverage-inline-8bit-counters -Cllvm-args=-sanitizer-coverage-pc-table \
     -Cllvm-args=-sanitizer-coverage-trace-compares --cfg fuzzing";

const HOST: &str = "x86_64-unknown-linux-gnu";

pub fn run(args: &[String]) -> Result<()> {
    const KNOWN: &Known = &[("--minutes", Takes::Number), ("--max-len", Takes::Number)];
    let flags = Flags::parse(args, KNOWN, TARGETS.len(), USAGE)?;
    let minutes: f64 = flags.number("--minutes", 10.0)?;
    let max_len: u64 = flags.number("--max-len", 65536)?;
    let names: Vec<&str> = if flags.positional.is_empty() {
        TARGETS.iter().map(|t| t.0).collect()
    } else {
        flags.positional.iter().map(String::as_str).collect()
    };
    for n in &names {
        if !TARGETS.iter().any(|t| t.0 == *n) {
            return Err(format!(
                "no fuzz target {n}; the targets are {:?}",
                TARGETS.iter().map(|t| t.0).collect::<Vec<_>>()
            ));
        }
    }
    let root = target_dir().join("fuzz");
    let exe = build(&root)?;
    let summary_path = root.join("summary.json");
    let mut summary: serde_json::Map<String, Value> =
        std::fs::read_to_string(&summary_path).ok().and_then(|t| serde_json::from_str(&t).ok()).unwrap_or_default();
    for name in names {
        let result = fuzz_one(&exe, name, &root, minutes, max_len)?;
        eprintln!("xtask fuzz: {name}: {result}");
        summary.insert(name.into(), result);
        crate::util::write_atomic(&summary_path, &serde_json::to_string_pretty(&summary).expect("json"))?;
    }
    eprintln!("xtask fuzz: summary in {}", summary_path.display());
    Ok(())
}

/// Builds `tests/fuzz` with coverage into `<root>` and returns the binary.
fn build(root: &Path) -> Result<PathBuf> {
    let mut cmd = Command::new(cargo());
    cmd.current_dir(project_root().join("tests/fuzz"))
        .args(["build", "--release", "--target", HOST])
        .env("CARGO_TARGET_DIR", root)
        .env("RUSTFLAGS", COVERAGE_FLAGS);
    crate::util::spawn(&mut cmd)?;
    Ok(root.join(HOST).join("release/hush-fuzz"))
}

/// The seed folder of `name`, filled afresh: its own seeds, the matching files of `data/` (64 KiB at
/// most each) and the kept regression cases.
fn seeds_of(name: &str, root: &Path) -> Result<PathBuf> {
    let dir = root.join("seeds").join(name);
    if dir.exists() {
        std::fs::remove_dir_all(&dir).map_err(|e| format!("cannot clear {}: {e}", dir.display()))?;
    }
    std::fs::create_dir_all(&dir).map_err(|e| format!("cannot create {}: {e}", dir.display()))?;
    let repo = project_root();
    let extensions = TARGETS.iter().find(|t| t.0 == name).map(|t| t.1).unwrap_or(&[]);
    let mut files = Vec::new();
    for folder in [repo.join("tests/fuzz/seeds").join(name), repo.join("tests/fuzz/regressions").join(name)] {
        files.extend(list(&folder, &|_| true));
    }
    if !extensions.is_empty() {
        files.extend(list(&repo.join("data"), &|p: &Path| {
            p.extension().and_then(|e| e.to_str()).is_some_and(|e| extensions.contains(&e))
                && p.metadata().is_ok_and(|m| m.len() <= 65536)
        }));
    }
    for (i, file) in files.iter().enumerate() {
        let base = file.file_name().map(|n| n.to_string_lossy().into_owned()).unwrap_or_default();
        std::fs::copy(file, dir.join(format!("{i:04}-{base}")))
            .map_err(|e| format!("cannot copy the seed {}: {e}", file.display()))?;
    }
    Ok(dir)
}

/// Every file under `dir` (recursively) that `keep` accepts, sorted.
fn list(dir: &Path, keep: &dyn Fn(&Path) -> bool) -> Vec<PathBuf> {
    crate::util::files_below(dir).into_iter().filter(|p| keep(p)).collect()
}

fn fuzz_one(exe: &Path, name: &str, root: &Path, minutes: f64, max_len: u64) -> Result<Value> {
    let seeds = seeds_of(name, root)?;
    let work = root.join("corpus").join(name);
    let artifacts = root.join("artifacts").join(name);
    for d in [&work, &artifacts] {
        std::fs::create_dir_all(d).map_err(|e| format!("cannot create {}: {e}", d.display()))?;
    }
    let seconds = (minutes * 60.0).round().max(1.0) as u64;
    let log = root.join(format!("{name}.log"));
    let log_file = std::fs::File::create(&log).map_err(|e| format!("cannot create {}: {e}", log.display()))?;
    let mut cmd = Command::new(exe);
    cmd.env("HUSH_FUZZ_TARGET", name)
        .arg(&work)
        .arg(&seeds)
        .arg(format!("-max_total_time={seconds}"))
        .arg(format!("-max_len={max_len}"))
        // A hang is an input that takes 10 s; an out-of-memory one that asks for 1 GiB at once or makes the
        // process 2 GiB large.
        .args(["-timeout=10", "-rss_limit_mb=2048", "-malloc_limit_mb=1024"])
        .args(["-fork=1", "-ignore_crashes=1", "-ignore_timeouts=1", "-ignore_ooms=1"])
        .arg(format!("-artifact_prefix={}/", artifacts.display()))
        .stderr(log_file.try_clone().map_err(|e| e.to_string())?)
        .stdout(log_file);
    eprintln!("xtask fuzz: {name} for {seconds} s (log: {})", log.display());
    let start = std::time::Instant::now();
    let status = cmd.status().map_err(|e| format!("cannot start {}: {e}", exe.display()))?;
    let elapsed = start.elapsed().as_secs_f64();
    let text = std::fs::read_to_string(&log).unwrap_or_default();
    let stats = last_stats(&text);
    let findings: Vec<String> =
        list(&artifacts, &|_| true).iter().map(|p| p.file_name().unwrap().to_string_lossy().into_owned()).collect();
    if !status.success() && stats.is_none() {
        return Err(format!("{name}: libFuzzer failed ({status}); see {}", log.display()));
    }
    let (execs, cov, oom, timeout, crash) = stats.unwrap_or_default();
    Ok(json!({
        "executions": execs,
        "seconds": elapsed.round(),
        "coverage": cov,
        "ooms": oom,
        "timeouts": timeout,
        "crashes": crash,
        "artifacts": findings,
    }))
}

/// The last status line of libFuzzer's fork mode (`#N: cov: C ... oom/timeout/crash: a/b/c ...`).
fn last_stats(log: &str) -> Option<(u64, u64, u64, u64, u64)> {
    let line = log.lines().rev().find(|l| l.starts_with('#') && l.contains("oom/timeout/crash:"))?;
    let execs = line[1..].split(':').next()?.trim().parse().ok()?;
    let after = |key: &str| line.split(key).nth(1).and_then(|r| r.split_whitespace().next());
    let cov = after("cov: ")?.parse().ok()?;
    let mut counts = after("oom/timeout/crash: ")?.split('/').map(|n| n.parse::<u64>().ok());
    Some((execs, cov, counts.next()??, counts.next()??, counts.next()??))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn reads_fork_mode_status_lines() {
        let log = "INFO: Seed: 1\n#10778: cov: 4387 ft: 5626 corp: 17 exec/s: 5389 oom/timeout/crash: 0/0/0 time: 2s\n\
                   #201233: cov: 5221 ft: 9140 corp: 633 exec/s: 4375 oom/timeout/crash: 1/2/3 time: 44s job: 8\n\
                   INFO: exiting: 0 time: 45s\n";
        assert_eq!(last_stats(log), Some((201233, 5221, 1, 2, 3)));
        assert_eq!(last_stats("INFO: nothing yet\n"), None);
    }
}
