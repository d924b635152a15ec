//! The `halftrace` command line.

use anyhow::Context;
use clap::{Parser, Subcommand};
use halftrace::bvh::{self, stats::stats};
use halftrace::encode::Layout;
use halftrace::pipeline::{self, Encoded, RayKind, RayParams};
use halftrace::rays::Camera;
use halftrace::{npy, scene};
use std::io::Write;
use std::path::PathBuf;
use std::time::Instant;

/// Writes a line to stdout, returning I/O errors (a closed pipe ends the command quietly).
macro_rules! outln {
    ($($t:tt)*) => { writeln!(std::io::stdout(), $($t)*)? };
}

#[derive(Parser)]
#[command(name = "halftrace", version, about = "Half-precision hierarchical BVH traversal harness")]
struct Cli {
    #[command(subcommand)]
    cmd: Cmd,
}

#[derive(Subcommand)]
enum Cmd {
    /// Trace a ray set through one layout and branching factor.
    Trace(TraceArgs),
    /// Print per-B, per-layout BVH statistics.
    BvhStats {
        /// OBJ or .obj.gz scene.
        #[arg(long)]
        scene: PathBuf,
    },
}

#[derive(clap::Args)]
struct TraceArgs {
    /// OBJ or .obj.gz scene.
    #[arg(long)]
    scene: PathBuf,
    /// Node layout: f32 or f16h.
    #[arg(long, default_value = "f16h")]
    layout: String,
    /// Branching factor: 2, 4, 8 or 16.
    #[arg(long, default_value_t = 4)]
    branching: usize,
    /// primary, ao, diffuse, grazing, or a FILE.npy (float32, N x 8).
    #[arg(long, default_value = "primary")]
    rays: String,
    #[arg(long, default_value_t = 256)]
    width: u32,
    #[arg(long, default_value_t = 256)]
    height: u32,
    /// eye_x,eye_y,eye_z,target_x,target_y,target_z,fov_degrees (default: frame the scene).
    #[arg(long)]
    camera: Option<String>,
    /// Seed for ao, diffuse and grazing rays.
    #[arg(long, default_value_t = 1)]
    seed: u64,
    /// Write hits (structured t, prim, u, v) to this .npy file.
    #[arg(long)]
    out: Option<PathBuf>,
    /// Write the traced rays to this .npy file.
    #[arg(long)]
    save_rays: Option<PathBuf>,
    /// Write a shaded PNG (primary rays only).
    #[arg(long)]
    image: Option<PathBuf>,
}

fn load_scene(path: &PathBuf) -> anyhow::Result<scene::Scene> {
    let s = scene::load(path)?;
    for w in &s.warnings {
        eprintln!("warning: {w}");
    }
    Ok(s)
}

fn trace(a: TraceArgs) -> anyhow::Result<()> {
    let layout: Layout = a.layout.parse()?;
    bvh::check_branching(a.branching).context("--branching")?;
    let kind: RayKind = a.rays.parse()?;
    let camera = a.camera.as_deref().map(Camera::parse).transpose()?;
    let scene = load_scene(&a.scene)?;
    let t0 = Instant::now();
    let bin = bvh::build_binary(&scene);
    let build_ms = t0.elapsed().as_secs_f64() * 1e3;
    let params = RayParams { width: a.width, height: a.height, camera, seed: a.seed, ..Default::default() };
    let rays = pipeline::make_rays(&scene, &bin, &kind, &params)?;
    let enc = Encoded::new(&scene, &bin, layout, a.branching)?;
    let t1 = Instant::now();
    let (hits, counters) = enc.trace(&rays);
    let secs = t1.elapsed().as_secs_f64();
    let nhit = hits.iter().filter(|h| h.is_hit()).count();
    let m = pipeline::mean_counters(&counters);
    outln!("scene {} ({} triangles), layout {layout}, B={}, rays {kind}: {} rays, {} hits", scene.name, scene.len(), a.branching, rays.len(), nhit);
    outln!("backend cpu (reference): {:.1} ms, {:.2} Mrays/s; BVH build {:.1} ms", secs * 1e3, rays.len() as f64 / secs / 1e6, build_ms);
    outln!("per ray: {:.2} nodes, {:.2} box tests, {:.2} triangle tests, {:.3} re-anchors", m[0], m[1], m[2], m[3]);
    if let Some(p) = &a.out {
        npy::write_hits(p, &hits)?;
        outln!("hits written to {}", p.display());
    }
    if let Some(p) = &a.save_rays {
        npy::write_rays(p, &rays)?;
        outln!("rays written to {}", p.display());
    }
    if let Some(p) = &a.image {
        anyhow::ensure!(kind == RayKind::Primary, "--image needs --rays primary");
        pipeline::write_image(p, &scene, &rays, &hits, a.width, a.height)?;
        outln!("image written to {}", p.display());
    }
    Ok(())
}

fn bvh_stats(path: &PathBuf) -> anyhow::Result<()> {
    let scene = load_scene(path)?;
    let t0 = Instant::now();
    let bin = bvh::build_binary(&scene);
    let ms = t0.elapsed().as_secs_f64() * 1e3;
    outln!("scene {} ({} triangles, {} degenerate); binary SAH build {:.1} ms ({:.2} Mtris/s)", scene.name, scene.len(), scene.degenerate, ms, scene.len() as f64 / ms / 1e3);
    outln!("{:>3} {:>6} {:>9} {:>9} {:>12} {:>10} {:>6} {:>9} {:>6}", "B", "layout", "nodes", "leaves", "node bytes", "bytes/node", "depth", "SAH cost", "fill");
    for b in bvh::BRANCHINGS {
        let w = bvh::collapse(&bin, b);
        let st = stats(&w);
        for layout in Layout::ALL {
            let enc = Encoded::new(&scene, &bin, layout, b)?;
            outln!(
                "{:>3} {:>6} {:>9} {:>9} {:>12} {:>10} {:>6} {:>9.2} {:>6.2}",
                b, layout.name(), st.inner_nodes, st.leaves, enc.node_bytes(), enc.node_bytes() / enc.node_count(), st.depth, st.sah_cost, st.fill
            );
        }
    }
    let tb = halftrace::encode::TriBuffer::new(&scene, &bvh::collapse(&bin, 2));
    outln!("triangles (shared by all layouts): {} bytes", tb.bytes());
    Ok(())
}

fn main() {
    let cli = Cli::parse();
    let r = match cli.cmd {
        Cmd::Trace(a) => trace(a),
        Cmd::BvhStats { scene } => bvh_stats(&scene),
    };
    if let Err(e) = r {
        eprintln!("error: {e:#}");
        std::process::exit(1);
    }
}
