//! `halftrace sweep`: the Cartesian product of scenes × ray kinds × variants, each variant
//! validated against the CPU reference of its layout, then timed, then counted; one result
//! row per variant, written as it finishes.

use crate::bvh;
use crate::encode::Layout;
use crate::gpu::{self, traversal};
use crate::pipeline::{make_rays, Encoded, RayKind, RayParams};
use crate::report::{self, Row};
use crate::trace::{packet, Hit};
use crate::variant::{stack_entries, Math, Variant, PACKETS};
use anyhow::Context;
use serde::Deserialize;
use std::collections::HashMap;
use std::path::{Path, PathBuf};

/// A sweep, as given by `--config sweep.toml` or by flags (see `sweep.example.toml`).
#[derive(Clone, Debug, Deserialize, PartialEq)]
#[serde(deny_unknown_fields, default)]
pub struct Config {
    /// OBJ / .obj.gz files.
    pub scenes: Vec<PathBuf>,
    /// primary, ao, diffuse, grazing or FILE.npy.
    pub rays: Vec<String>,
    /// f32, f16h, rq (the driver's ray queries; skipped on devices without them).
    pub layouts: Vec<String>,
    /// Branching factors swept at P = 1.
    pub branchings: Vec<usize>,
    /// Packet sizes swept at B = `packet_branching`.
    pub packets: Vec<usize>,
    /// f16h math modes: f16 (the seed), f32 (fp16 nodes, fp32 tests), mixed.
    pub maths: Vec<String>,
    pub packet_branching: usize,
    pub width: u32,
    pub height: u32,
    pub seed: u64,
    pub warmup: usize,
    pub repeat: usize,
    /// Vulkan device index or name substring ("" = default device).
    pub device: String,
}

/// The bundled scene of the default sweep.
pub const DEFAULT_SCENE: &str = "scenes/teapot.obj";

impl Default for Config {
    fn default() -> Config {
        Config {
            scenes: vec![PathBuf::from(DEFAULT_SCENE)],
            rays: vec!["primary".into(), "ao".into()],
            layouts: vec!["f32".into(), "f16h".into(), "rq".into()],
            branchings: bvh::BRANCHINGS.to_vec(),
            packets: PACKETS.to_vec(),
            maths: vec!["f16".into(), "f32".into()],
            packet_branching: 4,
            width: 256,
            height: 256,
            seed: 1,
            warmup: 2,
            repeat: 10,
            device: String::new(),
        }
    }
}

impl Config {
    pub fn load(path: &Path) -> anyhow::Result<Config> {
        let text = std::fs::read_to_string(path).with_context(|| format!("reading {}", path.display()))?;
        let c: Config = toml::from_str(&text).with_context(|| format!("{}: invalid sweep config", path.display()))?;
        c.check().with_context(|| path.display().to_string())?;
        Ok(c)
    }

    /// Checks every value names something that exists.
    pub fn check(&self) -> anyhow::Result<()> {
        anyhow::ensure!(!self.scenes.is_empty(), "scenes: at least one scene is needed");
        anyhow::ensure!(!self.rays.is_empty(), "rays: at least one ray kind is needed");
        for r in &self.rays {
            r.parse::<RayKind>()?;
        }
        for l in self.layouts.iter().filter(|l| *l != "rq") {
            l.parse::<Layout>()?;
        }
        for &b in self.branchings.iter().chain([&self.packet_branching]) {
            bvh::check_branching(b).context("branchings")?;
        }
        for &p in &self.packets {
            anyhow::ensure!(PACKETS.contains(&p), "packets: {p} is not one of 1, 4, 8, 16, 32, 64");
        }
        for m in &self.maths {
            m.parse::<Math>().map_err(anyhow::Error::msg).context("maths")?;
        }
        anyhow::ensure!(self.repeat >= 1, "repeat must be at least 1");
        anyhow::ensure!(self.width > 0 && self.height > 0, "width and height must be positive");
        Ok(())
    }

