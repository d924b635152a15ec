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
    // A column from a newer version: refused, the file untouched.
    let csv = out.join("results.csv");
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
