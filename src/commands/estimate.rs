//! `halftrace estimate`: ACO's cycle estimate of each kernel taken apart per loop, on RADV
//! null devices, and weighted by the work of real rays; writes estimate.md, estimate.csv and
//! estimate-rays.csv.

use super::outln;
use crate::cli::EstimateArgs;
use crate::estimate;
use crate::isa::{self, Matrix};
use crate::outdir::{OutDir, OutMode, Outputs};
use std::time::Instant;

const FILES: &[&str] =
    &["estimate.md", "estimate.csv", "estimate-rays.csv", "estimate-rays.json", "estimate.png", "estimate.svg"];

/// Like `isa`'s, the folder may be a sweep's or an isa run's: only its own files are refused.
const OUTPUTS: Outputs = Outputs {
    command: "estimate",
    owns: |n| FILES.contains(&n),
    folders: &[],
    alone: false,
    resume: None,
    force: true,
};

pub fn estimate(a: &EstimateArgs) -> anyhow::Result<()> {
    let t0 = Instant::now();
    let matrix = Matrix::parse(&a.matrix)
        .ok_or_else(|| anyhow::anyhow!("--matrix {}: layouts, cover, default or full", a.matrix))?;
    let out = a.out.clone().unwrap_or_else(|| crate::outdir::default_out(Some("estimate")));
    let _out = OutDir::claim_for(&out, "--out", OutMode::from_flags(false, a.force)?, &OUTPUTS)?;
    let exe = std::env::current_exe()?;
    let known = isa::known_families(&exe);
    let families: Vec<String> = a.family.iter().map(|f| f.to_lowercase()).collect();
    for f in &families {
        anyhow::ensure!(
            known.iter().any(|k| k.name == f),
            "--family '{f}': not an AMD family the installed RADV opens a null device for ({})",
            known.iter().map(|k| k.name).collect::<Vec<_>>().join(", ")
        );
    }
    let kinds: Vec<crate::rays::RayKind> = a
        .rays
        .iter()
        .map(|k| k.parse().map_err(|e| anyhow::anyhow!("--rays {k}: {e}")))
        .collect::<anyhow::Result<_>>()?;
    anyhow::ensure!(a.res > 0, "--res must be at least 1");
    let mut sets = Vec::new();
    for scene in &a.scene {
        for k in &kinds {
            sets.push(
                estimate::RaySet::load(scene, k, a.res).map_err(|e| anyhow::anyhow!("{}: {e:#}", scene.display()))?,
            );
        }
    }
    let (rows, ray_rows) = estimate::run(&exe, &families, matrix, &a.layouts, &sets)?;
    crate::fsx::write_atomic(&out.join("estimate.csv"), &estimate::csv(&rows)?)?;
    crate::report::estimate::write(&ray_rows, &out)?;
    crate::report::estimate::plot(&ray_rows, &out)?;
    let md = estimate::markdown(&rows) + &crate::report::estimate::section(&ray_rows);
    crate::fsx::write_atomic(&out.join("estimate.md"), md.as_bytes())?;
    let failed: Vec<String> = rows
        .iter()
        .map(|r| &r.status)
        .chain(ray_rows.iter().map(|r| &r.status))
        .filter(|s| s.is_failed())
        .map(|s| s.to_string())
        .collect();
    outln!(
        "{} kernels on {} famil{} taken apart ({} rebuilt exactly), {} estimated on {} ray set(s) in {:.1} s; report: {}",
        rows.len(),
        families.len(),
        if families.len() == 1 { "y" } else { "ies" },
        rows.iter().filter(|r| r.status.is_ok()).count(),
        ray_rows.iter().filter(|r| r.status.is_ok()).count(),
        sets.len(),
        t0.elapsed().as_secs_f64(),
        out.join("estimate.md").display()
    );
    anyhow::ensure!(failed.is_empty(), "{} kernel(s) failed:\n{}", failed.len(), failed.join("\n"));
    Ok(())
}
