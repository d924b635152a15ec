//! Broadcom VideoCore: v3dv under the v3d drm-shim (with halftrace's shim patch for
//! `V3D_GPU_ID`, scripts/install-compilers.sh).

use super::{model, Input, Neutral, Occupancy, Shim, Stats, Vendor, GPU_DEFAULT};
use ash::vk;

pub static BROADCOM: Vendor = Vendor {
    name: "Broadcom",
    driver_ids: &[vk::DriverId::MESA_V3DV, vk::DriverId::BROADCOM_PROPRIETARY],
    driver_names: &["v3dv"],
    shim: Some(Shim {
        kernel: "v3d",
        icd: "broadcom.json",
        driver: "v3dv",
        summary_env: &[("V3D_DEBUG", "shaderdb")],
    }),
    models: &[
        model("v3d-42", "VideoCore VI (V3D 4.2)", "V3D 4.2 (Raspberry Pi 4)", &[("V3D_GPU_ID", "42")]),
        model("v3d-71", "VideoCore VII (V3D 7.1)", "V3D 7.1 (Raspberry Pi 5)", &[("V3D_GPU_ID", "71")]),
    ],
    stats: Stats::Own,
    sources: [
        "max-temps (shaderdb: temporaries live at once)",
        "Spill Size ÷ 16 (channels of a QPU thread)",
        "spills + fills (shaderdb; TMU Spills and Fills repeat Spill Size in Mesa 25.0.7)",
        "Thread Count (QPU threads: 4, 2 or 1)",
        "Instruction Count",
        "–",
    ],
    neutral,
    disassembly: None,
    occupancy: Some(Occupancy { unit: "threads/QPU", words: "QPU threads", note: "VideoCore" }),
    cycles: "no cycle estimate from this driver",
    quirks: GPU_DEFAULT,
};

/// The spill buffer of a QPU thread covers its 16 channels (spills and the private arrays
/// alike). Mesa 25.0.7's "TMU Spills" and "TMU Fills" repeat "Spill Size": the counts come
/// from the compiler's shaderdb line.
fn neutral(s: &Input) -> Neutral {
    Neutral {
        registers: s.get("shaderdb: max-temps"),
        private_bytes: s.get("Spill Size").map(|b| b / 16.0),
        spills: s.sum("shaderdb: spills", "shaderdb: fills"),
        occupancy: s.get("Thread Count"),
        instructions: s.get("Instruction Count"),
        cycles: None,
    }
}
