//! Sweep definitions: `data/sweeps/scales.toml` (what every sweep shares at a scale: the dataset, the
//! training budget, evaluation flags, seeds) and one `data/sweeps/<name>.toml` per sweep (base settings,
//! per-scale overrides and axes of named variants), and the runs they enumerate.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use serde_json::{Map, Value};

use crate::util::Result;

pub const SCALES: [&str; 4] = ["tiny", "small", "medium", "thesis"];

/// `hush train` options a sweep may set (the flags without `--`; `dataset`, `out` and `seed` belong to
/// the sweep itself).
const TRAIN_KEYS: &[&str] = &[
    "init",
    "features",
    "spp",
    "arch",
    "head",
    "kernel-space",
    "width",
    "loss",
    "loss-space",
    "color-mean",
    "optimizer",
    "lr",
    "schedule",
    "epochs",
    "steps",
    "epoch-steps",
    "batch",
    "crop",
    "augment",
    "eval-every",
    "clip-grad-norm",
];

/// What every sweep shares at one scale.
#[derive(Clone, Debug, PartialEq)]
pub struct Scale {
    pub name: String,
    /// Scene files or folders for `hush dataset`, relative to the repository root unless absolute.
    pub scenes: Vec<String>,
    /// `hush dataset` flags.
    pub dataset: Map<String, Value>,
    /// `hush train` flags under every sweep's own.
    pub train: Map<String, Value>,
    /// `hush eval` flags.
    pub eval: Map<String, Value>,
    /// Every run is trained once per seed.
    pub seeds: Vec<u64>,
    /// Where each finished run's results are recorded (relative to the repository root unless absolute), so
    /// that a fresh clone skips them (`exec::record`); none for scales whose runs are cheap to redo.
    pub record: Option<PathBuf>,
    /// Where `hush train` and `hush eval` run their networks (`cpu` or `cuda`; `None`: hush's defaults). Not a
    /// train flag: where a run ran is not part of its identity, so a run recorded on a GPU restores on a CPU
    /// machine and the other way round.
    pub device: Option<String>,
}

impl Scale {
    /// The folder a run's results are recorded in, if the scale records them.
    pub fn record_of(&self, run: &Run) -> Option<PathBuf> {
        let root = self.record.as_ref()?;
        let root = if root.is_absolute() { root.clone() } else { crate::util::project_root().join(root) };
        Some(root.join(&run.sweep).join(&run.name))
    }
}

/// One sweep file.
#[derive(Clone, Debug, PartialEq)]
pub struct Sweep {
    pub name: String,
    pub description: String,
    base: Map<String, Value>,
    scale: BTreeMap<String, Map<String, Value>>,
    pub axes: Vec<Axis>,
}

#[derive(Clone, Debug, PartialEq)]
pub struct Axis {
    pub name: String,
    pub variants: Vec<Variant>,
}

#[derive(Clone, Debug, PartialEq)]
pub struct Variant {
    pub name: String,
    flags: Map<String, Value>,
    /// Per-scale flags over `flags` (`scale = { tiny = { width = 0.16 } }`).
    scale: BTreeMap<String, Map<String, Value>>,
}

/// One `hush train` + `hush eval` of a sweep at a scale.
#[derive(Clone, Debug, PartialEq)]
pub struct Run {
    pub sweep: String,
    /// The variants' names joined by `-` (`base` without axes), then `-s<seed>` with several seeds.
    pub name: String,
    /// (axis, variant) for every axis.
    pub variants: Vec<(String, String)>,
    pub seed: u64,
    /// The `hush train` flags, without dataset, out and seed.
    pub train: Map<String, Value>,
}

impl Run {
    /// The run's name without its seed suffix: runs that differ only in the seed share it.
    pub fn group(&self) -> String {
        if self.variants.is_empty() {
            "base".into()
        } else {
            self.variants.iter().map(|(_, v)| v.as_str()).collect::<Vec<_>>().join("-")
        }
    }
}

fn toml_to_json(text: &str, file: &Path) -> Result<Map<String, Value>> {
    let table: toml::Table = text.parse().map_err(|e| format!("{}: {e}", file.display()))?;
    match serde_json::to_value(table).map_err(|e| format!("{}: {e}", file.display()))? {
        Value::Object(map) => Ok(map),
        _ => Err(format!("{}: not a TOML table", file.display())),
    }
}

