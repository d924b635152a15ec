//! An open device ([`Gpu`]): the instance, the chosen physical device, the logical device
//! with its queue, command pool and allocator. Each part is owned by a value that destroys
//! it when dropped, so a failure half-way through opening unwinds what exists, and a `Gpu`
//! destroys everything once, in reverse order — unless a submission hung.

use super::device::{describe, pick, DeviceInfo};
use super::instance::Instance;
use super::{GpuError, VkResultExt};
use ash::vk;
use gpu_allocator::vulkan::{Allocator, AllocatorCreateDesc};
use std::mem::ManuallyDrop;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::Mutex;

/// How to open a device.
#[derive(Clone, Debug, Default)]
pub struct ContextOptions {
    /// Index or case-insensitive name substring; default: first discrete GPU, else
    /// integrated, else virtual, else CPU (lavapipe), else anything.
    pub device: Option<String>,
    /// Feature names to treat as missing (tests of the fallbacks): any of [`crate::gpu::MASKABLE`]
    /// (`floatControls`: every rounding and preserve mode).
    pub mask_features: Vec<String>,
    /// Enable VK_LAYER_KHRONOS_validation if installed (also `HALFTRACE_VALIDATION=1`).
    pub validation: bool,
    /// Pretend the device's storage-buffer limit is this many bytes (testing; also
    /// `HALFTRACE_MAX_STORAGE_BUFFER=BYTES`, so any command can exercise the addressed path;
    /// `HALFTRACE_MAX_ALLOCATION=BYTES` likewise lowers `maxMemoryAllocationSize`).
    pub max_buffer: Option<u64>,
    /// How long one submission may run before it is declared hung (default
    /// [`DEFAULT_KERNEL_TIMEOUT_S`]).
    pub kernel_timeout_s: Option<f64>,
    /// Open the device to read its compiler's view (`isa`): every pipeline is built with
    /// its statistics and internal representations captured (needs
    /// `VK_KHR_pipeline_executable_properties`), and a compile-only device is accepted.
    /// Without it a compile-only device is refused, naming `isa`.
    pub statistics: bool,
}

/// Seconds a submission may take before the kernel is declared hung: generous, since one
/// dispatch of a slow variant over a million rays on a CPU device can take minutes.
pub const DEFAULT_KERNEL_TIMEOUT_S: f64 = 600.0;

/// The logical device, its command pool and its allocator.
struct Logical {
    /// False on a compile-only device, where a wait crashes the driver (nothing was
    /// submitted there, so nothing is pending).
    wait_on_drop: bool,
    device: ash::Device,
    pool: vk::CommandPool,
    allocator: Option<Mutex<Allocator>>,
}

impl Drop for Logical {
    fn drop(&mut self) {
        unsafe {
            if self.wait_on_drop {
                let _ = self.device.device_wait_idle();
            }
            if self.pool != vk::CommandPool::null() {
                self.device.destroy_command_pool(self.pool, None);
            }
            // Frees every remaining block (and reports leaks through gpu-allocator's log).
            drop(self.allocator.take());
            self.device.destroy_device(None);
        }
    }
}

/// An open Vulkan device with its queue, allocator and command pool.
pub struct Gpu {
    logical: ManuallyDrop<Logical>,
    inst: ManuallyDrop<Instance>,
    pub(crate) instance: ash::Instance,
    pub(crate) physical: vk::PhysicalDevice,
    pub(crate) device: ash::Device,
    pub(crate) queue: vk::Queue,
    pub(crate) pool: vk::CommandPool,
    pub info: DeviceInfo,
    pub validation_enabled: bool,
    /// Pipelines capture their statistics and internal representations ([`ContextOptions::statistics`]).
    pub(crate) capture: bool,
    /// Nanoseconds a submission may run before it is declared hung ([`Gpu::set_kernel_timeout`]).
    kernel_timeout_ns: AtomicU64,
    /// How the device was opened ([`Gpu::sibling`] opens it again).
    opts: ContextOptions,
    /// Set when a submission did not finish in time: the device is still running it, so
    /// nothing it may use is destroyed any more (the process ends without freeing it).
    hung: AtomicBool,
}

