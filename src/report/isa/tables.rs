//! The compiler view's Markdown ([`section`], in `isa.md` and a merged `report.md`) and its
//! plots.

use super::releases::labeller;
use super::{sorted, AsmCounts, IsaRow};
use crate::report::plots;
use crate::report::rows::{order, Status};
use crate::vendor::{Stats, REGISTRY};
use std::path::Path;

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

/// The "compiler view" Markdown: one vendor-neutral table across every device, one AMD table
/// across its generations (P = 1), then per device the layouts at P = 1 (AMD's columns, or the
/// vendor-neutral ones with the driver's own figures), the packet series and what was skipped
/// or failed.
pub fn section(rows: &[IsaRow], level: usize) -> String {
    let rows = sorted(rows);
    let lab = labeller(&rows);
    let lab = &lab;
    let h = "#".repeat(level);
    let mut md = String::new();
    let mut devices: Vec<(String, String)> = Vec::new();
    for r in &rows {
        let d = (lab(r), r.driver.clone());
        if !devices.contains(&d) {
            devices.push(d);
        }
    }
    let ok: Vec<&IsaRow> = rows.iter().filter(|r| r.status.is_ok()).collect();
    md += &format!(
        "{h} Compiler view\n\n{} kernel build(s) on {} device(s) ({} ok, {} skipped, {} failed): the statistics the driver \
         reports through VK_KHR_pipeline_executable_properties and the instruction mix of its disassembly. A null \
         device (RADV_FORCE_FAMILY; the amdgpu drm-shim from Mesa 26 on) is AMD's compiler for that GPU without the \
         GPU, a model under Mesa's drm-shim another vendor's: nothing ran. Ratios (×) are to the f32 kernel of the same device, B, P and packet \
         implementation (and float controls, where it has them). The vendor-neutral columns and the statistic \
         each comes from per vendor: docs/vendors.md.\n\n",
        rows.len(),
        devices.len(),
        ok.len(),
        rows.iter().filter(|r| r.status.is_skipped()).count(),
        rows.iter().filter(|r| r.status.is_failed()).count()
    );
    for (d, drv) in &devices {
        let first = rows.iter().find(|r| lab(r) == *d);
        let full = first.map(|r| r.device.clone()).unwrap_or_default();
        let build = first.map(|r| r.device_build.clone()).filter(|b| !b.is_empty());
        md += &format!(
            "- **{d}**: {full}, driver {drv}{}\n",
            build.map(|b| format!("; kernels built with {b}")).unwrap_or_default()
        );
    }
    md += "\n";
    md += &across_vendors(&ok, &devices, &h, lab);
    md += &super::releases::section(&rows, &h);
    // Across AMD generations: VGPRs / scratch KiB per wave / waves per SIMD, P = 1.
    let cols: Vec<String> = devices
        .iter()
        .filter(|d| ok.iter().any(|r| lab(r) == d.0 && r.vendor.stats_are(Stats::Aco)))
        .map(|d| d.0.clone())
        .collect();
    let kernels = kernels_at_p1(ok.iter().copied());
    if !kernels.is_empty() && !cols.is_empty() {
        md += &format!("{h}# Across AMD generations (P = 1): VGPRs / scratch KiB per wave / waves per SIMD\n\n");
        md += &format!("| kernel | B | {} |\n|---|---|{}\n", cols.join(" | "), "---|".repeat(cols.len()));
        for (_, label, b) in &kernels {
            let cells: Vec<String> = cols
                .iter()
                .map(|c| {
                    ok.iter()
                        .find(|r| r.packet == 1 && r.branching == *b && r.label() == *label && lab(r) == *c)
                        .map(|r| format!("{} / {} / {}", num(r.vgprs), kib(r.scratch_bytes), num(r.waves_per_simd)))
                        .unwrap_or_else(|| "–".into())
                })
                .collect();
            md += &format!("| {label} | {b} | {} |\n", cells.join(" | "));
        }
        md += "\n";
    }
    for (d, drv) in &devices {
        let here: Vec<&IsaRow> = rows.iter().filter(|r| lab(r) == *d && r.driver == *drv).collect();
        md += &format!("{h}# {d}\n\n");
        let one: Vec<&&IsaRow> = here.iter().filter(|r| r.status.is_ok() && r.packet == 1).collect();
        if !one.is_empty() && one[0].vendor.stats_are(Stats::Own) {
            md += &vendor_table(&one);
        } else if !one.is_empty() {
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
    md += "![registers per thread by layout and B](isa_vgprs.png) ![private memory per thread by layout and B](isa_scratch.png)\n\n";
    md
}

/// The occupancy units of the vendors with rows in `rows`, in registry order.
fn shown_units<'a>(rows: impl Iterator<Item = &'a IsaRow>) -> impl Iterator<Item = crate::vendor::Occupancy> {
    let present: Vec<&'static str> = rows.map(|r| r.vendor.name()).collect();
    REGISTRY.iter().filter(move |v| present.contains(&v.name)).filter_map(|v| v.occupancy)
}

/// The kernels of `ok` at P = 1 as (layout order, label, B), each once, sorted: the rows of the
/// tables across devices.
fn kernels_at_p1<'a>(ok: impl Iterator<Item = &'a IsaRow>) -> Vec<(usize, String, usize)> {
    let mut kernels: Vec<(usize, String, usize)> = Vec::new();
    for r in ok.filter(|r| r.packet == 1) {
        let k = (order(&r.layout), r.label(), r.branching);
        if !kernels.contains(&k) {
            kernels.push(k);
        }
    }
    kernels.sort();
    kernels
}

