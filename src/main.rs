//! The `halftrace` command line.

use anyhow::Context;
use clap::{Parser, Subcommand};
use halftrace::bvh::{self, stats::stats};
use halftrace::gpu::kernel::{self, GpuBvh, Kernel, Source};
use halftrace::layout::{Encoded, LayoutId, Math};
use halftrace::measure::{self, BaselineTarget, KernelTarget, Plan, Reference};
use halftrace::rays::{make_rays, Camera, RayKind, RayParams};
use halftrace::variant::{Buffers, FcChoice, FloatControls, PacketImpl, Variant};
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
    /// Write a glTF binary (.glb) that instances a scene N times (rotated, scaled, on a grid):
    /// big test scenes without shipping them.
    Instance {
        /// Scene to instance (OBJ, glTF or PLY).
        #[arg(long)]
        scene: PathBuf,
        /// Number of instances.
        #[arg(long)]
        count: usize,
        /// Seed of the rotations and scales.
        #[arg(long, default_value_t = 1)]
        seed: u64,
        /// The .glb file to write (an existing file is refused).
        #[arg(long)]
        out: PathBuf,
    },
    /// Print per-B, per-layout BVH statistics.
    BvhStats {
        /// Scene: OBJ, glTF (.gltf, .glb) or PLY, each optionally gzip-compressed (.gz).
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
        /// Show what would run with these features treated as missing (testing).
        #[arg(long, hide = true)]
        mask_feature: Vec<String>,
    },
    /// Sweep scenes × ray kinds × layouts × B × P: validate, time, count, report.
    Sweep(SweepArgs),
    /// The speed ratios a kernel change is judged by (f16h ÷ f32, best reduced layout ÷ f32,
    /// best ÷ embree, packets ÷ P = 1, f32 ÷ rq), validated, then timed in interleaved rounds:
    /// medians with min/max.
    Bench(BenchArgs),
    /// Re-render report.md and the plots from one or more sweep folders (merging them).
    Report {
        /// Sweep folders holding results.csv.
        #[arg(required = true)]
        dirs: Vec<PathBuf>,
        /// Where to write the report (default: the first folder); a folder that is not one of
        /// the inputs also gets the merged results.csv and results.json.
        #[arg(long)]
        out: Option<PathBuf>,
    },
    /// Check every variant on a device against the CPU references (what to run first on a new
    /// GPU): writes conformance.md and conformance.csv, exits non-zero on any failure.
    Conformance(ConformanceArgs),
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
    /// Layouts that get the B and P series, comma-separated (default f32,f16h; "all" for
    /// every layout in --layouts); the others run at --scheme-branchings only.
    #[arg(long, value_delimiter = ',')]
    series: Vec<String>,
    /// Branching factors swept at P = 1 (series layouts).
    #[arg(long, value_delimiter = ',')]
    branchings: Vec<usize>,
    /// Branching factors at which every layout runs with P = 1 (default 4,8).
    #[arg(long, value_delimiter = ',')]
    scheme_branchings: Vec<usize>,
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
    /// Output folder (default reports/<UTC timestamp>/). A folder that already holds files is
    /// refused unless --resume or --force.
    #[arg(long)]
    out: Option<PathBuf>,
    /// Run share K of N of the job list (1 <= K <= N; deterministic, balanced by expected
    /// cost) into --out/shard-K-of-N; merge the shards with `halftrace report`. Inside a Slurm
    /// job array it defaults to the array task (SLURM_ARRAY_TASK_ID, SLURM_ARRAY_TASK_COUNT).
    #[arg(long)]
    shard: Option<String>,
    /// Continue the sweep in --out: keep its rows, run only the jobs they do not record.
    #[arg(long)]
    resume: bool,
    /// Replace the sweep's files in --out (other files there are left alone).
    #[arg(long)]
    force: bool,
    /// No progress bar.
    #[arg(long)]
    quiet: bool,
    /// Float-control modes of the kernels: auto, on or off (see `trace --help`).
    #[arg(long)]
    float_controls: Option<String>,
    /// Treat a device feature as missing (testing), e.g. rayQuery.
    #[arg(long, hide = true)]
    mask_feature: Vec<String>,
    /// Seconds a dispatch may run before its kernel is declared hung (default 600).
    #[arg(long)]
    kernel_timeout: Option<f64>,
}

#[derive(clap::Args)]
struct ConformanceArgs {
    /// A covering subset (each layout, B, P, math, float-control mode and packet
    /// implementation at least once) instead of the full cross product.
    #[arg(long)]
    quick: bool,
    /// Scene file (repeat for several; default: the bundled scene).
    #[arg(long)]
    scene: Vec<PathBuf>,
    /// Also every .obj / .obj.gz scene in this folder.
    #[arg(long)]
    scenes_dir: Option<PathBuf>,
    /// Vulkan device: index or name substring (see `halftrace devices`).
    #[arg(long)]
    device: Option<String>,
    /// Output folder for conformance.md and conformance.csv (default
    /// reports/conformance-<UTC timestamp>/).
    #[arg(long)]
    out: Option<PathBuf>,
    /// Run under the Khronos validation layer; any message fails the run.
    #[arg(long)]
    validation: bool,
    /// Treat a device feature as missing (testing the fallbacks).
    #[arg(long, hide = true)]
    mask_feature: Vec<String>,
}

