//! Runs a sweep's job list on one device through the [`Runner`]: one row per job, written as
//! it finishes; each encoding freed after its last job; the first scene's images at its end;
//! the report at the end of all. A folder that already holds results is refused, resumed
//! (its rows kept, their jobs not run again) or replaced, as asked ([`OUTPUTS`], by the one
//! policy of `outdir`).

use super::jobs::{self, Job};
use super::Config;
use crate::base::Status;
use crate::base::{mean_counters, simd_utilisation, Hit};
use crate::gpu::{self, Gpu};
use crate::layout::LayoutId;
use crate::outdir::{Claimed, Outputs};
use crate::rays::{RayKind, RayParams};
use crate::report::{self, Row, RowId};
use crate::runner::{Outcome, Plan, RaySetId, RaySpec, Runner, Target};
use anyhow::Context;
use std::collections::HashSet;
use std::path::{Path, PathBuf};

/// Outcome of a sweep.
pub struct Summary {
    pub rows: usize,
    pub failed: Vec<String>,
    pub out: PathBuf,
    /// Jobs left unrun when the budget ran out (`Config::budget`).
    pub unrun: usize,
}

/// What a sweep writes into its folder: the folder is its alone (a file there that is not the
/// sweep's is still refused without `--resume` or `--force`), `--resume` continues from
/// `results.csv`, `--force` replaces only the sweep's own files ([`report::is_output`]).
pub const OUTPUTS: Outputs = Outputs {
    command: "sweep",
    owns: report::is_output,
    folders: &[],
    alone: true,
    resume: Some(("results.csv", "keep its rows and run only the missing jobs")),
    force: true,
};

/// Readies a claimed output folder before anything runs: the rows a resumed sweep keeps, or,
/// under `--force`, the sweep's own files removed.
pub fn prepare_out(out: &Claimed) -> anyhow::Result<Vec<Row>> {
    if !out.resumes() {
        out.replace_own()?;
        return Ok(Vec::new());
    }
    // Columns this version does not write (a newer version's) would be lost when the kept
    // rows are written again: refuse.
    let csv = out.path().join("results.csv");
    let known = report::rows::columns();
    let header = std::fs::read_to_string(&csv)
        .with_context(|| format!("--resume: reading {}", csv.display()))?
        .lines()
        .next()
        .unwrap_or("")
        .to_string();
    let unknown: Vec<&str> = header.split(',').filter(|c| !known.iter().any(|k| k == c)).collect();
    anyhow::ensure!(
        unknown.is_empty(),
        "--resume: {} has column(s) this version does not write ({}); they would be lost — resume with the version \
         that wrote it, or --force",
        csv.display(),
        unknown.join(", ")
    );
    report::read_rows(out.path())
}

