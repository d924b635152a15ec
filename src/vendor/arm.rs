//! Arm Mali: panvk under the panfrost drm-shim. Its statistics report only the code size: the
//! columns come from the compiler's shaderdb line (`BIFROST_MESA_DEBUG=shaderdb`).

use super::{model, Disassembly, Input, Neutral, Occupancy, Shim, Stats, Vendor, GPU_DEFAULT};
use ash::vk;

pub static ARM: Vendor = Vendor {
    name: "Arm",
    driver_ids: &[vk::DriverId::MESA_PANVK, vk::DriverId::ARM_PROPRIETARY],
    driver_names: &["panvk"],
    shim: Some(Shim {
        kernel: "panfrost",
        icd: "panfrost.json",
        driver: "panvk",
        summary_env: &[("BIFROST_MESA_DEBUG", "shaderdb")],
    }),
    models: &[
        // panvk calls Bifrost v7 untested and opens it only when asked to.
        model(
            "g52",
            "Mali-G52",
            "Bifrost (v7)",
            &[("PAN_GPU_ID", "7212"), ("PAN_I_WANT_A_BROKEN_VULKAN_DRIVER", "1")],
        ),
        model("g610", "Mali-G610", "Valhall (v10)", &[("PAN_GPU_ID", "a867")]),
    ],
    stats: Stats::Own,
    sources: [
        "– (not reported)",
        "–",
        "spills + fills (shaderdb)",
        "threads (shaderdb: 1 at more than 32 registers)",
        "inst (shaderdb)",
        "cycles (shaderdb: normalized cycles, the busiest unit)",
    ],
    neutral,
    disassembly: Some(Disassembly::Mali),
    occupancy: Some(Occupancy { unit: "threads", words: "threads", note: "Mali; 1: more than 32 registers" }),
    cycles: "normalized cycles (`BIFROST_MESA_DEBUG=shaderdb`): the busiest functional unit's cycles, every \
             instruction counted once (loops not weighted)",
    quirks: GPU_DEFAULT,
};

fn neutral(s: &Input) -> Neutral {
    Neutral {
        registers: None,
        private_bytes: None,
        spills: s.sum("shaderdb: spills", "shaderdb: fills"),
        occupancy: s.get("shaderdb: threads"),
        instructions: s.get("shaderdb: inst"),
        cycles: s.get("shaderdb: cycles"),
    }
}
