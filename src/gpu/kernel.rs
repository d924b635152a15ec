//! A BVH resident on the device and the traversal kernels that run over it: building a
//! variant's pipeline (built-in, or a user's GLSL or SPIR-V module checked against the
//! variant's interface first) and dispatching it.

use super::buffer::Buffer;
use super::pipeline::ComputePipeline;
use super::timer::Timer;
use super::{shader, Gpu, GpuError};
use crate::interface::{binding, PushConstants, PRIM_OVERFLOW};
use crate::layout::Encoded;
use crate::rays::Ray;
use crate::trace::{Counters, Hit};
use crate::variant::{stack_entries, Buffers, PacketImpl, Variant};
use ash::vk;
use gpu_allocator::MemoryLocation;
use std::path::{Path, PathBuf};

/// A BVH resident on the device: the layout's node bytes, the triangles and the push
/// constants (ray count filled per dispatch). Bound as three storage buffers, or — when one
/// exceeds the device's `maxStorageBufferRange` — read by address ([`Buffers::Addressed`]):
/// then a table of the three buffers' addresses is bound in the nodes' place.
pub struct GpuBvh<'g> {
    nodes: Buffer<'g>,
    tris: Buffer<'g>,
    ids: Buffer<'g>,
    /// Addressed: the address table and a placeholder for the two unused bindings.
    table: Option<(Buffer<'g>, Buffer<'g>)>,
    /// How kernels must reach these buffers (build them with `Variant::with_buffers`).
    pub buffers: Buffers,
    pub push: PushConstants,
    /// Bytes uploaded (nodes and triangles).
    pub bytes: u64,
}

impl<'g> GpuBvh<'g> {
    /// Uploads an encoded BVH, bound where every buffer fits one storage-buffer binding and
    /// addressed otherwise (a clear error naming the limit where the device cannot address).
    pub fn upload(gpu: &'g Gpu, enc: &Encoded) -> Result<GpuBvh<'g>, GpuError> {
        let plan = UploadPlan::new(gpu, enc)?;
        let nodes = plan.nodes(gpu, &*enc.nodes)?;
        let tris = plan.upload(gpu, "triangles", bytemuck::cast_slice(&enc.tris.verts))?;
        let ids = plan.upload(gpu, "triangle ids", bytemuck::cast_slice(&enc.tris.ids))?;
        plan.finish(gpu, nodes, tris, ids)
    }

    /// [`Self::upload`], freeing each host array as soon as the device holds it, so a big
    /// scene's BVH is never held twice (on a CPU device, device memory is host memory too).
    pub fn upload_owned(gpu: &'g Gpu, enc: Encoded) -> Result<GpuBvh<'g>, GpuError> {
        let plan = UploadPlan::new(gpu, &enc)?;
        let Encoded { nodes: host_nodes, tris: host_tris, .. } = enc;
        let nodes = plan.nodes(gpu, &*host_nodes)?;
        drop(host_nodes);
        let crate::layout::TriBuffer { verts, ids: host_ids } = host_tris;
        let tris = plan.upload(gpu, "triangles", bytemuck::cast_slice(&verts))?;
        drop(verts);
        let ids = plan.upload(gpu, "triangle ids", bytemuck::cast_slice(&host_ids))?;
        drop(host_ids);
        plan.finish(gpu, nodes, tris, ids)
    }

    /// The buffers at the NODES, TRI_VERTS and TRI_IDS bindings.
    fn bindings(&self) -> [&Buffer<'g>; 3] {
        match &self.table {
            None => [&self.nodes, &self.tris, &self.ids],
            Some((t, unused)) => [t, unused, unused],
        }
    }
}

/// What an upload decided before any buffer is made: names, sizes, push constants and whether
/// the kernels read the buffers bound or by address.
struct UploadPlan {
    label: String,
    push: PushConstants,
    buffers: Buffers,
    node_size: u64,
    bytes: u64,
}

impl UploadPlan {
    fn new(gpu: &Gpu, enc: &Encoded) -> Result<UploadPlan, GpuError> {
        let (layout, b) = (enc.layout, enc.branching);
        if enc.max_stack > stack_entries(b) {
            return Err(GpuError::Other(format!(
                "BVH needs {} stack entries, more than the {} the B={b} kernels have",
                enc.max_stack,
                stack_entries(b)
            )));
        }
        let (lo, hi) = (enc.root_box.min, enc.root_box.max);
        let push = PushConstants {
            node_count: enc.node_count() as u32,
            root: enc.push_root,
            box_lo: [lo.x, lo.y, lo.z, 0.0],
            box_hi: [hi.x, hi.y, hi.z, 0.0],
            ..Default::default()
        };
        let label = format!("{layout}, B={b}");
        let node_size = enc.node_size() as u64;
        let node_bytes = enc.node_count() as u64 * node_size;
        let sizes = [
            ("nodes", node_bytes),
            ("triangles", std::mem::size_of_val(&enc.tris.verts[..]) as u64),
            ("triangle ids", std::mem::size_of_val(&enc.tris.ids[..]) as u64),
        ];
        let limit = gpu.info.max_storage_buffer;
        let buffers =
            match sizes.iter().find(|(_, n)| *n > limit) {
                None => Buffers::Bound,
                Some(_) if gpu.info.buffer_device_address => Buffers::Addressed,
                Some((what, n)) => return Err(GpuError::TooBig {
                    what: format!("{what} ({label})"),
                    bytes: *n,
                    limit,
                    limit_name: "maxStorageBufferRange",
                    hint: format!(
                        " for one storage buffer, and {} has no bufferDeviceAddress to read a larger buffer by address",
                        gpu.info.name
                    ),
                }),
            };
        Ok(UploadPlan { label, push, buffers, node_size, bytes: sizes.iter().map(|s| s.1).sum() })
    }

    fn usage(&self) -> vk::BufferUsageFlags {
        match self.buffers {
            Buffers::Bound => vk::BufferUsageFlags::STORAGE_BUFFER,
            Buffers::Addressed => vk::BufferUsageFlags::SHADER_DEVICE_ADDRESS,
        }
    }

    fn upload<'g>(&self, gpu: &'g Gpu, what: &str, data: &[u8]) -> Result<Buffer<'g>, GpuError> {
        Buffer::upload_with(gpu, &format!("{what} ({})", self.label), data, self.usage())
    }

