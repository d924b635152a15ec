//! The runner: the one way from a scene file to a validated, timed result, behind `trace`,
//! `sweep`, `bench` and `conformance`. It owns what results share and keeps each piece as long
//! as it is asked for:
//!
//! - one scene at a time, its binary SAH BVH built once ([`Runner::scene`]);
//! - ray sets by spec ([`Runner::ray_set`]), with the f32 reference's hits traced when first
//!   needed ([`Runner::f32_hits`]);
//! - per layout × B the encoded BVH and its device copy (freed with [`Runner::release`]);
//! - the latest CPU references per layout × B × P × math × float controls × ray set;
//! - kernels per [`KernelId`] and source, baselines per device and per scene;
//!
//! (the scene's share in `cache.rs`) and measures every [`Target`] the same way
//! ([`Runner::measure`]): resolve what the device runs (or skip, saying why), validate against
//! the reference ([`measure`]), then time. With [`Options::retime`] a target already validated
//! on a ray set is only timed again.

mod cache;
pub mod measure;
pub mod rays;
pub mod target;

pub use measure::{Measurement, Plan, Timing, Tracer};
pub use rays::{RaySet, RaySetId, RaySpec};
pub use target::{Facts, Outcome, Target};

use crate::base::Hit;
use crate::base::Status;
use crate::baseline::{BaselineDevice, BaselineId};
use crate::gpu::support::{self, Decision};
use crate::gpu::{Gpu, GpuError, Kernel};
use crate::precision::FloatControls;
use crate::variant::{KernelId, KernelSpec, Source};
use anyhow::Context;
use cache::SceneState;
use measure::FC_OFF_COUNTER_BOUND;
use std::cell::RefCell;
use std::collections::HashMap;
use target::{retime, status, BaselineTracer, KernelTracer};

/// How a runner keeps what it made.
#[derive(Clone, Copy, Debug, Default)]
pub struct Options {
    /// One measurement of one ray set (`trace`): every host array goes as soon as the device
    /// holds it or nothing needs it any more — the f32 reference encoding once the rays have
    /// their hits, the binary BVH once the layout is encoded, the layout's host nodes and
    /// triangles once uploaded; no CPU reference is kept. Anything asked for later is rebuilt.
    pub frugal: bool,
    /// Keep the hits of every validated (target, ray set), so that measuring it again only
    /// times it (`bench`'s interleaved rounds). Off, every measurement validates.
    pub retime: bool,
}

/// What validated hits are keyed by.
#[derive(Clone, Debug, PartialEq, Eq, Hash)]
enum Tracing {
    Kernel(KernelId, Source),
    Baseline(BaselineId),
}

pub struct Runner<'g> {
    gpu: Option<&'g Gpu>,
    opts: Options,
    /// Kernels per id and source; `None`: a user module that writes no counters.
    kernels: HashMap<(KernelId, Source), Option<Kernel<'g>>>,
    /// The device's decision for each kernel asked for (`support::decide`), made once.
    decisions: RefCell<HashMap<KernelSpec, Result<Decision, String>>>,
    /// Baselines prepared on the device, or why the device cannot run them.
    baselines: HashMap<BaselineId, Result<Box<dyn BaselineDevice<'g> + 'g>, String>>,
    scene: Option<SceneState<'g>>,
    /// Scenes loaded so far.
    loads: u64,
}

impl<'g> Runner<'g> {
    /// A runner on `gpu` (`None`: CPU references only), with `baselines` prepared on it.
    pub fn new(gpu: Option<&'g Gpu>, baselines: &[BaselineId], opts: Options) -> anyhow::Result<Runner<'g>> {
        let mut r = Runner {
            gpu,
            opts,
            kernels: HashMap::new(),
            decisions: RefCell::default(),
            baselines: HashMap::new(),
            scene: None,
            loads: 0,
        };
        if let Some(g) = gpu {
            for &b in baselines {
                let dev = match b.imp().unavailable(&g.info) {
                    Some(why) => Err(why),
                    None => Ok(b.imp().prepare(g).with_context(|| b.to_string())?),
                };
                r.baselines.insert(b, dev);
            }
        }
        Ok(r)
    }

    /// The device.
    pub fn gpu(&self) -> anyhow::Result<&'g Gpu> {
        self.gpu.ok_or_else(|| anyhow::anyhow!("no Vulkan device open (CPU reference only)"))
    }

    /// The device's decision for kernel `k` (made once per runner): what it builds, or why
    /// it cannot run it. `None` without a device.
    pub fn decide(&self, k: &KernelSpec) -> Option<Result<Decision, String>> {
        let g = self.gpu?;
        let mut d = self.decisions.borrow_mut();
        Some(d.entry(k.clone()).or_insert_with(|| support::decide(&g.info, k)).clone())
    }

