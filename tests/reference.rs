//! CPU reference traversal conformance: f32 against brute force, every other layout in every
//! math mode against f32 on every test scene, every B and every ray kind including the
//! grazing set.

mod common;
use common::*;
use halftrace::base::Hit;
use halftrace::bvh::BRANCHINGS;
use halftrace::layout::traverse::branch_work;
use halftrace::layout::LayoutId;
use rayon::prelude::*;

#[test]
fn f32_traversal_equals_brute_force() {
    for name in ["teapot.obj", "cornell_box.obj", "smallpine.obj"] {
        let p = prepare(&scene_path(name));
        for (kind, rays) in ray_sets(&p, 40, 1500) {
            let expected: Vec<Hit> = rays.par_iter().map(|r| p.scene.brute_force(r)).collect();
            assert!(expected.iter().any(|h| h.is_hit()), "{name} {kind}: no ray hits; the test would be vacuous");
            for b in BRANCHINGS {
                let (hits, _) = encode(&p, LayoutId::f32(), b).reference_default(&rays);
                assert_same_hits(&format!("{name} f32 B={b} {kind} vs brute force"), &rays, &expected, &hits);
            }
        }
    }
}

#[test]
fn every_layout_equals_f32_on_every_scene_b_ray_kind_and_math_mode() {
    // Every conservative layout (f16h-poster, the poster's literal algorithm, is not: its
    // disagreements are counted by the sweep and the test below).
    let layouts: Vec<LayoutId> = LayoutId::all().filter(|&l| l != LayoutId::f32() && l.info().conservative).collect();
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
                let (hf, cf) = f.reference_default(rays);
                f32_boxes += cf.iter().map(|c| c.box_tests as u64).sum::<u64>();
                for enc in &encoded {
                    for &math in enc.layout.info().maths {
                        let (hh, ch) = enc.reference(rays, 1, math, halftrace::precision::FloatControls::On);
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
        eprintln!(
            "{what} == f32 on {total} rays; box tests vs f32 {:.3}; re-anchors per ray {:.3}",
            boxes as f64 / f32_boxes as f64,
            reanchors as f64 / total as f64
        );
    }
}

#[test]
fn traversal_is_deterministic_and_hits_exist() {
    let p = prepare(&scene_path("teapot_in_stadium.obj"));
    let sets = ray_sets(&p, 32, 500);
    let h = encode(&p, layout("f16h"), 8);
    for (kind, rays) in &sets {
        let a = h.reference_default(rays);
        let b = h.reference_default(rays);
        assert_eq!(a.1, b.1, "{kind}: counters differ between runs");
        assert_same_hits(kind, rays, &a.0, &b.0);
        assert!(a.0.iter().any(|x| x.is_hit()), "{kind}: nothing hit");
    }
}

/// Adversarial scenes and rays for every conservative layout, math mode and B: clusters of
/// tiny and large triangles far from each other and from the origin (where one global fp16
/// grid is coarse and per-node frames matter), rays aimed exactly at vertices and along edges
/// and faces (where a box is touched only at its boundary), axis-parallel rays and rays with
/// zero components. Each must return exactly the f32 closest hits; a layout that drops any
/// of its outward roundings or widenings fails here.
#[test]
fn conservative_layouts_hold_on_adversarial_scenes_and_rays() {
    use glam::Vec3;
    use halftrace::base::Ray;
    use halftrace::scene::Scene;
    use proptest::prelude::*;
    use proptest::test_runner::{Config, TestRunner};
    let layouts: Vec<LayoutId> = LayoutId::all().filter(|&l| l != LayoutId::f32() && l.info().conservative).collect();
    let mut runner = TestRunner::new(Config { cases: 48, ..Config::default() });
    let cluster = (
        prop::array::uniform3(-1.0f32..1.0),
        prop_oneof![Just(1e-3f32), Just(1.0f32), Just(1e3f32), Just(1e6f32)],
        prop_oneof![Just(1e-4f32), Just(1e-2f32), Just(1.0f32)],
        1usize..40,
    );
    let strat = (prop::collection::vec(cluster, 1..5), any::<u64>());
    let rays_total = std::sync::atomic::AtomicUsize::new(0);
    runner
        .run(&strat, |(clusters, seed)| {
            let mut rng = halftrace::base::Rng::new(seed);
            let mut u = || (rng.next_u64() >> 40) as f32 / (1u64 << 24) as f32;
            let mut tris = Vec::new();
            for (c, dist, size, n) in &clusters {
                let centre = Vec3::from(*c) * *dist;
                for _ in 0..*n {
                    let p = centre + Vec3::new(u() - 0.5, u() - 0.5, u() - 0.5) * *size * 20.0;
                    let mut v =
                        [p, p + Vec3::new(u(), u(), u() * 0.1) * *size, p + Vec3::new(u() * 0.1, u(), u()) * *size];
                    if u() < 0.3 {
                        // axis-aligned: a face in a box plane
                        let z = v[0].z;
                        for w in &mut v {
                            w.z = z;
                        }
                    }
                    tris.push(v);
                }
            }
            let Ok(scene) = Scene::from_triangles("adversarial", tris.clone()) else { return Ok(()) };
            let p = Prepared { bin: halftrace::bvh::build_binary(&scene), scene };
            let lo = p.bin.nodes[0].bounds.min;
            let hi = p.bin.nodes[0].bounds.max;
            let diag = (hi - lo).length();
            let mut rays = Vec::new();
            for t in tris.iter().take(60) {
                for (k, target) in
                    [t[0], t[1], t[2], (t[0] + t[1]) * 0.5, (t[1] + t[2]) * 0.5, (t[0] + t[1] + t[2]) / 3.0]
                        .into_iter()
                        .enumerate()
                {
                    let d = match k % 3 {
                        0 => Vec3::new(u() - 0.5, u() - 0.5, u() - 0.5),
                        1 => Vec3::new(0.0, 0.0, if u() < 0.5 { 1.0 } else { -1.0 }),
                        _ => (t[1] - t[0]) + Vec3::new(0.0, 0.0, (u() - 0.5) * 1e-6),
                    };
                    if d.length() == 0.0 {
                        continue;
                    }
                    let d = d.normalize();
                    let back = if u() < 0.5 { diag } else { diag * 1e-3 };
                    rays.push(Ray::new(target - d * back, d, 0.0, f32::INFINITY));
                    // along the edge itself, starting on it
                    rays.push(Ray::new(t[0], (t[2] - t[0]).normalize_or_zero() + Vec3::X * 1e-7, 0.0, f32::INFINITY));
                }
            }
            rays.retain(|r| r.d().length() > 0.0 && r.d().is_finite());
            rays_total.fetch_add(rays.len(), std::sync::atomic::Ordering::Relaxed);
            for b in [2, 4, 8, 16] {
                let f = encode(&p, LayoutId::f32(), b);
                let (hf, _) = f.reference_default(&rays);
                for &l in &layouts {
                    let enc = encode(&p, l, b);
                    use halftrace::precision::FloatControls;
                    // The builds without float controls keep the hits too (their own bounds).
                    let fcs: &[FloatControls] = if l.info().float_controls_off {
                        &[FloatControls::On, FloatControls::Off]
                    } else {
                        &[FloatControls::On]
                    };
                    for (&math, &fc) in l.info().maths.iter().flat_map(|m| fcs.iter().map(move |f| (m, f))) {
                        let (h, _) = enc.reference(&rays, 1, math, fc);
                        let bad = (0..rays.len()).find(|&i| !hf[i].same_bits(&h[i]));
                        prop_assert!(
                            bad.is_none(),
                            "{l}/{} {} B={b}: ray {:?}: f32 {:?}, got {:?}",
                            math.name(),
                            fc.name(),
                            rays[bad.unwrap()],
                            hf[bad.unwrap()],
                            h[bad.unwrap()]
                        );
                    }
                }
            }
            Ok(())
        })
        .unwrap();
    let n = rays_total.into_inner();
    assert!(n > 1000, "only {n} rays: the test would be weak");
}

/// Finite but huge coordinates (the teapot scaled by 2^66, about 1e20): every layout returns
/// the hits of the unscaled scene — the same triangles at t scaled by exactly 2^66 — where
/// products of coordinates used to overflow fp32 and lose every hit.
#[test]
fn huge_coordinates_keep_every_hit() {
    use glam::Vec3;
    use halftrace::scene::Scene;
    let p = prepare(&scene_path("teapot.obj"));
    let k = 2f32.powi(66);
    let big =
        Scene::from_triangles("teapot_2e66", p.scene.tris.iter().map(|t| t.map(|v: Vec3| v * k)).collect()).unwrap();
    let q = Prepared { bin: halftrace::bvh::build_binary(&big), scene: big };
    let rays = &ray_sets(&p, 32, 0)[0].1;
    let big_rays = &ray_sets(&q, 32, 0)[0].1;
    let base = encode(&p, LayoutId::f32(), 4).reference_default(rays).0;
    assert!(base.iter().filter(|h| h.is_hit()).count() > 100);
    for l in LayoutId::all().filter(|l| l.info().conservative) {
        for b in [4, 8] {
            let enc = encode(&q, l, b);
            for &math in l.info().maths {
                let got = enc.reference(big_rays, 1, math, halftrace::precision::FloatControls::On).0;
                for (i, (g, e)) in got.iter().zip(&base).enumerate() {
                    assert!(
                        g.prim == e.prim && (g.prim < 0 || g.t == e.t * k),
                        "{l}/{} B={b} ray {i}: {g:?} vs unscaled {e:?} (t × 2^66 = {})",
                        math.name(),
                        e.t * k
                    );
                }
            }
        }
    }
}

/// The host baseline (Embree 3 on the CPU) against the f32 reference on every test scene
/// (the bar of common::baseline_agrees_with_f32; Embree's triangle test is not ours).
#[test]
fn embree_baseline_agrees_with_f32_on_every_scene() {
    baseline_agrees_with_f32("embree", &halftrace::baseline::embree::host(), 1);
}

/// Kernels that defer entries (trav.comp, `DEFER_ENTRIES`: f16h and f16h-poster)
/// derive a child's entry when they enter the child, with the node's visit recomputed under the
/// closest hit found by then, and keep only the hit result of the push. That gives the same
/// entries only if a layout's box-test data and child entries ignore the closest hit: checked
/// here along each ray's whole walk (every hit child, whatever the closest hit would cull) on
/// the adversarial teapot_in_stadium and the teapot, every math mode, with float controls on
/// and off — each child tested and entered under best = tmax, under best = the node's own
/// entry bound (the nearest best that still visits it) and under best = tmin (a child is
/// entered after its nearer siblings' subtrees, whose hits may lie before its parent's
/// bound), the test data, entries and counters compared.
#[test]
fn deferred_entries_ignore_the_closest_hit() {
    use halftrace::base::{Counters, RayPre};
    use halftrace::layout::f16h::F16h;
    use halftrace::layout::f16h_poster::F16hPoster;
    use halftrace::layout::{decode_child, Layout, Node};
    use halftrace::precision::FloatControls;

    fn walk<L: Layout, const B: usize>(
        enc: &halftrace::layout::encoded::Encoded,
        rays: &[halftrace::base::Ray],
    ) -> usize
    where
        L::Entry: std::fmt::Debug,
        L::ChildHit: std::fmt::Debug,
    {
        let (nodes, root) = enc.typed::<L, B>().unwrap();
        let mut checked = 0;
        for &(math, fc) in L::INFO
            .maths
            .iter()
            .flat_map(|m| {
                let offs: &[FloatControls] = if L::INFO.float_controls_off {
                    &[FloatControls::On, FloatControls::Off]
                } else {
                    &[FloatControls::On]
                };
                offs.iter().map(move |&f| (*m, f))
            })
            .collect::<Vec<_>>()
            .iter()
        {
            for ray in rays {
                let r = RayPre::new(ray);
                let lr = L::ray(&r, math, fc);
                let (lo, hi): ([f32; 3], [f32; 3]) = (enc.root_box.min.into(), enc.root_box.max.into());
                let (near, far) = halftrace::base::slab32(&r, lo, hi, r.tmin, r.tmax);
                if near > far {
                    continue;
                }
                let mut stack = vec![(0u32, L::root_entry(root, &r, &lr, near))];
                while let Some((ni, e)) = stack.pop() {
                    let n = &nodes[ni as usize];
                    let far_v = L::visit::<B>(n, root, &e, &r, &lr, r.tmax);
                    let near_v = L::visit::<B>(n, root, &e, &r, &lr, L::entry_t(&e));
                    let low_v = L::visit::<B>(n, root, &e, &r, &lr, r.tmin);
                    for s in 0..B {
                        let w = n.child(s);
                        if w == halftrace::interface::CHILD_EMPTY {
                            break;
                        }
                        let (Some(a), b) = (
                            L::test_child::<B>(n, s, &e, &far_v, &r, &lr),
                            L::test_child::<B>(n, s, &e, &near_v, &r, &lr),
                        ) else {
                            continue;
                        };
                        for b in [b, L::test_child::<B>(n, s, &e, &low_v, &r, &lr)].into_iter().flatten() {
                            assert_eq!(
                                format!("{a:?}"),
                                format!("{b:?}"),
                                "{} ray {ray:?} node {ni} slot {s}: box test",
                                L::INFO.name
                            );
                        }
                        if let halftrace::bvh::ChildRef::Inner(j) = decode_child(w) {
                            let mut ca = Counters::default();
                            let ea = L::child_entry::<B>(n, s, &e, &far_v, &a.1, &r, &lr, &mut ca);
                            for v in [&near_v, &low_v] {
                                let mut cb = Counters::default();
                                let eb = L::child_entry::<B>(n, s, &e, v, &a.1, &r, &lr, &mut cb);
                                assert_eq!(
                                    format!("{ea:?}"),
                                    format!("{eb:?}"),
                                    "{} ray {ray:?} node {ni} slot {s}: entry",
                                    L::INFO.name
                                );
                                assert_eq!(ca, cb);
                            }
                            checked += 1;
                            if stack.len() < 4096 {
                                stack.push((j, ea));
                            }
                        }
                    }
                }
            }
        }
        checked
    }

    for name in ["teapot_in_stadium.obj", "teapot.obj"] {
        let p = prepare(&scene_path(name));
        let rays: Vec<_> = ray_sets(&p, 24, 300).into_iter().flat_map(|(_, r)| r).collect();
        for b in [2usize, 4, 8, 16] {
            let f16h = encode(&p, LayoutId::parse("f16h").unwrap(), b);
            let poster = encode(&p, LayoutId::parse("f16h-poster").unwrap(), b);
            let n = match b {
                2 => walk::<F16h, 2>(&f16h, &rays) + walk::<F16hPoster, 2>(&poster, &rays),
                4 => walk::<F16h, 4>(&f16h, &rays) + walk::<F16hPoster, 4>(&poster, &rays),
                8 => walk::<F16h, 8>(&f16h, &rays) + walk::<F16hPoster, 8>(&poster, &rays),
                _ => walk::<F16h, 16>(&f16h, &rays) + walk::<F16hPoster, 16>(&poster, &rays),
            };
            assert!(n > 1000, "{name} B={b}: only {n} child entries checked");
        }
    }
}

/// The loop work the estimate weighs a kernel's loops with (`layout::traverse::loop_work`)
/// follows the reference's own counters: summed over rays each on its own, a visit per
/// counted node and a triangle pass per triangle test; in lockstep waves a wave makes at least
/// as many passes as its busiest lane and no more than its lanes together, and on incoherent
/// (ao, diffuse) rays strictly more than the average lane.
#[test]
fn loop_work_follows_the_counters_and_lockstep_costs_more() {
    use halftrace::precision::{FloatControls, Math};
    let p = prepare(&scene_path("sponza_dabrovic.obj"));
    for (kind, rays) in &ray_sets(&p, 48, 64) {
        for (name, math) in [("f32", Math::F32), ("f16h", Math::F16), ("q8", Math::F32)] {
            for b in [4, 8] {
                let enc = encode(&p, layout(name), b);
                let what = format!("{name} B{b} {kind}");
                let counters = enc.reference(rays, 1, math, FloatControls::On).1;
                let (lock, lanes) = enc.layout.imp().loop_work(&enc, rays, 1, 64, math, FloatControls::On);
                let nodes: u64 = counters.iter().map(|c| c.nodes as u64).sum();
                let tris: u64 = counters.iter().map(|c| c.tri_tests as u64).sum();
                assert_eq!((lanes.visits, lanes.tri_passes), (nodes, tris), "{what}: lane sums against the counters");
                assert_eq!(
                    (lanes.rays, lanes.waves, lock.rays),
                    (rays.len() as u64, rays.len() as u64, rays.len() as u64),
                    "{what}"
                );
                assert_eq!(lock.waves, rays.len().div_ceil(64) as u64, "{what}");
                assert!(lanes.steps >= lanes.visits && lock.steps >= lock.visits, "{what}: {lock:?}");
                assert!(lock.steps <= lanes.steps && lock.tri_passes <= lanes.tri_passes, "{what}: {lock:?} {lanes:?}");
                let avg = |x: u64| x as f64 / 64.0;
                if kind == "ao" || kind == "diffuse" {
                    assert!(lock.steps as f64 > avg(lanes.steps), "{what}: lockstep {lock:?} against lanes {lanes:?}");
                    assert!(lock.tri_passes as f64 > avg(lanes.tri_passes), "{what}: {lock:?} {lanes:?}");
                }
                // Each ray twice in a row: twice the lanes' work, per ray the same.
                let twice: Vec<_> = rays.iter().flat_map(|r| [*r, *r]).collect();
                let (_, lanes2) = enc.layout.imp().loop_work(&enc, &twice, 1, 64, math, FloatControls::On);
                assert_eq!(
                    (lanes2.steps, lanes2.visits, lanes2.tri_passes),
                    (2 * lanes.steps, 2 * lanes.visits, 2 * lanes.tri_passes),
                    "{what}"
                );
                // Packets of 8: a wave is 8 packets in lockstep; a packet's visits are its packet
                // counter; a wave makes no more passes than its packets together.
                let (plock, plane) = enc.layout.imp().loop_work(&enc, rays, 8, 64, math, FloatControls::On);
                let pc = enc.reference(rays, 8, math, FloatControls::On).1;
                let packet_nodes: u64 = pc.iter().map(|c| c.packet_nodes as u64).sum();
                assert_eq!(plane.visits, packet_nodes, "{what} P8: visits against the packet counters");
                // A packet runs a visit's triangle loop as long as its busiest lane: at most its
                // lanes' triangles together, at least their average.
                let ptris: u64 = pc.iter().map(|c| c.tri_tests as u64).sum();
                assert!(
                    plane.tri_passes <= ptris && 8 * plane.tri_passes >= ptris,
                    "{what} P8: {} triangle passes against {ptris} triangle tests",
                    plane.tri_passes
                );
                assert_eq!(
                    (plane.waves, plock.waves),
                    (rays.len().div_ceil(8) as u64, rays.len().div_ceil(64) as u64),
                    "{what} P8"
                );
                assert!(
                    plock.steps <= plane.steps && plock.tri_passes <= plane.tri_passes,
                    "{what} P8: {plock:?} {plane:?}"
                );
                // The named branches' counts (estimate's branch weights) pass through the same
                // triangle passes, single rays and packets, in lockstep and alone.
                for (p, l, a) in [(1, lock, lanes), (8, plock, plane)] {
                    let reads = enc.layout.imp().mem_reads(&enc, rays, p, math, FloatControls::On);
                    let (bl, ba) = branch_work(&reads, rays, &enc.tris, p, 64);
                    assert_eq!((bl.tri_passes, ba.tri_passes), (l.tri_passes, a.tri_passes), "{what} P{p}");
                    let [huge, edges, cross, flat, divide, candidate, best, note] = ba.taken;
                    let [_, ledges, lcross, ..] = bl.taken;
                    // Alone, each test takes one of flat and divide past the edge functions; every
                    // side lies past the one before it; a wave takes a side in a pass when any lane
                    // does: no more often than its passes, no less than its lanes' ÷ 64.
                    assert_eq!(huge, 0, "{what} P{p}: nothing here is beyond 2^40");
                    assert!(ba.tri_passes >= edges && edges >= cross && cross >= candidate, "{what} P{p}: {ba:?}");
                    assert!(candidate >= best + note && best > 0 && edges > cross, "{what} P{p}: {ba:?}");
                    if p == 1 {
                        assert_eq!(cross, flat + divide, "{what}: {ba:?}");
                    }
                    assert!(ledges <= bl.tri_passes && lcross <= ledges, "{what} P{p}: {bl:?}");
                    assert!(64 * ledges >= edges && 64 * lcross >= cross, "{what} P{p}: {bl:?} against {ba:?}");
                    if kind == "ao" || kind == "diffuse" {
                        assert!(ledges as f64 > edges as f64 / 64.0, "{what} P{p}: lockstep takes sides more often");
                    }
                }
            }
        }
    }
}
