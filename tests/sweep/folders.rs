//! Result folders: an interrupted sweep keeps its rows, a folder with results is refused, resumed or replaced, progress lines without a terminal.

use super::*;

#[test]
fn interrupted_sweep_keeps_finished_rows() {
    let out = tmp("interrupt");
    let mut child = Command::new(env!("CARGO_BIN_EXE_halftrace"))
        .args([
            "sweep",
            "--quiet",
            "--scene",
            &teapot(),
            "--width",
            "128",
            "--height",
            "128",
            "--repeat",
            "10",
            "--out",
            out.to_str().unwrap(),
        ])
        .spawn()
        .unwrap();
    let csv = out.join("results.csv");
    let t0 = std::time::Instant::now();
    loop {
        let lines = std::fs::read_to_string(&csv).map(|t| t.lines().count()).unwrap_or(0);
        if lines >= 3 {
            break;
        }
        assert!(t0.elapsed().as_secs() < 300, "sweep produced no rows");
        assert!(child.try_wait().unwrap().is_none(), "sweep ended before it could be interrupted");
        std::thread::sleep(std::time::Duration::from_millis(50));
    }
    // SIGTERM, as a batch system sends: a shell running the tests in the background ignores
    // SIGINT for its children.
    let st = Command::new("kill").args(["-TERM", &child.id().to_string()]).status().unwrap();
    assert!(st.success());
    let status = child.wait().unwrap();
    assert!(!status.success(), "the sweep should have been interrupted");
    // It released its folder: a requeued task (on any host) or a rerun is not refused.
    assert_eq!(status.code(), Some(143), "ends as SIGTERM would: {status:?}");
    assert!(!out.join(halftrace::outdir::LOCK_FILE).exists(), "SIGTERM left the lock");
    let rows = read_rows(&out).expect("rows written before the interrupt must parse");
    assert!(rows.len() >= 2 && rows.len() < 112, "{} rows", rows.len());
    assert!(rows.iter().all(|r| r.status.is_ok() && r.mrays_median > 0.0));
}

/// A folder with results is never overwritten by accident: refused without a flag (nothing
/// touched), `--resume` keeps its rows and runs only the missing jobs, `--force` replaces the
/// sweep's own files and nothing else.
#[test]
fn existing_out_folder_is_refused_resumed_or_replaced() {
    let out = tmp("resume");
    let args = [
        "--rays",
        "primary,ao",
        "--layouts",
        "f32,rq",
        "--branchings",
        "4",
        "--packets",
        "1",
        "--layout-branchings",
        "4",
    ];
    let o = sweep(&out, &args);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let full = read_rows(&out).unwrap();
    assert_eq!(full.len(), 4);
    // As after an interrupt: the last row is missing.
    let csv = out.join("results.csv");
    let text = std::fs::read_to_string(&csv).unwrap();
    let cut: String = text.lines().take(full.len()).map(|l| format!("{l}\n")).collect();
    std::fs::write(&csv, &cut).unwrap();
    std::fs::write(out.join("notes.txt"), "mine").unwrap();
    let o = sweep(&out, &args);
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(!o.status.success() && err.contains("--resume") && err.contains("--force"), "{err}");
    assert_eq!(std::fs::read_to_string(&csv).unwrap(), cut, "a refused sweep touched results.csv");
    let mut resume = args.to_vec();
    resume.push("--resume");
    let o = sweep(&out, &resume);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let resumed = read_rows(&out).unwrap();
    assert_eq!(resumed.len(), 4, "resume ran the missing job once");
    assert_eq!(&resumed[..3], &full[..3], "resume kept the recorded rows as they were");
    assert_eq!(
        (resumed[3].scene.as_str(), resumed[3].rays.as_str(), resumed[3].layout.as_str()),
        (full[3].scene.as_str(), full[3].rays.as_str(), full[3].layout.as_str())
    );
    let mut force = args.to_vec();
    force.push("--force");
    let o = sweep(&out, &force);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    assert_eq!(read_rows(&out).unwrap().len(), 4);
    assert_eq!(
        std::fs::read_to_string(out.join("notes.txt")).unwrap(),
        "mine",
        "--force touched a file that is not the sweep's"
    );
    let both: Vec<&str> = args.iter().copied().chain(["--resume", "--force"]).collect();
    assert!(!sweep(&out, &both).status.success());
}

