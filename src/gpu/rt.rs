//! The driver's ray-tracing pipeline (VK_KHR_ray_tracing_pipeline) over the acceleration
//! structures [`super::accel`] builds: the Vulkan side of the `rt` baseline. Three stages
//! (`glsl/trav_rt.rgen`, `.rchit`, `.rmiss`) in three groups — ray generation, miss, one
//! triangle hit group — and their shader binding table; one ray per launch index, timed with
//! the same timestamps, warm-up and repetitions as every kernel.

use super::accel::AccelScene;
use super::buffer::Buffer;
use super::timer::timed;
use super::{shader, Gpu, GpuError, VkResultExt};
use crate::base::{Hit, Ray, RunOutput};
use crate::interface::{binding, PushConstants};
use ash::vk;
use gpu_allocator::MemoryLocation;

/// Kernel name of the ray-tracing pipeline (its stages are `trav_rt.rgen`, `.rchit`, `.rmiss`).
pub const KERNEL: &str = "trav_rt";

/// The stages every shader reads the push constants in (only ray generation uses them; the
/// others include the same interface header).
const PUSH_STAGES: vk::ShaderStageFlags = vk::ShaderStageFlags::from_raw(
    vk::ShaderStageFlags::RAYGEN_KHR.as_raw()
        | vk::ShaderStageFlags::CLOSEST_HIT_KHR.as_raw()
        | vk::ShaderStageFlags::MISS_KHR.as_raw(),
);

/// The ray-tracing pipeline, its descriptor set (binding 0 the TLAS, 3 rays, 4 hits) and its
/// shader binding table.
pub struct RtPipeline<'g> {
    gpu: &'g Gpu,
    loader: ash::khr::ray_tracing_pipeline::Device,
    modules: Vec<vk::ShaderModule>,
    dsl: vk::DescriptorSetLayout,
    layout: vk::PipelineLayout,
    pipeline: vk::Pipeline,
    pool: vk::DescriptorPool,
    set: vk::DescriptorSet,
    /// Ray generation, miss, hit and (empty) callable regions of `_sbt`.
    regions: [vk::StridedDeviceAddressRegionKHR; 4],
    _sbt: Option<Buffer<'g>>,
    /// The widest and tallest launch (`maxComputeWorkGroupCount × maxComputeWorkGroupSize` in
    /// x and y) and the most invocations of one (`maxRayDispatchInvocationCount`).
    max_width: u64,
    max_height: u64,
    max_invocations: u64,
}

