//! Bad input gets a clear error naming the file, line or parameter; never a panic.

use halftrace::base::Ray;
use halftrace::npy;
use std::path::{Path, PathBuf};
use std::process::Command;

fn tmp(name: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("halftrace-errors-{}", std::process::id()));
    std::fs::create_dir_all(&d).unwrap();
    d.join(name)
}

fn teapot() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("scenes/teapot.obj")
}

/// Runs the CLI, expects failure, returns stderr.
fn fails(args: &[&str]) -> String {
    let out = Command::new(env!("CARGO_BIN_EXE_halftrace")).args(args).output().unwrap();
    let err = String::from_utf8_lossy(&out.stderr).to_string();
    assert!(!out.status.success(), "{args:?} should fail");
    assert_eq!(out.status.code(), Some(1), "{args:?}: {err}");
    assert!(!err.contains("panicked"), "{args:?} panicked: {err}");
    assert!(err.starts_with("error: "), "{args:?}: {err}");
    err
}

fn obj(name: &str, text: &str) -> PathBuf {
    let p = tmp(name);
    std::fs::write(&p, text).unwrap();
    p
}

fn trace_scene(p: &Path) -> String {
    fails(&["trace", "--scene", p.to_str().unwrap(), "--width", "8", "--height", "8"])
}

#[test]
fn missing_and_empty_files() {
    let e = trace_scene(Path::new("/nonexistent/scene.obj"));
    assert!(e.contains("/nonexistent/scene.obj") && e.contains("cannot read"), "{e}");
    let p = obj("empty.obj", "\n\n");
    let e = trace_scene(&p);
    assert!(e.contains("empty.obj") && e.contains("empty"), "{e}");
    let p = obj("bad.obj.gz", "this is not gzip");
    let e = trace_scene(&p);
    assert!(e.contains("bad.obj.gz") && e.contains("gzip"), "{e}");
}

#[test]
fn malformed_obj_names_the_line() {
    let cases = [
        ("short_v.obj", "v 0 0 0\nv 1 0\n", ":2:", "3 coordinates"),
        ("word_v.obj", "v 0 0 0\nv 1 zero 0\n", ":2:", "not a number"),
        ("bad_f.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 x\n", ":4:", "vertex reference"),
        ("range_f.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 9\n", ":4:", "out of range"),
        ("two_f.obj", "v 0 0 0\nv 1 0 0\nf 1 2\n", ":3:", "at least 3"),
        ("nan.obj", "v 0 0 0\nv nan 0 0\nv 0 1 0\nf 1 2 3\n", ":2:", "not finite"),
        ("inf.obj", "v 0 0 0\nv 1 0 0\nv 0 -inf 0\nf 1 2 3\n", ":3:", "not finite"),
        ("w_only.obj", "v 0 0 0\nv 1 0 0\nv 0.5\nf 1 2 3\n", ":3:", "3 coordinates, found 1"),
        ("continued.obj", "v 0 0 0\nv 1 0 \\\n 0\nv 0 1 0\nf 1 2 3\n", ":2:", "a line continued on the next"),
        ("continued_f.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 \\\n3\n", ":4:", "join the two lines"),
    ];
    for (name, text, line, what) in cases {
        let e = trace_scene(&obj(name, text));
        assert!(e.contains(name) && e.contains(line) && e.contains(what), "{name}: {e}");
    }
}

#[test]
fn scene_without_triangles() {
    let e = trace_scene(&obj("points.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\n"));
    assert!(e.contains("points.obj") && e.contains("no triangles"), "{e}");
}

#[test]
fn degenerate_triangles_load_and_never_hit() {
    // Zero-area triangles are kept (warning) and never hit.
    let p = obj("degen.obj", "v 0 0 0\nv 1 0 0\nv 2 0 0\nv 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\nf 4 5 6\n");
    let out = Command::new(env!("CARGO_BIN_EXE_halftrace"))
        .args([
            "trace",
            "--scene",
            p.to_str().unwrap(),
            "--layout",
            "f32",
            "--width",
            "16",
            "--height",
            "16",
            "--out",
            tmp("degen_hits.npy").to_str().unwrap(),
        ])
        .output()
        .unwrap();
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    assert!(String::from_utf8_lossy(&out.stderr).contains("1 zero-area"));
    let hits = npy::read_hits(&tmp("degen_hits.npy")).unwrap();
    assert!(hits.iter().all(|h| h.prim != 0), "the degenerate triangle was hit");
    assert!(hits.iter().any(|h| h.prim == 1));
}