/// Every device side by side at P = 1: registers per thread / private bytes per thread /
/// occupancy in the vendor's unit.
fn across_vendors(ok: &[&IsaRow], devices: &[(String, String)], h: &str, lab: &dyn Fn(&IsaRow) -> String) -> String {
    let kernels = kernels_at_p1(ok.iter().copied());
    if kernels.is_empty() || devices.len() < 2 {
        return String::new();
    }
    let cols: Vec<&String> = devices.iter().map(|d| &d.0).collect();
    let units: Vec<String> = shown_units(ok.iter().copied()).map(|o| format!("{} ({})", o.words, o.note)).collect();
    let mut md = format!(
        "{h}# Across vendors (P = 1): registers per thread / private bytes per thread / occupancy\n\n\
         Occupancy in the vendor's unit: {}; – where the driver does not say.\n\n| kernel | B | {} |\n|---|---|{}\n",
        units.join(", "),
        cols.iter().map(|c| c.as_str()).collect::<Vec<_>>().join(" | "),
        "---|".repeat(cols.len())
    );
    for (_, label, b) in &kernels {
        let cells: Vec<String> = cols
            .iter()
            .map(|c| {
                ok.iter()
                    .find(|r| r.packet == 1 && r.branching == *b && r.label() == *label && lab(r) == **c)
                    .map(|r| format!("{} / {} / {}", num(r.registers), num(r.private_bytes), num(r.occupancy)))
                    .unwrap_or_else(|| "–".into())
            })
            .collect();
        md += &format!("| {label} | {b} | {} |\n", cells.join(" | "));
    }
    md + "\n"
}

/// A non-AMD device's kernels at P = 1 in the vendor-neutral columns.
fn vendor_table(one: &[&&IsaRow]) -> String {
    let unit = one.iter().map(|r| r.occupancy_unit.as_str()).find(|u| !u.is_empty()).unwrap_or("occupancy");
    let mut md = format!(
        "Layouts at P = 1:\n\n| layout | B | fc | registers/thread | ×f32 | private B/thread | spills+fills | {unit} | \
         instructions | ×f32 | cycles (compiler) | ×f32 | fp16 ALU packed | private ld/st |\n\
         |---|---|---|---|---|---|---|---|---|---|---|---|---|---|\n"
    );
    for r in one {
        let q = r.vs_f32.unwrap_or_default();
        md += &format!(
            "| {} | {} | {} | {} | {} | {} | {} | {} | {} | {} | {} | {} | {} | {} |\n",
            r.label(),
            r.branching,
            r.float_controls,
            num(r.registers),
            times(q.registers),
            num(r.private_bytes),
            num(r.spills),
            num(r.occupancy),
            num(r.instructions),
            times(q.instructions),
            num(r.cycles),
            times(q.cycles),
            share(&r.asm),
            ldst(&r.asm)
        );
    }
    md + "\n"
}