    /// The variants: every layout × (B series at P = 1 ∪ P series at `packet_branching`).
    pub fn variants(&self) -> Vec<Variant> {
        let mut v = Vec::new();
        for l in self.layouts.iter().filter(|l| *l != "rq") {
            let layout: Layout = l.parse().unwrap();
            let maths: Vec<Math> = if layout == Layout::F16h { self.maths.iter().map(|m| m.parse().unwrap()).collect() } else { vec![Math::F32] };
            for math in maths {
                for &b in &self.branchings {
                    v.push(Variant::new(layout, b, 1).with_math(math));
                }
                for &p in &self.packets {
                    v.push(Variant::new(layout, self.packet_branching, p).with_math(math));
                }
            }
        }
        v.sort();
        v.dedup();
        v
    }
}

/// Stack bytes per ray of a variant: entries × entry size (f32: node + entry distance, 8 bytes;
/// f16h: node, frame w.xyz k, origin xyz fp16, error, tp, tlo, 38 bytes).
pub fn stack_bytes(v: &Variant) -> u64 {
    let entry = match v.layout {
        Layout::F32 => 8,
        Layout::F16h => 4 + 16 + 6 + 4 + 4 + 4,
    };
    (stack_entries(v.branching) * entry) as u64
}

/// Outcome of a sweep.
pub struct Summary {
    pub rows: usize,
    pub failed: Vec<String>,
    pub out: PathBuf,
}