#[test]
fn bad_parameters() {
    let t = teapot();
    let t = t.to_str().unwrap();
    let e = fails(&["trace", "--scene", t, "--branching", "3"]);
    assert!(e.contains("--branching") && e.contains("3"), "{e}");
    let e = fails(&["trace", "--scene", t, "--layout", "f8"]);
    assert!(e.contains("unknown layout 'f8'"), "{e}");
    let e = fails(&["trace", "--scene", t, "--rays", "sideways"]);
    assert!(e.contains("--rays 'sideways'"), "{e}");
    let e = fails(&["trace", "--scene", t, "--width", "0"]);
    assert!(e.contains("0x256"), "{e}");
    let e = fails(&["trace", "--scene", t, "--camera", "1,2,3"]);
    assert!(e.contains("--camera"), "{e}");
}

/// Durations are range-checked where they are parsed (flags and the sweep's TOML): a huge or
/// infinite timeout was a panic converting it to a Duration.
#[test]
fn durations_are_range_checked() {
    let t = teapot();
    let t = t.to_str().unwrap();
    for v in ["1e300", "inf", "nan", "0", "-1", "169h", "5 minutes"] {
        let e = fails(&["trace", "--scene", t, &format!("--kernel-timeout={v}")]);
        assert!(e.contains("--kernel-timeout") && e.contains(v), "{v}: {e}");
        let e = fails(&["sweep", "--scene", t, &format!("--budget={v}"), "--out", tmp("never").to_str().unwrap()]);
        assert!(e.contains("--budget") && e.contains(v), "{v}: {e}");
        let e = fails(&["device-report", &format!("--budget={v}"), "--out", tmp("never").to_str().unwrap()]);
        assert!(e.contains("--budget"), "{v}: {e}");
    }
    assert!(!tmp("never").exists());
    for v in ["1e300", "inf", "-3.0", "0.0"] {
        let toml = obj(&format!("timeout-{v}.toml"), &format!("kernel_timeout = {v}\n"));
        let e = fails(&["sweep", "--config", toml.to_str().unwrap(), "--out", tmp("never").to_str().unwrap()]);
        assert!(e.contains("kernel_timeout") && e.contains("timeout-"), "{v}: {e}");
        let table = format!("[[kernel]]\nname = \"k\"\nlayout = \"f32\"\nfile = {t:?}\nkernel_timeout = {v}\n");
        let toml = obj(&format!("kernel-timeout-{v}.toml"), &table);
        let e = fails(&["sweep", "--config", toml.to_str().unwrap(), "--out", tmp("never").to_str().unwrap()]);
        assert!(e.contains("[[kernel]] 'k'") && e.contains("kernel_timeout"), "{v}: {e}");
    }
    assert!(!tmp("never").exists());
}

fn write_raw_npy(name: &str, header: &str, data: &[u8]) -> PathBuf {
    let mut h = header.to_string();
    let pad = (64 - (10 + h.len() + 1) % 64) % 64;
    h.push_str(&" ".repeat(pad));
    h.push('\n');
    let mut b = b"\x93NUMPY\x01\x00".to_vec();
    b.extend((h.len() as u16).to_le_bytes());
    b.extend(h.as_bytes());
    b.extend(data);
    let p = tmp(name);
    std::fs::write(&p, b).unwrap();
    p
}

