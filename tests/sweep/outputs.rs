//! A small sweep writes every output, consistently: rows, reports, plots, images; the layouts table; user kernels as rows; bad configs refused.

use super::*;

#[test]
fn small_sweep_writes_consistent_outputs() {
    let out = tmp("small");
    let o = sweep(
        &out,
        &[
            "--rays",
            "primary,ao",
            "--layouts",
            "f32,f16h,rq,embree",
            "--maths",
            "f16,f32,mixed",
            "--branchings",
            "2,8",
            "--packets",
            "1,4,16",
        ],
    );
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    for f in [
        "results.csv",
        "results.json",
        "device_arith.json",
        "report.md",
        "headline.md",
        "ratio_vs_b.png",
        "ratio_vs_b.svg",
        "ratio_vs_p.png",
        "ratio_vs_p.svg",
        "mrays.png",
        "mrays.svg",
        "memory.png",
        "memory.svg",
        "render.png",
        "heat_f32.png",
        "heat_f16h.png",
        "diff_f16h_vs_f32.png",
    ] {
        let p = out.join(f);
        assert!(p.is_file() && std::fs::metadata(&p).unwrap().len() > 0, "{} missing or empty", p.display());
        if f.ends_with(".png") {
            image::open(&p).unwrap_or_else(|e| panic!("{}: {e}", p.display()));
        }
    }
    // variants: ({2, 8} at P=1 ∪ {1, 4, 16} at B=4) = 5, for f32 and for f16h in 3 math
    // modes, plus rq and embree: 22, × 2 ray kinds
    let rows = read_rows(&out).unwrap();
    assert_eq!(rows.len(), 44);
    let arith: halftrace::gpu::arith::ArithRates =
        serde_json::from_str(&std::fs::read_to_string(out.join("device_arith.json")).unwrap()).unwrap();
    assert_eq!(arith.ops.len(), 5);
    assert!(arith.fp16_ratio > 0.0 && rows.iter().all(|r| r.device_fp16_ratio == arith.fp16_ratio));
    let json: Vec<Row> = serde_json::from_str(&std::fs::read_to_string(out.join("results.json")).unwrap()).unwrap();
    // Each row's typed identity is parsed from its columns where a file is read.
    let json: Vec<Row> = json.into_iter().map(Row::typed).collect();
    assert_eq!(json, rows, "results.json and results.csv disagree");
    // no empty field, one row per variant
    let text = std::fs::read_to_string(out.join("results.csv")).unwrap();
    let mut rdr = csv::Reader::from_reader(text.as_bytes());
    for rec in rdr.records() {
        let rec = rec.unwrap();
        assert!(rec.iter().all(|f| !f.is_empty()), "empty field in {rec:?}");
    }
    let mut keys: Vec<_> = rows.iter().map(|r| (r.rays.clone(), r.kernel.clone())).collect();
    assert!(
        rows.iter().any(|r| r.kernel == "trav_f16h_m32_b8_p1")
            && rows.iter().any(|r| r.kernel.starts_with("trav_f16h_mix_b4_p16"))
    );
    keys.sort();
    keys.dedup();
    assert_eq!(keys.len(), rows.len(), "duplicate variant rows");
    for r in &rows {
        assert_eq!(r.status, Status::Ok, "{}: {}", r.kernel, r.status);
        let mrays = r.ray_count as f64 / r.ms_median / 1e3;
        assert!(
            (r.mrays_median - mrays).abs() <= 1e-9 * mrays,
            "{}: Mrays/s {} != rays / median time {}",
            r.kernel,
            r.mrays_median,
            mrays
        );
        assert!(r.mrays_min <= r.mrays_median && r.mrays_median <= r.mrays_max, "{}", r.kernel);
        assert_eq!(r.timed_dispatches, 3);
        assert!(r.build_ms > 0.0 && r.bvh_bytes > 0);
        let baseline = r.layout == "rq" || r.layout == "embree";
        assert_eq!(
            r.float_controls,
            if baseline { "n/a" } else { "on" },
            "{}: float controls on where lavapipe has them",
            r.kernel
        );
        if baseline {
            assert_eq!((r.branching, r.packet), (0, 0), "B and P do not apply to {}", r.layout);
            assert!(r.differs_from_f32 == 0 && r.false_misses == 0, "{} disagrees with f32 on the teapot", r.layout);
            continue;
        }
        assert!(r.nodes_per_ray > 0.0 && r.box_tests_per_ray >= r.nodes_per_ray);
        assert!(r.simd_utilisation > 0.0 && r.simd_utilisation <= 1.0);
        assert_eq!((r.differs_from_f32, r.false_misses, r.max_abs_dt), (0, 0, 0.0), "{} differs from f32", r.kernel);
        assert_eq!(r.bytes_per_node as usize, if r.layout == "f32" { 28 } else { 16 } * r.branching);
        // Stack bytes per ray: entries × (node index + the layout's entry in this math); f16h
        // keeps groups instead: depth − 1 of them, each an entry and an order word.
        let entry = match (r.layout.as_str(), r.math.as_str()) {
            ("f32", _) => 8,
            ("f16h", "f32") => 44,
            _ => 38,
        };
        let expect = if r.layout == "f16h" {
            let depth = (halftrace::variant::stack_entries(r.branching) - 1) / (r.branching - 1);
            (depth - 1) * (entry + if r.branching > 8 { 12 } else { 4 })
        } else {
            halftrace::variant::stack_entries(r.branching) * entry
        };
        assert_eq!(r.stack_bytes_per_ray as usize, expect, "{}", r.kernel);
        assert!(!r.commit.is_empty() && r.device.contains("llvmpipe") || !r.device.is_empty());
    }
    // The headline table is computed from the rows it shows (f16h in the poster's fp16 math).
    let md = std::fs::read_to_string(out.join("report.md")).unwrap();
    assert!(md.contains("Storage vs arithmetic"), "separated-effects table missing");
    for b in [2usize, 8] {
        for (math, col) in [("f16", 0usize), ("f32", 1), ("mixed", 2)] {
            let xs: Vec<f64> = ["primary", "ao"]
                .iter()
                .map(|k| {
                    let h = rows
                        .iter()
                        .find(|r| {
                            r.layout == "f16h" && r.math == math && r.rays == *k && r.branching == b && r.packet == 1
                        })
                        .unwrap();
                    let f = rows
                        .iter()
                        .find(|r| r.layout == "f32" && r.rays == *k && r.branching == b && r.packet == 1)
                        .unwrap();
                    h.mrays_median / f.mrays_median
                })
                .collect();
            let mean = (xs[0] + xs[1]) / 2.0;
            let line = md
                .lines()
                .find(|l| l.starts_with("| llvmpipe") && l.contains(&format!(" | {b} | 1 | ")))
                .expect("separated-effects row");
            let cells: Vec<&str> = line.split('|').map(str::trim).collect();
            assert_eq!(cells[4 + col], format!("{mean:.3}"), "B={b} {math}: {line}");
        }
    }
    let rat = ratios(&rows);
    assert_eq!(rat.len(), 10);
    assert!(rat.iter().all(|x| rows
        .iter()
        .any(|r| r.layout == "f16h" && r.math == "f16" && r.branching == x.branching && r.packet == x.packet)));
    for b in [2usize, 4, 8] {
        let xs: Vec<f64> = rat.iter().filter(|x| x.packet == 1 && x.branching == b).map(|x| x.time).collect();
        assert_eq!(xs.len(), 2, "B={b}: one ratio per ray kind");
        let mean = xs.iter().sum::<f64>() / 2.0;
        let line = md
            .lines()
            .find(|l| l.contains(&format!("| {b} | {mean:.3} |")))
            .unwrap_or_else(|| panic!("report.md has no B={b} row with time ratio {mean:.3}"));
        for x in rat.iter().filter(|x| x.packet == 1 && x.branching == b) {
            let f = rows
                .iter()
                .find(|r| r.layout == "f32" && r.rays == x.rays && r.branching == b && r.packet == 1)
                .unwrap();
            let h = rows
                .iter()
                .find(|r| {
                    r.layout == "f16h" && r.math == "f16" && r.rays == x.rays && r.branching == b && r.packet == 1
                })
                .unwrap();
            assert_eq!(x.time, h.ms_median / f.ms_median);
        }
        let _ = line;
    }
    for p in [1usize, 4, 16] {
        let xs: Vec<f64> = rat.iter().filter(|x| x.branching == 4 && x.packet == p).map(|x| x.time).collect();
        let mean = xs.iter().sum::<f64>() / xs.len() as f64;
        assert!(md.contains(&format!("| {p} | {mean:.3} |")), "report.md has no P={p} row with time ratio {mean:.3}");
    }
    // headline.md (what the README links to) holds report.md's headline tables verbatim.
    let head = std::fs::read_to_string(out.join("headline.md")).unwrap();
    let start = md.find("## Headline").expect("report.md has a headline");
    let table = &md[start..start + md[start..].find("![ratio vs B]").unwrap()];
    assert!(head.contains(table), "headline.md lacks report.md's headline tables:\n{head}");
}

