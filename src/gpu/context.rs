//! Instance, device selection, logical device, queue, allocator, command pool, and the
//! validation layer's messenger. Everything is destroyed once, in reverse order, on drop.

use super::{GpuError, VkResultExt};
use ash::vk;
use gpu_allocator::vulkan::{Allocator, AllocatorCreateDesc};
use std::ffi::{c_void, CStr};
use std::mem::ManuallyDrop;
use std::sync::Mutex;

const VALIDATION_LAYER: &CStr = c"VK_LAYER_KHRONOS_validation";

/// What the harness needs to know about a device.
#[derive(Clone, Debug)]
pub struct DeviceInfo {
    pub index: usize,
    pub name: String,
    pub kind: String,
    pub driver: String,
    pub api_version: String,
    pub shader_float16: bool,
    pub storage_16bit: bool,
    pub shader_float64: bool,
    pub subgroup_size: u32,
    /// `VkSubgroupFeatureFlags` the device supports (basic, vote, arithmetic, ballot, shuffle,
    /// shuffle relative, clustered, quad: bits 0..7).
    pub subgroup_ops: u32,
    pub ray_query: bool,
    /// `bufferDeviceAddress`: kernels may read buffers through 64-bit addresses, which is how
    /// a scene whose buffers exceed `maxStorageBufferRange` is still traced.
    pub buffer_device_address: bool,
    /// `maxStorageBufferRange`: the most bytes one storage-buffer binding may span.
    pub max_storage_buffer: u64,
    /// `maxMemoryAllocationSize`: the largest single allocation, so the largest buffer.
    pub max_allocation: u64,
    pub timestamp_period_ns: f32,
    pub timestamps: bool,
    /// Float controls the kernels declare: fp16 round-to-nearest-even and fp16/fp32
    /// signed-zero/inf/NaN preservation (without them, drivers may skip fp16 roundings).
    pub fp16_rte: bool,
    pub fp32_rte: bool,
    pub preserve_16: bool,
    pub preserve_32: bool,
    /// `subgroupSizeControl` with compute in its required-size stages: the subgroup size a
    /// kernel was built for can be pinned, between these bounds.
    pub subgroup_size_control: bool,
    pub min_subgroup_size: u32,
    pub max_subgroup_size: u32,
}

impl DeviceInfo {
    /// Treats feature `name` (one of [`MASKABLE`]) as missing.
    pub fn mask(&mut self, name: &str) -> Result<(), String> {
        match name {
            "shaderFloat16" => self.shader_float16 = false,
            "storageBuffer16BitAccess" => self.storage_16bit = false,
            "shaderFloat64" => self.shader_float64 = false,
            "rayQuery" => self.ray_query = false,
            "bufferDeviceAddress" => {
                self.buffer_device_address = false;
                self.ray_query = false;
            }
            "subgroupSizeControl" => {
                self.subgroup_size_control = false;
                (self.min_subgroup_size, self.max_subgroup_size) = (self.subgroup_size, self.subgroup_size);
            }
            "shaderRoundingModeRTEFloat16" => self.fp16_rte = false,
            "shaderRoundingModeRTEFloat32" => self.fp32_rte = false,
            "shaderSignedZeroInfNanPreserveFloat16" => self.preserve_16 = false,
            "shaderSignedZeroInfNanPreserveFloat32" => self.preserve_32 = false,
            "floatControls" => {
                (self.fp16_rte, self.fp32_rte, self.preserve_16, self.preserve_32) = (false, false, false, false)
            }
            other => return Err(format!("unknown feature to mask: '{other}' (use one of {})", MASKABLE.join(", "))),
        }
        Ok(())
    }
}

/// Every feature `--mask-feature` can hide, so each fallback runs on any device.
pub const MASKABLE: &[&str] = &[
    "shaderFloat16",
    "storageBuffer16BitAccess",
    "shaderFloat64",
    "rayQuery",
    "bufferDeviceAddress",
    "subgroupSizeControl",
    "shaderRoundingModeRTEFloat16",
    "shaderRoundingModeRTEFloat32",
    "shaderSignedZeroInfNanPreserveFloat16",
    "shaderSignedZeroInfNanPreserveFloat32",
    "floatControls",
];

