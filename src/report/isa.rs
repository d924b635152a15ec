//! The compiler's view (`halftrace isa`): one [`IsaRow`] per kernel × device — the statistics
//! the driver names, the instruction mix counted in its disassembly, each key figure as a
//! ratio to the f32 kernel of the same B, P and device — stored as `isa.json` and `isa.csv`,
//! rendered as tables ([`section`], in `isa.md` and in a merged `report.md`) and plots.

use super::plots;
use super::rows::{order, Status};
use crate::layout::LayoutId;
use anyhow::Context;
use serde::{Deserialize, Serialize};
use std::collections::{BTreeMap, BTreeSet};
use std::path::Path;

/// One kernel built on one device.
#[derive(Clone, Debug, Default, Serialize, Deserialize, PartialEq)]
pub struct IsaRow {
    pub device: String,
    /// The RADV family of a null device (`navi31`), empty for a real device.
    pub family: String,
    /// The family's generation (GCN4, RDNA3, …), empty when unknown.
    pub generation: String,
    pub driver: String,
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
    /// Ratios to the f32 kernel of the same device, B, P and packet implementation.
    pub vs_f32: Option<VsF32>,
    /// Every statistic as the driver names it.
    pub stats: BTreeMap<String, f64>,
}

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
    /// Fills the named columns from [`IsaRow::stats`].
    pub fn fill_known(&mut self) {
        let get = |name: &str| self.stats.iter().find(|(k, _)| k.eq_ignore_ascii_case(name)).map(|(_, v)| *v);
        let v: Vec<Option<f64>> = KNOWN_STATS.iter().map(|(_, n)| get(n)).collect();
        (self.vgprs, self.sgprs, self.spilled_vgprs, self.spilled_sgprs, self.scratch_bytes) =
            (v[0], v[1], v[2], v[3], v[4]);
        (self.lds_bytes, self.code_bytes, self.instructions, self.valu, self.waves_per_simd) =
            (v[5], v[6], v[7], v[8], v[9]);
    }

    /// `layout` or `layout math` for layouts with several math modes, then `fc off` for a
    /// kernel built without float controls.
    pub fn label(&self) -> String {
        let l = match LayoutId::parse(&self.layout) {
            Ok(l) if l.info().maths.len() == 1 => self.layout.clone(),
            _ => format!("{} {}", self.layout, self.math),
        };
        if self.float_controls == "off" {
            format!("{l} fc off")
        } else {
            l
        }
    }

    /// The device's short name: `navi31 (RDNA3)` for a null device, else the device's name.
    pub fn device_label(&self) -> String {
        if self.family.is_empty() || !self.device.starts_with("Null hardware") {
            self.device.clone()
        } else {
            format!("{} ({})", self.family, self.generation)
        }
    }
}

/// Sets every ok row's ratios to its f32 kernel (same device, driver, B, P, packet
/// implementation and float controls).
pub fn set_ratios(rows: &mut [IsaRow]) {
    let key = |r: &IsaRow| {
        (r.device.clone(), r.driver.clone(), r.branching, r.packet, r.packet_impl.clone(), r.float_controls.clone())
    };
    let base: BTreeMap<_, IsaRow> =
        rows.iter().filter(|r| r.layout == "f32" && r.status.is_ok()).map(|r| (key(r), r.clone())).collect();
    // An fp16 layout may build without float controls where f32 builds with them (or the
    // other way round): then the f32 kernel of the other mode.
    let other = |r: &IsaRow| {
        let mut k = key(r);
        k.5 = if k.5 == "off" { "on".into() } else { "off".into() };
        k
    };
    let ratio = |a: Option<f64>, b: Option<f64>| match (a, b) {
        (Some(a), Some(b)) if b > 0.0 => Some(a / b),
        (Some(0.0), Some(_)) => Some(1.0),
        _ => None,
    };
    for r in rows.iter_mut() {
        r.vs_f32 = match base.get(&key(r)).or_else(|| base.get(&other(r))) {
            Some(f) if r.status.is_ok() => Some(VsF32 {
                vgprs: ratio(r.vgprs, f.vgprs),
                scratch: ratio(r.scratch_bytes, f.scratch_bytes),
                instructions: ratio(r.instructions, f.instructions),
                valu: ratio(r.valu, f.valu),
                waves: ratio(r.waves_per_simd, f.waves_per_simd),
            }),
            _ => None,
        };
    }
}

