//! `halftrace report`: one report from one or more result folders.

use super::outln;
use crate::outdir::{OutDir, OutMode};
use crate::report::merge;
use std::path::{Path, PathBuf};

#[derive(clap::Args, Clone, Debug, PartialEq)]
pub struct ReportArgs {
    /// Sweep folders holding results.csv.
    #[arg(required = true)]
    pub dirs: Vec<PathBuf>,
    /// Where to write the report (default: the first folder); a folder that is not one of
    /// the inputs also gets the merged results.csv and results.json.
    #[arg(long)]
    pub out: Option<PathBuf>,
}

pub fn report(a: &ReportArgs) -> anyhow::Result<()> {
    let (dirs, out): (&[PathBuf], Option<&Path>) = (&a.dirs, a.out.as_deref());
    // A device report's folder (`device-report`) stands for its sweep.
    let dirs: Vec<PathBuf> = dirs
        .iter()
        .map(|d| {
            let sweep = d.join("sweep");
            if d.join("device-report.json").is_file() && !d.join("results.csv").exists() && sweep.is_dir() {
                sweep
            } else {
                d.clone()
            }
        })
        .collect();
    // The folder written (--out, else the first folder) has one writer: a sweep still running
    // there would overwrite this report, and a second merge would interleave with this one. A
    // folder of its own gets the merged rows too, and is refused if it holds rows already; into
    // one of the folders read, only the report is rendered again.
    let target = out.map(Path::to_path_buf).unwrap_or_else(|| dirs[0].clone());
    let own = out.is_some_and(|o| merge::into_own_folder(&dirs, o));
    let _out = if own { Some(OutDir::claim_for(&target, "--out", OutMode::New, &merge::OUTPUTS)?) } else { None };
    let _lock = if own { None } else { Some(OutDir::claim(&target, if out.is_some() { "--out" } else { "report" })?) };
    let m = merge::merge(&dirs, out)?;
    for s in &m.missing_shards {
        eprintln!("warning: {s} is not among the folders: the report covers only part of that sweep");
    }
    let merged = m.results.map(|r| format!(", merged rows: {}", r.display())).unwrap_or_default();
    outln!("{} rows from {} folder(s); report: {}{merged}", m.rows, dirs.len(), m.report.display());
    Ok(())
}
