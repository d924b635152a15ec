//! Which Vulkan devices there are, what each can do ([`DeviceInfo`], read once per device),
//! and which one `--device` picks ([`pick`]).

use super::instance::Instance;
use super::{GpuError, VkResultExt};
use ash::vk;
use std::ffi::CStr;

/// What the harness needs to know about a device.
#[derive(Clone, Debug, Default)]
pub struct DeviceInfo {
    pub index: usize,
    pub name: String,
    pub kind: String,
    pub driver: String,
    /// `VkDriverId`: which driver this is, whose vendor ([`crate::vendor`]) sets the quirks.
    pub driver_id: vk::DriverId,
    pub api_version: String,
    pub shader_float16: bool,
    pub storage_16bit: bool,
    pub shader_float64: bool,
    pub subgroup_size: u32,
    /// `VkSubgroupFeatureFlags` the device supports (basic, vote, arithmetic, ballot, shuffle,
    /// shuffle relative, clustered, quad: bits 0..7).
    pub subgroup_ops: u32,
    pub ray_query: bool,
    /// `VK_KHR_ray_tracing_pipeline` and `VK_KHR_acceleration_structure` with their
    /// `rayTracingPipeline` and `accelerationStructure` features, and `bufferDeviceAddress`
    /// (the shader binding table is read by address): the `rt` baseline runs.
    pub ray_tracing_pipeline: bool,
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
    /// `VK_KHR_pipeline_executable_properties` with `pipelineExecutableInfo`: the driver
    /// reports each pipeline's compiler statistics and internal representations (`isa`).
    pub pipeline_statistics: bool,
    /// A device that compiles pipelines but runs nothing — RADV's null device for a
    /// `RADV_FORCE_FAMILY`, or a driver under Mesa's drm-shim ([`shim`]): only `isa` uses it.
    pub compile_only: bool,
    /// The newest SPIR-V the device accepts, as its minor version (1.x): 5 on Vulkan 1.2 and
    /// later, 3 on 1.1 (4 with `VK_KHR_spirv_1_4`), 0 on 1.0.
    pub spirv_minor: u8,
    /// The largest private array the driver's compiler keeps in registers rather than in
    /// memory, in bytes, where it is known to matter: turnip (Adreno) keeps arrays there, each
    /// field of an array of structs on its own, of up to 256 bytes on Mesa 25.0.7 and up to 768
    /// on 26.2 (measured with `isa` on a740; the vendor file says how); Honeykrisp (Apple) of
    /// up to 256. 0: none known. A vendor quirk ([`DeviceInfo::with_quirks`]).
    pub register_array_bytes: u32,
    /// Whether kernels that defer entries keep the entry of the child to enter next in shared
    /// memory rather than in registers (`PENDING_SHARED`): on GPUs it saves registers (isa,
    /// f16h B = 4: navi31 84 -> 72 VGPRs; ga102 207 -> 186; g610 646 -> 357 spills and fills;
    /// a740 unchanged at B = 4, 168 -> 128 at B = 8). Not on Intel's compiler, where it costs
    /// registers (lnl f16h fp16 B = 4: 103 -> 110, and more spills at B = 16), nor on a CPU
    /// implementation, where registers are not scarce and shared memory is memory (lavapipe,
    /// `bench`: f16h fp32 math B = 4 0.82-0.84x the speed of the entry in registers). A vendor
    /// quirk ([`DeviceInfo::with_quirks`]).
    pub pending_shared: bool,
}

impl DeviceInfo {
    /// The device with its vendor's quirks set (`crate::vendor`, from the driver id; the GPU
    /// default for a driver of no vendor), after [`describe`] has read what Vulkan says. A CPU
    /// implementation keeps the pending entry in registers: registers are not scarce there and
    /// shared memory is memory.
    pub fn with_quirks(mut self) -> DeviceInfo {
        let q = crate::vendor::Vendor::of_driver_id(self.driver_id).map_or(crate::vendor::GPU_DEFAULT, |v| v.quirks);
        self.register_array_bytes = q.register_array_bytes;
        self.pending_shared = q.pending_shared && self.kind != "cpu";
        self
    }

    /// Whether the driver compiles a compute pipeline's code at its first dispatch rather than
    /// when the pipeline is created (lavapipe: llvmpipe compiles there).
    pub fn compiles_at_first_dispatch(&self) -> bool {
        self.driver_id == vk::DriverId::MESA_LLVMPIPE
    }
}

impl DeviceInfo {
    /// What a kernel's build takes from this device beyond its variant.
    pub fn build(&self) -> crate::variant::DeviceBuild {
        crate::variant::DeviceBuild {
            storage16: self.storage_16bit,
            spirv_minor: self.spirv_minor.min(5),
            register_array_bytes: self.register_array_bytes,
            pending_shared: self.pending_shared,
        }
    }
}