    /// The node bytes, produced one staging chunk at a time: no second copy of the nodes.
    fn nodes<'g>(&self, gpu: &'g Gpu, nodes: &dyn crate::layout::NodeArray) -> Result<Buffer<'g>, GpuError> {
        let ns = self.node_size;
        Buffer::upload_from(
            gpu,
            &format!("nodes ({})", self.label),
            nodes.len() as u64 * ns,
            ns,
            self.usage(),
            |off, dst| {
                let first = (off / ns) as usize;
                dst.copy_from_slice(&nodes.bytes_of(first..first + dst.len() / ns as usize));
            },
        )
    }

    fn finish<'g>(
        self,
        gpu: &'g Gpu,
        nodes: Buffer<'g>,
        tris: Buffer<'g>,
        ids: Buffer<'g>,
    ) -> Result<GpuBvh<'g>, GpuError> {
        let table = match self.buffers {
            Buffers::Bound => None,
            Buffers::Addressed => {
                let addrs: [u64; 3] = [nodes.address(), tris.address(), ids.address()];
                let t = Buffer::upload(gpu, &format!("address table ({})", self.label), bytemuck::cast_slice(&addrs))?;
                let unused = Buffer::new(
                    gpu,
                    &format!("unused binding ({})", self.label),
                    16,
                    vk::BufferUsageFlags::STORAGE_BUFFER,
                    MemoryLocation::GpuOnly,
                )?;
                Some((t, unused))
            }
        };
        Ok(GpuBvh { nodes, tris, ids, table, buffers: self.buffers, push: self.push, bytes: self.bytes })
    }
}

/// Where a kernel's module comes from.
#[derive(Clone, Debug, PartialEq)]
pub enum Source {
    /// Compiled from `glsl/trav.comp` with the variant's layout hooks.
    Builtin,
    /// A user's GLSL compute file, compiled with the built-in kernel's defines and includes.
    Glsl(PathBuf),
    /// A user's SPIR-V module.
    Spirv(PathBuf),
}

impl Source {
    /// A user file: `.spv` is SPIR-V, anything else GLSL.
    pub fn user(path: &Path) -> Source {
        if path.extension().is_some_and(|e| e == "spv") {
            Source::Spirv(path.into())
        } else {
            Source::Glsl(path.into())
        }
    }

    pub fn is_user(&self) -> bool {
        *self != Source::Builtin
    }
}

/// A traversal kernel ready to dispatch.
pub struct Kernel<'g> {
    pub pipe: ComputePipeline<'g>,
    pub variant: Variant,
    pub imp: PacketImpl,
    pub stats: bool,
    pub source: Source,
    /// The subgroup size the pipeline is pinned to (`None`: the driver's).
    pub subgroup: Option<u32>,
}