    /// The kernel a kernel's results go under (the built-in kernel in the packet
    /// implementation the device uses, reading the scene bound; its name is the row's) and
    /// whether the device can build it (`false`: it cannot run it, the portable kernel).
    pub fn kernel_id(&self, k: &KernelSpec) -> (KernelId, bool) {
        match self.decide(k) {
            Some(Ok(d)) => (d.id.with_stats(false), true),
            _ => (KernelId::new(k.variant, k.variant.portable_impl(), false), false),
        }
    }

    /// Measures `target` on ray set `set` as `plan` says: the device's decision for it is
    /// made (a variant the device cannot run, or a baseline it lacks, is skipped with the
    /// reason), then it is validated (with `Options::retime`, once per target and ray set),
    /// then timed.
    pub fn measure(&mut self, target: &Target, set: RaySetId, plan: Plan) -> anyhow::Result<Outcome> {
        self.index(set);
        match target {
            Target::Kernel(k) => self.measure_kernel(k, set, plan),
            Target::Baseline(b) => self.measure_baseline(*b, set, plan),
        }
    }

    /// The hits `key` was validated with, when it was validated with counters if `count`.
    fn validated(&self, key: &(Tracing, RaySetId), count: bool) -> Option<Vec<Hit>> {
        let (counted, hits) = self.scene.as_ref()?.validated.get(key)?;
        (*counted || !count).then(|| hits.clone())
    }

    fn remember(&mut self, key: (Tracing, RaySetId), m: &Measurement, count: bool) {
        if self.opts.retime && m.failure.is_none() {
            let e = self.state().validated.entry(key).or_insert((count, Vec::new()));
            if e.1.is_empty() || count {
                *e = (count || e.0, m.hits.clone());
            }
        }
    }

    fn measure_kernel(&mut self, k: &KernelSpec, set: RaySetId, plan: Plan) -> anyhow::Result<Outcome> {
        let gpu = self.gpu()?;
        let skipped = |name: String, why: String| Outcome {
            status: Status::Skipped(why),
            kernel: None,
            name,
            m: Measurement::none(),
            facts: Facts::default(),
        };
        let d = match self.decide(k).expect("a device is open") {
            Ok(d) => d,
            Err(why) => return Ok(skipped(k.variant.name(false), why)),
        };
        let (v, name) = (d.id.variant, d.id.name());
        // The f32 hits, then the reference, then the upload: in frugal mode each step frees
        // what the one before needed.
        self.ensure_f32_hits(set)?;
        let frugal = self.opts.frugal;
        let reference = if frugal { Some(self.reference(&v, set).with_context(|| name.clone())?) } else { None };
        self.upload(v.layout, v.branching).with_context(|| name.clone())?;
        let facts = self.state().encodings[&(v.layout, v.branching)].facts;
        // A scene beyond one storage buffer is read by address; the name stays the variant's.
        let d = match d.reading(&gpu.info, facts.buffers) {
            Ok(d) => d,
            Err(why) => return Ok(skipped(name, why)),
        };
        let (v, id) = (d.id.variant, d.id);
        for stats in [false, true].into_iter().take(if plan.count { 2 } else { 1 }) {
            match self.kernel(&d, stats, &k.source) {
                Ok(()) => {}
                Err(GpuError::Unsupported(why)) => return Ok(skipped(name, why)),
                Err(e) => return Err(anyhow::Error::new(e).context(name)),
            }
        }
        let key = (Tracing::Kernel(id, k.source.clone()), set);
        let validated = self.validated(&key, plan.count);
        let reference = match (&validated, reference) {
            (Some(_), _) => None,
            (None, Some(r)) => Some(r),
            (None, None) => Some(self.reference(&v, set).with_context(|| name.clone())?),
        };
        let s = self.scene.as_ref().expect("current");
        let rs = &s.sets[set.index];
        let f32_hits = rs.f32_hits.as_deref().expect("traced above");
        let bvh = s.encodings[&(v.layout, v.branching)].bvh.as_ref().expect("uploaded");
        let timed = self.kernels[&(id, k.source.clone())].as_ref().expect("a timed kernel is always built");
        let counting = self.kernels.get(&(id.with_stats(true), k.source.clone())).and_then(Option::as_ref);
        let tracer = KernelTracer {
            gpu,
            bvh,
            timed,
            counting: counting.filter(|_| plan.count),
            scene: &s.scene,
            bin: s.bin.as_ref(),
        };
        let m = match (validated, reference) {
            (Some(hits), _) => retime(&tracer, &rs.rays, &hits, f32_hits, plan)?,
            (None, Some((hits, counters))) => {
                let n = rs.rays.len();
                let slack = if v.fc == FloatControls::Off { (FC_OFF_COUNTER_BOUND * n as f64) as usize } else { 0 };
                let conservative = v.layout.info().conservative;
                let (hits, counters) = (&hits, &counters);
                let reference = measure::Reference::Exact { hits, counters, conservative, counter_slack: slack };
                measure::validate_then_time(&tracer, &rs.rays, reference, f32_hits, plan)
                    .with_context(|| name.clone())?
            }
            (None, None) => unreachable!("a reference is made when nothing was validated"),
        };
        self.remember(key, &m, plan.count);
        Ok(Outcome { status: status(&m), kernel: Some(id), name, m, facts })
    }