/// Reads a pretended lower limit from the environment (tests of the addressed path and of
/// the refusals).
fn env_limit(var: &str) -> Result<Option<u64>, GpuError> {
    match std::env::var(var) {
        Ok(v) => v
            .trim()
            .parse::<u64>()
            .map(Some)
            .map_err(|_| GpuError::Other(format!("{var}='{v}': give a number of bytes"))),
        Err(_) => Ok(None),
    }
}

/// A fence wait's nanoseconds as seconds, as messages print them (`30`, not `30.000000000000004`).
fn timeout_secs(ns: u64) -> f64 {
    std::time::Duration::from_nanos(ns).as_secs_f64()
}

/// `secs` as a fence wait's nanoseconds, clamped into what the wait takes.
fn timeout_ns(secs: f64) -> u64 {
    let d = std::time::Duration::try_from_secs_f64(secs.clamp(0.001, crate::units::MAX_SECONDS))
        .unwrap_or(std::time::Duration::from_secs_f64(DEFAULT_KERNEL_TIMEOUT_S));
    d.as_nanos().min(u64::MAX as u128) as u64
}

impl Gpu {
    pub fn new(opts: &ContextOptions) -> Result<Gpu, GpuError> {
        let validation = opts.validation || std::env::var("HALFTRACE_VALIDATION").is_ok_and(|v| v == "1");
        let inst = Instance::new(validation)?;
        let instance = inst.instance.clone();
        let pds = unsafe { instance.enumerate_physical_devices() }.vk("vkEnumeratePhysicalDevices")?;
        let infos: Vec<DeviceInfo> =
            pds.iter().enumerate().map(|(i, &pd)| describe(&instance, pd, i).with_quirks()).collect();
        let idx = pick(&infos, opts.device.as_deref())?;
        let mut info = infos[idx].clone();
        let physical = pds[idx];
        if let Some(m) = opts.max_buffer.or(env_limit("HALFTRACE_MAX_STORAGE_BUFFER")?) {
            info.max_storage_buffer = info.max_storage_buffer.min(m);
        }
        if let Some(m) = env_limit("HALFTRACE_MAX_ALLOCATION")? {
            info.max_allocation = info.max_allocation.min(m);
        }
        for m in &opts.mask_features {
            info.mask(m).map_err(GpuError::Other)?;
        }
        if info.compile_only && !opts.statistics {
            return Err(GpuError::CompileOnly(info.name.clone()));
        }
        if opts.statistics && !info.pipeline_statistics {
            let feature = "VK_KHR_pipeline_executable_properties (the compiler's statistics, for `isa`)".into();
            return Err(GpuError::MissingFeature { device: info.name.clone(), feature });
        }
        // No feature is required up front: each variant needs what its layout and math use
        // (gpu::support), and what a device lacks becomes one skipped line per variant. Timing
        // needs compute timestamps; reading the compiler's statistics does not.
        if !info.timestamps && !opts.statistics {
            let feature = "timestamp queries on a compute queue".into();
            return Err(GpuError::MissingFeature { device: info.name.clone(), feature });
        }
        let qfs = unsafe { instance.get_physical_device_queue_family_properties(physical) };
        let compute = |q: &vk::QueueFamilyProperties| q.queue_flags.contains(vk::QueueFlags::COMPUTE);
        let qfi = qfs
            .iter()
            .position(|q| compute(q) && q.timestamp_valid_bits > 0)
            .or_else(|| qfs.iter().position(compute))
            .ok_or_else(|| GpuError::MissingFeature { device: info.name.clone(), feature: "a compute queue".into() })?
            as u32;
        let logical = Self::create_device(&inst, physical, &info, qfi, opts.statistics)?;
        let queue = unsafe { logical.device.get_device_queue(qfi, 0) };
        // Parsed values are checked (crate::units); timeout_ns's clamp keeps any other caller's
        // value convertible.
        let timeout = opts.kernel_timeout_s.unwrap_or(DEFAULT_KERNEL_TIMEOUT_S);
        Ok(Gpu {
            instance,
            physical,
            device: logical.device.clone(),
            queue,
            pool: logical.pool,
            info,
            validation_enabled: inst.validation(),
            capture: opts.statistics,
            kernel_timeout_ns: AtomicU64::new(timeout_ns(timeout)),
            hung: AtomicBool::new(false),
            opts: ContextOptions { device: Some(idx.to_string()), ..opts.clone() },
            logical: ManuallyDrop::new(logical),
            inst: ManuallyDrop::new(inst),
        })
    }