#[test]
fn bad_ray_files() {
    let t = teapot();
    let t = t.to_str().unwrap();
    let run = |p: &Path| fails(&["trace", "--scene", t, "--rays", p.to_str().unwrap()]);

    let p = tmp("garbage.npy");
    std::fs::write(&p, b"not numpy at all").unwrap();
    let e = run(&p);
    assert!(e.contains("garbage.npy") && e.contains("not a .npy"), "{e}");

    let p = write_raw_npy("shape7.npy", "{'descr': '<f4', 'fortran_order': False, 'shape': (2, 7), }", &[0u8; 56]);
    let e = run(&p);
    assert!(e.contains("shape7.npy") && e.contains("(N, 8)"), "{e}");

    let p = write_raw_npy("f64.npy", "{'descr': '<f8', 'fortran_order': False, 'shape': (1, 8), }", &[0u8; 64]);
    let e = run(&p);
    assert!(e.contains("f64.npy") && e.contains("float32"), "{e}");

    let p = write_raw_npy("short.npy", "{'descr': '<f4', 'fortran_order': False, 'shape': (3, 8), }", &[0u8; 64]);
    let e = run(&p);
    assert!(e.contains("short.npy") && e.contains("bytes"), "{e}");

    let p = tmp("zero_dir.npy");
    let good = Ray { origin: [0.0, 0.0, 10.0], tmin: 0.0, dir: [0.0, 0.0, -1.0], tmax: f32::INFINITY };
    let zero = Ray { dir: [0.0; 3], ..good };
    npy::write_rays(&p, &[good, good, zero]).unwrap();
    let e = run(&p);
    assert!(e.contains("zero_dir.npy") && e.contains("ray 2") && e.contains("direction is zero"), "{e}");

    let p = tmp("nan_origin.npy");
    npy::write_rays(&p, &[Ray { origin: [f32::NAN, 0.0, 0.0], ..good }]).unwrap();
    let e = run(&p);
    assert!(e.contains("ray 0") && e.contains("origin"), "{e}");

    let p = tmp("neg_tmin.npy");
    npy::write_rays(&p, &[Ray { tmin: -1.0, ..good }]).unwrap();
    let e = run(&p);
    assert!(e.contains("ray 0") && e.contains("tmin"), "{e}");
}

#[test]
fn ray_file_round_trip_and_hits_file() {
    let t = teapot();
    let rays = tmp("rt_rays.npy");
    let hits = tmp("rt_hits.npy");
    let hits2 = tmp("rt_hits2.npy");
    let bin = env!("CARGO_BIN_EXE_halftrace");
    let ok = |args: &[&str]| {
        let o = Command::new(bin).args(args).output().unwrap();
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    };
    ok(&[
        "trace",
        "--scene",
        t.to_str().unwrap(),
        "--rays",
        "ao",
        "--width",
        "32",
        "--height",
        "32",
        "--save-rays",
        rays.to_str().unwrap(),
        "--out",
        hits.to_str().unwrap(),
    ]);
    ok(&[
        "trace",
        "--scene",
        t.to_str().unwrap(),
        "--layout",
        "f32",
        "--branching",
        "16",
        "--rays",
        rays.to_str().unwrap(),
        "--out",
        hits2.to_str().unwrap(),
    ]);
    let a = npy::read_hits(&hits).unwrap();
    let b = npy::read_hits(&hits2).unwrap();
    assert_eq!(a.len(), npy::read_rays(&rays).unwrap().len());
    assert!(a.iter().zip(&b).all(|(x, y)| x.same_bits(y)), "hits from the saved rays differ");
    assert!(a.iter().any(|h| h.is_hit()) && a.iter().any(|h| !h.is_hit()));
    assert!(a.iter().filter(|h| !h.is_hit()).all(|h| h.t == f32::INFINITY && h.prim == -1));
}

/// Rays the program makes itself are checked like rays from a file, and sizes are computed
/// without overflow: an eye 1e20 from its target (normalised in f64), a camera that cannot
/// give rays, a scene spanning ±2e38 (its default camera is beyond fp32), an image of 10^10
/// or 2^32 pixels, a `.npy` header claiming more rays than memory can address.
#[test]
fn generated_rays_and_sizes_are_checked() {
    let t = teapot();
    let t = t.to_str().unwrap();
    // An eye 1e20 from its target: the direction is normalised without overflow now, so the
    // rays are finite (and, the teapot being 1e-20 of the view, all miss).
    let o = Command::new(env!("CARGO_BIN_EXE_halftrace"))
        .args([
            "trace",
            "--scene",
            t,
            "--width",
            "8",
            "--height",
            "8",
            "--backend",
            "cpu",
            "--camera",
            "0.1,0.1,1e20,0.1,0.1,0,45",
            "--save-rays",
            tmp("far_rays.npy").to_str().unwrap(),
        ])
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    assert!(npy::read_rays(&tmp("far_rays.npy"))
        .unwrap()
        .iter()
        .all(|r| r.dir.iter().all(|x| x.is_finite()) && r.dir[2] < 0.0));
    for cam in ["1,1,1,1,1,1,45", "inf,0,0,0,0,0,45", "0,0,5,0,0,0,180"] {
        let e = fails(&["trace", "--scene", t, "--width", "8", "--height", "8", "--camera", cam]);
        assert!(e.contains("camera"), "{cam}: {e}");
    }
    let p = obj("huge.obj", "v -2e38 -2e38 -2e38\nv 2e38 -2e38 -2e38\nv 0 2e38 2e38\nf 1 2 3\n");
    let e = trace_scene(&p);
    assert!(e.contains("camera") || e.contains("huge.obj"), "{e}");
    for (w, h) in [("100000", "100000"), ("65536", "65536")] {
        let e = fails(&["trace", "--scene", t, "--width", w, "--height", h]);
        assert!(e.contains(&format!("{w}x{h}")) && e.contains("2^26"), "{e}");
        let e = fails(&["sweep", "--scene", t, "--width", w, "--height", h, "--out", tmp("never").to_str().unwrap()]);
        assert!(e.contains("2^26"), "{e}");
    }
    let p = write_raw_npy(
        "overflow.npy",
        "{'descr': '<f4', 'fortran_order': False, 'shape': (576460752303423490, 8), }",
        &[0u8; 64],
    );
    let e = fails(&["trace", "--scene", t, "--rays", p.to_str().unwrap()]);
    assert!(e.contains("overflow.npy") && e.contains("576460752303423490"), "{e}");
}

