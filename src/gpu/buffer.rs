//! Named storage buffers allocated through gpu-allocator; freed on drop.

use super::{Gpu, GpuError, VkResultExt};
use ash::vk;
use gpu_allocator::vulkan::{Allocation, AllocationCreateDesc, AllocationScheme};
use gpu_allocator::MemoryLocation;

/// The most bytes an upload stages at once (bounds the host memory an upload adds).
pub const STAGING_CHUNK: u64 = 64 << 20;

pub struct Buffer<'g> {
    gpu: &'g Gpu,
    pub raw: vk::Buffer,
    alloc: Option<Allocation>,
    pub size: u64,
    pub name: String,
}

impl<'g> Buffer<'g> {
    /// Creates a buffer of `size` bytes (at least 16) in `location`. A storage buffer larger
    /// than `maxStorageBufferRange`, or any buffer larger than `maxMemoryAllocationSize`, is
    /// refused with the limit named (rather than left to the driver).
    pub fn new(
        gpu: &'g Gpu,
        name: &str,
        size: u64,
        usage: vk::BufferUsageFlags,
        location: MemoryLocation,
    ) -> Result<Buffer<'g>, GpuError> {
        Buffer::new_aligned(gpu, name, size, usage, location, 16)
    }

    /// [`Buffer::new`] whose start (and so device address) is a multiple of `align` bytes, a
    /// power of two (at least 16).
    fn new_aligned(
        gpu: &'g Gpu,
        name: &str,
        size: u64,
        usage: vk::BufferUsageFlags,
        location: MemoryLocation,
        align: u64,
    ) -> Result<Buffer<'g>, GpuError> {
        let size = size.max(16);
        if usage.contains(vk::BufferUsageFlags::STORAGE_BUFFER) && size > gpu.info.max_storage_buffer {
            return Err(GpuError::TooBig {
                what: name.into(),
                bytes: size,
                limit: gpu.info.max_storage_buffer,
                limit_name: "maxStorageBufferRange",
                hint: String::new(),
            });
        }
        if size > gpu.info.max_allocation {
            return Err(GpuError::TooBig {
                what: name.into(),
                bytes: size,
                limit: gpu.info.max_allocation,
                limit_name: "maxMemoryAllocationSize",
                hint: String::new(),
            });
        }
        let d = &gpu.device;
        let raw = unsafe {
            d.create_buffer(
                &vk::BufferCreateInfo::default().size(size).usage(usage).sharing_mode(vk::SharingMode::EXCLUSIVE),
                None,
            )
        }
        .vk("vkCreateBuffer")?;
        let mut req = unsafe { d.get_buffer_memory_requirements(raw) };
        // Kernels that read a buffer by address assume 16-byte alignment (buffer_reference_align).
        req.alignment = req.alignment.max(align.max(16));
        let alloc = gpu.allocator().lock().unwrap().allocate(&AllocationCreateDesc {
            name,
            requirements: req,
            location,
            linear: true,
            allocation_scheme: AllocationScheme::GpuAllocatorManaged,
        });
        let alloc = match alloc {
            Ok(a) => a,
            Err(source) => {
                unsafe { d.destroy_buffer(raw, None) };
                return Err(GpuError::Alloc { what: name.into(), bytes: size, source });
            }
        };
        if let Err(e) = unsafe { d.bind_buffer_memory(raw, alloc.memory(), alloc.offset()) }.vk("vkBindBufferMemory") {
            let _ = gpu.allocator().lock().unwrap().free(alloc);
            unsafe { d.destroy_buffer(raw, None) };
            return Err(e);
        }
        Ok(Buffer { gpu, raw, alloc: Some(alloc), size, name: name.into() })
    }

    /// A device-local storage buffer filled with `data` through a staging copy.
    pub fn upload(gpu: &'g Gpu, name: &str, data: &[u8]) -> Result<Buffer<'g>, GpuError> {
        Buffer::upload_with(gpu, name, data, vk::BufferUsageFlags::STORAGE_BUFFER)
    }

    /// The buffer's device address (needs SHADER_DEVICE_ADDRESS usage).
    pub fn address(&self) -> vk::DeviceAddress {
        unsafe { self.gpu.device.get_buffer_device_address(&vk::BufferDeviceAddressInfo::default().buffer(self.raw)) }
    }

    /// A device-local buffer with `usage` (plus transfer destination) filled through a staging copy.
    pub fn upload_with(
        gpu: &'g Gpu,
        name: &str,
        data: &[u8],
        usage: vk::BufferUsageFlags,
    ) -> Result<Buffer<'g>, GpuError> {
        Buffer::upload_from(gpu, name, data.len() as u64, 1, usage, |off, dst| {
            dst.copy_from_slice(&data[off as usize..off as usize + dst.len()])
        })
    }

    /// A device-local buffer of `len` bytes with `usage` (plus transfer destination), filled
    /// through a staging buffer of at most [`STAGING_CHUNK`] bytes: `fill(offset, dst)` writes
    /// the bytes at `offset`, `dst.len()` of them, a multiple of `granule` (e.g. a node's size)
    /// unless it is the end. The host never holds a second full copy of the data.
    pub fn upload_from(
        gpu: &'g Gpu,
        name: &str,
        len: u64,
        granule: u64,
        usage: vk::BufferUsageFlags,
        mut fill: impl FnMut(u64, &mut [u8]),
    ) -> Result<Buffer<'g>, GpuError> {
        let dst = Buffer::new(gpu, name, len, usage | vk::BufferUsageFlags::TRANSFER_DST, MemoryLocation::GpuOnly)?;
        if len == 0 {
            return Ok(dst);
        }
        let granule = granule.max(1);
        let chunk = (STAGING_CHUNK / granule).max(1) * granule;
        let mut staging = Buffer::new(
            gpu,
            &format!("{name} (staging)"),
            chunk.min(len),
            vk::BufferUsageFlags::TRANSFER_SRC,
            MemoryLocation::CpuToGpu,
        )?;
        let mut off = 0u64;
        while off < len {
            let n = chunk.min(len - off);
            fill(off, &mut staging.mapped_mut()?[..n as usize]);
            gpu.submit_and_wait(|cmd| unsafe {
                gpu.device.cmd_copy_buffer(
                    cmd,
                    staging.raw,
                    dst.raw,
                    &[vk::BufferCopy { src_offset: 0, dst_offset: off, size: n }],
                )
            })?;
            off += n;
        }
        Ok(dst)
    }

    /// A host-visible buffer with `usage` holding `data`, its start a multiple of `align` bytes
    /// (a power of two): small tables the device reads by address at an alignment of its own,
    /// such as a shader binding table.
    pub fn host_aligned(
        gpu: &'g Gpu,
        name: &str,
        data: &[u8],
        usage: vk::BufferUsageFlags,
        align: u64,
    ) -> Result<Buffer<'g>, GpuError> {
        let mut b = Buffer::new_aligned(gpu, name, data.len() as u64, usage, MemoryLocation::CpuToGpu, align)?;
        b.mapped_mut()?[..data.len()].copy_from_slice(data);
        Ok(b)
    }

    /// The bytes of a host-visible buffer, writable.
    fn mapped_mut(&mut self) -> Result<&mut [u8], GpuError> {
        let name = &self.name;
        self.alloc
            .as_mut()
            .and_then(|a| a.mapped_slice_mut())
            .ok_or_else(|| GpuError::Other(format!("buffer {name} is not host-visible")))
    }

    /// Reads bytes from a host-visible buffer.
    pub fn read(&self, len: usize) -> Result<Vec<u8>, GpuError> {
        let m = self
            .alloc
            .as_ref()
            .and_then(|a| a.mapped_slice())
            .ok_or_else(|| GpuError::Other(format!("buffer {} is not host-visible", self.name)))?;
        Ok(m[..len].to_vec())
    }

    /// Copies `len` bytes of a device buffer back to the host.
    pub fn download(&self, len: usize) -> Result<Vec<u8>, GpuError> {
        if len == 0 {
            return Ok(Vec::new());
        }
        let rb = Buffer::new(
            self.gpu,
            &format!("{} (readback)", self.name),
            len as u64,
            vk::BufferUsageFlags::TRANSFER_DST,
            MemoryLocation::GpuToCpu,
        )?;
        let (src, dst) = (self.raw, rb.raw);
        self.gpu.submit_and_wait(|cmd| unsafe {
            self.gpu.device.cmd_copy_buffer(
                cmd,
                src,
                dst,
                &[vk::BufferCopy { src_offset: 0, dst_offset: 0, size: len as u64 }],
            )
        })?;
        rb.read(len)
    }
}

impl Drop for Buffer<'_> {
    fn drop(&mut self) {
        if self.gpu.hung() {
            return;
        }
        unsafe { self.gpu.device.destroy_buffer(self.raw, None) };
        if let Some(a) = self.alloc.take() {
            let _ = self.gpu.allocator().lock().map(|mut al| al.free(a));
        }
    }
}
