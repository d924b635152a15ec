//! The `halftrace` command line.

use anyhow::Context;
use clap::{Parser, Subcommand};
use halftrace::bvh::{self, stats::stats};
use halftrace::encode::Layout;
use halftrace::pipeline::{self, Encoded, RayKind, RayParams};
use halftrace::rays::Camera;
use halftrace::variant::{PacketImpl, Variant};
use halftrace::{gpu, npy, scene};
use std::io::Write;
use std::path::PathBuf;
use std::time::Instant;

/// Writes a line to stdout, returning I/O errors (a closed pipe ends the command quietly).
macro_rules! outln {
    ($($t:tt)*) => { writeln!(std::io::stdout(), $($t)*)? };
}

#[derive(Parser)]
#[command(name = "halftrace", version, about = "Half-precision hierarchical BVH traversal harness")]
struct Cli {
    #[command(subcommand)]
    cmd: Cmd,
}

#[derive(Subcommand)]
enum Cmd {
    /// Trace a ray set through one layout and branching factor.
    Trace(TraceArgs),
    /// Print per-B, per-layout BVH statistics.
    BvhStats {
        /// OBJ or .obj.gz scene.
        #[arg(long)]
        scene: PathBuf,
    },
    /// List Vulkan devices and their fp16, 16-bit storage, subgroup and ray-query support.
    Devices {
        /// Also measure raw fp16 vs fp32 throughput of sub, mul, min, max, compare.
        #[arg(long)]
        bench: bool,
        /// Device to benchmark (index or name substring; default: the default device).
        #[arg(long)]
        device: Option<String>,
    },
    /// Sweep scenes × ray kinds × layouts × B × P: validate, time, count, report.
    Sweep(SweepArgs),
    /// Re-render report.md and the plots from one or more sweep folders (merging them).
    Report {
        /// Sweep folders holding results.csv.
        #[arg(required = true)]
        dirs: Vec<PathBuf>,
        /// Where to write the report (default: the first folder).
        #[arg(long)]
        out: Option<PathBuf>,
    },
    /// Compile the default variant matrix and write one SPIR-V file per variant.
    Shaders {
        /// Output folder (e.g. spirv/).
        #[arg(long)]
        emit: PathBuf,
    },
}

#[derive(clap::Args)]
struct SweepArgs {
    /// TOML file with any of the keys of sweep.example.toml; flags override it.
    #[arg(long)]
    config: Option<PathBuf>,
    /// Scene file (repeat for several).
    #[arg(long)]
    scene: Vec<PathBuf>,
    /// Ray kinds, comma-separated (primary, ao, diffuse, grazing, FILE.npy).
    #[arg(long, value_delimiter = ',')]
    rays: Vec<String>,
    /// Layouts, comma-separated.
    #[arg(long, value_delimiter = ',')]
    layouts: Vec<String>,
    /// Branching factors swept at P = 1.
    #[arg(long, value_delimiter = ',')]
    branchings: Vec<usize>,
    /// Packet sizes swept at B = --packet-branching.
    #[arg(long, value_delimiter = ',')]
    packets: Vec<usize>,
    #[arg(long)]
    packet_branching: Option<usize>,
    /// f16h math modes, comma-separated: f16, f32, mixed.
    #[arg(long, value_delimiter = ',')]
    maths: Vec<String>,
    #[arg(long)]
    width: Option<u32>,
    #[arg(long)]
    height: Option<u32>,
    #[arg(long)]
    warmup: Option<usize>,
    #[arg(long)]
    repeat: Option<usize>,
    #[arg(long)]
    seed: Option<u64>,
    #[arg(long)]
    device: Option<String>,
    /// Output folder (default reports/<UTC timestamp>/).
    #[arg(long)]
    out: Option<PathBuf>,
    /// No progress bar.
    #[arg(long)]
    quiet: bool,
    /// Treat a device feature as missing (testing), e.g. rayQuery.
    #[arg(long, hide = true)]
    mask_feature: Vec<String>,
}

