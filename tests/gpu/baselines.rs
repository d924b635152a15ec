//! Baselines (`rq`, `rt`), a kernel that never ends, and `halftrace bench`.

use super::*;

/// The driver's ray queries (baseline `rq`) against the f32 reference: same prim, or t within
/// 1e-5 relative where triangles tie or share edges; at least 99.99% of primary, ao and
/// diffuse rays on every shared scene. The grazing set (rays through shared vertices and
/// along edges) is reported, not held to the bar: it measures whether the driver's triangle
/// test is watertight, which the Vulkan spec does not require.
#[test]
fn ray_query_baseline_agrees_with_f32_on_every_scene() {
    let g = gpu();
    let rq = halftrace::baseline::BaselineId::parse("rq").expect("rq is a baseline").imp();
    assert!(
        rq.unavailable(&g.info).is_none(),
        "{} has no ray queries; lavapipe from Mesa >= 24 has them (scripts/install-deps.sh)",
        g.info.name
    );
    let dev = rq.prepare(&g).unwrap();
    baseline_agrees_with_f32("rq", dev.as_ref(), 0);
    drop(dev);
    clean(&g);
}

/// The driver's ray-tracing pipeline (baseline `rt`: the acceleration structure rq traces,
/// `traceRayEXT` from a ray-generation shader) against the f32 reference, held to rq's bar on
/// four scenes that stress a triangle test (the bundled teapot; the Cornell box's axis-aligned
/// walls; the pine's thin overlapping cards; the stadium's five orders of magnitude), and ray
/// for ray against rq (reported: the same driver, so the same triangle test, but a driver may
/// trace the two differently).
#[test]
fn ray_tracing_pipeline_baseline_agrees_with_f32() {
    let g = gpu();
    let id = |n: &str| halftrace::baseline::BaselineId::parse(n).unwrap_or_else(|| panic!("{n} is a baseline")).imp();
    let (rt, rq) = (id("rt"), id("rq"));
    assert!(
        rt.unavailable(&g.info).is_none(),
        "{} has no ray-tracing pipelines; lavapipe from Mesa >= 25 has them (scripts/install-deps.sh)",
        g.info.name
    );
    let dev = rt.prepare(&g).unwrap();
    let scenes: Vec<PathBuf> = ["teapot.obj", "cornell_box.obj", "smallpine.obj", "teapot_in_stadium.obj"]
        .iter()
        .map(|s| scene_path(s))
        .collect();
    baseline_agrees_with_f32_on("rt", dev.as_ref(), 0, &scenes);
    let q = rq.prepare(&g).unwrap();
    let p = prepare(&scenes[0]);
    let (a, b) = (dev.scene(&p.scene).unwrap(), q.scene(&p.scene).unwrap());
    for (kind, rays) in ray_sets(&p, 32, 500) {
        let (x, y) = (a.run(&rays, 0, 1).unwrap().hits, b.run(&rays, 0, 1).unwrap().hits);
        let same = x.iter().zip(&y).filter(|(x, y)| x.same_bits(y)).count();
        eprintln!("teapot {kind}: rt's hits equal rq's, bit for bit, on {same} of {} rays", rays.len());
    }
    drop((a, b, dev, q));
    clean(&g);
}

/// `--mask-feature rayTracingPipeline` hides `rt` (one skipped line, naming why) and nothing
/// else; the device still opens, with the validation layer silent.
#[test]
fn masking_the_ray_tracing_pipeline_skips_rt() {
    let opts =
        ContextOptions { mask_features: vec!["rayTracingPipeline".into()], validation: true, ..Default::default() };
    let g = Gpu::new(&opts).unwrap();
    let b = |n: &str| halftrace::baseline::BaselineId::parse(n).unwrap().imp();
    assert!(b("rt").unavailable(&g.info).is_some_and(|why| why.contains("VK_KHR_ray_tracing_pipeline")));
    assert!(b("rq").unavailable(&g.info).is_none(), "rq still runs");
    clean(&g);
    let (ok, out, err) = cli(&["devices", "--device", "0", "--mask-feature", "rayTracingPipeline"]);
    assert!(ok, "{err}");
    let line = out.lines().find(|l| l.trim_start().starts_with("rt ")).unwrap_or_else(|| panic!("no rt line:\n{out}"));
    assert!(line.contains("skipped: ") && line.contains("rayTracingPipeline"), "{line}");
    let (ok, out, _) = cli(&["devices", "--device", "0"]);
    assert!(ok && out.lines().any(|l| l.trim_start().starts_with("rt ") && l.trim_end().ends_with("runs")), "{out}");
}

