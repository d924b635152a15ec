//! `halftrace trace`: one ray set through one layout, B and P (or a baseline), through the
//! runner: validated against the CPU reference, timed, and written out on request.

use super::outln;
use super::LayoutArg;
use crate::base::Status;
use crate::base::{agreement, mean_counters, simd_utilisation, Counters, Hit};
use crate::baseline::BaselineId;
use crate::gpu::{self, Gpu};
use crate::layout::LayoutId;
use crate::precision::{FcChoice, FloatControls};
use crate::rays::{RayKind, RayParams};
use crate::runner::measure::compare;
use crate::runner::{Measurement, Options, Plan, RaySetId, RaySpec, Runner, Target, Timing};
use crate::variant::{Buffers, KernelSpec, Source, Variant};
use anyhow::Context;
use std::path::{Path, PathBuf};
use std::time::Instant;

/// Where `trace` runs.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum Backend {
    /// The Vulkan device's kernels, checked against the CPU reference.
    Gpu,
    /// The CPU reference alone.
    Cpu,
}

#[derive(clap::Args, Clone, Debug, PartialEq)]
pub struct TraceArgs {
    /// Scene: OBJ, glTF (.gltf, .glb) or PLY, each optionally gzip-compressed (.gz).
    #[arg(long)]
    pub scene: PathBuf,
    /// Layout (f32, f16h, …) or baseline (rq: the driver's acceleration structure and ray
    /// queries; rt: the same structure and a ray-tracing pipeline; embree); `halftrace devices`
    /// lists them.
    #[arg(long, default_value = "f16h")]
    pub layout: LayoutArg,
    /// Branching factor: 2, 4, 8 or 16.
    #[arg(long, default_value_t = 4)]
    pub branching: usize,
    /// Rays per packet: 1, 4, 8, 16, 32 or 64.
    #[arg(long, default_value_t = 1)]
    pub packet: usize,
    /// Box-test arithmetic, for layouts with several modes (f16h: f16 = the poster's, f32 =
    /// fp16 nodes with fp32 tests, mixed); default: the layout's first mode.
    #[arg(long)]
    pub math: Option<crate::precision::Math>,
    /// Packet implementation (default: subgroup when P fits the device's subgroup, else hybrid
    /// where the device has subgroup arithmetic, else shared memory).
    #[arg(long)]
    pub packet_impl: Option<crate::variant::PacketImpl>,
    /// primary, ao, diffuse, grazing, or a FILE.npy (float32, N x 8).
    #[arg(long, default_value = "primary")]
    pub rays: crate::rays::RayKind,
    #[arg(long, default_value_t = 256)]
    pub width: u32,
    #[arg(long, default_value_t = 256)]
    pub height: u32,
    /// eye_x,eye_y,eye_z,target_x,target_y,target_z,fov_degrees (default: frame the scene).
    #[arg(long, value_parser = |s: &str| crate::rays::Camera::parse(s).map_err(|e| e.to_string()))]
    pub camera: Option<crate::rays::Camera>,
    /// Seed for ao, diffuse and grazing rays.
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Write hits (structured t, prim, u, v) to this .npy file.
    #[arg(long)]
    pub out: Option<PathBuf>,
    /// Write the traced rays to this .npy file.
    #[arg(long)]
    pub save_rays: Option<PathBuf>,
    /// Write a shaded PNG (primary rays only).
    #[arg(long)]
    pub image: Option<PathBuf>,
    /// Default: gpu when a Vulkan device can be opened.
    #[arg(long)]
    pub backend: Option<Backend>,
    /// Vulkan device: index or name substring (see `halftrace devices`).
    #[arg(long)]
    pub device: Option<String>,
    /// Timed dispatches after the warm-up.
    #[arg(long, default_value_t = 10)]
    pub repeat: usize,
    /// Untimed warm-up dispatches.
    #[arg(long, default_value_t = 2)]
    pub warmup: usize,
    /// Also run the counting kernel and print work per ray.
    #[arg(long)]
    pub stats: bool,
    /// Run this kernel in place of the built-in one of the variant: a GLSL compute file
    /// (compiled with the built-in kernel's defines and includes) or a SPIR-V module (.spv),
    /// checked against the variant's interface, then validated and timed like the built-in.
    #[arg(long, alias = "spirv")]
    pub kernel: Option<PathBuf>,
    /// Float-control execution modes of the kernel: on (round-to-nearest-even, inf/NaN
    /// preserved), off (a build whose hits stay exact without them), auto (on where the
    /// device has them, else off where the layout has such a build).
    #[arg(long, default_value = "auto")]
    pub float_controls: crate::precision::FcChoice,
    /// Treat a device feature as missing (testing the fallbacks), e.g. shaderFloat16,
    /// storageBuffer16BitAccess, floatControls, subgroupSizeControl, rayQuery.
    #[arg(long, hide = true)]
    pub mask_feature: Vec<String>,
    /// How long a dispatch may run before its kernel is declared hung: seconds or e.g. 90s,
    /// 10m (default 600 s; at most a week).
    #[arg(long, value_parser = |s: &str| crate::units::parse_duration("--kernel-timeout", s))]
    pub kernel_timeout: Option<f64>,
}

