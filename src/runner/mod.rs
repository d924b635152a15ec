//! The runner: the one way from a scene file to a validated, timed result, behind `trace`,
//! `sweep`, `bench` and `conformance`. It owns what results share and keeps each piece as long
//! as it is asked for:
//!
//! - one scene at a time, its binary SAH BVH built once ([`Runner::scene`]);
//! - ray sets by spec, each with the f32 reference's hits ([`Runner::ray_set`]);
//! - per layout × B the encoded BVH and its device copy (freed with [`Runner::release`]);
//! - CPU references per layout × B × P × math × float controls × ray set;
//! - kernels per [`KernelId`] and source, baselines per device and per scene;
//!
//! and measures every [`Target`] the same way ([`Runner::measure`]): resolve what the device
//! runs (or skip, saying why), validate against the reference ([`measure`]), then time. A
//! target already validated on a ray set is only timed again.

pub mod measure;
pub mod rays;
pub mod target;

pub use measure::{Measurement, Plan, Timing, Tracer};
pub use rays::{RaySet, RaySetId, RaySpec};
pub use target::{Facts, KernelTarget, Outcome, Target};

use crate::base::{Counters, Hit};
use crate::baseline::{BaselineDevice, BaselineId, BaselineScene};
use crate::bvh::{self, BinaryBvh};
use crate::gpu::{self, support, Gpu, GpuBvh, GpuError, Kernel, Source};
use crate::layout::{Encoded, LayoutId};
use crate::precision::{FloatControls, Math};
use crate::rays::RayKind;
use crate::report::Status;
use crate::scene::Scene;
use crate::variant::{KernelId, PacketImpl, Variant};
use anyhow::Context;
use measure::FC_OFF_COUNTER_BOUND;
use std::collections::HashMap;
use std::path::{Path, PathBuf};
use std::time::Instant;
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

/// A BVH encoded in one layout at one B, on the host and then on the device.
struct Resident<'g> {
    /// The host encoding (dropped in frugal mode once uploaded; re-encoded when needed).
    enc: Option<Encoded>,
    bvh: Option<GpuBvh<'g>>,
    facts: Facts,
}

/// The reference of a kernel target on a ray set.
type RefKey = (LayoutId, usize, usize, Math, FloatControls, RaySetId);
/// A CPU reference: hits and counters.
type CpuReference = (Vec<Hit>, Vec<Counters>);

/// What a scene's measurements share.
struct SceneState<'g> {
    path: PathBuf,
    /// Which load of a scene this is (ray set ids carry it).
    epoch: u64,
    scene: Scene,
    /// The binary BVH (rebuilt when needed after a frugal drop).
    bin: Option<BinaryBvh>,
    binary_ms: f64,
    /// The f32 layout at B = 4: the reference every result is compared with.
    f32_ref: Option<Encoded>,
    sets: Vec<RaySet>,
    encodings: HashMap<(LayoutId, usize), Resident<'g>>,
    /// The latest CPU references (the few a layout × B's kernels share).
    refs: Vec<(RefKey, CpuReference)>,
    baselines: HashMap<BaselineId, Box<dyn BaselineScene + 'g>>,
    /// With `Options::retime`: the hits of each (tracer, ray set) validated so far, and
    /// whether its counters were checked too.
    validated: HashMap<(Tracing, RaySetId), (bool, Vec<Hit>)>,
}

/// What validated hits are keyed by.
#[derive(Clone, Debug, PartialEq, Eq, Hash)]
enum Tracing {
    Kernel(KernelId, Source),
    Baseline(BaselineId),
}

/// How many CPU references a scene keeps.
const KEPT_REFERENCES: usize = 8;

pub struct Runner<'g> {
    gpu: Option<&'g Gpu>,
    opts: Options,
    /// Kernels per id and source; `None`: a user module that writes no counters.
    kernels: HashMap<(KernelId, Source), Option<Kernel<'g>>>,
    /// Baselines prepared on the device, or why the device cannot run them.
    baselines: HashMap<BaselineId, Result<Box<dyn BaselineDevice<'g> + 'g>, String>>,
    scene: Option<SceneState<'g>>,
    /// Scenes loaded so far.
    loads: u64,
}