/// Runs a sweep, writing `results.csv`/`.json` as it goes, then the report. `mask`: device
/// features to treat as missing (testing).
pub fn run(cfg: &Config, out: &Path, quiet: bool, mask: &[String]) -> anyhow::Result<Summary> {
    cfg.check()?;
    let opts = gpu::ContextOptions { device: (!cfg.device.is_empty()).then(|| cfg.device.clone()), mask_features: mask.to_vec(), ..Default::default() };
    let g = gpu::Gpu::new(&opts)?;
    let mut writer = report::Writer::create(out)?;
    let dev_bench = gpu::bench::run(&g, 16384, 256, 3)?;
    std::fs::write(out.join("device_bench.json"), serde_json::to_string_pretty(&dev_bench)?)?;
    let variants = cfg.variants();
    let kinds: Vec<RayKind> = cfg.rays.iter().map(|r| r.parse().unwrap()).collect();
    let with_rq = cfg.layouts.iter().any(|l| l == "rq");
    let total = (cfg.scenes.len() * kinds.len() * (variants.len() + with_rq as usize)) as u64;
    let rq_pipe = if with_rq && g.info.ray_query { Some(gpu::rq::pipeline(&g)?) } else { None };
    let bar = if quiet { indicatif::ProgressBar::hidden() } else { indicatif::ProgressBar::new(total) };
    bar.set_style(indicatif::ProgressStyle::with_template("{bar:30} {pos}/{len} [{elapsed_precise} ETA {eta}] {msg}").unwrap());
    let mut kernels: HashMap<(Variant, bool), traversal::Kernel> = HashMap::new();
    let mut failed = Vec::new();
    let version = env!("CARGO_PKG_VERSION").to_string();
    let commit = env!("HALFTRACE_COMMIT").to_string();
    for (si, scene_path) in cfg.scenes.iter().enumerate() {
        let scene = crate::scene::load(scene_path)?;
        for w in &scene.warnings {
            bar.suspend(|| eprintln!("warning: {w}"));
        }
        let t_build = std::time::Instant::now();
        let bin = bvh::build_binary(&scene);
        let binary_ms = t_build.elapsed().as_secs_f64() * 1e3;
        let rq_scene = match &rq_pipe {
            Some(_) => Some(gpu::rq::RqScene::build(&g, &scene)?),
            None => None,
        };
        let params = RayParams { width: cfg.width, height: cfg.height, camera: None, seed: cfg.seed, ..Default::default() };
        let f32_ref = Encoded::new(&scene, &bin, Layout::F32, 4)?;
        for kind in &kinds {
            let rays = make_rays(&scene, &bin, kind, &params)?;
            let (ref_hits, _) = f32_ref.trace(&rays);
            let mut encoded: HashMap<(Layout, usize), (Encoded, traversal::GpuBvh, f64)> = HashMap::new();
            let mut images: HashMap<Layout, (Vec<Hit>, Vec<f64>)> = HashMap::new();
            for v in &variants {
                bar.set_message(format!("{} {kind} {}", scene.name, v));
                let key = (v.layout, v.branching);
                if !encoded.contains_key(&key) {
                    let t0 = std::time::Instant::now();
                    let enc = Encoded::new(&scene, &bin, v.layout, v.branching)?;
                    let ms = binary_ms + t0.elapsed().as_secs_f64() * 1e3;
                    let gb = traversal::GpuBvh::upload(&g, &enc).with_context(|| v.to_string())?;
                    encoded.insert(key, (enc, gb, ms));
                }
                let (enc, gb, build_ms) = &encoded[&key];
                let imp = traversal::choose_impl(&g, v, None);
                for stats in [false, true] {
                    if let std::collections::hash_map::Entry::Vacant(e) = kernels.entry((*v, stats)) {
                        e.insert(traversal::pipeline(&g, v, imp, stats, None).with_context(|| v.name(stats))?);
                    }
                }
                let (timed, counting) = (&kernels[&(*v, false)], &kernels[&(*v, true)]);
                let name = timed.name();
                // Correctness before speed.
                let (cpu_hits, cpu_counters) = enc.trace_variant(&rays, v.packet, v.math);
                let out = traversal::run(&g, gb, timed, &rays, cfg.warmup, cfg.repeat).with_context(|| name.clone())?;
                let stats_run = traversal::run(&g, gb, counting, &rays, 0, 1).with_context(|| counting.name())?;
                let counters = stats_run.counters.unwrap();
                let mut status = "ok".to_string();
                if let Some(i) = (0..rays.len()).find(|&i| !out.hits[i].same_bits(&cpu_hits[i])) {
                    status = format!("FAILED: ray {i}: gpu {:?}, cpu reference {:?}", out.hits[i], cpu_hits[i]);
                } else if let Some(i) = (0..rays.len()).find(|&i| counters[i] != cpu_counters[i]) {
                    status = format!("FAILED: ray {i}: gpu counters {:?}, cpu reference {:?}", counters[i], cpu_counters[i]);
                }
                if status != "ok" {
                    bar.suspend(|| eprintln!("error: {} {kind} {name}: {status}", scene.name));
                    failed.push(format!("{} {kind} {name}", scene.name));
                }
                let t = report::Timing::of(&out.times_ms);
                let (mr_med, mr_min, mr_max) = t.mrays(rays.len());
                let m = crate::pipeline::mean_counters(&counters);
                let (mut differ, mut false_miss, mut max_dt) = (0usize, 0usize, 0f64);
                for (h, r) in out.hits.iter().zip(&ref_hits) {
                    if !h.same_bits(r) {
                        differ += 1;
                    }
                    if r.is_hit() && !h.is_hit() {
                        false_miss += 1;
                    }
                    if r.is_hit() && h.is_hit() {
                        max_dt = max_dt.max((h.t as f64 - r.t as f64).abs());
                    }
                }
                let packets_n = rays.len().div_ceil(v.packet).max(1) as f64;
                let node_size = enc.node_bytes() / enc.node_count();
                writer.push(Row {
                    scene: scene.name.clone(),
                    triangles: scene.len(),
                    rays: kind.to_string(),
                    ray_count: rays.len(),
                    layout: v.layout.to_string(),
                    math: v.math.name().into(),
                    branching: v.branching,
                    packet: v.packet,
                    kernel: name.clone(),
                    device: g.info.name.clone(),
                    driver: g.info.driver.clone(),
                    version: version.clone(),
                    commit: commit.clone(),
                    status,
                    mrays_median: mr_med,
                    mrays_min: mr_min,
                    mrays_max: mr_max,
                    ms_median: t.median,
                    ms_min: t.min,
                    ms_max: t.max,
                    timed_dispatches: t.count,
                    nodes_per_ray: m[0],
                    box_tests_per_ray: m[1],
                    tri_tests_per_ray: m[2],
                    reanchors_per_ray: m[3],
                    packet_nodes_per_packet: counters.iter().map(|c| c.packet_nodes as f64).sum::<f64>() / packets_n,
                    simd_utilisation: packet::simd_utilisation(&counters, v.packet),
                    bvh_bytes: enc.node_bytes() as u64,
                    build_ms: *build_ms,
                    bytes_per_node: node_size as u64,
                    triangle_bytes: match enc {
                        Encoded::F32(e) => e.tris.bytes() as u64,
                        Encoded::F16h(e) => e.tris.bytes() as u64,
                    },
                    stack_bytes_per_ray: stack_bytes(v),
                    node_bytes_per_ray: m[0] * node_size as f64,
                    differs_from_f32: differ,
                    false_misses: false_miss,
                    max_abs_dt: max_dt,
                    device_fp16_ratio: dev_bench.fp16_ratio,
                })?;
                if si == 0 && *kind == RayKind::Primary && v.branching == 4 && v.packet == 1 && v.math != Math::Mixed && (v.layout == Layout::F32 || v.math == Math::F16) {
                    images.insert(v.layout, (out.hits.clone(), counters.iter().map(|c| c.nodes as f64).collect()));
                }
                bar.inc(1);
            }
            if with_rq {
                bar.set_message(format!("{} {kind} {}", scene.name, gpu::rq::KERNEL));
                let base = |status: String| Row {
                    scene: scene.name.clone(),
                    triangles: scene.len(),
                    rays: kind.to_string(),
                    ray_count: rays.len(),
                    layout: "rq".into(),
                    math: "n/a".into(),
                    branching: 0,
                    packet: 0,
                    kernel: gpu::rq::KERNEL.into(),
                    device: g.info.name.clone(),
                    driver: g.info.driver.clone(),
                    version: version.clone(),
                    commit: commit.clone(),
                    status,
                    device_fp16_ratio: dev_bench.fp16_ratio,
                    ..Row::default()
                };
                let row = match (&rq_pipe, &rq_scene) {
                    (Some(pipe), Some(rs)) => {
                        let o = gpu::rq::run(&g, rs, pipe, &rays, cfg.warmup, cfg.repeat)?;
                        let t = report::Timing::of(&o.times_ms);
                        let (mrays_median, mrays_min, mrays_max) = t.mrays(rays.len());
                        let a = crate::trace::agreement(&o.hits, &ref_hits);
                        Row {
                            mrays_median,
                            mrays_min,
                            mrays_max,
                            ms_median: t.median,
                            ms_min: t.min,
                            ms_max: t.max,
                            timed_dispatches: t.count,
                            bvh_bytes: rs.bytes,
                            build_ms: rs.build_ms,
                            triangle_bytes: (scene.len() * 36) as u64,
                            differs_from_f32: a.total - a.agree,
                            false_misses: a.false_misses,
                            max_abs_dt: a.max_abs_dt,
                            ..base("ok".into())
                        }
                    }
                    _ => base("skipped: the device has no VK_KHR_ray_query / VK_KHR_acceleration_structure".into()),
                };
                writer.push(row)?;
                bar.inc(1);
            }
            if si == 0 && *kind == RayKind::Primary {
                write_images(out, &scene, &rays, &ref_hits, &images, cfg.width, cfg.height)?;
            }
        }
    }
    bar.finish_and_clear();
    drop(kernels);
    drop(rq_pipe);
    report::render(writer.rows(), out, &[out.to_path_buf()])?;
    Ok(Summary { rows: writer.rows().len(), failed, out: out.into() })
}

