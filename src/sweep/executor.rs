//! Runs a sweep's job list on one device: the BVH is built once per scene, encoded and
//! uploaded once per scene × layout × B (freed after its last job), rays and the f32 reference
//! made once per scene × ray kind; every job goes through [`measure::validate_then_time`] and
//! becomes one row, written as it finishes.

use super::jobs::{self, Job, Target};
use super::Config;
use crate::bvh::{self, BinaryBvh};
use crate::gpu::bench::DeviceBench;
use crate::gpu::kernel::{self, GpuBvh, Kernel, Source};
use crate::gpu::{self, Gpu};
use crate::layout::{BaselineDevice, BaselineScene, Encoded, LayoutId};
use crate::measure::{self, BaselineTarget, KernelTarget, Measurement, Plan, Reference};
use crate::rays::{make_rays, Ray, RayKind, RayParams};
use crate::report::{self, Row};
use crate::scene::Scene;
use crate::trace::{mean_counters, simd_utilisation, Counters, Hit};
use crate::variant::Variant;
use anyhow::Context;
use std::collections::HashMap;
use std::path::{Path, PathBuf};

/// Outcome of a sweep.
pub struct Summary {
    pub rows: usize,
    pub failed: Vec<String>,
    pub out: PathBuf,
}

/// What to do with an output folder that already holds files.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub enum OutMode {
    /// Refuse it (the default: a user's results are never overwritten by accident).
    #[default]
    New,
    /// Keep its rows and run only the jobs they do not record (after an interrupt, or to add
    /// variants).
    Resume,
    /// Replace the sweep's own files in it (nothing else in the folder is touched).
    Force,
}

/// Checks the output folder against `mode` before anything runs; returns the rows a resumed
/// sweep keeps. A non-empty folder is refused unless `Resume` or `Force`.
pub fn prepare_out(out: &Path, mode: OutMode) -> anyhow::Result<Vec<Row>> {
    let entries: Vec<String> = match std::fs::read_dir(out) {
        Ok(d) => d.filter_map(|e| e.ok()).map(|e| e.file_name().to_string_lossy().to_string()).collect(),
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(Vec::new()),
        Err(e) => anyhow::bail!("--out {}: {e}", out.display()),
    };
    if entries.is_empty() {
        return Ok(Vec::new());
    }
    match mode {
        OutMode::New => anyhow::bail!(
            "--out {} already holds results ({} file(s)); nothing was changed. Pass --resume to keep its rows and run only the missing jobs, or --force to replace it, or choose another folder",
            out.display(),
            entries.len()
        ),
        OutMode::Resume => {
            if !out.join("results.csv").is_file() {
                anyhow::bail!("--resume: {} has no results.csv to resume", out.display());
            }
            report::read_rows(out)
        }
        OutMode::Force => {
            for e in entries.iter().filter(|e| report::is_output(e)) {
                let p = out.join(e);
                std::fs::remove_file(&p).with_context(|| format!("--force: removing {}", p.display()))?;
            }
            Ok(Vec::new())
        }
    }
}

/// The layout, math, B and P fields of a job's row (for a row written without a result).
fn hung_identity(job: &Job) -> Row {
    match job.target {
        Target::Variant(v) => Row {
            layout: v.layout.name().into(),
            math: v.math.name().into(),
            branching: v.branching,
            packet: v.packet,
            float_controls: v.fc.name().into(),
            ..Default::default()
        },
        Target::Baseline(b) => {
            Row { layout: b.name().into(), math: "n/a".into(), float_controls: "n/a".into(), ..Default::default() }
        }
        Target::Kernel(_) => Row { math: "n/a".into(), float_controls: "n/a".into(), ..Default::default() },
    }
}

/// The identity of a job's row: scene, rays and what traced them (a built-in variant by
/// layout, math, B and P; a baseline by name; a user kernel by its name).
fn job_key(cfg: &Config, kinds: &[RayKind], job: &Job) -> String {
    let scene = crate::scene::scene_name(&cfg.scenes[job.scene]);
    let what = match job.target {
        Target::Variant(v) => format!("{}/{}/{}/{}", v.layout, v.math.name(), v.branching, v.packet),
        Target::Baseline(b) => format!("baseline {b}"),
        Target::Kernel(i) => format!("kernel {}", cfg.kernel[i].name),
    };
    format!("{scene}|{}|{what}", kinds[job.rays])
}

