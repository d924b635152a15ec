//! How often the closest-hit rule's fast path cannot decide a ray (docs/layouts.md, "The
//! closest-hit rule"): per scene and ray set (primary, ao, diffuse at 256², 4096 grazing rays,
//! `trace`'s defaults), the rays each conservative layout's traversal flags at B = 4 and 8 —
//! what its kernel flags, bit for bit — and the time of their exact re-trace on the host
//! through the binary BVH (`BinaryBvh::resolve`, what the runner does after a kernel).
//!
//! cargo run --release --example flag_rates -- SCENE...

use halftrace::layout::{Encoded, LayoutId};
use halftrace::precision::FloatControls;
use halftrace::rays::{RayKind, RayParams};
use halftrace::runner::rays::{make, RaySpec};
use std::time::Instant;

fn main() -> anyhow::Result<()> {
    let paths: Vec<String> = std::env::args().skip(1).collect();
    anyhow::ensure!(!paths.is_empty(), "usage: flag_rates SCENE...");
    println!("| scene | rays | count | layout | B | flagged | rate | worst of the layouts | re-trace ms |");
    println!("|---|---|---:|---|---:|---:|---:|---:|---:|");
    let mut worst = (0.0f64, String::new());
    for path in &paths {
        let scene = halftrace::scene::load(path.as_ref())?;
        let bin = halftrace::bvh::build_binary(&scene);
        for kind in [RayKind::Primary, RayKind::Ao, RayKind::Diffuse, RayKind::Grazing] {
            let rays = make(&scene, &bin, &RaySpec::new(kind.clone(), RayParams::default()))?;
            let mut rows = Vec::new();
            let mut most = 0usize;
            for layout in LayoutId::all().filter(|l| l.info().conservative) {
                for b in [4, 8] {
                    let enc = Encoded::new(&scene, &bin, layout, b)?;
                    let math = layout.info().maths[0];
                    let (mut hits, _) = enc.trace_raw(&rays, 1, math, FloatControls::On);
                    let t0 = Instant::now();
                    let n = bin.resolve(&scene, &rays, &mut hits);
                    let ms = t0.elapsed().as_secs_f64() * 1e3;
                    most = most.max(n);
                    rows.push((layout, b, n, ms));
                }
            }
            let rate = most as f64 / rays.len() as f64;
            if rate > worst.0 {
                worst = (rate, format!("{} {kind}", scene.name));
            }
            for (layout, b, n, ms) in rows {
                println!(
                    "| {} | {kind} | {} | {layout} | {b} | {n} | {:.1e} | {:.1e} | {ms:.1} |",
                    scene.name,
                    rays.len(),
                    n as f64 / rays.len() as f64,
                    rate
                );
            }
        }
    }
    println!("\nworst rate: {:.2e} ({})", worst.0, worst.1);
    Ok(())
}
