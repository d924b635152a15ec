//! The command line, one file per subcommand: each `commands/<name>.rs` owns its arguments
//! (clap) beside its `run`: arguments in, lines on stdout and files out (cargo's
//! `src/bin/cargo/commands/` is the model). This file holds the list of subcommands and their
//! dispatch; `main.rs` only parses and reports an error. A new command: its file, one line in
//! [`Cmd`], one in [`Cmd::run`].

use crate::baseline::BaselineId;
use crate::layout::LayoutId;
use clap::{Parser, Subcommand};

mod bench;
mod bvh_stats;
mod conformance;
mod device_report;
mod devices;
mod estimate;
mod instance;
mod isa;
mod memory;
mod report;
mod shaders;
mod sweep;
mod trace;

#[derive(Parser, Debug)]
#[command(name = "halftrace", version, about = "Half-precision hierarchical BVH traversal harness")]
pub struct Cli {
    #[command(subcommand)]
    pub cmd: Cmd,
}

#[derive(Subcommand, Clone, Debug, PartialEq)]
pub enum Cmd {
    /// Trace a ray set through one layout and branching factor.
    Trace(trace::TraceArgs),
    /// Write a glTF binary (.glb) that instances a scene N times (rotated, scaled, on a grid):
    /// big test scenes without shipping them.
    Instance(instance::InstanceArgs),
    /// Print per-B, per-layout BVH statistics.
    BvhStats(bvh_stats::BvhStatsArgs),
    /// List Vulkan devices, what each runs of every layout and packet size, and why the rest
    /// would be skipped.
    Devices(devices::DevicesArgs),
    /// Sweep scenes × ray kinds × layouts × B × P: validate, time, count, report.
    Sweep(sweep::SweepArgs),
    /// The speed ratios a kernel change is judged by (f16h ÷ f32, best reduced layout ÷ f32,
    /// best ÷ embree, packets ÷ P = 1, f32 ÷ rq, f32 ÷ rt), validated, then timed in
    /// interleaved rounds: medians with min/max.
    Bench(bench::BenchArgs),
    /// Re-render report.md and the plots from one or more sweep folders (merging them).
    Report(report::ReportArgs),
    /// Check every variant on a device against the CPU references (what to run first on a new
    /// GPU): writes conformance.md and conformance.csv, exits non-zero on any failure.
    Conformance(conformance::ConformanceArgs),
    /// A device's whole report in one command sized to a wall-time budget: devices,
    /// conformance --quick, a short bench, a sweep in the time that remains, isa where the
    /// driver reports pipeline statistics; one folder named after the device, resumable.
    DeviceReport(device_report::DeviceReportArgs),
    /// The compiler's view: build each kernel on RADV null devices (AMD's shader compiler for a
    /// GPU family, no GPU needed) or on a device whose driver reports pipeline statistics, and
    /// write registers, scratch, occupancy and the fp16 instruction mix per kernel (isa.md,
    /// isa.csv, isa.json, plots). Nothing runs.
    Isa(isa::IsaArgs),
    /// Estimated cycles per ray on AMD GPUs we do not have: ACO's cycle estimate (Latency) of
    /// each kernel taken apart per loop on RADV null devices (checked to rebuild it exactly),
    /// its loops' trips taken from real rays in lockstep waves (estimate.md, estimate.csv,
    /// estimate-rays.csv). The compiler's model, not a measurement; nothing runs.
    Estimate(estimate::EstimateArgs),
    /// The memory side of a ray on GPU models: bytes each kernel requests per ray (nodes,
    /// triangles, ids, stack), the distinct cache lines per ray and per lockstep wave, and a
    /// cache model of each GPU (an L1 per unit, the L2, a last-level cache, DRAM) fed by the
    /// waves it runs at once: bytes and hit rates at each level, DRAM bytes, energy and the
    /// DRAM-bound rays/s per ray, every layout ÷ f32, one verdict per GPU (memory.md,
    /// memory.csv, memory.json). From the CPU reference's exact walk; nothing runs on a GPU.
    Memory(memory::MemoryArgs),
    /// Print the RADV null devices listed with RADV_FORCE_FAMILY as set (how `isa` and `devices`
    /// learn which families the installed RADV knows: RADV aborts on the others).
    #[command(hide = true)]
    ProbeFamily,
    /// Build the isa matrix on the one model whose drm-shim environment this process was
    /// started with, printing one JSON row per kernel (how `isa` reads another vendor's
    /// compiler: one driver and model per process).
    #[command(hide = true)]
    IsaModel(isa::IsaModelArgs),
    /// Compile the default variant matrix and write one SPIR-V file per kernel.
    Shaders(shaders::ShadersArgs),
}

impl Cmd {
    /// Runs the subcommand.
    pub fn run(&self) -> anyhow::Result<()> {
        match self {
            Cmd::Trace(a) => trace::trace(a),
            Cmd::BvhStats(a) => bvh_stats::bvh_stats(a),
            Cmd::Instance(a) => instance::instance(a),
            Cmd::Devices(a) => devices::devices(a),
            Cmd::Conformance(a) => conformance::conformance(a),
            Cmd::Isa(a) => isa::isa(a),
            Cmd::Estimate(a) => estimate::estimate(a),
            Cmd::Memory(a) => memory::memory(a),
            Cmd::DeviceReport(a) => device_report::device_report(a),
            Cmd::ProbeFamily => isa::probe_family(),
            Cmd::IsaModel(a) => isa::isa_model(a),
            Cmd::Shaders(a) => shaders::shaders(a),
            Cmd::Sweep(a) => sweep::sweep(a),
            Cmd::Bench(a) => bench::bench(a),
            Cmd::Report(a) => report::report(a),
        }
    }
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

impl std::fmt::Display for LayoutArg {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            LayoutArg::Layout(l) => write!(f, "{l}"),
            LayoutArg::Baseline(b) => write!(f, "{b}"),
        }
    }
}

/// A command's arguments as its defaults make them (every flag left out): where halftrace
/// builds a child's command from typed arguments, the fields it sets go over these.
pub(crate) fn defaults<A: clap::Args + clap::FromArgMatches>(name: &'static str) -> A {
    let m = A::augment_args(clap::Command::new(name)).try_get_matches_from([name]);
    // Every command halftrace runs itself takes no required argument: a test builds each.
    A::from_arg_matches(&m.expect("no required argument")).expect("its own matches")
}

/// Writes a line to stdout, returning I/O errors (a closed pipe ends the command quietly).
macro_rules! outln {
    ($($t:tt)*) => { { use std::io::Write as _; writeln!(std::io::stdout(), $($t)*)? } };
}
pub(crate) use outln;
