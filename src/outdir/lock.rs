//! The lock that makes one run the only writer of an output folder ([`super::OutDir::claim`]):
//! a file created atomically in the folder, naming its [`Holder`], removed when the
//! [`OutDirLock`] is dropped; a lock whose process no longer runs on this host is stale.

use serde::{Deserialize, Serialize};
use std::fs::OpenOptions;
use std::io::Read;
use std::path::{Path, PathBuf};
use std::sync::Mutex;
use std::time::{Duration, SystemTime, UNIX_EPOCH};

/// The lock file's name, in the folder it locks.
pub const LOCK_FILE: &str = ".halftrace.lock";
/// Taken briefly by whoever removes a stale lock, so that two runs that both find one do not
/// both replace it (the second would remove the first's fresh lock).
pub(super) const BREAK_FILE: &str = ".halftrace.lock.break";
/// A lock file that cannot be read as a [`Holder`] (its writer died between creating and
/// writing it) is taken for stale once it is this old; younger, its writer may still be at it.
pub(super) const UNREADABLE_GRACE: Duration = Duration::from_secs(10);

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
    pub(super) fn may_run(&self) -> bool {
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
pub(super) fn host_name() -> String {
    std::fs::read_to_string("/proc/sys/kernel/hostname")
        .map(|h| h.trim().to_string())
        .or_else(|_| std::env::var("HOSTNAME"))
        .unwrap_or_default()
}

/// A process's state letter and start time in clock ticks since boot: fields 3 and 22 of
/// `/proc/<pid>/stat` (after the command name, which may hold spaces and parentheses).
pub(super) fn proc_stat(pid: u32) -> Option<(char, Option<u64>)> {
    let stat = std::fs::read_to_string(format!("/proc/{pid}/stat")).ok()?;
    let mut fields = stat.rsplit_once(')')?.1.split_whitespace();
    let state = fields.next()?.chars().next()?;
    Some((state, fields.nth(18).and_then(|t| t.parse().ok())))
}

/// A lock file's text (empty when unreadable) and age.
pub(super) fn read_lock(file: &Path) -> (String, Option<Duration>) {
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
pub(super) fn break_stale(dir: &Path, seen: &str) -> bool {
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

/// The locks this process holds (folder, holder), so that a signal that ends it releases them
/// first ([`release_on_signal`]).
static HELD: Mutex<Vec<(PathBuf, Holder)>> = Mutex::new(Vec::new());

fn held() -> std::sync::MutexGuard<'static, Vec<(PathBuf, Holder)>> {
    HELD.lock().unwrap_or_else(|e| e.into_inner())
}

/// Removes `dir`'s lock if it is `holder`'s.
fn release(dir: &Path, holder: &Holder) {
    let file = dir.join(LOCK_FILE);
    // Only our own lock (had it been broken as stale, the file may be another run's now).
    if serde_json::from_str::<Holder>(&read_lock(&file).0).is_ok_and(|h| h == *holder) {
        let _ = std::fs::remove_file(&file);
    }
}

/// Starts a thread that, on SIGTERM (a batch system stopping or requeueing a job), SIGINT
/// (Ctrl-C) or SIGHUP, removes every lock this process holds and ends it with 128 + the
/// signal's number, as the signal would have: a rerun or a requeued task — on this host or
/// another, where a holder's process cannot be looked up — finds the folder free. What the
/// run wrote stays whole (every file is written atomically; a sweep resumes from its rows).
pub fn release_on_signal() {
    use signal_hook::consts::{SIGHUP, SIGINT, SIGTERM};
    let Ok(mut signals) = signal_hook::iterator::Signals::new([SIGTERM, SIGINT, SIGHUP]) else { return };
    std::thread::spawn(move || {
        if let Some(sig) = signals.forever().next() {
            for (dir, holder) in held().iter() {
                release(dir, holder);
            }
            std::process::exit(128 + sig);
        }
    });
}

/// A claimed output folder ([`super::OutDir::claim`]); dropping it releases the folder.
#[derive(Debug)]
pub struct OutDirLock {
    pub(super) dir: PathBuf,
    pub(super) holder: Holder,
    pub(super) created: Vec<PathBuf>,
}

impl OutDirLock {
    /// The lock `holder` took on `dir` (`created`: the folders the claim made), released on
    /// drop or on a signal that ends the process.
    pub(super) fn new(dir: PathBuf, holder: Holder, created: Vec<PathBuf>) -> OutDirLock {
        held().push((dir.clone(), holder.clone()));
        OutDirLock { dir, holder, created }
    }

    /// The folder.
    pub fn path(&self) -> &Path {
        &self.dir
    }
}

impl Drop for OutDirLock {
    fn drop(&mut self) {
        let mut all = held();
        release(&self.dir, &self.holder);
        if let Some(i) = all.iter().position(|(d, h)| *d == self.dir && *h == self.holder) {
            all.remove(i);
        }
        drop(all);
        // A run that wrote nothing (a failed one) leaves no folder behind.
        remove_empty(&self.created);
    }
}

/// Removes the folders a claim made, deepest first, while they are empty.
pub(super) fn remove_empty(created: &[PathBuf]) {
    for d in created {
        if std::fs::remove_dir(d).is_err() {
            break;
        }
    }
}
