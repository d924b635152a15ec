//! Writing results without ever losing earlier ones: every file is written beside its target
//! under a temporary name and renamed into place, so an interrupt or a failed write leaves
//! the previous file whole. A path that exists and is not a regular file (a folder, a
//! symbolic link, a device, a FIFO) is never written: the rename would replace it.

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

/// Reads an input file, refusing anything but a regular file (after symbolic links): a FIFO
/// without a writer would block forever, and a device such as /dev/zero never ends.
pub fn read_regular(path: &Path) -> std::io::Result<Vec<u8>> {
    let m = std::fs::metadata(path)?;
    if !m.is_file() {
        let what = if m.is_dir() { "a folder" } else { "not a regular file (a FIFO or a device?)" };
        return Err(std::io::Error::new(std::io::ErrorKind::InvalidInput, format!("is {what}")));
    }
    std::fs::read(path)
}

/// Whether two paths name one file: the same spelling, or the same file once links and `.`
/// or `..` are resolved (both must exist for the second).
pub fn same_file(a: &Path, b: &Path) -> bool {
    a == b || matches!((a.canonicalize(), b.canonicalize()), (Ok(x), Ok(y)) if x == y)
}

/// What a path that exists is, when it is not a regular file (`None`: absent or regular).
fn special(path: &Path) -> Option<&'static str> {
    let t = std::fs::symlink_metadata(path).ok()?.file_type();
    (!t.is_file()).then(|| kind(&t))
}

/// What a file type is, for messages ("a regular file", "a FIFO", …).
pub fn kind(t: &std::fs::FileType) -> &'static str {
    use std::os::unix::fs::FileTypeExt;
    if t.is_file() {
        "a regular file"
    } else if t.is_dir() {
        "a folder"
    } else if t.is_symlink() {
        "a symbolic link"
    } else if t.is_char_device() {
        "a character device"
    } else if t.is_block_device() {
        "a block device"
    } else if t.is_fifo() {
        "a FIFO"
    } else if t.is_socket() {
        "a socket"
    } else {
        "an unknown kind of file"
    }
}

/// Refuses an output (`flag`: the option that names it) that exists and is not a regular
/// file, before any work is done: halftrace writes new or regular files only, and never
/// replaces a folder, symbolic link, device or FIFO (not even one named on purpose).
pub fn check_output(flag: &str, path: &Path) -> anyhow::Result<()> {
    if let Some(what) = special(path) {
        anyhow::bail!(
            "{flag} {}: exists and is {what}; halftrace writes only new or regular files (it never replaces a \
             folder, symbolic link, device or FIFO) — name another path",
            path.display()
        );
    }
    Ok(())
}

/// Runs `write` on a temporary path beside `path`, then renames it into place; on failure
/// the temporary file is removed and `path` is untouched. A `path` that is not a regular
/// file is refused ([`check_output`]).
pub fn with_temp(path: &Path, write: impl FnOnce(&Path) -> anyhow::Result<()>) -> anyhow::Result<()> {
    if let Some(what) = special(path) {
        anyhow::bail!("writing {}: it exists and is {what}, which is never replaced", path.display());
    }
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
        // A symbolic link, a folder or a FIFO is never replaced.
        let link = d.join("link.csv");
        std::os::unix::fs::symlink(&p, &link).unwrap();
        let e = write_atomic(&link, b"x").unwrap_err().to_string();
        assert!(e.contains("symbolic link"), "{e}");
        assert!(std::fs::symlink_metadata(&link).unwrap().file_type().is_symlink());
        assert_eq!(std::fs::read(&p).unwrap(), b"new");
        let e = check_output("--out", &d).unwrap_err().to_string();
        assert!(e.starts_with("--out ") && e.contains("a folder"), "{e}");
        std::fs::remove_file(&link).unwrap();
        std::fs::remove_dir_all(&d).unwrap();
    }
}
