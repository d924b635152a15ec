//! A compute pipeline with one descriptor set of storage buffers and a push-constant block.

use super::buffer::Buffer;
use super::{Gpu, GpuError, VkResultExt};
use ash::vk;

pub struct ComputePipeline<'g> {
    gpu: &'g Gpu,
    pub name: String,
    module: vk::ShaderModule,
    dsl: vk::DescriptorSetLayout,
    layout: vk::PipelineLayout,
    pipeline: vk::Pipeline,
    pool: vk::DescriptorPool,
    set: vk::DescriptorSet,
    types: Vec<vk::DescriptorType>,
    push_size: u32,
}

impl<'g> ComputePipeline<'g> {
    /// A pipeline whose `bindings` are all storage buffers.
    pub fn new(
        gpu: &'g Gpu,
        name: &str,
        spirv: &[u32],
        bindings: u32,
        push_size: u32,
    ) -> Result<ComputePipeline<'g>, GpuError> {
        Self::new_typed(gpu, name, spirv, &vec![vk::DescriptorType::STORAGE_BUFFER; bindings as usize], push_size, None)
    }

    /// A storage-buffer pipeline whose subgroup size is pinned to `subgroup` (needs
    /// `subgroupSizeControl`; `None`: the driver's choice).
    pub fn with_subgroup(
        gpu: &'g Gpu,
        name: &str,
        spirv: &[u32],
        bindings: u32,
        push_size: u32,
        subgroup: Option<u32>,
    ) -> Result<ComputePipeline<'g>, GpuError> {
        Self::new_typed(
            gpu,
            name,
            spirv,
            &vec![vk::DescriptorType::STORAGE_BUFFER; bindings as usize],
            push_size,
            subgroup,
        )
    }

    /// A pipeline with one descriptor of the given type per binding.
    pub fn new_typed(
        gpu: &'g Gpu,
        name: &str,
        spirv: &[u32],
        types: &[vk::DescriptorType],
        push_size: u32,
        subgroup: Option<u32>,
    ) -> Result<ComputePipeline<'g>, GpuError> {
        let d = &gpu.device;
        let mut p = ComputePipeline {
            gpu,
            name: name.into(),
            module: vk::ShaderModule::null(),
            dsl: vk::DescriptorSetLayout::null(),
            layout: vk::PipelineLayout::null(),
            pipeline: vk::Pipeline::null(),
            pool: vk::DescriptorPool::null(),
            set: vk::DescriptorSet::null(),
            types: types.to_vec(),
            push_size,
        };
        // Every object created is destroyed by Drop, even when a later step fails.
        unsafe {
            p.module = d
                .create_shader_module(&vk::ShaderModuleCreateInfo::default().code(spirv), None)
                .vk("vkCreateShaderModule")?;
            let b: Vec<vk::DescriptorSetLayoutBinding> = types
                .iter()
                .enumerate()
                .map(|(i, t)| {
                    vk::DescriptorSetLayoutBinding::default()
                        .binding(i as u32)
                        .descriptor_type(*t)
                        .descriptor_count(1)
                        .stage_flags(vk::ShaderStageFlags::COMPUTE)
                })
                .collect();
            p.dsl = d
                .create_descriptor_set_layout(&vk::DescriptorSetLayoutCreateInfo::default().bindings(&b), None)
                .vk("vkCreateDescriptorSetLayout")?;
            let dsls = [p.dsl];
            let ranges =
                [vk::PushConstantRange::default().stage_flags(vk::ShaderStageFlags::COMPUTE).offset(0).size(push_size)];
            p.layout = d
                .create_pipeline_layout(
                    &vk::PipelineLayoutCreateInfo::default().set_layouts(&dsls).push_constant_ranges(&ranges),
                    None,
                )
                .vk("vkCreatePipelineLayout")?;
            let mut size_info = vk::PipelineShaderStageRequiredSubgroupSizeCreateInfo::default()
                .required_subgroup_size(subgroup.unwrap_or(0));
            let mut stage = vk::PipelineShaderStageCreateInfo::default()
                .stage(vk::ShaderStageFlags::COMPUTE)
                .module(p.module)
                .name(c"main");
            if subgroup.is_some() {
                stage = stage.push_next(&mut size_info);
            }
            let flags = if gpu.capture {
                vk::PipelineCreateFlags::CAPTURE_STATISTICS_KHR
                    | vk::PipelineCreateFlags::CAPTURE_INTERNAL_REPRESENTATIONS_KHR
            } else {
                vk::PipelineCreateFlags::empty()
            };
            let info = [vk::ComputePipelineCreateInfo::default().flags(flags).stage(stage).layout(p.layout)];
            p.pipeline = d
                .create_compute_pipelines(vk::PipelineCache::null(), &info, None)
                .map_err(|(_, r)| GpuError::Vk { call: "vkCreateComputePipelines", result: r })?[0];
            let mut sizes: Vec<vk::DescriptorPoolSize> = Vec::new();
            for t in types {
                match sizes.iter_mut().find(|s| s.ty == *t) {
                    Some(s) => s.descriptor_count += 1,
                    None => sizes.push(vk::DescriptorPoolSize { ty: *t, descriptor_count: 1 }),
                }
            }
            p.pool = d
                .create_descriptor_pool(&vk::DescriptorPoolCreateInfo::default().max_sets(1).pool_sizes(&sizes), None)
                .vk("vkCreateDescriptorPool")?;
            p.set = d
                .allocate_descriptor_sets(
                    &vk::DescriptorSetAllocateInfo::default().descriptor_pool(p.pool).set_layouts(&dsls),
                )
                .vk("vkAllocateDescriptorSets")?[0];
        }
        Ok(p)
    }

    /// The raw pipeline (for [`super::executable`]).
    pub(crate) fn raw(&self) -> vk::Pipeline {
        self.pipeline
    }

    /// Points binding i at `buffers[i]`.
    pub fn bind(&self, buffers: &[&Buffer]) {
        let pairs: Vec<(u32, &Buffer)> = buffers.iter().enumerate().map(|(i, b)| (i as u32, *b)).collect();
        self.bind_at(&pairs);
    }

    /// Points each (binding, buffer) pair's storage-buffer binding at the buffer.
    pub fn bind_at(&self, buffers: &[(u32, &Buffer)]) {
        let infos: Vec<[vk::DescriptorBufferInfo; 1]> = buffers
            .iter()
            .map(|(_, b)| [vk::DescriptorBufferInfo { buffer: b.raw, offset: 0, range: vk::WHOLE_SIZE }])
            .collect();
        let writes: Vec<vk::WriteDescriptorSet> = infos
            .iter()
            .zip(buffers)
            .map(|(info, (i, _))| {
                vk::WriteDescriptorSet::default()
                    .dst_set(self.set)
                    .dst_binding(*i)
                    .descriptor_type(vk::DescriptorType::STORAGE_BUFFER)
                    .buffer_info(info)
            })
            .collect();
        unsafe { self.gpu.device.update_descriptor_sets(&writes, &[]) };
    }

    /// Points an acceleration-structure binding at `tlas`.
    pub fn bind_acceleration_structure(&self, binding: u32, tlas: vk::AccelerationStructureKHR) {
        let ases = [tlas];
        let mut asw = vk::WriteDescriptorSetAccelerationStructureKHR::default().acceleration_structures(&ases);
        let mut w = vk::WriteDescriptorSet::default()
            .dst_set(self.set)
            .dst_binding(binding)
            .descriptor_type(vk::DescriptorType::ACCELERATION_STRUCTURE_KHR)
            .push_next(&mut asw);
        w.descriptor_count = 1;
        unsafe { self.gpu.device.update_descriptor_sets(&[w], &[]) };
    }

    /// Has the driver compile the pipeline's code now, by submitting a dispatch of no
    /// workgroups with a small buffer behind every storage binding. lavapipe (llvmpipe)
    /// compiles a compute pipeline at its first dispatch, on the device's one queue thread, and
    /// keeps the code in Mesa's shader cache ([`Gpu::compiles_at_first_dispatch`]).
    pub fn warm(&self) -> Result<(), GpuError> {
        let usage = vk::BufferUsageFlags::STORAGE_BUFFER;
        let dummy = Buffer::new(self.gpu, "warm-up", 16, usage, gpu_allocator::MemoryLocation::GpuOnly)?;
        let storage: Vec<(u32, &Buffer)> = (0..self.types.len() as u32)
            .filter(|&i| self.types[i as usize] == vk::DescriptorType::STORAGE_BUFFER)
            .map(|i| (i, &dummy))
            .collect();
        self.bind_at(&storage);
        let push = vec![0u8; self.push_size as usize];
        let d = &self.gpu.device;
        self.gpu.submit_and_wait(|cmd| unsafe {
            d.cmd_bind_pipeline(cmd, vk::PipelineBindPoint::COMPUTE, self.pipeline);
            d.cmd_bind_descriptor_sets(cmd, vk::PipelineBindPoint::COMPUTE, self.layout, 0, &[self.set], &[]);
            d.cmd_push_constants(cmd, self.layout, vk::ShaderStageFlags::COMPUTE, 0, &push);
            d.cmd_dispatch(cmd, 0, 1, 1);
        })
    }

    /// Records a dispatch of `groups` workgroups (split over x and y past 65535).
    pub fn dispatch(&self, cmd: vk::CommandBuffer, push: &[u8], groups: u32) {
        assert_eq!(push.len() as u32, self.push_size);
        let d = &self.gpu.device;
        let gx = groups.clamp(1, 65535);
        let gy = groups.div_ceil(65535).max(1);
        unsafe {
            d.cmd_bind_pipeline(cmd, vk::PipelineBindPoint::COMPUTE, self.pipeline);
            d.cmd_bind_descriptor_sets(cmd, vk::PipelineBindPoint::COMPUTE, self.layout, 0, &[self.set], &[]);
            d.cmd_push_constants(cmd, self.layout, vk::ShaderStageFlags::COMPUTE, 0, push);
            d.cmd_dispatch(cmd, gx, gy, 1);
        }
    }

    /// A barrier making shader writes visible to transfers and later dispatches.
    pub fn barrier(&self, cmd: vk::CommandBuffer) {
        shader_write_barrier(self.gpu, cmd, vk::PipelineStageFlags::COMPUTE_SHADER);
    }
}

