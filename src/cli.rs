//! The command line's arguments (clap): every subcommand and flag, typed where clap can check
//! the value, and nothing else — the work is in [`crate::commands`].

use crate::baseline::BaselineId;
use crate::layout::LayoutId;
use crate::precision::{FcChoice, Math};
use crate::rays::{Camera, RayKind};
use crate::variant::PacketImpl;
use clap::{Parser, Subcommand};
use std::path::PathBuf;

#[derive(Parser)]
#[command(name = "halftrace", version, about = "Half-precision hierarchical BVH traversal harness")]
pub struct Cli {
    #[command(subcommand)]
    pub cmd: Cmd,
}

#[derive(Subcommand)]
pub enum Cmd {
    /// Trace a ray set through one layout and branching factor.
    Trace(TraceArgs),
    /// Write a glTF binary (.glb) that instances a scene N times (rotated, scaled, on a grid):
    /// big test scenes without shipping them.
    Instance(InstanceArgs),
    /// Print per-B, per-layout BVH statistics.
    BvhStats {
        /// Scene: OBJ, glTF (.gltf, .glb) or PLY, each optionally gzip-compressed (.gz).
        #[arg(long)]
        scene: PathBuf,
    },
    /// List Vulkan devices, what each runs of every layout and packet size, and why the rest
    /// would be skipped.
    Devices(DevicesArgs),
    /// Sweep scenes × ray kinds × layouts × B × P: validate, time, count, report.
    Sweep(SweepArgs),
    /// The speed ratios a kernel change is judged by (f16h ÷ f32, best reduced layout ÷ f32,
    /// best ÷ embree, packets ÷ P = 1, f32 ÷ rq, f32 ÷ rt), validated, then timed in
    /// interleaved rounds: medians with min/max.
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
    /// A device's whole report in one command sized to a wall-time budget: devices,
    /// conformance --quick, a short bench, a sweep in the time that remains, isa where the
    /// driver reports pipeline statistics; one folder named after the device, resumable.
    DeviceReport(DeviceReportArgs),
    /// The compiler's view: build each kernel on RADV null devices (AMD's shader compiler for a
    /// GPU family, no GPU needed) or on a device whose driver reports pipeline statistics, and
    /// write registers, scratch, occupancy and the fp16 instruction mix per kernel (isa.md,
    /// isa.csv, isa.json, plots). Nothing runs.
    Isa(IsaArgs),
    /// Estimated cycles per ray on AMD GPUs we do not have: ACO's cycle estimate (Latency) of
    /// each kernel taken apart per loop on RADV null devices (checked to rebuild it exactly),
    /// its loops' trips taken from real rays in lockstep waves (estimate.md, estimate.csv,
    /// estimate-rays.csv). The compiler's model, not a measurement; nothing runs.
    Estimate(EstimateArgs),
    /// The memory side of a ray on GPU models: bytes each kernel requests per ray (nodes,
    /// triangles, ids, stack), the distinct cache lines per ray and per lockstep wave, and a
    /// cache model of each GPU (an L1 per unit, the L2, a last-level cache, DRAM) fed by the
    /// waves it runs at once: bytes and hit rates at each level, DRAM bytes, energy and the
    /// DRAM-bound rays/s per ray, every layout ÷ f32, one verdict per GPU (memory.md,
    /// memory.csv, memory.json). From the CPU reference's exact walk; nothing runs on a GPU.
    Memory(MemoryArgs),
    /// Print the RADV null devices listed with RADV_FORCE_FAMILY as set (how `isa` and `devices`
    /// learn which families the installed RADV knows: RADV aborts on the others).
    #[command(hide = true)]
    ProbeFamily,
    /// Build the isa matrix on the one model whose drm-shim environment this process was
    /// started with, printing one JSON row per kernel (how `isa` reads another vendor's
    /// compiler: one driver and model per process).
    #[command(hide = true)]
    IsaModel(IsaModelArgs),
    /// Compile the default variant matrix and write one SPIR-V file per kernel.
    Shaders {
        /// Output folder (e.g. spirv/).
        #[arg(long)]
        emit: PathBuf,
    },
}

/// A `--layout` value: one of our layouts or a baseline.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum LayoutArg {
    Layout(LayoutId),
    Baseline(BaselineId),
}

