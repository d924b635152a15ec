//! One report's run, step by step: the folder and device readied ([`open`]), then each step
//! run as its child unless a resumed report finished it.

use super::*;
use crate::rays::RayKind;

/// A report being run: its device, folder, state and settings.
pub(super) struct Run<'a> {
    pub(super) opts: &'a Options,
    pub(super) exe: &'a Path,
    pub(super) dev: DeviceInfo,
    /// Held to the end; each step's child locks the subfolder it writes.
    _claimed: Claimed,
    pub(super) out: PathBuf,
    pub(super) state: State,
    pub(super) scenes: Vec<PathBuf>,
    pub(super) size: (u32, u32),
    pub(super) big_note: Option<String>,
}

/// Checks the options, claims the folder, picks the device, instances the big scene a GPU
/// gets, and records the run's start: the report ready for its steps.
pub(super) fn open<'a>(opts: &'a Options, exe: &'a Path, say: &mut impl FnMut(&str)) -> anyhow::Result<Run<'a>> {
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
    let dev = choose_device(opts.device.as_deref())?;
    let size = (opts.width.unwrap_or(default_size(&dev.kind)), opts.height.unwrap_or(default_size(&dev.kind)));
    crate::rays::check_image_size(size.0, size.1).map_err(anyhow::Error::msg)?;
    let claimed = match named {
        Some(c) => c,
        None => OutDir::claim_for(&opts.reports.join(slug(&dev.name)), "the report folder", mode, &OUTPUTS)?,
    };
    let out = claimed.path().to_path_buf();
    let big = big_scene(&dev, &out, &opts.scenes[0])?;
    let mut scenes = opts.scenes.clone();
    let mut big_note = None;
    if let Some((path, scene, copies)) = &big {
        scenes.insert(1, path.clone());
        big_note = Some(format!(
            "{}: {} instanced ×{copies} ({} triangles; `halftrace instance`), swept on a GPU to be past its caches",
            crate::scene::scene_name(path),
            scene.name,
            scene.len() * copies
        ));
    }
    let names: Vec<String> = scenes.iter().map(|p| p.display().to_string()).collect();
    let mut state = prepare(&claimed, &dev, &names, size)?;
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
    Ok(Run { opts, exe, dev, _claimed: claimed, out, state, scenes, size, big_note })
}

