//! Apple: Honeykrisp (Mesa's driver for Apple's AGX GPUs) under the asahi drm-shim — in Debian's
//! newest Mesa (`isa --compilers newest`), not in the pinned build. The shim fakes an M1 (G13G).

use super::{model, Input, Neutral, Occupancy, Quirks, Shim, Stats, Vendor, GPU_DEFAULT};
use ash::vk;

pub static APPLE: Vendor = Vendor {
    name: "Apple",
    // Honeykrisp's id (VK_DRIVER_ID_MESA_HONEYKRISP, ash's MESA_AGXV).
    driver_ids: &[vk::DriverId::MESA_AGXV],
    driver_names: &["honeykrisp", "agx"],
    shim: Some(Shim { kernel: "asahi", icd: "asahi.json", driver: "Honeykrisp", summary_env: &[] }),
    models: &[model("m1", "Apple M1", "G13G (AGX)", &[])],
    stats: Stats::Own,
    sources: [
        "GPRs ÷ 2 (16-bit registers)",
        "Scratch",
        "Spills + Fills (every stack_store and stack_load: the kernels' own stacks in scratch as well as register \
         spills)",
        "Threads (threads in flight)",
        "Instructions",
        "ALU (estimated ALU cycles; FSCIB and IC beside)",
    ],
    neutral,
    disassembly: None,
    occupancy: Some(Occupancy { unit: "threads", words: "threads in flight", note: "Apple" }),
    cycles: "`ALU` (Honeykrisp's statistics): the estimated ALU cycles of the whole shader (its `FSCIB` and `IC` \
             estimates beside in isa.csv), each instruction once as far as its statistics say",
    // Honeykrisp keeps private arrays of up to 256 bytes in registers, as turnip does (measured:
    // f16h's group stack allocated past 192 bytes a field array still filled the 255 16-bit
    // registers and spilled thousands; past 256 it takes 80 and spills 15).
    quirks: Quirks { register_array_bytes: 256, ..GPU_DEFAULT },
};

fn neutral(s: &Input) -> Neutral {
    Neutral {
        registers: s.get("GPRs").map(|g| g / 2.0),
        private_bytes: s.get("Scratch"),
        spills: s.sum("Spills", "Fills"),
        occupancy: s.get("Threads"),
        instructions: s.get("Instructions"),
        cycles: s.get("ALU"),
    }
}