/// `isa.md` and the two plots of an `isa` folder.
pub fn render(rows: &[IsaRow], out: &Path) -> anyhow::Result<()> {
    let mut md = String::from("# halftrace isa\n\n");
    md += &section(rows, 2);
    crate::fsx::write_atomic(&out.join("isa.md"), md.as_bytes())?;
    plot(rows, out)
}

/// `isa_vgprs` (registers per thread) and `isa_scratch` (private bytes per thread), PNG and
/// SVG: one panel per device, x = B, one line per layout and math (P = 1).
pub fn plot(rows: &[IsaRow], out: &Path) -> anyhow::Result<()> {
    let rows = sorted(rows);
    let lab = labeller(&rows);
    let mut devices: Vec<String> = Vec::new();
    for r in rows.iter().filter(|r| r.status.is_ok()) {
        if !devices.contains(&lab(r)) {
            devices.push(lab(r));
        }
    }
    let series = |f: &dyn Fn(&IsaRow) -> Option<f64>| -> Vec<(String, plots::Lines)> {
        devices
            .iter()
            .map(|d| {
                let mut lines: plots::Lines = Vec::new();
                for r in rows.iter().filter(|r| r.status.is_ok() && r.packet == 1 && lab(r) == *d) {
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
        "32-bit registers per thread (P = 1), by layout and B (AMD: VGPRs)",
        "branching factor B",
        "registers per thread",
        &series(&|r| r.registers),
    )?;
    plots::panels(
        out,
        "isa_scratch",
        "Private memory (scratch, spills) per thread, bytes (P = 1), by layout and B",
        "branching factor B",
        "bytes per thread",
        &series(&|r| r.private_bytes),
    )
}

/// The headline's compiler view: one line per device, the kernels at B = 4, P = 1 (float
/// controls as each device builds them first) as registers per thread / private bytes per
/// thread / occupancy; "" without rows.
pub fn headline(rows: &[IsaRow]) -> String {
    let rows = sorted(rows);
    let lab = labeller(&rows);
    let ok: Vec<&IsaRow> = rows.iter().filter(|r| r.status.is_ok() && r.packet == 1 && r.branching == 4).collect();
    // A kernel's label without the float-control mode: a device without float controls (Mali,
    // VideoCore) shows its build without them, marked.
    let base = |r: &IsaRow| r.label().trim_end_matches(" fc off").to_string();
    let mut devices: Vec<String> = Vec::new();
    let mut kernels: Vec<(usize, String)> = Vec::new();
    for r in &ok {
        if !devices.contains(&lab(r)) {
            devices.push(lab(r));
        }
        if !kernels.iter().any(|k| k.1 == base(r)) {
            kernels.push((order(&r.layout), base(r)));
        }
    }
    kernels.sort();
    if devices.is_empty() || kernels.is_empty() {
        return String::new();
    }
    let units: Vec<&str> = shown_units(ok.iter().copied()).map(|o| o.words).collect();
    let mut md = format!(
        "## Compiler view, B = 4, P = 1: registers per thread / private bytes per thread / occupancy\n\n\
         Each vendor's production compiler without its GPU (RADV null devices, Mesa's drm-shims; nothing ran). \
         Occupancy in the vendor's unit ({}); – where the driver does not say or the device cannot build the kernel (no shaderFloat16); † the build \
         without float controls (the device has none). More in [isa.md](isa.md).\n\n| device | {} |\n|---|{}\n",
        units.join(", "),
        kernels.iter().map(|k| k.1.as_str()).collect::<Vec<_>>().join(" | "),
        "---:|".repeat(kernels.len())
    );
    for d in &devices {
        let cells: Vec<String> = kernels
            .iter()
            .map(|(_, label)| {
                let of = |fc: &str| {
                    ok.iter()
                        .find(|r| lab(r) == *d && base(r) == *label && (r.float_controls == "off") == (fc == "off"))
                };
                of("on")
                    .map(|r| format!("{} / {} / {}", num(r.registers), num(r.private_bytes), num(r.occupancy)))
                    .or_else(|| {
                        of("off")
                            .map(|r| format!("{} / {} / {}†", num(r.registers), num(r.private_bytes), num(r.occupancy)))
                    })
                    .unwrap_or_else(|| "–".into())
            })
            .collect();
        md += &format!("| {d} | {} |\n", cells.join(" | "));
    }
    md + "\n"
}
