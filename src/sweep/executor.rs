//! Runs a sweep's job list on one device through the [`Runner`]: one row per job, written as
//! it finishes; each encoding freed after its last job; the first scene's images at its end;
//! the report at the end of all. A folder that already holds results is refused, resumed
//! (its rows kept, their jobs not run again) or replaced, as asked ([`OUTPUTS`], by the one
//! policy of `outdir`).

use super::jobs::{self, Job};
use super::Sweep;
use crate::base::Status;
use crate::base::{mean_counters, simd_utilisation, Hit};
use crate::gpu::{self, Gpu};
use crate::layout::LayoutId;
use crate::outdir::{Claimed, Outputs};
use crate::rays::RayKind;
use crate::report::{self, Row, RowId, What};
use crate::runner::{Outcome, Plan, RaySetId, Runner, Target};
use anyhow::Context;
use std::collections::HashSet;
use std::path::{Path, PathBuf};

/// Outcome of a sweep.
pub struct Summary {
    pub rows: usize,
    pub failed: Vec<String>,
    pub out: PathBuf,
    /// Jobs left unrun when the budget ran out (`Sweep::budget`).
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
    let header = report::rows::header(&csv).context("--resume")?;
    let unknown: Vec<&str> = header.iter().map(String::as_str).filter(|c| !known.iter().any(|k| k == c)).collect();
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
pub fn run(sweep: &Sweep, out: &Path, quiet: bool, mask: &[String], kept: Vec<Row>) -> anyhow::Result<Summary> {
    let start = std::time::Instant::now();
    let opts = gpu::ContextOptions {
        device: sweep.device.clone(),
        mask_features: mask.to_vec(),
        kernel_timeout_s: Some(sweep.kernel_timeout),
        ..Default::default()
    };
    let g = Gpu::new(&opts)?;
    let mut jobs = jobs::list(sweep);
    if let Some(s) = sweep.shard {
        let bytes: Vec<u64> = sweep.scenes.iter().map(|p| std::fs::metadata(p).map(|m| m.len()).unwrap_or(1)).collect();
        let all = jobs.len();
        jobs = jobs::shard(&jobs, s, &bytes);
        if !quiet {
            eprintln!("shard {}/{}: {} of {} jobs", s.k, s.n, jobs.len(), all);
        }
    }
    let runner = Runner::new(Some(&g), &sweep.baselines, Default::default())?;
    let mut ex = Executor {
        runner,
        gpu: &g,
        plan: sweep.plan,
        kinds: sweep.kinds().len(),
        images: None,
        scene: None,
        measured: Vec::new(),
    };
    let done: HashSet<RowId> = kept.iter().map(Row::id).collect();
    let jobs: Vec<Job> = jobs.into_iter().filter(|j| !done.contains(&ex.identity(j).id())).collect();
    let resumed = kept.len();
    let mut writer = report::Writer::create(out, kept)?;
    if let Some(s) = sweep.shard {
        // Which sweep this share is of, so that `report` merges only shards of one sweep.
        let manifest = report::merge::ShardManifest { k: s.k, n: s.n, config: sweep.config_hash.clone() };
        crate::fsx::write_atomic(&out.join("shard.json"), serde_json::to_string_pretty(&manifest)?.as_bytes())?;
    }
    let arith = gpu::arith::run(&g, 16384, 256, 3)?;
    if let (Some(why), false) = (&arith.fp16_unavailable, quiet) {
        eprintln!("note: the device's fp16:fp32 arithmetic ratio is not measured: {why}");
    }
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
        if let Some(budget) = sweep.budget {
            if i > 0 && start.elapsed().as_secs_f64() + longest > budget {
                unrun = jobs.len() - i;
                break;
            }
        }
        let job_start = std::time::Instant::now();
        bar.set_message(ex.describe(job));
        // A user kernel may have its own hang timeout; every other job has the sweep's.
        let own = job.user.as_ref().and_then(|n| sweep.kernels.iter().find(|k| &k.name == n)?.kernel_timeout);
        g.set_kernel_timeout(own.unwrap_or(sweep.kernel_timeout));
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
                    g.kernel_timeout_s(),
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
        if jobs.get(i + 1).is_none_or(|n| n.scene.index != job.scene.index) {
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
    width: u32,
    height: u32,
    layouts: Vec<(LayoutId, Vec<Hit>, Vec<f64>)>,
}

struct Executor<'g> {
    runner: Runner<'g>,
    gpu: &'g Gpu,
    /// How every job is measured.
    plan: Plan,
    /// How many ray kinds the sweep has (`Sweep::kinds`).
    kinds: usize,
    images: Option<Images>,
    /// The scene of the jobs run last (its warnings are printed once).
    scene: Option<usize>,
    /// The ray kinds measured on it: once all are, the f32 reference encoding is freed.
    measured: Vec<RayKind>,
}

impl Executor<'_> {
    fn describe(&self, job: &Job) -> String {
        format!("{} {} {}", job.scene.name, job.rays.kind, self.identity(job).kernel)
    }

