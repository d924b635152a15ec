//! `isa.json` (every field) and `isa.csv` (one column per field, then the drivers' own
//! statistics).

use super::IsaRow;
use crate::base::Status;
use crate::report::csvx::{display, fixed, header_of, to_bytes_with};
use anyhow::Context;
use serde::{Serialize, Serializer};
use std::collections::BTreeSet;
use std::path::Path;

/// A statistic's text: whole numbers without decimals, others with four; empty when absent.
fn cell_text(x: Option<f64>) -> String {
    match x {
        Some(v) if v.fract() == 0.0 && v.abs() < 1e15 => format!("{v:.0}"),
        Some(v) => format!("{v:.4}"),
        None => String::new(),
    }
}

/// A statistic's cell ([`cell_text`]).
fn cell<S: Serializer>(x: &Option<f64>, s: S) -> Result<S::Ok, S::Error> {
    s.serialize_str(&cell_text(*x))
}

/// One line of `isa.csv` before the drivers' own statistics.
#[derive(Serialize)]
struct Record<'a> {
    device: &'a str,
    family: &'a str,
    generation: &'a str,
    vendor: &'a str,
    driver: &'a str,
    device_build: &'a str,
    version: &'a str,
    commit: &'a str,
    kernel: &'a str,
    layout: &'a str,
    math: &'a str,
    branching: usize,
    packet: usize,
    packet_impl: &'a str,
    float_controls: &'a str,
    #[serde(serialize_with = "display")]
    status: &'a Status,
    subgroup_size: u32,
    #[serde(serialize_with = "fixed::<1, _>")]
    build_ms: f64,
    #[serde(serialize_with = "cell")]
    vgprs: Option<f64>,
    #[serde(serialize_with = "cell")]
    sgprs: Option<f64>,
    #[serde(serialize_with = "cell")]
    spilled_vgprs: Option<f64>,
    #[serde(serialize_with = "cell")]
    spilled_sgprs: Option<f64>,
    #[serde(serialize_with = "cell")]
    scratch_bytes: Option<f64>,
    #[serde(serialize_with = "cell")]
    lds_bytes: Option<f64>,
    #[serde(serialize_with = "cell")]
    code_bytes: Option<f64>,
    #[serde(serialize_with = "cell")]
    instructions: Option<f64>,
    #[serde(serialize_with = "cell")]
    valu: Option<f64>,
    #[serde(serialize_with = "cell")]
    waves_per_simd: Option<f64>,
    #[serde(serialize_with = "cell")]
    registers: Option<f64>,
    #[serde(serialize_with = "cell")]
    private_bytes: Option<f64>,
    #[serde(serialize_with = "cell")]
    spills: Option<f64>,
    #[serde(serialize_with = "cell")]
    occupancy: Option<f64>,
    occupancy_unit: &'a str,
    #[serde(serialize_with = "cell")]
    cycles: Option<f64>,
    asm_instructions: Option<u64>,
    asm_valu: Option<u64>,
    asm_packed_f16: Option<u64>,
    asm_scalar_f16: Option<u64>,
    asm_f32: Option<u64>,
    asm_conversions: Option<u64>,
    asm_scratch_loads: Option<u64>,
    asm_scratch_stores: Option<u64>,
    asm_undecoded: Option<u64>,
    #[serde(serialize_with = "cell")]
    packed_f16_share: Option<f64>,
    #[serde(serialize_with = "cell")]
    vgprs_vs_f32: Option<f64>,
    #[serde(serialize_with = "cell")]
    scratch_vs_f32: Option<f64>,
    #[serde(serialize_with = "cell")]
    instructions_vs_f32: Option<f64>,
    #[serde(serialize_with = "cell")]
    valu_vs_f32: Option<f64>,
    #[serde(serialize_with = "cell")]
    waves_vs_f32: Option<f64>,
    #[serde(serialize_with = "cell")]
    registers_vs_f32: Option<f64>,
    #[serde(serialize_with = "cell")]
    occupancy_vs_f32: Option<f64>,
    #[serde(serialize_with = "cell")]
    cycles_vs_f32: Option<f64>,
}