impl std::str::FromStr for LayoutArg {
    type Err = String;
    fn from_str(s: &str) -> Result<LayoutArg, String> {
        match BaselineId::parse(s) {
            Some(b) => Ok(LayoutArg::Baseline(b)),
            None => s.parse().map(LayoutArg::Layout).map_err(|e: crate::layout::UnknownLayout| {
                let baselines: Vec<&str> = BaselineId::all().map(|b| b.name()).collect();
                format!("{e}, or a baseline: {}", baselines.join(", "))
            }),
        }
    }
}

/// Where `trace` runs.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum Backend {
    /// The Vulkan device's kernels, checked against the CPU reference.
    Gpu,
    /// The CPU reference alone.
    Cpu,
}

#[derive(clap::Args)]
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
    pub math: Option<Math>,
    /// Packet implementation (default: subgroup when P fits the device's subgroup, else hybrid
    /// where the device has subgroup arithmetic, else shared memory).
    #[arg(long)]
    pub packet_impl: Option<PacketImpl>,
    /// primary, ao, diffuse, grazing, or a FILE.npy (float32, N x 8).
    #[arg(long, default_value = "primary")]
    pub rays: RayKind,
    #[arg(long, default_value_t = 256)]
    pub width: u32,
    #[arg(long, default_value_t = 256)]
    pub height: u32,
    /// eye_x,eye_y,eye_z,target_x,target_y,target_z,fov_degrees (default: frame the scene).
    #[arg(long, value_parser = |s: &str| Camera::parse(s).map_err(|e| e.to_string()))]
    pub camera: Option<Camera>,
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
    pub float_controls: FcChoice,
    /// Treat a device feature as missing (testing the fallbacks), e.g. shaderFloat16,
    /// storageBuffer16BitAccess, floatControls, subgroupSizeControl, rayQuery.
    #[arg(long, hide = true)]
    pub mask_feature: Vec<String>,
    /// How long a dispatch may run before its kernel is declared hung: seconds or e.g. 90s,
    /// 10m (default 600 s; at most a week).
    #[arg(long, value_parser = |s: &str| crate::units::parse_duration("--kernel-timeout", s))]
    pub kernel_timeout: Option<f64>,
}

#[derive(clap::Args)]
pub struct InstanceArgs {
    /// Scene to instance (OBJ, glTF or PLY).
    #[arg(long)]
    pub scene: PathBuf,
    /// Number of instances.
    #[arg(long)]
    pub count: usize,
    /// Seed of the rotations and scales.
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// The .glb file to write (an existing file is refused).
    #[arg(long)]
    pub out: PathBuf,
}

#[derive(clap::Args)]
pub struct DevicesArgs {
    /// Also measure the device's raw fp16 and fp32 arithmetic rates (sub, mul, min, max,
    /// compare).
    #[arg(long, alias = "bench")]
    pub arith: bool,
    /// Only this device (index or name substring; for --arith, default: the default device).
    #[arg(long)]
    pub device: Option<String>,
    /// Show what would run with these features treated as missing (testing).
    #[arg(long, hide = true)]
    pub mask_feature: Vec<String>,
}

