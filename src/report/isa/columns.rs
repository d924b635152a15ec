//! Columns that mean the same on every vendor, filled from each driver's own statistics (its
//! names kept in [`IsaRow::stats`]): registers per thread, private memory per thread, spill
//! instructions, occupancy, instructions and the compiler's cycle estimate. A *thread* is one
//! invocation: a lane of an AMD wave, an Adreno fiber, an Intel work-item (a channel of a SIMD
//! thread), an NVIDIA thread, a Mali or VideoCore thread. [`COLUMN_NAMES`] says where each
//! column comes from, per vendor (docs/vendors.md prints it).

use super::IsaRow;

/// Vendors in table order.
pub const VENDORS: [&str; 6] = ["AMD", "Qualcomm", "Arm", "Intel", "NVIDIA", "Broadcom"];

/// The vendor a driver compiles for, from the driver name the device reports ("radv …",
/// "turnip Mesa driver …").
pub fn vendor_of(driver: &str) -> &'static str {
    let d = driver.to_lowercase();
    if d.contains("radv") || d.contains("amd") {
        "AMD"
    } else if d.contains("turnip") {
        "Qualcomm"
    } else if d.contains("panvk") {
        "Arm"
    } else if d.contains("intel") || d.contains("anv") {
        "Intel"
    } else if d.contains("nvk") || d.contains("nvidia") {
        "NVIDIA"
    } else if d.contains("v3dv") {
        "Broadcom"
    } else {
        ""
    }
}

/// Each vendor-neutral column and, per vendor of [`VENDORS`], the statistic it comes from.
pub const COLUMN_NAMES: &[(&str, [&str; 6])] = &[
    (
        "registers per thread (32-bit)",
        [
            "VGPRs",
            "Registers used × 4 (vec4 registers)",
            "– (not reported)",
            "Max live registers × 32 B ÷ (4 B × Max dispatch width)",
            "Number of GPRs",
            "max-temps (shaderdb: temporaries live at once)",
        ],
    ),
    (
        "private memory per thread, bytes",
        [
            "Scratch size ÷ wave size",
            "–",
            "–",
            "Scratch Memory Size ÷ Max dispatch width",
            "SLM Size",
            "Spill Size ÷ 16 (channels of a QPU thread)",
        ],
    ),
    (
        "spill and fill instructions",
        [
            "scratch_load + scratch_store (disassembly, GFX9+)",
            "LDP Count + STP Count (private loads and stores)",
            "spills + fills (shaderdb)",
            "Spill Count + Fill Count",
            "ld.local + st.local (disassembly)",
            "spills + fills (shaderdb; TMU Spills and Fills repeat Spill Size in Mesa 25.0.7)",
        ],
    ),
    (
        "occupancy",
        [
            "Subgroups per SIMD (waves/SIMD)",
            "Max Waves Per Core (waves/core)",
            "threads (shaderdb: 1 at more than 32 registers)",
            "– (not reported)",
            "warps/SM from Number of GPRs (CUDA's occupancy rule; an estimate)",
            "Thread Count (QPU threads: 4, 2 or 1)",
        ],
    ),
    (
        "instructions",
        [
            "Instructions",
            "Instruction Count",
            "inst (shaderdb)",
            "Instruction Count",
            "Instruction count",
            "Instruction Count",
        ],
    ),
    (
        "the compiler's cycle estimate",
        [
            "Latency (ACO: issue + stall cycles, loops ×8)",
            "–",
            "cycles (shaderdb: normalized cycles, the busiest unit)",
            "Cycle Count (loops weighted)",
            "–",
            "–",
        ],
    ),
];

/// [`COLUMN_NAMES`] as a Markdown table (docs/vendors.md holds it; a test keeps them equal).
#[cfg(test)]
pub fn column_table() -> String {
    let mut md = format!("| column | {} |\n|---|{}\n", VENDORS.join(" | "), "---|".repeat(VENDORS.len()));
    for (col, names) in COLUMN_NAMES {
        md += &format!("| {col} | {} |\n", names.join(" | "));
    }
    md
}

/// Warps an NVIDIA SM holds at `gprs` registers per thread: 64 K registers per SM, allocated
/// per warp in units of 256 (8 per thread), at most `max_warps` (32 on Turing, 48 on Ampere's
/// GA10x and Ada). CUDA's occupancy rule, so an estimate: the driver reports only GPRs.
fn nvidia_warps(gprs: f64, max_warps: f64) -> f64 {
    let per_thread = (gprs / 8.0).ceil().max(1.0) * 8.0;
    (65536.0 / (per_thread * 32.0)).floor().min(max_warps)
}