#[test]
fn bad_sweep_configs_are_clear_errors() {
    let bad = std::env::temp_dir().join(format!("halftrace-bad-{}.toml", std::process::id()));
    for (text, want) in [
        ("layouts = [\"f8\"]\n", "unknown layout 'f8'"),
        ("packets = [3]\n", "packets: 3"),
        ("colour = 1\n", "unknown field `colour`"),
        ("branchings = [5]\n", "branching factor 5"),
    ] {
        std::fs::write(&bad, text).unwrap();
        let o = Command::new(env!("CARGO_BIN_EXE_halftrace"))
            .args(["sweep", "--config", bad.to_str().unwrap(), "--out", tmp("bad").to_str().unwrap()])
            .output()
            .unwrap();
        let err = String::from_utf8_lossy(&o.stderr);
        assert!(
            !o.status.success()
                && err.contains(want)
                && err.contains(bad.to_str().unwrap())
                && !err.contains("panicked"),
            "{text}: {err}"
        );
    }
    let example = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("sweep.example.toml");
    assert_eq!(
        halftrace::sweep::Config::load(&example).unwrap(),
        halftrace::sweep::Config::default(),
        "sweep.example.toml documents the defaults"
    );
}

/// `[[kernel]]` tables run as their own rows, validated against the layout's CPU reference
/// like the built-in kernels; a kernel of another layout fails validation and the sweep exits
/// non-zero.
#[test]
fn user_kernels_run_as_their_own_rows() {
    let root = PathBuf::from(env!("CARGO_MANIFEST_DIR"));
    let example = root.join("docs/examples/unordered.comp");
    let emitted = root.join("spirv/trav_f16h_m16_b4_p1.spv");
    let cfg = |extra: &str| {
        let p = std::env::temp_dir().join(format!("halftrace-kernels-{}-{}.toml", std::process::id(), extra.len()));
        std::fs::write(&p, format!(
            "scenes = [{:?}]\nrays = [\"primary\", \"ao\"]\nlayouts = [\"f32\"]\nbranchings = [4]\npackets = [1]\nwidth = 24\nheight = 24\nrepeat = 2\nwarmup = 1\n{extra}",
            teapot()
        )).unwrap();
        p
    };
    let good = format!(
        "[[kernel]]\nname = \"unordered\"\nlayout = \"f16h\"\nfile = {:?}\nbranching = 8\n\n[[kernel]]\nname = \"emitted\"\nlayout = \"f16h\"\nfile = {:?}\nrays = [\"primary\"]\n",
        example.display().to_string(),
        emitted.display().to_string()
    );
    let out = tmp("kernels");
    let o = Command::new(env!("CARGO_BIN_EXE_halftrace"))
        .args(["sweep", "--quiet", "--config", cfg(&good).to_str().unwrap(), "--out", out.to_str().unwrap()])
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let rows = read_rows(&out).unwrap();
    let unordered: Vec<&Row> = rows.iter().filter(|r| r.kernel == "unordered").collect();
    assert_eq!(unordered.len(), 2, "one row per ray kind");
    for r in &unordered {
        assert_eq!((&r.status, r.layout.as_str(), r.branching, r.packet), (&Status::Ok, "f16h", 8, 1));
        assert!(r.mrays_median > 0.0 && r.nodes_per_ray.is_nan(), "a kernel without counters reports none: {r:?}");
        assert_eq!(r.differs_from_f32, 0);
    }
    let emitted_rows: Vec<&Row> = rows.iter().filter(|r| r.kernel == "emitted").collect();
    assert_eq!(emitted_rows.len(), 1);
    assert_eq!(emitted_rows[0].status, Status::Ok);
    assert!(std::fs::read_to_string(out.join("report.md")).unwrap().contains("| unordered |"));

    // The f32 layout's kernel over an f16h BVH: it runs, and returns other hits.
    let f32_module = root.join("spirv/trav_f32_b4_p1.spv");
    let bad = format!(
        "[[kernel]]\nname = \"wrong-layout\"\nlayout = \"f16h\"\nmath = \"f32\"\nfile = {:?}\nrays = [\"primary\"]\n",
        f32_module.display().to_string()
    );
    let out = tmp("kernels-bad");
    let o = Command::new(env!("CARGO_BIN_EXE_halftrace"))
        .args(["sweep", "--quiet", "--config", cfg(&bad).to_str().unwrap(), "--out", out.to_str().unwrap()])
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(!o.status.success() && err.contains("wrong-layout") && err.contains("failed validation"), "{err}");
    let rows = read_rows(&out).unwrap();
    let r = rows.iter().find(|r| r.kernel == "wrong-layout").unwrap();
    assert!(r.status.is_failed() && r.status.to_string().contains("differ from the CPU reference"), "{}", r.status);
}