#[derive(clap::Args)]
pub struct SweepArgs {
    /// TOML file with any of the keys of sweep.example.toml; flags override it.
    #[arg(long)]
    pub config: Option<PathBuf>,
    /// Scene file (repeat for several).
    #[arg(long)]
    pub scene: Vec<PathBuf>,
    /// Ray kinds, comma-separated (primary, ao, diffuse, grazing, FILE.npy).
    #[arg(long, value_delimiter = ',')]
    pub rays: Vec<String>,
    /// Layouts and baselines, comma-separated.
    #[arg(long, value_delimiter = ',')]
    pub layouts: Vec<String>,
    /// Layouts that get the B and P series, comma-separated (default f32,f16h; "all" for
    /// every layout in --layouts); the others run at --layout-branchings only.
    #[arg(long, value_delimiter = ',')]
    pub series: Vec<String>,
    /// Branching factors swept at P = 1 (series layouts).
    #[arg(long, value_delimiter = ',')]
    pub branchings: Vec<usize>,
    /// Branching factors at which every layout runs with P = 1 (default 4,8).
    #[arg(long, value_delimiter = ',', alias = "scheme-branchings")]
    pub layout_branchings: Vec<usize>,
    /// Packet sizes swept at B = --packet-branching.
    #[arg(long, value_delimiter = ',')]
    pub packets: Vec<usize>,
    #[arg(long)]
    pub packet_branching: Option<usize>,
    /// Math modes, comma-separated: f16, f32, mixed.
    #[arg(long, value_delimiter = ',')]
    pub maths: Vec<String>,
    #[arg(long)]
    pub width: Option<u32>,
    #[arg(long)]
    pub height: Option<u32>,
    #[arg(long)]
    pub warmup: Option<usize>,
    #[arg(long)]
    pub repeat: Option<usize>,
    #[arg(long)]
    pub seed: Option<u64>,
    #[arg(long)]
    pub device: Option<String>,
    /// Output folder (default reports/<UTC timestamp>/). A folder that already holds files is
    /// refused unless --resume or --force.
    #[arg(long)]
    pub out: Option<PathBuf>,
    /// Run share K of N of the job list (1 <= K <= N; deterministic, balanced by expected
    /// cost) into --out/shard-K-of-N; merge the shards with `halftrace report`. Inside a Slurm
    /// job array it defaults to the array task (SLURM_ARRAY_TASK_ID, SLURM_ARRAY_TASK_COUNT).
    #[arg(long)]
    pub shard: Option<String>,
    /// Wall-time budget (seconds, or e.g. 90s, 8m, 1h30m): no job starts once the time so far
    /// plus the longest job so far would pass it (the first job always runs); --resume runs
    /// the rest.
    #[arg(long, value_parser = |s: &str| crate::units::parse_duration("--budget", s))]
    pub budget: Option<f64>,
    /// Continue the sweep in --out: keep its rows, run only the jobs they do not record.
    #[arg(long)]
    pub resume: bool,
    /// Replace the sweep's files in --out (other files there are left alone).
    #[arg(long)]
    pub force: bool,
    /// No progress bar.
    #[arg(long)]
    pub quiet: bool,
    /// Float-control modes of the kernels: auto, on or off (see `trace --help`).
    #[arg(long)]
    pub float_controls: Option<FcChoice>,
    /// Treat a device feature as missing (testing), e.g. rayQuery.
    #[arg(long, hide = true)]
    pub mask_feature: Vec<String>,
    /// How long a dispatch may run before its kernel is declared hung: seconds or e.g. 90s,
    /// 10m (default 600 s; at most a week).
    #[arg(long, value_parser = |s: &str| crate::units::parse_duration("--kernel-timeout", s))]
    pub kernel_timeout: Option<f64>,
}

#[derive(clap::Args)]
pub struct ConformanceArgs {
    /// A covering subset (each layout, B, P, math, float-control mode and packet
    /// implementation at least once) instead of the full cross product.
    #[arg(long)]
    pub quick: bool,
    /// Scene file (repeat for several; default: the bundled scene).
    #[arg(long)]
    pub scene: Vec<PathBuf>,
    /// Also every .obj / .obj.gz scene in this folder.
    #[arg(long)]
    pub scenes_dir: Option<PathBuf>,
    /// Vulkan device: index or name substring (see `halftrace devices`).
    #[arg(long)]
    pub device: Option<String>,
    /// Output folder for conformance.md and conformance.csv (default
    /// reports/conformance-<UTC timestamp>/). Its conformance files, if any, are refused
    /// unless --force; other files there are left alone.
    #[arg(long)]
    pub out: Option<PathBuf>,
    /// Replace the conformance files in --out.
    #[arg(long)]
    pub force: bool,
    /// Run under the Khronos validation layer; any message fails the run.
    #[arg(long)]
    pub validation: bool,
    /// Treat a device feature as missing (testing the fallbacks).
    #[arg(long, hide = true)]
    pub mask_feature: Vec<String>,
}

#[derive(clap::Args)]
pub struct EstimateArgs {
    /// AMD families, comma-separated (RADV null devices: e.g. navi31, navi21, navi10, vega10,
    /// gfx1201), and other vendors' models (a740, g610, lnl, ga102, v3d-71: their compilers'
    /// whole-shader estimates, shown beside); `vendors`: every model, `all`: every family the
    /// installed RADV opens and every model (as `isa` takes them).
    #[arg(long, value_delimiter = ',', default_value = "navi31")]
    pub family: Vec<String>,
    /// Kernels: layouts (every layout and math at B = 4), cover, default or full.
    #[arg(long, default_value = "default")]
    pub matrix: String,
    /// Only these layouts (and f32, the reference).
    #[arg(long, value_delimiter = ',')]
    pub layouts: Vec<crate::layout::LayoutId>,
    /// Scenes whose rays weight the loops (OBJ, glTF or PLY; repeatable).
    #[arg(long, default_value = "scenes/teapot.obj")]
    pub scene: Vec<PathBuf>,
    /// Ray kinds, comma-separated (primary, ao, diffuse, grazing or a .npy file).
    #[arg(long, value_delimiter = ',', default_value = "primary,ao")]
    pub rays: Vec<String>,
    /// Image side of the primary rays (ao and diffuse start from their hits).
    #[arg(long, default_value_t = 256)]
    pub res: u32,
    /// Output folder (default reports/estimate-<UTC timestamp>/). Its estimate files, if any,
    /// are refused unless --force; other files there are left alone.
    #[arg(long)]
    pub out: Option<PathBuf>,
    /// Replace the estimate files in --out.
    #[arg(long)]
    pub force: bool,
}

