//! The sweep as data: the job list, generated in one place from a checked [`Sweep`]. A job
//! carries all its row needs — scene, ray set, target, name and setup — so whoever runs it
//! reads the job alone, never the configuration.

use super::Sweep;
use crate::digest::fnv1a;
use crate::layout::LayoutId;
use crate::precision::Math;
use crate::rays::{RayKind, RayParams};
use crate::runner::{RaySpec, Target};
use crate::variant::{KernelSpec, Source};
use std::collections::HashMap;
use std::path::{Path, PathBuf};

/// A sweep's scene file, as its jobs carry it.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct SceneFile {
    /// Its place in the sweep's scene list (encodings are keyed by it; the first scene's
    /// images are rendered).
    pub index: usize,
    pub path: PathBuf,
    /// The short name its rows go under.
    pub name: String,
    /// Canonical path, size and modification time: its part of the rows' `setup`.
    pub stamp: String,
}

/// One row of the results and all it needs: a scene, a ray set, what traces it, a user
/// kernel's name (the row's `kernel` column; `None` for built-in kernels and baselines) and
/// the row's `setup`.
#[derive(Clone, Debug, PartialEq)]
pub struct Job {
    pub scene: SceneFile,
    pub rays: RaySpec,
    pub target: Target,
    pub user: Option<String>,
    /// What else decides the result, hashed ([`setup`]): with the rest of the row's identity,
    /// what `--resume` matches.
    pub setup: String,
}

/// Every job, in the order the executor runs them: per scene, the built-in variants (sorted,
/// so each layout and B is contiguous and its BVH is encoded and uploaded once) over every ray
/// kind, then the baselines, then the user kernels. Each file is stamped (a user kernel
/// hashed) once.
pub fn list(s: &Sweep) -> Vec<Job> {
    let mut stamps: HashMap<PathBuf, String> = HashMap::new();
    let mut stamp_of = |p: &Path| stamps.entry(p.to_path_buf()).or_insert_with(|| stamp(p)).clone();
    let scenes: Vec<SceneFile> = s
        .scenes
        .iter()
        .enumerate()
        .map(|(index, p)| SceneFile { index, path: p.clone(), name: crate::scene::scene_name(p), stamp: stamp_of(p) })
        .collect();
    let kernels: Vec<u64> = s.kernels.iter().map(|k| fnv1a(&std::fs::read(&k.file).unwrap_or_default())).collect();
    let fc = s.float_controls;
    let variants = s.variants();
    let mut jobs = Vec::new();
    for scene in &scenes {
        let mut push = |kinds: &[RayKind], target: Target, user: Option<(&str, u64)>| {
            for kind in kinds {
                let file = match kind {
                    RayKind::File(p) => Some(stamp_of(p)),
                    _ => None,
                };
                jobs.push(Job {
                    scene: scene.clone(),
                    rays: RaySpec::new(kind.clone(), s.params.clone()),
                    target: target.clone(),
                    user: user.map(|u| u.0.to_string()),
                    setup: setup(&scene.stamp, &s.params, file.as_deref(), user.map(|u| u.1)),
                });
            }
        };
        for &v in &variants {
            push(&s.rays, Target::Kernel(KernelSpec::builtin(v).with_fc(fc)), None);
        }
        for &b in &s.baselines {
            push(&s.rays, Target::Baseline(b), None);
        }
        for (k, &hash) in s.kernels.iter().zip(&kernels) {
            let target = Target::Kernel(KernelSpec::builtin(k.variant).with_fc(fc).with_source(Source::user(&k.file)));
            push(k.rays.as_deref().unwrap_or(&s.rays), target, Some((k.name.as_str(), hash)));
        }
    }
    jobs
}

/// A file as a row's `setup` knows it: canonical path, size and modification time (ns).
fn stamp(p: &Path) -> String {
    let m = std::fs::metadata(p).ok();
    let mtime = m.as_ref().and_then(|m| m.modified().ok()).and_then(|t| t.duration_since(std::time::UNIX_EPOCH).ok());
    format!(
        "{}:{}:{}",
        p.canonicalize().unwrap_or_else(|_| p.to_path_buf()).display(),
        m.map_or(0, |m| m.len()),
        mtime.map_or(0, |d| d.as_nanos())
    )
}

