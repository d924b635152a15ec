//! The device's raw fp16 and fp32 arithmetic throughput for the slab test's operations (sub,
//! mul, min, max, compare + select: `glsl/arith.comp`), so a report can state the device's own
//! fp16:fp32 ratio next to the traversal results (`halftrace devices --arith`, and once per
//! sweep).

use super::buffer::Buffer;
use super::pipeline::ComputePipeline;
use super::timer::Timer;
use super::{shader, Gpu, GpuError};
use ash::vk;
use gpu_allocator::MemoryLocation;
use serde::{Deserialize, Serialize};

pub const OPS: [&str; 5] = ["sub", "mul", "min", "max", "compare"];

/// Throughput of one operation: G operations per second, median of repeated dispatches.
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
pub struct OpRate {
    pub op: String,
    pub fp16_gops: f64,
    pub fp32_gops: f64,
    /// fp16 ÷ fp32 throughput (> 1: fp16 is faster).
    pub ratio: f64,
}

#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
pub struct ArithRates {
    pub device: String,
    pub driver: String,
    pub ops: Vec<OpRate>,
    /// Geometric mean of the per-operation ratios (NaN where fp16 was not measured).
    pub fp16_ratio: f64,
    /// Why the fp16 half was not measured (the device lacks `shaderFloat16`), `None` when it was.
    #[serde(default)]
    pub fp16_unavailable: Option<String>,
}

/// Measures every operation in both precisions: `threads` invocations × `iters` iterations × 16
/// operations. On a device without `shaderFloat16` only fp32 is measured (building the fp16
/// kernel there is invalid Vulkan usage, and SwiftShader's compiler dies on it): the fp16
/// figures are NaN and [`ArithRates::fp16_unavailable`] says why.
pub fn run(gpu: &Gpu, threads: u32, iters: u32, repeat: usize) -> Result<ArithRates, GpuError> {
    let fp16_unavailable = (!gpu.info.shader_float16).then(|| "the device has no shaderFloat16".to_string());
    let out = Buffer::new(
        gpu,
        "arithmetic output",
        threads as u64 * 4,
        vk::BufferUsageFlags::STORAGE_BUFFER,
        MemoryLocation::GpuOnly,
    )?;
    let timer = Timer::new(gpu)?;
    let mut ops = Vec::new();
    for (k, op) in OPS.iter().enumerate() {
        let mut rates = [0f64; 2];
        for (j, f16) in [true, false].into_iter().enumerate() {
            if f16 && fp16_unavailable.is_some() {
                rates[j] = f64::NAN;
                continue;
            }
            let mut defs = vec![("OP".to_string(), k.to_string())];
            if f16 {
                defs.push(("F16".into(), "1".into()));
            }
            let code = shader::compile_plain(
                &format!("arith {op} {}", if f16 { "fp16" } else { "fp32" }),
                "arith.comp",
                &defs,
            )?;
            let pipe = ComputePipeline::new(gpu, "arith", &code, 1, 8)?;
            pipe.bind(&[&out]);
            let mut push = [0u8; 8];
            push[..4].copy_from_slice(&iters.to_le_bytes());
            push[4..].copy_from_slice(&0.5f32.to_le_bytes());
            let mut t = Vec::new();
            for r in 0..repeat + 1 {
                gpu.submit_and_wait(|cmd| timer.record(cmd, || pipe.dispatch(cmd, &push, threads.div_ceil(64))))?;
                if r > 0 {
                    t.push(timer.elapsed_ms()?);
                }
            }
            t.sort_by(f64::total_cmp);
            let ms = t[t.len() / 2];
            rates[j] = threads as f64 * iters as f64 * 16.0 / (ms * 1e-3) / 1e9;
        }
        ops.push(OpRate { op: op.to_string(), fp16_gops: rates[0], fp32_gops: rates[1], ratio: rates[0] / rates[1] });
    }
    let fp16_ratio = (ops.iter().map(|o| o.ratio.ln()).sum::<f64>() / ops.len() as f64).exp();
    Ok(ArithRates { device: gpu.info.name.clone(), driver: gpu.info.driver.clone(), ops, fp16_ratio, fp16_unavailable })
}
