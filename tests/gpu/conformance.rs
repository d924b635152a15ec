//! Conformance on every scene, odd ray counts and partial packets: every kernel equals its CPU reference.

use super::*;

/// `halftrace conformance --quick` over every test scene under the validation layer: every
/// layout, B, P, math mode, float-control mode and packet implementation runs at least once
/// and equals the CPU reference of its layout (hits bitwise, counters exactly) and the f32
/// hits. The full cross product is `halftrace conformance` (CI runs it after the tests).
#[test]
fn quick_conformance_covers_every_value_on_every_scene() {
    use halftrace::conformance;
    use halftrace::precision::FloatControls;
    use halftrace::report::Status;
    let opts = conformance::Options { quick: true, scenes: all_scenes(), validation: true, ..Default::default() };
    let o = conformance::run(&opts, |_| {}).unwrap_or_else(|e| panic!("GPU TESTS CANNOT RUN: {e}"));
    let md = conformance::markdown(&o, true);
    assert!(o.validation.is_empty(), "validation messages:\n{}", o.validation.join("\n"));
    let fails = o.failures();
    assert!(
        fails.is_empty(),
        "{}",
        fails
            .iter()
            .map(|c| format!("{}: {}", c.variant.kernel_name(c.imp, false), c.status))
            .collect::<Vec<_>>()
            .join("\n")
    );
    let passed: Vec<_> = o.checks.iter().filter(|c| c.status == Status::Ok).collect();
    assert!(passed.iter().all(|c| c.rays > 1000), "every kernel traced every scene:\n{md}");
    for layout in LayoutId::all() {
        let of = |f: &dyn Fn(&&&conformance::Check) -> bool| {
            passed.iter().filter(|c| c.variant.layout == layout).any(|c| f(&c))
        };
        for b in BRANCHINGS {
            assert!(of(&|c| c.variant.branching == b), "{layout}: B={b} not covered\n{md}");
        }
        for p in PACKETS {
            assert!(of(&|c| c.variant.packet == p), "{layout}: P={p} not covered\n{md}");
        }
        for &m in layout.info().maths {
            assert!(of(&|c| c.variant.math == m), "{layout}: math {} not covered\n{md}", m.name());
        }
        // lavapipe (subgroups of 8, with subgroup arithmetic) runs hybrid packets above P = 8.
        for imp in [PacketImpl::Single, PacketImpl::Shared, PacketImpl::Subgroup, PacketImpl::Hybrid] {
            assert!(of(&|c| c.imp == imp), "{layout}: {imp:?} packets not covered\n{md}");
        }
        if layout.info().float_controls_off {
            assert!(
                of(&|c| c.variant.fc == FloatControls::Off && c.variant.packet == 1),
                "{layout}: no kernel without float controls covered\n{md}"
            );
            assert!(
                of(&|c| c.variant.fc == FloatControls::Off && c.imp == PacketImpl::Subgroup),
                "{layout}: no packet kernel without float controls covered\n{md}"
            );
        }
    }
    // Both packet implementations at every P the device's subgroup holds.
    let g = gpu();
    for p in PACKETS.into_iter().filter(|&p| p > 1 && p <= g.info.max_subgroup_size as usize) {
        for imp in [PacketImpl::Shared, PacketImpl::Subgroup] {
            assert!(passed.iter().any(|c| c.variant.packet == p && c.imp == imp), "P={p} {imp:?} not covered\n{md}");
        }
    }
    eprintln!("{md}");
}

#[test]
fn odd_ray_counts_and_all_miss_batches() {
    let g = gpu();
    let p = prepare(&scene_path("teapot.obj"));
    let sets = ray_sets(&p, 40, 10);
    let rays = &sets[0].1;
    for layout in LayoutId::all() {
        let enc = encode(&p, layout, 8);
        let gb = GpuBvh::upload(&g, &enc).unwrap();
        let k = builtin(&g, &Variant::new(layout, 8, 1), PacketImpl::Single, false);
        for n in [1usize, 63, 65, 1000] {
            let r = &rays[..n];
            let a = k.run(&g, &gb, r, 1, 2).unwrap();
            assert_eq!(a.times_ms.len(), 2);
            assert_same_hits(&format!("{layout} n={n}"), r, &enc.trace_raw_default(r), &a.hits);
        }
        // Rays pointing away from the scene: all misses.
        let away: Vec<Ray> = (0..100)
            .map(|i| Ray { origin: [100.0, i as f32, 0.0], tmin: 0.0, dir: [1.0, 0.0, 0.0], tmax: f32::INFINITY })
            .collect();
        let a = k.run(&g, &gb, &away, 0, 1).unwrap();
        assert!(a.hits.iter().all(|h| h.prim == -1 && h.t == f32::INFINITY));
    }
    clean(&g);
}

#[test]
fn packet_edge_cases_partial_packets_and_all_misses() {
    let g = gpu();
    let p = prepare(&scene_path("stanford-bunny.obj"));
    let rays = &ray_sets(&p, 40, 10)[0].1;
    let r1000 = &rays[..1000];
    let away: Vec<Ray> = (0..130)
        .map(|i| Ray { origin: [1.0, i as f32 * 0.01, 0.0], tmin: 0.0, dir: [1.0, 0.0, 0.0], tmax: f32::INFINITY })
        .collect();
    for layout in LayoutId::all() {
        let enc = encode(&p, layout, 4);
        let gb = GpuBvh::upload(&g, &enc).unwrap();
        let v = Variant::new(layout, 4, 64);
        let k = builtin(&g, &v, PacketImpl::Shared, true);
        let a = k.run(&g, &gb, r1000, 0, 1).unwrap();
        let (hits, counters) = enc.trace_raw(r1000, 64, v.math, halftrace::precision::FloatControls::On);
        assert_same_hits("1000 rays, P=64", r1000, &hits, &a.hits);
        assert_eq!(a.counters.unwrap(), counters);
        let m = k.run(&g, &gb, &away, 0, 1).unwrap();
        assert!(m.hits.iter().all(|h| h.prim == -1));
        let c = m.counters.unwrap();
        assert!(
            c.iter().all(|c| c.nodes == 0 && c.tri_tests == 0 && c.packet_nodes == 0),
            "all-miss packets visit nothing"
        );
    }
    clean(&g);
}