/// The identity of a recorded row, as [`job_key`] spells it.
fn row_key(r: &Row) -> String {
    let what = match LayoutId::parse(&r.layout) {
        Ok(l) if l.baseline().is_some() => format!("baseline {}", r.layout),
        _ if r.kernel.starts_with("trav_") => format!("{}/{}/{}/{}", r.layout, r.math, r.branching, r.packet),
        _ => format!("kernel {}", r.kernel),
    };
    format!("{}|{}|{what}", r.scene, r.rays)
}

/// Runs a sweep, writing `results.csv`/`.json` as it goes, then the report. `mask`: device
/// features to treat as missing (testing). `kept`: rows of a resumed sweep ([`prepare_out`]);
/// their jobs are not run again.
pub fn run(cfg: &Config, out: &Path, quiet: bool, mask: &[String], kept: Vec<Row>) -> anyhow::Result<Summary> {
    cfg.check()?;
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
    // Baselines need per-device state (pipelines); a device that cannot run one gets a line.
    let mut baselines: HashMap<LayoutId, Result<Box<dyn BaselineDevice + '_>, String>> = HashMap::new();
    for l in cfg.entries() {
        if let Some(b) = l.baseline() {
            let dev = match b.unavailable(&g.info) {
                Some(why) => Err(why),
                None => Ok(b.prepare(&g).with_context(|| l.to_string())?),
            };
            baselines.insert(l, dev);
        }
    }
    let done: std::collections::HashSet<String> = kept.iter().map(row_key).collect();
    let kinds = jobs::kinds(cfg);
    let jobs: Vec<Job> = jobs.into_iter().filter(|j| !done.contains(&job_key(cfg, &kinds, j))).collect();
    let resumed = kept.len();
    let mut writer = report::Writer::create(out, kept)?;
    let bench = gpu::bench::run(&g, 16384, 256, 3)?;
    crate::fsx::write_atomic(&out.join("device_bench.json"), serde_json::to_string_pretty(&bench)?.as_bytes())?;
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
    let mut ex = Executor {
        gpu: &g,
        cfg,
        kinds: jobs::kinds(cfg),
        baselines: &baselines,
        bench,
        kernels: HashMap::new(),
        user: HashMap::new(),
        scene: None,
        failed: Vec::new(),
        out,
        bar: &bar,
    };
    let last = jobs::last_uses(cfg, &jobs);
    for (i, job) in jobs.iter().enumerate() {
        ex.bar.set_message(ex.describe(job));
        let row = match ex.run_job(job) {
            Ok(row) => row,
            Err(e) if g.hung() => {
                // Recorded, so that --resume continues after it; the device is still busy with
                // it, so this process can run nothing more.
                let kind = &ex.kinds[job.rays];
                let what = ex.describe(job);
                let row = Row {
                    scene: crate::scene::scene_name(&cfg.scenes[job.scene]),
                    rays: kind.to_string(),
                    kernel: ex.target_name(job.target),
                    device: g.info.name.clone(),
                    driver: g.info.driver.clone(),
                    status: format!("FAILED: hung: {e:#}"),
                    ..hung_identity(job)
                };
                writer.push(row)?;
                bar.finish_and_clear();
                report::render(writer.rows(), out, &[out.to_path_buf()])?;
                anyhow::bail!("{what} hung (no result within {} s) and was recorded as FAILED in {}; the device stays busy with it, so the sweep stops here — rerun with --resume to continue after it", cfg.kernel_timeout, out.display());
            }
            Err(e) => return Err(e),
        };
        if row.status.starts_with("FAILED") {
            ex.bar.suspend(|| eprintln!("error: {} {} {}: {}", row.scene, row.rays, row.kernel, row.status));
            ex.failed.push(format!("{} {} {}", row.scene, row.rays, row.kernel));
        }
        if lines {
            // Not a terminal (CI logs, nohup, Slurm): one line per finished job instead of a bar.
            let done = i + 1;
            let el = t0.elapsed().as_secs_f64();
            let eta = el / done as f64 * (jobs.len() - done) as f64;
            eprintln!(
                "[{done}/{}] {} {} {}: {} ({:.2} Mrays/s) — {:.0} s elapsed, ETA {:.0} s",
                jobs.len(),
                row.scene,
                row.rays,
                row.kernel,
                row.status,
                row.mrays_median,
                el,
                eta
            );
        }
        writer.push(row)?;
        if let Some(s) = ex.scene.as_mut() {
            s.encodings.retain(|k, _| last.get(&(job.scene, k.0, k.1)).is_some_and(|&l| l > i));
        }
        if jobs.get(i + 1).is_none_or(|n| n.scene != job.scene) {
            ex.finish_scene()?;
        }
        bar.inc(1);
    }
    bar.finish_and_clear();
    let failed = std::mem::take(&mut ex.failed);
    drop(ex);
    report::render(writer.rows(), out, &[out.to_path_buf()])?;
    Ok(Summary { rows: writer.rows().len(), failed, out: out.into() })
}