#[derive(clap::Args)]
struct TraceArgs {
    /// OBJ or .obj.gz scene.
    #[arg(long)]
    scene: PathBuf,
    /// Node layout: f32, f16h, or rq (the driver's acceleration structure and ray queries).
    #[arg(long, default_value = "f16h")]
    layout: String,
    /// Branching factor: 2, 4, 8 or 16.
    #[arg(long, default_value_t = 4)]
    branching: usize,
    /// Rays per packet: 1, 4, 8, 16, 32 or 64.
    #[arg(long, default_value_t = 1)]
    packet: usize,
    /// f16h arithmetic: f16 (the seed), f32 (fp16 nodes, fp32 tests), mixed.
    #[arg(long, default_value = "f16")]
    math: String,
    /// Packet implementation: subgroup or shared (default: subgroup when P fits the device's
    /// subgroup, else shared memory).
    #[arg(long)]
    packet_impl: Option<String>,
    /// primary, ao, diffuse, grazing, or a FILE.npy (float32, N x 8).
    #[arg(long, default_value = "primary")]
    rays: String,
    #[arg(long, default_value_t = 256)]
    width: u32,
    #[arg(long, default_value_t = 256)]
    height: u32,
    /// eye_x,eye_y,eye_z,target_x,target_y,target_z,fov_degrees (default: frame the scene).
    #[arg(long)]
    camera: Option<String>,
    /// Seed for ao, diffuse and grazing rays.
    #[arg(long, default_value_t = 1)]
    seed: u64,
    /// Write hits (structured t, prim, u, v) to this .npy file.
    #[arg(long)]
    out: Option<PathBuf>,
    /// Write the traced rays to this .npy file.
    #[arg(long)]
    save_rays: Option<PathBuf>,
    /// Write a shaded PNG (primary rays only).
    #[arg(long)]
    image: Option<PathBuf>,
    /// gpu or cpu (default: gpu when a Vulkan device can be opened).
    #[arg(long)]
    backend: Option<String>,
    /// Vulkan device: index or name substring (see `halftrace devices`).
    #[arg(long)]
    device: Option<String>,
    /// Timed dispatches after the warm-up.
    #[arg(long, default_value_t = 10)]
    repeat: usize,
    /// Untimed warm-up dispatches.
    #[arg(long, default_value_t = 2)]
    warmup: usize,
    /// Also run the counting kernel and print work per ray.
    #[arg(long)]
    stats: bool,
    /// Run this SPIR-V module in place of the built-in kernel (same interface).
    #[arg(long)]
    spirv: Option<PathBuf>,
    /// Treat a device feature as missing (testing): shaderFloat16, storageBuffer16BitAccess.
    #[arg(long, hide = true)]
    mask_feature: Vec<String>,
}

fn load_scene(path: &PathBuf) -> anyhow::Result<scene::Scene> {
    let s = scene::load(path)?;
    for w in &s.warnings {
        eprintln!("warning: {w}");
    }
    Ok(s)
}

fn print_timing(times_ms: &[f64], warmup: usize, rays: usize) -> anyhow::Result<()> {
    let t = halftrace::report::Timing::of(times_ms);
    outln!("time over {} dispatches after {warmup} warm-up: median {:.3} ms (min {:.3}, max {:.3}), {:.2} Mrays/s", t.count, t.median, t.min, t.max, t.mrays(rays).0);
    Ok(())
}

/// `trace --layout rq`: the driver's acceleration structure and ray queries.
fn trace_rq(a: &TraceArgs) -> anyhow::Result<()> {
    let kind: RayKind = a.rays.parse()?;
    let camera = a.camera.as_deref().map(Camera::parse).transpose()?;
    anyhow::ensure!(a.backend.as_deref() != Some("cpu"), "--layout rq runs on the GPU only");
    let scene = load_scene(&a.scene)?;
    let bin = bvh::build_binary(&scene);
    let params = RayParams { width: a.width, height: a.height, camera, seed: a.seed, ..Default::default() };
    let rays = pipeline::make_rays(&scene, &bin, &kind, &params)?;
    let opts = gpu::ContextOptions { device: a.device.clone(), mask_features: a.mask_feature.clone(), ..Default::default() };
    let g = gpu::Gpu::new(&opts)?;
    outln!("scene {} ({} triangles), layout rq, rays {kind}: {} rays; device {} ({})", scene.name, scene.len(), rays.len(), g.info.name, g.info.driver);
    let rq = gpu::rq::RqScene::build(&g, &scene)?;
    outln!("acceleration structures: {} bytes (driver size query), built in {:.2} ms", rq.bytes, rq.build_ms);
    let pipe = gpu::rq::pipeline(&g)?;
    let out = gpu::rq::run(&g, &rq, &pipe, &rays, a.warmup, a.repeat.max(1))?;
    let f = Encoded::new(&scene, &bin, Layout::F32, 4)?;
    let (ref_hits, _) = f.trace(&rays);
    let agree = halftrace::trace::agreement(&out.hits, &ref_hits);
    outln!("agreement with the f32 reference: {:.4}% ({} of {} rays: same prim, or t within 1e-5 relative)", 100.0 * agree.rate(), agree.agree, agree.total);
    print_timing(&out.times_ms, a.warmup, rays.len())?;
    if let Some(p) = &a.out {
        npy::write_hits(p, &out.hits)?;
        outln!("hits written to {}", p.display());
    }
    Ok(())
}

