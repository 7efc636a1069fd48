//! Every kept fuzz input (`tests/fuzz/regressions/<target>/`: the inputs that once crashed, hung or ran out
//! of memory, each fixed) and every seed (`tests/fuzz/seeds/<target>/`) replayed through the same code the
//! fuzzer ran (`tests/fuzz/targets.rs`): none may panic. `cargo xtask fuzz` finds new ones.

use std::cell::Cell;
use std::path::Path;

use crate::fuzz_targets::{TARGETS, run};

thread_local! {
    /// Whether this thread panicked, even where the panic was caught: the fuzzer's panic hook aborts on any
    /// panic, so a loader that catches one of its dependency's panics is still a finding there.
    static PANICKED: Cell<bool> = const { Cell::new(false) };
}

fn files(dir: &Path) -> Vec<std::path::PathBuf> {
    let mut out: Vec<_> = std::fs::read_dir(dir)
        .map(|d| d.flatten().map(|e| e.path()).filter(|p| p.is_file()).collect())
        .unwrap_or_default();
    out.sort();
    out
}

#[test]
fn fuzz_regressions_and_seeds_replay_without_a_panic() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../tests/fuzz");
    let previous = std::panic::take_hook();
    std::panic::set_hook(Box::new(move |info| {
        PANICKED.with(|p| p.set(true));
        previous(info);
    }));
    let mut replayed = 0;
    let mut failures = Vec::new();
    for (target, _) in TARGETS {
        for kind in ["regressions", "seeds"] {
            for file in files(&root.join(kind).join(target)) {
                let bytes = std::fs::read(&file).unwrap();
                PANICKED.with(|p| p.set(false));
                let outcome = std::panic::catch_unwind(|| run(target, &bytes));
                if outcome.is_ok() && PANICKED.with(Cell::get) {
                    failures.push(format!("{target}: {} panics (the panic is caught inside hush)", file.display()));
                }
                match outcome {
                    Ok(accepted) => {
                        // A seed is a valid file: the loader must accept it (a fixture that rots is caught here).
                        if kind == "seeds" && !accepted {
                            failures.push(format!("{target}: seed {} is refused", file.display()));
                        }
                    }
                    Err(_) => failures.push(format!("{target}: {} panics", file.display())),
                }
                replayed += 1;
            }
        }
    }
    assert!(replayed >= 10, "only {replayed} inputs found under {}", root.display());
    assert!(failures.is_empty(), "{}", failures.join("\n"));
}
