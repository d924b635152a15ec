//! `halftrace report`: one report from one or more result folders (a sweep's shards, or
//! sweeps on several devices), refusing rows that two folders both record.

use super::rows::{is_image, read_rows, sorted, write_rows, Row, RowId};
use anyhow::Context;
use std::collections::HashMap;
use std::path::{Path, PathBuf};

/// What a merge wrote.
pub struct Merged {
    pub rows: usize,
    pub report: PathBuf,
    /// The merged `results.csv`, when `out` is a folder of its own.
    pub results: Option<PathBuf>,
}

/// Reads the rows of every folder in `dirs` and renders their report into `out` (default: the
/// first folder); a folder that is not one of the inputs also gets the merged rows and the
/// sweep's images.
pub fn merge(dirs: &[PathBuf], out: Option<&Path>) -> anyhow::Result<Merged> {
    let mut rows: Vec<Row> = Vec::new();
    // Identity of a row → (folder, CSV line) of its first occurrence.
    let mut seen: HashMap<RowId, (usize, usize)> = HashMap::new();
    let mut canon = Vec::new();
    let mut isa_rows: Vec<super::isa::IsaRow> = Vec::new();
    let mut isa_seen: HashMap<(String, String, String, String, String), usize> = HashMap::new();
    for (i, d) in dirs.iter().enumerate() {
        let c = d.canonicalize().unwrap_or_else(|_| d.clone());
        if let Some(j) = canon.iter().position(|x| *x == c) {
            let (a, b) = (dirs[j].display(), d.display());
            anyhow::bail!("{} is named twice (as {a} and {b}): its rows would count twice", c.display());
        }
        canon.push(c);
        let isa = super::isa::read(d)?;
        // A folder of `isa` alone has no results.csv.
        let sweep_rows = if isa.is_some() && !d.join("results.csv").exists() { Vec::new() } else { read_rows(d)? };
        for r in isa.unwrap_or_default() {
            let id =
                (r.device.clone(), r.driver.clone(), r.kernel.clone(), r.packet_impl.clone(), r.float_controls.clone());
            if let Some(f) = isa_seen.get(&id) {
                anyhow::bail!(
                    "{}/isa.json and {}/isa.json both hold {} on {} ({}); report the folders separately",
                    dirs[*f].display(),
                    d.display(),
                    r.kernel,
                    r.device,
                    r.driver
                );
            }
            isa_seen.insert(id, i);
            isa_rows.push(r);
        }
        for (k, r) in sweep_rows.into_iter().enumerate() {
            let id = r.id();
            if let Some(&(f, line)) = seen.get(&id) {
                anyhow::bail!(
                    "{}/results.csv line {line} and {}/results.csv line {} are the same variant ({id}); a merged \
                     report would average or double-count them — remove one, or report the folders separately",
                    dirs[f].display(),
                    d.display(),
                    k + 2
                );
            }
            seen.insert(id, (i, k + 2));
            rows.push(r);
        }
    }
    let out = out.map(Path::to_path_buf).unwrap_or_else(|| dirs[0].clone());
    // Into a folder of its own, the merged rows too (never into a folder it read from).
    let own = !canon.iter().any(|c| out.canonicalize().is_ok_and(|o| o == *c));
    if own {
        anyhow::ensure!(
            !out.join("results.csv").exists(),
            "--out {} already holds results.csv; name a new folder for the merged report",
            out.display()
        );
        anyhow::ensure!(
            !out.join("isa.json").exists(),
            "--out {} already holds isa.json; name a new folder for the merged report",
            out.display()
        );
        if !rows.is_empty() || isa_rows.is_empty() {
            write_rows(&out, &sorted(&rows))?;
        }
        if !isa_rows.is_empty() {
            super::isa::write(&out, &super::isa::sorted(&isa_rows))?;
        }
        // The images a sweep renders (render, heat maps, diff masks) come along from the
        // folder that has them, so the merged report shows what the unsplit one does.
        for d in dirs {
            for e in std::fs::read_dir(d).with_context(|| d.display().to_string())?.flatten() {
                let name = e.file_name().to_string_lossy().to_string();
                if is_image(&name) && !out.join(&name).exists() {
                    crate::fsx::write_atomic(&out.join(&name), &std::fs::read(e.path())?)?;
                }
            }
        }
    }
    super::markdown::render_with(&rows, &isa_rows, &out, dirs)?;
    Ok(Merged {
        rows: rows.len() + isa_rows.len(),
        report: out.join("report.md"),
        results: own.then(|| out.join(if rows.is_empty() { "isa.json" } else { "results.csv" })),
    })
}