/// A small sweep with both driver baselines: one `rt` row per ray kind, validated against f32
/// (agreement recorded), and the report's and the device headline's comparisons with it.
#[test]
fn ray_tracing_pipeline_rows_in_a_sweep() {
    let out = tmp("rt-sweep");
    let _ = std::fs::remove_dir_all(&out);
    let scene = repo("scenes/teapot.obj");
    let (ok, _, err) = cli(&[
        "sweep",
        "--quiet",
        "--scene",
        scene.to_str().unwrap(),
        "--layouts",
        "f32,rq,rt",
        "--branchings",
        "4",
        "--packets",
        "1",
        "--layout-branchings",
        "4",
        "--rays",
        "primary,ao",
        "--width",
        "16",
        "--height",
        "16",
        "--repeat",
        "1",
        "--out",
        out.to_str().unwrap(),
    ]);
    assert!(ok, "{err}");
    let rows = halftrace::report::read_rows(&out).unwrap();
    let rt: Vec<_> = rows.iter().filter(|r| r.layout == "rt").collect();
    assert_eq!(rt.len(), 2, "{rows:?}");
    for r in &rt {
        assert!(r.status.is_ok() && r.kernel == "trav_rt", "{r:?}");
        assert!(r.mrays_median > 0.0 && r.bvh_bytes > 0, "{r:?}");
    }
    let md = std::fs::read_to_string(out.join("report.md")).unwrap();
    assert!(md.contains("## Against `rt`") && md.contains("÷ rt"), "no comparison with rt in report.md");
    let head = halftrace::report::tables::device_headline(&rows);
    assert!(head.contains("f32 (B = 4) ÷ `rt`") && head.contains("f32 (B = 4) ÷ `rq`"), "{head}");
}

/// The baseline writes the image, rays and hits it is asked for, like every layout.
#[test]
fn ray_query_baseline_writes_its_outputs() {
    let (img, rays, hits) = (tmp("rq.png"), tmp("rq_rays.npy"), tmp("rq_hits.npy"));
    let scene = scene_path("teapot.obj");
    let (ok, out, err) = cli(&[
        "trace",
        "--scene",
        scene.to_str().unwrap(),
        "--layout",
        "rq",
        "--width",
        "24",
        "--height",
        "24",
        "--image",
        img.to_str().unwrap(),
        "--save-rays",
        rays.to_str().unwrap(),
        "--out",
        hits.to_str().unwrap(),
    ]);
    assert!(ok, "{out}{err}");
    assert_eq!(image::open(&img).unwrap().width(), 24);
    assert_eq!(halftrace::npy::read_rays(&rays).unwrap().len(), 576);
    assert_eq!(halftrace::npy::read_hits(&hits).unwrap().len(), 576);
}