/// Outputs never overwrite inputs or each other, `--image` must be a PNG of primary rays, and
/// all of it is refused before anything is traced (the files are untouched); a baseline says
/// which flags do not apply to it instead of ignoring them.
#[test]
fn outputs_are_checked_before_tracing_and_baselines_refuse_what_does_not_apply() {
    let t = teapot();
    let t = t.to_str().unwrap();
    let rays = tmp("inputs.npy");
    npy::write_rays(&rays, &[Ray { origin: [0.0, 0.0, 10.0], tmin: 0.0, dir: [0.0, 0.0, -1.0], tmax: f32::INFINITY }])
        .unwrap();
    let before = std::fs::read(&rays).unwrap();
    let r = rays.to_str().unwrap();
    let e = fails(&["trace", "--scene", t, "--rays", r, "--out", r]);
    assert!(e.contains("--out") && e.contains("--rays input"), "{e}");
    assert_eq!(std::fs::read(&rays).unwrap(), before, "the input was touched");
    let x = tmp("x.npy");
    let x = x.to_str().unwrap();
    let e = fails(&["trace", "--scene", t, "--out", x, "--save-rays", x]);
    assert!(e.contains("same file"), "{e}");
    let photo = tmp("photo.jpg");
    std::fs::write(&photo, b"my holiday").unwrap();
    let e = fails(&["trace", "--scene", t, "--image", photo.to_str().unwrap()]);
    assert!(e.contains(".png"), "{e}");
    assert_eq!(std::fs::read(&photo).unwrap(), b"my holiday");
    let e = fails(&["trace", "--scene", t, "--rays", "ao", "--image", tmp("ao.png").to_str().unwrap()]);
    assert!(e.contains("--rays primary"), "{e}");
    for flag in [
        &["--stats"][..],
        &["--branching", "7"],
        &["--packet", "8"],
        &["--math", "f16"],
        &["--kernel", "x.comp"],
        &["--float-controls", "off"],
    ] {
        let mut args = vec!["trace", "--scene", t, "--layout", "rq"];
        args.extend_from_slice(flag);
        let e = fails(&args);
        assert!(
            e.contains(flag[0]) && (e.contains("does not apply") || e.contains("branching factor 7")),
            "{flag:?}: {e}"
        );
    }
}

/// A scene that is not a regular file (a FIFO would block, /dev/zero never ends) is refused;
/// material files are never read, so `mtllib /dev/zero` cannot stall the load, and a missing
/// one is named in the warning; OS errors are printed once.
#[test]
fn special_files_never_stall_a_load() {
    let e = trace_scene(Path::new("/dev/zero"));
    assert!(e.contains("/dev/zero") && e.contains("not a regular file"), "{e}");
    assert_eq!(e.matches("not a regular file").count(), 1, "{e}");
    let fifo = tmp("scene_fifo.obj");
    let _ = std::fs::remove_file(&fifo);
    assert!(Command::new("mkfifo").arg(&fifo).status().unwrap().success());
    let e = trace_scene(&fifo);
    assert!(e.contains("scene_fifo.obj") && e.contains("not a regular file"), "{e}");
    let e = trace_scene(Path::new("/nonexistent/scene.obj"));
    assert_eq!(e.matches("No such file or directory").count(), 1, "{e}");
    let p = obj("mtl_zero.obj", "mtllib /dev/zero\nmtllib nowhere.mtl\nv 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n");
    let o = Command::new(env!("CARGO_BIN_EXE_halftrace"))
        .args(["trace", "--scene", p.to_str().unwrap(), "--backend", "cpu", "--width", "4", "--height", "4"])
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(o.status.success(), "{err}");
    assert!(err.contains("/dev/zero is not a regular file") && err.contains("nowhere.mtl was not found"), "{err}");
}

