//! Output folders: one policy for every command that writes results into a folder (`sweep`,
//! `device-report`, `isa`, `conformance`, `report`), in one place.
//!
//! - **Where.** A path that exists and is not a folder is refused before any work
//!   ([`OutDir::check`]); a missing one is created, and removed again if the run leaves it empty.
//! - **One writer.** The folder is claimed with [`OutDir::claim`]: a lock file, [`LOCK_FILE`],
//!   is created in it atomically (`O_CREAT|O_EXCL`), naming the holder. Two runs into one folder
//!   would each rewrite `results.csv` from the rows it holds, and one run's rows would vanish;
//!   the second is refused instead, naming the first, and touches nothing. The lock goes when
//!   its [`OutDirLock`] is dropped (on error paths too). A panic, a kill or a power cut leaves
//!   it; a lock whose process no longer runs on this host is taken for stale and replaced,
//!   saying so on stderr. The lock file is never a result: [`OutDir::entries`] leaves it out of
//!   what a folder "already holds".
//! - **What it may hold.** [`OutDir::claim_for`] checks what the folder holds against the
//!   [`OutMode`] asked for (`--resume`, `--force` or neither, [`OutMode::from_flags`]) and the
//!   command's [`Outputs`]: a folder with results is refused unless resumed (from the file a
//!   resume needs) or replaced, and `--force` replaces only the command's own files
//!   ([`Claimed::replace_own`]), never anything else there, and never a device, FIFO, socket or
//!   symbolic link. Every refusal names the folder, the files and the flags, and changes
//!   nothing.
//!
//! Files themselves are written through a temporary name and a rename (`fsx::write_atomic`), so
//! an interrupted run leaves the earlier ones whole.

mod lock;

use lock::{break_stale, read_lock, remove_empty, BREAK_FILE, UNREADABLE_GRACE};
pub use lock::{release_on_signal, Holder, OutDirLock, LOCK_FILE};

use crate::fsx::kind;
use std::fs::OpenOptions;
use std::io::{ErrorKind, Write};
use std::path::{Path, PathBuf};
use std::time::{Duration, SystemTime, UNIX_EPOCH};
use thiserror::Error;

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
    #[error(
        "{flag} {path}: its {lock_name} is {what}, not the lock file halftrace writes; nothing was changed — remove \
         {lock} (or choose another folder)"
    )]
    LockNotAFile { flag: String, path: PathBuf, lock_name: &'static str, what: &'static str, lock: PathBuf },
    #[error("{flag} {path}: {source}")]
    Io { flag: String, path: PathBuf, source: std::io::Error },
    #[error("--resume and --force exclude each other")]
    BothModes,
    #[error("{flag} {path} already holds {files}; nothing was changed. {hint}")]
    Holds { flag: String, path: PathBuf, files: String, hint: String },
    #[error("--resume: {flag} {path} has no {file} to resume (it holds {files}); nothing was changed. {hint}")]
    NoResume { flag: String, path: PathBuf, file: &'static str, files: String, hint: String },
    #[error(
        "{flag} {path}: its {name} is {what}, which halftrace never replaces or writes through; nothing was \
         changed — move it away, or choose another folder"
    )]
    Special { flag: String, path: PathBuf, name: String, what: &'static str },
    #[error("--force: removing {path}: {source}")]
    Remove { path: PathBuf, source: std::io::Error },
}

/// An output folder's policy, in one place: what it may be, who writes into it, what it holds.
pub struct OutDir;

