//! Writing results without ever losing earlier ones: every file is written beside its target
//! under a temporary name and renamed into place, so an interrupt or a failed write leaves
//! the previous file whole.

use anyhow::Context;
use std::path::{Path, PathBuf};

/// The temporary name a file is written under before it is renamed to `path`: hidden, in the
/// same folder (so the rename is atomic), keeping the extension (so format detection works).
pub fn temp_path(path: &Path) -> PathBuf {
    let name = path.file_name().map(|n| n.to_string_lossy().to_string()).unwrap_or_default();
    path.with_file_name(format!(
        ".{name}.partial-{}.{}",
        std::process::id(),
        path.extension().map(|e| e.to_string_lossy().to_string()).unwrap_or_else(|| "tmp".into())
    ))
}

/// Writes `bytes` to `path` through a temporary file and a rename.
pub fn write_atomic(path: &Path, bytes: &[u8]) -> anyhow::Result<()> {
    with_temp(path, |tmp| std::fs::write(tmp, bytes).map_err(anyhow::Error::from))
}

/// Runs `write` on a temporary path beside `path`, then renames it into place; on failure
/// the temporary file is removed and `path` is untouched.
pub fn with_temp(path: &Path, write: impl FnOnce(&Path) -> anyhow::Result<()>) -> anyhow::Result<()> {
    let tmp = temp_path(path);
    let r = write(&tmp).and_then(|()| std::fs::rename(&tmp, path).map_err(anyhow::Error::from));
    if r.is_err() {
        let _ = std::fs::remove_file(&tmp);
    }
    r.with_context(|| format!("writing {}", path.display()))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_failed_write_keeps_the_old_file() {
        let d = std::env::temp_dir().join(format!("halftrace-fsx-{}", std::process::id()));
        std::fs::create_dir_all(&d).unwrap();
        let p = d.join("results.csv");
        write_atomic(&p, b"old").unwrap();
        let e = with_temp(&p, |tmp| {
            std::fs::write(tmp, b"half a")?;
            anyhow::bail!("disk full")
        });
        assert!(e.is_err());
        assert_eq!(std::fs::read(&p).unwrap(), b"old");
        assert_eq!(std::fs::read_dir(&d).unwrap().count(), 1, "temporary file left behind");
        write_atomic(&p, b"new").unwrap();
        assert_eq!(std::fs::read(&p).unwrap(), b"new");
        std::fs::remove_dir_all(&d).unwrap();
    }
}
