//! The Vulkan backend: the only module with `unsafe`. One file per Vulkan concept:
//! [`instance`] (loader, instance, validation layer), [`device`] (what each device can do,
//! which one is picked), [`context`] (the open device: queue, command pool, allocator),
//! [`buffer`], [`shader`] (GLSL → SPIR-V, SPIR-V reading and patching, user-module checks),
//! [`pipeline`] (the Vulkan compute pipeline object), [`timer`] (timestamp queries),
//! [`bvh`] (a BVH resident on the device), [`kernel`] (a traversal kernel and its dispatch),
//! [`support`] (what a device runs of each variant), [`error`] (what can go wrong,
//! [`GpuError`]), [`accel`] (the driver's acceleration structures and ray queries), [`rt`] (the
//! driver's ray-tracing pipeline over them) and [`arith`] (raw fp16/fp32 arithmetic rates).

pub mod accel;
pub mod arith;
pub mod buffer;
pub mod bvh;
pub mod context;
pub mod device;
pub mod error;
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
pub use error::GpuError;
pub(crate) use error::VkResultExt;
pub use kernel::Kernel;