/// How to open a device.
#[derive(Clone, Debug, Default)]
pub struct ContextOptions {
    /// Index or case-insensitive name substring; default: first discrete GPU, else
    /// integrated, else virtual, else CPU (lavapipe), else anything.
    pub device: Option<String>,
    /// Feature names to treat as missing (tests of the fallbacks): any of [`MASKABLE`]
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
}

/// Seconds a submission may take before the kernel is declared hung: generous, since one
/// dispatch of a slow variant over a million rays on a CPU device can take minutes.
pub const DEFAULT_KERNEL_TIMEOUT_S: f64 = 600.0;

/// An open Vulkan device with its queue, allocator and command pool.
pub struct Gpu {
    _entry: ash::Entry,
    pub(crate) instance: ash::Instance,
    pub(crate) physical: vk::PhysicalDevice,
    debug: Option<(ash::ext::debug_utils::Instance, vk::DebugUtilsMessengerEXT, *mut Mutex<Vec<String>>)>,
    pub(crate) device: ash::Device,
    pub(crate) queue: vk::Queue,
    pub(crate) pool: vk::CommandPool,
    pub(crate) allocator: ManuallyDrop<Mutex<Allocator>>,
    pub info: DeviceInfo,
    pub validation_enabled: bool,
    kernel_timeout: std::time::Duration,
    /// Set when a submission did not finish in time: the device is still running it, so
    /// nothing it may use is destroyed any more (the process ends without freeing it).
    hung: std::sync::atomic::AtomicBool,
}

// The raw messages pointer is only touched through its Mutex.
unsafe impl Send for Gpu {}
unsafe impl Sync for Gpu {}

unsafe extern "system" fn debug_callback(
    severity: vk::DebugUtilsMessageSeverityFlagsEXT,
    _ty: vk::DebugUtilsMessageTypeFlagsEXT,
    data: *const vk::DebugUtilsMessengerCallbackDataEXT<'_>,
    user: *mut c_void,
) -> vk::Bool32 {
    if !data.is_null() && !user.is_null() {
        let msg = unsafe { (*data).message_as_c_str() }.map(|m| m.to_string_lossy().to_string()).unwrap_or_default();
        let store = unsafe { &*(user as *const Mutex<Vec<String>>) };
        if let Ok(mut v) = store.lock() {
            v.push(format!("{severity:?}: {msg}"));
        }
    }
    vk::FALSE
}

fn load_entry() -> Result<ash::Entry, GpuError> {
    unsafe { ash::Entry::load() }.map_err(|e| GpuError::Loader(e.to_string()))
}

fn make_instance(entry: &ash::Entry, validation: bool) -> Result<(ash::Instance, bool), GpuError> {
    let app = vk::ApplicationInfo::default().application_name(c"halftrace").api_version(vk::API_VERSION_1_2);
    let layers = unsafe { entry.enumerate_instance_layer_properties() }.vk("vkEnumerateInstanceLayerProperties")?;
    let have_layer = layers.iter().any(|l| l.layer_name_as_c_str().is_ok_and(|n| n == VALIDATION_LAYER));
    let use_layer = validation && have_layer;
    let layer_ptrs = if use_layer { vec![VALIDATION_LAYER.as_ptr()] } else { vec![] };
    let ext_ptrs = if use_layer { vec![ash::ext::debug_utils::NAME.as_ptr()] } else { vec![] };
    let info = vk::InstanceCreateInfo::default()
        .application_info(&app)
        .enabled_layer_names(&layer_ptrs)
        .enabled_extension_names(&ext_ptrs);
    let inst = unsafe { entry.create_instance(&info, None) }.vk("vkCreateInstance")?;
    Ok((inst, use_layer))
}