/// A ray set and the f32 reference's hits for it.
struct RaySet {
    rays: Vec<Ray>,
    f32_hits: Vec<Hit>,
}

/// What one scene's jobs share.
struct SceneState<'a, 'g> {
    index: usize,
    scene: Scene,
    bin: BinaryBvh,
    binary_ms: f64,
    /// The f32 layout at B = 4 on the CPU: the reference every row is compared with (dropped
    /// once every ray kind has its f32 hits: a big scene's memory).
    f32_ref: Option<Encoded>,
    rays: HashMap<usize, RaySet>,
    /// (layout, B) → encoded BVH, on the device, and its build time (binary + encode, ms).
    encodings: HashMap<(LayoutId, usize), (Encoded, GpuBvh<'g>, f64)>,
    baselines: HashMap<LayoutId, Box<dyn BaselineScene + 'a>>,
    /// First scene, primary rays, B = 4, P = 1, default math: hits and nodes per pixel.
    images: Vec<(LayoutId, Vec<Hit>, Vec<f64>)>,
}

struct Executor<'a, 'g> {
    gpu: &'g Gpu,
    cfg: &'a Config,
    kinds: Vec<RayKind>,
    baselines: &'a HashMap<LayoutId, Result<Box<dyn BaselineDevice + 'g>, String>>,
    bench: DeviceBench,
    /// Built-in kernels, timed and counting, compiled once per device.
    kernels: HashMap<(Variant, bool), Kernel<'g>>,
    /// User kernels: timed, and counting when the module counts.
    user: HashMap<usize, (Kernel<'g>, Option<Kernel<'g>>)>,
    scene: Option<SceneState<'a, 'g>>,
    failed: Vec<String>,
    out: &'a Path,
    bar: &'a indicatif::ProgressBar,
}

impl<'a, 'g> Executor<'a, 'g> {
    fn describe(&self, job: &Job) -> String {
        let scene = self.cfg.scenes[job.scene].file_stem().map(|s| s.to_string_lossy().to_string()).unwrap_or_default();
        format!("{scene} {} {}", self.kinds[job.rays], self.target_name(job.target))
    }

    fn target_name(&self, t: Target) -> String {
        match t {
            Target::Variant(v) => v.name(false),
            Target::Baseline(b) => b.baseline().expect("a baseline").kernel().to_string(),
            Target::Kernel(i) => self.cfg.kernel[i].name.clone(),
        }
    }

    /// The state of the job's scene, loading and building it when the scene changes.
    fn scene(&mut self, index: usize) -> anyhow::Result<&mut SceneState<'a, 'g>> {
        if self.scene.as_ref().is_none_or(|s| s.index != index) {
            self.scene = None;
            let scene = crate::scene::load(&self.cfg.scenes[index])?;
            for w in &scene.warnings {
                self.bar.suspend(|| eprintln!("warning: {w}"));
            }
            let t = std::time::Instant::now();
            let bin = bvh::build_binary(&scene);
            let binary_ms = t.elapsed().as_secs_f64() * 1e3;
            let f32_ref = Some(Encoded::new(&scene, &bin, LayoutId::f32(), 4)?);
            self.scene = Some(SceneState {
                index,
                scene,
                bin,
                binary_ms,
                f32_ref,
                rays: HashMap::new(),
                encodings: HashMap::new(),
                baselines: HashMap::new(),
                images: Vec::new(),
            });
        }
        Ok(self.scene.as_mut().expect("just set"))
    }

