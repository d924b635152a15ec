//! A BVH resident on the device ([`GpuBvh`]): the layout's node bytes, the triangles and
//! their ids, uploaded once and read by every kernel of its layout and B.

use super::buffer::Buffer;
use super::{Gpu, GpuError};
use crate::interface::PushConstants;
use crate::layout::{Encoded, NodeArray, TriBuffer};
use crate::variant::{stack_entries, Buffers};
use ash::vk;
use gpu_allocator::MemoryLocation;

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
        let TriBuffer { verts, ids: host_ids, .. } = host_tris;
        let tris = plan.upload(gpu, "triangles", bytemuck::cast_slice(&verts))?;
        drop(verts);
        let ids = plan.upload(gpu, "triangle ids", bytemuck::cast_slice(&host_ids))?;
        drop(host_ids);
        plan.finish(gpu, nodes, tris, ids)
    }

    /// The buffers at the NODES, TRI_VERTS and TRI_IDS bindings.
    pub(crate) fn bindings(&self) -> [&Buffer<'g>; 3] {
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
            hit_pad: enc.tris.pad,
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
        let buffers = match sizes.iter().find(|(_, n)| *n > limit) {
            None => Buffers::Bound,
            Some(_) if gpu.info.buffer_device_address => Buffers::Addressed,
            Some((what, n)) => {
                return Err(GpuError::TooBig {
                    what: format!("{what} ({label})"),
                    bytes: *n,
                    limit,
                    limit_name: "maxStorageBufferRange",
                    hint: format!(
                        " for one storage buffer, and {} has no bufferDeviceAddress to read a larger buffer by address",
                        gpu.info.name
                    ),
                })
            }
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
    fn nodes<'g>(&self, gpu: &'g Gpu, nodes: &dyn NodeArray) -> Result<Buffer<'g>, GpuError> {
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