pub fn trace(a: &TraceArgs) -> anyhow::Result<()> {
    anyhow::ensure!(a.repeat >= 1, "--repeat {}: at least one timed dispatch is needed", a.repeat);
    check_outputs(a)?;
    let layout = match a.layout {
        LayoutArg::Baseline(b) => return trace_baseline(a, b),
        LayoutArg::Layout(l) => l,
    };
    let mut variant = Variant::checked(layout, a.branching, a.packet, a.math)
        .map_err(|e| anyhow::anyhow!("--{} {e}", e.parameter()))?;
    if a.float_controls == FcChoice::Off {
        variant = variant.with_fc(FloatControls::Off);
    }
    let backend = match a.backend {
        Some(b) => b,
        None if a.kernel.is_some() => Backend::Gpu,
        // Without a device, the CPU reference — said on stderr, with the loader's reason; an
        // explicit --backend gpu fails instead.
        None => match gpu::list_devices() {
            Ok(d) if !d.is_empty() => Backend::Gpu,
            r => {
                let why = r.err().map(|e| format!(" ({e})")).unwrap_or_else(|| " found".into());
                eprintln!("warning: no Vulkan device{why}; tracing with the CPU reference (--backend cpu)");
                Backend::Cpu
            }
        },
    };
    let g = match backend {
        Backend::Gpu => Some(open(a)?),
        Backend::Cpu => None,
    };
    let mut runner = Runner::new(g.as_ref(), &[], Options { frugal: true, ..Default::default() })?;
    let (set, build_ms) = inputs(&mut runner, a)?;
    let (name, tris) = runner.current_scene().map(|s| (s.name.clone(), s.len())).expect("loaded");
    let n = runner.rays(set).rays.len();
    outln!("scene {name} ({tris} triangles), variant {variant}, rays {}: {n} rays", a.rays);
    let (hits, counters) = match &g {
        None => {
            // Encoded first, so that the time is the traversal's alone.
            runner.encode(layout, a.branching)?;
            let t = Instant::now();
            let (hits, counters) = runner.reference(&variant, set)?;
            let secs = t.elapsed().as_secs_f64();
            let rate = n as f64 / secs / 1e6;
            outln!("backend cpu (reference): {:.1} ms, {rate:.2} Mrays/s; BVH build {build_ms:.1} ms", secs * 1e3);
            // The device path's first check: a conservative layout returns the f32 hits.
            if layout != LayoutId::f32() {
                let rays = runner.rays(set).rays.clone();
                let f32_hits = runner.f32_hits(set)?;
                let label = format!("{variant} (CPU reference)");
                let vs = agreement(&hits, f32_hits);
                if layout.info().conservative {
                    compare(&label, "hits", "the f32 reference", &rays, &hits, f32_hits, 0, Hit::same_bits)
                        .map_err(|e| anyhow::anyhow!("{e} (a conservative layout must return the f32 hits)"))?;
                    outln!("against f32: all {n} rays identical");
                } else {
                    outln!("against f32: {} rays differ, {} false misses", vs.differs(), vs.false_misses);
                }
            }
            (hits, Some(counters))
        }
        Some(g) => {
            let m = trace_gpu(&mut runner, a, variant, set, g)?;
            (m.hits, m.counters)
        }
    };
    outln!("{} hits", hits.iter().filter(|h| h.is_hit()).count());
    if let Some(b) = crate::progress::peak_rss_bytes() {
        outln!("peak memory {} MB ({:.0} bytes per triangle)", b >> 20, b as f64 / tris as f64);
    }
    if let Some(c) = counters.filter(|_| a.stats || backend == Backend::Cpu) {
        print_counters(&c, n, a.packet)?;
    }
    write_outputs(a, &runner, set, &hits)
}

/// Loads the scene into the runner and makes the ray set; returns it and the binary build
/// time (ms).
fn inputs(runner: &mut Runner, a: &TraceArgs) -> anyhow::Result<(RaySetId, f64)> {
    let (scene, build_ms) = runner.scene(&a.scene)?;
    for w in &scene.warnings {
        eprintln!("warning: {w}");
    }
    let params = RayParams { width: a.width, height: a.height, camera: a.camera, seed: a.seed, ..Default::default() };
    let set = runner.ray_set(&RaySpec { kind: a.rays.clone(), params })?;
    Ok((set, build_ms))
}

