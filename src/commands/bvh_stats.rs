//! `halftrace bvh-stats`: the binary build, and per B and layout the nodes, bytes and tree
//! shape.

use super::outln;
use crate::bvh::{self, stats::stats};
use crate::layout::{Encoded, LayoutId, TriBuffer};
use std::path::Path;
use std::time::Instant;

#[derive(clap::Args, Clone, Debug, PartialEq)]
pub struct BvhStatsArgs {
    /// Scene: OBJ, glTF (.gltf, .glb) or PLY, each optionally gzip-compressed (.gz).
    #[arg(long)]
    pub scene: std::path::PathBuf,
}

pub fn bvh_stats(a: &BvhStatsArgs) -> anyhow::Result<()> {
    let path: &Path = &a.scene;
    let scene = crate::scene::load(path)?;
    for w in &scene.warnings {
        eprintln!("warning: {w}");
    }
    let t0 = Instant::now();
    let bin = bvh::build_binary(&scene);
    let ms = t0.elapsed().as_secs_f64() * 1e3;
    outln!(
        "scene {} ({} triangles, {} degenerate); binary SAH build {ms:.1} ms ({:.2} Mtris/s)",
        scene.name,
        scene.len(),
        scene.degenerate,
        scene.len() as f64 / ms / 1e3
    );
    outln!(
        "{:>3} {:>11} {:>9} {:>9} {:>12} {:>10} {:>6} {:>9} {:>6}",
        "B",
        "layout",
        "nodes",
        "leaves",
        "node bytes",
        "bytes/node",
        "depth",
        "SAH cost",
        "fill"
    );
    for b in bvh::BRANCHINGS {
        let st = stats(&bvh::collapse(&bin, b));
        for layout in LayoutId::all() {
            let enc = Encoded::new(&scene, &bin, layout, b)?;
            outln!(
                "{:>3} {:>11} {:>9} {:>9} {:>12} {:>10} {:>6} {:>9.2} {:>6.2}",
                b,
                layout.name(),
                st.inner_nodes,
                st.leaves,
                enc.node_bytes(),
                enc.node_size(),
                st.depth,
                st.sah_cost,
                st.fill
            );
        }
    }
    let tb = TriBuffer::new(&scene, &bvh::collapse(&bin, 2));
    outln!("triangles (shared by all layouts): {} bytes", tb.bytes());
    Ok(())
}
