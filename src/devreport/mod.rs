//! `halftrace device-report`: a device's whole report in one command sized to a wall-time
//! budget — `devices` (and `vulkaninfo --summary`, `nvidia-smi` where present), `conformance
//! --quick`, a short `bench`, a sweep that gets the time that remains (the default matrix on the
//! first scene, then the other scenes while time lasts), and `isa` where the driver reports
//! pipeline statistics — into one folder named after the device, with a `report.md` that
//! names the device and driver and gives the headline ratios.
//!
//! Sized by the device's type ([`default_size`], [`big_scene_copies`]): on a CPU
//! implementation (lavapipe) rays at 256×256 and the given scenes; on a GPU rays at 1024×1024
//! and, swept right after the first scene, that scene instanced to at least
//! [`BIG_SCENE_TRIANGLES`] triangles (written into the folder's `scenes/`).
//!
//! Each step runs as a child process of this binary (a crash in a driver ends one step, not
//! the report), its output streamed to `logs/<step>.log`; `device-report.json` records each
//! finished step, so an interrupted report rerun with `--resume` runs only what did not finish
//! or whose files are gone (the sweep continues with its own `--resume`). A child that runs far
//! past the budget is stopped and recorded as such. The folder has one writer
//! ([`OutDir::claim`]); each step's child claims the subfolder it writes.
//!
//! Files: [`state`] (what `device-report.json` records, which steps are finished),
//! [`steps`] (the child processes), [`markdown`] (the report).

use crate::gpu::{self, DeviceInfo};
use crate::outdir::{Claimed, OutDir, OutMode, Outputs};
use crate::report::{self, Row};
use crate::sweep;
use anyhow::Context;
use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

mod child;
mod markdown;
mod report_run;
mod state;
mod steps;

pub use child::Child;
use markdown::*;
use report_run::*;
use state::*;
pub use state::{RunRecord, State, StepRecord, STEPS};
use steps::*;

/// What the report runs.
#[derive(Clone, Debug)]
pub struct Options {
    /// Vulkan device (index or name substring; default: the device every command picks).
    pub device: Option<String>,
    /// Wall-time budget of the whole report, seconds.
    pub budget_s: f64,
    /// Output folder (default `<reports>/<device>`).
    pub out: Option<PathBuf>,
    pub reports: PathBuf,
    /// The scenes: the first gets conformance, the bench and the sweep's default matrix; the
    /// others are swept after it while the budget lasts.
    pub scenes: Vec<PathBuf>,
    /// Image size of the bench's and the sweep's ray sets (default: [`default_size`]).
    pub width: Option<u32>,
    pub height: Option<u32>,
    pub resume: bool,
    pub force: bool,
    /// Treat device features as missing in every step (testing).
    pub mask_features: Vec<String>,
    /// A step's command line from its typed [`Child`] (`commands` builds it from each
    /// command's own arguments).
    pub argv: fn(&Child) -> crate::argv::Argv,
}

/// The rays' image side where none is given: 256 on a CPU implementation (lavapipe: 65k rays
/// are tens of ms per dispatch there, and the whole report fits a few minutes on two cores);
/// 1024 on a GPU, where 1M rays keep a dispatch of a device 100–1000× faster than lavapipe at
/// a millisecond or so, far above its ~10 µs launch and timestamp overhead, while each job's
/// validation against the CPU reference (1M rays on the host's cores) stays around a second,
/// so the default 8-minute budget still leaves the sweep most of its time. 2048² would
/// quadruple the validation for no gain in the timings' resolution.
pub fn default_size(kind: &str) -> u32 {
    if kind == "cpu" {
        256
    } else {
        1024
    }
}

/// The fewest triangles of a scene a GPU's sweep should hold: past the last-level cache of a
/// large GPU (an H200's 50 MB holds every shared scene's f32 BVH but igea's, the largest at
/// 269k triangles), where node bytes — what the reduced-precision layouts save — decide speed.
pub const BIG_SCENE_TRIANGLES: usize = 300_000;

/// Copies of a scene of `n` triangles that reach [`BIG_SCENE_TRIANGLES`] (`None`: it does
/// already). The teapot's 6,320 take 48: 303,360 triangles.
pub fn big_scene_copies(n: usize) -> Option<usize> {
    (n < BIG_SCENE_TRIANGLES).then(|| BIG_SCENE_TRIANGLES.div_ceil(n.max(1)))
}