#[derive(clap::Args)]
struct BenchArgs {
    /// Scenes (OBJ, glTF or PLY); repeat the flag. Default: the bundled teapot, and the shared
    /// sponza_dabrovic (a large interior) and igea (a 270k-triangle scan) when
    /// `../shared/scenes` has them.
    #[arg(long)]
    scene: Vec<PathBuf>,
    /// Ray kinds, comma-separated: primary, ao, diffuse, grazing.
    #[arg(long, default_value = "primary,ao,diffuse", value_delimiter = ',')]
    rays: Vec<String>,
    /// Reduced-precision layouts to time beside f32, comma-separated (default: every
    /// conservative one) — for a quicker check of one layout's change.
    #[arg(long, value_delimiter = ',')]
    layouts: Vec<String>,
    #[arg(long, default_value_t = 256)]
    width: u32,
    #[arg(long, default_value_t = 256)]
    height: u32,
    /// Interleaved rounds (every target once per round).
    #[arg(long, default_value_t = 5)]
    rounds: usize,
    /// Timed dispatches per target and round (after one warm-up).
    #[arg(long, default_value_t = 5)]
    repeat: usize,
    /// Vulkan device (index or name substring).
    #[arg(long)]
    device: Option<String>,
    /// Enable the Khronos validation layer.
    #[arg(long)]
    validation: bool,
    /// Also write the report (Markdown) to this file.
    #[arg(long)]
    out: Option<PathBuf>,
}

#[derive(clap::Args)]
struct TraceArgs {
    /// Scene: OBJ, glTF (.gltf, .glb) or PLY, each optionally gzip-compressed (.gz).
    #[arg(long)]
    scene: PathBuf,
    /// Layout (f32, f16h) or baseline (rq: the driver's acceleration structure and ray
    /// queries); `halftrace devices` lists them.
    #[arg(long, default_value = "f16h")]
    layout: String,
    /// Branching factor: 2, 4, 8 or 16.
    #[arg(long, default_value_t = 4)]
    branching: usize,
    /// Rays per packet: 1, 4, 8, 16, 32 or 64.
    #[arg(long, default_value_t = 1)]
    packet: usize,
    /// Box-test arithmetic, for layouts with several modes (f16h: f16 = the seed, f32 = fp16
    /// nodes with fp32 tests, mixed); default: the layout's first mode.
    #[arg(long)]
    math: Option<String>,
    /// Packet implementation: subgroup, hybrid or shared (default: subgroup when P fits the
    /// device's subgroup, else hybrid where the device has subgroup arithmetic, else shared
    /// memory).
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
    /// Run this kernel in place of the built-in one of the variant: a GLSL compute file
    /// (compiled with the built-in kernel's defines and includes) or a SPIR-V module (.spv),
    /// checked against the variant's interface, then validated and timed like the built-in.
    #[arg(long, alias = "spirv")]
    kernel: Option<PathBuf>,
    /// Float-control execution modes of the kernel: on (round-to-nearest-even, inf/NaN
    /// preserved), off (a build whose hits stay exact without them), auto (on where the
    /// device has them, else off where the layout has such a build).
    #[arg(long, default_value = "auto")]
    float_controls: String,
    /// Treat a device feature as missing (testing the fallbacks), e.g. shaderFloat16,
    /// storageBuffer16BitAccess, floatControls, subgroupSizeControl, rayQuery.
    #[arg(long, hide = true)]
    mask_feature: Vec<String>,
    /// Seconds a dispatch may run before its kernel is declared hung (default 600).
    #[arg(long)]
    kernel_timeout: Option<f64>,
}

fn load_scene(path: &PathBuf) -> anyhow::Result<scene::Scene> {
    let s = scene::load(path)?;
    for w in &s.warnings {
        eprintln!("warning: {w}");
    }
    Ok(s)
}