fn table(v: &Value, what: &str, file: &Path) -> Result<Map<String, Value>> {
    v.as_object().cloned().ok_or_else(|| format!("{}: `{what}` must be a table", file.display()))
}

fn check_keys(map: &Map<String, Value>, allowed: &[&str], what: &str, file: &Path) -> Result<()> {
    for key in map.keys() {
        if !allowed.contains(&key.as_str()) {
            return Err(format!("{}: unknown key `{key}` in {what}; allowed: {}", file.display(), allowed.join(", ")));
        }
    }
    Ok(())
}

fn train_flags(v: &Value, what: &str, file: &Path) -> Result<Map<String, Value>> {
    let map = table(v, what, file)?;
    for (key, value) in &map {
        if key == "device" {
            return Err(format!(
                "{}: `device` in {what}: the device is set per scale (`device = \"cuda\"` in scales.toml) or by \
                 `cargo xtask sweep --device`, not per run",
                file.display()
            ));
        }
        if !TRAIN_KEYS.contains(&key.as_str()) {
            return Err(format!(
                "{}: `{key}` in {what} is not a `hush train` option a sweep may set; use one of {} (dataset, out and \
                 seed are set by the sweep)",
                file.display(),
                TRAIN_KEYS.join(", ")
            ));
        }
        flag_value(value).map_err(|e| format!("{}: `{key}` in {what}: {e}", file.display()))?;
    }
    Ok(map)
}

/// Later settings override earlier ones; `epochs` and `steps` replace each other.
pub fn merge(into: &mut Map<String, Value>, from: &Map<String, Value>) {
    for (key, value) in from {
        match key.as_str() {
            "epochs" => drop(into.remove("steps")),
            "steps" => drop(into.remove("epochs")),
            _ => {}
        }
        into.insert(key.clone(), value.clone());
    }
}

/// A TOML value as a command-line argument: arrays are comma-separated.
fn flag_value(v: &Value) -> std::result::Result<String, String> {
    match v {
        Value::String(s) => Ok(s.clone()),
        Value::Number(n) => Ok(n.to_string()),
        Value::Bool(b) => Ok(b.to_string()),
        Value::Array(a) => Ok(a.iter().map(flag_value).collect::<std::result::Result<Vec<_>, _>>()?.join(",")),
        _ => Err(format!("{v} cannot be a command-line value")),
    }
}

/// `{lr = 1e-4, eval-every = 5}` → `--eval-every 5 --lr 0.0001` (keys in order).
pub fn flags(map: &Map<String, Value>) -> Vec<String> {
    let mut out = Vec::new();
    for (key, value) in map {
        out.push(format!("--{key}"));
        out.push(flag_value(value).expect("checked when parsed"));
    }
    out
}

/// Whether `name` is a device `hush train --device` and `hush eval --device` know.
pub fn is_device(name: &str) -> bool {
    matches!(name, "cpu" | "cuda")
}

