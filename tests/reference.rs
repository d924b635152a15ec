//! CPU reference traversal conformance: f32 against brute force, f16h against f32 on every
//! shared scene, every B and every ray kind including the grazing set.

mod common;
use common::*;
use halftrace::bvh::BRANCHINGS;
use halftrace::encode::Layout;
use halftrace::pipeline::Encoded;
use halftrace::trace::{brute, trace_all, Hit};
use rayon::prelude::*;

#[test]
fn f32_traversal_equals_brute_force() {
    for name in ["teapot.obj", "cornell_box.obj", "smallpine.obj"] {
        let p = prepare(&scenes_dir().join(name));
        for (kind, rays) in ray_sets(&p, 40, 1500) {
            let expected: Vec<Hit> = rays.par_iter().map(|r| brute::trace(&p.scene, r)).collect();
            assert!(expected.iter().any(|h| h.is_hit()), "{name} {kind}: no ray hits; the test would be vacuous");
            for b in BRANCHINGS {
                let enc = Encoded::new(&p.scene, &p.bin, Layout::F32, b).unwrap();
                let (hits, _) = enc.trace(&rays);
                assert_same_hits(&format!("{name} f32 B={b} {kind} vs brute force"), &rays, &expected, &hits);
            }
        }
    }
}

#[test]
fn f16h_equals_f32_on_every_scene_b_ray_kind_and_math_mode() {
    use halftrace::trace::f16h::Math;
    let mut total = 0usize;
    let mut reanchors = [0u64; 3];
    let mut boxes = [0u64; 4];
    for path in all_scenes() {
        let p = prepare(&path);
        let sets = ray_sets(&p, 48, 1500);
        for b in BRANCHINGS {
            let f = Encoded::new(&p.scene, &p.bin, Layout::F32, b).unwrap();
            let h = Encoded::new(&p.scene, &p.bin, Layout::F16h, b).unwrap();
            for (kind, rays) in &sets {
                let (hf, cf) = f.trace(rays);
                boxes[0] += cf.iter().map(|c| c.box_tests as u64).sum::<u64>();
                for (m, math) in Math::ALL.into_iter().enumerate() {
                    let (hh, ch) = h.trace_variant(rays, 1, math);
                    assert_same_hits(&format!("{} f16h/{} B={b} {kind} vs f32", p.scene.name, math.tag()), rays, &hf, &hh);
                    reanchors[m] += ch.iter().map(|c| c.reanchors as u64).sum::<u64>();
                    boxes[m + 1] += ch.iter().map(|c| c.box_tests as u64).sum::<u64>();
                }
                total += rays.len();
            }
        }
    }
    for (m, math) in Math::ALL.into_iter().enumerate() {
        eprintln!(
            "f16h/{} == f32 on {total} rays; box tests vs f32 {:.3}; re-anchors per ray {:.3}",
            math.tag(),
            boxes[m + 1] as f64 / boxes[0] as f64,
            reanchors[m] as f64 / total as f64
        );
    }
}

#[test]
fn traversal_is_deterministic_and_hits_exist() {
    let p = prepare(&scenes_dir().join("teapot_in_stadium.obj"));
    let sets = ray_sets(&p, 32, 500);
    let h = Encoded::new(&p.scene, &p.bin, Layout::F16h, 8).unwrap();
    for (kind, rays) in &sets {
        let a = h.trace(rays);
        let b = trace_all(rays, |r| match &h {
            Encoded::F16h(e) => halftrace::trace::f16h::trace(e, r),
            _ => unreachable!(),
        });
        assert_eq!(a.1, b.1, "{kind}: counters differ between runs");
        assert_same_hits(kind, rays, &a.0, &b.0);
    }
}
