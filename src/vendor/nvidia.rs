//! NVIDIA: NVK under the nouveau drm-shim.

use super::{model, Disassembly, Input, Neutral, Occupancy, Shim, Stats, Vendor, GPU_DEFAULT};
use ash::vk;

pub static NVIDIA: Vendor = Vendor {
    name: "NVIDIA",
    driver_ids: &[vk::DriverId::MESA_NVK, vk::DriverId::NVIDIA_PROPRIETARY],
    driver_names: &["nvk", "nvidia"],
    shim: Some(Shim { kernel: "nouveau", icd: "nouveau.json", driver: "NVK", summary_env: &[] }),
    models: &[
        model("tu102", "NVIDIA TU102", "Turing", &[("NOUVEAU_CHIPSET", "162")]),
        model("ga102", "NVIDIA GA102", "Ampere", &[("NOUVEAU_CHIPSET", "172")]),
    ],
    stats: Stats::Own,
    sources: [
        "Number of GPRs",
        "SLM Size",
        "ld.local + st.local (disassembly)",
        "warps/SM from Number of GPRs (CUDA's occupancy rule; an estimate)",
        "Instruction count",
        "–",
    ],
    neutral,
    disassembly: Some(Disassembly::Nak),
    occupancy: Some(Occupancy { unit: "warps/SM", words: "warps per SM", note: "NVIDIA, estimated from the registers" }),
    cycles: "no cycle estimate from this driver",
    quirks: GPU_DEFAULT,
};

fn neutral(s: &Input) -> Neutral {
    let registers = s.get("Number of GPRs");
    let max_warps = if s.generation.contains("Turing") { 32.0 } else { 48.0 };
    Neutral {
        registers,
        private_bytes: s.get("SLM Size"),
        spills: s.private_ops(),
        occupancy: registers.map(|g| warps(g, max_warps)),
        instructions: s.get("Instruction count"),
        cycles: None,
    }
}

/// Warps an NVIDIA SM holds at `gprs` registers per thread: 64 K registers per SM, allocated
/// per warp in units of 256 (8 per thread), at most `max_warps` (32 on Turing, 48 on Ampere's
/// GA10x and Ada). CUDA's occupancy rule, so an estimate: the driver reports only GPRs.
fn warps(gprs: f64, max_warps: f64) -> f64 {
    let per_thread = (gprs / 8.0).ceil().max(1.0) * 8.0;
    (65536.0 / (per_thread * 32.0)).floor().min(max_warps)
}

#[cfg(test)]
mod tests {
    #[test]
    fn occupancy_follows_cuda_rule() {
        // 32 registers: 2 K registers per warp, 32 warps; 128: 8; 255: 8 (256 allocated).
        assert_eq!(super::warps(32.0, 48.0), 48.0);
        assert_eq!(super::warps(64.0, 48.0), 32.0);
        assert_eq!(super::warps(128.0, 48.0), 16.0);
        assert_eq!(super::warps(141.0, 48.0), 14.0);
        assert_eq!(super::warps(24.0, 32.0), 32.0);
    }
}