fn open(a: &TraceArgs) -> anyhow::Result<Gpu> {
    let opts = gpu::ContextOptions {
        device: a.device.clone(),
        mask_features: a.mask_feature.clone(),
        kernel_timeout_s: a.kernel_timeout,
        ..Default::default()
    };
    Ok(Gpu::new(&opts)?)
}

/// The variant's kernel (or the user's in its place) on the device, validated, then timed.
fn trace_gpu(
    runner: &mut Runner,
    a: &TraceArgs,
    variant: Variant,
    set: RaySetId,
    g: &Gpu,
) -> anyhow::Result<Measurement> {
    let n = runner.rays(set).rays.len();
    outln!("device {} ({}), driver {}", g.info.name, g.info.kind, g.info.driver);
    let source = a.kernel.as_deref().map(Source::user).unwrap_or(Source::Builtin);
    let k = KernelSpec { variant, fc: a.float_controls, imp: a.packet_impl, source: source.clone() };
    let d = runner.decide(&k).expect("a device is open").map_err(anyhow::Error::msg)?;
    let (name, fc) = (d.id.name(), d.id.variant.fc.name());
    match &a.kernel {
        Some(f) => outln!("kernel {} (the user's, in place of {name}; float controls {fc})", f.display()),
        None => outln!("kernel {name} (float controls {fc})"),
    }
    let plan = Plan { warmup: a.warmup, repeat: a.repeat, count: a.stats };
    let o = runner.measure(&Target::Kernel(k), set, plan)?;
    if o.facts.buffers == Buffers::Addressed {
        outln!(
            "scene buffers read by address: {} bytes of nodes and triangles, a buffer larger than one storage \
             binding may span on this device (maxStorageBufferRange {} bytes)",
            o.facts.upload_bytes,
            g.info.max_storage_buffer
        );
    }
    match &o.status {
        Status::Ok => {}
        Status::Failed(f) | Status::Skipped(f) => anyhow::bail!("{f}"),
    }
    let id = o.kernel.expect("a kernel ran");
    let label = match &a.kernel {
        Some(f) => format!("{id} (user kernel {})", f.display()),
        None => id.to_string(),
    };
    outln!("kernel {label}: validated against the CPU reference ({n} rays identical)");
    if a.stats && o.m.counters.is_none() {
        let f = a.kernel.as_deref().map(Path::display).map(|d| d.to_string()).unwrap_or_default();
        outln!("--stats: {f} writes no counters; work counters not measured");
    }
    if variant.layout != LayoutId::f32() {
        outln!("against f32: {} rays differ, {} false misses", o.m.vs_f32.differs(), o.m.vs_f32.false_misses);
    }
    outln!("flagged: {} rays fp32 could not decide, re-traced exactly on the host", o.m.flagged);
    print_timing(o.m.timing.as_ref().expect("validated and timed"), a.warmup, n)?;
    Ok(o.m)
}

/// `trace --layout <baseline>`: someone else's traversal of the same triangles (rq, rt: the
/// driver's acceleration structure and ray queries or a ray-tracing pipeline), checked against
/// the f32 reference.
fn trace_baseline(a: &TraceArgs, b: BaselineId) -> anyhow::Result<()> {
    anyhow::ensure!(a.backend != Some(Backend::Cpu), "--layout {b} runs on the GPU only");
    // A baseline has no B, P, math, float controls, counters or kernel of ours: say so rather
    // than ignore the flag.
    let na = |flag: &str| {
        anyhow::anyhow!(
            "{flag} does not apply to --layout {b} (a baseline: the driver's traversal has no B, P, math mode, float \
             controls, work counters or user kernel)"
        )
    };
    if a.branching != 4 {
        crate::bvh::check_branching(a.branching).context("--branching")?;
        return Err(na("--branching"));
    }
    let given = [
        ("--packet", a.packet != 1),
        ("--math", a.math.is_some()),
        ("--packet-impl", a.packet_impl.is_some()),
        ("--stats", a.stats),
        ("--kernel", a.kernel.is_some()),
        ("--float-controls", a.float_controls != FcChoice::Auto),
    ];
    if let Some((flag, _)) = given.iter().find(|(_, g)| *g) {
        return Err(na(flag));
    }
    let g = open(a)?;
    let mut runner = Runner::new(Some(&g), &[b], Options { frugal: true, ..Default::default() })?;
    let (set, _) = inputs(&mut runner, a)?;
    let (name, tris) = runner.current_scene().map(|s| (s.name.clone(), s.len())).expect("loaded");
    let n = runner.rays(set).rays.len();
    outln!(
        "scene {name} ({tris} triangles), layout {b}, rays {}: {n} rays; device {} ({})",
        a.rays,
        g.info.name,
        g.info.driver
    );
    let o = runner.measure(&Target::Baseline(b), set, Plan { warmup: a.warmup, repeat: a.repeat, count: false })?;
    if let Status::Skipped(why) | Status::Failed(why) = &o.status {
        anyhow::bail!("--layout {b}: {why}");
    }
    outln!("acceleration structures: {} bytes, built in {:.2} ms", o.facts.bvh_bytes, o.facts.build_ms);
    let agree = o.m.vs_f32;
    outln!(
        "agreement with the f32 reference: {:.4}% ({} of {} rays: same prim, or t within 1e-5 relative)",
        100.0 * agree.rate(),
        agree.agree,
        agree.total
    );
    print_timing(o.m.timing.as_ref().expect("baselines are always timed"), a.warmup, n)?;
    write_outputs(a, &runner, set, &o.m.hits)
}