/// Parses `scales.toml`.
pub fn parse_scales(text: &str, file: &Path) -> Result<Vec<Scale>> {
    let root = toml_to_json(text, file)?;
    check_keys(&root, &SCALES, "the scales file", file)?;
    let mut scales = Vec::new();
    for name in SCALES {
        let Some(v) = root.get(name) else {
            return Err(format!(
                "{}: no [{name}] table; every scale ({}) needs one",
                file.display(),
                SCALES.join(", ")
            ));
        };
        let s = table(v, name, file)?;
        check_keys(
            &s,
            &["description", "scenes", "dataset", "train", "eval", "seeds", "record", "device"],
            &format!("[{name}]"),
            file,
        )?;
        let record = match s.get("record") {
            None => None,
            Some(Value::String(r)) if !r.is_empty() => Some(PathBuf::from(r)),
            Some(_) => return Err(format!("{}: [{name}] record must be a folder path", file.display())),
        };
        let device = match s.get("device") {
            None => None,
            Some(Value::String(d)) if is_device(d) => Some(d.clone()),
            Some(d) => return Err(format!("{}: [{name}] device {d}: use \"cpu\" or \"cuda\"", file.display())),
        };
        let scenes = match s.get("scenes") {
            Some(Value::Array(a)) if !a.is_empty() => a
                .iter()
                .map(|v| v.as_str().map(String::from))
                .collect::<Option<Vec<_>>>()
                .ok_or_else(|| format!("{}: [{name}] scenes must be strings", file.display()))?,
            _ => return Err(format!("{}: [{name}] needs `scenes = [\"path\", ...]`", file.display())),
        };
        let empty = Value::Object(Map::new());
        let dataset = table(s.get("dataset").unwrap_or(&empty), &format!("[{name}] dataset"), file)?;
        for (key, value) in &dataset {
            if matches!(key.as_str(), "out" | "shard") {
                return Err(format!("{}: [{name}] dataset sets `{key}`, which the sweep sets", file.display()));
            }
            flag_value(value).map_err(|e| format!("{}: [{name}] dataset `{key}`: {e}", file.display()))?;
        }
        let train = train_flags(s.get("train").unwrap_or(&empty), &format!("[{name}] train"), file)?;
        let eval = table(s.get("eval").unwrap_or(&empty), &format!("[{name}] eval"), file)?;
        check_keys(&eval, &["spp", "timing-runs"], &format!("[{name}] eval"), file)?;
        let seeds = match s.get("seeds") {
            None => vec![0],
            Some(Value::Array(a)) if !a.is_empty() => a
                .iter()
                .map(Value::as_u64)
                .collect::<Option<Vec<_>>>()
                .ok_or_else(|| format!("{}: [{name}] seeds must be non-negative integers", file.display()))?,
            Some(_) => return Err(format!("{}: [{name}] seeds must be a non-empty list of integers", file.display())),
        };
        scales.push(Scale { name: name.into(), scenes, dataset, train, eval, seeds, record, device });
    }
    Ok(scales)
}

/// Parses one sweep file named `name`.
pub fn parse_sweep(name: &str, text: &str, file: &Path) -> Result<Sweep> {
    let root = toml_to_json(text, file)?;
    check_keys(&root, &["description", "base", "scale", "axis"], "the sweep", file)?;
    let description = root.get("description").and_then(Value::as_str).unwrap_or_default().to_string();
    let empty = Value::Object(Map::new());
    let base = train_flags(root.get("base").unwrap_or(&empty), "[base]", file)?;
    let scale = per_scale(root.get("scale"), "the sweep", file)?;
    let mut axes = Vec::new();
    for (i, a) in root.get("axis").and_then(Value::as_array).cloned().unwrap_or_default().iter().enumerate() {
        let a = table(a, &format!("[[axis]] {}", i + 1), file)?;
        check_keys(&a, &["name", "variants"], "[[axis]]", file)?;
        let axis = a
            .get("name")
            .and_then(Value::as_str)
            .ok_or_else(|| format!("{}: [[axis]] {} has no `name`", file.display(), i + 1))?
            .to_string();
        let mut variants = Vec::new();
        for v in a.get("variants").and_then(Value::as_array).cloned().unwrap_or_default() {
            let mut flags = table(&v, &format!("a variant of axis `{axis}`"), file)?;
            let vname = match flags.remove("name") {
                Some(Value::String(s)) if valid_name(&s) => s,
                _ => {
                    return Err(format!(
                        "{}: every variant of axis `{axis}` needs `name = \"...\"` (letters, digits, `_`, `.`)",
                        file.display()
                    ));
                }
            };
            if variants.iter().any(|v: &Variant| v.name == vname) {
                return Err(format!("{}: axis `{axis}` has two variants named `{vname}`", file.display()));
            }
            let what = format!("variant `{vname}` of axis `{axis}`");
            let scale = per_scale(flags.remove("scale").as_ref(), &what, file)?;
            let flags = train_flags(&Value::Object(flags), &what, file)?;
            variants.push(Variant { name: vname, flags, scale });
        }
        if variants.is_empty() {
            return Err(format!("{}: axis `{axis}` has no variants", file.display()));
        }
        axes.push(Axis { name: axis, variants });
    }
    Ok(Sweep { name: name.into(), description, base, scale, axes })
}

