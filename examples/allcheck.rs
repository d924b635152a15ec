//! GPU vs CPU over every shared scene, B, layout and ray kind (development check).
use halftrace::{bvh, encode::Layout, gpu, pipeline::{self, Encoded, RayKind, RayParams}, variant::Variant};
fn main() {
    let g = gpu::Gpu::new(&Default::default()).unwrap();
    let mut dirs: Vec<_> = std::fs::read_dir("../shared/scenes").unwrap().map(|e| e.unwrap().path()).filter(|p| p.to_string_lossy().contains(".obj")).collect();
    dirs.sort();
    for path in dirs {
        let scene = halftrace::scene::load(&path).unwrap();
        let bin = bvh::build_binary(&scene);
        let kinds = [RayKind::Primary, RayKind::Ao, RayKind::Diffuse, RayKind::Grazing];
        let sets: Vec<_> = kinds.iter().map(|k| (k.clone(), pipeline::make_rays(&scene, &bin, k, &RayParams { width: 48, height: 48, grazing: 1500, ..Default::default() }).unwrap())).collect();
        for layout in Layout::ALL { for b in bvh::BRANCHINGS {
            let enc = Encoded::new(&scene, &bin, layout, b).unwrap();
            let gb = gpu::traversal::GpuBvh::upload(&g, &enc).unwrap();
            let v = Variant::new(layout, b, 1);
            let p = gpu::traversal::pipeline(&g, &v, true, None).unwrap();
            for (k, rays) in &sets {
                let (ch, cc) = enc.trace(rays);
                let o = gpu::traversal::run(&g, &gb, &p, rays, 0, 1, true).unwrap();
                let gc = o.counters.unwrap();
                let hb = (0..rays.len()).filter(|&i| !o.hits[i].same_bits(&ch[i])).count();
                let cb = (0..rays.len()).filter(|&i| gc[i] != cc[i]).count();
                if hb + cb > 0 { println!("{} {v} {k}: {hb} hit, {cb} counter mismatches of {}", scene.name, rays.len()); }
            }
        }}
        println!("{} done", scene.name);
    }
}
