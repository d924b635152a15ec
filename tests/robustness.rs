//! The second round of hostile inputs (issue 30): compressed bombs, multi-member gzip, PLY
//! counts, outputs that are devices, FIFOs or links, FIFOs as inputs, empty ray files, sweep
//! configurations whose rows would collide, and no silent CPU fallback. Each case as it was
//! reproduced; each refused with a message naming the file or parameter, or answered right.

use std::io::Write;
use std::path::{Path, PathBuf};
use std::process::{Command, Output, Stdio};
use std::time::{Duration, Instant};

const BIN: &str = env!("CARGO_BIN_EXE_halftrace");

fn tmp(name: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("halftrace-robust-{}", std::process::id()));
    std::fs::create_dir_all(&d).unwrap();
    d.join(name)
}

const TRI: &str = "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n";

fn tri() -> PathBuf {
    let p = tmp("tri.obj");
    std::fs::write(&p, TRI).unwrap();
    p
}

fn teapot() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("scenes/teapot.obj")
}

/// Runs the CLI (killed after 60 s: nothing here may block), returns the output.
fn run(args: &[&str], env: &[(&str, &str)]) -> Output {
    let mut c = Command::new(BIN);
    c.args(args).stdin(Stdio::null()).stdout(Stdio::piped()).stderr(Stdio::piped());
    for (k, v) in env {
        c.env(k, v);
    }
    let mut child = c.spawn().unwrap();
    let t0 = Instant::now();
    while child.try_wait().unwrap().is_none() {
        if t0.elapsed() > Duration::from_secs(60) {
            let _ = child.kill();
            panic!("{args:?} still running after 60 s (blocked?)");
        }
        std::thread::sleep(Duration::from_millis(50));
    }
    child.wait_with_output().unwrap()
}

/// Expects a clean failure (exit 1, "error: …", no panic); returns stderr.
fn fails(args: &[&str]) -> String {
    let o = run(args, &[]);
    let err = String::from_utf8_lossy(&o.stderr).to_string();
    assert_eq!(o.status.code(), Some(1), "{args:?}: {err}");
    assert!(err.starts_with("error: ") && !err.contains("panicked"), "{args:?}: {err}");
    err
}

fn gzip(data: &[u8]) -> Vec<u8> {
    let mut e = flate2::write::GzEncoder::new(Vec::new(), flate2::Compression::fast());
    e.write_all(data).unwrap();
    e.finish().unwrap()
}

/// A gzip file of `copies` members, each `chunk` compressed (a few MB inflating to GBs).
fn bomb(name: &str, chunk: &[u8], copies: usize) -> PathBuf {
    let member = gzip(chunk);
    let p = tmp(name);
    let mut f = std::fs::File::create(&p).unwrap();
    for _ in 0..copies {
        f.write_all(&member).unwrap();
    }
    p
}

/// Under `ulimit -v 8000000` a 3 GB gzip of NULs and 3.2 GB of `v 0 0 0` lines aborted on
/// allocation; they are refused, naming the file, within the limit.
#[test]
fn compressed_bombs_are_refused_naming_the_file() {
    let nul = bomb("nul.obj.gz", &vec![0u8; 256 << 20], 12);
    let verts = bomb("verts.obj.gz", &b"v 0 0 0\n".repeat(8 << 20), 50);
    for p in [nul, verts] {
        let script = format!("ulimit -v 8000000; exec {BIN} trace --backend cpu --scene {}", p.display());
        let o = Command::new("sh").args(["-c", &script]).output().unwrap();
        let err = String::from_utf8_lossy(&o.stderr);
        assert_eq!(o.status.code(), Some(1), "{}: {err}", p.display());
        assert!(err.contains(&p.display().to_string()) && err.contains("decompresses to more than"), "{err}");
        std::fs::remove_file(&p).unwrap();
    }
}

/// Every member of a multi-member gzip is read (it loaded the first only); gzip data in a
/// plain-named file is read by its magic; a `.gz` name without gzip data is named.
#[test]
fn gzip_is_read_whole_and_by_its_magic() {
    let n_teapot = halftrace::scene::load(&teapot()).unwrap().len();
    let both = tmp("concat.obj.gz");
    let mut bytes = gzip(TRI.as_bytes());
    bytes.extend(gzip(&std::fs::read(teapot()).unwrap()));
    std::fs::write(&both, &bytes).unwrap();
    assert_eq!(halftrace::scene::load(&both).unwrap().len(), 1 + n_teapot);
    let plain = tmp("secretly_gzip.obj");
    std::fs::write(&plain, gzip(TRI.as_bytes())).unwrap();
    assert_eq!(halftrace::scene::load(&plain).unwrap().len(), 1);
    let fake = tmp("not_gzip.obj.gz");
    std::fs::write(&fake, TRI).unwrap();
    let e = halftrace::scene::load(&fake).unwrap_err().to_string();
    assert!(e.contains("not_gzip.obj.gz") && e.contains("gzip"), "{e}");
}