    /// The logical device with the features `info` says the device has, its command pool and
    /// its allocator.
    fn create_device(
        inst: &Instance,
        physical: vk::PhysicalDevice,
        info: &DeviceInfo,
        qfi: u32,
        statistics: bool,
    ) -> Result<Logical, GpuError> {
        let prio = [1.0f32];
        let qinfo = [vk::DeviceQueueCreateInfo::default().queue_family_index(qfi).queue_priorities(&prio)];
        let (rq, rt, bda) = (info.ray_query, info.ray_tracing_pipeline, info.buffer_device_address);
        let v12_ok = info.spirv_minor >= 5;
        let mut v11 = vk::PhysicalDeviceVulkan11Features::default().storage_buffer16_bit_access(info.storage_16bit);
        let mut v12 = vk::PhysicalDeviceVulkan12Features::default()
            .shader_float16(info.shader_float16)
            .buffer_device_address(bda);
        // Vulkan 1.0 and 1.1 devices: the same features through their extensions' structures.
        let mut s16 = vk::PhysicalDevice16BitStorageFeatures::default().storage_buffer16_bit_access(true);
        let mut f16 = vk::PhysicalDeviceShaderFloat16Int8Features::default().shader_float16(true);
        let mut bdaf = vk::PhysicalDeviceBufferDeviceAddressFeatures::default().buffer_device_address(true);
        let mut sscf = vk::PhysicalDeviceSubgroupSizeControlFeatures::default().subgroup_size_control(true);
        let mut asf = vk::PhysicalDeviceAccelerationStructureFeaturesKHR::default().acceleration_structure(true);
        let mut rqf = vk::PhysicalDeviceRayQueryFeaturesKHR::default().ray_query(true);
        let mut rtf = vk::PhysicalDeviceRayTracingPipelineFeaturesKHR::default().ray_tracing_pipeline(true);
        let mut pef =
            vk::PhysicalDevicePipelineExecutablePropertiesFeaturesKHR::default().pipeline_executable_info(true);
        let base = vk::PhysicalDeviceFeatures::default().shader_float64(info.shader_float64);
        let mut exts: Vec<*const std::ffi::c_char> = Vec::new();
        if rq || rt {
            exts.extend([
                ash::khr::acceleration_structure::NAME.as_ptr(),
                ash::khr::deferred_host_operations::NAME.as_ptr(),
            ]);
        }
        if rq {
            exts.push(ash::khr::ray_query::NAME.as_ptr());
        }
        if rt {
            exts.push(ash::khr::ray_tracing_pipeline::NAME.as_ptr());
        }
        if info.subgroup_size_control {
            exts.push(ash::ext::subgroup_size_control::NAME.as_ptr());
        }
        if statistics {
            exts.push(ash::khr::pipeline_executable_properties::NAME.as_ptr());
        }
        if !v12_ok {
            if info.storage_16bit && info.spirv_minor == 0 {
                exts.push(ash::khr::_16bit_storage::NAME.as_ptr());
                exts.push(ash::khr::storage_buffer_storage_class::NAME.as_ptr());
            }
            if info.shader_float16 {
                exts.push(ash::khr::shader_float16_int8::NAME.as_ptr());
            }
            if bda {
                exts.push(ash::khr::buffer_device_address::NAME.as_ptr());
            }
        }
        let mut dinfo = vk::DeviceCreateInfo::default()
            .queue_create_infos(&qinfo)
            .enabled_features(&base)
            .enabled_extension_names(&exts);
        if v12_ok {
            dinfo = dinfo.push_next(&mut v11).push_next(&mut v12);
        } else {
            if info.storage_16bit {
                dinfo = dinfo.push_next(&mut s16);
            }
            if info.shader_float16 {
                dinfo = dinfo.push_next(&mut f16);
            }
            if bda {
                dinfo = dinfo.push_next(&mut bdaf);
            }
        }
        if rq || rt {
            dinfo = dinfo.push_next(&mut asf);
        }
        if rq {
            dinfo = dinfo.push_next(&mut rqf);
        }
        if rt {
            dinfo = dinfo.push_next(&mut rtf);
        }
        if info.subgroup_size_control {
            dinfo = dinfo.push_next(&mut sscf);
        }
        if statistics {
            dinfo = dinfo.push_next(&mut pef);
        }
        let device = unsafe { inst.instance.create_device(physical, &dinfo, None) }.vk("vkCreateDevice")?;
        // From here on, dropping `logical` destroys what exists.
        let mut logical =
            Logical { wait_on_drop: !info.compile_only, device, pool: vk::CommandPool::null(), allocator: None };
        let pool_info = vk::CommandPoolCreateInfo::default()
            .queue_family_index(qfi)
            .flags(vk::CommandPoolCreateFlags::RESET_COMMAND_BUFFER);
        logical.pool = unsafe { logical.device.create_command_pool(&pool_info, None) }.vk("vkCreateCommandPool")?;
        let allocator = Allocator::new(&AllocatorCreateDesc {
            instance: inst.instance.clone(),
            device: logical.device.clone(),
            physical_device: physical,
            debug_settings: Default::default(),
            buffer_device_address: bda,
            allocation_sizes: Default::default(),
        })
        .map_err(|e| GpuError::Other(format!("creating the allocator: {e}")))?;
        logical.allocator = Some(Mutex::new(allocator));
        Ok(logical)
    }