#[derive(clap::Args)]
pub struct MemoryArgs {
    /// GPU models, comma-separated (navi31, navi21, vega10, g610, a740, lnl, ga102, h100, h200;
    /// default: all).
    #[arg(long, value_delimiter = ',')]
    pub gpu: Vec<String>,
    /// Only these layouts (and f32, the reference); every math of each.
    #[arg(long, value_delimiter = ',')]
    pub layouts: Vec<crate::layout::LayoutId>,
    /// Branching factors, comma-separated.
    #[arg(long, value_delimiter = ',', default_value = "4,8")]
    pub branchings: Vec<usize>,
    /// Scenes (OBJ, glTF or PLY; repeatable).
    #[arg(long, default_value = "scenes/teapot.obj")]
    pub scene: Vec<PathBuf>,
    /// Ray kinds, comma-separated (primary, ao, diffuse, grazing or a .npy file).
    #[arg(long, value_delimiter = ',', default_value = "primary,ao,diffuse")]
    pub rays: Vec<String>,
    /// Image side of the primary rays (ao and diffuse start from their hits).
    #[arg(long, default_value_t = 256)]
    pub res: u32,
    /// A folder of `halftrace estimate` (its estimate-rays.json): the issue cycles of the AMD
    /// families it estimated bound their rays/s beside DRAM's (the roofline).
    #[arg(long)]
    pub estimate: Option<PathBuf>,
    /// Output folder (default reports/memory-<UTC timestamp>/). Its memory files, if any, are
    /// refused unless --force; other files there are left alone.
    #[arg(long)]
    pub out: Option<PathBuf>,
    /// Replace the memory files in --out.
    #[arg(long)]
    pub force: bool,
}

#[derive(clap::Args)]
pub struct IsaModelArgs {
    /// A model under its drm-shim (this process has its environment) or an AMD family.
    #[arg(long)]
    pub model: String,
    /// layouts (isa --quick), cover, default or full (`variant::Matrix`).
    #[arg(long, default_value = "default")]
    pub matrix: String,
    #[arg(long, value_delimiter = ',')]
    pub layouts: Vec<crate::layout::LayoutId>,
    #[arg(long)]
    pub validation: bool,
    /// Write the representations under this folder.
    #[arg(long)]
    pub disasm: Option<PathBuf>,
}

#[derive(clap::Args)]
pub struct IsaArgs {
    /// GPU families and models, comma-separated. AMD through RADV's null devices (e.g.
    /// navi31,navi21,vega10); other vendors through Mesa's drm-shims, once
    /// scripts/install-compilers.sh has built them: a618,a660,a740,a750 (Qualcomm Adreno),
    /// g52,g610 (Arm Mali), tgl,dg2,mtl,lnl,bmg (Intel), tu102,ga102 (NVIDIA),
    /// v3d-42,v3d-71 (Broadcom). `vendors`: every model of the other vendors; `all`: every AMD
    /// family the installed RADV knows and every model. Default, without --device: polaris10,
    /// vega10, navi10, navi21, navi31, gfx1201 (GCN4 to RDNA4).
    #[arg(long, value_delimiter = ',')]
    pub family: Vec<String>,
    /// A Vulkan device (index or name substring) whose driver exposes
    /// VK_KHR_pipeline_executable_properties; repeat for several.
    #[arg(long)]
    pub device: Vec<String>,
    /// Layouts beside f32, comma-separated (default: every layout).
    #[arg(long, value_delimiter = ',')]
    pub layouts: Vec<crate::layout::LayoutId>,
    /// Every layout and math at B = 4, P = 1 only.
    #[arg(long, conflicts_with = "full")]
    pub quick: bool,
    /// Every layout, math, B and P, every packet implementation, float controls on and off.
    #[arg(long)]
    pub full: bool,
    /// Output folder (default reports/isa-<UTC timestamp>/). Its isa.* files, if any, are
    /// refused unless --force; other files there are left alone (a sweep folder may hold both).
    #[arg(long)]
    pub out: Option<PathBuf>,
    /// Replace the isa files in --out.
    #[arg(long)]
    pub force: bool,
    /// Also write each kernel's internal representations (NIR, ACO IR, disassembly) under
    /// disasm/<family>/.
    #[arg(long)]
    pub disasm: bool,
    /// Run under the Khronos validation layer; any message fails the run.
    #[arg(long)]
    pub validation: bool,
    /// No line per kernel.
    #[arg(long)]
    pub quiet: bool,
}