fn trace(a: TraceArgs) -> anyhow::Result<()> {
    if a.layout == "rq" {
        return trace_rq(&a);
    }
    let layout: Layout = a.layout.parse()?;
    bvh::check_branching(a.branching).context("--branching")?;
    let kind: RayKind = a.rays.parse()?;
    let camera = a.camera.as_deref().map(Camera::parse).transpose()?;
    let scene = load_scene(&a.scene)?;
    let t0 = Instant::now();
    let bin = bvh::build_binary(&scene);
    let build_ms = t0.elapsed().as_secs_f64() * 1e3;
    let params = RayParams { width: a.width, height: a.height, camera, seed: a.seed, ..Default::default() };
    let rays = pipeline::make_rays(&scene, &bin, &kind, &params)?;
    let enc = Encoded::new(&scene, &bin, layout, a.branching)?;
    anyhow::ensure!(halftrace::variant::PACKETS.contains(&a.packet), "--packet {}: use one of 1, 4, 8, 16, 32, 64", a.packet);
    let math: halftrace::variant::Math = a.math.parse().map_err(anyhow::Error::msg).context("--math")?;
    let variant = Variant::new(layout, a.branching, a.packet).with_math(math);
    let force_impl = match a.packet_impl.as_deref() {
        None => None,
        Some("subgroup") => Some(PacketImpl::Subgroup),
        Some("shared") => Some(PacketImpl::Shared),
        Some(o) => anyhow::bail!("--packet-impl '{o}': use subgroup or shared"),
    }
    .filter(|_| a.packet > 1);
    let backend = match a.backend.as_deref() {
        Some("cpu") => "cpu",
        Some("gpu") => "gpu",
        None if a.spirv.is_some() => "gpu",
        None => {
            if gpu::list_devices().map(|d| !d.is_empty()).unwrap_or(false) {
                "gpu"
            } else {
                "cpu"
            }
        }
        Some(other) => anyhow::bail!("--backend '{other}': use gpu or cpu"),
    };
    outln!("scene {} ({} triangles), variant {variant}, rays {kind}: {} rays", scene.name, scene.len(), rays.len());
    let (hits, counters) = if backend == "cpu" {
        let t1 = Instant::now();
        let (hits, counters) = enc.trace_variant(&rays, a.packet, variant.math);
        let secs = t1.elapsed().as_secs_f64();
        outln!("backend cpu (reference): {:.1} ms, {:.2} Mrays/s; BVH build {:.1} ms", secs * 1e3, rays.len() as f64 / secs / 1e6, build_ms);
        (hits, Some(counters))
    } else {
        let opts = gpu::ContextOptions { device: a.device.clone(), mask_features: a.mask_feature.clone(), ..Default::default() };
        let g = gpu::Gpu::new(&opts)?;
        outln!("device {} ({}), driver {}", g.info.name, g.info.kind, g.info.driver);
        let imp = gpu::traversal::choose_impl(&g, &variant, force_impl);
        let wg = variant.workgroup(imp);
        let custom = a.spirv.as_deref().map(|p| gpu::shader::load_checked(p, wg)).transpose()?;
        let bvh_gpu = gpu::traversal::GpuBvh::upload(&g, &enc).with_context(|| variant.to_string())?;
        let kernel = gpu::traversal::pipeline(&g, &variant, imp, false, custom.as_deref()).with_context(|| variant.to_string())?;
        let kname = kernel.name();
        let out = gpu::traversal::run(&g, &bvh_gpu, &kernel, &rays, a.warmup, a.repeat.max(1)).with_context(|| kname.clone())?;
        // Correctness before speed: the CPU reference of the same layout and packet size.
        let (ref_hits, ref_counters) = enc.trace_variant(&rays, a.packet, variant.math);
        let bad: Vec<usize> = (0..rays.len()).filter(|&i| !out.hits[i].same_bits(&ref_hits[i])).collect();
        if let Some(&i) = bad.first() {
            anyhow::bail!("{kname}{}: {} of {} rays differ from the CPU reference; first: ray {i} {:?}: gpu {:?}, cpu {:?}",
                if a.spirv.is_some() { " (custom SPIR-V)" } else { "" }, bad.len(), rays.len(), rays[i], out.hits[i], ref_hits[i]);
        }
        outln!("kernel {kname}: validated against the CPU reference ({} rays identical)", rays.len());
        print_timing(&out.times_ms, a.warmup, rays.len())?;
        let counters = if a.stats {
            let sk = gpu::traversal::pipeline(&g, &variant, imp, true, None)?;
            let so = gpu::traversal::run(&g, &bvh_gpu, &sk, &rays, 0, 1)?;
            let c = so.counters.unwrap();
            if let Some(i) = (0..rays.len()).find(|&i| c[i] != ref_counters[i]) {
                anyhow::bail!("{}: ray {i}: GPU counters {:?} differ from the CPU reference {:?}", sk.name(), c[i], ref_counters[i]);
            }
            Some(c)
        } else {
            None
        };
        (out.hits, counters)
    };
    let nhit = hits.iter().filter(|h| h.is_hit()).count();
    outln!("{nhit} hits");
    if let Some(c) = counters.filter(|_| a.stats || backend == "cpu") {
        let m = pipeline::mean_counters(&c);
        outln!("per ray: {:.2} nodes, {:.2} box tests, {:.2} triangle tests, {:.3} re-anchors", m[0], m[1], m[2], m[3]);
        let packets = rays.len().div_ceil(a.packet).max(1);
        let pn: u64 = c.iter().map(|x| x.packet_nodes as u64).sum();
        outln!(
            "per packet of {}: {:.2} nodes visited; SIMD utilisation {:.1}% (active rays per visited node)",
            a.packet,
            pn as f64 / packets as f64,
            100.0 * halftrace::trace::packet::simd_utilisation(&c, a.packet)
        );
    }
    if let Some(p) = &a.out {
        npy::write_hits(p, &hits)?;
        outln!("hits written to {}", p.display());
    }
    if let Some(p) = &a.save_rays {
        npy::write_rays(p, &rays)?;
        outln!("rays written to {}", p.display());
    }
    if let Some(p) = &a.image {
        anyhow::ensure!(kind == RayKind::Primary, "--image needs --rays primary");
        pipeline::write_image(p, &scene, &rays, &hits, a.width, a.height)?;
        outln!("image written to {}", p.display());
    }
    Ok(())
}

