//! A traversal kernel ready to dispatch ([`Kernel`]): built for one [`KernelId`] from the
//! built-in source or a user's GLSL or SPIR-V module (checked against the kernel's interface
//! first), and dispatched over a [`GpuBvh`] with timestamps.

use super::buffer::Buffer;
use super::bvh::GpuBvh;
use super::pipeline::ComputePipeline;
use super::support::Decision;
use super::timer::timed;
use super::{shader, Gpu, GpuError};
use crate::base::{Counters, Hit, Ray, RunOutput};
use crate::interface::{binding, PushConstants, PRIM_OVERFLOW};
use crate::variant::{KernelId, Source};
use ash::vk;
use gpu_allocator::MemoryLocation;

/// A traversal kernel ready to dispatch.
pub struct Kernel<'g> {
    pub pipe: ComputePipeline<'g>,
    pub id: KernelId,
    pub source: Source,
    /// The subgroup size the pipeline is pinned to (`None`: the driver's).
    pub subgroup: Option<u32>,
}

impl<'g> Kernel<'g> {
    /// The built-in kernel's name (a user's module runs in its place under the same name).
    pub fn name(&self) -> String {
        self.id.name()
    }

    /// The kernel's name, marked when the module is the user's.
    pub fn label(&self) -> String {
        match &self.source {
            Source::Builtin => self.name(),
            Source::Marked => format!("{} (branches marked)", self.name()),
            Source::Counted => format!("{} (branches counted)", self.name()),
            Source::Glsl(p) | Source::Spirv(p) => format!("{} (user kernel {})", self.name(), p.display()),
        }
    }

    /// Builds the pipeline of a kernel the device has admitted (`d`, from
    /// [`super::support::decide`] or [`super::support::admit`]) from `source`. A user's module is checked against the
    /// kernel's interface (entry point, workgroup, bindings, push constants, specialization
    /// constants, capabilities) before any pipeline is created.
    pub fn build(gpu: &'g Gpu, d: &Decision, source: &Source) -> Result<Kernel<'g>, GpuError> {
        let (k, pin, dev) = (&d.id, d.pin, d.build);
        let code = match source {
            Source::Builtin => shader::compile(k, dev)?,
            Source::Marked => shader::compile_marked(k, dev)?,
            Source::Counted => shader::compile_counted(k, dev)?,
            Source::Glsl(p) => shader::check_user(p, &shader::compile_user(p, k, dev)?, k, gpu)?,
            Source::Spirv(p) => {
                // The interface first (its messages say what a kernel must look like), then the
                // SPIRV-Tools validator (its message instead of a driver's "unknown error").
                let words = shader::check_user(p, &shader::read_spirv(p)?, k, gpu)?;
                shader::validate_user(p, &words)?;
                words
            }
        };
        Self::with_code(gpu, k, source, &code, pin)
    }

    fn with_code(
        gpu: &'g Gpu,
        k: &KernelId,
        source: &Source,
        code: &[u32],
        pin: Option<u32>,
    ) -> Result<Kernel<'g>, GpuError> {
        let push = std::mem::size_of::<PushConstants>() as u32;
        let pipe = ComputePipeline::with_subgroup(gpu, &k.name(), code, binding::COUNT, push, pin)?;
        Ok(Kernel { pipe, id: *k, source: source.clone(), subgroup: pin })
    }

    /// The counting kernel of a user's module (`k` counting): its GLSL compiled with `STATS`,
    /// when that build writes counters; `None` for a SPIR-V module or a kernel that does not
    /// count.
    pub fn user_counting(gpu: &'g Gpu, d: &Decision, source: &Source) -> Result<Option<Kernel<'g>>, GpuError> {
        let Source::Glsl(p) = source else { return Ok(None) };
        let k = d.id.with_stats(true);
        let code = shader::compile_user(p, &k, d.build)?;
        let itf =
            shader::parse_interface(&code).map_err(|msg| GpuError::Spirv { path: p.display().to_string(), msg })?;
        if !itf.bindings.contains(&(0, binding::COUNTERS)) {
            return Ok(None);
        }
        let code = shader::check_user(p, &code, &k, gpu)?;
        Self::with_code(gpu, &k, source, &code, d.pin).map(Some)
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
        let v = &self.id.variant;
        if v.buffers != bvh.buffers {
            return Err(GpuError::Other(format!(
                "{}: built for {:?} scene buffers, but this BVH is {:?} (build the kernel with `Variant::with_buffers(bvh.buffers)`)",
                self.label(),
                v.buffers,
                bvh.buffers
            )));
        }
        let pipe = &self.pipe;
        let wg = v.workgroup(self.id.imp);
        let n = rays.len();
        let ray_buf = Buffer::upload(gpu, "rays", bytemuck::cast_slice(rays))?;
        let out_usage = vk::BufferUsageFlags::STORAGE_BUFFER | vk::BufferUsageFlags::TRANSFER_SRC;
        let hit_bytes = n * std::mem::size_of::<Hit>();
        let counter_bytes = n * std::mem::size_of::<Counters>();
        let hits = Buffer::new(gpu, "hits", hit_bytes as u64, out_usage, MemoryLocation::GpuOnly)?;
        let counters = Buffer::new(
            gpu,
            "counters",
            if self.id.stats { counter_bytes as u64 } else { 16 },
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
                Source::Builtin | Source::Marked | Source::Counted => {
                    format!("{}: ray {bad} overflowed the traversal stack", self.name())
                }
                Source::Glsl(p) | Source::Spirv(p) => format!(
                    "the user's kernel {} (in place of {}): ray {bad} overflowed its traversal stack — was it built for another branching factor or layout than B = {}?",
                    p.display(),
                    self.name(),
                    v.branching
                ),
            }));
        }
        let counters: Option<Vec<Counters>> =
            if self.id.stats { Some(bytemuck::pod_collect_to_vec(&counters.download(counter_bytes)?)) } else { None };
        crate::digest::record("gpu", &self.label(), rays, &hits, counters.as_deref());
        Ok(RunOutput { hits, counters, times_ms: times, flagged: 0 })
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
    timed(gpu, warmup, repeat, |cmd| pipe.dispatch(cmd, push, groups), |cmd| pipe.barrier(cmd))
}
