//! `halftrace instance`: a big glTF scene made of copies of a small one.

use super::outln;
use crate::scene::{self, MAX_TRIANGLES};

#[derive(clap::Args, Clone, Debug, PartialEq)]
pub struct InstanceArgs {
    /// Scene to instance (OBJ, glTF or PLY).
    #[arg(long)]
    pub scene: std::path::PathBuf,
    /// Number of instances.
    #[arg(long)]
    pub count: usize,
    /// Seed of the rotations and scales.
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// The .glb file to write (an existing file is refused).
    #[arg(long)]
    pub out: std::path::PathBuf,
}

pub fn instance(a: &InstanceArgs) -> anyhow::Result<()> {
    let (count, out) = (a.count, &a.out);
    anyhow::ensure!(count >= 1, "--count must be at least 1");
    anyhow::ensure!(
        out.extension().is_some_and(|e| e.eq_ignore_ascii_case("glb")),
        "--out {}: name a .glb file",
        out.display()
    );
    anyhow::ensure!(!out.exists(), "--out {} exists; it is not overwritten", out.display());
    let s = scene::load(&a.scene)?;
    let Some(total) = s.len().checked_mul(count).filter(|&t| t <= MAX_TRIANGLES) else {
        anyhow::bail!(
            "{count} instances of {} triangles exceed the {MAX_TRIANGLES} triangles a scene may have",
            s.len()
        );
    };
    let bytes = scene::instance::instanced_glb(&s, count, a.seed);
    crate::fsx::write_atomic(out, &bytes)?;
    outln!(
        "{}: {count} instances of {} ({} triangles each): {total} triangles, {} bytes",
        out.display(),
        s.name,
        s.len(),
        bytes.len()
    );
    Ok(())
}