/// `{tiny = {...}, small = {...}}`: `hush train` flags per scale.
fn per_scale(v: Option<&Value>, what: &str, file: &Path) -> Result<BTreeMap<String, Map<String, Value>>> {
    let mut out = BTreeMap::new();
    let Some(v) = v else { return Ok(out) };
    for (s, v) in table(v, &format!("`scale` of {what}"), file)? {
        if !SCALES.contains(&s.as_str()) {
            return Err(format!("{}: scale `{s}` in {what}: no such scale; use {}", file.display(), SCALES.join(", ")));
        }
        out.insert(s.clone(), train_flags(&v, &format!("scale `{s}` of {what}"), file)?);
    }
    Ok(out)
}

fn valid_name(s: &str) -> bool {
    !s.is_empty() && s.chars().all(|c| c.is_ascii_alphanumeric() || c == '_' || c == '.')
}

impl Sweep {
    /// Every run at `scale`: the cartesian product of the axes (the first axis varies slowest), once
    /// per seed. Settings apply in the order scale, sweep base, the sweep's `[scale.<name>]`, variants.
    pub fn runs(&self, scale: &Scale) -> Vec<Run> {
        let mut combos: Vec<Vec<&Variant>> = vec![vec![]];
        for axis in &self.axes {
            combos = combos
                .into_iter()
                .flat_map(|c| {
                    axis.variants.iter().map(move |v| {
                        let mut c = c.clone();
                        c.push(v);
                        c
                    })
                })
                .collect();
        }
        let mut runs = Vec::new();
        for combo in combos {
            let mut train = scale.train.clone();
            merge(&mut train, &self.base);
            if let Some(o) = self.scale.get(&scale.name) {
                merge(&mut train, o);
            }
            for v in &combo {
                merge(&mut train, &v.flags);
                if let Some(o) = v.scale.get(&scale.name) {
                    merge(&mut train, o);
                }
            }
            let variants: Vec<(String, String)> =
                self.axes.iter().zip(&combo).map(|(a, v)| (a.name.clone(), v.name.clone())).collect();
            for &seed in &scale.seeds {
                let mut run = Run {
                    sweep: self.name.clone(),
                    name: String::new(),
                    variants: variants.clone(),
                    seed,
                    train: train.clone(),
                };
                run.name = if scale.seeds.len() > 1 { format!("{}-s{seed}", run.group()) } else { run.group() };
                runs.push(run);
            }
        }
        runs
    }
}

/// The sweep fuzz target (`cargo xtask fuzz sweep`): `text` as a sweep file and as a scales file, and
/// the runs of the sweep at each of the repository's scales. Returns whether the sweep parsed.
#[cfg(any(test, fuzzing))]
pub fn fuzz_entry(text: &str, scales: &[Scale]) -> bool {
    let file = Path::new("fuzz.toml");
    let _ = parse_scales(text, file);
    let Ok(sweep) = parse_sweep("fuzz", text, file) else { return false };
    for scale in scales {
        for run in sweep.runs(scale) {
            let _ = flags(&run.train);
        }
    }
    true
}

/// The sweep definitions folder.
pub fn sweeps_dir() -> PathBuf {
    crate::util::project_root().join("data/sweeps")
}

/// Loads the scale `name` from `dir/scales.toml`.
pub fn load_scale(dir: &Path, name: &str) -> Result<Scale> {
    let file = dir.join("scales.toml");
    let text = std::fs::read_to_string(&file).map_err(|e| format!("{}: {e}", file.display()))?;
    parse_scales(&text, &file)?
        .into_iter()
        .find(|s| s.name == name)
        .ok_or_else(|| format!("no scale `{name}`: use {}", SCALES.join(", ")))
}

/// The names of the sweeps in `dir` (every `*.toml` except `scales.toml`), sorted.
pub fn sweep_names(dir: &Path) -> Result<Vec<String>> {
    let mut names: Vec<String> = std::fs::read_dir(dir)
        .map_err(|e| format!("{}: {e}", dir.display()))?
        .filter_map(|e| e.ok()?.file_name().into_string().ok())
        .filter_map(|f| f.strip_suffix(".toml").map(String::from))
        .filter(|n| n != "scales")
        .collect();
    names.sort();
    Ok(names)
}

