//! What the driver's compiler made of a pipeline, read through
//! `VK_KHR_pipeline_executable_properties`: per executable (a compute pipeline has one), the
//! statistics the driver names and its internal representations (on RADV: NIR, ACO's IR and
//! the disassembly). Needs a [`Gpu`] opened with [`super::ContextOptions::statistics`].

use super::pipeline::ComputePipeline;
use super::{Gpu, GpuError, VkResultExt};
use ash::vk;

/// One statistic as the driver names it.
#[derive(Clone, Debug, PartialEq)]
pub struct Statistic {
    pub name: String,
    pub description: String,
    /// Booleans as 0 or 1, integers as they are (exact below 2^53).
    pub value: f64,
}

/// One executable of a pipeline.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Executable {
    pub name: String,
    pub description: String,
    /// The subgroup size the driver compiled it for.
    pub subgroup_size: u32,
    pub statistics: Vec<Statistic>,
    /// Textual internal representations: (name, text).
    pub representations: Vec<(String, String)>,
}

fn text(chars: &[std::ffi::c_char]) -> String {
    let bytes: Vec<u8> = chars.iter().take_while(|&&c| c != 0).map(|&c| c as u8).collect();
    String::from_utf8_lossy(&bytes).trim().to_string()
}

/// The executables of `pipe`, with their statistics and textual representations.
pub fn executables(gpu: &Gpu, pipe: &ComputePipeline) -> Result<Vec<Executable>, GpuError> {
    if !gpu.capture {
        return Err(GpuError::Other(format!(
            "{}: the device was not opened to capture pipeline statistics",
            pipe.name
        )));
    }
    let ext = ash::khr::pipeline_executable_properties::Device::new(&gpu.instance, &gpu.device);
    let pinfo = vk::PipelineInfoKHR::default().pipeline(pipe.raw());
    let props = unsafe { ext.get_pipeline_executable_properties(&pinfo) }.vk("vkGetPipelineExecutablePropertiesKHR")?;
    let mut out = Vec::new();
    for (i, p) in props.iter().enumerate() {
        let einfo = vk::PipelineExecutableInfoKHR::default().pipeline(pipe.raw()).executable_index(i as u32);
        let stats =
            unsafe { ext.get_pipeline_executable_statistics(&einfo) }.vk("vkGetPipelineExecutableStatisticsKHR")?;
        let statistics = stats
            .iter()
            .map(|s| {
                let value = unsafe {
                    match s.format {
                        vk::PipelineExecutableStatisticFormatKHR::BOOL32 => s.value.b32 as f64,
                        vk::PipelineExecutableStatisticFormatKHR::INT64 => s.value.i64 as f64,
                        vk::PipelineExecutableStatisticFormatKHR::UINT64 => s.value.u64 as f64,
                        _ => s.value.f64,
                    }
                };
                Statistic { name: text(&s.name), description: text(&s.description), value }
            })
            .collect();
        out.push(Executable {
            name: text(&p.name),
            description: text(&p.description),
            subgroup_size: p.subgroup_size,
            statistics,
            representations: representations(gpu, &ext, &einfo)?,
        });
    }
    Ok(out)
}

/// The textual internal representations of one executable: sizes first, then the texts.
fn representations(
    gpu: &Gpu,
    ext: &ash::khr::pipeline_executable_properties::Device,
    einfo: &vk::PipelineExecutableInfoKHR,
) -> Result<Vec<(String, String)>, GpuError> {
    let mut irs = unsafe { ext.get_pipeline_executable_internal_representations(einfo) }
        .vk("vkGetPipelineExecutableInternalRepresentationsKHR")?;
    let mut bufs: Vec<Vec<u8>> = irs.iter().map(|r| vec![0u8; r.data_size]).collect();
    for (r, b) in irs.iter_mut().zip(bufs.iter_mut()) {
        r.p_data = b.as_mut_ptr().cast();
    }
    let mut count = irs.len() as u32;
    let fp = ext.fp().get_pipeline_executable_internal_representations_khr;
    let r = unsafe { fp(gpu.device.handle(), einfo, &mut count, irs.as_mut_ptr()) };
    // INCOMPLETE would mean a text cut short: an error too.
    if r != vk::Result::SUCCESS {
        return Err(GpuError::Vk { call: "vkGetPipelineExecutableInternalRepresentationsKHR", result: r });
    }
    Ok(irs
        .iter()
        .zip(&bufs)
        .take(count as usize)
        .filter(|(r, _)| r.is_text == vk::TRUE)
        .map(|(r, b)| {
            let n = b.iter().position(|&c| c == 0).unwrap_or(r.data_size.min(b.len()));
            (text(&r.name), String::from_utf8_lossy(&b[..n]).to_string())
        })
        .collect())
}
