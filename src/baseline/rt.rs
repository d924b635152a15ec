//! Baseline `rt`: the driver's own acceleration structures (the ones `rq` traces) traced by a
//! ray-tracing pipeline (`traceRayEXT` from a ray-generation shader) — what a user would pick
//! where the driver offers ray-tracing pipelines but not ray queries ([`crate::gpu::rt`]).

use super::{Baseline, BaselineDevice, BaselineError, BaselineScene};
use crate::base::{Ray, RunOutput};
use crate::gpu::accel::AccelScene;
use crate::gpu::rt::{self, RtPipeline, KERNEL};
use crate::gpu::{DeviceInfo, Gpu, GpuError};
use crate::scene::Scene;
use std::rc::Rc;

/// The registry entry `rt`.
pub struct Rt;

impl Baseline for Rt {
    fn name(&self) -> &'static str {
        "rt"
    }
    fn summary(&self) -> &'static str {
        "the driver's acceleration structure (as rq's) traced with a ray-tracing pipeline (traceRayEXT)"
    }
    fn kernel(&self) -> &'static str {
        KERNEL
    }
    fn unavailable(&self, info: &DeviceInfo) -> Option<String> {
        if info.ray_tracing_pipeline {
            None
        } else if info.spirv_minor < 5 {
            Some(format!("ray-tracing pipelines need Vulkan 1.2; the device has {}", info.api_version))
        } else if !info.buffer_device_address {
            Some("the device has no bufferDeviceAddress (the shader binding table is read by address)".into())
        } else {
            Some(
                "the device has no VK_KHR_ray_tracing_pipeline / VK_KHR_acceleration_structure with the \
                 rayTracingPipeline and accelerationStructure features"
                    .into(),
            )
        }
    }
    fn prepare<'g>(&self, gpu: &'g Gpu) -> Result<Box<dyn BaselineDevice<'g> + 'g>, BaselineError> {
        if let Some(why) = self.unavailable(&gpu.info) {
            return Err(GpuError::MissingFeature { device: gpu.info.name.clone(), feature: why }.into());
        }
        Ok(Box::new(RtDevice { gpu, pipe: Rc::new(RtPipeline::new(gpu)?) }))
    }
}

struct RtDevice<'g> {
    gpu: &'g Gpu,
    pipe: Rc<RtPipeline<'g>>,
}

struct RtScene<'g> {
    gpu: &'g Gpu,
    pipe: Rc<RtPipeline<'g>>,
    scene: AccelScene<'g>,
}

impl<'g> BaselineDevice<'g> for RtDevice<'g> {
    fn scene(&self, scene: &Scene) -> Result<Box<dyn BaselineScene + 'g>, BaselineError> {
        let built = AccelScene::build(self.gpu, scene)?;
        Ok(Box::new(RtScene { gpu: self.gpu, pipe: self.pipe.clone(), scene: built }))
    }
}

impl BaselineScene for RtScene<'_> {
    fn bytes(&self) -> u64 {
        self.scene.bytes
    }
    fn build_ms(&self) -> f64 {
        self.scene.build_ms
    }
    fn run(&self, rays: &[Ray], warmup: usize, repeat: usize) -> Result<RunOutput, BaselineError> {
        Ok(rt::run(self.gpu, &self.scene, &self.pipe, rays, warmup, repeat)?)
    }
}