#[derive(clap::Args)]
pub struct BenchArgs {
    /// Scenes (OBJ, glTF or PLY); repeat the flag. Default: the bundled teapot, and
    /// sponza_dabrovic (a large interior) and igea (a 270k-triangle scan) from the test scenes
    /// (`tests/scenes`, else `../shared/scenes`) when they are there.
    #[arg(long)]
    pub scene: Vec<PathBuf>,
    /// Ray kinds, comma-separated: primary, ao, diffuse, grazing.
    #[arg(long, default_value = "primary,ao,diffuse", value_delimiter = ',')]
    pub rays: Vec<RayKind>,
    /// Reduced-precision layouts to time beside f32, comma-separated (default: every
    /// conservative one) — for a quicker check of one layout's change.
    #[arg(long, value_delimiter = ',')]
    pub layouts: Vec<LayoutArg>,
    #[arg(long, default_value_t = 256)]
    pub width: u32,
    #[arg(long, default_value_t = 256)]
    pub height: u32,
    /// Branching factors of the P = 1 kernels, comma-separated: 2, 4, 8, 16 (the fixed ratios
    /// are at B = 8; f16h ÷ f32 is reported at each other one).
    #[arg(long, default_value = "4,8", value_delimiter = ',')]
    pub branchings: Vec<usize>,
    /// Interleaved rounds (every target once per round).
    #[arg(long, default_value_t = 5)]
    pub rounds: usize,
    /// Timed dispatches per target and round (after one warm-up).
    #[arg(long, default_value_t = 5)]
    pub repeat: usize,
    /// Vulkan device (index or name substring).
    #[arg(long)]
    pub device: Option<String>,
    /// Enable the Khronos validation layer.
    #[arg(long)]
    pub validation: bool,
    /// Also write the report (Markdown) to this file.
    #[arg(long)]
    pub out: Option<PathBuf>,
}

#[derive(clap::Args)]
pub struct DeviceReportArgs {
    /// Vulkan device: index or name substring (default: the device every command picks).
    #[arg(long)]
    pub device: Option<String>,
    /// Wall time for the whole report (seconds, or e.g. 90s, 8m, 1h): the fixed steps run whole,
    /// the sweep gets what remains (at least one job).
    #[arg(long, default_value = "8m", value_parser = |s: &str| crate::units::parse_duration("--budget", s))]
    pub budget: f64,
    /// Output folder (default REPORTS/<device name>). One that holds files is refused unless
    /// --resume or --force.
    #[arg(long)]
    pub out: Option<PathBuf>,
    /// The folder the default --out is made in.
    #[arg(long, default_value = "reports", conflicts_with = "out")]
    pub reports: PathBuf,
    /// Scenes: the first (default: the bundled scene) gets conformance, the bench and the
    /// default matrix; the others are swept after it while the budget lasts. On a GPU the first
    /// is also swept instanced to at least 300k triangles, right after it.
    #[arg(long)]
    pub scene: Vec<PathBuf>,
    /// Also sweep every .obj / .obj.gz scene in this folder, after --scene (default:
    /// tests/scenes, the repository's test scenes, when run from the repository root, else
    /// ../shared/scenes when it exists; "none" for none).
    #[arg(long)]
    pub scenes_dir: Option<PathBuf>,
    /// Image size of the bench's and the sweep's rays (default 256 × 256 on a CPU device such
    /// as lavapipe, 1024 × 1024 on a GPU).
    #[arg(long)]
    pub width: Option<u32>,
    #[arg(long)]
    pub height: Option<u32>,
    /// Finish the report in --out: run only the steps that did not finish (the sweep resumes);
    /// a folder with no report yet gets a new one.
    #[arg(long)]
    pub resume: bool,
    /// Replace the report's own files in --out (other files there are left alone).
    #[arg(long)]
    pub force: bool,
    /// Treat a device feature as missing in every step (testing).
    #[arg(long, hide = true)]
    pub mask_feature: Vec<String>,
}
