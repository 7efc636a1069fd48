//! The contract with `hush sweep-report`: a JSON plan of the sweeps to report on (`plan.json` in the report's
//! folder; read by `hush_eval::sweep::Plan`). It names the scale, and per sweep its description, its report's
//! folder and its runs: name, group (the name without the seed), seed, `hush train` flags and folder.

use std::path::{Path, PathBuf};
use std::process::Command;

use serde_json::{Value, json};

use super::exec::Layout;
use super::spec::{Run, Scale, Sweep, flags};
use crate::util::{Result, spawn, write_json};

fn path(p: &Path) -> Value {
    Value::String(p.display().to_string())
}

/// `[["key", "value"], ...]`: a run's `hush train` flags in their order.
fn pairs(train: &serde_json::Map<String, Value>) -> Value {
    let f = flags(train);
    f.chunks(2).map(|kv| json!([kv[0].trim_start_matches("--"), kv[1]])).collect()
}

/// The plan of `sweeps` at `scale` (with the report of every sweep when there are several).
pub fn plan(sweeps: &[Sweep], scale: &Scale, runs: &[Run], layout: &Layout) -> Value {
    let run = |r: &Run| {
        json!({
            "sweep": r.sweep, "name": r.name, "group": r.group(), "seed": r.seed,
            "train": pairs(&r.train), "dir": path(&layout.run(r, &scale.name)),
        })
    };
    let sweep = |s: &Sweep| {
        json!({
            "name": s.name, "description": s.description, "dir": path(&layout.sweep(&s.name, &scale.name)),
            "runs": runs.iter().filter(|r| r.sweep == s.name).map(run).collect::<Vec<_>>(),
        })
    };
    json!({
        "scale": {
            "name": scale.name, "scenes": scale.scenes, "dataset": flags(&scale.dataset),
            "train": flags(&scale.train), "seeds": scale.seeds,
        },
        "sweeps": sweeps.iter().map(sweep).collect::<Vec<_>>(),
        "all": if sweeps.len() > 1 { path(&layout.sweep("all", &scale.name)) } else { Value::Null },
    })
}

/// Writes the plan into the folder of the report it asks for and has `hush sweep-report` write the reports.
pub fn report(hush: &Path, sweeps: &[Sweep], scale: &Scale, runs: &[Run], layout: &Layout) -> Result<()> {
    let plan = plan(sweeps, scale, runs, layout);
    let dir: PathBuf = match (&plan["all"], sweeps) {
        (Value::String(all), _) => all.into(),
        (_, [one]) => layout.sweep(&one.name, &scale.name),
        _ => return Err("no sweep to report on".into()),
    };
    let file = dir.join("plan.json");
    write_json(&file, &plan)?;
    spawn(Command::new(hush).arg("sweep-report").arg("--plan").arg(&file))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sweep::spec::{parse_scales, parse_sweep};

    #[test]
    fn a_plan_names_every_run_with_its_flags_and_folder() {
        let scales = "[tiny]\nscenes=[\"a\"]\nseeds=[1, 2]\n[small]\nscenes=[\"a\"]\n[medium]\nscenes=[\"a\"]\n[thesis]\nscenes=[\"a\"]\n";
        let scale = parse_scales(scales, Path::new("s.toml")).unwrap().remove(0);
        let text =
            "[[axis]]\nname = \"arch\"\nvariants = [{ name = \"oidn\" }, { name = \"dae\", arch = \"autoencoder\" }]";
        let sweep = parse_sweep("architecture", text, Path::new("a.toml")).unwrap();
        let runs = sweep.runs(&scale);
        let layout = Layout { root: PathBuf::from("/sweeps") };
        let p = plan(std::slice::from_ref(&sweep), &scale, &runs, &layout);
        assert_eq!(p["all"], Value::Null);
        assert_eq!(p["scale"]["name"], "tiny");
        assert_eq!(p["sweeps"][0]["dir"], "/sweeps/architecture/tiny");
        let runs = p["sweeps"][0]["runs"].as_array().unwrap();
        assert_eq!(runs.len(), 4, "two variants × two seeds: {runs:?}");
        let dae = runs.iter().find(|r| r["name"] == "dae-s2").unwrap();
        assert_eq!((&dae["group"], &dae["seed"]), (&json!("dae"), &json!(2)));
        assert!(dae["train"].as_array().unwrap().contains(&json!(["arch", "autoencoder"])), "{dae}");
        assert_eq!(dae["dir"], "/sweeps/architecture/tiny/dae-s2");
        let two = plan(&[sweep.clone(), sweep], &scale, &[], &layout);
        assert_eq!(two["all"], "/sweeps/all/tiny");
    }
}