fn describe(instance: &ash::Instance, pd: vk::PhysicalDevice, index: usize) -> DeviceInfo {
    unsafe {
        let props = instance.get_physical_device_properties(pd);
        let mut v11 = vk::PhysicalDeviceVulkan11Features::default();
        let mut v12 = vk::PhysicalDeviceVulkan12Features::default();
        let mut asf = vk::PhysicalDeviceAccelerationStructureFeaturesKHR::default();
        let mut rqf = vk::PhysicalDeviceRayQueryFeaturesKHR::default();
        let exts0 = instance.enumerate_device_extension_properties(pd).unwrap_or_default();
        let has0 = |n: &CStr| exts0.iter().any(|e| e.extension_name_as_c_str().is_ok_and(|x| x == n));
        let rq_exts = has0(ash::khr::ray_query::NAME)
            && has0(ash::khr::acceleration_structure::NAME)
            && has0(ash::khr::deferred_host_operations::NAME);
        let f64ok = {
            let mut f2 = vk::PhysicalDeviceFeatures2::default().push_next(&mut v11).push_next(&mut v12);
            if rq_exts {
                f2 = f2.push_next(&mut asf).push_next(&mut rqf);
            }
            instance.get_physical_device_features2(pd, &mut f2);
            f2.features.shader_float64 == vk::TRUE
        };
        let rq_ok = rq_exts
            && asf.acceleration_structure == vk::TRUE
            && rqf.ray_query == vk::TRUE
            && v12.buffer_device_address == vk::TRUE;
        let mut sub = vk::PhysicalDeviceSubgroupProperties::default();
        let mut drv = vk::PhysicalDeviceDriverProperties::default();
        let mut p11 = vk::PhysicalDeviceMaintenance3Properties::default();
        let mut fc = vk::PhysicalDeviceFloatControlsProperties::default();
        let mut ssc = vk::PhysicalDeviceSubgroupSizeControlProperties::default();
        let ssc_ext = has0(ash::ext::subgroup_size_control::NAME);
        let mut p2 = vk::PhysicalDeviceProperties2::default()
            .push_next(&mut sub)
            .push_next(&mut drv)
            .push_next(&mut fc)
            .push_next(&mut p11);
        if ssc_ext {
            p2 = p2.push_next(&mut ssc);
        }
        instance.get_physical_device_properties2(pd, &mut p2);
        let ssc_ok = ssc_ext && {
            let mut sf = vk::PhysicalDeviceSubgroupSizeControlFeatures::default();
            let mut f2 = vk::PhysicalDeviceFeatures2::default().push_next(&mut sf);
            instance.get_physical_device_features2(pd, &mut f2);
            sf.subgroup_size_control == vk::TRUE
                && ssc.required_subgroup_size_stages.contains(vk::ShaderStageFlags::COMPUTE)
        };
        let qf = instance.get_physical_device_queue_family_properties(pd);
        let timestamps =
            qf.iter().any(|q| q.queue_flags.contains(vk::QueueFlags::COMPUTE) && q.timestamp_valid_bits > 0);
        let v = props.api_version;
        DeviceInfo {
            index,
            name: props.device_name_as_c_str().map(|s| s.to_string_lossy().to_string()).unwrap_or_default(),
            kind: format!("{:?}", props.device_type).to_lowercase(),
            driver: format!(
                "{} {}",
                drv.driver_name_as_c_str().map(|s| s.to_string_lossy().to_string()).unwrap_or_default(),
                drv.driver_info_as_c_str().map(|s| s.to_string_lossy().to_string()).unwrap_or_default()
            ),
            api_version: format!(
                "{}.{}.{}",
                vk::api_version_major(v),
                vk::api_version_minor(v),
                vk::api_version_patch(v)
            ),
            shader_float16: v12.shader_float16 == vk::TRUE,
            storage_16bit: v11.storage_buffer16_bit_access == vk::TRUE,
            shader_float64: f64ok,
            subgroup_size: sub.subgroup_size,
            subgroup_ops: sub.supported_operations.as_raw(),
            ray_query: rq_ok,
            buffer_device_address: v12.buffer_device_address == vk::TRUE,
            max_storage_buffer: props.limits.max_storage_buffer_range as u64,
            max_allocation: p11.max_memory_allocation_size,
            timestamp_period_ns: props.limits.timestamp_period,
            timestamps,
            fp16_rte: fc.shader_rounding_mode_rte_float16 == vk::TRUE,
            fp32_rte: fc.shader_rounding_mode_rte_float32 == vk::TRUE,
            preserve_16: fc.shader_signed_zero_inf_nan_preserve_float16 == vk::TRUE,
            preserve_32: fc.shader_signed_zero_inf_nan_preserve_float32 == vk::TRUE,
            subgroup_size_control: ssc_ok,
            min_subgroup_size: if ssc_ok { ssc.min_subgroup_size } else { sub.subgroup_size },
            max_subgroup_size: if ssc_ok { ssc.max_subgroup_size } else { sub.subgroup_size },
        }
    }
}

