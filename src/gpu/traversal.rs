//! Uploading an encoded BVH and dispatching traversal kernels.

use super::buffer::Buffer;
use super::pipeline::ComputePipeline;
use super::timer::Timer;
use super::{shader, Gpu, GpuError};
use crate::encode::Layout;
use crate::pipeline::Encoded;
use crate::rays::Ray;
use crate::trace::{Counters, Hit};
use crate::variant::{stack_entries, PacketImpl, Variant};
use ash::vk;
use gpu_allocator::MemoryLocation;

/// Push constants of every traversal kernel (64 bytes): ray count, node count, root frame
/// (w.xyz, k) — the f16h root frame, or unused for f32 — and the root box.
#[repr(C)]
#[derive(Clone, Copy, Debug, bytemuck::Pod, bytemuck::Zeroable)]
pub struct PushConstants {
    pub ray_count: u32,
    pub node_count: u32,
    pub _pad: [u32; 2],
    pub root_wk: [f32; 4],
    pub box_lo: [f32; 4],
    pub box_hi: [f32; 4],
}
const _: () = assert!(std::mem::size_of::<PushConstants>() == 64);

/// Descriptor bindings: 0 nodes, 1 triangle vertices, 2 triangle ids, 3 rays, 4 hits,
/// 5 counters (two uvec4 per ray: nodes, box tests, triangle tests, re-anchors; packet
/// nodes, active rays summed over them — in the first ray of a packet — and two zeros).
pub const BINDINGS: u32 = 6;

/// A BVH resident on the device.
pub struct GpuBvh<'g> {
    pub layout: Layout,
    pub branching: usize,
    nodes: Buffer<'g>,
    tris: Buffer<'g>,
    ids: Buffer<'g>,
    pub push: PushConstants,
    pub bytes: u64,
}

impl<'g> GpuBvh<'g> {
    pub fn upload(gpu: &'g Gpu, enc: &Encoded) -> Result<GpuBvh<'g>, GpuError> {
        let (layout, b, max_stack) = (enc.layout(), enc.branching(), enc.max_stack());
        if max_stack > stack_entries(b) {
            return Err(GpuError::Other(format!("BVH needs {max_stack} stack entries, more than the {} the B={b} kernels have", stack_entries(b))));
        }
        let (nodes, tris, push) = match enc {
            Encoded::F32(e) => (e.nodes.bytes(), &e.tris, PushConstants {
                ray_count: 0,
                node_count: e.nodes.len() as u32,
                _pad: [0; 2],
                root_wk: [0.0; 4],
                box_lo: [e.root_lo[0], e.root_lo[1], e.root_lo[2], 0.0],
                box_hi: [e.root_hi[0], e.root_hi[1], e.root_hi[2], 0.0],
            }),
            Encoded::F16h(e) => (e.nodes.bytes(), &e.tris, PushConstants {
                ray_count: 0,
                node_count: e.nodes.len() as u32,
                _pad: [0; 2],
                root_wk: [e.root.w[0], e.root.w[1], e.root.w[2], e.root.k],
                box_lo: [e.root.box_lo[0], e.root.box_lo[1], e.root.box_lo[2], 0.0],
                box_hi: [e.root.box_hi[0], e.root.box_hi[1], e.root.box_hi[2], 0.0],
            }),
        };
        let name = |s: &str| format!("{s} ({layout}, B={b})");
        let tv: &[u8] = bytemuck::cast_slice(&tris.verts);
        let ti: &[u8] = bytemuck::cast_slice(&tris.ids);
        Ok(GpuBvh {
            layout,
            branching: b,
            nodes: Buffer::upload(gpu, &name("nodes"), nodes)?,
            tris: Buffer::upload(gpu, &name("triangles"), tv)?,
            ids: Buffer::upload(gpu, &name("triangle ids"), ti)?,
            push,
            bytes: (nodes.len() + tv.len() + ti.len()) as u64,
        })
    }
}

/// A traversal kernel ready to dispatch.
pub struct Kernel<'g> {
    pub pipe: ComputePipeline<'g>,
    pub variant: Variant,
    pub imp: PacketImpl,
    pub stats: bool,
}

