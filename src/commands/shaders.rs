//! `halftrace shaders --emit DIR`: the SPIR-V of the default matrix, one file per kernel.

use super::outln;
use crate::gpu::shader;
use crate::variant::{spirv_kernels, DeviceBuild};
use anyhow::Context;
use std::path::Path;

#[derive(clap::Args, Clone, Debug, PartialEq)]
pub struct ShadersArgs {
    /// Output folder (e.g. spirv/).
    #[arg(long)]
    pub emit: std::path::PathBuf,
}

pub fn shaders(a: &ShadersArgs) -> anyhow::Result<()> {
    let dir: &Path = &a.emit;
    std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
    for k in spirv_kernels() {
        for stats in [false, true] {
            let k = k.with_stats(stats);
            let code = shader::compile(&k, DeviceBuild::FULL)?;
            let p = dir.join(format!("{k}.spv"));
            std::fs::write(&p, bytemuck::cast_slice(&code)).with_context(|| format!("writing {}", p.display()))?;
            outln!("{}", p.display());
        }
    }
    Ok(())
}