fn print_timing(t: &measure::Timing, warmup: usize, rays: usize) -> anyhow::Result<()> {
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

fn print_counters(c: &[halftrace::trace::Counters], rays: usize, packet: usize) -> anyhow::Result<()> {
    let m = halftrace::trace::mean_counters(c);
    outln!("per ray: {:.2} nodes, {:.2} box tests, {:.2} triangle tests, {:.3} re-anchors", m[0], m[1], m[2], m[3]);
    let packets = rays.div_ceil(packet).max(1);
    let pn: u64 = c.iter().map(|x| x.packet_nodes as u64).sum();
    outln!(
        "per packet of {packet}: {:.2} nodes visited; SIMD utilisation {:.1}% (active rays per visited node)",
        pn as f64 / packets as f64,
        100.0 * halftrace::trace::simd_utilisation(c, packet)
    );
    Ok(())
}

/// Scene, BVH and rays of a `trace` command.
struct Traced {
    scene: scene::Scene,
    bin: bvh::BinaryBvh,
    build_ms: f64,
    kind: RayKind,
    rays: Vec<halftrace::rays::Ray>,
}

fn trace_inputs(a: &TraceArgs) -> anyhow::Result<Traced> {
    let kind: RayKind = a.rays.parse()?;
    let camera = a.camera.as_deref().map(Camera::parse).transpose()?;
    let scene = load_scene(&a.scene)?;
    let t0 = Instant::now();
    let bin = bvh::build_binary(&scene);
    let build_ms = t0.elapsed().as_secs_f64() * 1e3;
    let params = RayParams { width: a.width, height: a.height, camera, seed: a.seed, ..Default::default() };
    let rays = make_rays(&scene, &bin, &kind, &params)?;
    Ok(Traced { scene, bin, build_ms, kind, rays })
}

fn open_gpu(a: &TraceArgs) -> anyhow::Result<gpu::Gpu> {
    let opts = gpu::ContextOptions {
        device: a.device.clone(),
        mask_features: a.mask_feature.clone(),
        kernel_timeout_s: a.kernel_timeout,
        ..Default::default()
    };
    Ok(gpu::Gpu::new(&opts)?)
}

/// `trace --layout <baseline>`: someone else's traversal of the same triangles (rq: the
/// driver's acceleration structure and ray queries), checked against the f32 reference.
fn trace_baseline(a: &TraceArgs, layout: LayoutId) -> anyhow::Result<()> {
    let b = layout.baseline().expect("a baseline");
    anyhow::ensure!(a.backend.as_deref() != Some("cpu"), "--layout {layout} runs on the GPU only");
    // A baseline has no B, P, math, float controls, counters or kernel of ours: say so rather
    // than ignore the flag.
    let na = |flag: &str| {
        anyhow::anyhow!("{flag} does not apply to --layout {layout} (a baseline: the driver's traversal has no B, P, math mode, float controls, work counters or user kernel)")
    };
    if a.branching != 4 {
        bvh::check_branching(a.branching).context("--branching")?;
        return Err(na("--branching"));
    }
    if a.packet != 1 {
        return Err(na("--packet"));
    }
    for (flag, given) in [
        ("--math", a.math.is_some()),
        ("--packet-impl", a.packet_impl.is_some()),
        ("--stats", a.stats),
        ("--kernel", a.kernel.is_some()),
        ("--float-controls", a.float_controls != "auto"),
    ] {
        if given {
            return Err(na(flag));
        }
    }
    let t = trace_inputs(a)?;
    let g = open_gpu(a)?;
    outln!(
        "scene {} ({} triangles), layout {layout}, rays {}: {} rays; device {} ({})",
        t.scene.name,
        t.scene.len(),
        t.kind,
        t.rays.len(),
        g.info.name,
        g.info.driver
    );
    let dev = b.prepare(&g)?;
    let bs = dev.scene(&t.scene)?;
    outln!("acceleration structures: {} bytes, built in {:.2} ms", bs.bytes(), bs.build_ms());
    let f32_hits = Encoded::new(&t.scene, &t.bin, LayoutId::f32(), 4)?.trace_default(&t.rays).0;
    let plan = Plan { warmup: a.warmup, repeat: a.repeat, count: false };
    let m = measure::validate_then_time(
        &BaselineTarget { name: b.kernel(), scene: bs.as_ref() },
        &t.rays,
        Reference::Agreement,
        &f32_hits,
        plan,
    )?;
    let agree = m.vs_f32;
    outln!(
        "agreement with the f32 reference: {:.4}% ({} of {} rays: same prim, or t within 1e-5 relative)",
        100.0 * agree.rate(),
        agree.agree,
        agree.total
    );
    print_timing(m.timing.as_ref().expect("baselines are always timed"), a.warmup, t.rays.len())?;
    if let Some(p) = &a.out {
        npy::write_hits(p, &m.hits)?;
        outln!("hits written to {}", p.display());
    }
    if let Some(p) = &a.save_rays {
        npy::write_rays(p, &t.rays)?;
        outln!("rays written to {}", p.display());
    }
    if let Some(p) = &a.image {
        halftrace::images::render(p, &t.scene, &t.rays, &m.hits, a.width, a.height)?;
        outln!("image written to {}", p.display());
    }
    Ok(())
}

/// Checks the output files before anything is traced: each is distinct from every input and
/// from each other (an input is never overwritten), and `--image` is a PNG of primary rays.
fn check_outputs(a: &TraceArgs) -> anyhow::Result<()> {
    let same = |x: &std::path::Path, y: &std::path::Path| {
        let c = |p: &std::path::Path| {
            let parent = p.parent().filter(|q| !q.as_os_str().is_empty()).unwrap_or(std::path::Path::new("."));
            parent.canonicalize().ok().map(|d| d.join(p.file_name().unwrap_or_default()))
        };
        x == y || (c(x).is_some() && c(x) == c(y))
    };
    let mut inputs: Vec<(&str, PathBuf)> = vec![("--scene", a.scene.clone())];
    if let Ok(RayKind::File(p)) = a.rays.parse::<RayKind>() {
        inputs.push(("--rays", p));
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
        if p.is_dir() {
            anyhow::bail!("{n} {} is a folder; name a file", p.display());
        }
    }
    if let Some(p) = &a.image {
        anyhow::ensure!(
            p.extension().is_some_and(|e| e.eq_ignore_ascii_case("png")),
            "--image {}: name a .png file (the image is written as PNG)",
            p.display()
        );
        anyhow::ensure!(a.rays == "primary", "--image needs --rays primary (got --rays {})", a.rays);
    }
    Ok(())
}

fn instance(scene: &std::path::Path, count: usize, seed: u64, out: &std::path::Path) -> anyhow::Result<()> {
    anyhow::ensure!(count >= 1, "--count must be at least 1");
    anyhow::ensure!(
        out.extension().is_some_and(|e| e.eq_ignore_ascii_case("glb")),
        "--out {}: name a .glb file",
        out.display()
    );
    anyhow::ensure!(!out.exists(), "--out {} exists; it is not overwritten", out.display());
    let s = halftrace::scene::load(scene)?;
    let Some(total) = s.len().checked_mul(count).filter(|&t| t <= halftrace::scene::MAX_TRIANGLES) else {
        anyhow::bail!(
            "{} instances of {} triangles exceed the {} triangles a scene may have",
            count,
            s.len(),
            halftrace::scene::MAX_TRIANGLES
        );
    };
    let bytes = halftrace::formats::instanced_glb(&s, count, seed);
    halftrace::fsx::write_atomic(out, &bytes)?;
    outln!(
        "{}: {} instances of {} ({} triangles each): {} triangles, {} bytes",
        out.display(),
        count,
        s.name,
        s.len(),
        total,
        bytes.len()
    );
    Ok(())
}

fn bench(a: BenchArgs) -> anyhow::Result<()> {
    let mut scenes = a.scene.clone();
    if scenes.is_empty() {
        scenes.push(PathBuf::from("scenes/teapot.obj"));
        for s in ["../shared/scenes/sponza_dabrovic.obj", "../shared/scenes/igea.obj.gz"] {
            if std::path::Path::new(s).is_file() {
                scenes.push(PathBuf::from(s));
            }
        }
    }
    let mut kinds = Vec::new();
    for r in &a.rays {
        let k: RayKind = r.parse().with_context(|| format!("--rays {r}"))?;
        anyhow::ensure!(
            !matches!(k, RayKind::File(_)),
            "--rays {r}: bench uses the generated kinds (primary, ao, diffuse, grazing)"
        );
        kinds.push(k);
    }
    halftrace::rays::check_image_size(a.width, a.height).map_err(anyhow::Error::msg)?;
    if let Some(o) = &a.out {
        anyhow::ensure!(!o.is_dir(), "--out {} is a folder; name a file", o.display());
    }
    let mut layouts = Vec::new();
    for l in &a.layouts {
        let id: LayoutId = l.parse().with_context(|| format!("--layouts {l}"))?;
        anyhow::ensure!(
            id.bvh().is_some(),
            "--layouts {l}: a baseline; rq and embree are always timed when the device has them"
        );
        layouts.push(id);
    }
    let cfg = halftrace::bench::BenchConfig {
        scenes,
        kinds,
        width: a.width,
        height: a.height,
        rounds: a.rounds,
        repeat: a.repeat,
        device: a.device.clone(),
        validation: a.validation,
        layouts,
    };
    let r = halftrace::bench::run(&cfg)?;
    let md = halftrace::bench::markdown(&cfg, &r);
    outln!("{md}");
    if let Some(o) = &a.out {
        halftrace::fsx::write_atomic(o, md.as_bytes())?;
        outln!("report written to {}", o.display());
    }
    Ok(())
}

fn trace(a: TraceArgs) -> anyhow::Result<()> {
    let layout: LayoutId = a.layout.parse()?;
    anyhow::ensure!(a.repeat >= 1, "--repeat {}: at least one timed dispatch is needed", a.repeat);
    anyhow::ensure!(a.kernel_timeout.is_none_or(|t| t > 0.0), "--kernel-timeout must be a positive number of seconds");
    check_outputs(&a)?;
    if layout.baseline().is_some() {
        return trace_baseline(&a, layout);
    }
    bvh::check_branching(a.branching).context("--branching")?;
    anyhow::ensure!(
        halftrace::variant::PACKETS.contains(&a.packet),
        "--packet {}: use one of 1, 4, 8, 16, 32, 64",
        a.packet
    );
    let maths = layout.caps().maths;
    let math = match &a.math {
        None => maths[0],
        Some(m) => {
            let math: Math = m.parse().map_err(anyhow::Error::msg).context("--math")?;
            anyhow::ensure!(
                maths.contains(&math),
                "--math {m}: layout {layout} has {}",
                maths.iter().map(|m| m.name()).collect::<Vec<_>>().join(", ")
            );
            math
        }
    };
    let fc_choice: FcChoice = a.float_controls.parse().map_err(anyhow::Error::msg).context("--float-controls")?;
    let mut variant = Variant::new(layout, a.branching, a.packet).with_math(math);
    if fc_choice == FcChoice::Off {
        variant = variant.with_fc(FloatControls::Off);
    }
    let force_impl = match a.packet_impl.as_deref() {
        None => None,
        Some("subgroup") => Some(PacketImpl::Subgroup),
        Some("shared") => Some(PacketImpl::Shared),
        Some("hybrid") => Some(PacketImpl::Hybrid),
        Some(o) => anyhow::bail!("--packet-impl '{o}': use subgroup, hybrid or shared"),
    }
    .filter(|_| a.packet > 1);
    let backend = match a.backend.as_deref() {
        Some("cpu") => "cpu",
        Some("gpu") => "gpu",
        None if a.kernel.is_some() => "gpu",
        None => {
            if gpu::list_devices().map(|d| !d.is_empty()).unwrap_or(false) {
                "gpu"
            } else {
                "cpu"
            }
        }
        Some(other) => anyhow::bail!("--backend '{other}': use gpu or cpu"),
    };
    let Traced { scene, bin, build_ms, kind, rays } = trace_inputs(&a)?;
    let rays = &rays;
    // Memory on big scenes: f32's hits (the GPU run's "against f32" line) are taken and its
    // encoding dropped before the layout's is made, and the binary BVH goes once encoded.
    let f32_hits = if backend == "gpu" && layout != LayoutId::f32() {
        Some(Encoded::new(&scene, &bin, LayoutId::f32(), a.branching)?.trace_default(rays).0)
    } else {
        None
    };
    let enc = Encoded::new(&scene, &bin, layout, a.branching)?;
    drop(bin);
    outln!("scene {} ({} triangles), variant {variant}, rays {}: {} rays", scene.name, scene.len(), kind, rays.len());
    let t1 = Instant::now();
    let (ref_hits, ref_counters) = enc.trace_fc(rays, a.packet, math, variant.fc);
    let cpu_secs = t1.elapsed().as_secs_f64();
    let (hits, counters) = if backend == "cpu" {
        outln!(
            "backend cpu (reference): {:.1} ms, {:.2} Mrays/s; BVH build {:.1} ms",
            cpu_secs * 1e3,
            rays.len() as f64 / cpu_secs / 1e6,
            build_ms
        );
        (ref_hits, Some(ref_counters))
    } else {
        let g = open_gpu(&a)?;
        outln!("device {} ({}), driver {}", g.info.name, g.info.kind, g.info.driver);
        let resolved = gpu::support::resolve(&g.info, variant, fc_choice).map_err(anyhow::Error::msg)?;
        match &a.kernel {
            Some(k) => outln!(
                "kernel {} (the user's, in place of {}; float controls {})",
                k.display(),
                resolved.name(false),
                resolved.fc.name()
            ),
            None => outln!("kernel {} (float controls {})", resolved.name(false), resolved.fc.name()),
        }
        // The reference of the build the device runs (without float controls its bounds differ).
        let (ref_hits, ref_counters) = if resolved.fc == variant.fc {
            (ref_hits, ref_counters)
        } else {
            enc.trace_fc(rays, a.packet, math, resolved.fc)
        };
        let variant = resolved;
        let imp = kernel::choose_impl(&g, &variant, force_impl);
        let source = a.kernel.as_deref().map(Source::user).unwrap_or(Source::Builtin);
        // The reference hits were taken above: each host array goes once the device holds it.
        let gb = GpuBvh::upload_owned(&g, enc).with_context(|| variant.to_string())?;
        if gb.buffers == Buffers::Addressed {
            outln!("scene buffers read by address: {} bytes of nodes and triangles, a buffer larger than one storage binding may span on this device (maxStorageBufferRange {} bytes)", gb.bytes, g.info.max_storage_buffer);
        }
        let variant = variant.with_buffers(gb.buffers);
        let timed = Kernel::build(&g, &variant, imp, false, &source).with_context(|| variant.to_string())?;
        let counting = match (&source, a.stats) {
            (_, false) => None,
            (Source::Builtin, true) => Some(Kernel::build(&g, &variant, imp, true, &source)?),
            (_, true) => {
                let k = Kernel::user_counting(&g, &variant, imp, &source)?;
                if k.is_none() {
                    outln!("--stats: {} writes no counters; work counters not measured", source_name(&source));
                }
                k
            }
        };
        let f32_hits = f32_hits.unwrap_or_else(|| ref_hits.clone());
        let target = KernelTarget { gpu: &g, bvh: &gb, timed: &timed, counting: counting.as_ref() };
        let plan = Plan { warmup: a.warmup, repeat: a.repeat, count: counting.is_some() };
        // Correctness before speed: the CPU reference of the same layout, packet size and math.
        let m = measure::validate_then_time(
            &target,
            rays,
            Reference::Exact { hits: &ref_hits, counters: &ref_counters },
            &f32_hits,
            plan,
        )?;
        if let Some(f) = m.failure {
            anyhow::bail!("{f}");
        }
        outln!("kernel {}: validated against the CPU reference ({} rays identical)", timed.label(), rays.len());
        if layout != LayoutId::f32() {
            outln!("against f32: {} rays differ, {} false misses", m.vs_f32.differs(), m.vs_f32.false_misses);
        }
        print_timing(m.timing.as_ref().expect("validated targets are timed"), a.warmup, rays.len())?;
        (m.hits, m.counters)
    };
    let nhit = hits.iter().filter(|h| h.is_hit()).count();
    outln!("{nhit} hits");
    if let Some(b) = halftrace::progress::peak_rss_bytes() {
        outln!("peak memory {} MB ({:.0} bytes per triangle)", b >> 20, b as f64 / scene.len() as f64);
    }
    if let Some(c) = counters.filter(|_| a.stats || backend == "cpu") {
        print_counters(&c, rays.len(), a.packet)?;
    }
    if let Some(p) = &a.out {
        npy::write_hits(p, &hits)?;
        outln!("hits written to {}", p.display());
    }
    if let Some(p) = &a.save_rays {
        npy::write_rays(p, rays)?;
        outln!("rays written to {}", p.display());
    }
    if let Some(p) = &a.image {
        anyhow::ensure!(kind == RayKind::Primary, "--image needs --rays primary");
        halftrace::images::render(p, &scene, rays, &hits, a.width, a.height)?;
        outln!("image written to {}", p.display());
    }
    Ok(())
}

fn source_name(s: &Source) -> String {
    match s {
        Source::Builtin => "the built-in kernel".into(),
        Source::Glsl(p) | Source::Spirv(p) => p.display().to_string(),
    }
}

fn bvh_stats(path: &PathBuf) -> anyhow::Result<()> {
    let scene = load_scene(path)?;
    let t0 = Instant::now();
    let bin = bvh::build_binary(&scene);
    let ms = t0.elapsed().as_secs_f64() * 1e3;
    outln!(
        "scene {} ({} triangles, {} degenerate); binary SAH build {:.1} ms ({:.2} Mtris/s)",
        scene.name,
        scene.len(),
        scene.degenerate,
        ms,
        scene.len() as f64 / ms / 1e3
    );
    outln!(
        "{:>3} {:>6} {:>9} {:>9} {:>12} {:>10} {:>6} {:>9} {:>6}",
        "B",
        "layout",
        "nodes",
        "leaves",
        "node bytes",
        "bytes/node",
        "depth",
        "SAH cost",
        "fill"
    );
    for b in bvh::BRANCHINGS {
        let w = bvh::collapse(&bin, b);
        let st = stats(&w);
        for layout in LayoutId::layouts() {
            let enc = Encoded::new(&scene, &bin, layout, b)?;
            outln!(
                "{:>3} {:>6} {:>9} {:>9} {:>12} {:>10} {:>6} {:>9.2} {:>6.2}",
                b,
                layout.name(),
                st.inner_nodes,
                st.leaves,
                enc.node_bytes(),
                enc.node_size(),
                st.depth,
                st.sah_cost,
                st.fill
            );
        }
    }
    let tb = halftrace::layout::TriBuffer::new(&scene, &bvh::collapse(&bin, 2));
    outln!("triangles (shared by all layouts): {} bytes", tb.bytes());
    Ok(())
}

fn devices(bench: bool, device: Option<String>, mask: &[String]) -> anyhow::Result<()> {
    let mut list = gpu::list_devices()?;
    if list.is_empty() {
        outln!("no Vulkan devices");
    }
    if let Some(want) = &device {
        // The same choice --device makes everywhere (gpu::pick).
        let all: Vec<String> = list.iter().map(|d| format!("{}: {}", d.index, d.name)).collect();
        let i = gpu::pick(&list, Some(want))
            .map_err(|_| anyhow::anyhow!("--device {want}: no such device (found: {})", all.join("; ")))?;
        list = vec![list.swap_remove(i)];
    }
    for d in &mut list {
        for m in mask {
            d.mask(m).map_err(anyhow::Error::msg)?;
        }
        outln!(
            "{}: {} ({}), Vulkan {}, driver {}\n   shaderFloat16 {}, storageBuffer16BitAccess {}, shaderFloat64 {}, subgroup size {}, ray query {}, max storage buffer {} MiB",
            d.index, d.name, d.kind, d.api_version, d.driver, d.shader_float16, d.storage_16bit, d.shader_float64, d.subgroup_size, d.ray_query, d.max_storage_buffer >> 20
        );
        outln!(
            "   float controls: RTE fp16 {}, RTE fp32 {}, inf/NaN preserve fp16 {}, fp32 {}; subgroup size control {}",
            d.fp16_rte,
            d.fp32_rte,
            d.preserve_16,
            d.preserve_32,
            if d.subgroup_size_control {
                format!("{}..{}", d.min_subgroup_size, d.max_subgroup_size)
            } else {
                "no".into()
            }
        );
        for line in device_plan(d) {
            outln!("   {line}");
        }
    }
    outln!("\nlayouts and baselines (--layout):");
    for l in LayoutId::all() {
        let c = l.caps();
        let maths = if c.maths.is_empty() {
            "n/a".to_string()
        } else {
            c.maths.iter().map(|m| m.name()).collect::<Vec<_>>().join(", ")
        };
        outln!(
            "  {:<9} {} ({}; math: {maths})",
            l.name(),
            l.summary(),
            if l.baseline().is_some() { "baseline" } else { "layout" }
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

/// What halftrace will run on a device: per layout and math mode the float controls (or why it
/// is skipped), per packet size the implementation, and the baselines.
fn device_plan(d: &gpu::DeviceInfo) -> Vec<String> {
    let mut out = Vec::new();
    for l in LayoutId::layouts() {
        for &m in l.caps().maths {
            let v = Variant::new(l, 4, 1).with_math(m);
            let what = match gpu::support::resolve(d, v, FcChoice::Auto) {
                Ok(r) => format!("runs, float controls {}", r.fc.name()),
                Err(why) => format!("skipped: {why}"),
            };
            out.push(format!("{:<9} math {:<6} {what}", l.name(), m.name()));
        }
    }
    let packets: Vec<String> = halftrace::variant::PACKETS
        .iter()
        .filter(|&&p| p > 1)
        .map(|&p| match gpu::support::packet_plan(d, p) {
            (PacketImpl::Subgroup, Some(n)) => format!("P={p} subgroup (pinned to {n})"),
            (PacketImpl::Subgroup, None) => format!("P={p} subgroup ({})", d.subgroup_size),
            (PacketImpl::Hybrid, _) => format!("P={p} hybrid (subgroups of {}, then shared memory)", d.subgroup_size),
            (imp, _) => format!("P={p} {}", if imp == PacketImpl::Shared { "shared memory" } else { "single" }),
        })
        .collect();
    out.push(format!("packets: {}", packets.join(", ")));
    for (l, b) in LayoutId::all().filter_map(|l| Some((l, l.baseline()?))) {
        out.push(format!(
            "{:<9} {}",
            l.name(),
            b.unavailable(d).map(|why| format!("skipped: {why}")).unwrap_or_else(|| "runs".into())
        ));
    }
    out
}

fn conformance(a: ConformanceArgs) -> anyhow::Result<()> {
    use halftrace::conformance;
    let mut scenes = a.scene.clone();
    if let Some(d) = &a.scenes_dir {
        let mut found: Vec<PathBuf> = std::fs::read_dir(d)
            .with_context(|| format!("--scenes-dir {}", d.display()))?
            .filter_map(|e| e.ok().map(|e| e.path()))
            .filter(|p| p.to_string_lossy().ends_with(".obj") || p.to_string_lossy().ends_with(".obj.gz"))
            .collect();
        anyhow::ensure!(!found.is_empty(), "--scenes-dir {}: no .obj or .obj.gz scenes in it", d.display());
        found.sort();
        scenes.extend(found);
    }
    if scenes.is_empty() {
        scenes.push(PathBuf::from(halftrace::sweep::DEFAULT_SCENE));
    }
    let out = a.out.clone().unwrap_or_else(|| {
        let d = halftrace::sweep::default_out();
        d.with_file_name(format!(
            "conformance-{}",
            d.file_name().map(|f| f.to_string_lossy().to_string()).unwrap_or_default()
        ))
    });
    let opts = conformance::Options {
        quick: a.quick,
        scenes,
        device: a.device.clone(),
        mask_features: a.mask_feature.clone(),
        validation: a.validation,
    };
    let o = conformance::run(&opts, |line| eprintln!("{line}"))?;
    conformance::write(&o, a.quick, &out)?;
    outln!("{}", conformance::markdown(&o, a.quick));
    outln!("written to {}", out.join("conformance.md").display());
    let fails = o.failures();
    anyhow::ensure!(
        o.validation.is_empty(),
        "{} validation layer message(s); see {}",
        o.validation.len(),
        out.join("conformance.md").display()
    );
    anyhow::ensure!(
        fails.is_empty(),
        "{} kernel(s) failed conformance: {}",
        fails.len(),
        fails.iter().map(|c| c.variant.kernel_name(c.imp, false)).collect::<Vec<_>>().join(", ")
    );
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
    if !a.series.is_empty() {
        c.series = if a.series == ["all"] { c.layouts.clone() } else { a.series.clone() };
    }
    if !a.scheme_branchings.is_empty() {
        c.scheme_branchings = a.scheme_branchings.clone();
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
    c.kernel_timeout = a.kernel_timeout.unwrap_or(c.kernel_timeout);
    if let Some(d) = &a.device {
        c.device = d.clone();
    }
    if let Some(f) = &a.float_controls {
        c.float_controls = f.parse().map_err(anyhow::Error::msg).context("--float-controls")?;
    }
    c.check()?;
    c.shard = match &a.shard {
        Some(s) => Some(s.parse().map_err(anyhow::Error::msg)?),
        None => sweep::Shard::from_slurm(|k| std::env::var(k).ok()).map_err(anyhow::Error::msg)?,
    };
    let mut out = a.out.clone().unwrap_or_else(sweep::default_out);
    if let Some(s) = c.shard {
        out = out.join(s.folder());
    }
    anyhow::ensure!(!(a.resume && a.force), "--resume and --force exclude each other");
    let mode = if a.resume {
        sweep::OutMode::Resume
    } else if a.force {
        sweep::OutMode::Force
    } else {
        sweep::OutMode::New
    };
    let kept = sweep::prepare_out(&out, mode)?;
    halftrace::progress::set_quiet(a.quiet);
    let t0 = Instant::now();
    let s = sweep::run(&c, &out, a.quiet, &a.mask_feature, kept)?;
    outln!("{} variants in {:.0} s; report: {}", s.rows, t0.elapsed().as_secs_f64(), s.out.join("report.md").display());
    if !s.failed.is_empty() {
        anyhow::bail!("{} variant(s) failed validation: {}", s.failed.len(), s.failed.join(", "));
    }
    Ok(())
}

fn report(dirs: &[PathBuf], out: Option<&PathBuf>) -> anyhow::Result<()> {
    let mut rows = Vec::new();
    // (identity of a row) → (folder, CSV line) of its first occurrence
    let mut seen: std::collections::HashMap<String, (usize, usize)> = std::collections::HashMap::new();
    let mut canon = Vec::new();
    for (i, d) in dirs.iter().enumerate() {
        let c = d.canonicalize().unwrap_or_else(|_| d.clone());
        if let Some(j) = canon.iter().position(|x| *x == c) {
            anyhow::bail!(
                "{} is named twice (as {} and {}): its rows would count twice",
                c.display(),
                dirs[j].display(),
                d.display()
            );
        }
        canon.push(c);
        for (k, r) in halftrace::report::read_rows(d)?.into_iter().enumerate() {
            let id = format!(
                "{} | {} | {} | {} | {} | {}/{}/B{}/P{} fc {}",
                r.device,
                r.driver,
                r.scene,
                r.rays,
                r.kernel,
                r.layout,
                r.math,
                r.branching,
                r.packet,
                r.float_controls
            );
            if let Some(&(f, line)) = seen.get(&id) {
                anyhow::bail!(
                    "{}/results.csv line {} and {}/results.csv line {} are the same variant ({id}); a merged report would average or double-count them — remove one, or report the folders separately",
                    dirs[f].display(),
                    line,
                    d.display(),
                    k + 2
                );
            }
            seen.insert(id, (i, k + 2));
            rows.push(r);
        }
    }
    let out = out.cloned().unwrap_or_else(|| dirs[0].clone());
    // Into a folder of its own, the merged rows too (never into a folder it read from).
    let own = !canon.iter().any(|c| out.canonicalize().is_ok_and(|o| o == *c));
    if own {
        anyhow::ensure!(
            !out.join("results.csv").exists(),
            "--out {} already holds results.csv; name a new folder for the merged report",
            out.display()
        );
        halftrace::report::write_rows(&out, &halftrace::report::sorted(&rows))?;
        // The images a sweep renders (render, heat maps, diff masks) come along from the
        // folder that has them, so the merged report shows what the unsplit one does.
        for d in dirs {
            for e in std::fs::read_dir(d).with_context(|| d.display().to_string())?.flatten() {
                let name = e.file_name().to_string_lossy().to_string();
                if halftrace::report::is_image(&name) && !out.join(&name).exists() {
                    halftrace::fsx::write_atomic(&out.join(&name), &std::fs::read(e.path())?)?;
                }
            }
        }
    }
    halftrace::report::render(&rows, &out, dirs)?;
    outln!(
        "{} rows from {} folder(s); report: {}{}",
        rows.len(),
        dirs.len(),
        out.join("report.md").display(),
        if own { format!(", merged rows: {}", out.join("results.csv").display()) } else { String::new() }
    );
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
        Cmd::Instance { scene, count, seed, out } => instance(&scene, count, seed, &out),
        Cmd::Devices { bench, device, mask_feature } => devices(bench, device, &mask_feature),
        Cmd::Conformance(a) => conformance(a),
        Cmd::Shaders { emit } => shaders(&emit),
        Cmd::Sweep(a) => sweep(a),
        Cmd::Bench(a) => bench(a),
        Cmd::Report { dirs, out } => report(&dirs, out.as_ref()),
    };
    if let Err(e) = r {
        // The context chain, each cause once: an error whose message already quotes its
        // source (an OS or gzip error) does not print it again.
        let mut msg = e.to_string();
        for c in e.chain().skip(1) {
            let t = c.to_string();
            if !msg.contains(&t) {
                msg += ": ";
                msg += &t;
            }
        }
        eprintln!("error: {msg}");
        std::process::exit(1);
    }
}
