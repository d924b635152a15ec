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

mod markdown;
mod state;
mod steps;

use markdown::*;
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
    let mode = OutMode::from_flags(opts.resume, opts.force)?;
    anyhow::ensure!(!opts.scenes.is_empty(), "at least one scene is needed");
    for s in &opts.scenes {
        anyhow::ensure!(s.is_file(), "--scene {}: not a readable file", s.display());
    }
    crate::units::check_seconds("--budget", opts.budget_s).map_err(anyhow::Error::msg)?;
    // A folder named by --out is claimed (and refused when it is no folder, another run's, or
    // holds files without --resume or --force) before Vulkan is opened; the default one is
    // known only once the device is.
    let named = match &opts.out {
        Some(o) => Some(OutDir::claim_for(o, "--out", mode, &OUTPUTS)?),
        None => None,
    };
    let start = Instant::now();
    let dev = choose_device(opts.device.as_deref())?;
    let (width, height) =
        (opts.width.unwrap_or(default_size(&dev.kind)), opts.height.unwrap_or(default_size(&dev.kind)));
    crate::rays::check_image_size(width, height).map_err(anyhow::Error::msg)?;
    // Held to the end; each step's child locks the subfolder it writes (conformance/, sweep/).
    let claimed = match named {
        Some(c) => c,
        None => OutDir::claim_for(&opts.reports.join(slug(&dev.name)), "the report folder", mode, &OUTPUTS)?,
    };
    let out = claimed.path().to_path_buf();
    let big = big_scene(&dev, &out, &opts.scenes[0])?;
    let mut scene_paths = opts.scenes.clone();
    let mut big_note = None;
    if let Some((path, scene, copies)) = &big {
        scene_paths.insert(1, path.clone());
        big_note = Some(format!(
            "{}: {} instanced ×{copies} ({} triangles; `halftrace instance`), swept on a GPU to be past its caches",
            crate::scene::scene_name(path),
            scene.name,
            scene.len() * copies
        ));
    }
    let scenes: Vec<String> = scene_paths.iter().map(|p| p.display().to_string()).collect();
    let mut state = prepare(&claimed, &dev, &scenes, (width, height))?;
    if let Some((path, scene, copies)) = big.filter(|(p, _, _)| !p.is_file()) {
        say(&format!("instancing {} ×{copies} into {}", scene.name, path.display()));
        std::fs::create_dir_all(out.join("scenes"))
            .with_context(|| format!("creating {}", out.join("scenes").display()))?;
        crate::fsx::write_atomic(&path, &crate::scene::instance::instanced_glb(&scene, copies, 1))?;
    }
    for step in STEPS {
        if let Some(f) = missing(&state, &out, step) {
            say(&format!("{step} is recorded as finished but {f} is missing: it runs again"));
        }
    }
    std::fs::create_dir_all(out.join("logs")).with_context(|| format!("creating {}", out.join("logs").display()))?;
    let started_unix =
        std::time::SystemTime::now().duration_since(std::time::UNIX_EPOCH).map(|d| d.as_secs()).unwrap_or(0);
    state.runs.push(RunRecord { started_unix, budget_s: opts.budget_s, seconds: 0.0 });
    save(&out, &state)?;
    let device_arg = dev.index.to_string();
    let deadline = start + Duration::from_secs_f64(opts.budget_s);
    let mut common: Vec<String> = vec!["--device".into(), device_arg.clone()];
    for m in &opts.mask_features {
        common.extend(["--mask-feature".into(), m.clone()]);
    }
    let first = scenes[0].clone();
    let size = |v: &mut Vec<String>| {
        v.extend(["--width".into(), width.to_string(), "--height".into(), height.to_string()]);
    };
    let runner = Steps { exe, out: &out };

    // devices, and what the machine's own tools say.
    if !finished(&state, &out, "devices") {
        say("devices");
        let mut args: Vec<String> = vec!["devices".into()];
        for m in &opts.mask_features {
            args.extend(["--mask-feature".into(), m.clone()]);
        }
        let r = runner.run("devices", &args, Some("devices.txt"), HANG)?;
        for (tool, args, file) in [
            ("vulkaninfo", &["--summary"][..], "vulkaninfo.txt"),
            (
                "nvidia-smi",
                &["--query-gpu=name,driver_version,memory.total,clocks.max.sm", "--format=csv"][..],
                "nvidia-smi.txt",
            ),
        ] {
            if let Some(t) = find_tool(exe, tool) {
                let _ = runner.tool(&t, args, file);
            }
        }
        record(&mut state, "devices", r);
        save(&out, &state)?;
    }

    if !finished(&state, &out, "conformance") {
        say("conformance --quick");
        let mut args: Vec<String> = vec!["conformance".into(), "--quick".into(), "--scene".into(), first.clone()];
        args.extend(common.iter().cloned());
        // The folder is the report's own: a rerun (after an interrupt, or a deleted file)
        // replaces what an earlier one left there.
        args.extend(["--out".into(), out.join("conformance").display().to_string(), "--force".into()]);
        let mut r = runner.run("conformance", &args, None, HANG)?;
        if let Some(c) = conformance_counts(&out.join("conformance/conformance.csv")) {
            r.status = format!("{} ({c})", r.status);
        }
        record(&mut state, "conformance", r);
        save(&out, &state)?;
    }

    if !finished(&state, &out, "bench") {
        say("bench (short)");
        let mut args: Vec<String> = vec![
            "bench".into(),
            "--scene".into(),
            first.clone(),
            "--rays".into(),
            "primary,ao".into(),
            "--rounds".into(),
            "3".into(),
            "--repeat".into(),
            "3".into(),
            "--device".into(),
            device_arg.clone(),
            "--out".into(),
            out.join("bench.md").display().to_string(),
        ];
        size(&mut args);
        let r = runner.run("bench", &args, None, HANG)?;
        record(&mut state, "bench", r);
        save(&out, &state)?;
    }

    // The sweep gets what the budget has left, less a share for isa and the report; at least
    // one job runs (every report has a row).
    let isa_runs = dev.pipeline_statistics;
    let cfg = sweep::Config { scenes: scene_paths.clone(), width, height, ..Default::default() };
    let jobs = sweep::jobs::list(&cfg.check().context("the sweep's configuration")?).len();
    if !finished(&state, &out, "sweep") {
        let reserve = if isa_runs { (opts.budget_s * 0.1).max(20.0) } else { 2.0 };
        let left = deadline.saturating_duration_since(Instant::now()).as_secs_f64() - reserve;
        let budget = left.max(1.0);
        say(&format!("sweep ({jobs} jobs, budget {budget:.0} s)"));
        let dir = out.join("sweep");
        let mut args: Vec<String> = vec!["sweep".into(), "--quiet".into()];
        for s in &scenes {
            args.extend(["--scene".into(), s.clone()]);
        }
        size(&mut args);
        args.extend(common.iter().cloned());
        args.extend([
            "--kernel-timeout".into(),
            "120".into(),
            "--budget".into(),
            format!("{budget:.1}"),
            "--out".into(),
            dir.display().to_string(),
        ]);
        // Rows to keep: resumed; none, but an earlier run's report or isa files: the sweep
        // replaces its own and leaves isa's.
        args.extend(sweep::OUTPUTS.mode_to_continue(&dir).flag().map(String::from));
        // The sweep stops itself between jobs; a job far longer than the budget is stopped.
        let limit = Duration::from_secs_f64(budget + (budget / 2.0).max(120.0));
        let mut r = runner.run("sweep", &args, None, limit)?;
        let rows = report::read_rows(&dir).map(|r| r.len()).unwrap_or(0);
        // Partial only when the sweep ended well with jobs left (its budget ran out); a sweep
        // that failed stays failed, its log named, whatever rows it left.
        let ended_well = r.done && r.status == "ok";
        if ended_well && rows < jobs {
            r.done = false;
            r.status = format!("partial: {rows} of {jobs} jobs (budget reached; --resume runs the rest)");
        } else if ended_well {
            r.status = format!("ok: {rows} jobs");
        } else {
            r.done = false;
            r.status = format!("{}; {rows} of {jobs} jobs", r.status);
        }
        record(&mut state, "sweep", r);
        save(&out, &state)?;
    }

    if !finished(&state, &out, "isa") {
        let r = if isa_runs {
            say("isa");
            let mut args: Vec<String> = vec!["isa".into(), "--quiet".into(), "--device".into(), device_arg.clone()];
            args.extend(["--out".into(), out.join("sweep").display().to_string(), "--force".into()]);
            runner.run("isa", &args, None, HANG)?
        } else {
            StepRecord {
                status: "skipped: the driver does not report pipeline statistics \
                         (VK_KHR_pipeline_executable_properties)"
                    .into(),
                done: true,
                ..Default::default()
            }
        };
        record(&mut state, "isa", r);
        save(&out, &state)?;
    }

    // The sweep's report again, with the compiler's view beside it when isa ran.
    if out.join("sweep/results.csv").is_file() {
        let _sweep = OutDir::claim(&out.join("sweep"), "the sweep folder")?;
        report::merge::merge(&[out.join("sweep")], None).context("rendering sweep/report.md")?;
    }
    let seconds = start.elapsed().as_secs_f64();
    if let Some(r) = state.runs.last_mut() {
        r.seconds = seconds;
    }
    save(&out, &state)?;
    let rows = report::read_rows(&out.join("sweep")).unwrap_or_default();
    let md = markdown(&state, &dev, &rows, &out, jobs, big_note.as_deref());
    crate::fsx::write_atomic(&out.join("report.md"), md.as_bytes())?;
    Ok(Summary { out, state, seconds, sweep_rows: rows.len(), sweep_jobs: jobs })
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