/// Lists every Vulkan device with the features halftrace cares about.
pub fn list_devices() -> Result<Vec<DeviceInfo>, GpuError> {
    let entry = load_entry()?;
    let (instance, _) = make_instance(&entry, false)?;
    let pds = unsafe { instance.enumerate_physical_devices() };
    let out = pds
        .map(|v| v.into_iter().enumerate().map(|(i, pd)| describe(&instance, pd, i)).collect())
        .vk("vkEnumeratePhysicalDevices");
    unsafe { instance.destroy_instance(None) };
    out
}

/// The device `--device` chooses: an index, or a case-insensitive name substring; without
/// one, the first discrete GPU, else integrated, else virtual, else CPU.
pub fn pick(infos: &[DeviceInfo], want: Option<&str>) -> Result<usize, GpuError> {
    if infos.is_empty() {
        return Err(GpuError::NoDevice);
    }
    if let Some(w) = want {
        if let Ok(i) = w.parse::<usize>() {
            return if i < infos.len() { Ok(i) } else { Err(GpuError::DeviceNotFound(w.into())) };
        }
        let wl = w.to_lowercase();
        return infos
            .iter()
            .position(|d| d.name.to_lowercase().contains(&wl))
            .ok_or_else(|| GpuError::DeviceNotFound(w.into()));
    }
    for kind in ["discrete_gpu", "integrated_gpu", "virtual_gpu", "cpu"] {
        if let Some(i) = infos.iter().position(|d| d.kind == kind) {
            return Ok(i);
        }
    }
    Ok(0)
}

impl Gpu {
    pub fn new(opts: &ContextOptions) -> Result<Gpu, GpuError> {
        let validation = opts.validation || std::env::var("HALFTRACE_VALIDATION").is_ok_and(|v| v == "1");
        let entry = load_entry()?;
        let (instance, use_layer) = make_instance(&entry, validation)?;
        // From here on, failures must destroy the instance.
        match Self::open(entry.clone(), instance.clone(), use_layer, opts) {
            Ok(g) => Ok(g),
            Err((e, debug)) => {
                unsafe {
                    if let Some((du, m, store)) = debug {
                        du.destroy_debug_utils_messenger(m, None);
                        drop(Box::from_raw(store));
                    }
                    instance.destroy_instance(None);
                }
                Err(e)
            }
        }
    }

