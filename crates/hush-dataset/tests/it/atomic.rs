use std::io::Write;

use hush_dataset::write_atomic;

use crate::TempDir;

#[test]
fn success_replaces_the_target() {
    let dir = TempDir::new("atomic-ok");
    let target = dir.join("a.txt");
    std::fs::write(&target, "old").unwrap();
    let n = write_atomic(&target, |tmp| {
        assert_eq!(tmp.parent(), target.parent(), "the temporary file is in the target's directory");
        std::fs::write(tmp, "new").map(|_| 3)
    })
    .unwrap();
    assert_eq!(n, 3);
    assert_eq!(std::fs::read_to_string(&target).unwrap(), "new");
    assert_eq!(dir.files(), ["a.txt"]);
}

#[test]
fn error_leaves_the_old_target_and_no_temporary_file() {
    let dir = TempDir::new("atomic-err");
    let target = dir.join("a.txt");
    std::fs::write(&target, "old").unwrap();
    let result: std::io::Result<()> = write_atomic(&target, |tmp| {
        let mut f = std::fs::File::create(tmp)?;
        f.write_all(b"partial")?;
        Err(std::io::Error::other("disk full halfway"))
    });
    assert!(result.is_err());
    assert_eq!(std::fs::read_to_string(&target).unwrap(), "old");
    assert_eq!(dir.files(), ["a.txt"]);

    // No target before: still none after.
    let fresh = dir.join("b.txt");
    let result: std::io::Result<()> = write_atomic(&fresh, |tmp| {
        std::fs::write(tmp, "partial")?;
        Err(std::io::Error::other("failed"))
    });
    assert!(result.is_err());
    assert_eq!(dir.files(), ["a.txt"]);
}

#[test]
fn panic_leaves_no_temporary_file() {
    let dir = TempDir::new("atomic-panic");
    let target = dir.join("c.txt");
    let caught = std::panic::catch_unwind(|| {
        let _: std::io::Result<()> = write_atomic(&target, |tmp| {
            std::fs::write(tmp, "partial").unwrap();
            panic!("writer panicked");
        });
    });
    assert!(caught.is_err());
    assert!(dir.files().is_empty(), "{:?}", dir.files());
}

#[test]
fn missing_directory_is_a_clear_error() {
    let dir = TempDir::new("atomic-nodir");
    let target = dir.join("missing/sub/x.txt");
    let err = write_atomic(&target, |tmp| std::fs::write(tmp, "x")).unwrap_err().to_string();
    assert!(err.contains("does not exist") && err.contains("x.txt"), "{err}");
}