/// A resume knows what it ran: a row measured with another seed (image size, scene file or
/// rays file) is not taken for the job with this one, and a results.csv with columns this version
/// does not write (a newer version's) is refused rather than rewritten without them.
#[test]
fn resume_runs_what_no_longer_matches_and_keeps_unknown_columns() {
    let out = tmp("resume-identity");
    let args =
        ["--rays", "primary", "--layouts", "f32", "--branchings", "4", "--packets", "1", "--layout-branchings", "4"];
    let o = sweep(&out, &args);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let first = read_rows(&out).unwrap();
    assert_eq!(first.len(), 1);
    // Another seed: the old row is kept, the job runs.
    let mut other: Vec<&str> = args.to_vec();
    other.extend(["--seed", "7", "--resume"]);
    let o = sweep(&out, &other);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let rows = read_rows(&out).unwrap();
    assert_eq!(rows.len(), 2, "the seed-7 job ran beside the seed-1 row");
    assert_ne!(rows[0].setup, rows[1].setup);
    // The same settings again: nothing to run.
    let o = sweep(&out, &other);
    assert!(o.status.success());
    assert_eq!(read_rows(&out).unwrap().len(), 2);
    // As a spreadsheet re-saves it: a byte-order mark and every name quoted. The same columns
    // (this was "column(s) this version does not write" before the header was read as CSV).
    let csv = out.join("results.csv");
    let text = std::fs::read_to_string(&csv).unwrap();
    let (head, body) = text.split_once('\n').unwrap();
    let quoted: Vec<String> = head.split(',').map(|c| format!("\"{c}\"")).collect();
    std::fs::write(&csv, format!("\u{feff}{}\n{body}", quoted.join(","))).unwrap();
    let ids = |rows: &[halftrace::report::Row]| rows.iter().map(|r| format!("{:?}", r.id())).collect::<Vec<_>>();
    assert_eq!(ids(&read_rows(&out).unwrap()), ids(&rows), "a BOM and quoted names read as the same rows");
    let o = sweep(&out, &other);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    assert_eq!(ids(&read_rows(&out).unwrap()), ids(&rows), "nothing left to run, the rows kept");
    // A column from a newer version: refused, the file untouched.
    let text = std::fs::read_to_string(&csv).unwrap();
    let newer: String = text
        .lines()
        .enumerate()
        .map(|(i, l)| format!("{l},{}\n", if i == 0 { "energy_joules" } else { "1.5" }))
        .collect();
    std::fs::write(&csv, &newer).unwrap();
    let o = sweep(&out, &other);
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(!o.status.success() && err.contains("energy_joules"), "{err}");
    assert_eq!(std::fs::read_to_string(&csv).unwrap(), newer);
    let _ = std::fs::remove_dir_all(&out);
}

/// Without a terminal (CI logs, nohup, Slurm) the sweep prints one line per finished job with
/// elapsed time and ETA instead of a progress bar.
#[test]
fn progress_lines_when_not_a_terminal() {
    let out = tmp("lines");
    let o = Command::new(env!("CARGO_BIN_EXE_halftrace"))
        .args([
            "sweep",
            "--scene",
            &teapot(),
            "--width",
            "16",
            "--height",
            "16",
            "--repeat",
            "1",
            "--warmup",
            "0",
            "--rays",
            "primary",
            "--layouts",
            "f32,q8",
            "--branchings",
            "4",
            "--packets",
            "1",
            "--layout-branchings",
            "4",
            "--out",
            out.to_str().unwrap(),
        ])
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(o.status.success(), "{err}");
    let lines: Vec<&str> = err.lines().filter(|l| l.starts_with('[')).collect();
    assert_eq!(lines.len(), 3, "{err}");
    assert!(lines[0].starts_with("[1/3] teapot primary trav_") && lines[2].contains("ETA 0 s"), "{err}");
}

/// The arguments of a one-job sweep.
const ONE_JOB: [&str; 10] =
    ["--rays", "primary", "--layouts", "f32", "--branchings", "4", "--packets", "1", "--layout-branchings", "4"];

/// Runs `halftrace args`, expecting a fast refusal that names the lock's holder (this test
/// process) and the folder; returns the seconds it took.
fn refused_by_holder(args: &[&str], folder: &Path) -> f64 {
    let t0 = std::time::Instant::now();
    let o = Command::new(env!("CARGO_BIN_EXE_halftrace")).args(args).output().unwrap();
    let secs = t0.elapsed().as_secs_f64();
    let err = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(1), "{args:?}: {err}");
    let holder = format!("pid {} on ", std::process::id());
    assert!(
        err.contains(&format!("{}: another run is writing into it", folder.display())) && err.contains(&holder),
        "{args:?}: {err}"
    );
    eprintln!("{} refused in {secs:.3} s", args[..2].join(" "));
    assert!(secs < 5.0, "{args:?}: refused only after {secs:.1} s");
    secs
}