    /// The allocator every buffer comes from.
    pub(crate) fn allocator(&self) -> &Mutex<Allocator> {
        self.logical.allocator.as_ref().expect("created with the device")
    }

    /// Bytes currently allocated through the allocator (0 once every buffer is dropped).
    pub fn allocated_bytes(&self) -> u64 {
        self.allocator().lock().map(|a| a.generate_report().total_allocated_bytes).unwrap_or(u64::MAX)
    }

    /// Validation messages (warnings and errors) reported so far.
    pub fn validation_messages(&self) -> Vec<String> {
        self.inst.messages()
    }

    /// Whether a submission hung (then nothing the device may still use is destroyed).
    pub fn hung(&self) -> bool {
        self.hung.load(Ordering::SeqCst)
    }

    /// Seconds a submission may run from now on before it is declared hung (a sweep sets each
    /// job's: a user kernel's own `kernel_timeout` or the sweep's).
    pub fn set_kernel_timeout(&self, secs: f64) {
        self.kernel_timeout_ns.store(timeout_ns(secs), Ordering::SeqCst);
    }

    /// The hang timeout in force, in seconds.
    pub fn kernel_timeout_s(&self) -> f64 {
        timeout_secs(self.kernel_timeout_ns.load(Ordering::SeqCst))
    }

    /// The same device opened again, by its index and with the same options, but without the
    /// validation layer: a second queue for work beside this device's, such as warming
    /// pipelines ([`super::pipeline::ComputePipeline::warm`]).
    pub fn sibling(&self) -> Result<Gpu, GpuError> {
        Gpu::new(&ContextOptions {
            validation: false,
            kernel_timeout_s: Some(self.kernel_timeout_s()),
            ..self.opts.clone()
        })
    }

