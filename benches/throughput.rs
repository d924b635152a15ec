//! GPU traversal throughput on the default Vulkan device: primary and ao rays at 512x512 on
//! a shared scene, every layout in its default math, B = 4, packet sizes 1..64. Each variant
//! goes through the runner, as in the sweep: checked against the CPU reference first, then 2
//! warm-up and 10 timed dispatches; median, min, max.
//!
//! `cargo bench --bench throughput [-- SCENE.obj]`

use halftrace::gpu::{ContextOptions, Gpu};
use halftrace::layout::LayoutId;
use halftrace::rays::{RayKind, RayParams};
use halftrace::runner::{Plan, RaySpec, Runner, Target};
use halftrace::variant::{Variant, PACKETS};
use std::path::PathBuf;

fn main() {
    let scene_path = std::env::args()
        .skip(1)
        .find(|a| a.ends_with(".obj") || a.ends_with(".obj.gz"))
        .map(PathBuf::from)
        .unwrap_or_else(|| PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("tests/scenes/sponza_dabrovic.obj.gz"));
    let g = Gpu::new(&ContextOptions::default()).expect("no Vulkan device");
    let mut runner = Runner::new(Some(&g), &[], Default::default()).expect("runner");
    let (scene, _) = runner.scene(&scene_path).expect("scene");
    println!("scene {} ({} triangles), device {} ({})", scene.name, scene.len(), g.info.name, g.info.driver);
    println!(
        "{:<10} {:<26} {:>8} {:>10} {:>10} {:>10} {:>9}",
        "rays", "variant", "count", "median ms", "min ms", "max ms", "Mrays/s"
    );
    let params = RayParams { width: 512, height: 512, ..Default::default() };
    for kind in [RayKind::Primary, RayKind::Ao] {
        let set = runner.ray_set(&RaySpec::new(kind.clone(), params.clone())).unwrap();
        let n = runner.rays(set).rays.len();
        for layout in LayoutId::all() {
            for p in PACKETS {
                let v = Variant::new(layout, 4, p);
                let o = runner.measure(&Target::builtin(v), set, Plan { warmup: 2, repeat: 10, count: false }).unwrap();
                assert!(o.status.is_ok(), "{}: {}", o.name, o.status);
                let t = o.m.timing.unwrap();
                let (med, min, max, rate) = (t.median, t.min, t.max, t.mrays(n).0);
                println!(
                    "{:<10} {:<26} {n:>8} {med:>10.2} {min:>10.2} {max:>10.2} {rate:>9.2}",
                    kind.to_string(),
                    o.name
                );
            }
        }
    }
}