fn write_images(out: &Path, scene: &crate::scene::Scene, rays: &[crate::rays::Ray], f32_hits: &[Hit], images: &HashMap<Layout, (Vec<Hit>, Vec<f64>)>, w: u32, h: u32) -> anyhow::Result<()> {
    crate::pipeline::write_image(&out.join("render.png"), scene, rays, f32_hits, w, h)?;
    let max = images.values().flat_map(|(_, n)| n.iter().cloned()).fold(0.0, f64::max);
    for (layout, (_, nodes)) in images {
        report::heat_map(&out.join(format!("heat_{layout}.png")), w, h, nodes, max)?;
    }
    if let Some((hits, _)) = images.get(&Layout::F16h) {
        let mask: Vec<bool> = hits.iter().zip(f32_hits).map(|(a, b)| !a.same_bits(b)).collect();
        report::mask_image(&out.join("diff_f16h_vs_f32.png"), w, h, &mask)?;
    }
    Ok(())
}

/// `reports/<UTC timestamp>` for a default output folder.
pub fn default_out() -> PathBuf {
    let secs = std::time::SystemTime::now().duration_since(std::time::UNIX_EPOCH).map(|d| d.as_secs()).unwrap_or(0) as i64;
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
    PathBuf::from(format!("reports/{y:04}{m:02}{d:02}-{:02}{:02}{:02}", rem / 3600, rem % 3600 / 60, rem % 60))
}