impl IsaRow {
    /// Fills the vendor-neutral columns from the driver's statistics (and, where the driver
    /// has none, from the disassembly counts).
    pub(super) fn normalize(&mut self) {
        let get = |n: &str| self.stats.get(n).copied();
        self.vendor = vendor_of(&self.driver).to_string();
        let (mut reg, mut private, mut spills, mut occ, mut unit, mut inst, mut cyc) =
            (None, None, None, None, "", self.instructions, None);
        let sum = |a: Option<f64>, b: Option<f64>| a.zip(b).map(|(a, b)| a + b);
        match self.vendor.as_str() {
            "AMD" => {
                reg = self.vgprs;
                private = self.scratch_bytes.map(|b| b / self.subgroup_size.max(1) as f64);
                spills = self.asm.and_then(|a| a.scratch_loads.zip(a.scratch_stores)).map(|(l, s)| (l + s) as f64);
                occ = self.waves_per_simd;
                unit = "waves/SIMD";
                cyc = get("Latency");
            }
            "Qualcomm" => {
                reg = get("Registers used").map(|r| 4.0 * r);
                spills = sum(get("LDP Count"), get("STP Count"));
                occ = get("Max Waves Per Core");
                unit = "waves/core";
                inst = get("Instruction Count");
            }
            "Arm" => {
                spills = sum(get("shaderdb: spills"), get("shaderdb: fills"));
                occ = get("shaderdb: threads");
                unit = "threads";
                inst = get("shaderdb: inst");
                cyc = get("shaderdb: cycles");
            }
            "Intel" => {
                let width = get("Max dispatch width");
                reg = get("Max live registers").zip(width).map(|(r, w)| r * 32.0 / (4.0 * w));
                private = get("Scratch Memory Size").zip(width).map(|(b, w)| b / w);
                spills = sum(get("Spill Count"), get("Fill Count"));
                inst = get("Instruction Count");
                cyc = get("Cycle Count");
            }
            "NVIDIA" => {
                reg = get("Number of GPRs");
                private = get("SLM Size");
                spills = self.asm.and_then(|a| a.scratch_loads.zip(a.scratch_stores)).map(|(l, s)| (l + s) as f64);
                let max_warps = if self.generation.contains("Turing") { 32.0 } else { 48.0 };
                occ = reg.map(|g| nvidia_warps(g, max_warps));
                unit = "warps/SM";
                inst = get("Instruction count");
            }
            "Broadcom" => {
                // The spill buffer of a QPU thread covers its 16 channels (spills and the
                // private arrays alike). Mesa 25.0.7's "TMU Spills" and "TMU Fills" repeat
                // "Spill Size": the counts come from the compiler's shaderdb line.
                reg = get("shaderdb: max-temps");
                private = get("Spill Size").map(|b| b / 16.0);
                spills = sum(get("shaderdb: spills"), get("shaderdb: fills"));
                occ = get("Thread Count");
                unit = "threads/QPU";
                inst = get("Instruction Count");
            }
            _ => {}
        }
        (self.registers, self.private_bytes, self.spills, self.occupancy) = (reg, private, spills, occ);
        self.occupancy_unit = unit.to_string();
        (self.instructions, self.cycles) = (inst, cyc);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn nvidia_occupancy_follows_cuda_rule() {
        // 32 registers: 2 K registers per warp, 32 warps; 128: 8; 255: 8 (256 allocated).
        assert_eq!(nvidia_warps(32.0, 48.0), 48.0);
        assert_eq!(nvidia_warps(64.0, 48.0), 32.0);
        assert_eq!(nvidia_warps(128.0, 48.0), 16.0);
        assert_eq!(nvidia_warps(141.0, 48.0), 14.0);
        assert_eq!(nvidia_warps(24.0, 32.0), 32.0);
    }

    #[test]
    fn docs_hold_the_column_table() {
        let doc = std::fs::read_to_string(concat!(env!("CARGO_MANIFEST_DIR"), "/docs/vendors.md")).unwrap();
        let want = column_table();
        assert!(doc.contains(&want), "docs/vendors.md must hold the column table as the code has it:\n{want}");
    }

    #[test]
    fn every_vendor_named_once_per_column() {
        for (col, names) in COLUMN_NAMES {
            assert_eq!(names.len(), VENDORS.len(), "{col}");
        }
        assert_eq!(vendor_of("turnip Mesa driver Mesa 25.0.7"), "Qualcomm");
        assert_eq!(vendor_of("radv Mesa 25.0.7"), "AMD");
        assert_eq!(vendor_of("NVK Mesa 25.0.7"), "NVIDIA");
    }
}
