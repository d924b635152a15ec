//! The compiler's view (`halftrace isa`): one [`IsaRow`] per kernel × device — the statistics
//! the driver names, the instruction mix counted in its disassembly, each key figure as a
//! ratio to the f32 kernel of the same B, P and device — stored as `isa.json` and `isa.csv`,
//! rendered as tables ([`section`], in `isa.md` and in a merged `report.md`) and plots.

mod columns;
mod files;
mod releases;
mod tables;

pub use files::{read, write};
pub use releases::release;
pub use tables::{headline, plot, render, section};

use super::key::{f32_peer, What};
use super::rows::{order, Status};
use crate::vendor::VendorId;
use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;

/// One kernel built on one device.
#[derive(Clone, Debug, Default, Serialize, Deserialize, PartialEq)]
pub struct IsaRow {
    pub device: String,
    /// The RADV family of a null device (`navi31`) or the model a drm-shim fakes (`a740`,
    /// `g610`, `lnl`, `ga102`, `v3d-71`: `crate::vendor`), empty for a real device.
    pub family: String,
    /// The family's generation or architecture (GCN4, RDNA3, Adreno 7xx, Valhall, Xe2, …),
    /// empty when unknown.
    pub generation: String,
    /// The vendor whose compiler built it (`crate::vendor`, from the driver); written as its
    /// name.
    #[serde(default)]
    pub vendor: VendorId,
    pub driver: String,
    /// What the device's build of the kernels used: fp64 or its integer fallback, 16-bit
    /// storage or 32-bit words, the SPIR-V version, and where it differs from the GPU default
    /// the group stack's allocation or the next entry in registers (`variant::DeviceBuild`).
    #[serde(default)]
    pub device_build: String,
    pub version: String,
    pub commit: String,
    pub kernel: String,
    pub layout: String,
    pub math: String,
    pub branching: usize,
    pub packet: usize,
    /// single, subgroup, shared or hybrid: what the device would run for this P.
    pub packet_impl: String,
    pub float_controls: String,
    /// `ok`, `skipped: why` (the device lacks a feature) or `FAILED: why` (did not build).
    pub status: Status,
    /// The subgroup (wave) size the driver compiled for.
    pub subgroup_size: u32,
    /// Wall time of the pipeline's creation, ms.
    pub build_ms: f64,
    /// Vector registers allocated per wave (RADV: "VGPRs").
    pub vgprs: Option<f64>,
    pub sgprs: Option<f64>,
    pub spilled_vgprs: Option<f64>,
    pub spilled_sgprs: Option<f64>,
    /// Private memory per wave, bytes (RADV: "Scratch size").
    pub scratch_bytes: Option<f64>,
    /// Shared memory per workgroup, bytes.
    pub lds_bytes: Option<f64>,
    pub code_bytes: Option<f64>,
    pub instructions: Option<f64>,
    /// Vector ALU instructions as the driver counts them.
    pub valu: Option<f64>,
    /// Waves in flight per SIMD at most (RADV: "Subgroups per SIMD"): occupancy.
    pub waves_per_simd: Option<f64>,
    /// Counted in the disassembly: vector ALU instructions, of which packed fp16 (`v_pk_*_f16`),
    /// scalar fp16 (`v_*_f16`, conversions apart) and fp32; scratch loads and stores
    /// (`scratch_*`; none where the generation reaches scratch through buffer instructions,
    /// GCN1–4); instructions the disassembler could not decode.
    pub asm: Option<AsmCounts>,
    /// The vendor-neutral columns ([`columns`]): 32-bit registers per thread, private memory
    /// per thread (bytes), spill and fill instructions, occupancy in `occupancy_unit` (waves
    /// per SIMD, waves per core, warps per SM, threads), the compiler's cycle estimate.
    #[serde(default)]
    pub registers: Option<f64>,
    #[serde(default)]
    pub private_bytes: Option<f64>,
    #[serde(default)]
    pub spills: Option<f64>,
    #[serde(default)]
    pub occupancy: Option<f64>,
    #[serde(default)]
    pub occupancy_unit: String,
    #[serde(default)]
    pub cycles: Option<f64>,
    /// Ratios to the f32 kernel of the same device, B, P and packet implementation.
    pub vs_f32: Option<VsF32>,
    /// Every statistic as the driver names it.
    pub stats: BTreeMap<String, f64>,
    /// The kernel, typed: set where the row is built, parsed once where rows are read
    /// ([`IsaRow::typed`]).
    #[serde(skip)]
    pub what: What,
}

super::key::keyed_row!(IsaRow, |r| place: [&r.device, &r.driver, "", ""], float_controls: &r.float_controls, packet_impl: Some(&r.packet_impl));