/// Small things a careless user meets: a non-UTF-8 byte in a comment loads (in a statement it
/// is named with its line), `--repeat 0` is refused rather than silently 1, `devices --device`
/// with no such device says so.
#[test]
fn small_input_mistakes_get_clear_answers() {
    let p = tmp("latin1.obj");
    std::fs::write(&p, b"# caf\xe9 comment\nv 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n").unwrap();
    let o = Command::new(env!("CARGO_BIN_EXE_halftrace"))
        .args(["trace", "--scene", p.to_str().unwrap(), "--backend", "cpu", "--width", "4", "--height", "4"])
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let p = tmp("latin1_vertex.obj");
    std::fs::write(&p, b"v 0 0 0\nv 1 0 0\nv 0 1 \xff\nf 1 2 3\n").unwrap();
    let e = trace_scene(&p);
    assert!(e.contains("latin1_vertex.obj:3"), "{e}");
    let t = teapot();
    let e = fails(&["trace", "--scene", t.to_str().unwrap(), "--repeat", "0"]);
    assert!(e.contains("--repeat 0"), "{e}");
    let e = fails(&["devices", "--device", "no-such-gpu"]);
    assert!(e.contains("no-such-gpu") && e.contains("no such device"), "{e}");
}

/// A reader that stops early (`halftrace devices | head -1`) ends the command quietly: no
/// "error: Broken pipe" on stderr.
#[test]
fn a_closed_stdout_ends_quietly() {
    let script = format!("{} devices | head -c 1 >/dev/null", env!("CARGO_BIN_EXE_halftrace"));
    let o = Command::new("bash").args(["-o", "pipefail", "-c", &script]).output().unwrap();
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(!err.contains("Broken pipe") && !err.contains("panicked"), "{err}");
}

/// Every command that writes results checks where before it works: an `--out` that exists and
/// is no folder (a regular file, a device) is refused in well under a second, before a scene is
/// loaded or Vulkan opened, and nothing is written there; so is a folder with an earlier
/// conformance run's files, without `--force`.
#[test]
fn outputs_are_refused_before_any_work() {
    let t = teapot();
    let t = t.to_str().unwrap();
    let file = tmp("mine.txt");
    std::fs::write(&file, "mine").unwrap();
    let file = file.to_str().unwrap();
    let dir = tmp("report-input");
    std::fs::create_dir_all(&dir).unwrap();
    let dir = dir.to_str().unwrap();
    for out in ["/dev/full", file] {
        let what = if out == file { "exists and is a regular file" } else { "exists and is a character device" };
        let runs: Vec<Vec<&str>> = vec![
            vec!["sweep", "--scene", t, "--out", out],
            vec!["sweep", "--scene", t, "--resume", "--out", out],
            vec!["conformance", "--quick", "--scene", t, "--out", out],
            vec!["isa", "--quick", "--out", out],
            vec!["device-report", "--scene", t, "--scenes-dir", "none", "--out", out],
            vec!["report", dir, "--out", out],
            vec!["bench", "--scene", t, "--out", out],
        ];
        for args in runs {
            let t0 = std::time::Instant::now();
            let e = fails(&args);
            let secs = t0.elapsed().as_secs_f64();
            eprintln!("{} --out {out}: refused in {secs:.3} s", args[0]);
            // bench writes one file: an existing one is never overwritten, a device never written.
            let want = if args[0] == "bench" && out == file { "exists; a report is never overwritten" } else { what };
            assert!(e.contains(&format!("--out {out}")) && e.contains(want), "{args:?}: {e}");
            assert!(secs < 5.0, "{args:?}: refused only after {secs:.1} s");
        }
    }
    assert_eq!(std::fs::read_to_string(file).unwrap(), "mine");
    // bench writes its report at the end: a folder that is not there fails it now.
    let e = fails(&["bench", "--scene", t, "--out", "/nonexistent/bench.md"]);
    assert!(e.contains("/nonexistent is not a folder"), "{e}");
    // An earlier conformance run's files are kept unless --force (which gets past the check
    // to the scene, here one that does not exist).
    let conf = tmp("conformance-out");
    std::fs::create_dir_all(&conf).unwrap();
    std::fs::write(conf.join("conformance.md"), "earlier").unwrap();
    let c = conf.to_str().unwrap();
    let t0 = std::time::Instant::now();
    let e = fails(&["conformance", "--quick", "--scene", t, "--out", c]);
    eprintln!("conformance into a folder with results: refused in {:.3} s", t0.elapsed().as_secs_f64());
    assert!(e.contains("already holds conformance.md") && e.contains("--force"), "{e}");
    assert!(t0.elapsed().as_secs_f64() < 5.0);
    let o = Command::new(env!("CARGO_BIN_EXE_halftrace"))
        .args(["conformance", "--quick", "--force", "--scene", "/nonexistent/scene.obj", "--out", c])
        .output()
        .unwrap();
    let e = String::from_utf8_lossy(&o.stderr);
    assert!(!o.status.success() && e.contains("error: /nonexistent/scene.obj") && !e.contains("already holds"), "{e}");
    assert_eq!(std::fs::read_to_string(conf.join("conformance.md")).unwrap(), "earlier");
    assert_eq!(std::fs::read_dir(&conf).unwrap().count(), 1, "a refused run left something behind");
    // A merge's folder of its own that holds rows is someone's results: refused before any
    // input is read (this one has none).
    let rows = tmp("report-out-rows");
    std::fs::create_dir_all(&rows).unwrap();
    std::fs::write(rows.join("results.csv"), "mine").unwrap();
    let r = rows.to_str().unwrap();
    let e = fails(&["report", dir, "--out", r]);
    assert!(e.contains(&format!("--out {r} already holds results.csv; nothing was changed")), "{e}");
    assert_eq!(std::fs::read_to_string(rows.join("results.csv")).unwrap(), "mine");
}

