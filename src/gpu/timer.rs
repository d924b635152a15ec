//! Timestamp queries around a dispatch, and the timed repetition every traversal is measured
//! by (kernels, ray queries, ray-tracing pipelines alike).

use super::{Gpu, GpuError, VkResultExt};
use ash::vk;

pub struct Timer<'g> {
    gpu: &'g Gpu,
    pub pool: vk::QueryPool,
}

impl<'g> Timer<'g> {
    pub fn new(gpu: &'g Gpu) -> Result<Timer<'g>, GpuError> {
        let pool = unsafe {
            gpu.device.create_query_pool(
                &vk::QueryPoolCreateInfo::default().query_type(vk::QueryType::TIMESTAMP).query_count(2),
                None,
            )
        }
        .vk("vkCreateQueryPool")?;
        Ok(Timer { gpu, pool })
    }

    /// Records: reset, timestamp, `body`, timestamp.
    pub fn record(&self, cmd: vk::CommandBuffer, body: impl FnOnce()) {
        let d = &self.gpu.device;
        unsafe {
            d.cmd_reset_query_pool(cmd, self.pool, 0, 2);
            d.cmd_write_timestamp(cmd, vk::PipelineStageFlags::TOP_OF_PIPE, self.pool, 0);
            body();
            d.cmd_write_timestamp(cmd, vk::PipelineStageFlags::BOTTOM_OF_PIPE, self.pool, 1);
        }
    }

    /// Milliseconds between the two timestamps of the last recorded submission.
    pub fn elapsed_ms(&self) -> Result<f64, GpuError> {
        let mut t = [0u64; 2];
        unsafe {
            self.gpu.device.get_query_pool_results(
                self.pool,
                0,
                &mut t,
                vk::QueryResultFlags::TYPE_64 | vk::QueryResultFlags::WAIT,
            )
        }
        .vk("vkGetQueryPoolResults")?;
        Ok(t[1].wrapping_sub(t[0]) as f64 * self.gpu.info.timestamp_period_ns as f64 * 1e-6)
    }
}

impl Drop for Timer<'_> {
    fn drop(&mut self) {
        if self.gpu.hung() {
            return;
        }
        unsafe { self.gpu.device.destroy_query_pool(self.pool, None) };
    }
}

/// Records `warmup + repeat` (at least one) submissions of `work`, each with timestamps around
/// it and `after` (a barrier making its writes visible) behind them; returns the times of the
/// last `repeat`, ms.
pub(crate) fn timed(
    gpu: &Gpu,
    warmup: usize,
    repeat: usize,
    work: impl Fn(vk::CommandBuffer),
    after: impl Fn(vk::CommandBuffer),
) -> Result<Vec<f64>, GpuError> {
    let timer = Timer::new(gpu)?;
    let mut times = Vec::with_capacity(repeat);
    for i in 0..(warmup + repeat).max(1) {
        gpu.submit_and_wait(|cmd| {
            timer.record(cmd, || work(cmd));
            after(cmd);
        })?;
        if i >= warmup {
            times.push(timer.elapsed_ms()?);
        }
    }
    Ok(times)
}
