//! GPU traversal throughput on the default Vulkan device: primary and ao rays at 512x512 on
//! a shared scene, every BVH layout in its default math, B = 4, packet sizes 1..64. Each
//! variant goes through the same validate-then-time path as the sweep: checked against the
//! CPU reference first, then 2 warm-up and 10 timed dispatches; median, min, max.
//!
//! `cargo bench --bench throughput [-- SCENE.obj]`

use halftrace::gpu::kernel::{choose_impl, GpuBvh, Kernel, Source};
use halftrace::gpu::{ContextOptions, Gpu};
use halftrace::layout::{Encoded, LayoutId};
use halftrace::measure::{validate_then_time, KernelTarget, Plan, Reference};
use halftrace::rays::{make_rays, RayKind, RayParams};
use halftrace::variant::{Variant, PACKETS};
use std::path::PathBuf;

fn main() {
    let scene_path = std::env::args()
        .skip(1)
        .find(|a| a.ends_with(".obj") || a.ends_with(".obj.gz"))
        .map(PathBuf::from)
        .unwrap_or_else(|| PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../shared/scenes/sponza_dabrovic.obj"));
    let scene = halftrace::scene::load(&scene_path).expect("scene");
    let bin = halftrace::bvh::build_binary(&scene);
    let g = Gpu::new(&ContextOptions::default()).expect("no Vulkan device");
    println!("scene {} ({} triangles), device {} ({})", scene.name, scene.len(), g.info.name, g.info.driver);
    println!(
        "{:<10} {:<26} {:>8} {:>10} {:>10} {:>10} {:>9}",
        "rays", "variant", "count", "median ms", "min ms", "max ms", "Mrays/s"
    );
    let params = RayParams { width: 512, height: 512, ..Default::default() };
    for kind in [RayKind::Primary, RayKind::Ao] {
        let rays = make_rays(&scene, &bin, &kind, &params).unwrap();
        let f32_hits = Encoded::new(&scene, &bin, LayoutId::f32(), 4).unwrap().trace_default(&rays).0;
        for layout in LayoutId::layouts() {
            let enc = Encoded::new(&scene, &bin, layout, 4).unwrap();
            let gb = GpuBvh::upload(&g, &enc).unwrap();
            for p in PACKETS {
                let v = Variant::new(layout, 4, p);
                let (cpu_hits, cpu_counters) = enc.trace(&rays, p, v.math);
                let k = Kernel::build(&g, &v, choose_impl(&g, &v, None), false, &Source::Builtin).unwrap();
                let target = KernelTarget { gpu: &g, bvh: &gb, timed: &k, counting: None };
                let m = validate_then_time(
                    &target,
                    &rays,
                    Reference::Exact { hits: &cpu_hits, counters: &cpu_counters },
                    &f32_hits,
                    Plan { warmup: 2, repeat: 10, count: false },
                )
                .unwrap();
                if let Some(f) = m.failure {
                    panic!("{f}");
                }
                let t = m.timing.unwrap();
                println!(
                    "{:<10} {:<26} {:>8} {:>10.2} {:>10.2} {:>10.2} {:>9.2}",
                    kind.to_string(),
                    k.name(),
                    rays.len(),
                    t.median,
                    t.min,
                    t.max,
                    t.mrays(rays.len()).0
                );
            }
        }
    }
}
