//! The sweep as data: the job list, generated in one place from a [`Config`].

use super::Config;
use crate::layout::LayoutId;
use crate::precision::Math;
use crate::rays::RayKind;
use crate::runner::Target;
use crate::variant::{KernelSpec, Source};
use std::collections::HashMap;

/// One row of the results: a scene (index into `Config::scenes`), a ray set (index into
/// [`kinds`]) and what traces it; `user` names the `Config::kernel` entry of a user kernel.
#[derive(Clone, Debug, PartialEq, Eq, Hash)]
pub struct Job {
    pub scene: usize,
    pub rays: usize,
    pub target: Target,
    pub user: Option<usize>,
}

/// The ray kinds of a sweep: the configured ones, then any a user kernel adds.
pub fn kinds(cfg: &Config) -> Vec<RayKind> {
    let mut k: Vec<RayKind> = cfg.rays.iter().map(|r| r.parse().expect("checked by Config::check")).collect();
    for spec in &cfg.kernel {
        for r in spec.rays.iter().flatten() {
            let r: RayKind = r.parse().expect("checked by Config::check");
            if !k.contains(&r) {
                k.push(r);
            }
        }
    }
    k
}

/// Every job, in the order the executor runs them: per scene, the built-in variants (sorted,
/// so each layout and B is contiguous and its BVH is encoded and uploaded once) over every ray
/// kind, then the baselines, then the user kernels.
pub fn list(cfg: &Config) -> Vec<Job> {
    let kinds = kinds(cfg);
    let index =
        |r: &str| kinds.iter().position(|k| *k == r.parse::<RayKind>().expect("checked")).expect("listed in kinds");
    let swept: Vec<usize> = cfg.rays.iter().map(|r| index(r)).collect();
    let fc = cfg.float_controls;
    let mut jobs = Vec::new();
    for scene in 0..cfg.scenes.len() {
        for v in cfg.variants() {
            let target = Target::Kernel(KernelSpec::builtin(v).with_fc(fc));
            jobs.extend(swept.iter().map(|&rays| Job { scene, rays, target: target.clone(), user: None }));
        }
        for b in cfg.baselines() {
            jobs.extend(swept.iter().map(|&rays| Job { scene, rays, target: Target::Baseline(b), user: None }));
        }
        for (i, spec) in cfg.kernel.iter().enumerate() {
            let rays: Vec<usize> = match &spec.rays {
                Some(r) => r.iter().map(|r| index(r)).collect(),
                None => swept.clone(),
            };
            let variant = spec.variant().expect("checked by Config::check");
            let target = Target::Kernel(KernelSpec::builtin(variant).with_fc(fc).with_source(Source::user(&spec.file)));
            jobs.extend(rays.into_iter().map(|rays| Job { scene, rays, target: target.clone(), user: Some(i) }));
        }
    }
    jobs
}

/// The (scene, layout, B) encoding a job needs, if any.
pub fn encoding(job: &Job) -> Option<(usize, LayoutId, usize)> {
    match &job.target {
        Target::Kernel(k) => Some((job.scene, k.variant.layout, k.variant.branching)),
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
fn cost(cfg: &Config, job: &Job, scene_bytes: &[u64]) -> f64 {
    let rays = (cfg.width as f64 * cfg.height as f64).max(1.0);
    let size = (scene_bytes[job.scene].max(2) as f64).ln();
    let factor = match (&job.target, job.user) {
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
pub fn shard(cfg: &Config, jobs: &[Job], shard: Shard, scene_bytes: &[u64]) -> Vec<Job> {
    #[derive(PartialEq)]
    enum Group {
        Encoding((usize, LayoutId, usize)),
        Baseline(usize, crate::baseline::BaselineId),
    }
    let mut groups: Vec<(Group, f64, Vec<usize>)> = Vec::new();
    for (i, j) in jobs.iter().enumerate() {
        let g = match (encoding(j), &j.target) {
            (Some(e), _) => Group::Encoding(e),
            (None, Target::Baseline(b)) => Group::Baseline(j.scene, *b),
            (None, Target::Kernel(_)) => unreachable!("every kernel job has an encoding"),
        };
        let c = cost(cfg, j, scene_bytes);
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

    #[test]
    fn shards_partition_the_jobs_keep_encodings_together_and_balance() {
        let cfg = Config { scenes: vec!["a.obj".into(), "b.obj".into(), "c.obj".into()], ..Default::default() };
        let jobs = list(&cfg);
        let bytes = [1_000_000, 50_000, 20_000_000];
        for n in [1, 2, 3, 5, 8] {
            let shards: Vec<Vec<Job>> = (1..=n).map(|k| shard(&cfg, &jobs, Shard { k, n }, &bytes)).collect();
            assert_eq!(
                shards,
                (1..=n).map(|k| shard(&cfg, &jobs, Shard { k, n }, &bytes)).collect::<Vec<_>>(),
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
                None => format!("{} {:?}", j.scene, j.target),
            };
            let biggest = jobs
                .iter()
                .map(|j| jobs.iter().filter(|x| group(x) == group(j)).map(|x| cost(&cfg, x, &bytes)).sum::<f64>())
                .fold(0.0, f64::max);
            let costs: Vec<f64> = shards.iter().map(|s| s.iter().map(|j| cost(&cfg, j, &bytes)).sum()).collect();
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
        let cfg = Config::default();
        let jobs = list(&cfg);
        let variants = cfg.variants();
        let baselines = cfg.baselines().len();
        assert_eq!(jobs.len(), (variants.len() + baselines) * cfg.rays.len());
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
}