impl<'g> Kernel<'g> {
    /// The built-in kernel's name (a user's module runs in its place under the same name).
    pub fn name(&self) -> String {
        self.variant.kernel_name(self.imp, self.stats)
    }

    /// The kernel's name, marked when the module is the user's.
    pub fn label(&self) -> String {
        match &self.source {
            Source::Builtin => self.name(),
            Source::Glsl(p) | Source::Spirv(p) => format!("{} (user kernel {})", self.name(), p.display()),
        }
    }

    /// Builds the pipeline of a variant from `source`. A user's module is checked against the
    /// variant's interface (entry point, workgroup, bindings, push constants, specialization
    /// constants, capabilities) before any pipeline is created.
    pub fn build(
        gpu: &'g Gpu,
        v: &Variant,
        imp: PacketImpl,
        stats: bool,
        source: &Source,
    ) -> Result<Kernel<'g>, GpuError> {
        super::support::check(&gpu.info, v).map_err(GpuError::Unsupported)?;
        let pin = subgroup_pin(gpu, v, imp, stats)?;
        let f64 = gpu.info.shader_float64;
        let code = match source {
            Source::Builtin => shader::compile(v, imp, stats, f64)?,
            Source::Glsl(p) => {
                shader::check_user(p, &shader::compile_user(p, v, imp, stats, f64)?, v, imp, stats, gpu)?
            }
            Source::Spirv(p) => {
                // The interface first (its messages say what a kernel must look like), then the
                // SPIRV-Tools validator (its message instead of a driver's "unknown error").
                let words = shader::check_user(p, &shader::read_spirv(p)?, v, imp, stats, gpu)?;
                shader::validate_user(p, &words)?;
                words
            }
        };
        Self::with_code(gpu, v, imp, stats, source, &code, pin)
    }

    fn with_code(
        gpu: &'g Gpu,
        v: &Variant,
        imp: PacketImpl,
        stats: bool,
        source: &Source,
        code: &[u32],
        pin: Option<u32>,
    ) -> Result<Kernel<'g>, GpuError> {
        let pipe = ComputePipeline::with_subgroup(
            gpu,
            &v.kernel_name(imp, stats),
            code,
            binding::COUNT,
            std::mem::size_of::<PushConstants>() as u32,
            pin,
        )?;
        Ok(Kernel { pipe, variant: *v, imp, stats, source: source.clone(), subgroup: pin })
    }

    /// The counting kernel of a user's module: its GLSL compiled with `STATS`, when that build
    /// writes counters; `None` for a SPIR-V module or a kernel that does not count.
    pub fn user_counting(
        gpu: &'g Gpu,
        v: &Variant,
        imp: PacketImpl,
        source: &Source,
    ) -> Result<Option<Kernel<'g>>, GpuError> {
        let Source::Glsl(p) = source else { return Ok(None) };
        let code = shader::compile_user(p, v, imp, true, gpu.info.shader_float64)?;
        let itf =
            shader::parse_interface(&code).map_err(|msg| GpuError::Spirv { path: p.display().to_string(), msg })?;
        if !itf.bindings.contains(&(0, binding::COUNTERS)) {
            return Ok(None);
        }
        let code = shader::check_user(p, &code, v, imp, true, gpu)?;
        Self::with_code(gpu, v, imp, true, source, &code, subgroup_pin(gpu, v, imp, true)?).map(Some)
    }

    /// Dispatches the kernel over `rays`: `warmup` untimed dispatches, then `repeat` timed
    /// ones (at least one dispatch in all). A counting kernel also reads back the counters.
    pub fn run(
        &self,
        gpu: &Gpu,
        bvh: &GpuBvh,
        rays: &[Ray],
        warmup: usize,
        repeat: usize,
    ) -> Result<RunOutput, GpuError> {
        if self.variant.buffers != bvh.buffers {
            return Err(GpuError::Other(format!(
                "{}: built for {:?} scene buffers, but this BVH is {:?} (build the kernel with `Variant::with_buffers(bvh.buffers)`)",
                self.label(),
                self.variant.buffers,
                bvh.buffers
            )));
        }
        let pipe = &self.pipe;
        let wg = self.variant.workgroup(self.imp);
        let n = rays.len();
        let ray_buf = Buffer::upload(gpu, "rays", bytemuck::cast_slice(rays))?;
        let out_usage = vk::BufferUsageFlags::STORAGE_BUFFER | vk::BufferUsageFlags::TRANSFER_SRC;
        let hit_bytes = n * std::mem::size_of::<Hit>();
        let counter_bytes = n * std::mem::size_of::<Counters>();
        let hits = Buffer::new(gpu, "hits", hit_bytes as u64, out_usage, MemoryLocation::GpuOnly)?;
        let counters = Buffer::new(
            gpu,
            "counters",
            if self.stats { counter_bytes as u64 } else { 16 },
            out_usage,
            MemoryLocation::GpuOnly,
        )?;
        let [b0, b1, b2] = bvh.bindings();
        pipe.bind(&[b0, b1, b2, &ray_buf, &hits, &counters]);
        let mut push = bvh.push;
        push.ray_count = n as u32;
        let times = dispatch_timed(gpu, pipe, bytemuck::bytes_of(&push), (n as u32).div_ceil(wg), warmup, repeat)?;
        let hits: Vec<Hit> = bytemuck::pod_collect_to_vec(&hits.download(hit_bytes)?);
        if let Some(bad) = hits.iter().position(|h| h.prim == PRIM_OVERFLOW) {
            return Err(GpuError::Other(match &self.source {
                Source::Builtin => format!("{}: ray {bad} overflowed the traversal stack", self.name()),
                Source::Glsl(p) | Source::Spirv(p) => format!(
                    "the user's kernel {} (in place of {}): ray {bad} overflowed its traversal stack — was it built for another branching factor or layout than B = {}?",
                    p.display(),
                    self.name(),
                    self.variant.branching
                ),
            }));
        }
        let counters: Option<Vec<Counters>> =
            if self.stats { Some(bytemuck::pod_collect_to_vec(&counters.download(counter_bytes)?)) } else { None };
        crate::digest::record("gpu", &self.label(), rays, &hits, counters.as_deref());
        Ok(RunOutput { hits, counters, times_ms: times })
    }
}

