//! Validate, then time — the one path every built-in kernel, user kernel and baseline goes
//! through, in `trace`, the sweep and the benchmark. A target's hits are first compared with
//! a reference (for our layouts, the CPU reference of the same layout and packet size, bit
//! for bit, then the counters exactly); only a target that passes is timed: `warmup` untimed
//! then `repeat` timed dispatches, summarised as median, min and max.

use crate::gpu::kernel::{GpuBvh, Kernel, RunOutput};
use crate::gpu::{Gpu, GpuError};
use crate::layout::BaselineScene;
use crate::rays::Ray;
use crate::trace::{agreement, Agreement, Counters, Hit};

/// Median, min and max of repeated timings (ms).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Timing {
    pub median: f64,
    pub min: f64,
    pub max: f64,
    pub count: usize,
}

impl Timing {
    /// Summarises at least one timing.
    pub fn of(times_ms: &[f64]) -> Timing {
        let mut t = times_ms.to_vec();
        t.sort_by(f64::total_cmp);
        Timing { median: t[t.len() / 2], min: t[0], max: t[t.len() - 1], count: t.len() }
    }

    /// Mrays/s of `rays` at the median, the slowest and the fastest timing.
    pub fn mrays(&self, rays: usize) -> (f64, f64, f64) {
        let n = rays.max(1) as f64;
        (n / self.median / 1e3, n / self.max / 1e3, n / self.min / 1e3)
    }
}

/// Something that traces rays on a device.
pub trait Target {
    /// Names the target in messages (the variant, and the user's file if it is theirs).
    fn label(&self) -> String;
    /// `warmup` untimed then `repeat` timed traversals (at least one in all).
    fn dispatch(&self, rays: &[Ray], warmup: usize, repeat: usize) -> Result<RunOutput, GpuError>;
    /// The counting pass, when the target has one.
    fn count(&self, rays: &[Ray]) -> Option<Result<Vec<Counters>, GpuError>>;
}

/// A traversal kernel over a BVH on the device, with its counting kernel when there is one.
pub struct KernelTarget<'a, 'g> {
    pub gpu: &'g Gpu,
    pub bvh: &'a GpuBvh<'g>,
    pub timed: &'a Kernel<'g>,
    pub counting: Option<&'a Kernel<'g>>,
}

impl Target for KernelTarget<'_, '_> {
    fn label(&self) -> String {
        self.timed.label()
    }
    fn dispatch(&self, rays: &[Ray], warmup: usize, repeat: usize) -> Result<RunOutput, GpuError> {
        self.timed.run(self.gpu, self.bvh, rays, warmup, repeat)
    }
    fn count(&self, rays: &[Ray]) -> Option<Result<Vec<Counters>, GpuError>> {
        self.counting.map(|k| {
            k.run(self.gpu, self.bvh, rays, 0, 1).map(|o| o.counters.expect("a counting kernel returns counters"))
        })
    }
}

/// A baseline's structures over a scene.
pub struct BaselineTarget<'a> {
    pub name: &'a str,
    pub scene: &'a dyn BaselineScene,
}

impl Target for BaselineTarget<'_> {
    fn label(&self) -> String {
        self.name.to_string()
    }
    fn dispatch(&self, rays: &[Ray], warmup: usize, repeat: usize) -> Result<RunOutput, GpuError> {
        self.scene.run(rays, warmup, repeat)
    }
    fn count(&self, _: &[Ray]) -> Option<Result<Vec<Counters>, GpuError>> {
        None
    }
}

/// What a target's results are checked against before it is timed.
pub enum Reference<'a> {
    /// The CPU reference of the same layout and packet size: hits bit for bit, counters
    /// exactly (when the target counts).
    Exact { hits: &'a [Hit], counters: &'a [Counters] },
    /// Nothing exact (a baseline with its own triangle test): its agreement with the f32
    /// reference is measured and reported, never a failure.
    Agreement,
}

/// How to time a target.
#[derive(Clone, Copy, Debug)]
pub struct Plan {
    pub warmup: usize,
    pub repeat: usize,
    /// Run the counting pass (when the target has one).
    pub count: bool,
}

/// The outcome of [`validate_then_time`].
pub struct Measurement {
    pub hits: Vec<Hit>,
    /// Per-ray counters, when counted.
    pub counters: Option<Vec<Counters>>,
    /// `None` when validation failed (nothing was timed).
    pub timing: Option<Timing>,
    /// Why validation failed, naming the target, the ray and both results.
    pub failure: Option<String>,
    /// Agreement with the f32 reference: the one definition of "differs from f32".
    pub vs_f32: Agreement,
}

impl Measurement {
    /// Nothing measured: a target the device cannot run.
    pub fn skipped() -> Measurement {
        Measurement { hits: Vec::new(), counters: None, timing: None, failure: None, vs_f32: agreement(&[], &[]) }
    }
}

/// Where `got` and `want` (per-ray `what`: hits or counters) differ, as a message naming the
/// target, how many rays, the first ray and both results; `None` when they agree.
pub fn compare<T: std::fmt::Debug>(
    label: &str,
    what: &str,
    against: &str,
    rays: &[Ray],
    got: &[T],
    want: &[T],
    same: impl Fn(&T, &T) -> bool,
) -> Option<String> {
    let bad: Vec<usize> = (0..got.len()).filter(|&i| !same(&got[i], &want[i])).collect();
    let &i = bad.first()?;
    Some(format!(
        "{label}: {} of {} rays differ from {against} in their {what}; first: ray {i} {:?}: got {:?}, {against} {:?}",
        bad.len(),
        got.len(),
        rays[i],
        got[i],
        want[i]
    ))
}

const CPU: &str = "the CPU reference";

/// Validates `target` on `rays` against `reference`, then times it (see the module docs).
/// `f32_hits` are the f32 reference's hits, for the agreement every row reports.
pub fn validate_then_time(
    target: &dyn Target,
    rays: &[Ray],
    reference: Reference,
    f32_hits: &[Hit],
    plan: Plan,
) -> Result<Measurement, GpuError> {
    let label = target.label();
    let first = target.dispatch(rays, 0, 1)?;
    let vs_f32 = agreement(&first.hits, f32_hits);
    let mut m = Measurement { hits: first.hits, counters: None, timing: None, failure: None, vs_f32 };
    if let Reference::Exact { hits, .. } = reference {
        m.failure = compare(&label, "hits", CPU, rays, &m.hits, hits, Hit::same_bits);
        if m.failure.is_some() {
            return Ok(m);
        }
    }
    if plan.count {
        m.counters = target.count(rays).transpose()?;
    }
    if let (Reference::Exact { counters, .. }, Some(c)) = (&reference, &m.counters) {
        m.failure = compare(&label, "counters", CPU, rays, c, counters, |a, b| a == b);
        if m.failure.is_some() {
            return Ok(m);
        }
    }
    let timed = target.dispatch(rays, plan.warmup, plan.repeat)?;
    m.failure = compare(&label, "hits", "its first dispatch", rays, &timed.hits, &m.hits, Hit::same_bits);
    if m.failure.is_some() {
        return Ok(m);
    }
    m.timing = Some(Timing::of(&timed.times_ms));
    Ok(m)
}