/// A barrier making the writes of shaders in `stage` (compute, ray tracing) visible to
/// transfers and to later work in the same stage.
pub(crate) fn shader_write_barrier(gpu: &Gpu, cmd: vk::CommandBuffer, stage: vk::PipelineStageFlags) {
    let mb = [vk::MemoryBarrier::default().src_access_mask(vk::AccessFlags::SHADER_WRITE).dst_access_mask(
        vk::AccessFlags::TRANSFER_READ | vk::AccessFlags::SHADER_READ | vk::AccessFlags::SHADER_WRITE,
    )];
    unsafe {
        gpu.device.cmd_pipeline_barrier(
            cmd,
            stage,
            vk::PipelineStageFlags::TRANSFER | stage,
            vk::DependencyFlags::empty(),
            &mb,
            &[],
            &[],
        );
    }
}

impl Drop for ComputePipeline<'_> {
    fn drop(&mut self) {
        if self.gpu.hung() {
            return;
        }
        destroy_parts(self.gpu, self.pool, self.pipeline, self.layout, self.dsl, &[self.module]);
    }
}

/// Destroys what a pipeline is made of, each object that was made (null ones are skipped):
/// the compute and the ray-tracing pipelines' one teardown.
pub(super) fn destroy_parts(
    gpu: &Gpu,
    pool: vk::DescriptorPool,
    pipeline: vk::Pipeline,
    layout: vk::PipelineLayout,
    dsl: vk::DescriptorSetLayout,
    modules: &[vk::ShaderModule],
) {
    let d = &gpu.device;
    unsafe {
        if pool != vk::DescriptorPool::null() {
            d.destroy_descriptor_pool(pool, None);
        }
        if pipeline != vk::Pipeline::null() {
            d.destroy_pipeline(pipeline, None);
        }
        if layout != vk::PipelineLayout::null() {
            d.destroy_pipeline_layout(layout, None);
        }
        if dsl != vk::DescriptorSetLayout::null() {
            d.destroy_descriptor_set_layout(dsl, None);
        }
        for &m in modules.iter().filter(|&&m| m != vk::ShaderModule::null()) {
            d.destroy_shader_module(m, None);
        }
    }
}
