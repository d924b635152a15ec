//! BVH build + collapse + encode throughput on the largest shared scene (igea, 268k
//! triangles), every B and registered layout. Target on the 2-core CI machine: ≥ 2 M triangles/s for
//! the binary SAH build.

use criterion::{criterion_group, criterion_main, Criterion, Throughput};
use halftrace::bvh::{self, BRANCHINGS};
use halftrace::layout::{Encoded, LayoutId};
use std::path::PathBuf;

fn bench(c: &mut Criterion) {
    let path = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../shared/scenes/igea.obj.gz");
    let scene = halftrace::scene::load(&path).expect("benchmarks need ../shared/scenes/igea.obj.gz");
    let n = scene.len() as u64;
    let mut g = c.benchmark_group("build");
    g.sample_size(20);
    g.throughput(Throughput::Elements(n));
    g.bench_function("binary_sah/igea", |b| b.iter(|| bvh::build_binary(&scene)));
    let bin = bvh::build_binary(&scene);
    for b in BRANCHINGS {
        g.bench_function(format!("collapse/b{b}"), |bn| bn.iter(|| bvh::collapse(&bin, b)));
        let w = bvh::collapse(&bin, b);
        for l in LayoutId::layouts() {
            let layout = l.bvh().unwrap();
            g.bench_function(format!("encode_{l}/b{b}"), |bn| bn.iter(|| layout.encode(&scene, &w).unwrap()));
        }
        let f16h = LayoutId::parse("f16h").unwrap();
        g.bench_function(format!("total_f16h/b{b}"), |bn| bn.iter(|| Encoded::new(&scene, &bvh::build_binary(&scene), f16h, b).unwrap()));
    }
    g.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
