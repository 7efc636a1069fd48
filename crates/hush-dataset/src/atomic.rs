//! Atomic file replacement: write a temporary file beside the target, then rename it over the target.

use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU64, Ordering};

/// Writes `path` atomically: `write` receives a temporary path in the same directory and must create the
/// complete file there; on `Ok` the temporary file is synced and renamed over `path`, on `Err` (or a panic)
/// it is removed. Readers therefore see either the old file or the complete new one, never a partial one.
///
/// The temporary name is `.<file name>.<pid>.<n>.tmp`; `*.tmp` is git-ignored. The directory must exist.
/// Any error type that converts from `std::io::Error` works, so callers using `anyhow` can use this too.
///
/// ```
/// # fn main() -> hush_dataset::Result<()> {
/// let dir = std::env::temp_dir().join(format!("hush-doc-atomic-{}", std::process::id()));
/// std::fs::create_dir_all(&dir)?;
/// let target = dir.join("hello.txt");
/// hush_dataset::write_atomic(&target, |tmp| std::fs::write(tmp, "hello"))?;
/// assert_eq!(std::fs::read_to_string(&target)?, "hello");
/// # std::fs::remove_dir_all(&dir)?;
/// # Ok(())
/// # }
/// ```
pub fn write_atomic<T, E>(path: &Path, write: impl FnOnce(&Path) -> Result<T, E>) -> Result<T, E>
where
    E: From<std::io::Error>,
{
    let tmp = temp_path(path).map_err(E::from)?;
    let mut guard = RemoveOnDrop(Some(tmp.clone()));
    let value = write(&tmp)?;
    sync(&tmp).map_err(E::from)?;
    std::fs::rename(&tmp, path).map_err(|e| {
        E::from(std::io::Error::new(
            e.kind(),
            format!("{}: cannot rename {} over it: {e}", path.display(), tmp.display()),
        ))
    })?;
    guard.0 = None; // renamed: nothing left to remove
    Ok(value)
}

/// A fresh temporary path in the directory of `path`.
fn temp_path(path: &Path) -> std::io::Result<PathBuf> {
    static COUNTER: AtomicU64 = AtomicU64::new(0);
    let name = path.file_name().ok_or_else(|| {
        std::io::Error::new(std::io::ErrorKind::InvalidInput, format!("{}: not a file path", path.display()))
    })?;
    let dir = match path.parent() {
        Some(p) if !p.as_os_str().is_empty() => p,
        _ => Path::new("."),
    };
    if !dir.is_dir() {
        return Err(std::io::Error::new(
            std::io::ErrorKind::NotFound,
            format!("{}: directory {} does not exist; create it first", path.display(), dir.display()),
        ));
    }
    let n = COUNTER.fetch_add(1, Ordering::Relaxed);
    Ok(dir.join(format!(".{}.{}.{n}.tmp", name.to_string_lossy(), std::process::id())))
}

fn sync(tmp: &Path) -> std::io::Result<()> {
    let file = std::fs::File::open(tmp).map_err(|e| {
        std::io::Error::new(e.kind(), format!("{}: the writer returned Ok but left no file there: {e}", tmp.display()))
    })?;
    file.sync_all()
}

struct RemoveOnDrop(Option<PathBuf>);

impl Drop for RemoveOnDrop {
    fn drop(&mut self) {
        if let Some(p) = self.0.take() {
            let _ = std::fs::remove_file(p);
        }
    }
}