/// A row's `setup`: the scene file's stamp, the image size and seed, a rays file's stamp and a
/// user kernel's hash, hashed. Rows of older folders are matched by it (`--resume`): the text
/// hashed must not change.
fn setup(scene: &str, params: &RayParams, rays: Option<&str>, kernel: Option<u64>) -> String {
    let mut text = format!("scene {scene}; {}x{} seed {}", params.width, params.height, params.seed);
    if let Some(r) = rays {
        text += &format!("; rays {r}");
    }
    if let Some(k) = kernel {
        text += &format!("; kernel {k:016x}");
    }
    format!("{:016x}", fnv1a(text.as_bytes()))
}

/// The (scene, layout, B) encoding a job needs, if any.
pub fn encoding(job: &Job) -> Option<(usize, LayoutId, usize)> {
    match &job.target {
        Target::Kernel(k) => Some((job.scene.index, k.variant.layout, k.variant.branching)),
        Target::Baseline(_) => None,
    }
}

/// One of N deterministic shares of a sweep's job list (`sweep --shard K/N`, or a Slurm job
/// array's task): K in 1..=N.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Shard {
    pub k: usize,
    pub n: usize,
}

impl std::str::FromStr for Shard {
    type Err = String;
    fn from_str(s: &str) -> Result<Shard, String> {
        let bad = || format!("--shard '{s}': give K/N with 1 <= K <= N (e.g. 2/8)");
        let (k, n) = s.split_once('/').ok_or_else(bad)?;
        let (k, n): (usize, usize) = (k.trim().parse().map_err(|_| bad())?, n.trim().parse().map_err(|_| bad())?);
        if n == 0 || k == 0 || k > n {
            return Err(bad());
        }
        Ok(Shard { k, n })
    }
}

impl Shard {
    /// The shard of a Slurm job-array task: `SLURM_ARRAY_TASK_ID` counted from
    /// `SLURM_ARRAY_TASK_MIN` (default 0) among `SLURM_ARRAY_TASK_COUNT` tasks; `None` outside
    /// an array. `var` reads the environment (a parameter so tests need not set it).
    pub fn from_slurm(var: impl Fn(&str) -> Option<String>) -> Result<Option<Shard>, String> {
        let Some(count) = var("SLURM_ARRAY_TASK_COUNT") else { return Ok(None) };
        let num = |name: &str, v: Option<String>| -> Result<usize, String> {
            let v = v.ok_or_else(|| format!("SLURM_ARRAY_TASK_COUNT is set but {name} is not"))?;
            v.trim().parse().map_err(|_| format!("{name}='{v}' is not a task index"))
        };
        let n = num("SLURM_ARRAY_TASK_COUNT", Some(count))?;
        let id = num("SLURM_ARRAY_TASK_ID", var("SLURM_ARRAY_TASK_ID"))?;
        let min = match var("SLURM_ARRAY_TASK_MIN") {
            Some(m) => num("SLURM_ARRAY_TASK_MIN", Some(m))?,
            None => 0,
        };
        if id < min || id - min >= n {
            return Err(format!("SLURM_ARRAY_TASK_ID={id} is not one of the {n} tasks from SLURM_ARRAY_TASK_MIN={min}: submit the array as --array=0-{} (or 1-{n})", n.saturating_sub(1)));
        }
        Ok(Some(Shard { k: id - min + 1, n }))
    }

    /// The shard's folder inside the sweep's `--out`.
    pub fn folder(&self) -> String {
        format!("shard-{}-of-{}", self.k, self.n)
    }
}

