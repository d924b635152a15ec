//! `report`: merging folders and shards, refusing duplicate rows.

use super::*;

#[test]
fn report_merges_folders() {
    let a = tmp("merge-a");
    let b = tmp("merge-b");
    let only = ["--layouts", "f32,f16h,rq", "--branchings", "4", "--packets", "1", "--layout-branchings", "4"];
    assert!(sweep(&a, &[&["--rays", "primary"][..], &only].concat()).status.success());
    assert!(sweep(&b, &[&["--rays", "ao"][..], &only].concat()).status.success());
    let merged = tmp("merged");
    let o = Command::new(env!("CARGO_BIN_EXE_halftrace"))
        .args(["report", a.to_str().unwrap(), b.to_str().unwrap(), "--out", merged.to_str().unwrap()])
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let md = std::fs::read_to_string(merged.join("report.md")).unwrap();
    assert!(md.contains("Rendered from 8 result row(s)"), "{md}");
    assert!(md.contains("÷ rq"), "the rq comparison table is missing");
    assert!(md.contains("| primary (") && md.contains("| ao ("));
    assert!(merged.join("ratio_vs_b.svg").is_file());
    let e = Command::new(env!("CARGO_BIN_EXE_halftrace")).args(["report", "/nonexistent/dir"]).output().unwrap();
    assert!(!e.status.success() && String::from_utf8_lossy(&e.stderr).contains("/nonexistent/dir/results.csv"));
}

/// `report` refuses to merge a folder with itself or two folders holding the same variant
/// (it would average or double-count them), naming both places.
#[test]
fn report_refuses_duplicate_rows() {
    let a = tmp("dup-a");
    assert!(sweep(
        &a,
        &["--rays", "primary", "--layouts", "f32", "--branchings", "4", "--packets", "1", "--layout-branchings", "4"]
    )
    .status
    .success());
    let b = tmp("dup-b");
    std::fs::create_dir_all(&b).unwrap();
    std::fs::copy(a.join("results.csv"), b.join("results.csv")).unwrap();
    let run = |dirs: &[&Path]| {
        Command::new(env!("CARGO_BIN_EXE_halftrace"))
            .arg("report")
            .args(dirs)
            .args(["--out", tmp("dup-out").to_str().unwrap()])
            .output()
            .unwrap()
    };
    let o = run(&[&a, &a]);
    let e = String::from_utf8_lossy(&o.stderr);
    assert!(!o.status.success() && e.contains("named twice"), "{e}");
    let o = run(&[&a, &b]);
    let e = String::from_utf8_lossy(&o.stderr);
    assert!(!o.status.success() && e.contains("same variant") && e.contains("line 2"), "{e}");
    // What report reads is checked: halftrace's columns, each value in its domain.
    let row = read_rows(&a).unwrap().remove(0);
    let bad = |name: &str, write: &dyn Fn(&Path)| {
        let d = tmp(&format!("bad-{name}"));
        let _ = std::fs::remove_dir_all(&d);
        std::fs::create_dir_all(&d).unwrap();
        write(&d);
        let o = Command::new(env!("CARGO_BIN_EXE_halftrace")).arg("report").arg(&d).output().unwrap();
        let e = String::from_utf8_lossy(&o.stderr).to_string();
        assert_eq!(o.status.code(), Some(1), "{name}: {e}");
        assert!(!d.join("report.md").exists(), "{name}: a report was written");
        e
    };
    let e = bad("dir", &|d| std::fs::create_dir_all(d.join("results.csv")).unwrap());
    assert!(e.contains("results.csv") && e.contains("folder"), "{e}");
    let e = bad("empty", &|d| std::fs::write(d.join("results.csv"), b"").unwrap());
    assert!(e.contains("not a halftrace results.csv") && e.contains("empty"), "{e}");
    let e = bad("junk", &|d| std::fs::write(d.join("results.csv"), [0x89u8, 0x50, 0x4e, 0x47, 0, 1, 2, 255]).unwrap());
    assert!(e.contains("not a halftrace results.csv"), "{e}");
    let text = std::fs::read_to_string(a.join("results.csv")).unwrap();
    let e = bad("status", &|d| std::fs::write(d.join("results.csv"), text.replace(",ok,", ",weird,")).unwrap());
    assert!(e.contains("row 2") && e.contains("weird"), "{e}");
    // A column missing is named (it once gave serde's raw "missing field").
    let e = bad("column", &|d| {
        let mut rd = csv::Reader::from_reader(text.as_bytes());
        let h = rd.headers().unwrap().clone();
        let drop = h.iter().position(|c| c == "bvh_bytes").unwrap();
        let mut w = csv::Writer::from_writer(Vec::new());
        w.write_record(h.iter().enumerate().filter(|(i, _)| *i != drop).map(|(_, c)| c)).unwrap();
        for r in rd.records() {
            w.write_record(r.unwrap().iter().enumerate().filter(|(i, _)| *i != drop).map(|(_, c)| c)).unwrap();
        }
        std::fs::write(d.join("results.csv"), w.into_inner().unwrap()).unwrap();
    });
    assert!(e.contains("the column 'bvh_bytes' is missing"), "{e}");
    type Edit = fn(&mut Row);
    let edits: [(&str, Edit, &str); 6] = [
        ("nan", |r| r.mrays_median = f64::NAN, "mrays_median NaN"),
        ("inf", |r| r.ms_median = f64::INFINITY, "ms_median inf"),
        ("negative", |r| r.ms_min = -1.0, "ms_min -1"),
        ("b3", |r| r.branching = 3, "branching 3"),
        ("p5", |r| r.packet = 5, "packet 5"),
        ("layout", |r| r.layout = "f8".into(), "layout 'f8'"),
    ];
    for (name, edit, want) in edits {
        let mut r = row.clone();
        edit(&mut r);
        let e = bad(name, &|d| halftrace::report::write_rows(d, std::slice::from_ref(&r)).unwrap());
        assert!(e.contains("row 2") && e.contains(want), "{name}: {e}");
    }
}