/// Rows in report order: device, then layout (registry order), math, B, P, kernel.
pub fn sorted(rows: &[IsaRow]) -> Vec<IsaRow> {
    let mut v = rows.to_vec();
    let gen = |r: &IsaRow| crate::gpu::null::FAMILIES.iter().position(|f| f.name == r.family).unwrap_or(usize::MAX);
    v.sort_by(|a, b| {
        (gen(a), &a.device, &a.driver, order(&a.layout), &a.math, a.branching, a.packet, &a.kernel).cmp(&(
            gen(b),
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

/// Columns of `isa.csv` before the driver's own statistics.
const CSV_COLUMNS: &[&str] = &[
    "device",
    "family",
    "generation",
    "driver",
    "version",
    "commit",
    "kernel",
    "layout",
    "math",
    "branching",
    "packet",
    "packet_impl",
    "float_controls",
    "status",
    "subgroup_size",
    "build_ms",
    "vgprs",
    "sgprs",
    "spilled_vgprs",
    "spilled_sgprs",
    "scratch_bytes",
    "lds_bytes",
    "code_bytes",
    "instructions",
    "valu",
    "waves_per_simd",
    "asm_instructions",
    "asm_valu",
    "asm_packed_f16",
    "asm_scalar_f16",
    "asm_f32",
    "asm_conversions",
    "asm_scratch_loads",
    "asm_scratch_stores",
    "asm_undecoded",
    "packed_f16_share",
    "vgprs_vs_f32",
    "scratch_vs_f32",
    "instructions_vs_f32",
    "valu_vs_f32",
    "waves_vs_f32",
];

fn cell(x: Option<f64>) -> String {
    x.map(|v| if v.fract() == 0.0 && v.abs() < 1e15 { format!("{v:.0}") } else { format!("{v:.4}") })
        .unwrap_or_default()
}

fn ucell(x: Option<u64>) -> String {
    x.map(|v| v.to_string()).unwrap_or_default()
}

/// Writes `isa.json` (every field) and `isa.csv` (one column per field, then one `stat: NAME`
/// column per statistic any row names), each atomically.
pub fn write(dir: &Path, rows: &[IsaRow]) -> anyhow::Result<()> {
    std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
    let names: BTreeSet<&String> = rows.iter().flat_map(|r| r.stats.keys()).collect();
    let mut csv = csv::Writer::from_writer(Vec::new());
    let header: Vec<String> =
        CSV_COLUMNS.iter().map(|c| c.to_string()).chain(names.iter().map(|n| format!("stat: {n}"))).collect();
    csv.write_record(&header)?;
    for r in rows {
        let a = r.asm.unwrap_or_default();
        let has = r.asm.is_some();
        let u = |x: u64| if has { x.to_string() } else { String::new() };
        let q = r.vs_f32.unwrap_or_default();
        let mut rec: Vec<String> = vec![
            r.device.clone(),
            r.family.clone(),
            r.generation.clone(),
            r.driver.clone(),
            r.version.clone(),
            r.commit.clone(),
            r.kernel.clone(),
            r.layout.clone(),
            r.math.clone(),
            r.branching.to_string(),
            r.packet.to_string(),
            r.packet_impl.clone(),
            r.float_controls.clone(),
            r.status.to_string(),
            r.subgroup_size.to_string(),
            format!("{:.1}", r.build_ms),
        ];
        rec.extend(
            [
                r.vgprs,
                r.sgprs,
                r.spilled_vgprs,
                r.spilled_sgprs,
                r.scratch_bytes,
                r.lds_bytes,
                r.code_bytes,
                r.instructions,
                r.valu,
                r.waves_per_simd,
            ]
            .map(cell),
        );
        rec.extend([u(a.instructions), u(a.valu), u(a.packed_f16), u(a.scalar_f16), u(a.f32), u(a.conversions)]);
        rec.extend([ucell(r.asm.and_then(|a| a.scratch_loads)), ucell(r.asm.and_then(|a| a.scratch_stores))]);
        rec.push(u(a.undecoded));
        rec.push(cell(r.asm.and_then(|a| a.packed_share())));
        rec.extend([q.vgprs, q.scratch, q.instructions, q.valu, q.waves].map(cell));
        rec.extend(names.iter().map(|n| cell(r.stats.get(*n).copied())));
        csv.write_record(&rec)?;
    }
    let bytes = csv.into_inner().map_err(|e| anyhow::anyhow!("{e}"))?;
    crate::fsx::write_atomic(&dir.join("isa.csv"), &bytes)?;
    crate::fsx::write_atomic(&dir.join("isa.json"), serde_json::to_string_pretty(rows)?.as_bytes())
}

/// The rows of `DIR/isa.json`, or `None` when the folder has none.
pub fn read(dir: &Path) -> anyhow::Result<Option<Vec<IsaRow>>> {
    let p = dir.join("isa.json");
    if !p.exists() {
        return Ok(None);
    }
    let text = std::fs::read_to_string(&p).with_context(|| format!("reading {}", p.display()))?;
    let rows: Vec<IsaRow> =
        serde_json::from_str(&text).with_context(|| format!("{}: not the rows `halftrace isa` writes", p.display()))?;
    Ok(Some(rows))
}

fn num(x: Option<f64>) -> String {
    x.map(|v| format!("{v:.0}")).unwrap_or_else(|| "–".into())
}

fn kib(x: Option<f64>) -> String {
    x.map(|v| format!("{:.1}", v / 1024.0)).unwrap_or_else(|| "–".into())
}

fn times(x: Option<f64>) -> String {
    x.map(|v| format!("{v:.2}×")).unwrap_or_else(|| "–".into())
}

fn share(a: &Option<AsmCounts>) -> String {
    match a {
        Some(a) => match a.packed_share() {
            Some(s) => format!("{}/{} ({:.0}%)", a.packed_f16, a.packed_f16 + a.scalar_f16, 100.0 * s),
            None => "no fp16".into(),
        },
        None => "–".into(),
    }
}

fn ldst(a: &Option<AsmCounts>) -> String {
    match a.and_then(|a| a.scratch_loads.zip(a.scratch_stores)) {
        Some((l, s)) => format!("{l}/{s}"),
        None => "n/a".into(),
    }
}

/// The "compiler view" Markdown: one table across devices (P = 1), then per device the
/// layouts at P = 1, the packet series and what was skipped or failed.
pub fn section(rows: &[IsaRow], level: usize) -> String {
    let rows = sorted(rows);
    let h = "#".repeat(level);
    let mut md = String::new();
    let mut devices: Vec<(String, String)> = Vec::new();
    for r in &rows {
        let d = (r.device_label(), r.driver.clone());
        if !devices.contains(&d) {
            devices.push(d);
        }
    }
    let ok: Vec<&IsaRow> = rows.iter().filter(|r| r.status.is_ok()).collect();
    md += &format!(
        "{h} Compiler view\n\n{} kernel build(s) on {} device(s) ({} ok, {} skipped, {} failed): the statistics the driver \
         reports through VK_KHR_pipeline_executable_properties and the instruction mix of its disassembly. A null \
         device (RADV_FORCE_FAMILY) is AMD's compiler for that GPU without the GPU: nothing ran. Ratios (×) are to \
         the f32 kernel of the same device, B, P and packet implementation (and float controls, where it has them).\n\n",
        rows.len(),
        devices.len(),
        ok.len(),
        rows.iter().filter(|r| r.status.is_skipped()).count(),
        rows.iter().filter(|r| r.status.is_failed()).count()
    );
    for (d, drv) in &devices {
        let full = rows.iter().find(|r| r.device_label() == *d).map(|r| r.device.clone()).unwrap_or_default();
        md += &format!("- **{d}**: {full}, driver {drv}\n");
    }
    md += "\n";
    // Across devices: VGPRs / scratch KiB per wave / waves per SIMD, P = 1.
    let cols: Vec<String> = devices.iter().map(|d| d.0.clone()).collect();
    let mut kernels: Vec<(usize, String, usize)> = Vec::new();
    for r in ok.iter().filter(|r| r.packet == 1) {
        let k = (order(&r.layout), r.label(), r.branching);
        if !kernels.contains(&k) {
            kernels.push(k);
        }
    }
    kernels.sort();
    if !kernels.is_empty() {
        md += &format!("{h}# Across devices (P = 1): VGPRs / scratch KiB per wave / waves per SIMD\n\n");
        md += &format!("| kernel | B | {} |\n|---|---|{}\n", cols.join(" | "), "---|".repeat(cols.len()));
        for (_, label, b) in &kernels {
            let cells: Vec<String> = cols
                .iter()
                .map(|c| {
                    ok.iter()
                        .find(|r| r.packet == 1 && r.branching == *b && r.label() == *label && r.device_label() == *c)
                        .map(|r| format!("{} / {} / {}", num(r.vgprs), kib(r.scratch_bytes), num(r.waves_per_simd)))
                        .unwrap_or_else(|| "–".into())
                })
                .collect();
            md += &format!("| {label} | {b} | {} |\n", cells.join(" | "));
        }
        md += "\n";
    }
    for (d, drv) in &devices {
        let here: Vec<&IsaRow> = rows.iter().filter(|r| r.device_label() == *d && r.driver == *drv).collect();
        md += &format!("{h}# {d}\n\n");
        let one: Vec<&&IsaRow> = here.iter().filter(|r| r.status.is_ok() && r.packet == 1).collect();
        if !one.is_empty() {
            md += "Layouts at P = 1:\n\n| layout | B | fc | VGPRs | ×f32 | SGPRs | scratch KiB/wave | ×f32 | waves/SIMD | \
                   instructions | ×f32 | VALU | ×f32 | fp16 VALU packed | scratch ld/st |\n\
                   |---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|\n";
            for r in one {
                let q = r.vs_f32.unwrap_or_default();
                md += &format!(
                    "| {} | {} | {} | {} | {} | {} | {} | {} | {} | {} | {} | {} | {} | {} | {} |\n",
                    r.label(),
                    r.branching,
                    r.float_controls,
                    num(r.vgprs),
                    times(q.vgprs),
                    num(r.sgprs),
                    kib(r.scratch_bytes),
                    times(q.scratch),
                    num(r.waves_per_simd),
                    num(r.instructions),
                    times(q.instructions),
                    num(r.valu),
                    times(q.valu),
                    share(&r.asm),
                    ldst(&r.asm)
                );
            }
            md += "\n";
        }
        let packets: Vec<&&IsaRow> = here.iter().filter(|r| r.status.is_ok() && r.packet > 1).collect();
        if !packets.is_empty() {
            md += "Packet series:\n\n| layout | B | P | implementation | wave | VGPRs | ×f32 | scratch KiB/wave | ×f32 | \
                   LDS bytes | waves/SIMD | instructions | ×f32 |\n|---|---|---|---|---|---|---|---|---|---|---|---|---|\n";
            for r in packets {
                let q = r.vs_f32.unwrap_or_default();
                md += &format!(
                    "| {} | {} | {} | {} | {} | {} | {} | {} | {} | {} | {} | {} | {} |\n",
                    r.label(),
                    r.branching,
                    r.packet,
                    r.packet_impl,
                    r.subgroup_size,
                    num(r.vgprs),
                    times(q.vgprs),
                    kib(r.scratch_bytes),
                    times(q.scratch),
                    num(r.lds_bytes),
                    num(r.waves_per_simd),
                    num(r.instructions),
                    times(q.instructions)
                );
            }
            md += "\n";
        }
        let mut notes: Vec<String> = here
            .iter()
            .filter(|r| !r.status.is_ok())
            .map(|r| match &r.status {
                Status::Skipped(why) => format!("Skipped: {why}"),
                s => format!("**{}**: {s}", r.kernel),
            })
            .collect();
        notes.dedup();
        for n in notes {
            md += &format!("{n}\n\n");
        }
    }
    md += "![vector registers per wave by layout and B](isa_vgprs.png) ![scratch per wave by layout and B](isa_scratch.png)\n\n";
    md
}

/// `isa.md` and the two plots of an `isa` folder.
pub fn render(rows: &[IsaRow], out: &Path) -> anyhow::Result<()> {
    let mut md = String::from("# halftrace isa\n\n");
    md += &section(rows, 2);
    crate::fsx::write_atomic(&out.join("isa.md"), md.as_bytes())?;
    plot(rows, out)
}

/// `isa_vgprs` and `isa_scratch` (PNG and SVG): one panel per device, x = B, one line per
/// layout and math (P = 1).
pub fn plot(rows: &[IsaRow], out: &Path) -> anyhow::Result<()> {
    let rows = sorted(rows);
    let mut devices: Vec<String> = Vec::new();
    for r in rows.iter().filter(|r| r.status.is_ok()) {
        if !devices.contains(&r.device_label()) {
            devices.push(r.device_label());
        }
    }
    let series = |f: &dyn Fn(&IsaRow) -> Option<f64>| -> Vec<(String, plots::Lines)> {
        devices
            .iter()
            .map(|d| {
                let mut lines: plots::Lines = Vec::new();
                for r in rows.iter().filter(|r| r.status.is_ok() && r.packet == 1 && r.device_label() == *d) {
                    if let Some(y) = f(r) {
                        match lines.iter_mut().find(|l| l.0 == r.label()) {
                            Some(l) => l.1.push((r.branching, y)),
                            None => lines.push((r.label(), vec![(r.branching, y)])),
                        }
                    }
                }
                (d.clone(), lines)
            })
            .collect()
    };
    plots::panels(
        out,
        "isa_vgprs",
        "Vector registers per wave (P = 1), by layout and B",
        "branching factor B",
        "VGPRs",
        &series(&|r| r.vgprs),
    )?;
    plots::panels(
        out,
        "isa_scratch",
        "Scratch (private memory) per wave, KiB (P = 1), by layout and B",
        "branching factor B",
        "KiB per wave",
        &series(&|r| r.scratch_bytes.map(|b| b / 1024.0)),
    )
}
