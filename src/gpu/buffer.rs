//! Named storage buffers allocated through gpu-allocator; freed on drop.

use super::{Gpu, GpuError, VkResultExt};
use ash::vk;
use gpu_allocator::vulkan::{Allocation, AllocationCreateDesc, AllocationScheme};
use gpu_allocator::MemoryLocation;

pub struct Buffer<'g> {
    gpu: &'g Gpu,
    pub raw: vk::Buffer,
    alloc: Option<Allocation>,
    pub size: u64,
    pub name: String,
}

impl<'g> Buffer<'g> {
    /// Creates a buffer of `size` bytes (at least 16) in `location`.
    pub fn new(gpu: &'g Gpu, name: &str, size: u64, usage: vk::BufferUsageFlags, location: MemoryLocation) -> Result<Buffer<'g>, GpuError> {
        let size = size.max(16);
        if usage.contains(vk::BufferUsageFlags::STORAGE_BUFFER) && size > gpu.info.max_storage_buffer {
            return Err(GpuError::TooBig { what: name.into(), bytes: size, limit: gpu.info.max_storage_buffer });
        }
        let d = &gpu.device;
        let raw = unsafe { d.create_buffer(&vk::BufferCreateInfo::default().size(size).usage(usage).sharing_mode(vk::SharingMode::EXCLUSIVE), None) }.vk("vkCreateBuffer")?;
        let req = unsafe { d.get_buffer_memory_requirements(raw) };
        let alloc = gpu.allocator.lock().unwrap().allocate(&AllocationCreateDesc { name, requirements: req, location, linear: true, allocation_scheme: AllocationScheme::GpuAllocatorManaged });
        let alloc = match alloc {
            Ok(a) => a,
            Err(source) => {
                unsafe { d.destroy_buffer(raw, None) };
                return Err(GpuError::Alloc { what: name.into(), bytes: size, source });
            }
        };
        if let Err(e) = unsafe { d.bind_buffer_memory(raw, alloc.memory(), alloc.offset()) }.vk("vkBindBufferMemory") {
            let _ = gpu.allocator.lock().unwrap().free(alloc);
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
    pub fn upload_with(gpu: &'g Gpu, name: &str, data: &[u8], usage: vk::BufferUsageFlags) -> Result<Buffer<'g>, GpuError> {
        let dst = Buffer::new(gpu, name, data.len() as u64, usage | vk::BufferUsageFlags::TRANSFER_DST, MemoryLocation::GpuOnly)?;
        if data.is_empty() {
            return Ok(dst);
        }
        let mut staging = Buffer::new(gpu, &format!("{name} (staging)"), data.len() as u64, vk::BufferUsageFlags::TRANSFER_SRC, MemoryLocation::CpuToGpu)?;
        staging.write(data)?;
        let n = data.len() as u64;
        gpu.submit_and_wait(|cmd| unsafe { gpu.device.cmd_copy_buffer(cmd, staging.raw, dst.raw, &[vk::BufferCopy { src_offset: 0, dst_offset: 0, size: n }]) })?;
        Ok(dst)
    }

    /// Copies bytes into a host-visible buffer.
    pub fn write(&mut self, data: &[u8]) -> Result<(), GpuError> {
        let name = self.name.clone();
        let m = self.alloc.as_mut().and_then(|a| a.mapped_slice_mut()).ok_or_else(|| GpuError::Other(format!("buffer {name} is not host-visible")))?;
        m[..data.len()].copy_from_slice(data);
        Ok(())
    }

    /// Reads bytes from a host-visible buffer.
    pub fn read(&self, len: usize) -> Result<Vec<u8>, GpuError> {
        let m = self.alloc.as_ref().and_then(|a| a.mapped_slice()).ok_or_else(|| GpuError::Other(format!("buffer {} is not host-visible", self.name)))?;
        Ok(m[..len].to_vec())
    }

    /// Copies `len` bytes of a device buffer back to the host.
    pub fn download(&self, len: usize) -> Result<Vec<u8>, GpuError> {
        if len == 0 {
            return Ok(Vec::new());
        }
        let rb = Buffer::new(self.gpu, &format!("{} (readback)", self.name), len as u64, vk::BufferUsageFlags::TRANSFER_DST, MemoryLocation::GpuToCpu)?;
        let (src, dst) = (self.raw, rb.raw);
        self.gpu.submit_and_wait(|cmd| unsafe { self.gpu.device.cmd_copy_buffer(cmd, src, dst, &[vk::BufferCopy { src_offset: 0, dst_offset: 0, size: len as u64 }]) })?;
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
            let _ = self.gpu.allocator.lock().map(|mut al| al.free(a));
        }
    }
}