/// The layouts comparison: every layout and math mode at one B beside f32, one table row and
/// one plot line each; the conservative ones agree with f32 on every ray, and q8's nodes take
/// at most 0.4 of f32's bytes at B = 8.
#[test]
fn layouts_table_sets_every_layout_beside_f32() {
    let out = tmp("layouts");
    let o = sweep(
        &out,
        &[
            "--rays",
            "primary,grazing",
            "--layouts",
            "f32,f16h,f16w,f16a,q8,f16h-poster",
            "--maths",
            "f16,f32",
            "--series",
            "f32",
            "--branchings",
            "8",
            "--packets",
            "1",
            "--packet-branching",
            "8",
            "--layout-branchings",
            "8",
        ],
    );
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let rows = read_rows(&out).unwrap();
    // f32, f16h ×2, f16w ×2, f16a ×2, q8 ×2, f16h-poster: 10 variants × 2 ray kinds
    assert_eq!(rows.len(), 20, "{:?}", rows.iter().map(|r| &r.kernel).collect::<Vec<_>>());
    let f32_bytes = rows.iter().find(|r| r.layout == "f32").unwrap().bvh_bytes as f64;
    for r in &rows {
        assert_eq!(r.status, Status::Ok, "{}: {}", r.kernel, r.status);
        assert_eq!(r.branching, 8);
        if r.layout != "f16h-poster" {
            assert_eq!(
                (r.differs_from_f32, r.false_misses),
                (0, 0),
                "{} {}: a conservative layout differs from f32",
                r.kernel,
                r.rays
            );
        }
        if r.layout == "q8" {
            assert!(r.bvh_bytes as f64 <= 0.4 * f32_bytes, "q8 {} bytes vs f32 {f32_bytes}", r.bvh_bytes);
        }
    }
    let md = std::fs::read_to_string(out.join("report.md")).unwrap();
    let table = &md[md.find("## Layouts").expect("layouts table")..];
    let table = &table[..table.find("\n\n![layouts]").unwrap()];
    for label in [
        "| f32 | 8 |",
        "| f16h/f16 | 8 |",
        "| f16h/f32 | 8 |",
        "| f16w/f32 | 8 |",
        "| f16w/f16 | 8 |",
        "| f16a/f16 | 8 |",
        "| f16a/f32 | 8 |",
        "| q8/f32 | 8 |",
        "| q8/f16 | 8 |",
        "| f16h-poster | 8 |",
    ] {
        assert!(table.contains(label), "no layouts row {label}:\n{table}");
    }
    // f32 against itself is 1 in every ratio.
    let f32_line = table.lines().find(|l| l.contains("| f32 | 8 |")).unwrap();
    assert!(f32_line.contains("| 1.000 | 1.000 |"), "{f32_line}");
    for f in ["layouts.png", "layouts.svg"] {
        assert!(std::fs::metadata(out.join(f)).map(|m| m.len() > 0).unwrap_or(false), "{f} missing");
    }
}
