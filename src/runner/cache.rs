//! What a scene's measurements share, kept as long as they are asked for: the scene and its
//! binary BVH, ray sets and their f32 hits, encodings and their device copies per layout × B,
//! the latest CPU references (see the module docs of [`super`]).

use super::rays;
use super::target::Facts;
use super::{RaySet, RaySetId, RaySpec, Runner, Tracing};
use crate::base::{Counters, Hit};
use crate::baseline::{BaselineId, BaselineScene};
use crate::bvh::{self, BinaryBvh};
use crate::gpu::GpuBvh;
use crate::layout::traverse::{BranchWork, LoopWork, Reads};
use crate::layout::{Encoded, LayoutId};
use crate::precision::{FloatControls, Math};
use crate::rays::RayKind;
use crate::scene::Scene;
use crate::variant::Variant;
use anyhow::Context;
use std::collections::HashMap;
use std::path::{Path, PathBuf};
use std::time::Instant;

/// A BVH encoded in one layout at one B, on the host and then on the device.
pub(super) struct Resident<'g> {
    /// The host encoding (dropped in frugal mode once uploaded; re-encoded when needed).
    pub(super) enc: Option<Encoded>,
    pub(super) bvh: Option<GpuBvh<'g>>,
    pub(super) facts: Facts,
}

/// The reference of a kernel target on a ray set.
type RefKey = (LayoutId, usize, usize, Math, FloatControls, RaySetId);
/// A CPU reference: hits and counters.
type CpuReference = (Vec<Hit>, Vec<Counters>);

/// What a scene's measurements share.
pub(super) struct SceneState<'g> {
    pub(super) path: PathBuf,
    /// Which load of a scene this is (ray set ids carry it).
    pub(super) epoch: u64,
    pub(super) scene: Scene,
    /// The binary BVH (rebuilt when needed after a frugal drop).
    pub(super) bin: Option<BinaryBvh>,
    pub(super) binary_ms: f64,
    /// The f32 layout at B = 4: the reference every result is compared with.
    pub(super) f32_ref: Option<Encoded>,
    pub(super) sets: Vec<RaySet>,
    pub(super) encodings: HashMap<(LayoutId, usize), Resident<'g>>,
    /// The latest CPU references (the few a layout × B's kernels share).
    pub(super) refs: Vec<(RefKey, CpuReference)>,
    pub(super) baselines: HashMap<BaselineId, Box<dyn BaselineScene + 'g>>,
    /// With `Options::retime`: the hits of each (tracer, ray set) validated so far, and
    /// whether its counters were checked too.
    pub(super) validated: HashMap<(Tracing, RaySetId), (bool, Vec<Hit>)>,
}

/// How many CPU references a scene keeps.
const KEPT_REFERENCES: usize = 8;

impl<'g> Runner<'g> {
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
    pub(super) fn state(&mut self) -> &mut SceneState<'g> {
        self.scene.as_mut().expect("Runner::scene first")
    }

    /// The index of a ray set of the current scene.
    pub(super) fn index(&self, id: RaySetId) -> usize {
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

    pub(super) fn ensure_f32_hits(&mut self, id: RaySetId) -> anyhow::Result<()> {
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
        let enc = s.f32_ref.as_ref().expect("just made");
        let mut hits = enc.trace_raw_default(&s.sets[i].rays);
        crate::bvh::exact::resolve(&s.scene, s.bin.as_ref(), &s.sets[i].rays, &mut hits);
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
    pub fn encoding(&mut self, layout: LayoutId, b: usize) -> anyhow::Result<&Encoded> {
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
    pub(super) fn upload(&mut self, layout: LayoutId, b: usize) -> anyhow::Result<()> {
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

    /// How often `v`'s loops run on ray set `set`, its rays in packets of `v.packet` and waves
    /// of `wave` lanes (the estimate's trips: [`crate::layout::traverse::loop_work`]), on the
    /// encoding this scene keeps.
    pub fn loop_work(&mut self, v: &Variant, set: RaySetId, wave: usize) -> anyhow::Result<(LoopWork, LoopWork)> {
        let i = self.index(set);
        self.encoding(v.layout, v.branching)?;
        let s = self.scene.as_ref().expect("current");
        let enc = s.encodings[&(v.layout, v.branching)].enc.as_ref().expect("just encoded");
        Ok(v.layout.imp().loop_work(enc, &s.sets[i].rays, v.packet, wave, v.math, v.fc))
    }

    /// How often `v`'s named branches run on ray set `set`, in waves of `wave` lanes and each
    /// packet on its own ([`crate::layout::traverse::branch_work`]: the estimate's branch
    /// weights).
    pub fn branch_work(&mut self, v: &Variant, set: RaySetId, wave: usize) -> anyhow::Result<(BranchWork, BranchWork)> {
        let (reads, _) = self.mem_reads(v, set)?;
        let i = self.index(set);
        let s = self.scene.as_ref().expect("current");
        let enc = s.encodings[&(v.layout, v.branching)].enc.as_ref().expect("just encoded");
        Ok(crate::layout::traverse::branch_work(&reads, &s.sets[i].rays, &enc.tris, v.packet, wave))
    }

    /// Every packet's reads of the scene's buffers for `v` on ray set `set`, pass by pass
    /// ([`crate::layout::traverse::mem_reads`]), with the encoding's node size, node count
    /// and triangle count.
    pub fn mem_reads(&mut self, v: &Variant, set: RaySetId) -> anyhow::Result<(Vec<Vec<Reads>>, [usize; 3])> {
        let i = self.index(set);
        self.encoding(v.layout, v.branching)?;
        let s = self.scene.as_ref().expect("current");
        let enc = s.encodings[&(v.layout, v.branching)].enc.as_ref().expect("just encoded");
        let sizes = [enc.node_size(), enc.nodes.len(), enc.tris.verts.len()];
        Ok((v.layout.imp().mem_reads(enc, &s.sets[i].rays, v.packet, v.math, v.fc), sizes))
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
        let (mut hits, counters) = enc.trace_raw(&s.sets[i].rays, v.packet, v.math, v.fc);
        crate::bvh::exact::resolve(&s.scene, s.bin.as_ref(), &s.sets[i].rays, &mut hits);
        let r = (hits, counters);
        if !frugal {
            if s.refs.len() == KEPT_REFERENCES {
                s.refs.remove(0);
            }
            s.refs.push((key, r.clone()));
        }
        Ok(r)
    }
}
