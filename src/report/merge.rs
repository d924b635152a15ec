//! `halftrace report`: one report from one or more result folders (a sweep's shards, or
//! sweeps on several devices), refusing rows that two folders both record.

use super::rows::{is_image, read_rows, sorted, write_rows, Row, RowId};
use crate::outdir::Outputs;
use anyhow::Context;
use std::collections::HashMap;
use std::path::{Path, PathBuf};

/// What a merge wrote.
pub struct Merged {
    pub rows: usize,
    pub report: PathBuf,
    /// The merged `results.csv`, when `out` is a folder of its own.
    pub results: Option<PathBuf>,
    /// Shards of a sweep that are not among the folders ("shard 2 of 4 of sweep …").
    pub missing_shards: Vec<String>,
}

/// `shard.json` in a shard's folder: which share of which sweep (a hash of its whole
/// configuration) it holds.
#[derive(Clone, Debug, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub struct ShardManifest {
    pub k: usize,
    pub n: usize,
    pub config: String,
}

/// The shards among `dirs`: all of one sweep (else refused, naming both), each once; returns
/// the shards of that sweep that are missing.
fn check_shards(dirs: &[PathBuf]) -> anyhow::Result<Vec<String>> {
    let mut seen: Vec<(&PathBuf, ShardManifest)> = Vec::new();
    for d in dirs {
        let p = d.join("shard.json");
        if !p.exists() {
            continue;
        }
        let text = String::from_utf8(crate::fsx::read_regular(&p).with_context(|| format!("reading {}", p.display()))?)
            .with_context(|| p.display().to_string())?;
        let m: ShardManifest =
            serde_json::from_str(&text).with_context(|| format!("{}: not a shard manifest", p.display()))?;
        if let Some((other, o)) = seen.iter().find(|(_, o)| o.config != m.config || o.n != m.n) {
            anyhow::bail!(
                "{} is shard {}/{} of sweep {} but {} is shard {}/{} of sweep {}: shards of different sweeps do not \
                 merge into one sweep's report; report them separately",
                other.display(),
                o.k,
                o.n,
                o.config,
                d.display(),
                m.k,
                m.n,
                m.config
            );
        }
        if let Some((other, _)) = seen.iter().find(|(_, o)| o.k == m.k) {
            anyhow::bail!("{} and {} are both shard {}/{}", other.display(), d.display(), m.k, m.n);
        }
        seen.push((d, m));
    }
    let Some((_, first)) = seen.first() else { return Ok(Vec::new()) };
    Ok((1..=first.n)
        .filter(|k| !seen.iter().any(|(_, m)| m.k == *k))
        .map(|k| format!("shard {k} of {} of sweep {}", first.n, first.config))
        .collect())
}

/// What a merge writes into a folder of its own besides the report: the merged rows. A folder
/// that already holds rows is someone's results, never overwritten (there is no `--force`:
/// merged rows go into a new folder).
pub const OUTPUTS: Outputs = Outputs {
    command: "report",
    owns: |n| ["results.csv", "results.json", "isa.csv", "isa.json"].contains(&n),
    folders: &[],
    alone: false,
    resume: None,
    force: false,
};

/// Whether `out` is a folder of its own, not one of `dirs` (it gets the merged rows too).
pub fn into_own_folder(dirs: &[PathBuf], out: &Path) -> bool {
    let out = out.canonicalize();
    !dirs.iter().any(|d| out.as_ref().is_ok_and(|o| *o == d.canonicalize().unwrap_or_else(|_| d.clone())))
}

/// Reads the rows of every folder in `dirs` and renders their report into `out` (default: the
/// first folder); a folder that is not one of the inputs ([`into_own_folder`]) also gets the
/// merged rows and the sweep's images. The caller has claimed `out` ([`OUTPUTS`]).
pub fn merge(dirs: &[PathBuf], out: Option<&Path>) -> anyhow::Result<Merged> {
    let missing_shards = check_shards(dirs)?;
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
        if isa.is_none() && !d.join("results.csv").exists() {
            let other =
                ["estimate.md", "memory.md", "conformance.md", "bench.md"].into_iter().find(|f| d.join(f).is_file());
            anyhow::bail!(
                "{}: not found — `report` renders sweep folders (results.csv) and isa folders (isa.json){}",
                d.join("results.csv").display(),
                other
                    .map(|f| format!("; this folder's {f} is its own command's report, already rendered"))
                    .unwrap_or_default()
            );
        }
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
    let own = into_own_folder(dirs, &out);
    if own {
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
    if !missing_shards.is_empty() {
        // Said at the top of the report, too: its tables cover only part of that sweep.
        let p = out.join("report.md");
        let md = std::fs::read_to_string(&p).with_context(|| p.display().to_string())?;
        let (title, rest) = md.split_once("\n\n").unwrap_or((&md, ""));
        let note = format!(
            "**Incomplete sweep:** not among the folders: {}. Every table covers only the shards given.",
            missing_shards.join("; ")
        );
        crate::fsx::write_atomic(&p, format!("{title}\n\n{note}\n\n{rest}").as_bytes())?;
    }
    Ok(Merged {
        rows: rows.len() + isa_rows.len(),
        report: out.join("report.md"),
        results: own.then(|| out.join(if rows.is_empty() { "isa.json" } else { "results.csv" })),
        missing_shards,
    })
}
