//! The output-folder policy's tests: claims, modes, locks, stale and live holders.

use super::lock::proc_stat;
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
    // An old unreadable lock that another run is breaking (a fresh break file): held, and the
    // message says so instead of naming an empty holder.
    std::fs::write(&file, "").unwrap();
    std::fs::File::options().write(true).open(&file).unwrap().set_modified(old).unwrap();
    std::fs::write(d.join(BREAK_FILE), "").unwrap();
    let e = OutDir::claim(&d, "--out").unwrap_err().to_string();
    assert!(e.contains("an unreadable lock, ") && e.contains(BREAK_FILE) && !e.contains("()"), "{e}");
    std::fs::remove_file(d.join(BREAK_FILE)).unwrap();
    drop(OutDir::claim(&d, "--out").unwrap());
    // A folder in the lock's place is no lock: refused at once, naming what to remove, and
    // left as it is.
    std::fs::create_dir(&file).unwrap();
    let e = OutDir::claim(&d, "--out").unwrap_err().to_string();
    assert!(e.contains(&format!("its {LOCK_FILE} is a folder")) && e.contains("remove"), "{e}");
    assert!(file.is_dir());
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

/// A sweep-like command (the folder is its alone, it resumes from results.csv) and an
/// isa-like one (its own files only, `--force` and no `--resume`).
const ALONE: Outputs = Outputs {
    command: "sweep",
    owns: |n| ["results.csv", "report.md", "plots"].contains(&n),
    folders: &["plots"],
    alone: true,
    resume: Some(("results.csv", "keep its rows")),
    force: true,
};
const SHARED: Outputs =
    Outputs { command: "isa", owns: |n| n == "isa.md", folders: &[], alone: false, resume: None, force: true };

#[test]
fn what_a_folder_may_hold() {
    use std::os::unix::fs::FileTypeExt;
    let d = tmp("policy");
    let claim = |mode, outputs: &Outputs| OutDir::claim_for(&d, "--out", mode, outputs);
    assert_eq!(OutMode::from_flags(true, true).unwrap_err().to_string(), "--resume and --force exclude each other");
    assert_eq!(OutMode::from_flags(false, true).unwrap(), OutMode::Force);
    // Anything new goes: a missing folder, made (and removed again if left empty).
    for mode in [OutMode::New, OutMode::Resume, OutMode::Force] {
        let c = claim(mode, &ALONE).unwrap();
        assert!(c.held.is_empty() && !c.resumes());
        c.replace_own().unwrap();
    }
    assert!(!d.exists());
    // New into a folder that holds files: refused, naming the folder, the files and the
    // flags; nothing changed. A folder shared with others counts only its own files.
    std::fs::create_dir_all(d.join("plots")).unwrap();
    std::fs::write(d.join("results.csv"), "rows").unwrap();
    std::fs::write(d.join("notes.txt"), "mine").unwrap();
    let e = claim(OutMode::New, &ALONE).unwrap_err().to_string();
    let start = format!("--out {} already holds notes.txt, plots, results.csv; nothing was changed.", d.display());
    assert!(e.starts_with(&start) && e.contains("--resume to keep its rows") && e.contains("--force"), "{e}");
    assert_eq!(OutDir::entries(&d).unwrap(), ["notes.txt", "plots", "results.csv"]);
    let shared = claim(OutMode::New, &SHARED).unwrap();
    assert_eq!((shared.held.len(), shared.own.len()), (3, 0));
    drop(shared);
    std::fs::write(d.join("isa.md"), "earlier").unwrap();
    let e = claim(OutMode::New, &SHARED).unwrap_err().to_string();
    assert!(
        e.contains("already holds isa.md;")
            && e.contains("Pass --force to replace isa's own")
            && !e.contains("--resume"),
        "{e}"
    );
    std::fs::remove_file(d.join("isa.md")).unwrap();
    // Resume needs the file it continues from.
    let c = claim(OutMode::Resume, &ALONE).unwrap();
    assert!(c.resumes() && c.mode() == OutMode::Resume);
    drop(c);
    std::fs::rename(d.join("results.csv"), d.join("results.old")).unwrap();
    let e = claim(OutMode::Resume, &ALONE).unwrap_err().to_string();
    assert!(e.starts_with(&format!("--resume: --out {} has no results.csv to resume", d.display())), "{e}");
    assert!(e.contains("notes.txt") && e.contains("--force"), "{e}");
    assert_eq!(ALONE.mode_to_continue(&d), OutMode::Force);
    std::fs::rename(d.join("results.old"), d.join("results.csv")).unwrap();
    assert_eq!(ALONE.mode_to_continue(&d), OutMode::Resume);
    // Force replaces the command's own files and folders, nothing else.
    let c = claim(OutMode::Force, &ALONE).unwrap();
    assert_eq!(c.own, ["plots", "results.csv"]);
    c.replace_own().unwrap();
    drop(c);
    assert_eq!(OutDir::entries(&d).unwrap(), ["notes.txt"]);
    assert_eq!(std::fs::read_to_string(d.join("notes.txt")).unwrap(), "mine");
    // Nor a folder under a name the command writes as a file (a user's, then).
    std::fs::create_dir_all(d.join("report.md")).unwrap();
    std::fs::write(d.join("report.md/draft.txt"), "mine").unwrap();
    let e = claim(OutMode::Force, &ALONE).unwrap_err().to_string();
    assert!(e.contains("its report.md is a folder"), "{e}");
    assert_eq!(std::fs::read_to_string(d.join("report.md/draft.txt")).unwrap(), "mine");
    std::fs::remove_dir_all(d.join("report.md")).unwrap();
    // Never a FIFO or a link, even of an own name: refused under --force or --resume.
    let fifo = d.join("report.md");
    assert!(std::process::Command::new("mkfifo").arg(&fifo).status().unwrap().success());
    std::os::unix::fs::symlink(d.join("notes.txt"), d.join("results.csv")).unwrap();
    for mode in [OutMode::Force, OutMode::Resume] {
        let e = claim(mode, &ALONE).unwrap_err().to_string();
        assert!(e.contains("is a FIFO") || e.contains("is a symbolic link") || e.contains("no results.csv"), "{e}");
    }
    let e = claim(OutMode::Force, &ALONE).unwrap_err().to_string();
    assert!(e.contains("its report.md is a FIFO, which halftrace never replaces"), "{e}");
    assert!(std::fs::symlink_metadata(&fifo).unwrap().file_type().is_fifo());
    assert_eq!(std::fs::read_to_string(d.join("results.csv")).unwrap(), "mine");
    // A path that is not a folder: refused before anything else.
    let e = OutDir::claim_for(&d.join("notes.txt"), "--out", OutMode::Force, &ALONE).unwrap_err().to_string();
    assert!(e.contains("exists and is a regular file"), "{e}");
    std::fs::remove_dir_all(&d).unwrap();
}

#[test]
fn default_folders_are_stamped() {
    let (sweep, isa) = (default_out(None), default_out(Some("isa")));
    let stamp = sweep.file_name().unwrap().to_str().unwrap();
    assert!(sweep.starts_with("reports") && stamp.len() == 15 && stamp.as_bytes()[8] == b'-', "{stamp}");
    assert!(isa.file_name().unwrap().to_str().unwrap().starts_with("isa-20"), "{}", isa.display());
}