/// Records `warmup + repeat` (at least one) dispatches of `groups` workgroups, each in its own
/// submission with timestamps around it; returns the times of the last `repeat`.
pub(crate) fn dispatch_timed(
    gpu: &Gpu,
    pipe: &ComputePipeline,
    push: &[u8],
    groups: u32,
    warmup: usize,
    repeat: usize,
) -> Result<Vec<f64>, GpuError> {
    let timer = Timer::new(gpu)?;
    let mut times = Vec::with_capacity(repeat);
    for i in 0..(warmup + repeat).max(1) {
        gpu.submit_and_wait(|cmd| {
            timer.record(cmd, || pipe.dispatch(cmd, push, groups));
            pipe.barrier(cmd);
        })?;
        if i >= warmup {
            times.push(timer.elapsed_ms()?);
        }
    }
    Ok(times)
}

/// Hits (and counters, for a counting kernel) and the GPU time of each timed dispatch.
pub struct RunOutput {
    pub hits: Vec<Hit>,
    pub counters: Option<Vec<Counters>>,
    pub times_ms: Vec<f64>,
}

/// The subgroup size a kernel's pipeline is pinned to: for the subgroup packet implementation,
/// the size planned for its P where the device allows pinning; otherwise none, and then the
/// reported size must hold the packet.
fn subgroup_pin(gpu: &Gpu, v: &Variant, imp: PacketImpl, stats: bool) -> Result<Option<u32>, GpuError> {
    if imp == PacketImpl::Hybrid && !super::support::has_subgroup_arithmetic(&gpu.info) {
        return Err(GpuError::Unsupported(format!(
            "{}: hybrid packets need subgroup arithmetic in compute shaders (device: {})",
            v.kernel_name(imp, stats),
            gpu.info.name
        )));
    }
    if imp != PacketImpl::Subgroup {
        return Ok(None);
    }
    let pin = super::support::packet_plan(&gpu.info, v.packet).1;
    if pin.is_none() && v.packet > gpu.info.subgroup_size as usize {
        return Err(GpuError::Unsupported(format!(
            "{}: packets of {} need a subgroup of at least {} (device: {})",
            v.kernel_name(imp, stats),
            v.packet,
            v.packet,
            gpu.info.subgroup_size
        )));
    }
    Ok(pin)
}

/// The packet implementation this device uses for a variant (`force` overrides it).
pub fn choose_impl(gpu: &Gpu, v: &Variant, force: Option<PacketImpl>) -> PacketImpl {
    force.unwrap_or_else(|| super::support::packet_plan(&gpu.info, v.packet).0)
}
