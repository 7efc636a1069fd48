//! Reading the files users give hush, bounded. Every reader of a scene, mesh, weight or manifest file goes
//! through [`read_limited`]: a file whose size is above its limit is refused before anything is read, one
//! that grows while it is read is refused after reading at most the limit, and a device or pipe (which can
//! never end, such as `/dev/zero`) is refused unread. Errors say what the path is: "no such file" only for a
//! path that does not exist, "is a directory" for a folder, "a symbolic link loop" for one.
//!
//! ```
//! let dir = std::env::temp_dir().join(format!("hush-io-doc-{}", std::process::id()));
//! std::fs::create_dir_all(&dir)?;
//! let file = dir.join("a.txt");
//! std::fs::write(&file, "hello")?;
//! let limit = |bytes| hush_io::Limit { bytes, var: "HUSH_MAX_TEXT_BYTES" };
//! assert_eq!(hush_io::read_limited(&file, limit(5), "text file")?, b"hello");
//! let err = hush_io::read_limited(&file, limit(4), "text file").unwrap_err().to_string();
//! assert!(err.contains("larger than the limit of 4 bytes") && err.contains("HUSH_MAX_TEXT_BYTES"), "{err}");
//! assert!(hush_io::read_limited(&dir, limit(10), "text file").unwrap_err().to_string().contains("is a directory"));
//! # std::fs::remove_dir_all(&dir)?;
//! # Ok::<(), std::io::Error>(())
//! ```

use std::io::{Error, ErrorKind, Read};
use std::path::Path;

/// A limit in bytes: the environment variable `var` when it is set to a number, else `default`.
pub fn limit_from_env(var: &str, default: u64) -> u64 {
    std::env::var(var).ok().and_then(|v| v.trim().parse().ok()).unwrap_or(default)
}

/// A size limit in bytes, and the environment variable that raises it (named in the refusal).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Limit {
    pub bytes: u64,
    pub var: &'static str,
}

impl Limit {
    /// The value of `var` where it is set to a number, else `default`.
    pub fn from_env(var: &'static str, default: u64) -> Limit {
        Limit { bytes: limit_from_env(var, default), var }
    }
}

/// Why a path cannot be read as a file. Its text ("no such file", "is a directory, not a file", ...) follows
/// the path in a message.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum Unreadable {
    /// Nothing is there: the only case called "no such file".
    Missing,
    Directory,
    /// A device, a pipe or a socket.
    NotRegular,
    DanglingLink,
    LinkLoop,
    PermissionDenied,
    /// Any other error of the file system, in its words.
    Other(String),
}

impl Unreadable {
    /// The I/O error kind of an error made from this: `NotFound` for a missing file only.
    pub fn kind(&self) -> ErrorKind {
        match self {
            Unreadable::Missing => ErrorKind::NotFound,
            _ => ErrorKind::InvalidInput,
        }
    }
}

impl std::fmt::Display for Unreadable {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(match self {
            Unreadable::Missing => "no such file",
            Unreadable::Directory => "is a directory, not a file",
            Unreadable::NotRegular => "is not a regular file (a device, pipe or socket): give hush a file",
            Unreadable::DanglingLink => "is a symbolic link to nothing (a dangling link)",
            Unreadable::LinkLoop => "is a symbolic link loop",
            Unreadable::PermissionDenied => "cannot be read: permission denied",
            Unreadable::Other(e) => e,
        })
    }
}

/// Why `path` cannot be read as a file: `None` when it is a regular file (symbolic links followed).
pub fn describe_unreadable(path: &Path) -> Option<Unreadable> {
    match std::fs::metadata(path) {
        Ok(m) if m.is_dir() => Some(Unreadable::Directory),
        Ok(m) if !m.is_file() => Some(Unreadable::NotRegular),
        Ok(_) => None,
        Err(e) => Some(match e.kind() {
            ErrorKind::NotFound => match std::fs::symlink_metadata(path) {
                Ok(_) => Unreadable::DanglingLink,
                Err(_) => Unreadable::Missing,
            },
            _ if e.raw_os_error() == Some(40) => Unreadable::LinkLoop,
            ErrorKind::PermissionDenied => Unreadable::PermissionDenied,
            _ => Unreadable::Other(e.to_string()),
        }),
    }
}