/// A PLY header whose counts disagree with its data is refused (extra faces were dropped), and
/// a truncated element is named.
#[test]
fn ply_counts_must_match_the_data() {
    let head = |faces: usize| {
        format!(
            "ply\nformat ascii 1.0\nelement vertex 4\nproperty float x\nproperty float y\nproperty float z\n\
             element face {faces}\nproperty list uchar int vertex_indices\nend_header\n0 0 0\n1 0 0\n0 1 0\n1 1 0\n"
        )
    };
    let p = tmp("short_header.ply");
    std::fs::write(&p, head(1) + "3 0 1 2\n3 1 3 2\n").unwrap();
    let e = halftrace::scene::load(&p).unwrap_err().to_string();
    assert!(e.contains("short_header.ply") && e.contains("1 face") && e.contains("counts do not match"), "{e}");
    let p = tmp("truncated.ply");
    std::fs::write(&p, head(3) + "3 0 1 2\n").unwrap();
    let e = halftrace::scene::load(&p).unwrap_err().to_string();
    assert!(e.contains("truncated.ply") && e.contains("element 'face' (3 declared, from line 14)"), "{e}");
    let p = tmp("exact.ply");
    std::fs::write(&p, head(2) + "3 0 1 2\n3 1 3 2\n").unwrap();
    assert_eq!(halftrace::scene::load(&p).unwrap().len(), 2);
}

/// An output that exists and is not a regular file — a device, a FIFO, a symbolic link, a
/// folder — is refused before any work and left as it was (the rename replaced /dev/full).
#[test]
fn outputs_never_replace_devices_fifos_or_links() {
    use std::os::unix::fs::FileTypeExt;
    let t = tri();
    let t = t.to_str().unwrap();
    let fifo = tmp("out_fifo.npy");
    let _ = std::fs::remove_file(&fifo);
    assert!(Command::new("mkfifo").arg(&fifo).status().unwrap().success());
    let target = tmp("target.npy");
    std::fs::write(&target, b"keep").unwrap();
    let link = tmp("link.npy");
    let _ = std::fs::remove_file(&link);
    std::os::unix::fs::symlink(&target, &link).unwrap();
    let dir = tmp("a_folder.npy");
    std::fs::create_dir_all(&dir).unwrap();
    let cases: [(&str, &Path, &str); 5] = [
        ("--out", Path::new("/dev/full"), "character device"),
        ("--save-rays", Path::new("/dev/full"), "character device"),
        ("--out", &fifo, "FIFO"),
        ("--out", &link, "symbolic link"),
        ("--out", &dir, "folder"),
    ];
    for (flag, p, what) in cases {
        let e = fails(&[
            "trace",
            "--scene",
            t,
            "--backend",
            "cpu",
            "--width",
            "4",
            "--height",
            "4",
            flag,
            p.to_str().unwrap(),
        ]);
        assert!(e.contains(flag) && e.contains(&p.display().to_string()) && e.contains(what), "{flag} {what}: {e}");
    }
    assert!(std::fs::metadata("/dev/full").unwrap().file_type().is_char_device(), "/dev/full is no longer a device");
    assert!(std::fs::symlink_metadata(&fifo).unwrap().file_type().is_fifo());
    assert!(std::fs::symlink_metadata(&link).unwrap().file_type().is_symlink());
    assert_eq!(std::fs::read(&target).unwrap(), b"keep");
    // bench refuses an existing report as instance does, and a device.
    let report = tmp("bench.md");
    std::fs::write(&report, b"my notes").unwrap();
    let e = fails(&["bench", "--scene", t, "--out", report.to_str().unwrap()]);
    assert!(e.contains("bench.md") && e.contains("never overwritten"), "{e}");
    assert_eq!(std::fs::read(&report).unwrap(), b"my notes");
    let e = fails(&["bench", "--scene", t, "--out", "/dev/full"]);
    assert!(e.contains("character device"), "{e}");
}

