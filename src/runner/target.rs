//! What the runner measures ([`Target`]), what a measurement yields ([`Outcome`]), and the
//! tracers that dispatch a kernel or a baseline for [`super::measure`].

use super::measure::{self, Measurement, Plan, Tracer};
use crate::base::Status;
use crate::base::{Hit, Ray, RunOutput};
use crate::baseline::{BaselineId, BaselineScene};
use crate::bvh::BinaryBvh;
use crate::gpu::{Gpu, GpuBvh, Kernel};
use crate::scene::Scene;
use crate::variant::{Buffers, KernelId, KernelSpec, Variant};

/// What a measurement traces with.
#[derive(Clone, Debug, PartialEq, Eq, Hash)]
pub enum Target {
    /// A kernel of a variant: the built-in one, or a user's module standing in for it.
    Kernel(KernelSpec),
    /// Someone else's traversal (`rq`, `embree`).
    Baseline(BaselineId),
}

impl Target {
    /// The built-in kernel of `v`, float controls on where the device has them.
    pub fn builtin(v: Variant) -> Target {
        Target::Kernel(KernelSpec::builtin(v))
    }
}

/// What a measurement's row reports besides its timing and work: the sizes and build time
/// of what it traced.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Facts {
    /// Node bytes of our BVH, or a baseline's acceleration-structure bytes.
    pub bvh_bytes: u64,
    pub node_size: u64,
    pub triangle_bytes: u64,
    /// Binary SAH build + collapse + encode, or a baseline's build, ms.
    pub build_ms: f64,
    /// How the kernels reached the scene's buffers, and the bytes uploaded.
    pub buffers: Buffers,
    pub upload_bytes: u64,
}

/// One measurement.
pub struct Outcome {
    pub status: Status,
    /// The kernel the device ran: float controls resolved, reaching the scene as it must.
    pub kernel: Option<KernelId>,
    /// The tracer's name: the kernel's (a user's module runs under the built-in name), or the
    /// baseline's kernel column.
    pub name: String,
    pub m: Measurement,
    pub facts: Facts,
}

/// A measurement's status: failed when validation failed, else ok.
pub(super) fn status(m: &Measurement) -> Status {
    match &m.failure {
        Some(f) => Status::Failed(f.clone()),
        None => Status::Ok,
    }
}

/// The measurement of a tracer already validated on these rays: only its timed dispatches.
pub(super) fn retime(
    tracer: &dyn Tracer,
    rays: &[Ray],
    hits: &[Hit],
    f32_hits: &[Hit],
    plan: Plan,
) -> anyhow::Result<Measurement> {
    let mut m =
        Measurement { hits: hits.to_vec(), vs_f32: crate::base::agreement(hits, f32_hits), ..Measurement::none() };
    if plan.repeat > 0 {
        match measure::time(tracer, rays, hits, plan)? {
            Ok(t) => m.timing = Some(t),
            Err(f) => m.failure = Some(f),
        }
    }
    Ok(m)
}

/// A kernel over a BVH on the device, with its counting kernel when there is one; the rays a
/// kernel flags are re-traced exactly on the host (through the scene's binary BVH where the
/// runner holds it, `BinaryBvh::resolve`, else by brute force, [`Scene::resolve`]), and each
/// timed run's time includes that re-trace's.
pub(super) struct KernelTracer<'a, 'g> {
    pub gpu: &'g Gpu,
    pub bvh: &'a GpuBvh<'g>,
    pub timed: &'a Kernel<'g>,
    pub counting: Option<&'a Kernel<'g>>,
    pub scene: &'a Scene,
    pub bin: Option<&'a BinaryBvh>,
}

impl KernelTracer<'_, '_> {
    fn resolved(&self, rays: &[Ray], mut out: RunOutput) -> RunOutput {
        let t0 = std::time::Instant::now();
        out.flagged = crate::bvh::exact::resolve(self.scene, self.bin, rays, &mut out.hits);
        let ms = t0.elapsed().as_secs_f64() * 1e3;
        for t in out.times_ms.iter_mut() {
            *t += ms;
        }
        out
    }
}

impl Tracer for KernelTracer<'_, '_> {
    fn label(&self) -> String {
        self.timed.label()
    }
    fn dispatch(&self, rays: &[Ray], warmup: usize, repeat: usize) -> anyhow::Result<RunOutput> {
        Ok(self.resolved(rays, self.timed.run(self.gpu, self.bvh, rays, warmup, repeat)?))
    }
    fn count(&self, rays: &[Ray]) -> Option<anyhow::Result<RunOutput>> {
        self.counting
            .map(|k| k.run(self.gpu, self.bvh, rays, 0, 1).map(|o| self.resolved(rays, o)).map_err(anyhow::Error::from))
    }
}

/// A baseline's structures over a scene.
pub(super) struct BaselineTracer<'a> {
    pub name: &'a str,
    pub scene: &'a dyn BaselineScene,
}

impl Tracer for BaselineTracer<'_> {
    fn label(&self) -> String {
        self.name.to_string()
    }
    fn dispatch(&self, rays: &[Ray], warmup: usize, repeat: usize) -> anyhow::Result<RunOutput> {
        Ok(self.scene.run(rays, warmup, repeat)?)
    }
    fn count(&self, _: &[Ray]) -> Option<anyhow::Result<RunOutput>> {
        None
    }
}
