//! The sweep as data: the job list, generated in one place from a [`Config`].

use super::Config;
use crate::layout::LayoutId;
use crate::rays::RayKind;
use crate::variant::Variant;
use std::collections::HashMap;

/// What a job traces with.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Target {
    /// A built-in kernel of a BVH layout.
    Variant(Variant),
    /// A baseline (e.g. `rq`).
    Baseline(LayoutId),
    /// The user kernel `Config::kernel[i]`.
    Kernel(usize),
}

/// One row of the results: a scene (index into `Config::scenes`), a ray set (index into
/// [`kinds`]) and a target.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct Job {
    pub scene: usize,
    pub rays: usize,
    pub target: Target,
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
    let index = |r: &str| kinds.iter().position(|k| *k == r.parse::<RayKind>().expect("checked")).expect("listed in kinds");
    let swept: Vec<usize> = cfg.rays.iter().map(|r| index(r)).collect();
    let mut jobs = Vec::new();
    for scene in 0..cfg.scenes.len() {
        for v in cfg.variants() {
            jobs.extend(swept.iter().map(|&rays| Job { scene, rays, target: Target::Variant(v) }));
        }
        for b in cfg.entries().into_iter().filter(|l| l.baseline().is_some()) {
            jobs.extend(swept.iter().map(|&rays| Job { scene, rays, target: Target::Baseline(b) }));
        }
        for (i, spec) in cfg.kernel.iter().enumerate() {
            let rays: Vec<usize> = match &spec.rays {
                Some(r) => r.iter().map(|r| index(r)).collect(),
                None => swept.clone(),
            };
            jobs.extend(rays.into_iter().map(|rays| Job { scene, rays, target: Target::Kernel(i) }));
        }
    }
    jobs
}

/// The (scene, layout, B) encoding a job needs, if any.
pub fn encoding(cfg: &Config, job: &Job) -> Option<(usize, LayoutId, usize)> {
    match job.target {
        Target::Variant(v) => Some((job.scene, v.layout, v.branching)),
        Target::Kernel(i) => cfg.kernel[i].variant().ok().map(|v| (job.scene, v.layout, v.branching)),
        Target::Baseline(_) => None,
    }
}

/// For each encoding, the index of the last job that needs it (so it can be freed after).
pub fn last_uses(cfg: &Config, jobs: &[Job]) -> HashMap<(usize, LayoutId, usize), usize> {
    let mut m = HashMap::new();
    for (i, j) in jobs.iter().enumerate() {
        if let Some(k) = encoding(cfg, j) {
            m.insert(k, i);
        }
    }
    m
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn default_jobs_cover_every_variant_kind_and_baseline_once() {
        let cfg = Config::default();
        let jobs = list(&cfg);
        let variants = cfg.variants();
        let baselines = cfg.entries().into_iter().filter(|l| l.baseline().is_some()).count();
        assert_eq!(jobs.len(), (variants.len() + baselines) * cfg.rays.len());
        let mut uniq = jobs.clone();
        uniq.sort_by_key(|j| format!("{j:?}"));
        uniq.dedup();
        assert_eq!(uniq.len(), jobs.len(), "duplicate jobs");
        // Each encoding's jobs are contiguous: it is encoded and uploaded once.
        let last = last_uses(&cfg, &jobs);
        for (i, j) in jobs.iter().enumerate() {
            if let Some(k) = encoding(&cfg, j) {
                let first = jobs.iter().position(|x| encoding(&cfg, x) == Some(k)).unwrap();
                assert!(jobs[first..=last[&k]].iter().all(|x| encoding(&cfg, x) == Some(k)), "encoding {k:?} is needed again after job {i}");
            }
        }
    }
}
