//! CPU reference traversal conformance: f32 against brute force, every other layout in every
//! math mode against f32 on every shared scene, every B and every ray kind including the
//! grazing set.

mod common;
use common::*;
use halftrace::bvh::BRANCHINGS;
use halftrace::layout::LayoutId;
use halftrace::trace::{brute, Hit};
use rayon::prelude::*;

#[test]
fn f32_traversal_equals_brute_force() {
    for name in ["teapot.obj", "cornell_box.obj", "smallpine.obj"] {
        let p = prepare(&scenes_dir().join(name));
        for (kind, rays) in ray_sets(&p, 40, 1500) {
            let expected: Vec<Hit> = rays.par_iter().map(|r| brute::trace(&p.scene, r)).collect();
            assert!(expected.iter().any(|h| h.is_hit()), "{name} {kind}: no ray hits; the test would be vacuous");
            for b in BRANCHINGS {
                let (hits, _) = encode(&p, LayoutId::f32(), b).trace_default(&rays);
                assert_same_hits(&format!("{name} f32 B={b} {kind} vs brute force"), &rays, &expected, &hits);
            }
        }
    }
}

#[test]
fn every_layout_equals_f32_on_every_scene_b_ray_kind_and_math_mode() {
    let layouts: Vec<LayoutId> = LayoutId::layouts().filter(|&l| l != LayoutId::f32()).collect();
    assert!(!layouts.is_empty());
    let mut total = 0usize;
    // per (layout, math): re-anchors, box tests; and f32's box tests
    let mut stats: Vec<(String, u64, u64)> = Vec::new();
    let mut f32_boxes = 0u64;
    for path in all_scenes() {
        let p = prepare(&path);
        let sets = ray_sets(&p, 48, 1500);
        for b in BRANCHINGS {
            let f = encode(&p, LayoutId::f32(), b);
            let encoded: Vec<_> = layouts.iter().map(|&l| encode(&p, l, b)).collect();
            for (kind, rays) in &sets {
                let (hf, cf) = f.trace_default(rays);
                f32_boxes += cf.iter().map(|c| c.box_tests as u64).sum::<u64>();
                for enc in &encoded {
                    for &math in enc.layout.caps().maths {
                        let (hh, ch) = enc.trace(rays, 1, math);
                        let what = format!("{}/{}", enc.layout, math.tag());
                        assert_same_hits(&format!("{} {what} B={b} {kind} vs f32", p.scene.name), rays, &hf, &hh);
                        let i = stats.iter().position(|s| s.0 == what).unwrap_or_else(|| {
                            stats.push((what.clone(), 0, 0));
                            stats.len() - 1
                        });
                        stats[i].1 += ch.iter().map(|c| c.reanchors as u64).sum::<u64>();
                        stats[i].2 += ch.iter().map(|c| c.box_tests as u64).sum::<u64>();
                    }
                }
                total += rays.len();
            }
        }
    }
    for (what, reanchors, boxes) in stats {
        eprintln!("{what} == f32 on {total} rays; box tests vs f32 {:.3}; re-anchors per ray {:.3}", boxes as f64 / f32_boxes as f64, reanchors as f64 / total as f64);
    }
}

#[test]
fn traversal_is_deterministic_and_hits_exist() {
    let p = prepare(&scenes_dir().join("teapot_in_stadium.obj"));
    let sets = ray_sets(&p, 32, 500);
    let h = encode(&p, layout("f16h"), 8);
    for (kind, rays) in &sets {
        let a = h.trace_default(rays);
        let b = h.trace_default(rays);
        assert_eq!(a.1, b.1, "{kind}: counters differ between runs");
        assert_same_hits(kind, rays, &a.0, &b.0);
        assert!(a.0.iter().any(|x| x.is_hit()), "{kind}: nothing hit");
    }
}