/// Loads the sweep `name` (`all`: every sweep) from `dir`.
pub fn load_sweeps(dir: &Path, name: &str) -> Result<Vec<Sweep>> {
    let names = sweep_names(dir)?;
    let chosen: Vec<String> = if name == "all" {
        names.clone()
    } else if names.iter().any(|n| n == name) {
        vec![name.to_string()]
    } else {
        return Err(format!("no sweep `{name}` in {}: use all or one of {}", dir.display(), names.join(", ")));
    };
    chosen
        .iter()
        .map(|n| {
            let file = dir.join(format!("{n}.toml"));
            let text = std::fs::read_to_string(&file).map_err(|e| format!("{}: {e}", file.display()))?;
            parse_sweep(n, &text, &file)
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    const SCALES_TOML: &str = r#"
[tiny]
scenes = ["data/scenes/cbox/scene.xml"]
dataset = { size = 32, spp = [4, 16] }
train = { epochs = 2, batch = 2, lr = 1e-3 }
eval = { timing-runs = 1 }
seeds = [0, 1]
[small]
scenes = ["a"]
record = "docs/results/sweeps-small/runs"
[medium]
scenes = ["m"]
[thesis]
scenes = ["b"]
train = { steps = 100 }
device = "cuda"
"#;

    const SWEEP_TOML: &str = r#"
description = "optimizers"
[base]
loss = "mix"
[scale.tiny]
steps = 7
[[axis]]
name = "optimizer"
variants = [{ name = "sgd", optimizer = "sgd", lr = 0.01, scale = { tiny = { lr = 0.1 } } }, { name = "adam", optimizer = "adam" }]
[[axis]]
name = "schedule"
variants = [{ name = "const", schedule = "constant" }, { name = "cosine", schedule = "cosine" }]
"#;

    fn scales() -> Vec<Scale> {
        parse_scales(SCALES_TOML, Path::new("scales.toml")).unwrap()
    }

    /// The sweep fuzz target's kept cases (`tests/fuzz/regressions/sweep/`) and the repository's sweeps,
    /// replayed as `cargo xtask fuzz sweep` ran them: none panics, and every real sweep parses.
    #[test]
    fn fuzz_regressions_replay() {
        let root = crate::util::project_root();
        let scales = load_scales_file(&root.join("data/sweeps/scales.toml"));
        let mut replayed = 0;
        for dir in ["tests/fuzz/regressions/sweep", "data/sweeps"] {
            let Ok(entries) = std::fs::read_dir(root.join(dir)) else { continue };
            for file in entries.flatten().map(|e| e.path()) {
                let text = std::fs::read_to_string(&file).unwrap_or_default();
                let parsed = fuzz_entry(&text, &scales);
                let is_sweep = dir == "data/sweeps" && !file.ends_with("scales.toml");
                assert!(parsed || !is_sweep, "{} does not parse", file.display());
                replayed += 1;
            }
        }
        assert!(replayed >= 5, "{replayed} files replayed");
    }

    fn load_scales_file(file: &Path) -> Vec<Scale> {
        parse_scales(&std::fs::read_to_string(file).unwrap(), file).unwrap()
    }

    #[test]
    fn scales_parse_with_defaults() {
        let s = scales();
        assert_eq!(s.iter().map(|s| s.name.as_str()).collect::<Vec<_>>(), SCALES);
        assert_eq!(s[0].seeds, vec![0, 1]);
        assert_eq!(s[1].seeds, vec![0]);
        assert_eq!(flags(&s[0].dataset), ["--size", "32", "--spp", "4,16"]);
        assert_eq!(flags(&s[0].eval), ["--timing-runs", "1"]);
        let run = parse_sweep("loss", "[base]\nloss = \"l1\"", Path::new("loss.toml")).unwrap().runs(&s[1]).remove(0);
        assert_eq!(
            (s[0].record_of(&run), s[1].record.as_deref()),
            (None, Some(Path::new("docs/results/sweeps-small/runs")))
        );
        assert!(s[1].record_of(&run).unwrap().ends_with("docs/results/sweeps-small/runs/loss/base"));
        let bad = SCALES_TOML.replace("record = \"docs/results/sweeps-small/runs\"", "record = 3");
        assert!(parse_scales(&bad, Path::new("scales.toml")).unwrap_err().contains("record must be a folder path"));
        assert_eq!((s[1].device.as_deref(), s[3].device.as_deref()), (None, Some("cuda")));
        let bad = SCALES_TOML.replace("device = \"cuda\"", "device = \"tpu\"");
        assert!(
            parse_scales(&bad, Path::new("scales.toml"))
                .unwrap_err()
                .contains("device \"tpu\": use \"cpu\" or \"cuda\"")
        );
    }

    #[test]
    fn runs_are_the_product_of_the_axes_per_seed() {
        let sweep = parse_sweep("optimizer", SWEEP_TOML, Path::new("optimizer.toml")).unwrap();
        let runs = sweep.runs(&scales()[0]);
        let names: Vec<&str> = runs.iter().map(|r| r.name.as_str()).collect();
        assert_eq!(
            names,
            [
                "sgd-const-s0",
                "sgd-const-s1",
                "sgd-cosine-s0",
                "sgd-cosine-s1",
                "adam-const-s0",
                "adam-const-s1",
                "adam-cosine-s0",
                "adam-cosine-s1"
            ]
        );
        // Scale, base, the sweep's per-scale override (steps replaces the scale's epochs), variants.
        let r = &runs[2];
        assert_eq!(r.group(), "sgd-cosine");
        assert_eq!(r.variants[1], ("schedule".to_string(), "cosine".to_string()));
        assert_eq!(
            flags(&r.train),
            [
                "--batch",
                "2",
                "--loss",
                "mix",
                "--lr",
                "0.1",
                "--optimizer",
                "sgd",
                "--schedule",
                "cosine",
                "--steps",
                "7"
            ]
        );
        // One seed: no suffix; the thesis scale's steps survive because the sweep overrides only tiny.
        let thesis = sweep.runs(&scales()[3]);
        assert_eq!(thesis[0].name, "sgd-const");
        assert_eq!(thesis[0].train["steps"], 100);
        assert_eq!(thesis[0].train["lr"], 0.01);
    }

    #[test]
    fn a_sweep_without_axes_has_one_base_run() {
        let sweep = parse_sweep("epochs", "[base]\nepochs = 3\n", Path::new("epochs.toml")).unwrap();
        let runs = sweep.runs(&scales()[1]);
        assert_eq!(runs.len(), 1);
        assert_eq!(runs[0].name, "base");
        assert_eq!(flags(&runs[0].train), ["--epochs", "3"]);
    }

    #[test]
    fn mistakes_name_the_file_and_the_fix() {
        let err = |text: &str| parse_sweep("x", text, Path::new("x.toml")).unwrap_err();
        assert!(err("[base]\nlearning-rate = 1").contains("x.toml: `learning-rate` in [base] is not a `hush train`"));
        assert!(err("[base]\nseed = 1").contains("set by the sweep"));
        assert!(err("[base]\ndevice = \"cuda\"").contains("the device is set per scale"));
        assert!(err("[scale.huge]\nlr = 1").contains("scale `huge` in the sweep: no such scale"));
        assert!(err("[[axis]]\nname = \"a\"\nvariants = [{ lr = 1 }]").contains("needs `name"));
        assert!(err("[[axis]]\nname = \"a\"\nvariants = []").contains("axis `a` has no variants"));
        assert!(err("bogus = 1").contains("unknown key `bogus`"));
        assert!(err("[base\n").contains("x.toml"));
        let e = parse_scales("[tiny]\nscenes = []\n", Path::new("s.toml")).unwrap_err();
        assert!(e.contains("s.toml: [tiny] needs `scenes"), "{e}");
    }

    #[test]
    fn the_repository_sweeps_parse_at_every_scale() {
        let dir = sweeps_dir();
        let names = sweep_names(&dir).unwrap();
        for want in ["architecture", "epochs", "features", "init", "loss", "optimizer"] {
            assert!(names.iter().any(|n| n == want), "data/sweeps/{want}.toml is missing");
        }
        for scale in SCALES {
            let scale = load_scale(&dir, scale).unwrap();
            for sweep in load_sweeps(&dir, "all").unwrap() {
                let runs = sweep.runs(&scale);
                assert!(!runs.is_empty(), "{} has no runs", sweep.name);
            }
        }
    }
}