    /// Makes the job's scene, ray set and (for BVH targets) encoding resident.
    fn prepare(&mut self, job: &Job, enc: Option<(LayoutId, usize)>) -> anyhow::Result<()> {
        let (gpu, cfg) = (self.gpu, self.cfg);
        let (kind, kinds) = (self.kinds[job.rays].clone(), self.kinds.len());
        let s = self.scene(job.scene)?;
        if !s.rays.contains_key(&job.rays) {
            let params =
                RayParams { width: cfg.width, height: cfg.height, camera: None, seed: cfg.seed, ..Default::default() };
            let rays = make_rays(&s.scene, &s.bin, &kind, &params)?;
            let f32_hits = s.f32_ref.as_ref().expect("kept until every ray kind has its hits").trace_default(&rays).0;
            s.rays.insert(job.rays, RaySet { rays, f32_hits });
            if s.rays.len() == kinds {
                s.f32_ref = None;
            }
        }
        if let Some((layout, b)) = enc {
            if !s.encodings.contains_key(&(layout, b)) {
                let t = std::time::Instant::now();
                let e = Encoded::new(&s.scene, &s.bin, layout, b)?;
                let ms = s.binary_ms + t.elapsed().as_secs_f64() * 1e3;
                let gb = GpuBvh::upload(gpu, &e).with_context(|| format!("{layout}, B={b}"))?;
                s.encodings.insert((layout, b), (e, gb, ms));
            }
        }
        Ok(())
    }

    fn run_job(&mut self, job: &Job) -> anyhow::Result<Row> {
        match job.target {
            Target::Variant(v) => match gpu::support::resolve(&self.gpu.info, v, self.cfg.float_controls) {
                Ok(v) => self.run_variant(job, v, None),
                Err(why) => self.skip_variant(job, v, &v.name(false), why),
            },
            Target::Kernel(i) => {
                let v = self.cfg.kernel[i].variant()?;
                match gpu::support::resolve(&self.gpu.info, v, self.cfg.float_controls) {
                    Ok(v) => self.run_variant(job, v, Some(i)),
                    Err(why) => self.skip_variant(job, v, &self.cfg.kernel[i].name.clone(), why),
                }
            }
            Target::Baseline(b) => self.run_baseline(job, b),
        }
    }

    /// Builds (once per device) the kernels of a built-in variant or of user kernel `user`.
    fn build_kernels(&mut self, v: &Variant, user: Option<usize>) -> anyhow::Result<()> {
        let g = self.gpu;
        let imp = kernel::choose_impl(g, v, None);
        match user {
            None => {
                for stats in [false, true] {
                    if !self.kernels.contains_key(&(*v, stats)) {
                        let k = Kernel::build(g, v, imp, stats, &Source::Builtin).with_context(|| v.name(stats))?;
                        self.kernels.insert((*v, stats), k);
                    }
                }
            }
            Some(i) if !self.user.contains_key(&i) => {
                let spec = &self.cfg.kernel[i];
                let src = Source::user(&spec.file);
                let timed =
                    Kernel::build(g, v, imp, false, &src).with_context(|| format!("[[kernel]] '{}'", spec.name))?;
                let counting = Kernel::user_counting(g, v, imp, &src)
                    .with_context(|| format!("[[kernel]] '{}' (counting)", spec.name))?;
                self.user.insert(i, (timed, counting));
            }
            Some(_) => {}
        }
        Ok(())
    }

    /// The timed and counting kernels [`Self::build_kernels`] made.
    fn kernels(&self, v: &Variant, user: Option<usize>) -> (&Kernel<'g>, Option<&Kernel<'g>>) {
        match user {
            None => (&self.kernels[&(*v, false)], Some(&self.kernels[&(*v, true)])),
            Some(i) => (&self.user[&i].0, self.user[&i].1.as_ref()),
        }
    }