impl<'g> RtPipeline<'g> {
    pub fn new(gpu: &'g Gpu) -> Result<RtPipeline<'g>, GpuError> {
        if !gpu.info.ray_tracing_pipeline {
            return Err(GpuError::MissingFeature {
                device: gpu.info.name.clone(),
                feature: "VK_KHR_ray_tracing_pipeline / VK_KHR_acceleration_structure".into(),
            });
        }
        let code: Vec<Vec<u32>> = ["trav_rt.rgen", "trav_rt.rmiss", "trav_rt.rchit"]
            .into_iter()
            .map(|f| shader::compile_plain(KERNEL, f, &[]))
            .collect::<Result<_, _>>()?;
        let mut props = vk::PhysicalDeviceRayTracingPipelinePropertiesKHR::default();
        let limits = unsafe {
            let mut p2 = vk::PhysicalDeviceProperties2::default().push_next(&mut props);
            gpu.instance.get_physical_device_properties2(gpu.physical, &mut p2);
            p2.properties.limits
        };
        let d = &gpu.device;
        let mut p = RtPipeline {
            gpu,
            loader: ash::khr::ray_tracing_pipeline::Device::new(&gpu.instance, d),
            modules: Vec::new(),
            dsl: vk::DescriptorSetLayout::null(),
            layout: vk::PipelineLayout::null(),
            pipeline: vk::Pipeline::null(),
            pool: vk::DescriptorPool::null(),
            set: vk::DescriptorSet::null(),
            regions: Default::default(),
            _sbt: None,
            max_width: limits.max_compute_work_group_count[0] as u64 * limits.max_compute_work_group_size[0] as u64,
            max_height: limits.max_compute_work_group_count[1] as u64 * limits.max_compute_work_group_size[1] as u64,
            max_invocations: props.max_ray_dispatch_invocation_count as u64,
        };
        let types = [
            (binding::NODES, vk::DescriptorType::ACCELERATION_STRUCTURE_KHR),
            (binding::RAYS, vk::DescriptorType::STORAGE_BUFFER),
            (binding::HITS, vk::DescriptorType::STORAGE_BUFFER),
        ];
        // Every object created is destroyed by Drop, even when a later step fails.
        unsafe {
            for c in &code {
                let m = d
                    .create_shader_module(&vk::ShaderModuleCreateInfo::default().code(c), None)
                    .vk("vkCreateShaderModule")?;
                p.modules.push(m);
            }
            let b: Vec<vk::DescriptorSetLayoutBinding> = types
                .iter()
                .map(|&(i, t)| {
                    vk::DescriptorSetLayoutBinding::default()
                        .binding(i)
                        .descriptor_type(t)
                        .descriptor_count(1)
                        .stage_flags(vk::ShaderStageFlags::RAYGEN_KHR)
                })
                .collect();
            p.dsl = d
                .create_descriptor_set_layout(&vk::DescriptorSetLayoutCreateInfo::default().bindings(&b), None)
                .vk("vkCreateDescriptorSetLayout")?;
            let dsls = [p.dsl];
            let ranges = [vk::PushConstantRange::default()
                .stage_flags(PUSH_STAGES)
                .offset(0)
                .size(std::mem::size_of::<PushConstants>() as u32)];
            p.layout = d
                .create_pipeline_layout(
                    &vk::PipelineLayoutCreateInfo::default().set_layouts(&dsls).push_constant_ranges(&ranges),
                    None,
                )
                .vk("vkCreatePipelineLayout")?;
            let stage = |s: vk::ShaderStageFlags, m: vk::ShaderModule| {
                vk::PipelineShaderStageCreateInfo::default().stage(s).module(m).name(c"main")
            };
            let stages = [
                stage(vk::ShaderStageFlags::RAYGEN_KHR, p.modules[0]),
                stage(vk::ShaderStageFlags::MISS_KHR, p.modules[1]),
                stage(vk::ShaderStageFlags::CLOSEST_HIT_KHR, p.modules[2]),
            ];
            let group = |ty: vk::RayTracingShaderGroupTypeKHR, general: u32, closest_hit: u32| {
                vk::RayTracingShaderGroupCreateInfoKHR::default()
                    .ty(ty)
                    .general_shader(general)
                    .closest_hit_shader(closest_hit)
                    .any_hit_shader(vk::SHADER_UNUSED_KHR)
                    .intersection_shader(vk::SHADER_UNUSED_KHR)
            };
            let (general, triangles, unused) = (
                vk::RayTracingShaderGroupTypeKHR::GENERAL,
                vk::RayTracingShaderGroupTypeKHR::TRIANGLES_HIT_GROUP,
                vk::SHADER_UNUSED_KHR,
            );
            // Groups 0, 1, 2: ray generation, miss, hit — the order of the table's regions.
            let groups = [group(general, 0, unused), group(general, 1, unused), group(triangles, unused, 2)];
            let info = [vk::RayTracingPipelineCreateInfoKHR::default()
                .stages(&stages)
                .groups(&groups)
                .max_pipeline_ray_recursion_depth(1)
                .layout(p.layout)];
            p.pipeline = p
                .loader
                .create_ray_tracing_pipelines(vk::DeferredOperationKHR::null(), vk::PipelineCache::null(), &info, None)
                .map_err(|(_, r)| GpuError::Vk { call: "vkCreateRayTracingPipelinesKHR", result: r })?[0];
            let sizes = [
                vk::DescriptorPoolSize { ty: vk::DescriptorType::ACCELERATION_STRUCTURE_KHR, descriptor_count: 1 },
                vk::DescriptorPoolSize { ty: vk::DescriptorType::STORAGE_BUFFER, descriptor_count: 2 },
            ];
            p.pool = d
                .create_descriptor_pool(&vk::DescriptorPoolCreateInfo::default().max_sets(1).pool_sizes(&sizes), None)
                .vk("vkCreateDescriptorPool")?;
            p.set = d
                .allocate_descriptor_sets(
                    &vk::DescriptorSetAllocateInfo::default().descriptor_pool(p.pool).set_layouts(&dsls),
                )
                .vk("vkAllocateDescriptorSets")?[0];
        }
        p.binding_table(&props)?;
        Ok(p)
    }

    /// The shader binding table: one record (the group's handle) per region; a record's
    /// stride is the handle size rounded up to `shaderGroupHandleAlignment`, and each region
    /// starts at a multiple of `shaderGroupBaseAlignment` (the buffer itself is aligned so).
    fn binding_table(&mut self, props: &vk::PhysicalDeviceRayTracingPipelinePropertiesKHR) -> Result<(), GpuError> {
        let handle = props.shader_group_handle_size as u64;
        let stride = handle.next_multiple_of(props.shader_group_handle_alignment.max(1) as u64);
        let base = (props.shader_group_base_alignment as u64).max(1);
        let region = stride.next_multiple_of(base);
        let handles =
            unsafe { self.loader.get_ray_tracing_shader_group_handles(self.pipeline, 0, 3, 3 * handle as usize) }
                .vk("vkGetRayTracingShaderGroupHandlesKHR")?;
        let mut table = vec![0u8; (2 * region + stride) as usize];
        for (g, h) in handles.chunks_exact(handle as usize).enumerate() {
            let at = g * region as usize;
            table[at..at + h.len()].copy_from_slice(h);
        }
        let usage = vk::BufferUsageFlags::SHADER_BINDING_TABLE_KHR | vk::BufferUsageFlags::SHADER_DEVICE_ADDRESS;
        let sbt = Buffer::host_aligned(self.gpu, "rt shader binding table", &table, usage, base)?;
        let at = |i: u64| vk::StridedDeviceAddressRegionKHR {
            device_address: sbt.address() + i * region,
            stride,
            size: stride,
        };
        self.regions = [at(0), at(1), at(2), vk::StridedDeviceAddressRegionKHR::default()];
        self._sbt = Some(sbt);
        Ok(())
    }

    /// The launch of `n` rays: one row where the device allows it (neighbouring invocations
    /// trace neighbouring rays), else rows of the widest launch.
    fn launch(&self, n: usize) -> Result<(u32, u32), GpuError> {
        let n = (n as u64).max(1);
        let width = n.min(self.max_width).min(u32::MAX as u64);
        let height = n.div_ceil(width);
        if height > self.max_height || width * height > self.max_invocations {
            return Err(GpuError::Other(format!(
                "{KERNEL}: {n} rays in one launch is more than {} allows (maxRayDispatchInvocationCount {})",
                self.gpu.info.name, self.max_invocations
            )));
        }
        Ok((width as u32, height as u32))
    }

    /// Points the descriptors at the TLAS, the rays and the hits.
    fn bind(&self, tlas: vk::AccelerationStructureKHR, rays: &Buffer, hits: &Buffer) {
        let ases = [tlas];
        let mut asw = vk::WriteDescriptorSetAccelerationStructureKHR::default().acceleration_structures(&ases);
        let mut w_as = vk::WriteDescriptorSet::default()
            .dst_set(self.set)
            .dst_binding(binding::NODES)
            .descriptor_type(vk::DescriptorType::ACCELERATION_STRUCTURE_KHR)
            .push_next(&mut asw);
        w_as.descriptor_count = 1;
        let infos =
            [rays, hits].map(|b| [vk::DescriptorBufferInfo { buffer: b.raw, offset: 0, range: vk::WHOLE_SIZE }]);
        let [w_rays, w_hits] = [binding::RAYS, binding::HITS].map(|i| {
            vk::WriteDescriptorSet::default()
                .dst_set(self.set)
                .dst_binding(i)
                .descriptor_type(vk::DescriptorType::STORAGE_BUFFER)
        });
        let writes = [w_as, w_rays.buffer_info(&infos[0]), w_hits.buffer_info(&infos[1])];
        unsafe { self.gpu.device.update_descriptor_sets(&writes, &[]) };
    }

    /// Records one `vkCmdTraceRaysKHR` of `width × height` invocations.
    fn trace(&self, cmd: vk::CommandBuffer, push: &[u8], width: u32, height: u32) {
        let d = &self.gpu.device;
        let [raygen, miss, hit, callable] = &self.regions;
        unsafe {
            d.cmd_bind_pipeline(cmd, vk::PipelineBindPoint::RAY_TRACING_KHR, self.pipeline);
            d.cmd_bind_descriptor_sets(cmd, vk::PipelineBindPoint::RAY_TRACING_KHR, self.layout, 0, &[self.set], &[]);
            d.cmd_push_constants(cmd, self.layout, PUSH_STAGES, 0, push);
            self.loader.cmd_trace_rays(cmd, raygen, miss, hit, callable, width, height, 1);
        }
    }

    /// A barrier making the ray-generation stage's writes visible to transfers and later
    /// launches.
    fn barrier(&self, cmd: vk::CommandBuffer) {
        super::pipeline::shader_write_barrier(self.gpu, cmd, vk::PipelineStageFlags::RAY_TRACING_SHADER_KHR);
    }
}

impl Drop for RtPipeline<'_> {
    fn drop(&mut self) {
        if self.gpu.hung() {
            return;
        }
        super::pipeline::destroy_parts(self.gpu, self.pool, self.pipeline, self.layout, self.dsl, &self.modules);
    }
}