    #[allow(clippy::type_complexity)]
    fn open(
        entry: ash::Entry,
        instance: ash::Instance,
        use_layer: bool,
        opts: &ContextOptions,
    ) -> Result<
        Gpu,
        (GpuError, Option<(ash::ext::debug_utils::Instance, vk::DebugUtilsMessengerEXT, *mut Mutex<Vec<String>>)>),
    > {
        let mut debug = None;
        if use_layer {
            let du = ash::ext::debug_utils::Instance::new(&entry, &instance);
            let store = Box::into_raw(Box::new(Mutex::new(Vec::<String>::new())));
            let info = vk::DebugUtilsMessengerCreateInfoEXT::default()
                .message_severity(
                    vk::DebugUtilsMessageSeverityFlagsEXT::WARNING | vk::DebugUtilsMessageSeverityFlagsEXT::ERROR,
                )
                .message_type(
                    vk::DebugUtilsMessageTypeFlagsEXT::GENERAL
                        | vk::DebugUtilsMessageTypeFlagsEXT::VALIDATION
                        | vk::DebugUtilsMessageTypeFlagsEXT::PERFORMANCE,
                )
                .pfn_user_callback(Some(debug_callback))
                .user_data(store as *mut c_void);
            match unsafe { du.create_debug_utils_messenger(&info, None) } {
                Ok(m) => debug = Some((du, m, store)),
                Err(r) => {
                    unsafe { drop(Box::from_raw(store)) };
                    return Err((GpuError::Vk { call: "vkCreateDebugUtilsMessengerEXT", result: r }, None));
                }
            }
        }
        macro_rules! tryd {
            ($e:expr) => {
                match $e {
                    Ok(v) => v,
                    Err(e) => return Err((e, debug)),
                }
            };
        }
        let pds = tryd!(unsafe { instance.enumerate_physical_devices() }.vk("vkEnumeratePhysicalDevices"));
        let infos: Vec<DeviceInfo> = pds.iter().enumerate().map(|(i, &pd)| describe(&instance, pd, i)).collect();
        let idx = tryd!(pick(&infos, opts.device.as_deref()));
        let mut info = infos[idx].clone();
        let physical = pds[idx];
        // Pretended lower limits (tests of the addressed path and of the refusals).
        let env_limit = |var: &str| match std::env::var(var) {
            Ok(v) => v
                .trim()
                .parse::<u64>()
                .map(Some)
                .map_err(|_| GpuError::Other(format!("{var}='{v}': give a number of bytes"))),
            Err(_) => Ok(None),
        };
        if let Some(m) = opts.max_buffer.or(tryd!(env_limit("HALFTRACE_MAX_STORAGE_BUFFER"))) {
            info.max_storage_buffer = info.max_storage_buffer.min(m);
        }
        if let Some(m) = tryd!(env_limit("HALFTRACE_MAX_ALLOCATION")) {
            info.max_allocation = info.max_allocation.min(m);
        }
        for m in &opts.mask_features {
            if let Err(e) = info.mask(m) {
                return Err((GpuError::Other(e), debug));
            }
        }
        // No feature is required up front: each variant needs what its layout and math use
        // (gpu::support), and what a device lacks becomes one skipped line per variant.
        if !info.timestamps {
            return Err((
                GpuError::MissingFeature {
                    device: info.name.clone(),
                    feature: "timestamp queries on a compute queue".into(),
                },
                debug,
            ));
        }
        let qfs = unsafe { instance.get_physical_device_queue_family_properties(physical) };
        let qfi = qfs
            .iter()
            .position(|q| q.queue_flags.contains(vk::QueueFlags::COMPUTE) && q.timestamp_valid_bits > 0)
            .unwrap() as u32;
        let prio = [1.0f32];
        let qinfo = [vk::DeviceQueueCreateInfo::default().queue_family_index(qfi).queue_priorities(&prio)];
        let rq = info.ray_query;
        let bda = info.buffer_device_address;
        let mut v11 = vk::PhysicalDeviceVulkan11Features::default().storage_buffer16_bit_access(info.storage_16bit);
        let mut v12 = vk::PhysicalDeviceVulkan12Features::default()
            .shader_float16(info.shader_float16)
            .buffer_device_address(bda);
        let mut sscf = vk::PhysicalDeviceSubgroupSizeControlFeatures::default().subgroup_size_control(true);
        let mut asf = vk::PhysicalDeviceAccelerationStructureFeaturesKHR::default().acceleration_structure(true);
        let mut rqf = vk::PhysicalDeviceRayQueryFeaturesKHR::default().ray_query(true);
        let base = vk::PhysicalDeviceFeatures::default().shader_float64(info.shader_float64);
        let ext_names = [
            ash::khr::acceleration_structure::NAME.as_ptr(),
            ash::khr::ray_query::NAME.as_ptr(),
            ash::khr::deferred_host_operations::NAME.as_ptr(),
        ];
        let mut exts: Vec<*const std::ffi::c_char> = Vec::new();
        if rq {
            exts.extend(ext_names);
        }
        if info.subgroup_size_control {
            exts.push(ash::ext::subgroup_size_control::NAME.as_ptr());
        }
        let mut dinfo = vk::DeviceCreateInfo::default()
            .queue_create_infos(&qinfo)
            .enabled_features(&base)
            .push_next(&mut v11)
            .push_next(&mut v12)
            .enabled_extension_names(&exts);
        if rq {
            dinfo = dinfo.push_next(&mut asf).push_next(&mut rqf);
        }
        if info.subgroup_size_control {
            dinfo = dinfo.push_next(&mut sscf);
        }
        let device = tryd!(unsafe { instance.create_device(physical, &dinfo, None) }.vk("vkCreateDevice"));
        let queue = unsafe { device.get_device_queue(qfi, 0) };
        let pool = match unsafe {
            device.create_command_pool(
                &vk::CommandPoolCreateInfo::default()
                    .queue_family_index(qfi)
                    .flags(vk::CommandPoolCreateFlags::RESET_COMMAND_BUFFER),
                None,
            )
        } {
            Ok(p) => p,
            Err(r) => {
                unsafe { device.destroy_device(None) };
                return Err((GpuError::Vk { call: "vkCreateCommandPool", result: r }, debug));
            }
        };
        let allocator = match Allocator::new(&AllocatorCreateDesc {
            instance: instance.clone(),
            device: device.clone(),
            physical_device: physical,
            debug_settings: Default::default(),
            buffer_device_address: bda,
            allocation_sizes: Default::default(),
        }) {
            Ok(a) => a,
            Err(e) => {
                unsafe {
                    device.destroy_command_pool(pool, None);
                    device.destroy_device(None);
                }
                return Err((GpuError::Other(format!("creating the allocator: {e}")), debug));
            }
        };
        Ok(Gpu {
            _entry: entry,
            instance,
            physical,
            debug,
            device,
            queue,
            pool,
            allocator: ManuallyDrop::new(Mutex::new(allocator)),
            info,
            validation_enabled: use_layer,
            kernel_timeout: std::time::Duration::from_secs_f64(
                opts.kernel_timeout_s.unwrap_or(DEFAULT_KERNEL_TIMEOUT_S).max(0.001),
            ),
            hung: std::sync::atomic::AtomicBool::new(false),
        })
    }

