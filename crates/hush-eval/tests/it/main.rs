//! Integration tests of hush-eval (one binary, modules by topic).

mod browser;
mod external;
mod flip;
mod golden;
mod guided;
mod html;
mod metrics;
mod pictures;
mod reference_checks;
mod report;
mod sweep;
mod sweep_claims;
mod timing;
mod tonemap;
mod tradeoff;

use std::path::{Path, PathBuf};

/// A fresh, empty directory for one test, removed when dropped.
pub struct TempDir(PathBuf);

impl TempDir {
    pub fn new(name: &str) -> TempDir {
        let dir = std::env::temp_dir().join(format!("hush-eval-it-{}-{name}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        std::fs::create_dir_all(&dir).unwrap();
        TempDir(dir)
    }

    pub fn path(&self) -> &Path {
        &self.0
    }

    pub fn files(&self) -> Vec<String> {
        let mut names: Vec<String> = std::fs::read_dir(&self.0)
            .unwrap()
            .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
            .collect();
        names.sort();
        names
    }
}

impl Drop for TempDir {
    fn drop(&mut self) {
        let _ = std::fs::remove_dir_all(&self.0);
    }
}

/// `shared/reference/<sub>`: `shared/` sits beside the repository root (`<repo>/../shared`).
pub fn shared_reference(sub: &str) -> PathBuf {
    let shared = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../../shared");
    assert!(
        shared.is_dir(),
        "shared/ not found: expected it at {} (beside the repository root, i.e. <repo>/../shared)",
        shared.display()
    );
    shared.join("reference").join(sub)
}

/// `tests/it/fixtures/<name>`.
pub fn fixture(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/it/fixtures").join(name)
}