    fn run_variant(&mut self, job: &Job, v: Variant, user: Option<usize>) -> anyhow::Result<Row> {
        self.prepare(job, Some((v.layout, v.branching)))?;
        // A scene beyond one storage buffer is read by address; the row keeps the variant's name.
        let buffers = self.scene.as_ref().expect("prepared").encodings[&(v.layout, v.branching)].1.buffers;
        let (bound, v) = (v, v.with_buffers(buffers));
        self.build_kernels(&v, user)?;
        let (g, plan) = (self.gpu, Plan { warmup: self.cfg.warmup, repeat: self.cfg.repeat, count: true });
        let (timed, counting) = self.kernels(&v, user);
        let name = match user {
            Some(i) => self.cfg.kernel[i].name.clone(),
            None => bound.kernel_name(timed.imp, false),
        };
        let s = self.scene.as_ref().expect("prepared");
        let set = &s.rays[&job.rays];
        let (enc, gb, build_ms) = &s.encodings[&(v.layout, v.branching)];
        // Correctness before speed: the CPU reference of the same layout, packet size and math.
        let (ref_hits, ref_counters) = enc.trace_fc(&set.rays, v.packet, v.math, v.fc);
        let target = KernelTarget { gpu: g, bvh: gb, timed, counting };
        let m = measure::validate_then_time(
            &target,
            &set.rays,
            Reference::Exact { hits: &ref_hits, counters: &ref_counters },
            &set.f32_hits,
            plan,
        )
        .with_context(|| name.clone())?;
        let node_size = enc.node_size();
        let mut row = self.base_row(job, &s.scene, set.rays.len(), v.layout, &name, &m);
        row.math = v.math.name().into();
        row.float_controls = v.fc.name().into();
        row.branching = v.branching;
        row.packet = v.packet;
        row.bvh_bytes = enc.node_bytes() as u64;
        row.build_ms = *build_ms;
        row.bytes_per_node = node_size as u64;
        row.triangle_bytes = enc.tris.bytes() as u64;
        row.stack_bytes_per_ray = v.stack_bytes();
        let counts = |c: Option<&Vec<Counters>>| -> [f64; 6] {
            match c {
                Some(c) => {
                    let mc = mean_counters(c);
                    let packets = set.rays.len().div_ceil(v.packet).max(1) as f64;
                    [
                        mc[0],
                        mc[1],
                        mc[2],
                        mc[3],
                        c.iter().map(|x| x.packet_nodes as f64).sum::<f64>() / packets,
                        simd_utilisation(c, v.packet),
                    ]
                }
                None => [f64::NAN; 6],
            }
        };
        let c = counts(m.counters.as_ref());
        (
            row.nodes_per_ray,
            row.box_tests_per_ray,
            row.tri_tests_per_ray,
            row.reanchors_per_ray,
            row.packet_nodes_per_packet,
            row.simd_utilisation,
        ) = (c[0], c[1], c[2], c[3], c[4], c[5]);
        row.node_bytes_per_ray = c[0] * node_size as f64;
        let wants_image = s.index == 0
            && self.kinds[job.rays] == RayKind::Primary
            && user.is_none()
            && v.branching == 4
            && v.packet == 1
            && v.math == v.layout.caps().maths[0];
        if wants_image && m.failure.is_none() {
            let nodes = m.counters.as_ref().map(|c| c.iter().map(|x| x.nodes as f64).collect()).unwrap_or_default();
            self.scene.as_mut().expect("prepared").images.push((v.layout, m.hits, nodes));
        }
        Ok(row)
    }

    /// The row of a variant the device cannot run: one line in the report, not a failure.
    fn skip_variant(&mut self, job: &Job, v: Variant, name: &str, why: String) -> anyhow::Result<Row> {
        self.prepare(job, None)?;
        let s = self.scene.as_ref().expect("prepared");
        let n = s.rays[&job.rays].rays.len();
        let mut row = self.base_row(job, &s.scene, n, v.layout, name, &Measurement::skipped());
        row.status = format!("skipped: {why}");
        (row.math, row.branching, row.packet) = (v.math.name().into(), v.branching, v.packet);
        row.float_controls = "n/a".into();
        Ok(row)
    }

