//! BVH build + collapse + encode throughput on the largest shared scene (igea, 268k
//! triangles), every B and registered layout. Goal on the 2-core CI machine: ≥ 2 M triangles/s for
//! the binary SAH build. Beside it, the yardstick for that rate on the machine at hand: Intel
//! Embree 3's own build of the same triangles (its default, medium build quality, all host
//! threads; timed with filling its vertex and index buffers, as ours is with the triangles'
//! boxes).
//!
//! `HALFTRACE_BENCH_SCENE=FILE cargo bench --bench build -- 'binary_sah|embree'` measures both
//! builds on another scene (any format `halftrace` reads), e.g. a 10 M-triangle
//! `halftrace instance` GLB.

use criterion::{criterion_group, criterion_main, Criterion, Throughput};
use halftrace::baseline::BaselineDevice;
use halftrace::bvh::{self, BRANCHINGS};
use halftrace::layout::{Encoded, LayoutId};
use std::path::PathBuf;

fn bench(c: &mut Criterion) {
    let path = std::env::var_os("HALFTRACE_BENCH_SCENE")
        .map(PathBuf::from)
        .unwrap_or_else(|| PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("tests/scenes/igea.obj.gz"));
    let scene =
        halftrace::scene::load(&path).unwrap_or_else(|e| panic!("the build benchmark needs {}: {e}", path.display()));
    let name = scene.name.clone();
    let n = scene.len() as u64;
    let mut g = c.benchmark_group("build");
    // Criterion's least for scenes of millions of triangles (seconds a build).
    g.sample_size(if n > 1_000_000 { 10 } else { 20 });
    g.throughput(Throughput::Elements(n));
    g.bench_function(format!("binary_sah/{name}"), |b| b.iter(|| bvh::build_binary(&scene)));
    let embree = halftrace::baseline::embree::host();
    g.bench_function(format!("embree_scene/{name}"), |b| {
        b.iter(|| BaselineDevice::scene(&embree, &scene).expect("Embree builds the scene"))
    });
    let bin = bvh::build_binary(&scene);
    for b in BRANCHINGS {
        g.bench_function(format!("collapse/b{b}"), |bn| bn.iter(|| bvh::collapse(&bin, b)));
        let w = bvh::collapse(&bin, b);
        for l in LayoutId::all() {
            let layout = l.imp();
            g.bench_function(format!("encode_{l}/b{b}"), |bn| bn.iter(|| layout.encode(&scene, &w).unwrap()));
        }
        let f16h = LayoutId::parse("f16h").unwrap();
        g.bench_function(format!("total_f16h/b{b}"), |bn| {
            bn.iter(|| Encoded::new(&scene, &bvh::build_binary(&scene), f16h, b).unwrap())
        });
    }
    g.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