impl<'a> Record<'a> {
    fn of(r: &'a IsaRow) -> Record<'a> {
        let a = r.asm.as_ref();
        let q = r.vs_f32.unwrap_or_default();
        Record {
            device: &r.device,
            family: &r.family,
            generation: &r.generation,
            vendor: r.vendor.name(),
            driver: &r.driver,
            device_build: &r.device_build,
            version: &r.version,
            commit: &r.commit,
            kernel: &r.kernel,
            layout: &r.layout,
            math: &r.math,
            branching: r.branching,
            packet: r.packet,
            packet_impl: &r.packet_impl,
            float_controls: &r.float_controls,
            status: &r.status,
            subgroup_size: r.subgroup_size,
            build_ms: r.build_ms,
            vgprs: r.vgprs,
            sgprs: r.sgprs,
            spilled_vgprs: r.spilled_vgprs,
            spilled_sgprs: r.spilled_sgprs,
            scratch_bytes: r.scratch_bytes,
            lds_bytes: r.lds_bytes,
            code_bytes: r.code_bytes,
            instructions: r.instructions,
            valu: r.valu,
            waves_per_simd: r.waves_per_simd,
            registers: r.registers,
            private_bytes: r.private_bytes,
            spills: r.spills,
            occupancy: r.occupancy,
            occupancy_unit: &r.occupancy_unit,
            cycles: r.cycles,
            asm_instructions: a.map(|a| a.instructions),
            asm_valu: a.map(|a| a.valu),
            asm_packed_f16: a.map(|a| a.packed_f16),
            asm_scalar_f16: a.map(|a| a.scalar_f16),
            asm_f32: a.map(|a| a.f32),
            asm_conversions: a.map(|a| a.conversions),
            asm_scratch_loads: a.and_then(|a| a.scratch_loads),
            asm_scratch_stores: a.and_then(|a| a.scratch_stores),
            asm_undecoded: a.map(|a| a.undecoded),
            packed_f16_share: a.and_then(|a| a.packed_share()),
            vgprs_vs_f32: q.vgprs,
            scratch_vs_f32: q.scratch,
            instructions_vs_f32: q.instructions,
            valu_vs_f32: q.valu,
            waves_vs_f32: q.waves,
            registers_vs_f32: q.registers,
            occupancy_vs_f32: q.occupancy,
            cycles_vs_f32: q.cycles,
        }
    }
}

/// Writes `isa.json` (every field) and `isa.csv` (one column per field, then one `stat: NAME`
/// column per statistic any row names), each atomically.
pub fn write(dir: &Path, rows: &[IsaRow]) -> anyhow::Result<()> {
    std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
    crate::fsx::write_atomic(&dir.join("isa.csv"), &csv_bytes(rows)?)?;
    crate::fsx::write_atomic(&dir.join("isa.json"), serde_json::to_string_pretty(rows)?.as_bytes())
}

/// `isa.csv`'s bytes.
pub(super) fn csv_bytes(rows: &[IsaRow]) -> anyhow::Result<Vec<u8>> {
    let names: BTreeSet<&String> = rows.iter().flat_map(|r| r.stats.keys()).collect();
    let template = IsaRow::default();
    let header: Vec<String> =
        header_of(Record::of(&template)).into_iter().chain(names.iter().map(|n| format!("stat: {n}"))).collect();
    let records = rows
        .iter()
        .map(|r| (Record::of(r), names.iter().map(|n| cell_text(r.stats.get(*n).copied())).collect::<Vec<_>>()));
    to_bytes_with(&header, records)
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
    Ok(Some(rows.into_iter().map(IsaRow::typed).collect()))
}
