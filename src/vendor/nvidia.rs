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
        "SLM Size (Mesa 26: SLM size)",
        "ld.local + st.local (disassembly)",
        "Max warps/SM (Mesa 26), else warps/SM from Number of GPRs (CUDA's occupancy rule; an estimate)",
        "Instruction count",
        "Static cycle count (Mesa 26; NAK's static estimate)",
    ],
    neutral,
    disassembly: Some(Disassembly::Nak),
    occupancy: Some(Occupancy { unit: "warps/SM", words: "warps per SM", note: "NVIDIA, estimated from the registers" }),
    cycles: "`Static cycle count` (Mesa 26's NVK): NAK's static estimate of one warp's cycles, its assumptions about \
             loops not documented by NVK; Mesa 25's NVK gives none",
    quirks: GPU_DEFAULT,
};

/// Mesa 25's NVK and Mesa 26's: 26 renamed `SLM Size` to `SLM size` and reports its own
/// occupancy (`Max warps/SM`) and a static cycle estimate.
fn neutral(s: &Input) -> Neutral {
    let registers = s.get("Number of GPRs");
    let max_warps = if s.generation.contains("Turing") { 32.0 } else { 48.0 };
    Neutral {
        registers,
        private_bytes: s.get("SLM Size").or_else(|| s.get("SLM size")),
        spills: s.private_ops(),
        occupancy: s.get("Max warps/SM").or_else(|| registers.map(|g| warps(g, max_warps))),
        instructions: s.get("Instruction count"),
        cycles: s.get("Static cycle count"),
    }
}

/// Hopper's most warps per SM (GA10x and Ada: 48, Turing: 32).
pub const HOPPER_MAX_WARPS: f64 = 64.0;

/// Warps an NVIDIA SM holds at `gprs` registers per thread: 64 K registers per SM, allocated
/// per warp in units of 256 (8 per thread), at most `max_warps` (32 on Turing, 48 on Ampere's
/// GA10x and Ada, 64 on Hopper). CUDA's occupancy rule, so an estimate: the driver reports
/// only GPRs.
pub fn warps(gprs: f64, max_warps: f64) -> f64 {
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
