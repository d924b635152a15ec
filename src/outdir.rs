//! Output folders: one writer at a time. Every command that writes results into a folder
//! (`sweep`, `device-report`, `isa`, `conformance`, `report`) first claims it with
//! [`OutDir::claim`]: the folder is checked (a path that exists and is not a folder is refused
//! before any work) and a lock file, [`LOCK_FILE`], is created in it atomically
//! (`O_CREAT|O_EXCL`), naming the holder. Two runs into one folder would each rewrite
//! `results.csv` from the rows it holds, and one run's rows would vanish; the second is
//! refused instead, naming the first, and touches nothing.
//!
//! The lock goes when its [`OutDirLock`] is dropped (on error paths too). A panic, a kill or
//! a power cut leaves it; a lock whose process no longer runs on this host is taken for stale
//! and replaced, saying so on stderr. The lock file is never a result: [`OutDir::entries`]
//! leaves it out of what a folder "already holds".

use serde::{Deserialize, Serialize};
use std::fs::OpenOptions;
use std::io::{ErrorKind, Read, Write};
use std::path::{Path, PathBuf};
use std::time::{Duration, SystemTime, UNIX_EPOCH};
use thiserror::Error;

/// The lock file's name, in the folder it locks.
pub const LOCK_FILE: &str = ".halftrace.lock";
/// Taken briefly by whoever removes a stale lock, so that two runs that both find one do not
/// both replace it (the second would remove the first's fresh lock).
const BREAK_FILE: &str = ".halftrace.lock.break";
/// A lock file that cannot be read as a [`Holder`] (its writer died between creating and
/// writing it) is taken for stale once it is this old; younger, its writer may still be at it.
const UNREADABLE_GRACE: Duration = Duration::from_secs(10);

#[derive(Debug, Error)]
pub enum OutDirError {
    #[error(
        "{flag} {path}: exists and is {what}; results go into a folder (halftrace never writes into or replaces \
         anything else) — name another path"
    )]
    NotAFolder { flag: String, path: PathBuf, what: &'static str },
    #[error(
        "{flag} {path}: another run is writing into it ({holder}); nothing was changed. Wait for it to finish or \
         choose another folder (if that process is gone, remove {lock})"
    )]
    Held { flag: String, path: PathBuf, holder: String, lock: PathBuf },
    #[error("{flag} {path}: {source}")]
    Io { flag: String, path: PathBuf, source: std::io::Error },
}

/// Who holds a lock: the lock file's contents (JSON).
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct Holder {
    pub pid: u32,
    pub host: String,
    /// The holder's command line (for the message a second writer gets).
    pub command: String,
    pub started_unix: u64,
    /// The process's start time in clock ticks since boot (`/proc/<pid>/stat`), so that a
    /// pid reused by another process after a kill is not taken for the holder.
    #[serde(default)]
    pub start_ticks: Option<u64>,
}

impl Holder {
    /// This process.
    pub fn current() -> Holder {
        let mut command: String = std::env::args()
            .collect::<Vec<_>>()
            .join(" ")
            .chars()
            .map(|c| if c.is_control() { ' ' } else { c })
            .collect();
        if command.chars().count() > 300 {
            command = command.chars().take(300).collect::<String>() + "…";
        }
        let started_unix = SystemTime::now().duration_since(UNIX_EPOCH).map_or(0, |d| d.as_secs());
        Holder {
            pid: std::process::id(),
            host: host_name(),
            command,
            started_unix,
            start_ticks: proc_stat(std::process::id()).and_then(|s| s.1),
        }
    }

    /// Whether the holder may still be running: on another host, or where `/proc` does not
    /// list processes, it cannot be told, so yes. A zombie (killed, not yet reaped: an orphan
    /// in a container whose init reaps nothing) has ended. (Through `/proc` rather than
    /// `kill(pid, 0)`: the `unsafe` of this crate stays in `gpu`.)
    fn may_run(&self) -> bool {
        if self.host != host_name() || !Path::new("/proc/self/stat").exists() {
            return true;
        }
        match proc_stat(self.pid) {
            Some((state, ticks)) => {
                !matches!(state, 'Z' | 'X') && !matches!((self.start_ticks, ticks), (Some(a), Some(b)) if a != b)
            }
            None => Path::new(&format!("/proc/{}", self.pid)).exists(),
        }
    }
}

impl std::fmt::Display for Holder {
    fn fmt(&self, f: &mut std::fmt::Formatter) -> std::fmt::Result {
        let now = SystemTime::now().duration_since(UNIX_EPOCH).map_or(0, |d| d.as_secs());
        write!(
            f,
            "pid {} on {}, `{}`, started {} s ago",
            self.pid,
            self.host,
            self.command,
            now.saturating_sub(self.started_unix)
        )
    }
}