impl Kernel<'_> {
    pub fn name(&self) -> String {
        self.variant.kernel_name(self.imp, self.stats)
    }
}

/// The packet implementation this device uses for a variant (`force` overrides it).
pub fn choose_impl(gpu: &Gpu, v: &Variant, force: Option<PacketImpl>) -> PacketImpl {
    force.unwrap_or_else(|| PacketImpl::choose(v.packet, gpu.info.subgroup_size))
}

/// Compiles (or takes) the module of a variant and builds its pipeline.
pub fn pipeline<'g>(gpu: &'g Gpu, v: &Variant, imp: PacketImpl, stats: bool, spirv: Option<&[u32]>) -> Result<Kernel<'g>, GpuError> {
    if imp == PacketImpl::Subgroup && v.packet > gpu.info.subgroup_size as usize {
        return Err(GpuError::Other(format!("{}: packets of {} need a subgroup of at least {} (device: {})", v.kernel_name(imp, stats), v.packet, v.packet, gpu.info.subgroup_size)));
    }
    let code = match spirv {
        Some(c) => c.to_vec(),
        None => shader::compile(v, imp, stats, gpu.info.shader_float64)?,
    };
    let pipe = ComputePipeline::new(gpu, &v.kernel_name(imp, stats), &code, BINDINGS, std::mem::size_of::<PushConstants>() as u32)?;
    Ok(Kernel { pipe, variant: *v, imp, stats })
}

/// Hits (and counters, for a counting kernel) and the GPU time of each timed dispatch.
pub struct RunOutput {
    pub hits: Vec<Hit>,
    pub counters: Option<Vec<Counters>>,
    pub times_ms: Vec<f64>,
}

/// Dispatches `pipe` over `rays`: `warmup` untimed dispatches, then `repeat` timed ones
/// (at least one dispatch in all). With `stats`, reads back the per-ray counters.
pub fn run(gpu: &Gpu, bvh: &GpuBvh, kernel: &Kernel, rays: &[Ray], warmup: usize, repeat: usize) -> Result<RunOutput, GpuError> {
    let (pipe, stats) = (&kernel.pipe, kernel.stats);
    let wg = kernel.variant.workgroup(kernel.imp);
    let n = rays.len();
    let ray_buf = Buffer::upload(gpu, "rays", bytemuck::cast_slice(rays))?;
    let out_usage = vk::BufferUsageFlags::STORAGE_BUFFER | vk::BufferUsageFlags::TRANSFER_SRC;
    let hits = Buffer::new(gpu, "hits", (n * 16) as u64, out_usage, MemoryLocation::GpuOnly)?;
    let counters = Buffer::new(gpu, "counters", if stats { (n * 32) as u64 } else { 16 }, out_usage, MemoryLocation::GpuOnly)?;
    pipe.bind(&[&bvh.nodes, &bvh.tris, &bvh.ids, &ray_buf, &hits, &counters]);
    let mut push = bvh.push;
    push.ray_count = n as u32;
    let groups = (n as u32).div_ceil(wg);
    let timer = Timer::new(gpu)?;
    let mut times = Vec::with_capacity(repeat);
    for i in 0..(warmup + repeat).max(1) {
        gpu.submit_and_wait(|cmd| {
            timer.record(cmd, || pipe.dispatch(cmd, bytemuck::bytes_of(&push), groups));
            pipe.barrier(cmd);
        })?;
        if i >= warmup {
            times.push(timer.elapsed_ms()?);
        }
    }
    let hits: Vec<Hit> = bytemuck::pod_collect_to_vec(&hits.download(n * 16)?);
    if let Some(bad) = hits.iter().position(|h| h.prim == -2) {
        return Err(GpuError::Other(format!("{}: ray {bad} overflowed the traversal stack", kernel.name())));
    }
    let counters = if stats {
        let raw: Vec<[u32; 8]> = bytemuck::pod_collect_to_vec(&counters.download(n * 32)?);
        Some(raw.into_iter().map(|c| Counters { nodes: c[0], box_tests: c[1], tri_tests: c[2], reanchors: c[3], packet_nodes: c[4], active_lanes: c[5] }).collect())
    } else {
        None
    };
    Ok(RunOutput { hits, counters, times_ms: times })
}