/// The whole of `path`, refused if it holds more than `limit` bytes. `what` names the file in errors
/// ("scene file", "weight file"). An error's message names the path and, for the limit, how to raise it.
pub fn read_limited(path: &Path, limit: Limit, what: &str) -> std::io::Result<Vec<u8>> {
    read_bounded(path, limit).map_err(|(kind, msg)| Error::new(kind, format!("{what} {}: {msg}", path.display())))
}

/// [`read_limited`] for callers whose errors name the path already: the message alone ("no such file",
/// "larger than the limit of ...").
pub fn read_limited_bare(path: &Path, limit: Limit) -> Result<Vec<u8>, String> {
    read_bounded(path, limit).map_err(|(_, msg)| msg)
}

fn read_bounded(path: &Path, limit: Limit) -> Result<Vec<u8>, (ErrorKind, String)> {
    if let Some(why) = describe_unreadable(path) {
        return Err((why.kind(), why.to_string()));
    }
    let file = std::fs::File::open(path).map_err(|e| (e.kind(), e.to_string()))?;
    let declared = file.metadata().map(|m| m.len()).unwrap_or(0);
    if declared > limit.bytes {
        return Err((ErrorKind::InvalidData, too_large(&format!("it holds {declared} bytes"), limit)));
    }
    let mut bytes = Vec::with_capacity(declared as usize);
    file.take(limit.bytes.saturating_add(1)).read_to_end(&mut bytes).map_err(|e| (e.kind(), e.to_string()))?;
    if bytes.len() as u64 > limit.bytes {
        return Err((ErrorKind::InvalidData, too_large("it grew past that while being read", limit)));
    }
    Ok(bytes)
}

/// [`read_limited`] as UTF-8 text.
pub fn read_text_limited(path: &Path, limit: Limit, what: &str) -> std::io::Result<String> {
    let bytes = read_limited(path, limit, what)?;
    String::from_utf8(bytes).map_err(|e| {
        Error::new(
            ErrorKind::InvalidData,
            format!("{what} {}: not UTF-8 text (byte {} is invalid)", path.display(), e.utf8_error().valid_up_to()),
        )
    })
}

fn too_large(seen: &str, limit: Limit) -> String {
    format!(
        "larger than the limit of {} bytes ({seen}); if the file is genuine, raise the limit with {}=<bytes>",
        limit.bytes, limit.var
    )
}

/// An exclusive lock on a folder that a job writes, held until it is dropped. The kernel releases it when
/// the process ends in any way, so a killed job leaves no stale lock and its resume takes the folder again.
#[derive(Debug)]
pub struct FolderLock {
    _file: std::fs::File,
}