/// A kernel that never terminates is declared hung after --kernel-timeout instead of hanging
/// the process; in a sweep it is recorded as a FAILED row, the sweep stops (the device is still
/// busy with it) and `--resume` continues after it. Only the hanging kernel has a 2 s timeout
/// (its table's own `kernel_timeout`); the well-behaved f32 kernel beside it keeps the sweep's
/// default, so a loaded machine cannot make it hung too (a shared 2 s once did, beside a release
/// build).
#[test]
fn a_kernel_that_never_ends_is_reported_hung() {
    let k = tmp("hang.comp");
    std::fs::write(&k, "#version 460\n#include \"interface.glsl\"\n#include \"ray.glsl\"\nvoid main() {\n    uint i = ray_index();\n    if (i >= pc.ray_count) return;\n    float t = ray_f[8u * i];\n    while (t == t) { t += 1.0; hits[i] = Hit(t, 0, 0.0, 0.0); }\n}\n").unwrap();
    let scene = scene_path("teapot.obj");
    let t0 = std::time::Instant::now();
    let (ok, out, err) = cli(&[
        "trace",
        "--scene",
        scene.to_str().unwrap(),
        "--layout",
        "f32",
        "--kernel",
        k.to_str().unwrap(),
        "--kernel-timeout",
        "2",
        "--width",
        "8",
        "--height",
        "8",
    ]);
    assert!(!ok && err.contains("within 2 s"), "{out}{err}");
    assert!(t0.elapsed().as_secs() < 60, "took {:?}", t0.elapsed());
    let cfg = tmp("hang.toml");
    std::fs::write(&cfg, format!("scenes = [{:?}]\nrays = [\"primary\"]\nlayouts = [\"f32\"]\nbranchings = [4]\npackets = [1]\nlayout_branchings = [4]\nwidth = 8\nheight = 8\nrepeat = 1\nwarmup = 0\n\n[[kernel]]\nname = \"hang\"\nlayout = \"f32\"\nfile = {:?}\nkernel_timeout = 2.0\n", scene.display().to_string(), k.display().to_string())).unwrap();
    let out_dir = tmp("hang-sweep");
    let _ = std::fs::remove_dir_all(&out_dir);
    let (ok, _, err) =
        cli(&["sweep", "--quiet", "--config", cfg.to_str().unwrap(), "--out", out_dir.to_str().unwrap()]);
    assert!(!ok && err.contains("hang") && err.contains("within 2 s") && err.contains("--resume"), "{err}");
    let rows = halftrace::report::read_rows(&out_dir).unwrap();
    assert_eq!(rows.len(), 2, "{rows:?}");
    assert!(
        rows[0].status.is_ok() && rows[1].kernel == "hang" && rows[1].status.to_string().starts_with("FAILED: hung"),
        "{rows:?}"
    );
    let (ok, _, err) =
        cli(&["sweep", "--quiet", "--config", cfg.to_str().unwrap(), "--out", out_dir.to_str().unwrap(), "--resume"]);
    assert!(ok, "{err}");
    assert_eq!(halftrace::report::read_rows(&out_dir).unwrap().len(), 2);
}

/// `halftrace bench` validates every target, then prints every ratio the speed issue names
/// (median, min, max over its rounds, with the target) and every target's speed; `--out`
/// writes the same report.
#[test]
fn bench_prints_every_ratio_with_medians_and_ranges() {
    let md = tmp("bench.md");
    let scene = repo("scenes/teapot.obj");
    let (ok, out, err) = cli(&[
        "bench",
        "--scene",
        scene.to_str().unwrap(),
        "--width",
        "16",
        "--height",
        "16",
        "--rounds",
        "2",
        "--repeat",
        "1",
        "--out",
        md.to_str().unwrap(),
    ]);
    assert!(ok, "{err}");
    assert!(err.contains("targets validated"), "{err}");
    let text = std::fs::read_to_string(&md).unwrap();
    assert!(out.contains(&text), "--out differs from what was printed");
    for what in [
        "f16h fp32-math ÷ f32, B = 8, P = 1",
        "f16h fp16-math ÷ f32, B = 8, P = 1",
        "best reduced-precision ÷ f32 (same B), largest scene",
        "best halftrace variant ÷ embree (host CPU)",
        "P = 8 ÷ P = 1, f32, B = 4",
        "P = 64 ÷ P = 1, f32, B = 4",
        "f32 ÷ rq (driver ray queries)",
    ] {
        let line = text
            .lines()
            .find(|l| l.starts_with(&format!("| {what} |")))
            .unwrap_or_else(|| panic!("no ratio '{what}' in\n{text}"));
        let cells: Vec<&str> = line.split('|').map(str::trim).collect();
        let (med, lo, hi): (f64, f64, f64) =
            (cells[5].parse().unwrap(), cells[6].parse().unwrap(), cells[7].parse().unwrap());
        assert!(lo > 0.0 && lo <= med && med <= hi, "{line}");
    }
    for t in ["trav_f32_b8_p1", "trav_f16h_m16_b8_p1", "trav_q8_m32_b4_p1", "rq", "embree"] {
        assert!(text.contains(&format!("| teapot | primary | {t} |")), "no speed of {t}");
    }
    // --layouts narrows the reduced-precision set (f32 stays); a baseline or unknown name is
    // refused before anything runs.
    for (bad, want) in [("rq", "a baseline"), ("f9", "unknown layout 'f9'")] {
        let (ok, _, err) = cli(&["bench", "--scene", scene.to_str().unwrap(), "--layouts", bad]);
        assert!(!ok && err.contains(want), "{bad}: {err}");
    }
}