/// A scene's name comes from its file name and names rows and table cells: one with a newline
/// (or another control character, or '|') is refused as a kernel's name is; so is a scene
/// given twice to `bench`, as to `sweep`.
#[test]
fn scene_names_that_would_split_a_report_are_refused() {
    let text = "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n";
    for name in ["two\nlines.obj", "tab\there.obj", "pipe|name.obj"] {
        let p = obj(name, text);
        let e = trace_scene(&p);
        let quoted = format!("{:?}", name.trim_end_matches(".obj"));
        assert!(e.contains(&quoted) && e.contains("rename the file"), "{name:?}: {e}");
        assert_eq!(e.lines().count(), 1, "the message itself is split: {e}");
        let e = fails(&["sweep", "--scene", p.to_str().unwrap(), "--out", tmp("never").to_str().unwrap()]);
        assert!(e.contains("rename the file"), "{e}");
    }
    assert!(!tmp("never").exists());
    let t = teapot();
    let t = t.to_str().unwrap();
    let e = fails(&["bench", "--scene", t, "--scene", t]);
    assert!(e.contains("--scene") && e.contains("are the same file"), "{e}");
    let copy = tmp("teapot.obj");
    std::fs::copy(t, &copy).unwrap();
    let e = fails(&["bench", "--scene", t, "--scene", copy.to_str().unwrap()]);
    assert!(e.contains("would both be 'teapot'"), "{e}");
}