/// Runs a sweep, writing `results.csv`/`.json` as it goes, then the report. `mask`: device
/// features to treat as missing (testing). `kept`: rows of a resumed sweep ([`prepare_out`]);
/// their jobs are not run again.
pub fn run(cfg: &Config, out: &Path, quiet: bool, mask: &[String], kept: Vec<Row>) -> anyhow::Result<Summary> {
    cfg.check()?;
    let start = std::time::Instant::now();
    let opts = gpu::ContextOptions {
        device: (!cfg.device.is_empty()).then(|| cfg.device.clone()),
        mask_features: mask.to_vec(),
        kernel_timeout_s: Some(cfg.kernel_timeout),
        ..Default::default()
    };
    let g = Gpu::new(&opts)?;
    let mut jobs = jobs::list(cfg);
    if let Some(s) = cfg.shard {
        let bytes: Vec<u64> = cfg.scenes.iter().map(|p| std::fs::metadata(p).map(|m| m.len()).unwrap_or(1)).collect();
        let all = jobs.len();
        jobs = jobs::shard(cfg, &jobs, s, &bytes);
        if !quiet {
            eprintln!("shard {}/{}: {} of {} jobs", s.k, s.n, jobs.len(), all);
        }
    }
    let runner = Runner::new(Some(&g), &cfg.baselines(), Default::default())?;
    let files = SetupFiles::of(cfg);
    let mut ex = Executor { runner, cfg, gpu: &g, images: None, scene: None, measured: HashSet::new(), files };
    let done: HashSet<RowId> = kept.iter().map(Row::id).collect();
    let jobs: Vec<Job> = jobs.into_iter().filter(|j| !done.contains(&ex.identity(j).id())).collect();
    let resumed = kept.len();
    let mut writer = report::Writer::create(out, kept)?;
    if let Some(s) = cfg.shard {
        // Which sweep this share is of, so that `report` merges only shards of one sweep.
        let whole = Config { shard: None, budget: None, ..cfg.clone() };
        let config = format!("{:016x}", crate::digest::fnv1a(format!("{whole:?}").as_bytes()));
        let manifest = report::merge::ShardManifest { k: s.k, n: s.n, config };
        crate::fsx::write_atomic(&out.join("shard.json"), serde_json::to_string_pretty(&manifest)?.as_bytes())?;
    }
    let arith = gpu::arith::run(&g, 16384, 256, 3)?;
    crate::fsx::write_atomic(&out.join("device_arith.json"), serde_json::to_string_pretty(&arith)?.as_bytes())?;
    if resumed > 0 && !quiet {
        eprintln!("resuming {}: {resumed} row(s) kept, {} job(s) to run", out.display(), jobs.len());
    }
    use std::io::IsTerminal;
    let lines = !quiet && !std::io::stderr().is_terminal();
    let t0 = std::time::Instant::now();
    let bar =
        if quiet || lines { indicatif::ProgressBar::hidden() } else { indicatif::ProgressBar::new(jobs.len() as u64) };
    bar.set_style(
        indicatif::ProgressStyle::with_template("{bar:30} {pos}/{len} [{elapsed_precise} ETA {eta}] {msg}").unwrap(),
    );
    let last = jobs::last_uses(&jobs);
    let mut failed = Vec::new();
    let (mut longest, mut unrun) = (0.0f64, 0);
    for (i, job) in jobs.iter().enumerate() {
        if let Some(budget) = cfg.budget {
            if i > 0 && start.elapsed().as_secs_f64() + longest > budget {
                unrun = jobs.len() - i;
                break;
            }
        }
        let job_start = std::time::Instant::now();
        bar.set_message(ex.describe(job));
        let mut row = match ex.run_job(job, &bar) {
            Ok(row) => row,
            Err(e) if g.hung() => {
                // Recorded, so that --resume continues after it; the device is still busy with
                // it, so this process can run nothing more.
                let mut row = ex.identity(job);
                row.status = Status::Failed(format!("hung: {e:#}"));
                writer.push(row)?;
                bar.finish_and_clear();
                report::render(writer.rows(), out, &[out.to_path_buf()])?;
                anyhow::bail!(
                    "{} hung (no result within {} s) and was recorded as FAILED in {}; the device stays busy with it, \
                     so the sweep stops here — rerun with --resume to continue after it",
                    ex.describe(job),
                    cfg.kernel_timeout,
                    out.display()
                );
            }
            Err(e) => return Err(e),
        };
        row.device_fp16_ratio = arith.fp16_ratio;
        if row.status.is_failed() {
            bar.suspend(|| eprintln!("error: {} {} {}: {}", row.scene, row.rays, row.kernel, row.status));
            failed.push(format!("{} {} {}", row.scene, row.rays, row.kernel));
        }
        if lines {
            // Not a terminal (CI logs, nohup, Slurm): one line per finished job instead of a bar.
            let done = i + 1;
            let el = t0.elapsed().as_secs_f64();
            let eta = el / done as f64 * (jobs.len() - done) as f64;
            eprintln!(
                "[{done}/{}] {} {} {}: {} ({:.2} Mrays/s) — {el:.0} s elapsed, ETA {eta:.0} s",
                jobs.len(),
                row.scene,
                row.rays,
                row.kernel,
                row.status,
                row.mrays_median
            );
        }
        writer.push(row)?;
        if let Some((scene, layout, b)) = jobs::encoding(job) {
            if last.get(&(scene, layout, b)) == Some(&i) {
                ex.runner.release(layout, b);
            }
        }
        if jobs.get(i + 1).is_none_or(|n| n.scene != job.scene) {
            ex.finish_scene(out)?;
        }
        longest = longest.max(job_start.elapsed().as_secs_f64());
        bar.inc(1);
    }
    if unrun > 0 {
        // Stopped by the budget inside a scene: its images from the jobs that ran.
        ex.finish_scene(out)?;
    }
    bar.finish_and_clear();
    drop(ex);
    report::render(writer.rows(), out, &[out.to_path_buf()])?;
    Ok(Summary { rows: writer.rows().len(), failed, out: out.into(), unrun })
}

/// The first scene's primary hits and nodes per pixel of each layout (B = 4, P = 1, default
/// math), for its images.
struct Images {
    set: RaySetId,
    layouts: Vec<(LayoutId, Vec<Hit>, Vec<f64>)>,
}

