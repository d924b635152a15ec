//! Baseline `rq`: the driver's own acceleration structures traced with `rayQueryEXT` — what a
//! user would otherwise pick ([`crate::gpu::accel`] builds and traces them).

use super::{Baseline, BaselineDevice, BaselineError, BaselineScene};
use crate::base::{Ray, RunOutput};
use crate::gpu::accel::{self, AccelScene, KERNEL};
use crate::gpu::pipeline::ComputePipeline;
use crate::gpu::{DeviceInfo, Gpu, GpuError};
use crate::scene::Scene;
use std::rc::Rc;

/// The registry entry `rq`.
pub struct Rq;

impl Baseline for Rq {
    fn name(&self) -> &'static str {
        "rq"
    }
    fn summary(&self) -> &'static str {
        "the driver's acceleration structure (prefer fast trace) traced with rayQueryEXT"
    }
    fn kernel(&self) -> &'static str {
        KERNEL
    }
    fn unavailable(&self, info: &DeviceInfo) -> Option<String> {
        (!info.ray_query).then(|| "the device has no VK_KHR_ray_query / VK_KHR_acceleration_structure".to_string())
    }
    fn prepare<'g>(&self, gpu: &'g Gpu) -> Result<Box<dyn BaselineDevice<'g> + 'g>, BaselineError> {
        if let Some(why) = self.unavailable(&gpu.info) {
            return Err(GpuError::MissingFeature { device: gpu.info.name.clone(), feature: why }.into());
        }
        Ok(Box::new(RqDevice { gpu, pipe: Rc::new(accel::pipeline(gpu)?) }))
    }
}

struct RqDevice<'g> {
    gpu: &'g Gpu,
    pipe: Rc<ComputePipeline<'g>>,
}

struct RqScene<'g> {
    gpu: &'g Gpu,
    pipe: Rc<ComputePipeline<'g>>,
    scene: AccelScene<'g>,
}

impl<'g> BaselineDevice<'g> for RqDevice<'g> {
    fn scene(&self, scene: &Scene) -> Result<Box<dyn BaselineScene + 'g>, BaselineError> {
        let built = AccelScene::build(self.gpu, scene)?;
        Ok(Box::new(RqScene { gpu: self.gpu, pipe: self.pipe.clone(), scene: built }))
    }
}

impl BaselineScene for RqScene<'_> {
    fn bytes(&self) -> u64 {
        self.scene.bytes
    }
    fn build_ms(&self) -> f64 {
        self.scene.build_ms
    }
    fn run(&self, rays: &[Ray], warmup: usize, repeat: usize) -> Result<RunOutput, BaselineError> {
        Ok(accel::run(self.gpu, &self.scene, &self.pipe, rays, warmup, repeat)?)
    }
}