fn bvh_stats(path: &PathBuf) -> anyhow::Result<()> {
    let scene = load_scene(path)?;
    let t0 = Instant::now();
    let bin = bvh::build_binary(&scene);
    let ms = t0.elapsed().as_secs_f64() * 1e3;
    outln!("scene {} ({} triangles, {} degenerate); binary SAH build {:.1} ms ({:.2} Mtris/s)", scene.name, scene.len(), scene.degenerate, ms, scene.len() as f64 / ms / 1e3);
    outln!("{:>3} {:>6} {:>9} {:>9} {:>12} {:>10} {:>6} {:>9} {:>6}", "B", "layout", "nodes", "leaves", "node bytes", "bytes/node", "depth", "SAH cost", "fill");
    for b in bvh::BRANCHINGS {
        let w = bvh::collapse(&bin, b);
        let st = stats(&w);
        for layout in Layout::ALL {
            let enc = Encoded::new(&scene, &bin, layout, b)?;
            outln!(
                "{:>3} {:>6} {:>9} {:>9} {:>12} {:>10} {:>6} {:>9.2} {:>6.2}",
                b, layout.name(), st.inner_nodes, st.leaves, enc.node_bytes(), enc.node_bytes() / enc.node_count(), st.depth, st.sah_cost, st.fill
            );
        }
    }
    let tb = halftrace::encode::TriBuffer::new(&scene, &bvh::collapse(&bin, 2));
    outln!("triangles (shared by all layouts): {} bytes", tb.bytes());
    Ok(())
}

