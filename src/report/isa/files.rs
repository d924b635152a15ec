//! `isa.json` (every field) and `isa.csv` (one column per field, then the drivers' own
//! statistics).

use super::IsaRow;
use anyhow::Context;
use std::collections::BTreeSet;
use std::path::Path;

/// Columns of `isa.csv` before the driver's own statistics.
const CSV_COLUMNS: &[&str] = &[
    "device",
    "family",
    "generation",
    "vendor",
    "driver",
    "device_build",
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
    "registers",
    "private_bytes",
    "spills",
    "occupancy",
    "occupancy_unit",
    "cycles",
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
    "registers_vs_f32",
    "occupancy_vs_f32",
    "cycles_vs_f32",
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
            r.vendor.clone(),
            r.driver.clone(),
            r.device_build.clone(),
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
                r.registers,
                r.private_bytes,
                r.spills,
                r.occupancy,
            ]
            .map(cell),
        );
        rec.push(r.occupancy_unit.clone());
        rec.push(cell(r.cycles));
        rec.extend([u(a.instructions), u(a.valu), u(a.packed_f16), u(a.scalar_f16), u(a.f32), u(a.conversions)]);
        rec.extend([ucell(r.asm.and_then(|a| a.scratch_loads)), ucell(r.asm.and_then(|a| a.scratch_stores))]);
        rec.push(u(a.undecoded));
        rec.push(cell(r.asm.and_then(|a| a.packed_share())));
        rec.extend([q.vgprs, q.scratch, q.instructions, q.valu, q.waves, q.registers, q.occupancy, q.cycles].map(cell));
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