/// A FIFO with no writer as `--rays` or `--config` blocked forever; a rays file of no rays
/// reported speeds and 100% SIMD utilisation.
#[test]
fn inputs_must_be_regular_files_with_something_in_them() {
    let t = tri();
    let t = t.to_str().unwrap();
    let fifo = tmp("in_fifo.npy");
    let _ = std::fs::remove_file(&fifo);
    assert!(Command::new("mkfifo").arg(&fifo).status().unwrap().success());
    let f = fifo.to_str().unwrap();
    let e = fails(&["trace", "--scene", t, "--backend", "cpu", "--rays", f]);
    assert!(e.contains("in_fifo.npy") && e.contains("not a regular file"), "{e}");
    let e = fails(&["sweep", "--config", f, "--out", tmp("never").to_str().unwrap()]);
    assert!(e.contains("in_fifo.npy") && e.contains("not a regular file"), "{e}");
    let empty = tmp("no_rays.npy");
    halftrace::npy::write_rays(&empty, &[]).unwrap();
    let e = fails(&["trace", "--scene", t, "--backend", "cpu", "--rays", empty.to_str().unwrap()]);
    assert!(e.contains("no_rays.npy") && e.contains("at least one ray"), "{e}");
    assert!(!tmp("never").exists());
}

/// Sweep configurations whose rows would collide are refused when read: no layouts, one
/// scene twice, two scenes of one name, user kernels named like a built-in, empty, or with a
/// control character (a newline split the report's table).
#[test]
fn sweep_configs_whose_rows_would_collide_are_refused() {
    let t = tri();
    let a = tmp("a");
    let b = tmp("b");
    std::fs::create_dir_all(&a).unwrap();
    std::fs::create_dir_all(&b).unwrap();
    std::fs::write(a.join("tri.obj"), TRI).unwrap();
    std::fs::write(b.join("tri.obj"), TRI).unwrap();
    let kernel = tmp("mine.comp");
    std::fs::write(&kernel, "#version 460\nvoid main() {}\n").unwrap();
    let ts = t.display().to_string();
    let dot = format!("{}/./tri.obj", t.parent().unwrap().display());
    let k = kernel.display().to_string();
    let cases: Vec<(String, &str)> = vec![
        ("layouts = []\n".into(), "layouts: at least one"),
        (format!("scenes = [{ts:?}, {ts:?}]\n"), "are the same file"),
        (format!("scenes = [{ts:?}, {dot:?}]\n"), "are the same file"),
        (format!("scenes = [{:?}, {:?}]\n", a.join("tri.obj"), b.join("tri.obj")), "would both be 'tri'"),
        (format!("[[kernel]]\nname = \"trav_f32_b4_p1\"\nlayout = \"f32\"\nfile = {k:?}\n"), "built-in"),
        (format!("[[kernel]]\nname = \"\"\nlayout = \"f32\"\nfile = {k:?}\n"), "printable"),
        (format!("[[kernel]]\nname = \"two\\nlines\"\nlayout = \"f32\"\nfile = {k:?}\n"), "printable"),
    ];
    for (i, (toml, want)) in cases.iter().enumerate() {
        let p = tmp(&format!("collide-{i}.toml"));
        std::fs::write(&p, toml).unwrap();
        let e = fails(&["sweep", "--config", p.to_str().unwrap(), "--out", tmp("never").to_str().unwrap()]);
        assert!(e.contains(&format!("collide-{i}.toml")) && e.contains(want), "{toml}: {e}");
    }
    let e = fails(&[
        "sweep",
        "--scene",
        &a.join("tri.obj").display().to_string(),
        "--scene",
        &b.join("tri.obj").display().to_string(),
        "--out",
        tmp("never").to_str().unwrap(),
    ]);
    assert!(e.contains("would both be 'tri'"), "{e}");
    assert!(!tmp("never").exists());
}

/// Without a Vulkan driver `trace` said nothing and traced on the CPU: now it says so and
/// why; `--backend gpu` fails.
#[test]
fn no_silent_cpu_fallback() {
    let t = tri();
    let t = t.to_str().unwrap();
    let missing = [("VK_ICD_FILENAMES", "/nonexistent/icd.json"), ("VK_DRIVER_FILES", "/nonexistent/icd.json")];
    let o = run(&["trace", "--scene", t, "--width", "4", "--height", "4"], &missing);
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(o.status.success(), "{err}");
    assert!(err.contains("warning: no Vulkan device") && err.contains("CPU reference"), "{err}");
    let o = run(&["trace", "--scene", t, "--width", "4", "--height", "4", "--backend", "gpu"], &missing);
    let err = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(1), "{err}");
    assert!(err.starts_with("error: "), "{err}");
}