impl Run<'_> {
    fn steps(&self) -> Steps<'_> {
        Steps { exe: self.exe, out: &self.out }
    }

    fn device(&self) -> String {
        self.dev.index.to_string()
    }

    /// Runs `child` as step `name` (stopped after `limit`) unless finished; `then` may amend
    /// its record before it is saved.
    fn step(
        &mut self,
        name: &str,
        child: Child,
        stdout_file: Option<&str>,
        limit: Duration,
        then: impl FnOnce(&Path, &mut StepRecord),
    ) -> anyhow::Result<()> {
        let args = (self.opts.argv)(&child).0;
        let mut r = self.steps().run(name, &args, stdout_file, limit)?;
        then(&self.out, &mut r);
        record(&mut self.state, name, r);
        save(&self.out, &self.state)
    }

    /// `devices`, and what the machine's own tools say.
    pub(super) fn devices(&mut self, say: &mut impl FnMut(&str)) -> anyhow::Result<()> {
        if finished(&self.state, &self.out, "devices") {
            return Ok(());
        }
        say("devices");
        let child = Child::Devices { mask_features: self.opts.mask_features.clone() };
        let exe = self.exe;
        self.step("devices", child, Some("devices.txt"), HANG, |out, _| {
            let steps = Steps { exe, out };
            for (tool, args, file) in [
                ("vulkaninfo", &["--summary"][..], "vulkaninfo.txt"),
                (
                    "nvidia-smi",
                    &["--query-gpu=name,driver_version,memory.total,clocks.max.sm", "--format=csv"][..],
                    "nvidia-smi.txt",
                ),
            ] {
                if let Some(t) = find_tool(exe, tool) {
                    let _ = steps.tool(&t, args, file);
                }
            }
        })
    }

    /// `conformance --quick` on the first scene.
    pub(super) fn conformance(&mut self, say: &mut impl FnMut(&str)) -> anyhow::Result<()> {
        if finished(&self.state, &self.out, "conformance") {
            return Ok(());
        }
        say("conformance --quick");
        let child = Child::Conformance {
            scene: self.scenes[0].clone(),
            device: self.device(),
            mask_features: self.opts.mask_features.clone(),
            out: self.out.join("conformance"),
        };
        self.step("conformance", child, None, HANG, |out, r| {
            if let Some(c) = conformance_counts(&out.join("conformance/conformance.csv")) {
                r.status = format!("{} ({c})", r.status);
            }
        })
    }

    /// A short bench on the first scene.
    pub(super) fn bench(&mut self, say: &mut impl FnMut(&str)) -> anyhow::Result<()> {
        if finished(&self.state, &self.out, "bench") {
            return Ok(());
        }
        say("bench (short)");
        let child = Child::Bench {
            scene: self.scenes[0].clone(),
            device: self.device(),
            rays: vec![RayKind::Primary, RayKind::Ao],
            rounds: 3,
            repeat: 3,
            width: self.size.0,
            height: self.size.1,
            out: self.out.join("bench.md"),
        };
        self.step("bench", child, None, HANG, |_, _| {})
    }

    /// The sweep of every scene in `budget` seconds; returns its jobs.
    pub(super) fn sweep(&mut self, budget: f64, say: &mut impl FnMut(&str)) -> anyhow::Result<usize> {
        let (width, height) = self.size;
        let cfg = sweep::Config { scenes: self.scenes.clone(), width, height, ..Default::default() };
        let jobs = sweep::jobs::list(&cfg.check().context("the sweep's configuration")?).len();
        if finished(&self.state, &self.out, "sweep") {
            return Ok(jobs);
        }
        say(&format!("sweep ({jobs} jobs, budget {budget:.0} s)"));
        let dir = self.out.join("sweep");
        // Rows to keep: resumed; none, but an earlier run's report or isa files: the sweep
        // replaces its own and leaves isa's.
        let mode = sweep::OUTPUTS.mode_to_continue(&dir);
        let child = Child::Sweep {
            scenes: self.scenes.clone(),
            device: self.device(),
            mask_features: self.opts.mask_features.clone(),
            width,
            height,
            kernel_timeout_s: 120.0,
            budget_s: (budget * 10.0).round() / 10.0,
            out: dir.clone(),
            resume: matches!(mode, OutMode::Resume),
            force: matches!(mode, OutMode::Force),
        };
        // The sweep stops itself between jobs; a job far longer than the budget is stopped.
        let limit = Duration::from_secs_f64(budget + (budget / 2.0).max(120.0));
        self.step("sweep", child, None, limit, |_, r| {
            let rows = report::read_rows(&dir).map(|r| r.len()).unwrap_or(0);
            // Partial only when the sweep ended well with jobs left (its budget ran out); a
            // sweep that failed stays failed, its log named, whatever rows it left.
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
        })?;
        Ok(jobs)
    }

    /// `isa` of the device where its driver reports pipeline statistics.
    pub(super) fn isa(&mut self, runs: bool, say: &mut impl FnMut(&str)) -> anyhow::Result<()> {
        if finished(&self.state, &self.out, "isa") {
            return Ok(());
        }
        if !runs {
            let r = StepRecord {
                status: "skipped: the driver does not report pipeline statistics \
                         (VK_KHR_pipeline_executable_properties)"
                    .into(),
                done: true,
                ..Default::default()
            };
            record(&mut self.state, "isa", r);
            return save(&self.out, &self.state);
        }
        say("isa");
        let child = Child::Isa { device: self.device(), out: self.out.join("sweep") };
        self.step("isa", child, None, HANG, |_, _| {})
    }
}