/// Counts of the disassembly ([`crate::isa::counts`] makes them).
#[derive(Clone, Copy, Debug, Default, Serialize, Deserialize, PartialEq, Eq)]
pub struct AsmCounts {
    pub instructions: u64,
    pub valu: u64,
    pub packed_f16: u64,
    pub scalar_f16: u64,
    pub f32: u64,
    pub conversions: u64,
    pub scratch_loads: Option<u64>,
    pub scratch_stores: Option<u64>,
    pub undecoded: u64,
}

impl AsmCounts {
    /// Packed share of the fp16 vector ALU instructions (None without any).
    pub fn packed_share(&self) -> Option<f64> {
        let all = self.packed_f16 + self.scalar_f16;
        (all > 0).then(|| self.packed_f16 as f64 / all as f64)
    }
}

/// Key figures as ratios to the f32 kernel of the same device, B, P and packet implementation.
#[derive(Clone, Copy, Debug, Default, Serialize, Deserialize, PartialEq)]
pub struct VsF32 {
    pub vgprs: Option<f64>,
    pub scratch: Option<f64>,
    pub instructions: Option<f64>,
    pub valu: Option<f64>,
    pub waves: Option<f64>,
    /// The vendor-neutral columns' ratios.
    #[serde(default)]
    pub registers: Option<f64>,
    #[serde(default)]
    pub occupancy: Option<f64>,
    #[serde(default)]
    pub cycles: Option<f64>,
}

/// The driver statistics a row names in its own columns: (column, RADV's name).
pub const KNOWN_STATS: &[(&str, &str)] = &[
    ("vgprs", "VGPRs"),
    ("sgprs", "SGPRs"),
    ("spilled_vgprs", "Spilled VGPRs"),
    ("spilled_sgprs", "Spilled SGPRs"),
    ("scratch_bytes", "Scratch size"),
    ("lds_bytes", "LDS size"),
    ("code_bytes", "Code size"),
    ("instructions", "Instructions"),
    ("valu", "VALU"),
    ("waves_per_simd", "Subgroups per SIMD"),
];

impl IsaRow {
    /// Fills the named columns from [`IsaRow::stats`] (RADV's names), then the vendor-neutral
    /// ones from whichever driver's names the row has.
    pub fn fill_known(&mut self) {
        let get = |name: &str| self.stats.iter().find(|(k, _)| k.eq_ignore_ascii_case(name)).map(|(_, v)| *v);
        let v: Vec<Option<f64>> = KNOWN_STATS.iter().map(|(_, n)| get(n)).collect();
        (self.vgprs, self.sgprs, self.spilled_vgprs, self.spilled_sgprs, self.scratch_bytes) =
            (v[0], v[1], v[2], v[3], v[4]);
        (self.lds_bytes, self.code_bytes, self.instructions, self.valu, self.waves_per_simd) =
            (v[5], v[6], v[7], v[8], v[9]);
        self.normalize();
    }

    /// `layout` or `layout math` for layouts with several math modes, then `fc off` for a
    /// kernel built without float controls.
    pub fn label(&self) -> String {
        let l = match self.what.layout() {
            Some(l) if l.info().maths.len() == 1 => self.layout.clone(),
            _ => format!("{} {}", self.layout, self.math),
        };
        if self.float_controls == "off" {
            format!("{l} fc off")
        } else {
            l
        }
    }

    /// The device's short name: `navi31 (RDNA3)` for a null device, `a740 (Adreno 7xx)` for a
    /// model under a drm-shim, else the device's name.
    pub fn device_label(&self) -> String {
        // A null device, or a family under the amdgpu shim (`… (amdgpu shim)`).
        let null = self.device.starts_with("Null hardware") || self.device.ends_with(" shim)");
        if self.family.is_empty() || (!null && crate::gpu::null::family(&self.family).is_some()) {
            self.device.clone()
        } else {
            format!("{} ({})", self.family, self.generation)
        }
    }
}

/// Sets every ok row's ratios to its f32 kernel ([`f32_peer`]: same device, driver, B, P,
/// packet implementation and float controls, else the other float controls).
pub fn set_ratios(rows: &mut [IsaRow]) {
    let ratio = |a: Option<f64>, b: Option<f64>| match (a, b) {
        (Some(a), Some(b)) if b > 0.0 => Some(a / b),
        (Some(0.0), Some(_)) => Some(1.0),
        _ => None,
    };
    let ratios: Vec<Option<VsF32>> = rows
        .iter()
        .map(|r| match f32_peer(r, rows.iter()) {
            Some(f) if r.status.is_ok() => Some(VsF32 {
                vgprs: ratio(r.vgprs, f.vgprs),
                scratch: ratio(r.scratch_bytes, f.scratch_bytes),
                instructions: ratio(r.instructions, f.instructions),
                valu: ratio(r.valu, f.valu),
                waves: ratio(r.waves_per_simd, f.waves_per_simd),
                registers: ratio(r.registers, f.registers),
                occupancy: ratio(r.occupancy, f.occupancy),
                cycles: ratio(r.cycles, f.cycles),
            }),
            _ => None,
        })
        .collect();
    for (r, q) in rows.iter_mut().zip(ratios) {
        r.vs_f32 = q;
    }
}