/// A one-triangle glTF with `node` as its only node and its positions in `uri`.
fn gltf(name: &str, version: &str, node: &str, byte_length: usize, uri: &str) -> PathBuf {
    let json = format!(
        r#"{{"asset":{{"version":"{version}"}},"scene":0,"scenes":[{{"nodes":[0]}}],"nodes":[{node}],
        "meshes":[{{"primitives":[{{"attributes":{{"POSITION":0}}}}]}}],
        "accessors":[{{"bufferView":0,"componentType":5126,"count":3,"type":"VEC3","min":[0,0,0],"max":[1,1,0]}}],
        "bufferViews":[{{"buffer":0,"byteLength":36}}],
        "buffers":[{{"byteLength":{byte_length},"uri":"{uri}"}}]}}"#
    );
    let p = tmp(name);
    std::fs::write(&p, json).unwrap();
    p
}

/// glTF that was accepted and read wrongly: transforms validated, the version, byteLength,
/// and buffer URIs confined to the file's folder; a bad GLB magic and a JSON root that is not
/// an object are named as such.
#[test]
fn gltf_transforms_versions_lengths_and_uris_are_checked() {
    let tri: Vec<u8> = [0f32, 0., 0., 1., 0., 0., 0., 1., 0.].iter().flat_map(|x| x.to_le_bytes()).collect();
    std::fs::write(tmp("tri.bin"), &tri).unwrap();
    let mut long = tri.clone();
    long.extend([0u8; 12]);
    std::fs::write(tmp("long.bin"), &long).unwrap();
    let outside = std::env::temp_dir().join(format!("halftrace-outside-{}.bin", std::process::id()));
    std::fs::write(&outside, &tri).unwrap();
    let load = |p: &Path| halftrace::scene::load(p).map(|s| s.len()).map_err(|e| e.to_string());
    let ok = gltf("ok.gltf", "2.0", r#"{"mesh":0,"rotation":[0,0,0,1]}"#, 36, "tri.bin");
    assert_eq!(load(&ok), Ok(1));
    let cases = [
        (
            "zero_q.gltf",
            "2.0",
            r#"{"mesh":0,"rotation":[0,0,0,0]}"#,
            36,
            "tri.bin".to_string(),
            "not a unit quaternion",
        ),
        (
            "both.gltf",
            "2.0",
            r#"{"mesh":0,"matrix":[1,0,0,0,0,1,0,0,0,0,1,0,0,0,0,1],"translation":[5,0,0]}"#,
            36,
            "tri.bin".to_string(),
            "both a matrix and",
        ),
        (
            "projective.gltf",
            "2.0",
            r#"{"mesh":0,"matrix":[1,0,0,0.5,0,1,0,0,0,0,1,0,0,0,0,1]}"#,
            36,
            "tri.bin".to_string(),
            "not affine",
        ),
        ("v3.gltf", "3.0", r#"{"mesh":0}"#, 36, "tri.bin".to_string(), "asset.version is 3.0"),
        (
            "short.gltf",
            "2.0",
            r#"{"mesh":0}"#,
            36,
            "long.bin".to_string(),
            "byteLength 36 is smaller than its 48 bytes",
        ),
        ("abs.gltf", "2.0", r#"{"mesh":0}"#, 36, outside.display().to_string(), "outside the glTF's folder"),
        (
            "up.gltf",
            "2.0",
            r#"{"mesh":0}"#,
            36,
            format!("../{}", outside.file_name().unwrap().to_str().unwrap()),
            "outside",
        ),
    ];
    for (name, version, node, len, uri, want) in cases {
        let p = gltf(name, version, node, len, &uri);
        let e = load(&p).expect_err(name);
        assert!(e.contains(name) && e.contains(want), "{name}: {e}");
    }
    let p = tmp("notglb.glb");
    std::fs::write(&p, b"{\"asset\":{\"version\":\"2.0\"}}").unwrap();
    let e = load(&p).unwrap_err();
    assert!(e.contains("notglb.glb") && e.contains("magic 'glTF'"), "{e}");
    let p = tmp("array.gltf");
    std::fs::write(&p, b"[1, 2, 3]").unwrap();
    let e = load(&p).unwrap_err();
    assert!(e.contains("array.gltf") && e.contains("root is not a JSON object"), "{e}");
    std::fs::remove_file(&outside).unwrap();
}
