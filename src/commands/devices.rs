//! `halftrace devices`: every Vulkan device, what it can do, and what halftrace runs on it.

use super::outln;
use crate::argv::Argv;
use crate::baseline::BaselineId;
use crate::gpu::{self, DeviceInfo};
use crate::layout::LayoutId;
use crate::precision::FcChoice;
use crate::variant::{Matrix, PacketImpl, PACKETS};

#[derive(clap::Args, Clone, Debug, PartialEq)]
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

impl DevicesArgs {
    /// This command's line, every argument as set.
    pub fn argv(&self) -> Argv {
        Argv::new("devices")
            .flag("arith", self.arith)
            .opt("device", self.device.as_ref())
            .each("mask-feature", &self.mask_feature)
    }
}

pub fn devices(a: &DevicesArgs) -> anyhow::Result<()> {
    let mut list = gpu::list_devices()?;
    if list.is_empty() {
        outln!("no Vulkan devices");
    }
    if let Some(want) = &a.device {
        // The same choice --device makes everywhere (gpu::pick).
        let all: Vec<String> = list.iter().map(|d| format!("{}: {}", d.index, d.name)).collect();
        let i = gpu::pick(&list, Some(want))
            .map_err(|_| anyhow::anyhow!("--device {want}: no such device (found: {})", all.join("; ")))?;
        list = vec![list.swap_remove(i)];
    }
    for d in &mut list {
        for m in &a.mask_feature {
            d.mask(m).map_err(anyhow::Error::msg)?;
        }
        outln!("{}: {} ({}), Vulkan {}, driver {}", d.index, d.name, d.kind, d.api_version, d.driver);
        outln!(
            "   shaderFloat16 {}, storageBuffer16BitAccess {}, shaderFloat64 {}, subgroup size {}, ray query {}, \
             ray-tracing pipeline {}, max storage buffer {} MiB",
            d.shader_float16,
            d.storage_16bit,
            d.shader_float64,
            d.subgroup_size,
            d.ray_query,
            d.ray_tracing_pipeline,
            d.max_storage_buffer >> 20
        );
        let control = if d.subgroup_size_control {
            format!("{}..{}", d.min_subgroup_size, d.max_subgroup_size)
        } else {
            "no".into()
        };
        outln!(
            "   float controls: RTE fp16 {}, RTE fp32 {}, inf/NaN preserve fp16 {}, fp32 {}; subgroup size control {control}",
            d.fp16_rte,
            d.fp32_rte,
            d.preserve_16,
            d.preserve_32
        );
        outln!(
            "   pipeline statistics (VK_KHR_pipeline_executable_properties, for `isa`): {}",
            if d.pipeline_statistics { "yes" } else { "no" }
        );
        if d.compile_only {
            let what = match crate::gpu::shim() {
                Some(s) if !d.driver.to_lowercase().contains("radv") => {
                    format!("a driver under Mesa's drm-shim (lib{s}_noop_drm_shim.so)")
                }
                _ => "RADV's null device (RADV_FORCE_FAMILY)".to_string(),
            };
            outln!(
                "   COMPILE ONLY: {what} builds pipelines with the vendor's compiler but runs nothing; trace, sweep, \
                 bench and conformance refuse it — `halftrace isa --device {}` (or `isa --family <model>`) reads its \
                 compiler's statistics",
                d.index
            );
        }
        for line in plan(d) {
            outln!("   {}", if d.compile_only { line.replace("runs", "builds") } else { line });
        }
    }
    let known = crate::isa::known_families(&std::env::current_exe()?, None)?;
    if known.is_empty() {
        outln!("\nRADV null devices (isa --family): none open here (RADV is Debian's mesa-vulkan-drivers)");
    } else {
        let names: Vec<String> = known.iter().map(|f| format!("{} ({})", f.name, f.generation)).collect();
        outln!(
            "\nRADV null devices (`halftrace isa --family F`, AMD's compiler without the GPU): {}",
            names.join(", ")
        );
    }
    outln!("\nlayouts and baselines (--layout):");
    for l in LayoutId::all() {
        let maths: Vec<&str> = l.info().maths.iter().map(|m| m.name()).collect();
        outln!("  {:<11} {} (layout; math: {})", l.name(), l.info().summary, maths.join(", "));
    }
    for b in BaselineId::all() {
        outln!("  {:<11} {} (baseline)", b.name(), b.imp().summary());
    }
    if a.arith {
        let g = gpu::Gpu::new(&gpu::ContextOptions { device: a.device.clone(), ..Default::default() })?;
        let r = gpu::arith::run(&g, 65536, 512, 5)?;
        outln!("\nraw arithmetic on {} ({}): G operations/s, median of 5", r.device, r.driver);
        outln!("{:<9} {:>10} {:>10} {:>12}", "op", "fp16", "fp32", "fp16:fp32");
        for o in &r.ops {
            outln!("{:<9} {:>10.2} {:>10.2} {:>12.3}", o.op, o.fp16_gops, o.fp32_gops, o.ratio);
        }
        match &r.fp16_unavailable {
            None => outln!("fp16:fp32 ratio (geometric mean): {:.3}", r.fp16_ratio),
            Some(why) => outln!("fp16 not measured: {why}"),
        }
    }
    Ok(())
}

/// What halftrace runs on a device: per layout and math mode the float controls (or why it is
/// skipped), per packet size the implementation, and the baselines.
fn plan(d: &DeviceInfo) -> Vec<String> {
    let mut out = Vec::new();
    // Every layout in every math at B = 4, P = 1: the matrix `isa --quick` builds.
    for k in crate::variant::matrix(Matrix::Layouts, &|_| vec![None]) {
        let v = k.variant;
        let what = match gpu::support::resolve(d, v, FcChoice::Auto) {
            Ok(r) => format!("runs, float controls {}", r.fc.name()),
            Err(why) => format!("skipped: {why}"),
        };
        out.push(format!("{:<11} math {:<6} {what}", v.layout.name(), v.math.name()));
    }
    let packets: Vec<String> = PACKETS
        .iter()
        .filter(|&&p| p > 1)
        .map(|&p| match gpu::support::packet_plan(d, p) {
            (PacketImpl::Subgroup, Some(n)) => format!("P={p} subgroup (pinned to {n})"),
            (PacketImpl::Subgroup, None) => format!("P={p} subgroup ({})", d.subgroup_size),
            (PacketImpl::Hybrid, _) if gpu::support::subgroup_holds(d, p) => format!(
                "P={p} hybrid (subgroups of {}, then shared memory; no clustered subgroup operations)",
                d.subgroup_size
            ),
            (PacketImpl::Hybrid, _) => format!("P={p} hybrid (subgroups of {}, then shared memory)", d.subgroup_size),
            (imp, _) => format!("P={p} {}", if imp == PacketImpl::Shared { "shared memory" } else { "single" }),
        })
        .collect();
    out.push(format!("packets: {}", packets.join(", ")));
    for b in BaselineId::all() {
        let what = b.imp().unavailable(d).map(|why| format!("skipped: {why}")).unwrap_or_else(|| "runs".into());
        out.push(format!("{:<11} {what}", b.name()));
    }
    out
}