fn devices(bench: bool, device: Option<String>) -> anyhow::Result<()> {
    let list = gpu::list_devices()?;
    if list.is_empty() {
        outln!("no Vulkan devices");
    }
    for d in &list {
        outln!(
            "{}: {} ({}), Vulkan {}, driver {}\n   shaderFloat16 {}, storageBuffer16BitAccess {}, shaderFloat64 {}, subgroup size {}, ray query {}, max storage buffer {} MiB",
            d.index, d.name, d.kind, d.api_version, d.driver, d.shader_float16, d.storage_16bit, d.shader_float64, d.subgroup_size, d.ray_query, d.max_storage_buffer >> 20
        );
    }
    if bench {
        let g = gpu::Gpu::new(&gpu::ContextOptions { device, ..Default::default() })?;
        let b = gpu::bench::run(&g, 65536, 512, 5)?;
        outln!("\nraw arithmetic on {} ({}): G operations/s, median of 5", b.device, b.driver);
        outln!("{:<9} {:>10} {:>10} {:>12}", "op", "fp16", "fp32", "fp16:fp32");
        for o in &b.ops {
            outln!("{:<9} {:>10.2} {:>10.2} {:>12.3}", o.op, o.fp16_gops, o.fp32_gops, o.ratio);
        }
        outln!("fp16:fp32 ratio (geometric mean): {:.3}", b.fp16_ratio);
    }
    Ok(())
}

fn sweep(a: SweepArgs) -> anyhow::Result<()> {
    use halftrace::sweep::{self, Config};
    let mut c = match &a.config {
        Some(p) => Config::load(p)?,
        None => Config::default(),
    };
    if !a.scene.is_empty() {
        c.scenes = a.scene.clone();
    }
    if !a.rays.is_empty() {
        c.rays = a.rays.clone();
    }
    if !a.layouts.is_empty() {
        c.layouts = a.layouts.clone();
    }
    if !a.branchings.is_empty() {
        c.branchings = a.branchings.clone();
    }
    if !a.packets.is_empty() {
        c.packets = a.packets.clone();
    }
    if !a.maths.is_empty() {
        c.maths = a.maths.clone();
    }
    c.packet_branching = a.packet_branching.unwrap_or(c.packet_branching);
    c.width = a.width.unwrap_or(c.width);
    c.height = a.height.unwrap_or(c.height);
    c.warmup = a.warmup.unwrap_or(c.warmup);
    c.repeat = a.repeat.unwrap_or(c.repeat);
    c.seed = a.seed.unwrap_or(c.seed);
    if let Some(d) = &a.device {
        c.device = d.clone();
    }
    c.check()?;
    let out = a.out.clone().unwrap_or_else(sweep::default_out);
    let t0 = Instant::now();
    let s = sweep::run(&c, &out, a.quiet, &a.mask_feature)?;
    outln!("{} variants in {:.0} s; report: {}", s.rows, t0.elapsed().as_secs_f64(), s.out.join("report.md").display());
    if !s.failed.is_empty() {
        anyhow::bail!("{} variant(s) failed validation: {}", s.failed.len(), s.failed.join(", "));
    }
    Ok(())
}

fn report(dirs: &[PathBuf], out: Option<&PathBuf>) -> anyhow::Result<()> {
    let mut rows = Vec::new();
    for d in dirs {
        rows.extend(halftrace::report::read_rows(d)?);
    }
    let out = out.cloned().unwrap_or_else(|| dirs[0].clone());
    halftrace::report::render(&rows, &out, dirs)?;
    outln!("{} rows from {} folder(s); report: {}", rows.len(), dirs.len(), out.join("report.md").display());
    Ok(())
}

fn shaders(dir: &PathBuf) -> anyhow::Result<()> {
    std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
    for (v, imp) in halftrace::variant::spirv_matrix() {
        for stats in [false, true] {
            let code = gpu::shader::compile(&v, imp, stats, true)?;
            let p = dir.join(format!("{}.spv", v.kernel_name(imp, stats)));
            std::fs::write(&p, bytemuck::cast_slice(&code)).with_context(|| format!("writing {}", p.display()))?;
            outln!("{}", p.display());
        }
    }
    Ok(())
}

fn main() {
    let cli = Cli::parse();
    let r = match cli.cmd {
        Cmd::Trace(a) => trace(a),
        Cmd::BvhStats { scene } => bvh_stats(&scene),
        Cmd::Devices { bench, device } => devices(bench, device),
        Cmd::Shaders { emit } => shaders(&emit),
        Cmd::Sweep(a) => sweep(a),
        Cmd::Report { dirs, out } => report(&dirs, out.as_ref()),
    };
    if let Err(e) = r {
        eprintln!("error: {e:#}");
        std::process::exit(1);
    }
}