/// `.npy` headers are read as the Python literal NumPy writes: keys in any order and either
/// quote, big-endian float32; a shape whose size overflows is an error, not a panic.
#[test]
fn npy_headers_are_read_as_numpy_reads_them() {
    let ray = [0.5f32, 0.25, 10.0, 0.0, 0.0, 0.0, -1.0, f32::INFINITY];
    let le: Vec<u8> = ray.iter().flat_map(|x| x.to_le_bytes()).collect();
    let be: Vec<u8> = ray.iter().flat_map(|x| x.to_be_bytes()).collect();
    let want = Ray { origin: [0.5, 0.25, 10.0], tmin: 0.0, dir: [0.0, 0.0, -1.0], tmax: f32::INFINITY };
    for (name, header, data) in [
        ("reordered.npy", r#"{"shape": (1, 8), "fortran_order": False, "descr": "<f4"}"#, &le),
        ("big_endian.npy", "{'descr': '>f4', 'fortran_order': False, 'shape': (1, 8), }", &be),
    ] {
        let p = write_raw_npy(name, header, data);
        let r = npy::read_rays(&p).unwrap_or_else(|e| panic!("{name}: {e}"));
        assert_eq!(r.len(), 1);
        assert_eq!((r[0].origin, r[0].tmin, r[0].dir, r[0].tmax), (want.origin, want.tmin, want.dir, want.tmax));
    }
    // Before, the first "'shape'" in the text was taken for the key, here a field's name.
    let p = write_raw_npy(
        "field_named_shape.npy",
        "{'descr': [('shape', '<f4'), ('prim', '<i4'), ('u', '<f4'), ('v', '<f4')], 'fortran_order': False, 'shape': (1,), }",
        &[0u8; 16],
    );
    let e = npy::read_hits(&p).unwrap_err().to_string();
    assert!(e.contains("field_named_shape.npy") && e.contains("structured hits") && e.contains("(1,)"), "{e}");
    // Hits with every name in double quotes (as a hand-written header has them) read as NumPy's.
    let one: Vec<u8> = [1.5f32.to_le_bytes(), 7i32.to_le_bytes(), 0.25f32.to_le_bytes(), 0.5f32.to_le_bytes()].concat();
    let p = write_raw_npy(
        "hits_quoted.npy",
        r#"{"descr": [("t", "<f4"), ("prim", "<i4"), ("u", "<f4"), ("v", "<f4")], "fortran_order": False, "shape": (1,)}"#,
        &one,
    );
    let h = npy::read_hits(&p).unwrap_or_else(|e| panic!("hits_quoted.npy: {e}"));
    assert!(h.len() == 1 && h[0].same_bits(&halftrace::base::Hit { t: 1.5, prim: 7, u: 0.25, v: 0.5 }));
    // A byte-order mark, before the magic or at the start of the header text: refused naming the
    // file (NumPy refuses both too), never read as other numbers.
    let p = write_raw_npy("hits_bom_header.npy", "\u{feff}{'descr': [('t', '<f4'), ('prim', '<i4'), ('u', '<f4'), ('v', '<f4')], 'fortran_order': False, 'shape': (1,), }", &one);
    let e = npy::read_hits(&p).unwrap_err().to_string();
    assert!(e.contains("hits_bom_header.npy") && e.contains("not a .npy file"), "{e}");
    let p = tmp("hits_bom_magic.npy");
    let mut b = b"\xEF\xBB\xBF".to_vec();
    b.extend(std::fs::read(tmp("hits_quoted.npy")).unwrap());
    std::fs::write(&p, b).unwrap();
    let e = npy::read_hits(&p).unwrap_err().to_string();
    assert!(e.contains("hits_bom_magic.npy") && e.contains("not a .npy file"), "{e}");
    let p =
        write_raw_npy("huge.npy", "{'descr': '<f4', 'fortran_order': False, 'shape': (4611686018427387904, 8), }", &le);
    let e = npy::read_rays(&p).unwrap_err().to_string();
    assert!(e.contains("huge.npy") && e.contains("4611686018427387904 rays"), "{e}");
    let p = write_raw_npy(
        "huge3.npy",
        "{'descr': '<f4', 'fortran_order': False, 'shape': (4294967296, 4294967296, 8), }",
        &le,
    );
    let e = npy::read_rays(&p).unwrap_err().to_string();
    assert!(e.contains("huge3.npy") && e.contains("(N, 8)"), "{e}");
    let p = write_raw_npy("v9.npy", "{'descr': '<f4', 'fortran_order': False, 'shape': (1, 8), }", &le);
    let mut b = std::fs::read(&p).unwrap();
    b[6] = 9;
    std::fs::write(&p, b).unwrap();
    let e = npy::read_rays(&p).unwrap_err().to_string();
    assert!(e.contains("v9.npy") && e.contains("not a .npy file") && e.contains("version"), "{e}");
    // What halftrace writes reads back bit for bit.
    let p = tmp("hits_rt.npy");
    let hits = [
        halftrace::base::Hit { t: 1.5, prim: 7, u: 0.25, v: 0.5 },
        halftrace::base::Hit { t: f32::INFINITY, prim: -1, u: 0.0, v: 0.0 },
    ];
    npy::write_hits(&p, &hits).unwrap();
    let back = npy::read_hits(&p).unwrap();
    assert!(back.iter().zip(&hits).all(|(a, b)| a.same_bits(b)) && back.len() == 2);
}