    fn run_baseline(&mut self, job: &Job, b: LayoutId) -> anyhow::Result<Row> {
        self.prepare(job, None)?;
        let bl = b.baseline().expect("a baseline");
        let baselines = self.baselines;
        let dev = match &baselines[&b] {
            Ok(d) => d,
            Err(why) => {
                let s = self.scene.as_ref().expect("prepared");
                let n = s.rays[&job.rays].rays.len();
                let mut row = self.base_row(job, &s.scene, n, b, bl.kernel(), &Measurement::skipped());
                row.status = format!("skipped: {why}");
                return Ok(row);
            }
        };
        let s = self.scene.as_mut().expect("prepared");
        if !s.baselines.contains_key(&b) {
            let built = dev.scene(&s.scene).with_context(|| b.to_string())?;
            s.baselines.insert(b, built);
        }
        let s = self.scene.as_ref().expect("prepared");
        let (bs, set) = (&s.baselines[&b], &s.rays[&job.rays]);
        let plan = Plan { warmup: self.cfg.warmup, repeat: self.cfg.repeat, count: false };
        let m = measure::validate_then_time(
            &BaselineTarget { name: bl.kernel(), scene: bs.as_ref() },
            &set.rays,
            Reference::Agreement,
            &set.f32_hits,
            plan,
        )?;
        let mut row = self.base_row(job, &s.scene, set.rays.len(), b, bl.kernel(), &m);
        row.bvh_bytes = bs.bytes();
        row.build_ms = bs.build_ms();
        row.triangle_bytes = (s.scene.len() * 36) as u64;
        Ok(row)
    }

    /// The row fields every target shares: identity, status, timing, agreement with f32.
    fn base_row(
        &self,
        job: &Job,
        scene: &Scene,
        ray_count: usize,
        layout: LayoutId,
        kernel: &str,
        m: &Measurement,
    ) -> Row {
        let kind = &self.kinds[job.rays];
        let status = match &m.failure {
            None => "ok".to_string(),
            Some(msg) => format!("FAILED: {msg}"),
        };
        let mut row = Row {
            scene: scene.name.clone(),
            triangles: scene.len(),
            rays: kind.to_string(),
            ray_count,
            layout: layout.name().into(),
            math: "n/a".into(),
            float_controls: "n/a".into(),
            kernel: kernel.into(),
            device: self.gpu.info.name.clone(),
            driver: self.gpu.info.driver.clone(),
            version: env!("CARGO_PKG_VERSION").into(),
            commit: env!("HALFTRACE_COMMIT").into(),
            status,
            differs_from_f32: m.vs_f32.differs(),
            false_misses: m.vs_f32.false_misses,
            max_abs_dt: m.vs_f32.max_abs_dt,
            device_fp16_ratio: self.bench.fp16_ratio,
            ..Row::default()
        };
        if let Some(t) = &m.timing {
            (row.mrays_median, row.mrays_min, row.mrays_max) = t.mrays(ray_count);
            (row.ms_median, row.ms_min, row.ms_max, row.timed_dispatches) = (t.median, t.min, t.max, t.count);
        }
        row
    }

    /// After a scene's last job: its images (first scene only).
    fn finish_scene(&mut self) -> anyhow::Result<()> {
        let Some(s) = self.scene.take() else { return Ok(()) };
        if s.index != 0 || s.images.is_empty() {
            return Ok(());
        }
        let primary = self.kinds.iter().position(|k| *k == RayKind::Primary).and_then(|i| s.rays.get(&i));
        let Some(set) = primary else { return Ok(()) };
        let (w, h) = (self.cfg.width, self.cfg.height);
        crate::images::render(&self.out.join("render.png"), &s.scene, &set.rays, &set.f32_hits, w, h)?;
        let max = s.images.iter().flat_map(|(_, _, n)| n.iter().cloned()).fold(0.0, f64::max);
        for (layout, hits, nodes) in &s.images {
            if !nodes.is_empty() {
                crate::images::heat_map(&self.out.join(format!("heat_{layout}.png")), w, h, nodes, max)?;
            }
            if *layout != LayoutId::f32() {
                let mask: Vec<bool> = hits.iter().zip(&set.f32_hits).map(|(a, b)| !a.same_bits(b)).collect();
                crate::images::mask_image(&self.out.join(format!("diff_{layout}_vs_f32.png")), w, h, &mask)?;
            }
        }
        Ok(())
    }
}