impl<'g> Runner<'g> {
    /// A runner on `gpu` (`None`: CPU references only), with `baselines` prepared on it.
    pub fn new(gpu: Option<&'g Gpu>, baselines: &[BaselineId], opts: Options) -> anyhow::Result<Runner<'g>> {
        let mut r = Runner { gpu, opts, kernels: HashMap::new(), baselines: HashMap::new(), scene: None, loads: 0 };
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

    /// Makes the scene at `path` current (loading it and building its binary BVH when it is
    /// not already); returns it and the build time (ms).
    pub fn scene(&mut self, path: &Path) -> anyhow::Result<(&Scene, f64)> {
        if self.scene.as_ref().is_none_or(|s| s.path != path) {
            self.scene = None;
            let scene = crate::scene::load(path)?;
            let t = Instant::now();
            let bin = bvh::build_binary(&scene);
            let binary_ms = t.elapsed().as_secs_f64() * 1e3;
            self.loads += 1;
            self.scene = Some(SceneState {
                path: path.into(),
                epoch: self.loads,
                scene,
                bin: Some(bin),
                binary_ms,
                f32_ref: None,
                sets: Vec::new(),
                encodings: HashMap::new(),
                refs: Vec::new(),
                baselines: HashMap::new(),
                validated: HashMap::new(),
            });
        }
        let s = self.scene.as_ref().expect("just made");
        Ok((&s.scene, s.binary_ms))
    }

    /// The current scene, if any.
    pub fn current_scene(&self) -> Option<&Scene> {
        self.scene.as_ref().map(|s| &s.scene)
    }

    /// The name a kernel target's results go under (the built-in kernel's name in the packet
    /// implementation the device uses, reading the scene bound) and the float controls the
    /// device builds it with (`None`: the device cannot run it).
    pub fn name(&self, k: &KernelTarget) -> (String, Option<FloatControls>) {
        let Some(g) = self.gpu else { return (k.variant.name(false), None) };
        match support::resolve(&g.info, k.variant, k.fc) {
            Ok(v) => (v.kernel_name(imp_of(g, &v, k.imp), false), Some(v.fc)),
            Err(_) => (k.variant.name(false), None),
        }
    }

    fn state(&mut self) -> &mut SceneState<'g> {
        self.scene.as_mut().expect("Runner::scene first")
    }

    /// The index of a ray set of the current scene.
    fn index(&self, id: RaySetId) -> usize {
        let s = self.scene.as_ref().expect("Runner::scene first");
        assert_eq!(id.epoch, s.epoch, "a ray set of another scene");
        id.index
    }

    /// The rays of a set made earlier.
    pub fn rays(&self, id: RaySetId) -> &RaySet {
        &self.scene.as_ref().expect("Runner::scene first").sets[self.index(id)]
    }

    /// The ray set `spec` of the current scene, made once: generated (ao and diffuse from the
    /// primary rays of the same parameters and their f32 hits) or read.
    pub fn ray_set(&mut self, spec: &RaySpec) -> anyhow::Result<RaySetId> {
        let id = self.make_set(spec)?;
        if self.opts.frugal {
            self.release_f32_reference();
        }
        Ok(id)
    }

    fn make_set(&mut self, spec: &RaySpec) -> anyhow::Result<RaySetId> {
        let epoch = self.state().epoch;
        if let Some(index) = self.state().sets.iter().position(|s| s.spec == *spec) {
            return Ok(RaySetId { epoch, index });
        }
        let prim = match spec.kind {
            RayKind::Ao | RayKind::Diffuse => {
                let p = self.make_set(&RaySpec { kind: RayKind::Primary, ..spec.clone() })?;
                self.ensure_f32_hits(p)?;
                Some(p)
            }
            _ => None,
        };
        self.ensure_bin();
        let s = self.state();
        let primary = prim.map(|p| {
            let set = &s.sets[p.index];
            (&set.rays[..], set.f32_hits.as_deref().expect("made above"))
        });
        let rays = rays::generate(&s.scene, s.bin.as_ref().expect("built"), spec, primary)?;
        s.sets.push(RaySet { spec: spec.clone(), rays, f32_hits: None });
        Ok(RaySetId { epoch, index: s.sets.len() - 1 })
    }

    /// The f32 reference's hits on ray set `id` (traced once, when first asked for).
    pub fn f32_hits(&mut self, id: RaySetId) -> anyhow::Result<&[Hit]> {
        self.ensure_f32_hits(id)?;
        let i = self.index(id);
        Ok(self.state().sets[i].f32_hits.as_deref().expect("just traced"))
    }

    fn ensure_f32_hits(&mut self, id: RaySetId) -> anyhow::Result<()> {
        let i = self.index(id);
        if self.state().sets[i].f32_hits.is_some() {
            return Ok(());
        }
        if self.state().f32_ref.is_none() {
            self.ensure_bin();
            let s = self.scene.as_ref().expect("current");
            let enc = Encoded::new(&s.scene, s.bin.as_ref().expect("built"), LayoutId::f32(), 4)?;
            self.state().f32_ref = Some(enc);
        }
        let s = self.state();
        let hits = s.f32_ref.as_ref().expect("just made").reference_default(&s.sets[i].rays).0;
        s.sets[i].f32_hits = Some(hits);
        if self.opts.frugal {
            self.release_f32_reference();
        }
        Ok(())
    }

    /// Makes sure the current scene has its binary BVH (rebuilt if a frugal run dropped it).
    fn ensure_bin(&mut self) {
        let s = self.state();
        if s.bin.is_none() {
            s.bin = Some(bvh::build_binary(&s.scene));
        }
    }

    /// Drops the f32 reference encoding (a big scene's memory); it is rebuilt if needed.
    pub fn release_f32_reference(&mut self) {
        if let Some(s) = self.scene.as_mut() {
            s.f32_ref = None;
        }
    }

    /// Frees the encoding of `layout` at `b` (host and device), its references and what was
    /// validated on it.
    pub fn release(&mut self, layout: LayoutId, b: usize) {
        if let Some(s) = self.scene.as_mut() {
            s.encodings.remove(&(layout, b));
            s.refs.retain(|(k, _)| (k.0, k.1) != (layout, b));
            s.validated.retain(|(t, _), _| {
                !matches!(t, Tracing::Kernel(k, _) if (k.variant.layout, k.variant.branching) == (layout, b))
            });
        }
    }

    /// Encodes `layout` at `b` for the current scene, unless it is (so that a later reference
    /// or upload does not include the encoding's time).
    pub fn encode(&mut self, layout: LayoutId, b: usize) -> anyhow::Result<()> {
        self.encoding(layout, b).map(|_| ())
    }

    /// The host encoding of `layout` at `b`, encoded once (again after a frugal drop).
    fn encoding(&mut self, layout: LayoutId, b: usize) -> anyhow::Result<&Encoded> {
        let have = self.state().encodings.get(&(layout, b)).is_some_and(|r| r.enc.is_some());
        if !have {
            self.ensure_bin();
            let t = Instant::now();
            let s = self.scene.as_ref().expect("current");
            let enc = Encoded::new(&s.scene, s.bin.as_ref().expect("built"), layout, b)?;
            let frugal = self.opts.frugal;
            let s = self.state();
            let facts = Facts {
                bvh_bytes: enc.node_bytes() as u64,
                node_size: enc.node_size() as u64,
                triangle_bytes: enc.tris.bytes() as u64,
                build_ms: s.binary_ms + t.elapsed().as_secs_f64() * 1e3,
                ..Facts::default()
            };
            let r = s.encodings.entry((layout, b)).or_insert(Resident { enc: None, bvh: None, facts });
            r.enc = Some(enc);
            if frugal {
                s.bin = None;
            }
        }
        Ok(self.state().encodings[&(layout, b)].enc.as_ref().expect("just made"))
    }

    /// The device copy of `layout` at `b`, uploaded once.
    fn upload(&mut self, layout: LayoutId, b: usize) -> anyhow::Result<()> {
        if self.state().encodings.get(&(layout, b)).is_some_and(|r| r.bvh.is_some()) {
            return Ok(());
        }
        let gpu = self.gpu()?;
        self.encoding(layout, b)?;
        let frugal = self.opts.frugal;
        let r = self.state().encodings.get_mut(&(layout, b)).expect("encoded");
        let what = || format!("{layout}, B={b}");
        let bvh = if frugal {
            GpuBvh::upload_owned(gpu, r.enc.take().expect("encoded")).with_context(what)?
        } else {
            GpuBvh::upload(gpu, r.enc.as_ref().expect("encoded")).with_context(what)?
        };
        (r.facts.buffers, r.facts.upload_bytes) = (bvh.buffers, bvh.bytes);
        r.bvh = Some(bvh);
        Ok(())
    }

    /// The CPU reference of `v` on ray set `set` (the latest few are kept, unless frugal).
    pub fn reference(&mut self, v: &Variant, set: RaySetId) -> anyhow::Result<(Vec<Hit>, Vec<Counters>)> {
        let key = (v.layout, v.branching, v.packet, v.math, v.fc, set);
        if let Some((_, r)) = self.state().refs.iter().find(|(k, _)| *k == key) {
            return Ok(r.clone());
        }
        let i = self.index(set);
        self.encoding(v.layout, v.branching)?;
        let frugal = self.opts.frugal;
        let s = self.state();
        let enc = s.encodings[&(v.layout, v.branching)].enc.as_ref().expect("just encoded");
        let r = enc.reference(&s.sets[i].rays, v.packet, v.math, v.fc);
        if !frugal {
            if s.refs.len() == KEPT_REFERENCES {
                s.refs.remove(0);
            }
            s.refs.push((key, r.clone()));
        }
        Ok(r)
    }

    /// Measures `target` on ray set `set` as `plan` says: the device's build of it is resolved
    /// (a variant the device cannot run, or a baseline it lacks, is skipped with the reason),
    /// validated (with `Options::retime`, once per target and ray set), then timed.
    pub fn measure(&mut self, target: &Target, set: RaySetId, plan: Plan) -> anyhow::Result<Outcome> {
        self.index(set);
        match target {
            Target::Kernel(k) => self.measure_kernel(k, set, plan),
            Target::Baseline(b) => self.measure_baseline(*b, set, plan),
        }
    }

    /// The kernel the device runs for `k` (float controls resolved), or why it cannot.
    pub fn resolve(&self, k: &KernelTarget) -> anyhow::Result<Result<Variant, String>> {
        Ok(support::resolve(&self.gpu()?.info, k.variant, k.fc))
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

    fn measure_kernel(&mut self, k: &KernelTarget, set: RaySetId, plan: Plan) -> anyhow::Result<Outcome> {
        let gpu = self.gpu()?;
        let skipped = |name: String, why: String| Outcome {
            status: Status::Skipped(why),
            kernel: None,
            name,
            m: Measurement::none(),
            facts: Facts::default(),
        };
        let v = match support::resolve(&gpu.info, k.variant, k.fc) {
            Ok(v) => v,
            Err(why) => return Ok(skipped(k.variant.name(false), why)),
        };
        let (name, _) = self.name(k);
        // The f32 hits, then the reference, then the upload: in frugal mode each step frees
        // what the one before needed.
        self.ensure_f32_hits(set)?;
        let frugal = self.opts.frugal;
        let reference = if frugal { Some(self.reference(&v, set).with_context(|| name.clone())?) } else { None };
        self.upload(v.layout, v.branching).with_context(|| name.clone())?;
        let facts = self.state().encodings[&(v.layout, v.branching)].facts;
        // A scene beyond one storage buffer is read by address; the name stays the variant's.
        let v = v.with_buffers(facts.buffers);
        let id = KernelId::new(v, imp_of(gpu, &v, k.imp), false);
        for stats in [false, true].into_iter().take(if plan.count { 2 } else { 1 }) {
            match self.kernel(&id.with_stats(stats), &k.source) {
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
        let tracer = KernelTracer { gpu, bvh, timed, counting: counting.filter(|_| plan.count) };
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

    /// Builds (once) kernel `id` from `source`; a user's counting kernel may not exist.
    fn kernel(&mut self, id: &KernelId, source: &Source) -> Result<(), GpuError> {
        let key = (*id, source.clone());
        if self.kernels.contains_key(&key) {
            return Ok(());
        }
        let gpu = self.gpu.expect("kernels need a device");
        let k = match (source, id.stats) {
            (Source::Builtin, _) | (_, false) => Some(Kernel::build(gpu, id, source)?),
            (_, true) => Kernel::user_counting(gpu, id, source)?,
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

/// The packet implementation a kernel target runs with: the one asked for (packets only),
/// else the device's choice.
fn imp_of(gpu: &Gpu, v: &Variant, asked: Option<PacketImpl>) -> PacketImpl {
    gpu::kernel::choose_impl(gpu, v, asked.filter(|_| v.packet > 1))
}