/// Rows in report order: device (its releases oldest first), then layout (registry order),
/// math, B, P, kernel.
pub fn sorted(rows: &[IsaRow]) -> Vec<IsaRow> {
    let mut v = rows.to_vec();
    // AMD families oldest first, then the other vendors in table order.
    let gen = |r: &IsaRow| {
        crate::gpu::null::FAMILIES
            .iter()
            .position(|f| f.name == r.family)
            .unwrap_or_else(|| 1000 + r.vendor.get().map_or(crate::vendor::REGISTRY.len(), |v| v.position()) * 100)
    };
    // One device's releases side by side, oldest first (`isa --compilers pinned,newest`).
    let rel = |r: &IsaRow| (r.device_label(), releases::version(&releases::release(&r.driver)));
    v.sort_by(|a, b| {
        (gen(a), rel(a), &a.device, &a.driver, order(&a.layout), &a.math, a.branching, a.packet, &a.kernel).cmp(&(
            gen(b),
            rel(b),
            &b.device,
            &b.driver,
            order(&b.layout),
            &b.math,
            b.branching,
            b.packet,
            &b.kernel,
        ))
    });
    v
}

/// A test's row: `layout`'s kernel at B = 4, P = 1 (its default math) on the device `place`
/// names — (device, family, generation, driver) — untyped, its figures unset.
#[cfg(test)]
pub(crate) fn test_row(layout: &str, (device, family, generation, driver): (&str, &str, &str, &str)) -> IsaRow {
    use crate::variant::{KernelId, PacketImpl, Variant};
    let v = Variant::new(crate::layout::LayoutId::parse(layout).unwrap(), 4, 1);
    IsaRow {
        device: device.into(),
        family: family.into(),
        generation: generation.into(),
        driver: driver.into(),
        kernel: KernelId::new(v, PacketImpl::Single, false).name(),
        layout: layout.into(),
        math: v.math.name().into(),
        branching: 4,
        packet: 1,
        packet_impl: "single".into(),
        float_controls: v.fc.name().into(),
        ..IsaRow::default()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A kernel at B = 4, P = 1 built by `crate::vendor::fake`'s compiler, which names its
    /// statistics its own way.
    fn fake_row(layout: &str, regs: f64) -> IsaRow {
        let mut r = IsaRow {
            stats: [("Fake regs", regs), ("Fake lanes", 12.0), ("Fake ops", 900.0), ("Fake spills", 3.0)]
                .map(|(k, v)| (k.to_string(), v))
                .into(),
            ..test_row(layout, ("Fake GPU One (fakedrv)", "fk1", "Fake 1", "fakedrv 1.0"))
        }
        .typed();
        r.fill_known();
        r
    }

    /// A vendor is one file and one registry line: the fake vendor's rows get their vendor,
    /// its columns and its occupancy unit, and reach every table of `isa` with nothing else
    /// touched.
    #[test]
    fn a_vendor_in_one_file_reaches_the_tables() {
        let mut rows = vec![fake_row("f32", 40.0), fake_row("f16h", 52.0)];
        set_ratios(&mut rows);
        let h = &rows[1];
        assert_eq!(h.vendor, "Fakevendor");
        assert_eq!(
            (h.registers, h.occupancy, h.spills, h.instructions),
            (Some(52.0), Some(12.0), Some(3.0), Some(900.0))
        );
        assert_eq!(h.occupancy_unit, "lanes/unit");
        assert_eq!(h.vs_f32.and_then(|q| q.registers), Some(1.3));
        let md = section(&rows, 2);
        assert!(md.contains("## fk1 (Fake 1)"), "{md}");
        assert!(md.contains("| lanes/unit |"), "the vendor's own table, in its unit:\n{md}");
        assert!(md.contains("| f16h "), "{md}");
        assert!(md.contains("| 52 | 1.30× |"), "{md}");
        let head = headline(&rows);
        assert!(head.contains("| fk1 (Fake 1) | 40 / – / 12 | 52 / – / 12 |"), "{head}");
        assert!(head.contains("lanes per unit"), "the vendor's unit named in words:\n{head}");
        let csv = String::from_utf8(files::csv_bytes(&rows).unwrap()).unwrap();
        assert!(csv.lines().nth(1).unwrap().contains(",Fakevendor,fakedrv 1.0,"), "{csv}");
    }
}
