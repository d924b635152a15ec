//! The driver's own acceleration structures (VK_KHR_acceleration_structure, prefer fast
//! trace) and the ray-query kernel that traces them (`rayQueryEXT`): the Vulkan side of the
//! `rq` baseline; the `rt` baseline traces the same structures with a ray-tracing pipeline
//! ([`super::rt`]). The BLAS holds the scene's triangles in `prim` order, non-indexed, so the
//! primitive index the query reports is the public `prim` id; one TLAS instance with the
//! identity transform.

use super::buffer::Buffer;
use super::kernel::dispatch_timed;
use super::pipeline::ComputePipeline;
use super::{shader, Gpu, GpuError, VkResultExt};
use crate::base::{Hit, Ray, RunOutput};
use crate::interface::{binding, PushConstants};
use crate::scene::Scene;
use ash::vk;
use gpu_allocator::MemoryLocation;

/// A scene's driver-built acceleration structures.
pub struct AccelScene<'g> {
    gpu: &'g Gpu,
    loader: ash::khr::acceleration_structure::Device,
    blas: vk::AccelerationStructureKHR,
    pub(super) tlas: vk::AccelerationStructureKHR,
    _bufs: Vec<Buffer<'g>>,
    /// BLAS + TLAS bytes, from the driver's size query.
    pub bytes: u64,
    /// Wall time of the two builds on the device (submit to completion), ms.
    pub build_ms: f64,
}

fn aligned(b: &Buffer, align: u64) -> vk::DeviceAddress {
    b.address().div_ceil(align) * align
}

