//! `report.md`: the report of one or more result folders — provenance, failures and skips,
//! the tables ([`super::tables`]), the plots ([`super::plots`]) and the images a sweep
//! rendered.

use super::plots;
use super::rows::{sorted, Row, Status};
use super::tables;
use crate::layout::LayoutId;
use std::path::{Path, PathBuf};

/// Renders `report.md` and the plots into `out` from `rows` (from the folders `sources`), with
/// the compiler view of every `isa.json` among the sources.
pub fn render(rows: &[Row], out: &Path, sources: &[PathBuf]) -> anyhow::Result<()> {
    let mut isa_rows = Vec::new();
    for s in sources {
        isa_rows.extend(super::isa::read(s)?.unwrap_or_default());
    }
    render_with(rows, &isa_rows, out, sources)
}

/// [`render`] with the compiler-view rows given.
pub fn render_with(
    rows: &[Row],
    isa_rows: &[super::isa::IsaRow],
    out: &Path,
    sources: &[PathBuf],
) -> anyhow::Result<()> {
    std::fs::create_dir_all(out)?;
    let rows = &sorted(rows);
    let r = tables::ratios(rows);
    let by_b = tables::series(&r, true);
    let by_p = tables::series(&r, false);
    let mut md = String::from("# halftrace sweep report\n\n");
    let from: Vec<String> = sources.iter().map(|p| format!("`{}`", p.display())).collect();
    md += &format!("Rendered from {} result row(s) in: {}.\n\n", rows.len() + isa_rows.len(), from.join(", "));
    let mut devices: Vec<(String, String)> = rows.iter().map(|r| (r.device.clone(), r.driver.clone())).collect();
    devices.sort();
    devices.dedup();
    for (d, drv) in &devices {
        md += &format!("- device **{d}**, driver {drv}\n");
    }
    let mut versions: Vec<String> = rows.iter().map(|r| format!("{} ({})", r.version, r.commit)).collect();
    versions.sort();
    versions.dedup();
    md += &format!("- halftrace {}\n", versions.join(", "));
    let failed: Vec<&Row> = rows.iter().filter(|r| r.status.is_failed()).collect();
    let skipped: Vec<&Row> = rows.iter().filter(|r| r.status.is_skipped()).collect();
    let ok = rows.len() - failed.len() - skipped.len();
    md += &format!("- variants: {ok} ok, {} failed validation, {} skipped\n\n", failed.len(), skipped.len());
    for f in &failed {
        md += &format!("**FAILED**: {} {} {}: {}\n\n", f.scene, f.rays, f.kernel, f.status);
    }
    let why = |s: &Status| match s {
        Status::Skipped(why) => why.clone(),
        other => other.to_string(),
    };
    let mut skip_lines: Vec<String> =
        skipped.iter().map(|f| format!("{} on {}: {}", f.kernel, f.device, why(&f.status))).collect();
    skip_lines.dedup();
    for l in skip_lines {
        md += &format!("Skipped: {l}\n\n");
    }
    let mut estimates = Vec::new();
    let mut memory = Vec::new();
    for s in sources {
        estimates.extend(super::estimate::read(s)?.unwrap_or_default());
        memory.extend(super::memory::read(s)?.unwrap_or_default());
    }
    // The answer the harness exists for, first: which layout wins on each GPU's memory.
    let verdict = super::memory::verdict_section(&memory);
    md += &verdict;
    let estimate_section = |md: &mut String| -> anyhow::Result<()> {
        if !estimates.is_empty() {
            *md += "\n";
            *md += &super::estimate::section(&estimates)
                .replacen("# Estimated", "## Estimated", 1)
                .replace("\n## ", "\n### ");
            *md += "\n![Estimated cycles per ray](estimate.png)\n";
            super::estimate::plot(&estimates, out)?;
        }
        Ok(())
    };
    if rows.is_empty() && !isa_rows.is_empty() {
        // Only the compiler's view (isa folders).
        md += &super::isa::section(isa_rows, 2);
        estimate_section(&mut md)?;
        crate::fsx::write_atomic(&out.join("report.md"), md.as_bytes())?;
        write_headline(out, &devices, &verdict, isa_rows)?;
        return isa_files(isa_rows, out);
    }
    md += &tables::headline(&by_b, &by_p);
    md += &tables::separated_effects(rows);
    let points = tables::layout_points(rows);
    md += &tables::layouts_table(&points);
    md += &tables::against_baselines(rows);
    md += &tables::every_row(rows);
    md += "\n![Mrays/s per variant](mrays.png) ![memory per layout and B](memory.png)\n";
    md += &images(out);
    if !isa_rows.is_empty() {
        md += "\n";
        md += &super::isa::section(isa_rows, 2);
        isa_files(isa_rows, out)?;
    }
    estimate_section(&mut md)?;
    crate::fsx::write_atomic(&out.join("report.md"), md.as_bytes())?;
    write_headline(out, &devices, &(verdict + &tables::headline(&by_b, &by_p)), isa_rows)?;
    plots::plots(rows, &by_b, &by_p, out)?;
    plots::layouts_plot(&points, out)
}

/// The compiler view's plots and, in a folder that holds the rows (`isa.json`), its `isa.md`
/// rendered again from them, so the folder's documents all say the same.
fn isa_files(isa_rows: &[super::isa::IsaRow], out: &Path) -> anyhow::Result<()> {
    if out.join("isa.json").is_file() {
        super::isa::render(isa_rows, out)
    } else {
        super::isa::plot(isa_rows, out)
    }
}

/// `headline.md`: the headline ratios (`sweep`, from `report.md`) and the compiler view across
/// devices at B = 4 — what the README's first screen links to, so a kernel change needs no
/// README commit.
fn write_headline(
    out: &Path,
    devices: &[(String, String)],
    sweep: &str,
    isa_rows: &[super::isa::IsaRow],
) -> anyhow::Result<()> {
    let mut md = String::from("# halftrace headline\n\nWritten by halftrace with [report.md](report.md)");
    if devices.is_empty() {
        md += ".\n\n";
    } else {
        let d: Vec<String> = devices.iter().map(|(d, drv)| format!("{d} ({drv})")).collect();
        md += &format!("; timed on {}.\n\n", d.join(", "));
    }
    md += sweep;
    md += &super::isa::headline(isa_rows);
    crate::fsx::write_atomic(&out.join("headline.md"), md.as_bytes())
}

/// The images section: those of the sweep's images that exist in `out`.
fn images(out: &Path) -> String {
    let mut imgs = vec!["render.png".to_string()];
    imgs.extend(LayoutId::all().map(|l| format!("heat_{l}.png")));
    imgs.extend(LayoutId::all().filter(|&l| l != LayoutId::f32()).map(|l| format!("diff_{l}_vs_f32.png")));
    imgs.retain(|f| out.join(f).exists());
    if imgs.is_empty() {
        return String::new();
    }
    let mut md = String::from(concat!(
        "\n## Images\n\nShaded primary render (f32 hits); nodes visited per pixel of each layout (B = 4, P = 1, ",
        "default math; one colour scale); pixels whose hit differs from f32 (white), black when none does.\n\n",
    ));
    for i in imgs {
        md += &format!("![{i}]({i}) ");
    }
    md + "\n"
}