impl OutDir {
    /// Refuses `path` (named by option `flag`, for messages) if it exists and is not a folder
    /// (after symbolic links: a link to a folder is a folder, writing into it replaces
    /// nothing); touches nothing.
    pub fn check(path: &Path, flag: &str) -> Result<(), OutDirError> {
        let Ok(link) = std::fs::symlink_metadata(path) else { return Ok(()) };
        let what = match std::fs::metadata(path) {
            Ok(m) if m.is_dir() => return Ok(()),
            Err(_) if link.file_type().is_symlink() => "a symbolic link to nothing",
            Err(source) => return Err(OutDirError::Io { flag: flag.into(), path: path.into(), source }),
            Ok(m) => kind(&m.file_type()),
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
                    return Ok(OutDirLock::new(path.into(), holder, created));
                }
                Err(e) if e.kind() == ErrorKind::AlreadyExists => {}
                Err(e) => {
                    remove_empty(&created);
                    return Err(io(e));
                }
            }
            // A folder (or anything but a file) in the lock's place is no lock: no run removes it.
            if let Ok(t) = std::fs::symlink_metadata(&file).map(|m| m.file_type()) {
                if !t.is_file() {
                    remove_empty(&created);
                    let (lock_name, what) = (LOCK_FILE, kind(&t));
                    return Err(OutDirError::LockNotAFile {
                        flag: flag.into(),
                        path: path.into(),
                        lock_name,
                        what,
                        lock: file,
                    });
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
                    let secs = age.unwrap_or_default().as_secs();
                    if break_stale(path, &text) {
                        eprintln!("warning: {}: replaced an unreadable lock {secs} s old", file.display());
                    } else {
                        last = format!(
                            "an unreadable lock, {secs} s old, which another run is replacing now ({} exists; if no \
                             run is, remove it too)",
                            path.join(BREAK_FILE).display()
                        );
                    }
                }
                Err(_) => last = "a process that is still writing the lock file".into(),
            }
            std::thread::sleep(Duration::from_millis(if attempt < 20 { 5 } else { 25 }));
        }
        if last.is_empty() {
            last = "an unreadable lock".into();
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

    /// Claims `path` ([`OutDir::claim`]) for a command that writes `outputs` into it, and
    /// checks what it holds against `mode`; refuses, changing nothing, a folder that holds
    /// files (anything, for a command whose folder is its alone; else its own files) unless
    /// `Resume` — from the file a resume needs — or `Force`, and, under either, one of the
    /// command's own names that is not what the command writes there (a regular file, or a
    /// folder where [`Outputs::folders`] says so): it would be replaced or written through. Removes nothing: [`Claimed::replace_own`] does, when the command is
    /// ready to.
    pub fn claim_for(path: &Path, flag: &str, mode: OutMode, outputs: &Outputs) -> Result<Claimed, OutDirError> {
        let lock = Self::claim(path, flag)?;
        let held =
            Self::entries(path).map_err(|source| OutDirError::Io { flag: flag.into(), path: path.into(), source })?;
        let own: Vec<String> = held.iter().filter(|n| (outputs.owns)(n)).cloned().collect();
        let blocking = if outputs.alone { &held } else { &own };
        if blocking.is_empty() {
            return Ok(Claimed { lock, flag: flag.into(), mode, resumes: false, held, own });
        }
        let (flag, path, files) = (flag.to_string(), path.to_path_buf(), list(blocking));
        match (mode, outputs.resume) {
            (OutMode::Resume, Some((file, _))) => {
                if !is_regular(&path.join(file)) {
                    return Err(OutDirError::NoResume { flag, path, file, files, hint: outputs.hint(false) });
                }
            }
            (OutMode::Force, _) if outputs.force => {}
            _ => return Err(OutDirError::Holds { flag, path, files, hint: outputs.hint(true) }),
        }
        for name in &own {
            let folder = outputs.folders.contains(&name.as_str());
            let t = std::fs::symlink_metadata(path.join(name)).map(|m| m.file_type());
            if let Some(t) = t.ok().filter(|t| if folder { !t.is_dir() } else { !t.is_file() }) {
                return Err(OutDirError::Special { flag, path, name: name.clone(), what: kind(&t) });
            }
        }
        Ok(Claimed { lock, flag, mode, resumes: mode == OutMode::Resume, held, own })
    }
}

/// What a command does with an output folder that already holds files.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub enum OutMode {
    /// Refuse it (the default: a user's results are never overwritten by accident).
    #[default]
    New,
    /// Continue from what it holds (a sweep's rows, a device report's finished steps).
    Resume,
    /// Replace the command's own files in it; nothing else there is touched.
    Force,
}

impl OutMode {
    /// The mode `--resume` and `--force` ask for (a command without one passes `false`); they
    /// exclude each other.
    pub fn from_flags(resume: bool, force: bool) -> Result<OutMode, OutDirError> {
        match (resume, force) {
            (true, true) => Err(OutDirError::BothModes),
            (true, false) => Ok(OutMode::Resume),
            (false, true) => Ok(OutMode::Force),
            (false, false) => Ok(OutMode::New),
        }
    }

    /// The flag that asks for this mode (none for `New`).
    pub fn flag(self) -> Option<&'static str> {
        match self {
            OutMode::New => None,
            OutMode::Resume => Some("--resume"),
            OutMode::Force => Some("--force"),
        }
    }
}

/// What a command writes into its output folder: the facts [`OutDir::claim_for`] decides by.
#[derive(Clone, Copy, Debug)]
pub struct Outputs {
    /// The command, for messages.
    pub command: &'static str,
    /// Whether a name in the folder is one of the command's files or folders: what `--force`
    /// replaces (nothing else there is ever touched).
    pub owns: fn(&str) -> bool,
    /// Of those, the ones that are folders; the rest are regular files. An own name of the
    /// other kind is not the command's (a user's folder called `report.md`) and is refused
    /// under `--resume` or `--force`, never replaced.
    pub folders: &'static [&'static str],
    /// The folder is the command's alone (a sweep's, a device report's): anything in it counts
    /// as held. Otherwise (`isa` and `conformance` may write into a sweep's folder, `report`
    /// beside other files) only the command's own files do.
    pub alone: bool,
    /// The file `--resume` continues from, and what resuming does (for messages); `None`: the
    /// command has no `--resume`.
    pub resume: Option<(&'static str, &'static str)>,
    /// Whether the command has `--force`.
    pub force: bool,
}