/// `--shard 1/2` and `--shard 2/2` (the second through Slurm's array variables) each run
/// their share into `OUT/shard-K-of-2`; `report` merges them into the rows of the unsplit
/// sweep (timings aside) and the same report, numbers aside (images included).
#[test]
fn shards_merge_into_the_unsplit_sweep() {
    let only = [
        "--rays",
        "primary,ao",
        "--layouts",
        "f32,f16h,q8,rq",
        "--maths",
        "f32",
        "--branchings",
        "4,8",
        "--packets",
        "1,4",
        "--layout-branchings",
        "4",
    ];
    let whole = tmp("shard-whole");
    assert!(sweep(&whole, &only).status.success());
    let split = tmp("shard-split");
    let first = sweep(&split, &[&only[..], &["--shard", "1/2"]].concat());
    assert!(first.status.success(), "{}", String::from_utf8_lossy(&first.stderr));
    let second = sweep_cmd(&split, &only)
        .env("SLURM_ARRAY_TASK_COUNT", "2")
        .env("SLURM_ARRAY_TASK_ID", "1")
        .env("SLURM_ARRAY_TASK_MIN", "0")
        .output()
        .unwrap();
    assert!(second.status.success(), "{}", String::from_utf8_lossy(&second.stderr));
    let (s1, s2) = (split.join("shard-1-of-2"), split.join("shard-2-of-2"));
    let (r1, r2) = (read_rows(&s1).unwrap(), read_rows(&s2).unwrap());
    assert!(!r1.is_empty() && !r2.is_empty(), "an empty shard");
    let merged = tmp("shard-merged");
    let o = Command::new(env!("CARGO_BIN_EXE_halftrace"))
        .args(["report", s1.to_str().unwrap(), s2.to_str().unwrap(), "--out", merged.to_str().unwrap()])
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    // Rows: the same set, every field but the timings (and what is derived from them) equal.
    let untimed = |mut r: Row| {
        (r.mrays_median, r.mrays_min, r.mrays_max, r.ms_median, r.ms_min, r.ms_max, r.build_ms, r.device_fp16_ratio) =
            (0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0);
        format!("{r:?}")
    };
    let mut want: Vec<String> = read_rows(&whole).unwrap().into_iter().map(untimed).collect();
    let mut got: Vec<String> = read_rows(&merged).unwrap().into_iter().map(untimed).collect();
    assert_eq!(got.len(), r1.len() + r2.len());
    want.sort();
    got.sort();
    assert_eq!(got, want, "merged shards differ from the unsplit sweep");
    // The report: the same lines, once every number is masked (the timings differ).
    let mask = |p: &Path| -> Vec<String> {
        let md = std::fs::read_to_string(p.join("report.md")).unwrap();
        let one = |l: &str| {
            let mut o = String::new();
            for c in l.chars().map(|c| if c.is_ascii_digit() { '#' } else { c }) {
                if !(c == '#' && o.ends_with('#')) {
                    o.push(c);
                }
            }
            o
        };
        md.lines().filter(|l| !l.starts_with("Rendered from")).map(one).collect()
    };
    assert_eq!(mask(&whole), mask(&merged), "the merged report differs from the unsplit one beyond its numbers");
    assert!(merged.join("render.png").is_file() && merged.join("heat_q8.png").is_file(), "the images came along");
    // A lone shard merges with a warning and a note naming the missing one; a shard of another
    // sweep (another configuration hash in its shard.json) is refused.
    let report = |dirs: &[&Path], out: &Path| {
        let mut c = Command::new(env!("CARGO_BIN_EXE_halftrace"));
        c.arg("report").args(dirs).arg("--out").arg(out);
        c.output().unwrap()
    };
    let lone = tmp("shard-lone");
    let o = report(&[&s1], &lone);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    assert!(String::from_utf8_lossy(&o.stderr).contains("shard 2 of 2"), "{}", String::from_utf8_lossy(&o.stderr));
    let md = std::fs::read_to_string(lone.join("report.md")).unwrap();
    assert!(md.contains("**Incomplete sweep:**") && md.contains("shard 2 of 2"), "{md}");
    let other = tmp("shard-other");
    std::fs::create_dir_all(&other).unwrap();
    for f in ["results.csv", "results.json"] {
        std::fs::copy(s2.join(f), other.join(f)).unwrap();
    }
    let manifest = std::fs::read_to_string(s2.join("shard.json")).unwrap();
    let config = manifest.split("\"config\": \"").nth(1).unwrap().split('"').next().unwrap().to_string();
    std::fs::write(other.join("shard.json"), manifest.replace(&config, "0123456789abcdef")).unwrap();
    let o = report(&[&s1, &other], &tmp("shard-mixed"));
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(!o.status.success() && err.contains("different sweeps"), "{err}");
    assert!(!tmp("shard-mixed").join("report.md").exists());
    // A bad shard is refused before anything runs.
    let bad = sweep(&tmp("shard-bad"), &[&only[..], &["--shard", "3/2"]].concat());
    assert!(!bad.status.success() && String::from_utf8_lossy(&bad.stderr).contains("K/N"));
}
