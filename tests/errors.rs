//! Bad input gets a clear error naming the file, line or parameter; never a panic.

use halftrace::npy;
use halftrace::rays::Ray;
use std::path::{Path, PathBuf};
use std::process::Command;

fn tmp(name: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("halftrace-errors-{}", std::process::id()));
    std::fs::create_dir_all(&d).unwrap();
    d.join(name)
}

fn teapot() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../shared/scenes/teapot.obj")
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
        .args(["trace", "--scene", p.to_str().unwrap(), "--layout", "f32", "--width", "16", "--height", "16", "--out", tmp("degen_hits.npy").to_str().unwrap()])
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
    ok(&["trace", "--scene", t.to_str().unwrap(), "--rays", "ao", "--width", "32", "--height", "32", "--save-rays", rays.to_str().unwrap(), "--out", hits.to_str().unwrap()]);
    ok(&["trace", "--scene", t.to_str().unwrap(), "--layout", "f32", "--branching", "16", "--rays", rays.to_str().unwrap(), "--out", hits2.to_str().unwrap()]);
    let a = npy::read_hits(&hits).unwrap();
    let b = npy::read_hits(&hits2).unwrap();
    assert_eq!(a.len(), npy::read_rays(&rays).unwrap().len());
    assert!(a.iter().zip(&b).all(|(x, y)| x.same_bits(y)), "hits from the saved rays differ");
    assert!(a.iter().any(|h| h.is_hit()) && a.iter().any(|h| !h.is_hit()));
    assert!(a.iter().filter(|h| !h.is_hit()).all(|h| h.t == f32::INFINITY && h.prim == -1));
}