    /// The row a job writes, before it runs: its identity (what `--resume` matches) with no
    /// results, status ok.
    fn identity(&self, job: &Job) -> Row {
        let g = &self.gpu.info;
        let mut row = Row {
            scene: job.scene.name.clone(),
            rays: job.rays.kind.to_string(),
            device: g.name.clone(),
            driver: g.driver.clone(),
            version: env!("CARGO_PKG_VERSION").into(),
            commit: env!("HALFTRACE_COMMIT").into(),
            math: "n/a".into(),
            float_controls: "n/a".into(),
            setup: job.setup.clone(),
            ..Row::default()
        };
        match &job.target {
            Target::Kernel(k) => {
                let v = k.variant;
                (row.layout, row.math, row.branching, row.packet) =
                    (v.layout.name().into(), v.math.name().into(), v.branching, v.packet);
                let (id, built) = self.runner.kernel_id(k);
                row.kernel = job.user.clone().unwrap_or(id.name());
                if built {
                    row.float_controls = id.variant.fc.name().into();
                }
                row.what = match &job.user {
                    Some(name) => What::User(name.clone(), id),
                    None => What::Builtin(id),
                };
            }
            Target::Baseline(b) => {
                (row.layout, row.kernel) = (b.name().into(), b.imp().kernel().into());
                row.what = What::Baseline(*b);
            }
        }
        row
    }

    fn run_job(&mut self, job: &Job, bar: &indicatif::ProgressBar) -> anyhow::Result<Row> {
        let (scene, _) = self.runner.scene(&job.scene.path)?;
        if self.scene != Some(job.scene.index) {
            for w in &scene.warnings {
                bar.suspend(|| eprintln!("warning: {w}"));
            }
            (self.scene, self.measured) = (Some(job.scene.index), Vec::new());
        }
        let triangles = scene.len();
        let set = self.runner.ray_set(&job.rays)?;
        let o = match &job.user {
            Some(name) => {
                self.runner.measure(&job.target, set, self.plan).with_context(|| format!("[[kernel]] '{name}'"))
            }
            None => self.runner.measure(&job.target, set, self.plan),
        }?;
        // Every ray set of the scene has its f32 hits now: the reference encoding can go.
        if !self.measured.contains(&job.rays.kind) {
            self.measured.push(job.rays.kind.clone());
        }
        if self.measured.len() == self.kinds {
            self.runner.release_f32_reference();
        }
        let mut row = self.identity(job);
        row.triangles = triangles;
        row.ray_count = self.runner.rays(set).rays.len();
        self.fill(&mut row, &o);
        if job.scene.index == 0 && job.user.is_none() && job.rays.kind == RayKind::Primary && o.status.is_ok() {
            if let (Target::Kernel(k), Some(c)) = (&job.target, &o.m.counters) {
                let v = k.variant;
                if v.branching == 4 && v.packet == 1 && v.math == v.layout.default_math() {
                    let (width, height) = (job.rays.params.width, job.rays.params.height);
                    let img = self.images.get_or_insert_with(|| Images { set, width, height, layouts: Vec::new() });
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
        row.flagged_rays = m.flagged;
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
        let (w, h) = (img.width, img.height);
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
