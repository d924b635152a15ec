//! The Vulkan backend: the only module with `unsafe`. One file per Vulkan concept:
//! [`instance`] (loader, instance, validation layer), [`device`] (what each device can do,
//! which one is picked), [`context`] (the open device: queue, command pool, allocator),
//! [`buffer`], [`shader`] (GLSL → SPIR-V, SPIR-V reading and patching, user-module checks),
//! [`pipeline`] (the Vulkan compute pipeline object), [`timer`] (timestamp queries),
//! [`bvh`] (a BVH resident on the device), [`kernel`] (a traversal kernel and its dispatch),
//! [`support`] (what a device runs of each variant), [`accel`] (the driver's acceleration
//! structures and ray queries), [`rt`] (the driver's ray-tracing pipeline over them) and
//! [`arith`] (raw fp16/fp32 arithmetic rates).

pub mod accel;
pub mod arith;
pub mod buffer;
pub mod bvh;
pub mod context;
pub mod device;
pub mod executable;
pub(crate) mod instance;
pub mod kernel;
pub mod null;
pub mod pipeline;
pub mod rt;
pub mod shader;
pub mod support;
pub mod timer;

pub use bvh::GpuBvh;
pub use context::{ContextOptions, Gpu, DEFAULT_KERNEL_TIMEOUT_S};
pub use device::{list_devices, pick, shim, DeviceInfo, MASKABLE};
pub use kernel::{Kernel, Source};
use thiserror::Error;

#[derive(Debug, Error)]
pub enum GpuError {
    #[error("Vulkan loader not available: {0} (install libvulkan1 and a driver, e.g. mesa-vulkan-drivers)")]
    Loader(String),
    #[error("no Vulkan device found")]
    NoDevice,
    #[error("--device '{0}' matches no device (see `halftrace devices`)")]
    DeviceNotFound(String),
    #[error("device '{device}' lacks {feature}, which halftrace needs")]
    MissingFeature { device: String, feature: String },
    #[error("Vulkan call {call} failed: {result}")]
    Vk { call: &'static str, result: ash::vk::Result },
    #[error("allocating {what} ({bytes} bytes): {source}")]
    Alloc { what: String, bytes: u64, source: gpu_allocator::AllocationError },
    #[error("{what} needs {bytes} bytes, more than the device's {limit_name} of {limit} bytes{hint}")]
    TooBig { what: String, bytes: u64, limit: u64, limit_name: &'static str, hint: String },
    #[error("shader {variant} failed to compile:\n{log}")]
    Compile { variant: String, log: String },
    #[error("{path}: {msg}")]
    Spirv { path: String, msg: String },
    /// The device lacks what this variant needs (a skipped line, not a failure).
    #[error("{0}")]
    Unsupported(String),
    #[error("the device did not finish a submission within {secs} s (a kernel that never terminates?); it is still busy with it, so nothing more can run on it in this process")]
    Hung { secs: f64 },
    #[error("'{0}' is a compile-only device (RADV's null device, opened by RADV_FORCE_FAMILY, or a driver under Mesa's drm-shim): it builds pipelines but cannot run them; read its compiler's statistics with `halftrace isa --family F` (an AMD family or another vendor's model, e.g. a740) or `halftrace isa --device '{0}'`, or choose another device with --device")]
    CompileOnly(String),
    #[error("{0}")]
    Other(String),
}

/// Maps a failed Vulkan call to a [`GpuError`].
pub(crate) trait VkResultExt<T> {
    fn vk(self, call: &'static str) -> Result<T, GpuError>;
}

impl<T> VkResultExt<T> for Result<T, ash::vk::Result> {
    fn vk(self, call: &'static str) -> Result<T, GpuError> {
        self.map_err(|result| GpuError::Vk { call, result })
    }
}