struct Executor<'a, 'g> {
    runner: Runner<'g>,
    cfg: &'a Config,
    gpu: &'g Gpu,
    images: Option<Images>,
    /// The scene of the jobs run last (its warnings are printed once).
    scene: Option<usize>,
    /// The ray kinds measured on it: once all are, the f32 reference encoding is freed.
    measured: HashSet<usize>,
    /// The files behind each row's `setup`, read once per sweep.
    files: SetupFiles,
}

/// What the files a sweep reads contribute to its rows' `setup`: each scene and rays file by
/// canonical path, size and modification time, each user kernel by its bytes' hash; taken
/// once, not for every job identity.
struct SetupFiles {
    scenes: Vec<String>,
    /// Per ray kind (`jobs::kinds`): a rays file's stamp, none for generated rays.
    rays: Vec<Option<String>>,
    kernels: Vec<u64>,
}

impl SetupFiles {
    fn of(cfg: &Config) -> SetupFiles {
        let stamp = |p: &Path| {
            let m = std::fs::metadata(p).ok();
            let mtime =
                m.as_ref().and_then(|m| m.modified().ok()).and_then(|t| t.duration_since(std::time::UNIX_EPOCH).ok());
            format!(
                "{}:{}:{}",
                p.canonicalize().unwrap_or_else(|_| p.to_path_buf()).display(),
                m.map_or(0, |m| m.len()),
                mtime.map_or(0, |d| d.as_nanos())
            )
        };
        SetupFiles {
            scenes: cfg.scenes.iter().map(|p| stamp(p)).collect(),
            rays: jobs::kinds(cfg)
                .iter()
                .map(|k| match k {
                    RayKind::File(p) => Some(stamp(p)),
                    _ => None,
                })
                .collect(),
            kernels: cfg
                .kernel
                .iter()
                .map(|k| crate::digest::fnv1a(&std::fs::read(&k.file).unwrap_or_default()))
                .collect(),
        }
    }
}

impl Executor<'_, '_> {
    fn kind(&self, job: &Job) -> RayKind {
        jobs::kinds(self.cfg)[job.rays].clone()
    }

    fn describe(&self, job: &Job) -> String {
        let scene = crate::scene::scene_name(&self.cfg.scenes[job.scene]);
        format!("{scene} {} {}", self.kind(job), self.identity(job).kernel)
    }

    fn spec(&self, job: &Job) -> RaySpec {
        let c = self.cfg;
        RaySpec {
            kind: self.kind(job),
            params: RayParams { width: c.width, height: c.height, seed: c.seed, ..Default::default() },
        }
    }

    /// The row a job writes, before it runs: its identity (what `--resume` matches) with no
    /// results, status ok.
    fn identity(&self, job: &Job) -> Row {
        let g = &self.gpu.info;
        let mut row = Row {
            scene: crate::scene::scene_name(&self.cfg.scenes[job.scene]),
            rays: self.kind(job).to_string(),
            device: g.name.clone(),
            driver: g.driver.clone(),
            version: env!("CARGO_PKG_VERSION").into(),
            commit: env!("HALFTRACE_COMMIT").into(),
            math: "n/a".into(),
            float_controls: "n/a".into(),
            setup: self.setup(job),
            ..Row::default()
        };
        match &job.target {
            Target::Kernel(k) => {
                let v = k.variant;
                (row.layout, row.math, row.branching, row.packet) =
                    (v.layout.name().into(), v.math.name().into(), v.branching, v.packet);
                let (name, fc) = self.runner.name(k);
                row.kernel = job.user.map_or(name, |i| self.cfg.kernel[i].name.clone());
                if let Some(fc) = fc {
                    row.float_controls = fc.name().into();
                }
            }
            Target::Baseline(b) => (row.layout, row.kernel) = (b.name().into(), b.imp().kernel().into()),
        }
        row
    }

    /// What else decides a job's result (the row's `setup`): the scene file, the image size,
    /// seed and rays file, a user kernel's source; files by canonical path, size and
    /// modification time (a kernel by its bytes).
    fn setup(&self, job: &Job) -> String {
        let (c, f) = (self.cfg, &self.files);
        let mut text = format!("scene {}; {}x{} seed {}", f.scenes[job.scene], c.width, c.height, c.seed);
        if let Some(r) = &f.rays[job.rays] {
            text += &format!("; rays {r}");
        }
        if let Some(i) = job.user {
            text += &format!("; kernel {:016x}", f.kernels[i]);
        }
        format!("{:016x}", crate::digest::fnv1a(text.as_bytes()))
    }