/// Takes the lock of the folder `lock` lies in (the file `lock`, made if missing, with this process's id
/// written in it), or fails at once, naming the process that holds it, when another job writes the folder;
/// `job` names the command in that message ("`hush dataset`"). Jobs that may share a folder (a dataset's
/// shards) each lock a file of their own.
pub fn lock_folder(lock: &Path, job: &str) -> std::io::Result<FolderLock> {
    use std::io::{Seek, Write};
    let dir = lock.parent().unwrap_or(Path::new("."));
    let mut file = std::fs::OpenOptions::new()
        .read(true)
        .write(true)
        .create(true)
        .truncate(false)
        .open(lock)
        .map_err(|e| Error::new(e.kind(), format!("cannot open the lock file {}: {e}", lock.display())))?;
    match file.try_lock() {
        Ok(()) => {}
        Err(std::fs::TryLockError::WouldBlock) => {
            let mut holder = String::new();
            let _ = file.read_to_string(&mut holder);
            let holder = holder.trim();
            let by = if holder.is_empty() { String::new() } else { format!(" (process {holder})") };
            return Err(Error::new(
                ErrorKind::WouldBlock,
                format!(
                    "{} is being written by another {job}{by}: wait for it to finish, or give this one another folder",
                    dir.display()
                ),
            ));
        }
        Err(std::fs::TryLockError::Error(e)) => {
            return Err(Error::new(e.kind(), format!("cannot lock {}: {e}", lock.display())));
        }
    }
    // Who holds it, for the message above; a failure to write this only loses that detail.
    let _ = file.set_len(0).and_then(|()| file.rewind()).and_then(|()| write!(file, "{}", std::process::id()));
    Ok(FolderLock { _file: file })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_device_that_never_ends_is_refused_unread() {
        let err = read_limited(Path::new("/dev/zero"), Limit { bytes: 1 << 20, var: "X" }, "weight file").unwrap_err();
        assert!(err.to_string().contains("weight file /dev/zero: is not a regular file"), "{err}");
    }

    #[test]
    fn a_file_above_the_limit_is_refused_with_its_size() {
        let dir = std::env::temp_dir().join(format!("hush-io-size-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let file = dir.join("big.bin");
        std::fs::write(&file, [7u8; 100]).unwrap();
        let limit = |bytes| Limit { bytes, var: "HUSH_MAX_WEIGHT_BYTES" };
        let err = read_limited(&file, limit(99), "weight file").unwrap_err().to_string();
        assert!(err.contains("larger than the limit of 99 bytes (it holds 100 bytes)"), "{err}");
        assert!(err.contains("raise the limit with HUSH_MAX_WEIGHT_BYTES=<bytes>"), "{err}");
        assert_eq!(read_limited(&file, limit(100), "weight file").unwrap().len(), 100);
        std::fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn a_locked_folder_is_refused_until_its_lock_is_dropped() {
        let dir = std::env::temp_dir().join(format!("hush-io-lock-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let lock = dir.join(".hush.lock");
        let held = lock_folder(&lock, "`hush dataset`").unwrap();
        // A second open file description conflicts, as another process's would.
        let err = lock_folder(&lock, "`hush dataset`").unwrap_err().to_string();
        assert!(err.contains("is being written by another `hush dataset`"), "{err}");
        assert!(err.contains(&format!("(process {})", std::process::id())), "{err}");
        drop(held);
        drop(lock_folder(&lock, "`hush dataset`").unwrap());
        drop(lock_folder(&dir.join(".other.lock"), "`hush dataset`").unwrap());
        std::fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn missing_and_dangling_paths_are_told_apart() {
        let dir = std::env::temp_dir().join(format!("hush-io-test-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let missing = dir.join("missing.xml");
        assert_eq!(describe_unreadable(&missing), Some(Unreadable::Missing));
        assert_eq!(Unreadable::Missing.to_string(), "no such file");
        let link = dir.join("dangling.xml");
        let _ = std::fs::remove_file(&link);
        std::os::unix::fs::symlink(&missing, &link).unwrap();
        assert_eq!(describe_unreadable(&link), Some(Unreadable::DanglingLink));
        assert!(Unreadable::DanglingLink.to_string().contains("dangling"));
        let (a, b) = (dir.join("loop-a"), dir.join("loop-b"));
        let _ = (std::fs::remove_file(&a), std::fs::remove_file(&b));
        std::os::unix::fs::symlink(&b, &a).unwrap();
        std::os::unix::fs::symlink(&a, &b).unwrap();
        assert_eq!(describe_unreadable(&a), Some(Unreadable::LinkLoop));
        assert!(Unreadable::LinkLoop.to_string().contains("loop"));
        assert!(
            read_limited(&dir, Limit { bytes: 10, var: "X" }, "scene file")
                .unwrap_err()
                .to_string()
                .contains("is a directory")
        );
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
