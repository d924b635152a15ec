//! Qualcomm Adreno: turnip under the freedreno drm-shim.

use super::{model, Disassembly, Input, Neutral, Occupancy, Quirks, Shim, Stats, Vendor};
use ash::vk;

pub static QUALCOMM: Vendor = Vendor {
    name: "Qualcomm",
    driver_ids: &[vk::DriverId::MESA_TURNIP, vk::DriverId::QUALCOMM_PROPRIETARY],
    driver_names: &["turnip"],
    shim: Some(Shim { kernel: "freedreno", icd: "freedreno.json", driver: "turnip", summary_env: &[] }),
    models: &[
        model("a618", "Adreno 618", "Adreno 6xx", &[("FD_GPU_ID", "618")]),
        model("a660", "Adreno 660", "Adreno 6xx", &[("FD_GPU_ID", "660")]),
        model("a740", "Adreno 740", "Adreno 7xx", &[("FD_GPU_ID", "740")]),
        model("a750", "Adreno 750", "Adreno 7xx", &[("FD_GPU_ID", "750")]),
    ],
    stats: Stats::Own,
    sources: [
        "Registers used × 4 (vec4 registers)",
        "–",
        "LDP Count + STP Count (private loads and stores)",
        "Max Waves Per Core (waves/core)",
        "Instruction Count",
        "–",
    ],
    neutral,
    disassembly: Some(Disassembly::Ir3),
    occupancy: Some(Occupancy { unit: "waves/core", words: "waves per core", note: "Adreno" }),
    cycles: "no cycle estimate from this driver",
    // turnip keeps private arrays in registers, each field of an array of structs on its own:
    // on Mesa 25.0.7 every array of up to 256 bytes (a740: f16h's group stack at B = 4 needs
    // 192 registers with 64 groups, 128 with 65); on 26.2 arrays of up to 768 bytes, its 48
    // vec4 registers, while they fit beside each other (a740: f32's two 388-byte stack arrays,
    // one kept there, 192 registers and 4 waves; each allocated past 704 bytes, the same;
    // past 768, 76 and 10). The stacks are allocated past 768, which serves both releases.
    quirks: Quirks { register_array_bytes: 768, pending_shared: true },
};

fn neutral(s: &Input) -> Neutral {
    Neutral {
        registers: s.get("Registers used").map(|r| 4.0 * r),
        private_bytes: None,
        spills: s.sum("LDP Count", "STP Count"),
        occupancy: s.get("Max Waves Per Core"),
        instructions: s.get("Instruction Count"),
        cycles: None,
    }
}