    fn run_job(&mut self, job: &Job, bar: &indicatif::ProgressBar) -> anyhow::Result<Row> {
        let (scene, _) = self.runner.scene(&self.cfg.scenes[job.scene])?;
        if self.scene != Some(job.scene) {
            for w in &scene.warnings {
                bar.suspend(|| eprintln!("warning: {w}"));
            }
            (self.scene, self.measured) = (Some(job.scene), HashSet::new());
        }
        let triangles = scene.len();
        let set = self.runner.ray_set(&self.spec(job))?;
        let plan = Plan { warmup: self.cfg.warmup, repeat: self.cfg.repeat, count: true };
        let o = match job.user {
            Some(i) => self
                .runner
                .measure(&job.target, set, plan)
                .with_context(|| format!("[[kernel]] '{}'", self.cfg.kernel[i].name)),
            None => self.runner.measure(&job.target, set, plan),
        }?;
        // Every ray set of the scene has its f32 hits now: the reference encoding can go.
        self.measured.insert(job.rays);
        if self.measured.len() == jobs::kinds(self.cfg).len() {
            self.runner.release_f32_reference();
        }
        let mut row = self.identity(job);
        row.triangles = triangles;
        row.ray_count = self.runner.rays(set).rays.len();
        self.fill(&mut row, &o);
        if job.scene == 0 && job.user.is_none() && self.kind(job) == RayKind::Primary && o.status.is_ok() {
            if let (Target::Kernel(k), Some(c)) = (&job.target, &o.m.counters) {
                let v = k.variant;
                if v.branching == 4 && v.packet == 1 && v.math == v.layout.default_math() {
                    let img = self.images.get_or_insert_with(|| Images { set, layouts: Vec::new() });
                    img.layouts.push((v.layout, o.m.hits.clone(), c.iter().map(|x| x.nodes as f64).collect()));
                }
            }
        }
        Ok(row)
    }

    /// A row's results from its measurement.
    fn fill(&self, row: &mut Row, o: &Outcome) {
        row.status = o.status.clone();
        let (m, f) = (&o.m, &o.facts);
        (row.differs_from_f32, row.false_misses, row.max_abs_dt) =
            (m.vs_f32.differs(), m.vs_f32.false_misses, m.vs_f32.max_abs_dt);
        if let Some(t) = &m.timing {
            (row.mrays_median, row.mrays_min, row.mrays_max) = t.mrays(row.ray_count);
            (row.ms_median, row.ms_min, row.ms_max, row.timed_dispatches) = (t.median, t.min, t.max, t.count);
        }
        (row.bvh_bytes, row.build_ms, row.triangle_bytes) = (f.bvh_bytes, f.build_ms, f.triangle_bytes);
        let Some(k) = o.kernel else { return };
        let v = k.variant;
        (row.bytes_per_node, row.stack_bytes_per_ray) = (f.node_size, v.stack_bytes());
        let c = match &m.counters {
            Some(c) => {
                let mc = mean_counters(c);
                let packets = row.ray_count.div_ceil(v.packet).max(1) as f64;
                let pn = c.iter().map(|x| x.packet_nodes as f64).sum::<f64>() / packets;
                [mc[0], mc[1], mc[2], mc[3], pn, simd_utilisation(c, v.packet)]
            }
            None => [f64::NAN; 6],
        };
        (row.nodes_per_ray, row.box_tests_per_ray, row.tri_tests_per_ray, row.reanchors_per_ray) =
            (c[0], c[1], c[2], c[3]);
        (row.packet_nodes_per_packet, row.simd_utilisation) = (c[4], c[5]);
        row.node_bytes_per_ray = c[0] * f.node_size as f64;
    }

    /// After a scene's last job: its images (the first scene only).
    fn finish_scene(&mut self, out: &Path) -> anyhow::Result<()> {
        let Some(img) = self.images.take() else { return Ok(()) };
        let f32_hits = self.runner.f32_hits(img.set)?.to_vec();
        let scene = self.runner.current_scene().expect("the images' scene is current");
        let set = self.runner.rays(img.set);
        let (w, h) = (self.cfg.width, self.cfg.height);
        crate::images::render(&out.join("render.png"), scene, &set.rays, &f32_hits, w, h)?;
        let max = img.layouts.iter().flat_map(|(_, _, n)| n.iter().cloned()).fold(0.0, f64::max);
        for (layout, hits, nodes) in &img.layouts {
            crate::images::heat_map(&out.join(format!("heat_{layout}.png")), w, h, nodes, max)?;
            if *layout != LayoutId::f32() {
                let mask: Vec<bool> = hits.iter().zip(&f32_hits).map(|(a, b)| !a.same_bits(b)).collect();
                crate::images::mask_image(&out.join(format!("diff_{layout}_vs_f32.png")), w, h, &mask)?;
            }
        }
        Ok(())
    }
}
