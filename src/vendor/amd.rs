//! AMD: RADV with ACO, AMD's production compiler, opened without the GPU as RADV's null device
//! for any family (`gpu::null` lists the families; Mesa 25 and before) or under the amdgpu
//! drm-shim, which fakes the family named in `AMDGPU_GPU_ID` (Mesa 26 removed the null device:
//! `isa --compilers newest`), or on the GPU itself.

use super::{Disassembly, Input, Neutral, Occupancy, Shim, Stats, Vendor, GPU_DEFAULT};
use ash::vk;

pub static AMD: Vendor = Vendor {
    name: "AMD",
    driver_ids: &[vk::DriverId::MESA_RADV, vk::DriverId::AMD_PROPRIETARY, vk::DriverId::AMD_OPEN_SOURCE],
    driver_names: &["radv", "amd"],
    // No models: the families are `gpu::null`'s, opened under this shim where a compilers
    // folder has it (`isa::shim::amd_shim`), else as RADV's null device.
    shim: Some(Shim { kernel: "amdgpu", icd: "radeon.json", driver: "radv", summary_env: &[] }),
    models: &[],
    stats: Stats::Aco,
    sources: [
        "VGPRs",
        "Scratch size ÷ wave size",
        "scratch_load + scratch_store (disassembly, GFX9+)",
        "Subgroups per SIMD (waves/SIMD)",
        "Instructions",
        "Latency (ACO: issue + stall cycles, loops ×8)",
    ],
    neutral,
    disassembly: Some(Disassembly::Aco),
    occupancy: Some(Occupancy { unit: "waves/SIMD", words: "waves per SIMD", note: "AMD" }),
    cycles: "`Latency` (`ACO_DEBUG=perfinfo`): issue and stall cycles of one wave, each loop's body weighted ×8",
    quirks: GPU_DEFAULT,
};

fn neutral(s: &Input) -> Neutral {
    Neutral {
        registers: s.get_any_case("VGPRs"),
        private_bytes: s.get_any_case("Scratch size").map(|b| b / s.subgroup_size.max(1) as f64),
        spills: s.private_ops(),
        occupancy: s.get_any_case("Subgroups per SIMD"),
        instructions: s.get_any_case("Instructions"),
        cycles: s.get("Latency"),
    }
}