/// The host name, to tell whether a lock's pid can be checked here.
fn host_name() -> String {
    std::fs::read_to_string("/proc/sys/kernel/hostname")
        .map(|h| h.trim().to_string())
        .or_else(|_| std::env::var("HOSTNAME"))
        .unwrap_or_default()
}

/// A process's state letter and start time in clock ticks since boot: fields 3 and 22 of
/// `/proc/<pid>/stat` (after the command name, which may hold spaces and parentheses).
fn proc_stat(pid: u32) -> Option<(char, Option<u64>)> {
    let stat = std::fs::read_to_string(format!("/proc/{pid}/stat")).ok()?;
    let mut fields = stat.rsplit_once(')')?.1.split_whitespace();
    let state = fields.next()?.chars().next()?;
    Some((state, fields.nth(18).and_then(|t| t.parse().ok())))
}

/// An output folder's policy, in one place: what it may be, who writes into it, what it holds.
pub struct OutDir;

impl OutDir {
    /// Refuses `path` (named by option `flag`, for messages) if it exists and is not a folder
    /// (after symbolic links: a link to a folder is a folder, writing into it replaces
    /// nothing); touches nothing.
    pub fn check(path: &Path, flag: &str) -> Result<(), OutDirError> {
        use std::os::unix::fs::FileTypeExt;
        let Ok(link) = std::fs::symlink_metadata(path) else { return Ok(()) };
        let what = match std::fs::metadata(path) {
            Ok(m) if m.is_dir() => return Ok(()),
            Err(_) if link.file_type().is_symlink() => "a symbolic link to nothing",
            Err(source) => return Err(OutDirError::Io { flag: flag.into(), path: path.into(), source }),
            Ok(m) => {
                let t = m.file_type();
                if t.is_file() {
                    "a regular file"
                } else if t.is_char_device() {
                    "a character device"
                } else if t.is_block_device() {
                    "a block device"
                } else if t.is_fifo() {
                    "a FIFO"
                } else if t.is_socket() {
                    "a socket"
                } else {
                    "not a folder"
                }
            }
        };
        Err(OutDirError::NotAFolder { flag: flag.into(), path: path.into(), what })
    }

    /// Claims `path` for this process until the returned lock is dropped: checks it
    /// ([`OutDir::check`]), creates it if missing, and takes its lock, replacing a stale one;
    /// refuses it, naming the holder, while another run holds it.
    pub fn claim(path: &Path, flag: &str) -> Result<OutDirLock, OutDirError> {
        Self::check(path, flag)?;
        let io = |source| OutDirError::Io { flag: flag.into(), path: path.into(), source };
        // The folders made here, deepest first: removed again if the run leaves them empty.
        let mut created = Vec::new();
        let mut p = path;
        while !p.as_os_str().is_empty() && std::fs::symlink_metadata(p).is_err() {
            created.push(p.to_path_buf());
            p = p.parent().unwrap_or(Path::new(""));
        }
        std::fs::create_dir_all(path).map_err(io)?;
        let holder = Holder::current();
        let file = path.join(LOCK_FILE);
        let me = serde_json::to_string_pretty(&holder).expect("a holder serialises");
        let mut last = String::new();
        for attempt in 0..60 {
            match OpenOptions::new().write(true).create_new(true).open(&file) {
                Ok(mut f) => {
                    let written = f.write_all(me.as_bytes()).and_then(|()| f.sync_all());
                    if let Err(e) = written {
                        let _ = std::fs::remove_file(&file);
                        remove_empty(&created);
                        return Err(io(e));
                    }
                    return Ok(OutDirLock { dir: path.into(), holder, created });
                }
                Err(e) if e.kind() == ErrorKind::AlreadyExists => {}
                Err(e) => {
                    remove_empty(&created);
                    return Err(io(e));
                }
            }
            let (text, age) = read_lock(&file);
            match serde_json::from_str::<Holder>(&text) {
                Ok(h) if h.may_run() => {
                    return Err(OutDirError::Held {
                        flag: flag.into(),
                        path: path.into(),
                        holder: h.to_string(),
                        lock: file,
                    });
                }
                Ok(h) => {
                    if break_stale(path, &text) {
                        eprintln!(
                            "warning: {}: replaced a stale lock ({h}: no such process runs on this host any more)",
                            file.display()
                        );
                    }
                }
                // Being written (or its writer died before it could): stale only once old.
                Err(_) if age.is_some_and(|a| a > UNREADABLE_GRACE) => {
                    if break_stale(path, &text) {
                        eprintln!(
                            "warning: {}: replaced an unreadable lock {} s old",
                            file.display(),
                            age.unwrap_or_default().as_secs()
                        );
                    }
                }
                Err(_) => last = "a process that is still writing the lock file".into(),
            }
            std::thread::sleep(Duration::from_millis(if attempt < 20 { 5 } else { 25 }));
        }
        Err(OutDirError::Held { flag: flag.into(), path: path.into(), holder: last, lock: file })
    }