    /// Whether the driver compiles a compute pipeline's code at its first dispatch rather than
    /// when the pipeline is created, keeping it in Mesa's shader cache (lavapipe: llvmpipe
    /// compiles there, one pipeline at a time on the device's one queue thread); false where
    /// that cache is switched off (`MESA_SHADER_CACHE_DISABLE`), since then a warmed pipeline
    /// helps no other device.
    pub fn compiles_at_first_dispatch(&self) -> bool {
        let cache_off = std::env::var("MESA_SHADER_CACHE_DISABLE").is_ok_and(|v| v == "1" || v == "true");
        self.info.compiles_at_first_dispatch() && !cache_off
    }

    /// Records commands with `record`, submits them and waits for completion, at most the
    /// kernel timeout: past it the work is declared hung ([`GpuError::Hung`]) and its command
    /// buffer and fence are left to the device.
    pub fn submit_and_wait(&self, record: impl FnOnce(vk::CommandBuffer)) -> Result<(), GpuError> {
        if self.info.compile_only {
            return Err(GpuError::CompileOnly(self.info.name.clone()));
        }
        let d = &self.device;
        unsafe {
            let cmd = d
                .allocate_command_buffers(
                    &vk::CommandBufferAllocateInfo::default()
                        .command_pool(self.pool)
                        .level(vk::CommandBufferLevel::PRIMARY)
                        .command_buffer_count(1),
                )
                .vk("vkAllocateCommandBuffers")?[0];
            let result = (|| {
                d.begin_command_buffer(
                    cmd,
                    &vk::CommandBufferBeginInfo::default().flags(vk::CommandBufferUsageFlags::ONE_TIME_SUBMIT),
                )
                .vk("vkBeginCommandBuffer")?;
                record(cmd);
                d.end_command_buffer(cmd).vk("vkEndCommandBuffer")?;
                let fence = d.create_fence(&vk::FenceCreateInfo::default(), None).vk("vkCreateFence")?;
                let cmds = [cmd];
                let submit = [vk::SubmitInfo::default().command_buffers(&cmds)];
                if let Err(r) = d.queue_submit(self.queue, &submit, fence) {
                    d.destroy_fence(fence, None);
                    return Err(GpuError::Vk { call: "vkQueueSubmit", result: r });
                }
                match d.wait_for_fences(&[fence], true, self.kernel_timeout_ns.load(Ordering::SeqCst)) {
                    Err(vk::Result::TIMEOUT) => {
                        self.hung.store(true, Ordering::SeqCst);
                        Err(GpuError::Hung { secs: self.kernel_timeout_s() })
                    }
                    r => {
                        d.destroy_fence(fence, None);
                        r.vk("vkWaitForFences")
                    }
                }
            })();
            if !self.hung() {
                d.free_command_buffers(self.pool, &[cmd]);
            }
            result
        }
    }
}

impl Drop for Gpu {
    fn drop(&mut self) {
        if self.hung() {
            // The device is still running the hung work: waiting would never return and
            // destroying would pull memory from under it. The process exit reclaims it all.
            return;
        }
        // Everything made from the device is gone (its values borrow the Gpu): the device,
        // then the instance.
        unsafe {
            ManuallyDrop::drop(&mut self.logical);
            ManuallyDrop::drop(&mut self.inst);
        }
    }
}

#[cfg(test)]
mod tests {
    /// A timeout reads back as it was given: messages say "within 30 s".
    #[test]
    fn timeouts_read_back_as_given() {
        for secs in [0.5, 2.0, 30.0, 120.0, 600.0, 604800.0] {
            assert_eq!(super::timeout_secs(super::timeout_ns(secs)), secs);
            assert_eq!(format!("{}", super::timeout_secs(super::timeout_ns(secs))), format!("{secs}"));
        }
    }
}