/// The drm-shim this process runs under, if any: Mesa's `lib<driver>_noop_drm_shim.so` in
/// `LD_PRELOAD` fakes the kernel driver of `<driver>` (freedreno, panfrost, intel, nouveau,
/// v3d), so that driver's Vulkan device builds pipelines and runs nothing.
pub fn shim() -> Option<String> {
    let pre = std::env::var("LD_PRELOAD").ok()?;
    pre.split([':', ' ']).find_map(|p| {
        let f = std::path::Path::new(p).file_name()?.to_str()?;
        Some(f.strip_prefix("lib")?.strip_suffix("_noop_drm_shim.so")?.to_string())
    })
}

impl DeviceInfo {
    /// Treats feature `name` (one of [`MASKABLE`]) as missing.
    pub fn mask(&mut self, name: &str) -> Result<(), String> {
        match name {
            "shaderFloat16" => self.shader_float16 = false,
            "storageBuffer16BitAccess" => self.storage_16bit = false,
            "shaderFloat64" => self.shader_float64 = false,
            "rayQuery" => self.ray_query = false,
            "rayTracingPipeline" => self.ray_tracing_pipeline = false,
            "bufferDeviceAddress" => {
                self.buffer_device_address = false;
                self.ray_query = false;
                self.ray_tracing_pipeline = false;
            }
            "subgroupClustered" => self.subgroup_ops &= !(1 << 6),
            "subgroupArithmetic" => self.subgroup_ops &= !((1 << 2) | (1 << 6)),
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
    "rayTracingPipeline",
    "bufferDeviceAddress",
    "subgroupSizeControl",
    "subgroupClustered",
    "subgroupArithmetic",
    "shaderRoundingModeRTEFloat16",
    "shaderRoundingModeRTEFloat32",
    "shaderSignedZeroInfNanPreserveFloat16",
    "shaderSignedZeroInfNanPreserveFloat32",
    "floatControls",
];

/// What the harness reads of one physical device, from Vulkan's queries alone (the vendor's
/// quirks come after: [`DeviceInfo::with_quirks`]). Vulkan 1.0 and 1.1 devices (panvk on Mali,
/// for one) are asked through the structures of their extensions, not the 1.2 aggregates.
pub(crate) fn describe(instance: &ash::Instance, pd: vk::PhysicalDevice, index: usize) -> DeviceInfo {
    unsafe {
        let props = instance.get_physical_device_properties(pd);
        let v = props.api_version;
        let minor = if vk::api_version_major(v) > 1 { 99 } else { vk::api_version_minor(v) };
        let exts0 = instance.enumerate_device_extension_properties(pd).unwrap_or_default();
        let has0 = |n: &CStr| exts0.iter().any(|e| e.extension_name_as_c_str().is_ok_and(|x| x == n));
        let mut v11 = vk::PhysicalDeviceVulkan11Features::default();
        let mut v12 = vk::PhysicalDeviceVulkan12Features::default();
        let mut s16 = vk::PhysicalDevice16BitStorageFeatures::default();
        let mut f16 = vk::PhysicalDeviceShaderFloat16Int8Features::default();
        let mut bdaf = vk::PhysicalDeviceBufferDeviceAddressFeatures::default();
        let mut asf = vk::PhysicalDeviceAccelerationStructureFeaturesKHR::default();
        let mut rqf = vk::PhysicalDeviceRayQueryFeaturesKHR::default();
        let mut rtf = vk::PhysicalDeviceRayTracingPipelineFeaturesKHR::default();
        // Acceleration structures (and so ray queries and ray-tracing pipelines) are asked
        // about only on Vulkan 1.2 devices, where their SPIR-V 1.4+ shaders can run.
        let as_exts = minor >= 2
            && has0(ash::khr::acceleration_structure::NAME)
            && has0(ash::khr::deferred_host_operations::NAME);
        let rq_exts = as_exts && has0(ash::khr::ray_query::NAME);
        let rt_exts = as_exts && has0(ash::khr::ray_tracing_pipeline::NAME);
        let (f64ok, shader_float16, storage_16bit, bda) = {
            let mut f2 = vk::PhysicalDeviceFeatures2::default();
            if minor >= 2 {
                f2 = f2.push_next(&mut v11).push_next(&mut v12);
                if as_exts {
                    f2 = f2.push_next(&mut asf);
                }
                if rq_exts {
                    f2 = f2.push_next(&mut rqf);
                }
                if rt_exts {
                    f2 = f2.push_next(&mut rtf);
                }
            } else {
                if minor >= 1 || has0(ash::khr::_16bit_storage::NAME) {
                    f2 = f2.push_next(&mut s16);
                }
                if has0(ash::khr::shader_float16_int8::NAME) {
                    f2 = f2.push_next(&mut f16);
                }
                if has0(ash::khr::buffer_device_address::NAME) {
                    f2 = f2.push_next(&mut bdaf);
                }
            }
            instance.get_physical_device_features2(pd, &mut f2);
            if minor >= 2 {
                (
                    f2.features.shader_float64 == vk::TRUE,
                    v12.shader_float16 == vk::TRUE,
                    v11.storage_buffer16_bit_access == vk::TRUE,
                    v12.buffer_device_address == vk::TRUE,
                )
            } else {
                (
                    f2.features.shader_float64 == vk::TRUE,
                    f16.shader_float16 == vk::TRUE,
                    s16.storage_buffer16_bit_access == vk::TRUE,
                    bdaf.buffer_device_address == vk::TRUE,
                )
            }
        };
        let as_ok = asf.acceleration_structure == vk::TRUE && bda;
        let rq_ok = rq_exts && as_ok && rqf.ray_query == vk::TRUE;
        let rt_ok = rt_exts && as_ok && rtf.ray_tracing_pipeline == vk::TRUE;
        let mut sub = vk::PhysicalDeviceSubgroupProperties::default();
        let mut drv = vk::PhysicalDeviceDriverProperties::default();
        let mut p11 = vk::PhysicalDeviceMaintenance3Properties::default();
        let mut fc = vk::PhysicalDeviceFloatControlsProperties::default();
        let mut ssc = vk::PhysicalDeviceSubgroupSizeControlProperties::default();
        let ssc_ext = has0(ash::ext::subgroup_size_control::NAME);
        let mut p2 = vk::PhysicalDeviceProperties2::default();
        if minor >= 1 {
            p2 = p2.push_next(&mut sub);
        }
        if minor >= 1 || has0(ash::khr::maintenance3::NAME) {
            p2 = p2.push_next(&mut p11);
        }
        if minor >= 2 || has0(ash::khr::driver_properties::NAME) {
            p2 = p2.push_next(&mut drv);
        }
        if minor >= 2 || has0(ash::khr::shader_float_controls::NAME) {
            p2 = p2.push_next(&mut fc);
        }
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
        let stats_ok = has0(ash::khr::pipeline_executable_properties::NAME) && {
            let mut pf = vk::PhysicalDevicePipelineExecutablePropertiesFeaturesKHR::default();
            let mut f2 = vk::PhysicalDeviceFeatures2::default().push_next(&mut pf);
            instance.get_physical_device_features2(pd, &mut f2);
            pf.pipeline_executable_info == vk::TRUE
        };
        let qf = instance.get_physical_device_queue_family_properties(pd);
        let timestamps =
            qf.iter().any(|q| q.queue_flags.contains(vk::QueueFlags::COMPUTE) && q.timestamp_valid_bits > 0);
        let name = props.device_name_as_c_str().map(|s| s.to_string_lossy().to_string()).unwrap_or_default();
        let shimmed = shim().is_some_and(|s| crate::vendor::Vendor::shimmed(&s, drv.driver_id).is_some());
        let spirv_minor = match minor {
            0 => 0,
            1 if has0(ash::khr::spirv_1_4::NAME) => 4,
            1 => 3,
            _ => 5,
        };
        DeviceInfo {
            index,
            compile_only: is_null_device(&name, drv.driver_id) || shimmed,
            name,
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
            shader_float16,
            storage_16bit,
            shader_float64: f64ok,
            subgroup_size: sub.subgroup_size,
            subgroup_ops: sub.supported_operations.as_raw(),
            ray_query: rq_ok,
            ray_tracing_pipeline: rt_ok,
            buffer_device_address: bda,
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
            pipeline_statistics: stats_ok,
            spirv_minor,
            driver_id: drv.driver_id,
            // The vendor's quirks are set after: [`DeviceInfo::with_quirks`].
            register_array_bytes: 0,
            pending_shared: true,
        }
    }
}

/// Whether a device is RADV's null device: what `RADV_FORCE_FAMILY` opens where no AMD GPU is
/// (named "Null hardware (RADV FAMILY)"). It builds pipelines with AMD's compiler, but a
/// submission or a wait on it crashes the process.
fn is_null_device(name: &str, driver: vk::DriverId) -> bool {
    driver == vk::DriverId::MESA_RADV && name.starts_with("Null hardware")
}

/// Lists every Vulkan device with the features halftrace cares about.
pub fn list_devices() -> Result<Vec<DeviceInfo>, GpuError> {
    let inst = Instance::new(false)?;
    let pds = unsafe { inst.instance.enumerate_physical_devices() }.vk("vkEnumeratePhysicalDevices")?;
    Ok(pds.into_iter().enumerate().map(|(i, pd)| describe(&inst.instance, pd, i).with_quirks()).collect())
}

/// The device `--device` chooses: an index, or a case-insensitive name substring; without
/// one, the first discrete GPU, else integrated, else virtual, else CPU — a device that can
/// run before a compile-only one.
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
    for compile_only in [false, true] {
        for kind in ["discrete_gpu", "integrated_gpu", "virtual_gpu", "cpu"] {
            if let Some(i) = infos.iter().position(|d| d.kind == kind && d.compile_only == compile_only) {
                return Ok(i);
            }
        }
    }
    Ok(0)
}