    /// Bytes currently allocated through the allocator (0 once every buffer is dropped).
    pub fn allocated_bytes(&self) -> u64 {
        self.allocator.lock().map(|a| a.generate_report().total_allocated_bytes).unwrap_or(u64::MAX)
    }

    /// Validation messages (warnings and errors) reported so far.
    pub fn validation_messages(&self) -> Vec<String> {
        match &self.debug {
            Some((_, _, store)) => unsafe { &**store }.lock().map(|v| v.clone()).unwrap_or_default(),
            None => Vec::new(),
        }
    }

    /// Whether a submission hung (then nothing the device may still use is destroyed).
    pub fn hung(&self) -> bool {
        self.hung.load(std::sync::atomic::Ordering::SeqCst)
    }

    /// Records commands with `record`, submits them and waits for completion, at most the
    /// kernel timeout: past it the work is declared hung ([`GpuError::Hung`]) and its command
    /// buffer and fence are left to the device.
    pub fn submit_and_wait(&self, record: impl FnOnce(vk::CommandBuffer)) -> Result<(), GpuError> {
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
                d.queue_submit(self.queue, &submit, fence).vk("vkQueueSubmit")?;
                match d.wait_for_fences(&[fence], true, self.kernel_timeout.as_nanos().min(u64::MAX as u128) as u64) {
                    Err(vk::Result::TIMEOUT) => {
                        self.hung.store(true, std::sync::atomic::Ordering::SeqCst);
                        Err(GpuError::Hung { secs: self.kernel_timeout.as_secs_f64() })
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
        unsafe {
            let _ = self.device.device_wait_idle();
            self.device.destroy_command_pool(self.pool, None);
            // Frees every remaining block (and reports leaks through gpu-allocator's log).
            ManuallyDrop::drop(&mut self.allocator);
            self.device.destroy_device(None);
            if let Some((du, m, store)) = self.debug.take() {
                du.destroy_debug_utils_messenger(m, None);
                drop(Box::from_raw(store));
            }
            self.instance.destroy_instance(None);
        }
    }
}