impl Outputs {
    /// The mode in which the command continues whatever an earlier run left in `path` (a
    /// device report's steps): `Resume` where the file a resume needs is there, else `Force`
    /// where the folder holds anything that would be refused, else `New`.
    pub fn mode_to_continue(&self, path: &Path) -> OutMode {
        let held = OutDir::entries(path).unwrap_or_default();
        match self.resume {
            Some((file, _)) if is_regular(&path.join(file)) => OutMode::Resume,
            _ if held.iter().any(|n| self.alone || (self.owns)(n)) => OutMode::Force,
            _ => OutMode::New,
        }
    }

    /// What a refused user may do instead, as a sentence.
    fn hint(&self, resume: bool) -> String {
        let mut ways = Vec::new();
        if let Some((_, does)) = self.resume.filter(|_| resume) {
            ways.push(format!("--resume to {does}"));
        }
        if self.force {
            ways.push(format!("--force to replace {}'s own files (nothing else there is touched)", self.command));
        }
        match ways.len() {
            0 => "Choose another folder".into(),
            _ => format!("Pass {}, or choose another folder", ways.join(", ")),
        }
    }
}

/// An output folder claimed for a command and checked against its mode
/// ([`OutDir::claim_for`]); dropping it releases the folder.
#[derive(Debug)]
pub struct Claimed {
    lock: OutDirLock,
    flag: String,
    mode: OutMode,
    resumes: bool,
    /// What the folder held when claimed, its lock aside (sorted names).
    pub held: Vec<String>,
    /// Of those, the command's own.
    pub own: Vec<String>,
}

impl Claimed {
    /// The folder.
    pub fn path(&self) -> &Path {
        self.lock.path()
    }

    /// The mode it was claimed in.
    pub fn mode(&self) -> OutMode {
        self.mode
    }

    /// Whether the run continues from what the folder holds: `--resume` into a folder that
    /// holds what would otherwise be refused (then the file a resume needs is there).
    pub fn resumes(&self) -> bool {
        self.resumes
    }

    /// Under `--force`, removes the command's own files and folders found at the claim — never
    /// anything else, never a device, FIFO, socket, link or a name of the wrong kind (refused
    /// at the claim); otherwise nothing. A command that writes its files whole at its end (`isa`, `conformance`) need not
    /// call it: each file is replaced by a rename as it is written, so a run that fails first
    /// leaves the earlier ones.
    pub fn replace_own(&self) -> Result<(), OutDirError> {
        if self.mode != OutMode::Force {
            return Ok(());
        }
        for name in &self.own {
            let p = self.path().join(name);
            let r = match std::fs::symlink_metadata(&p) {
                Ok(m) if m.is_dir() => std::fs::remove_dir_all(&p),
                Ok(m) if m.is_file() => std::fs::remove_file(&p),
                Ok(m) => {
                    let (flag, path, name) = (self.flag.clone(), self.path().into(), name.clone());
                    return Err(OutDirError::Special { flag, path, name, what: kind(&m.file_type()) });
                }
                Err(e) if e.kind() == ErrorKind::NotFound => Ok(()),
                Err(e) => Err(e),
            };
            r.map_err(|source| OutDirError::Remove { path: p, source })?;
        }
        Ok(())
    }
}

/// Whether `path` is a regular file (not through a link).
fn is_regular(path: &Path) -> bool {
    std::fs::symlink_metadata(path).is_ok_and(|m| m.is_file())
}

/// Names for a message: the first few, then how many more.
fn list(names: &[String]) -> String {
    const SHOWN: usize = 6;
    let mut s = names.iter().take(SHOWN).map(String::as_str).collect::<Vec<_>>().join(", ");
    if names.len() > SHOWN {
        s += &format!(" and {} more", names.len() - SHOWN);
    }
    s
}

/// `reports/[<command>-]<UTC timestamp>`: a command's default output folder.
pub fn default_out(command: Option<&str>) -> PathBuf {
    let secs = SystemTime::now().duration_since(UNIX_EPOCH).map(|d| d.as_secs()).unwrap_or(0) as i64;
    let (days, rem) = (secs.div_euclid(86400), secs.rem_euclid(86400));
    // civil-from-days (H. Hinnant)
    let z = days + 719_468;
    let era = z.div_euclid(146_097);
    let doe = z - era * 146_097;
    let yoe = (doe - doe / 1460 + doe / 36524 - doe / 146_096) / 365;
    let doy = doe - (365 * yoe + yoe / 4 - yoe / 100);
    let mp = (5 * doy + 2) / 153;
    let d = doy - (153 * mp + 2) / 5 + 1;
    let m = if mp < 10 { mp + 3 } else { mp - 9 };
    let y = yoe + era * 400 + if m <= 2 { 1 } else { 0 };
    let prefix = command.map(|c| format!("{c}-")).unwrap_or_default();
    PathBuf::from(format!("reports/{prefix}{y:04}{m:02}{d:02}-{:02}{:02}{:02}", rem / 3600, rem % 3600 / 60, rem % 60))
}

#[cfg(test)]
mod tests;
