//! GPU traversal throughput on the default Vulkan device: primary and ao rays at 512x512 on
//! a shared scene, f32 and f16h, B = 4, packet sizes 1..64. Each variant is validated against
//! the CPU reference first, then timed with timestamp queries: 2 warm-up dispatches, 10
//! timed; median, min, max.
//!
//! `cargo bench --bench throughput [-- SCENE.obj]`

use halftrace::encode::Layout;
use halftrace::gpu::{traversal, ContextOptions, Gpu};
use halftrace::pipeline::{make_rays, Encoded, RayKind, RayParams};
use halftrace::variant::Variant;
use std::path::PathBuf;

fn main() {
    let scene_path = std::env::args().skip(1).find(|a| a.ends_with(".obj") || a.ends_with(".obj.gz")).map(PathBuf::from)
        .unwrap_or_else(|| PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../shared/scenes/sponza_dabrovic.obj"));
    let scene = halftrace::scene::load(&scene_path).expect("scene");
    let bin = halftrace::bvh::build_binary(&scene);
    let g = Gpu::new(&ContextOptions::default()).expect("no Vulkan device");
    println!("scene {} ({} triangles), device {} ({})", scene.name, scene.len(), g.info.name, g.info.driver);
    println!("{:<10} {:<26} {:>8} {:>10} {:>10} {:>10} {:>9}", "rays", "variant", "count", "median ms", "min ms", "max ms", "Mrays/s");
    let params = RayParams { width: 512, height: 512, ..Default::default() };
    for kind in [RayKind::Primary, RayKind::Ao] {
        let rays = make_rays(&scene, &bin, &kind, &params).unwrap();
        for layout in Layout::ALL {
          let enc = Encoded::new(&scene, &bin, layout, 4).unwrap();
          let gb = traversal::GpuBvh::upload(&g, &enc).unwrap();
          let (cpu, _) = enc.trace(&rays);
          for p in halftrace::variant::PACKETS {
            let v = Variant::new(layout, 4, p);
            let pipe = traversal::pipeline(&g, &v, traversal::choose_impl(&g, &v, None), false, None).unwrap();
            let out = traversal::run(&g, &gb, &pipe, &rays, 2, 10).unwrap();
            let bad = (0..rays.len()).filter(|&i| !out.hits[i].same_bits(&cpu[i])).count();
            assert_eq!(bad, 0, "{v} {kind}: {bad} rays differ from the CPU reference");
            let t = halftrace::report::Timing::of(&out.times_ms);
            println!("{:<10} {:<26} {:>8} {:>10.2} {:>10.2} {:>10.2} {:>9.2}", kind.to_string(), pipe.name(), rays.len(), t.median, t.min, t.max, t.mrays(rays.len()).0);
          }
        }
    }
}
