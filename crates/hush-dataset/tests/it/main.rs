//! Integration tests of hush-dataset (one binary; modules by topic). All tiny and fast; the reference-image
//! tests read `shared/reference/` beside the repository.

mod atomic;
mod dataset;
mod exr;
mod firefly;
mod image;
mod pfm;
mod png;
mod validate;

use std::path::{Path, PathBuf};

/// A fresh, empty directory for one test, removed when dropped.
pub struct TempDir(PathBuf);

impl TempDir {
    pub fn new(name: &str) -> TempDir {
        let dir = std::env::temp_dir().join(format!("hush-dataset-it-{}-{name}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        std::fs::create_dir_all(&dir).unwrap();
        TempDir(dir)
    }

    pub fn path(&self) -> &Path {
        &self.0
    }

    pub fn join(&self, name: &str) -> PathBuf {
        self.0.join(name)
    }

    /// The names of the files in the directory, sorted.
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
        "shared/ not found: expected it at {} (beside the repository root, i.e. <repo>/../shared); \
         it holds the reference EXR files these tests read",
        shared.display()
    );
    shared.join("reference").join(sub)
}

/// A small deterministic test image with distinct values everywhere.
pub fn ramp(w: usize, h: usize, c: usize, offset: f32) -> hush_dataset::Image {
    hush_dataset::Image::from_fn(w, h, c, |x, y, k| offset + x as f32 * 0.25 + y as f32 * 1.5 + k as f32 * 0.01)
}