    /// The names of what `path` holds, less the lock: what "a folder that already holds
    /// results" means (`NotFound`: no such folder).
    pub fn entries(path: &Path) -> std::io::Result<Vec<String>> {
        let mut names: Vec<String> = std::fs::read_dir(path)?
            .filter_map(|e| e.ok())
            .map(|e| e.file_name().to_string_lossy().into_owned())
            .filter(|n| n != LOCK_FILE && n != BREAK_FILE)
            .collect();
        names.sort();
        Ok(names)
    }
}

/// A lock file's text (empty when unreadable) and age.
fn read_lock(file: &Path) -> (String, Option<Duration>) {
    let mut text = String::new();
    let age = std::fs::metadata(file).ok().and_then(|m| m.modified().ok()).and_then(|t| t.elapsed().ok());
    if let Ok(mut f) = std::fs::File::open(file) {
        let _ = f.read_to_string(&mut text);
    }
    (text, age)
}

/// Removes `dir`'s lock if it still reads `seen` (stale), under the break file; whether it
/// did. A break file older than the grace period is itself stale (its taker died in these few
/// lines) and removed.
fn break_stale(dir: &Path, seen: &str) -> bool {
    let brk = dir.join(BREAK_FILE);
    if OpenOptions::new().write(true).create_new(true).open(&brk).is_err() {
        if read_lock(&brk).1.is_some_and(|a| a > UNREADABLE_GRACE) {
            let _ = std::fs::remove_file(&brk);
        }
        return false;
    }
    let file = dir.join(LOCK_FILE);
    let removed = read_lock(&file).0 == seen && std::fs::remove_file(&file).is_ok();
    let _ = std::fs::remove_file(&brk);
    removed
}

/// A claimed output folder ([`OutDir::claim`]); dropping it releases the folder.
#[derive(Debug)]
pub struct OutDirLock {
    dir: PathBuf,
    holder: Holder,
    created: Vec<PathBuf>,
}

impl OutDirLock {
    /// The folder.
    pub fn path(&self) -> &Path {
        &self.dir
    }
}

impl Drop for OutDirLock {
    fn drop(&mut self) {
        let file = self.dir.join(LOCK_FILE);
        // Only our own lock (had it been broken as stale, the file may be another run's now).
        if serde_json::from_str::<Holder>(&read_lock(&file).0).is_ok_and(|h| h == self.holder) {
            let _ = std::fs::remove_file(&file);
        }
        // A run that wrote nothing (a failed one) leaves no folder behind.
        remove_empty(&self.created);
    }
}

