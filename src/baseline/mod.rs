//! Baselines: someone else's traversal of the same triangles and rays, run beside our layouts
//! as the answer a user would otherwise get — `rq` (the driver's acceleration structure and
//! ray queries, [`rq`]), `rt` (the same structure traced by a ray-tracing pipeline, [`rt`]) and
//! `embree` (Intel Embree 3 on the host CPU, [`embree`]). They have no
//! B, P, math mode or work counters; their hits are compared with the f32 reference and
//! reported as agreement. Adding one is a file here and one line in [`BASELINES`].

pub mod embree;
pub mod rq;
pub mod rt;

use crate::base::{Ray, RunOutput};
use crate::gpu::{DeviceInfo, Gpu, GpuError};
use crate::scene::Scene;
use thiserror::Error;

/// Every baseline, in report order.
pub static BASELINES: &[&dyn Baseline] = &[&rq::Rq, &rt::Rt, &embree::Embree];

#[derive(Debug, Error)]
pub enum BaselineError {
    #[error(transparent)]
    Gpu(#[from] GpuError),
}

/// A handle to a registered baseline.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub struct BaselineId(u8);

impl BaselineId {
    /// Every baseline, in [`BASELINES`] order.
    pub fn all() -> impl Iterator<Item = BaselineId> {
        (0..BASELINES.len()).map(|i| BaselineId(i as u8))
    }

    /// The baseline called `name`, if any.
    pub fn parse(name: &str) -> Option<BaselineId> {
        Self::all().find(|b| b.name() == name)
    }

    pub fn imp(self) -> &'static dyn Baseline {
        BASELINES[self.0 as usize]
    }

    pub fn name(self) -> &'static str {
        self.imp().name()
    }
}

impl std::fmt::Display for BaselineId {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

/// A traversal that is not ours, run on the same rays.
pub trait Baseline: Send + Sync {
    /// Name in flags, configs and reports.
    fn name(&self) -> &'static str;
    /// One line for `--help`, `halftrace devices` and the docs.
    fn summary(&self) -> &'static str;
    /// The `kernel` column of its rows.
    fn kernel(&self) -> &'static str;
    /// Why a device cannot run it (one line for the report and `devices`), or `None`.
    fn unavailable(&self, info: &DeviceInfo) -> Option<String>;
    /// What it needs once per device (pipelines).
    fn prepare<'g>(&self, gpu: &'g Gpu) -> Result<Box<dyn BaselineDevice<'g> + 'g>, BaselineError>;
}

/// A baseline prepared on one device.
pub trait BaselineDevice<'g> {
    /// Builds its structures over a scene's triangles (in `prim` order).
    fn scene(&self, scene: &Scene) -> Result<Box<dyn BaselineScene + 'g>, BaselineError>;
}

/// A baseline's structures over one scene.
pub trait BaselineScene {
    /// Bytes of its acceleration structures.
    fn bytes(&self) -> u64;
    /// Build time, ms.
    fn build_ms(&self) -> f64;
    /// `warmup` untimed then `repeat` timed traversals of `rays` (at least one in all).
    fn run(&self, rays: &[Ray], warmup: usize, repeat: usize) -> Result<RunOutput, BaselineError>;
}