impl<'g> AccelScene<'g> {
    pub fn build(gpu: &'g Gpu, scene: &Scene) -> Result<AccelScene<'g>, GpuError> {
        if !gpu.info.ray_query && !gpu.info.ray_tracing_pipeline {
            return Err(GpuError::MissingFeature {
                device: gpu.info.name.clone(),
                feature: "VK_KHR_acceleration_structure with ray queries or a ray-tracing pipeline to trace it".into(),
            });
        }
        let loader = ash::khr::acceleration_structure::Device::new(&gpu.instance, &gpu.device);
        let mut rq = AccelScene {
            gpu,
            loader,
            blas: vk::AccelerationStructureKHR::null(),
            tlas: vk::AccelerationStructureKHR::null(),
            _bufs: Vec::new(),
            bytes: 0,
            build_ms: 0.0,
        };
        let mut props = vk::PhysicalDeviceAccelerationStructurePropertiesKHR::default();
        let align = {
            let mut p2 = vk::PhysicalDeviceProperties2::default().push_next(&mut props);
            unsafe { gpu.instance.get_physical_device_properties2(gpu.physical, &mut p2) };
            props.min_acceleration_structure_scratch_offset_alignment.max(256) as u64
        };
        let input = vk::BufferUsageFlags::ACCELERATION_STRUCTURE_BUILD_INPUT_READ_ONLY_KHR
            | vk::BufferUsageFlags::SHADER_DEVICE_ADDRESS;
        let verts: Vec<f32> = scene.tris.iter().flat_map(|t| t.iter().flat_map(|v| [v.x, v.y, v.z])).collect();
        let vbuf = Buffer::upload_with(gpu, "accel vertices", bytemuck::cast_slice(&verts), input)?;
        let n = scene.tris.len() as u32;
        let tri = vk::AccelerationStructureGeometryTrianglesDataKHR::default()
            .vertex_format(vk::Format::R32G32B32_SFLOAT)
            .vertex_data(vk::DeviceOrHostAddressConstKHR { device_address: vbuf.address() })
            .vertex_stride(12)
            .max_vertex(3 * n - 1)
            .index_type(vk::IndexType::NONE_KHR);
        let geom = [vk::AccelerationStructureGeometryKHR::default()
            .geometry_type(vk::GeometryTypeKHR::TRIANGLES)
            .geometry(vk::AccelerationStructureGeometryDataKHR { triangles: tri })
            .flags(vk::GeometryFlagsKHR::OPAQUE)];
        let (blas, blas_size, t_blas) =
            rq.build_one(vk::AccelerationStructureTypeKHR::BOTTOM_LEVEL, &geom, n, align, "blas")?;
        rq.blas = blas;
        let blas_addr = unsafe {
            rq.loader.get_acceleration_structure_device_address(
                &vk::AccelerationStructureDeviceAddressInfoKHR::default().acceleration_structure(blas),
            )
        };
        let inst = vk::AccelerationStructureInstanceKHR {
            transform: vk::TransformMatrixKHR { matrix: [1.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0] },
            instance_custom_index_and_mask: vk::Packed24_8::new(0, 0xff),
            instance_shader_binding_table_record_offset_and_flags: vk::Packed24_8::new(
                0,
                vk::GeometryInstanceFlagsKHR::TRIANGLE_FACING_CULL_DISABLE.as_raw() as u8,
            ),
            acceleration_structure_reference: vk::AccelerationStructureReferenceKHR { device_handle: blas_addr },
        };
        let inst_bytes = unsafe {
            std::slice::from_raw_parts(
                &inst as *const _ as *const u8,
                std::mem::size_of::<vk::AccelerationStructureInstanceKHR>(),
            )
        };
        let ibuf = Buffer::upload_with(gpu, "accel instance", inst_bytes, input)?;
        let inst_data = vk::AccelerationStructureGeometryInstancesDataKHR::default()
            .array_of_pointers(false)
            .data(vk::DeviceOrHostAddressConstKHR { device_address: ibuf.address() });
        let geom = [vk::AccelerationStructureGeometryKHR::default()
            .geometry_type(vk::GeometryTypeKHR::INSTANCES)
            .geometry(vk::AccelerationStructureGeometryDataKHR { instances: inst_data })
            .flags(vk::GeometryFlagsKHR::OPAQUE)];
        let (tlas, tlas_size, t_tlas) =
            rq.build_one(vk::AccelerationStructureTypeKHR::TOP_LEVEL, &geom, 1, align, "tlas")?;
        rq.tlas = tlas;
        rq.bytes = blas_size + tlas_size;
        rq.build_ms = t_blas + t_tlas;
        rq._bufs.push(vbuf);
        rq._bufs.push(ibuf);
        Ok(rq)
    }

    /// Creates and builds one acceleration structure; returns it, its size and build time (ms).
    fn build_one(
        &mut self,
        ty: vk::AccelerationStructureTypeKHR,
        geom: &[vk::AccelerationStructureGeometryKHR],
        count: u32,
        align: u64,
        name: &str,
    ) -> Result<(vk::AccelerationStructureKHR, u64, f64), GpuError> {
        let gpu = self.gpu;
        let mut info = vk::AccelerationStructureBuildGeometryInfoKHR::default()
            .ty(ty)
            .flags(vk::BuildAccelerationStructureFlagsKHR::PREFER_FAST_TRACE)
            .mode(vk::BuildAccelerationStructureModeKHR::BUILD)
            .geometries(geom);
        let mut sizes = vk::AccelerationStructureBuildSizesInfoKHR::default();
        unsafe {
            self.loader.get_acceleration_structure_build_sizes(
                vk::AccelerationStructureBuildTypeKHR::DEVICE,
                &info,
                &[count],
                &mut sizes,
            )
        };
        let storage = Buffer::new(
            gpu,
            &format!("accel {name}"),
            sizes.acceleration_structure_size,
            vk::BufferUsageFlags::ACCELERATION_STRUCTURE_STORAGE_KHR | vk::BufferUsageFlags::SHADER_DEVICE_ADDRESS,
            MemoryLocation::GpuOnly,
        )?;
        let ci = vk::AccelerationStructureCreateInfoKHR::default()
            .buffer(storage.raw)
            .size(sizes.acceleration_structure_size)
            .ty(ty);
        let handle =
            unsafe { self.loader.create_acceleration_structure(&ci, None) }.vk("vkCreateAccelerationStructureKHR")?;
        self._bufs.push(storage);
        let scratch = Buffer::new(
            gpu,
            &format!("accel {name} scratch"),
            sizes.build_scratch_size + align,
            vk::BufferUsageFlags::STORAGE_BUFFER | vk::BufferUsageFlags::SHADER_DEVICE_ADDRESS,
            MemoryLocation::GpuOnly,
        );
        let scratch = match scratch {
            Ok(s) => s,
            Err(e) => {
                unsafe { self.loader.destroy_acceleration_structure(handle, None) };
                return Err(e);
            }
        };
        info = info
            .dst_acceleration_structure(handle)
            .scratch_data(vk::DeviceOrHostAddressKHR { device_address: aligned(&scratch, align) });
        let range = [vk::AccelerationStructureBuildRangeInfoKHR::default().primitive_count(count)];
        let t0 = std::time::Instant::now();
        let r = gpu.submit_and_wait(|cmd| unsafe {
            self.loader.cmd_build_acceleration_structures(cmd, std::slice::from_ref(&info), &[&range]);
            let mb = [vk::MemoryBarrier::default()
                .src_access_mask(vk::AccessFlags::ACCELERATION_STRUCTURE_WRITE_KHR)
                .dst_access_mask(vk::AccessFlags::ACCELERATION_STRUCTURE_READ_KHR)];
            // The readers: the TLAS build, ray queries, and ray-tracing shaders (a stage that
            // exists only where the feature was enabled).
            let mut readers =
                vk::PipelineStageFlags::ACCELERATION_STRUCTURE_BUILD_KHR | vk::PipelineStageFlags::COMPUTE_SHADER;
            if gpu.info.ray_tracing_pipeline {
                readers |= vk::PipelineStageFlags::RAY_TRACING_SHADER_KHR;
            }
            gpu.device.cmd_pipeline_barrier(
                cmd,
                vk::PipelineStageFlags::ACCELERATION_STRUCTURE_BUILD_KHR,
                readers,
                vk::DependencyFlags::empty(),
                &mb,
                &[],
                &[],
            );
        });
        let ms = t0.elapsed().as_secs_f64() * 1e3;
        if let Err(e) = r {
            // A hung build may still write into it: then it is left to the process's end.
            if !gpu.hung() {
                unsafe { self.loader.destroy_acceleration_structure(handle, None) };
            }
            return Err(e);
        }
        Ok((handle, sizes.acceleration_structure_size, ms))
    }
}

impl Drop for AccelScene<'_> {
    fn drop(&mut self) {
        if self.gpu.hung() {
            return;
        }
        unsafe {
            let _ = self.gpu.device.device_wait_idle();
            if self.tlas != vk::AccelerationStructureKHR::null() {
                self.loader.destroy_acceleration_structure(self.tlas, None);
            }
            if self.blas != vk::AccelerationStructureKHR::null() {
                self.loader.destroy_acceleration_structure(self.blas, None);
            }
        }
    }
}