/// What a job is expected to cost, in arbitrary units: rays × log(scene bytes), times the
/// work of its arithmetic (emulated fp16 is the slowest on every device measured) and packet
/// size. Only the ratios between jobs matter (shards are balanced with it).
fn cost(job: &Job, scene_bytes: &[u64]) -> f64 {
    let p = &job.rays.params;
    let rays = (p.width as f64 * p.height as f64).max(1.0);
    let size = (scene_bytes[job.scene.index].max(2) as f64).ln();
    let factor = match (&job.target, &job.user) {
        (Target::Kernel(_), Some(_)) => 2.0,
        (Target::Kernel(k), None) => {
            let v = k.variant;
            let math = match v.math {
                Math::F16 => 4.0,
                Math::Mixed => 3.0,
                Math::F32 if v.layout == LayoutId::f32() => 1.0,
                Math::F32 => 1.5,
            };
            math * if v.packet >= 16 { 2.5 } else { 1.0 }
        }
        (Target::Baseline(_), _) => 0.5,
    };
    rays * size * factor
}

/// The jobs of `shard`, in list order. Jobs that share an encoding (scene, layout, B) — or a
/// baseline's structures over a scene — stay in one shard, so each is built once; those groups
/// are dealt largest expected cost first, each to the shard with the least so far (ties to the
/// lower shard, groups in list order): deterministic, and the shards of 1..=N partition the
/// list. `scene_bytes`: each scene's file size (the cost model's scene size).
pub fn shard(jobs: &[Job], shard: Shard, scene_bytes: &[u64]) -> Vec<Job> {
    #[derive(PartialEq)]
    enum Group {
        Encoding((usize, LayoutId, usize)),
        Baseline(usize, crate::baseline::BaselineId),
    }
    let mut groups: Vec<(Group, f64, Vec<usize>)> = Vec::new();
    for (i, j) in jobs.iter().enumerate() {
        let g = match (encoding(j), &j.target) {
            (Some(e), _) => Group::Encoding(e),
            (None, Target::Baseline(b)) => Group::Baseline(j.scene.index, *b),
            (None, Target::Kernel(_)) => unreachable!("every kernel job has an encoding"),
        };
        let c = cost(j, scene_bytes);
        match groups.iter_mut().find(|x| x.0 == g) {
            Some(x) => {
                x.1 += c;
                x.2.push(i);
            }
            None => groups.push((g, c, vec![i])),
        }
    }
    let mut order: Vec<usize> = (0..groups.len()).collect();
    order.sort_by(|&a, &b| groups[b].1.total_cmp(&groups[a].1).then(a.cmp(&b)));
    let mut load = vec![0.0f64; shard.n];
    let mut mine = vec![false; jobs.len()];
    for g in order {
        let (s, _) = load.iter().enumerate().min_by(|a, b| a.1.total_cmp(b.1).then(a.0.cmp(&b.0))).expect("n >= 1");
        load[s] += groups[g].1;
        if s + 1 == shard.k {
            for &i in &groups[g].2 {
                mine[i] = true;
            }
        }
    }
    jobs.iter().zip(mine).filter(|(_, m)| *m).map(|(j, _)| j.clone()).collect()
}