/// One writer per folder: while a folder is claimed (here by this test process, whose pid is
/// alive), every command that writes into it is refused at once, naming the holder, and
/// touches nothing; the lock goes with its guard.
#[test]
fn a_claimed_folder_refuses_every_other_writer() {
    use halftrace::outdir::{OutDir, LOCK_FILE};
    let out = tmp("claimed");
    let o = sweep(&out, &ONE_JOB);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    assert!(!out.join(LOCK_FILE).exists(), "the sweep left its lock");
    let before = OutDir::entries(&out).unwrap();
    let csv = std::fs::read(out.join("results.csv")).unwrap();
    let lock = OutDir::claim(&out, "--out").unwrap();
    let (o, scene) = (out.to_str().unwrap(), teapot());
    let s = scene.as_str();
    for args in [
        vec!["sweep", "--scene", s, "--out", o],
        vec!["sweep", "--scene", s, "--out", o, "--resume"],
        vec!["sweep", "--scene", s, "--out", o, "--force"],
        vec!["device-report", "--scene", s, "--scenes-dir", "none", "--out", o, "--resume"],
        vec!["conformance", "--quick", "--scene", s, "--out", o],
        vec!["isa", "--quick", "--out", o, "--force"],
        vec!["report", o],
    ] {
        refused_by_holder(&args, &out);
    }
    let merged = tmp("claimed-merged");
    std::fs::create_dir_all(&merged).unwrap();
    let m = OutDir::claim(&merged, "--out").unwrap();
    refused_by_holder(&["report", o, "--out", merged.to_str().unwrap()], &merged);
    drop(m);
    // A shard's folder is the one it writes.
    let shard = out.join("shard-1-of-2");
    let sl = OutDir::claim(&shard, "--out").unwrap();
    refused_by_holder(&["sweep", "--scene", s, "--out", o, "--shard", "1/2"], &shard);
    drop(sl);
    assert_eq!(OutDir::entries(&out).unwrap(), before, "a refused command changed the folder");
    assert_eq!(std::fs::read(out.join("results.csv")).unwrap(), csv);
    drop(lock);
    assert!(!out.join(LOCK_FILE).exists());
    // Released, the folder is the sweep's again (and its lock never reaches a merge).
    let mut resume = ONE_JOB.to_vec();
    resume.push("--resume");
    let o = sweep(&out, &resume);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let o = Command::new(env!("CARGO_BIN_EXE_halftrace"))
        .arg("report")
        .arg(&out)
        .arg("--out")
        .arg(&merged)
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    assert!(!merged.join(LOCK_FILE).exists() && !out.join(LOCK_FILE).exists());
    let _ = std::fs::remove_dir_all(&out);
    let _ = std::fs::remove_dir_all(&merged);
}

/// A lock left by a run that was killed (its pid no longer runs) is replaced, saying so; the
/// sweep runs and leaves no lock.
#[test]
fn a_stale_lock_is_replaced() {
    use halftrace::outdir::{Holder, LOCK_FILE};
    let out = tmp("stale-lock");
    std::fs::create_dir_all(&out).unwrap();
    let mut gone = Command::new("true").spawn().unwrap();
    let pid = gone.id();
    gone.wait().unwrap();
    let dead = Holder { pid, command: "halftrace sweep (killed)".into(), ..Holder::current() };
    std::fs::write(out.join(LOCK_FILE), serde_json::to_string(&dead).unwrap()).unwrap();
    let o = sweep(&out, &ONE_JOB);
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(o.status.success(), "{err}");
    assert!(err.contains("replaced a stale lock") && err.contains(&format!("pid {pid} ")), "{err}");
    assert_eq!(read_rows(&out).unwrap().len(), 1);
    assert!(!out.join(LOCK_FILE).exists());
    let _ = std::fs::remove_dir_all(&out);
}

/// Two sweeps into one folder at once: before, both exited 0 and one run's rows vanished from
/// results.csv. The second is refused while the first runs (as a second `--resume` is), and
/// the first's rows are all there.
#[test]
fn a_second_sweep_into_a_running_ones_folder_is_refused() {
    use halftrace::outdir::LOCK_FILE;
    let out = tmp("race");
    let args = [
        "--rays",
        "primary,ao",
        "--layouts",
        "f32,f16h",
        "--branchings",
        "4",
        "--packets",
        "1",
        "--layout-branchings",
        "4",
    ];
    let mut first = sweep_cmd(&out, &args)
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    let t0 = std::time::Instant::now();
    while !out.join(LOCK_FILE).exists() {
        assert!(first.try_wait().unwrap().is_none(), "the first sweep ended before it took its lock");
        assert!(t0.elapsed().as_secs() < 60, "no lock within a minute");
        std::thread::sleep(std::time::Duration::from_millis(5));
    }
    for extra in [&[][..], &["--resume"], &["--force"]] {
        let mut a = args.to_vec();
        a.extend_from_slice(extra);
        let t = std::time::Instant::now();
        let o = sweep(&out, &a);
        let secs = t.elapsed().as_secs_f64();
        let err = String::from_utf8_lossy(&o.stderr);
        eprintln!("second sweep {extra:?}: refused in {secs:.3} s");
        assert!(!o.status.success(), "a second sweep {extra:?} ran into a running one's folder: {err}");
        assert!(
            err.contains("another run is writing into it") && err.contains(&format!("pid {} ", first.id())),
            "{err}"
        );
        assert!(secs < 5.0);
    }
    assert!(first.try_wait().unwrap().is_none(), "the first sweep ended before the refusals: the test proved nothing");
    let o = first.wait_with_output().unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    // "N variants in T s": every row the first sweep measured is in results.csv.
    let said: usize = String::from_utf8_lossy(&o.stdout).split_whitespace().next().unwrap().parse().unwrap();
    assert!(said >= 4);
    assert_eq!(read_rows(&out).unwrap().len(), said, "rows of the first sweep vanished");
    assert!(!out.join(LOCK_FILE).exists());
    let _ = std::fs::remove_dir_all(&out);
}