fn print_timing(t: &Timing, warmup: usize, rays: usize) -> anyhow::Result<()> {
    outln!(
        "time over {} dispatches after {warmup} warm-up: median {:.3} ms (min {:.3}, max {:.3}), {:.2} Mrays/s",
        t.count,
        t.median,
        t.min,
        t.max,
        t.mrays(rays).0
    );
    Ok(())
}

fn print_counters(c: &[Counters], rays: usize, packet: usize) -> anyhow::Result<()> {
    let m = mean_counters(c);
    outln!("per ray: {:.2} nodes, {:.2} box tests, {:.2} triangle tests, {:.3} re-anchors", m[0], m[1], m[2], m[3]);
    let packets = rays.div_ceil(packet).max(1);
    let pn: u64 = c.iter().map(|x| x.packet_nodes as u64).sum();
    outln!(
        "per packet of {packet}: {:.2} nodes visited; SIMD utilisation {:.1}% (active rays per visited node)",
        pn as f64 / packets as f64,
        100.0 * simd_utilisation(c, packet)
    );
    Ok(())
}

/// `--out`, `--save-rays` and `--image`, each written atomically.
fn write_outputs(a: &TraceArgs, runner: &Runner, set: RaySetId, hits: &[Hit]) -> anyhow::Result<()> {
    let rays = &runner.rays(set).rays;
    if let Some(p) = &a.out {
        crate::npy::write_hits(p, hits)?;
        outln!("hits written to {}", p.display());
    }
    if let Some(p) = &a.save_rays {
        crate::npy::write_rays(p, rays)?;
        outln!("rays written to {}", p.display());
    }
    if let Some(p) = &a.image {
        anyhow::ensure!(a.rays == RayKind::Primary, "--image needs --rays primary");
        let scene = runner.current_scene().expect("loaded");
        crate::images::render(p, scene, rays, hits, a.width, a.height)?;
        outln!("image written to {}", p.display());
    }
    Ok(())
}

/// Checks the output files before anything is traced: each is distinct from every input and
/// from each other (an input is never overwritten), and `--image` is a PNG of primary rays.
fn check_outputs(a: &TraceArgs) -> anyhow::Result<()> {
    let same = |x: &Path, y: &Path| {
        let c = |p: &Path| {
            let parent = p.parent().filter(|q| !q.as_os_str().is_empty()).unwrap_or(Path::new("."));
            parent.canonicalize().ok().map(|d| d.join(p.file_name().unwrap_or_default()))
        };
        x == y || (c(x).is_some() && c(x) == c(y))
    };
    let mut inputs: Vec<(&str, PathBuf)> = vec![("--scene", a.scene.clone())];
    if let RayKind::File(p) = &a.rays {
        inputs.push(("--rays", p.clone()));
    }
    if let Some(k) = &a.kernel {
        inputs.push(("--kernel", k.clone()));
    }
    let outputs: Vec<(&str, &PathBuf)> =
        [("--out", a.out.as_ref()), ("--save-rays", a.save_rays.as_ref()), ("--image", a.image.as_ref())]
            .into_iter()
            .filter_map(|(n, p)| Some((n, p?)))
            .collect();
    for (i, (n, p)) in outputs.iter().enumerate() {
        for (m, q) in &inputs {
            anyhow::ensure!(!same(p, q), "{n} {} is also the {m} input: an input is never overwritten", p.display());
        }
        for (m, q) in &outputs[..i] {
            anyhow::ensure!(!same(p, q), "{n} and {m} are the same file ({})", p.display());
        }
        crate::fsx::check_output(n, p)?;
    }
    if let Some(p) = &a.image {
        let png = p.extension().is_some_and(|e| e.eq_ignore_ascii_case("png"));
        anyhow::ensure!(png, "--image {}: name a .png file (the image is written as PNG)", p.display());
        anyhow::ensure!(a.rays == RayKind::Primary, "--image needs --rays primary (got --rays {})", a.rays);
    }
    Ok(())
}