/// For each encoding, the index of the last job that needs it (so it can be freed after).
pub fn last_uses(jobs: &[Job]) -> HashMap<(usize, LayoutId, usize), usize> {
    let mut m = HashMap::new();
    for (i, j) in jobs.iter().enumerate() {
        if let Some(k) = encoding(j) {
            m.insert(k, i);
        }
    }
    m
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sweep::{Config, KernelTable};

    #[test]
    fn shards_partition_the_jobs_keep_encodings_together_and_balance() {
        let cfg = Config { scenes: vec!["a.obj".into(), "b.obj".into(), "c.obj".into()], ..Default::default() };
        let jobs = list(&cfg.check().unwrap());
        let bytes = [1_000_000, 50_000, 20_000_000];
        for n in [1, 2, 3, 5, 8] {
            let shards: Vec<Vec<Job>> = (1..=n).map(|k| shard(&jobs, Shard { k, n }, &bytes)).collect();
            assert_eq!(
                shards,
                (1..=n).map(|k| shard(&jobs, Shard { k, n }, &bytes)).collect::<Vec<_>>(),
                "deterministic"
            );
            let mut all: Vec<Job> = shards.concat();
            assert_eq!(all.len(), jobs.len(), "n={n}: every job in exactly one shard");
            all.sort_by_key(|j| jobs.iter().position(|x| x == j).unwrap());
            assert_eq!(all, jobs);
            for s in &shards {
                assert!(!s.is_empty(), "n={n}: an empty shard");
                // In list order, and an encoding's jobs in one shard.
                let pos: Vec<usize> = s.iter().map(|j| jobs.iter().position(|x| x == j).unwrap()).collect();
                assert!(pos.windows(2).all(|w| w[0] < w[1]));
                for j in s {
                    if let Some(e) = encoding(j) {
                        assert!(
                            jobs.iter().filter(|x| encoding(x) == Some(e)).all(|x| s.contains(x)),
                            "n={n}: encoding {e:?} split"
                        );
                    }
                }
            }
            // Greedy dealing, largest first: no shard exceeds the lightest by more than the
            // largest group.
            let group = |j: &Job| match encoding(j) {
                Some(e) => format!("{e:?}"),
                None => format!("{} {:?}", j.scene.index, j.target),
            };
            let biggest = jobs
                .iter()
                .map(|j| jobs.iter().filter(|x| group(x) == group(j)).map(|x| cost(x, &bytes)).sum::<f64>())
                .fold(0.0, f64::max);
            let costs: Vec<f64> = shards.iter().map(|s| s.iter().map(|j| cost(j, &bytes)).sum()).collect();
            let (lo, hi) =
                (costs.iter().cloned().fold(f64::INFINITY, f64::min), costs.iter().cloned().fold(0.0, f64::max));
            assert!(hi <= lo + biggest * 1.0001, "n={n}: unbalanced {costs:?} (largest group {biggest})");
        }
    }

    #[test]
    fn shard_flags_and_slurm_variables() {
        assert_eq!("2/8".parse::<Shard>(), Ok(Shard { k: 2, n: 8 }));
        for bad in ["0/2", "3/2", "1/0", "2", "a/b", "1/2/3"] {
            assert!(bad.parse::<Shard>().unwrap_err().contains("K/N"), "{bad}");
        }
        let env = |vars: &'static [(&'static str, &'static str)]| {
            move |k: &str| vars.iter().find(|v| v.0 == k).map(|v| v.1.to_string())
        };
        assert_eq!(Shard::from_slurm(env(&[])), Ok(None));
        assert_eq!(
            Shard::from_slurm(env(&[
                ("SLURM_ARRAY_TASK_COUNT", "4"),
                ("SLURM_ARRAY_TASK_ID", "0"),
                ("SLURM_ARRAY_TASK_MIN", "0")
            ])),
            Ok(Some(Shard { k: 1, n: 4 }))
        );
        assert_eq!(
            Shard::from_slurm(env(&[
                ("SLURM_ARRAY_TASK_COUNT", "4"),
                ("SLURM_ARRAY_TASK_ID", "4"),
                ("SLURM_ARRAY_TASK_MIN", "1")
            ])),
            Ok(Some(Shard { k: 4, n: 4 }))
        );
        assert!(Shard::from_slurm(env(&[("SLURM_ARRAY_TASK_COUNT", "4"), ("SLURM_ARRAY_TASK_ID", "7")]))
            .unwrap_err()
            .contains("--array=0-3"));
        assert!(Shard::from_slurm(env(&[("SLURM_ARRAY_TASK_COUNT", "4")]))
            .unwrap_err()
            .contains("SLURM_ARRAY_TASK_ID is not"));
        assert_eq!(Shard { k: 2, n: 8 }.folder(), "shard-2-of-8");
    }

    #[test]
    fn default_jobs_cover_every_variant_kind_and_baseline_once() {
        let sweep = Config::default().check().unwrap();
        let jobs = list(&sweep);
        let variants = sweep.variants();
        let baselines = sweep.baselines.len();
        assert_eq!(jobs.len(), (variants.len() + baselines) * sweep.rays.len());
        let mut uniq = jobs.clone();
        uniq.sort_by_key(|j| format!("{j:?}"));
        uniq.dedup();
        assert_eq!(uniq.len(), jobs.len(), "duplicate jobs");
        // Each encoding's jobs are contiguous: it is encoded and uploaded once.
        let last = last_uses(&jobs);
        for (i, j) in jobs.iter().enumerate() {
            if let Some(k) = encoding(j) {
                let first = jobs.iter().position(|x| encoding(x) == Some(k)).unwrap();
                assert!(
                    jobs[first..=last[&k]].iter().all(|x| encoding(x) == Some(k)),
                    "encoding {k:?} is needed again after job {i}"
                );
            }
        }
    }

    /// The job list of a sweep with every kind of job — layouts (one by its former name), a
    /// baseline, a rays file, user kernels with and without their own ray kinds, two scenes —
    /// in the order, with the names, targets, shards and `setup` hashes the list had when jobs
    /// were indices into the configuration (before jobs carried their own scene, rays and
    /// setup): `--resume` matches rows written then. The first scene and the rays file do not
    /// exist, so their stamps (path, size 0, time 0) and hashes are the same on every machine;
    /// the second scene's setup depends on its file's time and is left out.
    #[test]
    fn jobs_keep_their_order_names_shards_and_setup() {
        let k = std::env::temp_dir().join(format!("halftrace-jobs-kernel-{}.comp", std::process::id()));
        std::fs::write(&k, b"// a kernel\n").unwrap();
        let user = |name: &str, layout: &str| KernelTable {
            name: name.into(),
            layout: layout.into(),
            file: k.clone(),
            branching: None,
            packet: None,
            math: None,
            rays: None,
            kernel_timeout: None,
        };
        let cfg = Config {
            scenes: vec!["a.obj".into(), "scenes/teapot.obj".into()],
            rays: vec!["primary".into(), "ao".into(), "r.npy".into()],
            layouts: vec!["f32".into(), "f16h".into(), "rq".into(), "f16h-seed".into()],
            series: vec!["f16h".into()],
            branchings: vec![2, 4],
            layout_branchings: vec![8],
            packets: vec![1, 4],
            maths: vec!["f32".into(), "mixed".into()],
            width: 32,
            height: 16,
            seed: 7,
            kernel: vec![
                KernelTable {
                    branching: Some(8),
                    packet: Some(4),
                    math: Some("f32".into()),
                    rays: Some(vec!["grazing".into(), "ao".into()]),
                    ..user("mine", "f16h")
                },
                user("other", "f32"),
            ],
            ..Default::default()
        };
        let jobs = list(&cfg.check().unwrap());
        std::fs::remove_file(&k).unwrap();
        let bytes = [1000, 5_000_000];
        let shards: Vec<Vec<Job>> =
            (1..=4).flat_map(|n| (1..=n).map(move |k| Shard { k, n })).map(|s| shard(&jobs, s, &bytes)).collect();
        let mut text = String::new();
        for (i, j) in jobs.iter().enumerate() {
            let (name, source) = match &j.target {
                Target::Kernel(k) => {
                    (k.variant.name(false), if k.source == Source::Builtin { "builtin" } else { "user" })
                }
                Target::Baseline(b) => (b.name().to_string(), "-"),
            };
            let setup = if j.scene.index == 0 { j.setup.as_str() } else { "-" };
            // The shard of each of 1..=4 shares.
            let mut of = Vec::new();
            let mut first = 0;
            for n in 1..=4 {
                of.push((1..=n).find(|&k| shards[first + k - 1].contains(j)).unwrap());
                first += n;
            }
            text += &format!("{i} {} {} {name} {source} {:?} {setup} {of:?}\n", j.scene.name, j.rays.kind, j.user);
        }
        assert_eq!(format!("{:016x}", fnv1a(text.as_bytes())), "d3c3488851b2fd82", "the job list changed:\n{text}");
    }
}