/// Kernel name of the ray-query traversal.
pub const KERNEL: &str = "trav_rq";

/// The ray-query kernel's pipeline: binding 0 is the TLAS, 3 rays, 4 hits.
pub fn pipeline(gpu: &Gpu) -> Result<ComputePipeline<'_>, GpuError> {
    let code = shader::compile_plain(KERNEL, "trav_rq.comp", &[])?;
    let mut types = vec![vk::DescriptorType::STORAGE_BUFFER; binding::COUNT as usize];
    types[binding::NODES as usize] = vk::DescriptorType::ACCELERATION_STRUCTURE_KHR;
    ComputePipeline::new_typed(gpu, KERNEL, &code, &types, std::mem::size_of::<PushConstants>() as u32, None)
}

/// Traces `rays` with ray queries: `warmup` untimed, `repeat` timed dispatches.
pub fn run(
    gpu: &Gpu,
    scene: &AccelScene,
    pipe: &ComputePipeline,
    rays: &[Ray],
    warmup: usize,
    repeat: usize,
) -> Result<RunOutput, GpuError> {
    let n = rays.len();
    let ray_buf = Buffer::upload(gpu, "rays", bytemuck::cast_slice(rays))?;
    let usage = vk::BufferUsageFlags::STORAGE_BUFFER | vk::BufferUsageFlags::TRANSFER_SRC;
    let hit_bytes = n * std::mem::size_of::<Hit>();
    let hits = Buffer::new(gpu, "hits", hit_bytes as u64, usage, MemoryLocation::GpuOnly)?;
    let unused = Buffer::new(gpu, "unused", 16, usage, MemoryLocation::GpuOnly)?;
    pipe.bind_acceleration_structure(binding::NODES, scene.tlas);
    pipe.bind_at(&[
        (binding::TRI_VERTS, &unused),
        (binding::TRI_IDS, &unused),
        (binding::RAYS, &ray_buf),
        (binding::HITS, &hits),
        (binding::COUNTERS, &unused),
    ]);
    let push = PushConstants { ray_count: n as u32, ..Default::default() };
    let times = dispatch_timed(gpu, pipe, bytemuck::bytes_of(&push), (n as u32).div_ceil(64), warmup, repeat)?;
    let hits: Vec<Hit> = bytemuck::pod_collect_to_vec(&hits.download(hit_bytes)?);
    crate::digest::record("baseline", KERNEL, rays, &hits, None);
    Ok(RunOutput { hits, counters: None, times_ms: times, flagged: 0 })
}