/// Traces `rays` with the ray-tracing pipeline: `warmup` untimed, `repeat` timed launches.
pub fn run(
    gpu: &Gpu,
    scene: &AccelScene,
    pipe: &RtPipeline,
    rays: &[Ray],
    warmup: usize,
    repeat: usize,
) -> Result<RunOutput, GpuError> {
    let n = rays.len();
    let (width, height) = pipe.launch(n)?;
    let ray_buf = Buffer::upload(gpu, "rays", bytemuck::cast_slice(rays))?;
    let usage = vk::BufferUsageFlags::STORAGE_BUFFER | vk::BufferUsageFlags::TRANSFER_SRC;
    let hit_bytes = n * std::mem::size_of::<Hit>();
    let hits = Buffer::new(gpu, "hits", hit_bytes as u64, usage, MemoryLocation::GpuOnly)?;
    pipe.bind(scene.tlas, &ray_buf, &hits);
    let push = PushConstants { ray_count: n as u32, ..Default::default() };
    let push = bytemuck::bytes_of(&push);
    let times = timed(gpu, warmup, repeat, |cmd| pipe.trace(cmd, push, width, height), |cmd| pipe.barrier(cmd))?;
    let hits: Vec<Hit> = bytemuck::pod_collect_to_vec(&hits.download(hit_bytes)?);
    crate::digest::record("baseline", KERNEL, rays, &hits, None);
    Ok(RunOutput { hits, counters: None, times_ms: times, flagged: 0 })
}