    /// Builds the built-in kernels of `ks` that the device admits and this runner has not built
    /// yet, timed and counting, on every core at once (pipelines are independent), so that
    /// measuring them later finds them built; on a device that compiles at the first dispatch
    /// ([`Gpu::compiles_at_first_dispatch`]) the kernels are also warmed, on every core, so
    /// that the first dispatches find their code compiled. A kernel that fails to build is
    /// left out: measuring it builds it again and reports why.
    pub fn prebuild(&mut self, ks: &[KernelSpec]) {
        use rayon::prelude::*;
        let Some(gpu) = self.gpu else { return };
        let mut todo = Vec::new();
        for k in ks.iter().filter(|k| k.source == Source::Builtin) {
            let Some(Ok(d)) = self.decide(k) else { continue };
            for stats in [false, true] {
                if !self.kernels.contains_key(&(d.id.with_stats(stats), Source::Builtin)) {
                    todo.push(d.with_stats(stats));
                }
            }
        }
        todo.sort_by_key(|d| d.id);
        todo.dedup();
        if gpu.compiles_at_first_dispatch() {
            // Its first dispatches would compile one kernel at a time; warmed on one sibling
            // device per core, they find the code in Mesa's shader cache instead.
            let n = rayon::current_num_threads().clamp(1, todo.len().max(1));
            (0..n).into_par_iter().for_each(|t| {
                let Ok(sib) = gpu.sibling() else { return };
                for d in todo.iter().skip(t).step_by(n) {
                    if let Ok(k) = Kernel::build(&sib, d, &Source::Builtin) {
                        let _ = k.pipe.warm();
                    }
                }
            });
        }
        let built: Vec<(KernelId, Kernel<'g>)> =
            todo.par_iter().filter_map(|d| Kernel::build(gpu, d, &Source::Builtin).ok().map(|k| (d.id, k))).collect();
        for (id, k) in built {
            self.kernels.insert((id, Source::Builtin), Some(k));
        }
    }

    /// Builds (once) the kernel of decision `d`, timed or counting (`stats`), from `source`;
    /// a user's counting kernel may not exist.
    fn kernel(&mut self, d: &Decision, stats: bool, source: &Source) -> Result<(), GpuError> {
        let key = (d.id.with_stats(stats), source.clone());
        if self.kernels.contains_key(&key) {
            return Ok(());
        }
        let gpu = self.gpu.expect("kernels need a device");
        let k = match (source, stats) {
            (Source::Builtin, _) | (_, false) => Some(Kernel::build(gpu, &d.with_stats(stats), source)?),
            (_, true) => Kernel::user_counting(gpu, d, source)?,
        };
        self.kernels.insert(key, k);
        Ok(())
    }

    fn measure_baseline(&mut self, b: BaselineId, set: RaySetId, plan: Plan) -> anyhow::Result<Outcome> {
        let name = b.imp().kernel().to_string();
        let none = |status: Status, name: String| Outcome {
            status,
            kernel: None,
            name,
            m: Measurement::none(),
            facts: Facts::default(),
        };
        match self.baselines.get(&b) {
            Some(Ok(_)) => {}
            Some(Err(why)) => return Ok(none(Status::Skipped(why.clone()), name)),
            None => anyhow::bail!("baseline {b} was not prepared on this runner"),
        }
        self.ensure_f32_hits(set)?;
        let key = (Tracing::Baseline(b), set);
        let validated = self.validated(&key, false);
        let s = self.scene.as_mut().expect("Runner::scene first");
        if !s.baselines.contains_key(&b) {
            let dev = self.baselines[&b].as_ref().expect("prepared");
            let built = dev.scene(&s.scene).with_context(|| format!("{b} on {}", s.scene.name))?;
            s.baselines.insert(b, built);
        }
        let bs = &s.baselines[&b];
        let facts = Facts {
            bvh_bytes: bs.bytes(),
            build_ms: bs.build_ms(),
            triangle_bytes: (s.scene.len() * 36) as u64,
            ..Facts::default()
        };
        let rs = &s.sets[set.index];
        let f32_hits = rs.f32_hits.as_deref().expect("traced above");
        let tracer = BaselineTracer { name: &name, scene: bs.as_ref() };
        let m = match validated {
            Some(hits) => retime(&tracer, &rs.rays, &hits, f32_hits, plan)?,
            None => measure::validate_then_time(&tracer, &rs.rays, measure::Reference::Agreement, f32_hits, plan)?,
        };
        self.remember(key, &m, false);
        Ok(Outcome { status: status(&m), kernel: None, name, m, facts })
    }
}