/// Removes the folders a claim made, deepest first, while they are empty.
fn remove_empty(created: &[PathBuf]) {
    for d in created {
        if std::fs::remove_dir(d).is_err() {
            break;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn tmp(name: &str) -> PathBuf {
        let d = std::env::temp_dir().join(format!("halftrace-outdir-{}-{name}", std::process::id()));
        let _ = std::fs::remove_dir_all(&d);
        d
    }

    /// A pid that ran and is gone (reaped).
    fn dead_pid() -> u32 {
        let mut c = std::process::Command::new("true").spawn().unwrap();
        let pid = c.id();
        c.wait().unwrap();
        pid
    }

    #[test]
    fn one_writer_at_a_time() {
        let d = tmp("held").join("deeper");
        let lock = OutDir::claim(&d, "--out").unwrap();
        assert!(d.join(LOCK_FILE).is_file());
        assert_eq!(OutDir::entries(&d).unwrap(), Vec::<String>::new(), "the lock is not a result");
        // A second claim (this process is alive) is refused, naming the holder; the folder is
        // as it was.
        let e = OutDir::claim(&d, "--out").unwrap_err().to_string();
        assert!(e.starts_with(&format!("--out {}: another run", d.display())), "{e}");
        assert!(e.contains(&format!("pid {} on ", std::process::id())) && e.contains(LOCK_FILE), "{e}");
        assert!(d.join(LOCK_FILE).is_file(), "the refused claim removed the holder's lock");
        std::fs::write(d.join("results.csv"), "x").unwrap();
        assert_eq!(OutDir::entries(&d).unwrap(), ["results.csv"]);
        drop(lock);
        assert!(!d.join(LOCK_FILE).exists(), "the lock outlived its guard");
        assert!(d.join("results.csv").is_file(), "a folder with results is kept");
        let again = OutDir::claim(&d, "--out").unwrap();
        drop(again);
        std::fs::remove_file(d.join("results.csv")).unwrap();
        // Folders the claim made, left empty, go with it.
        let top = d.parent().unwrap();
        drop(OutDir::claim(&top.join("a/b"), "--out").unwrap());
        assert!(top.join("deeper").is_dir() && !top.join("a").exists());
        std::fs::remove_dir_all(top).unwrap();
    }

    #[test]
    fn stale_and_unreadable_locks() {
        let d = tmp("stale");
        std::fs::create_dir_all(&d).unwrap();
        let file = d.join(LOCK_FILE);
        let dead = Holder { pid: dead_pid(), command: "halftrace sweep (killed)".into(), ..Holder::current() };
        std::fs::write(&file, serde_json::to_string(&dead).unwrap()).unwrap();
        let lock = OutDir::claim(&d, "--out").unwrap();
        let now: Holder = serde_json::from_str(&std::fs::read_to_string(&file).unwrap()).unwrap();
        assert_eq!(now.pid, std::process::id(), "the stale lock was not replaced");
        drop(lock);
        // The pid of a live process that is not the holder (started later than the lock says).
        let reused = Holder { start_ticks: Some(1), ..Holder::current() };
        std::fs::write(&file, serde_json::to_string(&reused).unwrap()).unwrap();
        drop(OutDir::claim(&d, "--out").unwrap());
        // A zombie (ended, not reaped yet) has ended.
        let mut zombie = std::process::Command::new("true").spawn().unwrap();
        while proc_stat(zombie.id()).is_some_and(|(state, _)| state != 'Z') {
            std::thread::sleep(Duration::from_millis(5));
        }
        let ended = Holder { pid: zombie.id(), start_ticks: None, ..Holder::current() };
        std::fs::write(&file, serde_json::to_string(&ended).unwrap()).unwrap();
        drop(OutDir::claim(&d, "--out").unwrap());
        zombie.wait().unwrap();
        // Another host's lock cannot be checked from here: held.
        let far = Holder { host: "elsewhere.example".into(), pid: dead_pid(), ..Holder::current() };
        std::fs::write(&file, serde_json::to_string(&far).unwrap()).unwrap();
        let e = OutDir::claim(&d, "--out").unwrap_err().to_string();
        assert!(e.contains("on elsewhere.example"), "{e}");
        // An empty lock just made is being written: held; an old one is stale.
        std::fs::write(&file, "").unwrap();
        let e = OutDir::claim(&d, "--out").unwrap_err().to_string();
        assert!(e.contains("still writing"), "{e}");
        let old = SystemTime::now() - Duration::from_secs(60);
        std::fs::File::options().write(true).open(&file).unwrap().set_modified(old).unwrap();
        drop(OutDir::claim(&d, "--out").unwrap());
        assert!(!file.exists());
        std::fs::remove_dir_all(&d).unwrap();
    }

    #[test]
    fn only_folders_are_claimed() {
        let d = tmp("kinds");
        std::fs::create_dir_all(&d).unwrap();
        let f = d.join("results.csv");
        std::fs::write(&f, "mine").unwrap();
        let e = OutDir::claim(&f, "--out").unwrap_err().to_string();
        assert!(e.starts_with(&format!("--out {}: exists and is a regular file", f.display())), "{e}");
        let e = OutDir::claim(Path::new("/dev/full"), "--out").unwrap_err().to_string();
        assert!(e.contains("a character device"), "{e}");
        let link = d.join("nowhere");
        std::os::unix::fs::symlink(d.join("missing"), &link).unwrap();
        let e = OutDir::claim(&link, "--out").unwrap_err().to_string();
        assert!(e.contains("a symbolic link to nothing"), "{e}");
        assert!(!d.join("missing").exists());
        let to_dir = d.join("to_dir");
        std::os::unix::fs::symlink(&d, &to_dir).unwrap();
        drop(OutDir::claim(&to_dir, "--out").unwrap());
        assert_eq!(std::fs::read(&f).unwrap(), b"mine");
        std::fs::remove_dir_all(&d).unwrap();
    }
}