/// The instanced scene a GPU's report adds after the first scene (path, source scene, copies),
/// or `None` on a CPU device or where the first scene is big enough.
fn big_scene(
    dev: &DeviceInfo,
    out: &Path,
    first: &Path,
) -> anyhow::Result<Option<(PathBuf, crate::scene::Scene, usize)>> {
    if dev.kind == "cpu" {
        return Ok(None);
    }
    let scene = crate::scene::load(first).with_context(|| format!("loading {} to instance it", first.display()))?;
    Ok(big_scene_copies(scene.len()).map(|c| (out.join("scenes").join(format!("{}-x{c}.glb", scene.name)), scene, c)))
}

/// A folder name from a device name: lower case letters, digits and single dashes.
pub fn slug(name: &str) -> String {
    let mut s = String::new();
    for c in name.chars().flat_map(char::to_lowercase) {
        if c.is_ascii_alphanumeric() {
            s.push(c);
        } else if !s.ends_with('-') && !s.is_empty() {
            s.push('-');
        }
    }
    let s = s.trim_end_matches('-').to_string();
    if s.is_empty() {
        "device".into()
    } else {
        s
    }
}

/// The device the report is for: the one `--device` names, or the one every command picks.
pub fn choose_device(want: Option<&str>) -> anyhow::Result<DeviceInfo> {
    let mut list = gpu::list_devices().context("listing Vulkan devices")?;
    let i = gpu::pick(&list, want).map_err(|e| {
        let all: Vec<String> = list.iter().map(|d| format!("{}: {}", d.index, d.name)).collect();
        anyhow::anyhow!("{e} (found: {})", if all.is_empty() { "none".into() } else { all.join("; ") })
    })?;
    let d = list.swap_remove(i);
    anyhow::ensure!(
        !d.compile_only,
        "{} is compile-only (RADV's null device): it runs nothing; `halftrace isa --device {}` reads its compiler's \
         statistics",
        d.name,
        d.index
    );
    Ok(d)
}

/// The summary of a finished (or resumed) report.
pub struct Summary {
    pub out: PathBuf,
    pub state: State,
    pub seconds: f64,
    pub sweep_rows: usize,
    pub sweep_jobs: usize,
}

/// Runs the report (or what an interrupted one left) into its folder.
pub fn run(opts: &Options, exe: &Path, mut say: impl FnMut(&str)) -> anyhow::Result<Summary> {
    let start = Instant::now();
    let mut r = open(opts, exe, &mut say)?;
    let deadline = start + Duration::from_secs_f64(opts.budget_s);
    r.devices(&mut say)?;
    r.conformance(&mut say)?;
    r.bench(&mut say)?;
    // The sweep gets what the budget has left, less a share for isa and the report; at least
    // one job runs (every report has a row).
    let isa_runs = r.dev.pipeline_statistics;
    let reserve = if isa_runs { (opts.budget_s * 0.1).max(20.0) } else { 2.0 };
    let left = deadline.saturating_duration_since(Instant::now()).as_secs_f64() - reserve;
    let jobs = r.sweep(left.max(1.0), &mut say)?;
    r.isa(isa_runs, &mut say)?;
    // The sweep's report again, with the compiler's view beside it when isa ran.
    if r.out.join("sweep/results.csv").is_file() {
        let _sweep = OutDir::claim(&r.out.join("sweep"), "the sweep folder")?;
        report::merge::merge(&[r.out.join("sweep")], None).context("rendering sweep/report.md")?;
    }
    let seconds = start.elapsed().as_secs_f64();
    if let Some(run) = r.state.runs.last_mut() {
        run.seconds = seconds;
    }
    save(&r.out, &r.state)?;
    let rows = report::read_rows(&r.out.join("sweep")).unwrap_or_default();
    let md = markdown(&r.state, &r.dev, &rows, &r.out, jobs, r.big_note.as_deref());
    crate::fsx::write_atomic(&r.out.join("report.md"), md.as_bytes())?;
    Ok(Summary { out: r.out.clone(), state: r.state, seconds, sweep_rows: rows.len(), sweep_jobs: jobs })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn device_names_become_folder_names() {
        assert_eq!(slug("NVIDIA H200"), "nvidia-h200");
        assert_eq!(slug("llvmpipe (LLVM 15.0.6, 256 bits)"), "llvmpipe-llvm-15-0-6-256-bits");
        assert_eq!(slug("../../etc"), "etc");
        assert_eq!(slug("  "), "device");
    }
}
