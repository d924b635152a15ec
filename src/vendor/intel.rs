//! Intel: anv under the intel drm-shim.

use super::{model, Disassembly, Input, Neutral, Quirks, Shim, Stats, Vendor};
use ash::vk;

pub static INTEL: Vendor = Vendor {
    name: "Intel",
    driver_ids: &[vk::DriverId::INTEL_OPEN_SOURCE_MESA, vk::DriverId::INTEL_PROPRIETARY_WINDOWS],
    driver_names: &["intel", "anv"],
    shim: Some(Shim { kernel: "intel", icd: "intel.json", driver: "anv", summary_env: &[] }),
    models: &[
        model("tgl", "Intel Tiger Lake", "Xe-LP (Gen12)", &[("INTEL_STUB_GPU_PLATFORM", "tgl")]),
        model("dg2", "Intel Arc A-series (DG2)", "Xe-HPG", &[("INTEL_STUB_GPU_PLATFORM", "dg2")]),
        model("mtl", "Intel Meteor Lake", "Xe-LPG", &[("INTEL_STUB_GPU_PLATFORM", "mtl")]),
        model("lnl", "Intel Lunar Lake", "Xe2", &[("INTEL_STUB_GPU_PLATFORM", "lnl")]),
        model("bmg", "Intel Arc B-series (Battlemage)", "Xe2", &[("INTEL_STUB_GPU_PLATFORM", "bmg")]),
    ],
    stats: Stats::Own,
    sources: [
        "Max live registers × 32 B ÷ (4 B × Max dispatch width)",
        "Scratch Memory Size ÷ Max dispatch width",
        "Spill Count + Fill Count",
        "– (not reported)",
        "Instruction Count",
        "Cycle Count (loops weighted)",
    ],
    neutral,
    disassembly: Some(Disassembly::Intel),
    occupancy: None,
    cycles: "`Cycle Count` (`INTEL_DEBUG=cs`): one SIMD thread's issue and dependency cycles, each loop's body \
             weighted ×10 per nesting level, branches unweighted",
    // The next child's entry stays in registers: in shared memory it costs registers on
    // Intel's compiler (lnl f16h fp16 B = 4: 103 -> 110, and more spills at B = 16).
    quirks: Quirks { register_array_bytes: 0, pending_shared: false },
};

fn neutral(s: &Input) -> Neutral {
    let width = s.get("Max dispatch width");
    Neutral {
        registers: s.get("Max live registers").zip(width).map(|(r, w)| r * 32.0 / (4.0 * w)),
        private_bytes: s.get("Scratch Memory Size").zip(width).map(|(b, w)| b / w),
        spills: s.sum("Spill Count", "Fill Count"),
        occupancy: None,
        instructions: s.get("Instruction Count"),
        cycles: s.get("Cycle Count"),
    }
}
