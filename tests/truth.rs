//! The hunt for truth beside the hunt for consistency (tests/exact.rs): hits checked against
//! exact geometry — exact predicates on the fp32 inputs, integer arithmetic
//! (`base::exact`) — on closed meshes (cubes, tessellated cubes, spheres; axis-aligned and
//! rotated) seen from 1× to 10⁴× their extent, placed 0 to 10⁴ extents from the origin, with
//! rays aimed exactly at vertices, edge midpoints and face points, and tmin set at and around
//! the front face's crossing.
//!
//! The closest-hit rule (`base::ClosestTrue`) must report a hit exactly where the exact ray
//! meets the mesh, on a triangle the exact ray crosses at s ≤ t', and every conservative
//! layout's traversal must return its brute force's hits bit for bit. The box rule it replaced
//! (`base::ClosestBox`) is measured beside it and must be seen to fail here (docs/layouts.md,
//! "True hits").

use glam::{Mat3, Vec3};
use halftrace::base::exact::{crossing_in, next_down, next_up};
use halftrace::base::{Ray, RayPre, Rng};
use halftrace::layout::{Encoded, LayoutId};
use halftrace::precision::FloatControls;
use halftrace::scene::Scene;
use rayon::prelude::*;
use std::cmp::Ordering;

/// A cube [−1, 1]³ with each face split into n×n quads of two triangles.
fn cube(n: usize) -> Vec<[Vec3; 3]> {
    let mut t = Vec::new();
    for axis in 0..3 {
        for sign in [-1.0f32, 1.0] {
            let p = |i: usize, j: usize| -> Vec3 {
                let (a, b) = (-1.0 + 2.0 * i as f32 / n as f32, -1.0 + 2.0 * j as f32 / n as f32);
                let mut v = [0.0; 3];
                v[axis] = sign;
                v[(axis + 1) % 3] = a;
                v[(axis + 2) % 3] = b;
                Vec3::from(v)
            };
            for i in 0..n {
                for j in 0..n {
                    t.push([p(i, j), p(i + 1, j), p(i + 1, j + 1)]);
                    t.push([p(i, j), p(i + 1, j + 1), p(i, j + 1)]);
                }
            }
        }
    }
    t
}

/// A UV sphere of radius 1.
fn sphere(rings: usize, segs: usize) -> Vec<[Vec3; 3]> {
    let p = |i: usize, j: usize| -> Vec3 {
        if i == 0 {
            return Vec3::Z;
        }
        if i == rings {
            return -Vec3::Z;
        }
        let th = std::f32::consts::PI * i as f32 / rings as f32;
        let ph = 2.0 * std::f32::consts::PI * (j % segs) as f32 / segs as f32;
        Vec3::new(th.sin() * ph.cos(), th.sin() * ph.sin(), th.cos())
    };
    let mut t = Vec::new();
    for i in 0..rings {
        for j in 0..segs {
            let (a, b, c, d) = (p(i, j), p(i, j + 1), p(i + 1, j), p(i + 1, j + 1));
            if i > 0 {
                t.push([a, c, b]);
            }
            if i + 1 < rings {
                t.push([b, c, d]);
            }
        }
    }
    t
}

#[derive(Default, Debug)]
struct Tally {
    rays: usize,
    true_hits: usize,
    new_wrong: Vec<String>,
    new_rare_rays: usize,
    old_lost: usize,
    old_false: usize,
    /// The largest (t' − s)·|d|∞ seen, as a share of the ∞-norm distance from the origin to
    /// the hit triangle's farthest vertex.
    worst_dt: f64,
    /// Traversals (layout, B, P) whose hits differ from the brute force, and the rays they
    /// flagged for the exact re-trace.
    traversal_wrong: Vec<String>,
    flagged: usize,
    traversals: usize,
}

/// Every ray of one mesh placement: the truth, the true rule and the box rule.
fn hunt(name: &str, tris: &[[Vec3; 3]], dist: f32, rng_seed: u64) -> Tally {
    let scene = Scene::from_triangles(name, tris.to_vec()).unwrap();
    let mut rng = Rng::new(rng_seed);
    let extent = (scene.bounds.max - scene.bounds.min).max_element();
    // Targets: every vertex and edge midpoint, and points inside faces.
    let mut targets = Vec::new();
    for t in tris.iter().step_by((tris.len() / 24).max(1)) {
        targets.push(t[0]);
        targets.push((t[0] + t[1]) * 0.5);
        targets.push(t[0] * 0.2 + t[1] * 0.3 + t[2] * 0.5);
    }
    let mut tally = Tally::default();
    let mut rays = Vec::new();
    let mut expected = Vec::new();
    for target in targets {
        let dir = Vec3::new(rng.next_f32() - 0.5, rng.next_f32() - 0.5, rng.next_f32() - 0.5).normalize_or(Vec3::Z);
        let o = target - dir * (dist * extent);
        let d = target - o;
        let base = Ray::new(o, d, 0.0, f32::INFINITY);
        // tmin at 0, then at and around the first exact crossing (the front face's).
        let first = truth(&scene, &base).map(|(_, s)| s);
        let mut tmins = vec![0.0f32];
        if let Some(s) = first {
            tmins.extend([next_down(s), s, next_up(s)]);
        }
        for tmin in tmins {
            let ray = Ray::new(o, d, tmin, f32::INFINITY);
            tally.rays += 1;
            let truth = truth(&scene, &ray);
            let (new, rare) = scene.brute_force_counted(&ray);
            rays.push(ray);
            expected.push(new);
            let old = scene.brute_force_box(&ray);
            tally.new_rare_rays += (rare > 0) as usize;
            tally.true_hits += truth.is_some() as usize;
            match (truth.is_some(), old.is_hit()) {
                (true, false) => tally.old_lost += 1,
                (false, true) => tally.old_false += 1,
                _ => {}
            }
            let r = RayPre::new(&ray);
            let wrong = match (truth, new.is_hit()) {
                (Some(_), false) => Some("lost hit".to_string()),
                (None, true) => Some(format!("false hit {new:?}")),
                (Some(_), true) => {
                    // The reported triangle is crossed by the exact ray at s ≤ t', and t' − s is within
                    // the stated bound: 2⁻⁹ of the farthest vertex's depth and 2⁻²¹ of t (asserted at 2⁻⁸).
                    let x = crossing_in(&r, &scene.verts(new.prim as usize));
                    match x {
                        None => Some(format!("hit {new:?} on a triangle the exact ray does not cross")),
                        Some(x) if x.s.cmp_f32(new.t) == Ordering::Greater => {
                            Some(format!("t' {} below the exact crossing {}", new.t, x.s.to_f64()))
                        }
                        // The nearest exact crossing: no surface in front of it is passed through.
                        Some(x) if Some(x.s.round_up()) != truth.map(|(_, s)| s) => {
                            Some(format!("hit {new:?} at {} is not the nearest exact crossing {truth:?}", x.s.to_f64()))
                        }
                        Some(x) => {
                            // t' − s in world units, against the triangle's farthest vertex from o
                            let t = &scene.tris[new.prim as usize];
                            let far = t.iter().map(|v| (*v - o).abs().max_element()).fold(0.0f32, f32::max) as f64;
                            let rel = (new.t as f64 - x.s.to_f64()) * d.abs().max_element() as f64 / far;
                            tally.worst_dt = tally.worst_dt.max(rel);
                            (rel > 1.0 / 256.0)
                                .then(|| format!("t' {} far from the exact crossing {}", new.t, x.s.to_f64()))
                        }
                    }
                }
                (None, false) => None,
            };
            if let Some(w) = wrong {
                tally.new_wrong.push(format!("{name} at {dist}× its extent: ray {ray:?}: {w}"));
            }
        }
    }
    // Every conservative layout's traversal (its CPU reference: fast rule, flagged rays
    // re-traced) returns the brute force's hits bit for bit, at B = 4 and 8, single rays and
    // packets of 8.
    let bin = halftrace::bvh::build_binary(&scene);
    for layout in LayoutId::all().filter(|l| l.info().conservative) {
        for b in [4, 8] {
            let enc = Encoded::new(&scene, &bin, layout, b).unwrap();
            for (p, &math) in [1, 8].into_iter().zip(layout.info().maths.iter().cycle()) {
                tally.traversals += 1;
                let (raw, _) = enc.trace_raw(&rays, p, math, FloatControls::On);
                tally.flagged += raw.iter().filter(|h| h.is_flagged()).count();
                let (got, _) = enc.reference(&rays, p, math, FloatControls::On);
                if let Some(i) = (0..rays.len()).find(|&i| !got[i].same_bits(&expected[i])) {
                    tally.traversal_wrong.push(format!(
                        "{name} at {dist}×, {layout} B{b} P{p} {}: ray {:?}: {:?}, brute force {:?}",
                        math.name(),
                        rays[i],
                        got[i],
                        expected[i]
                    ));
                }
            }
        }
    }
    tally
}

/// The first exact crossing of any triangle in the ray's interval: (prim, s rounded up).
fn truth(scene: &Scene, ray: &Ray) -> Option<(usize, f32)> {
    let r = RayPre::new(ray);
    let mut best: Option<(usize, halftrace::base::exact::Ratio)> = None;
    for i in 0..scene.len() {
        if let Some(x) = crossing_in(&r, &scene.verts(i)) {
            let better = match &best {
                None => true,
                Some((_, s)) => (&x.s.n * &s.d).cmp(&(&s.n * &x.s.d)) == Ordering::Less,
            };
            if better {
                best = Some((i, x.s));
            }
        }
    }
    best.map(|(i, s)| (i, s.round_up()))
}

fn placed(tris: &[[Vec3; 3]], rot: Mat3, scale: f32, offset: Vec3) -> Vec<[Vec3; 3]> {
    tris.iter().map(|t| t.map(|v| rot * v * scale + offset)).collect()
}

#[test]
fn closed_meshes_are_hit_exactly_where_the_exact_ray_meets_them() {
    let t0 = std::time::Instant::now();
    let rot = Mat3::from_rotation_x(0.7) * Mat3::from_rotation_z(0.4);
    let meshes: Vec<(&str, Vec<[Vec3; 3]>)> = vec![
        ("cube", cube(1)),
        ("cube4", cube(4)),
        ("sphere", sphere(8, 12)),
        ("cube-rotated", placed(&cube(1), rot, 1.0, Vec3::ZERO)),
        ("sphere-rotated", placed(&sphere(6, 10), rot, 1.0, Vec3::ZERO)),
    ];
    let mut cases = Vec::new();
    for (name, tris) in &meshes {
        for offset in [0.0f32, 1.0, 100.0, 10_000.0] {
            for dist in [1.0f32, 10.0, 100.0, 1000.0, 10_000.0] {
                let moved = placed(tris, Mat3::IDENTITY, 1.0, Vec3::new(0.9, 1.1, 1.0) * offset * 2.0);
                cases.push((format!("{name}@{offset}"), moved, dist));
            }
        }
    }
    let tallies: Vec<Tally> = cases
        .par_iter()
        .enumerate()
        .map(|(k, (name, tris, dist))| hunt(name, tris, *dist, 0x7275_7468 + k as u64))
        .collect();
    let sum = |f: fn(&Tally) -> usize| tallies.iter().map(f).sum::<usize>();
    let wrong: Vec<&String> = tallies.iter().flat_map(|t| &t.new_wrong).collect();
    eprintln!(
        "truth hunt: {} rays over {} placements, {} truly hit; true rule: {} wrong, {} rays took the exact path; \
         worst t' − s: {:.2e} of the farthest vertex's distance; box rule: {} hits lost, {} false hits ({:.1} s)",
        sum(|t| t.rays),
        cases.len(),
        sum(|t| t.true_hits),
        wrong.len(),
        sum(|t| t.new_rare_rays),
        tallies.iter().map(|t| t.worst_dt).fold(0.0, f64::max),
        sum(|t| t.old_lost),
        sum(|t| t.old_false),
        t0.elapsed().as_secs_f64()
    );
    assert!(wrong.is_empty(), "{} rays wrong under the true rule; first: {}", wrong.len(), wrong[0]);
    let twrong: Vec<&String> = tallies.iter().flat_map(|t| &t.traversal_wrong).collect();
    eprintln!(
        "traversals: {} (conservative layouts × B 4, 8 × P 1, 8 per placement), {} rays flagged for the exact re-trace",
        sum(|t| t.traversals),
        sum(|t| t.flagged)
    );
    assert!(twrong.is_empty(), "{} traversals differ from the brute force; first: {}", twrong.len(), twrong[0]);
    // The hunt finds what the box rule gets wrong (the repros of the issue): it must.
    assert!(sum(|t| t.old_lost) > 0, "the hunt no longer finds the box rule's lost hits");
}

/// The first repro: one triangle, rays straight down from every height. The true rule
/// hits from every height; the box rule loses it beyond about 4× the extent.
#[test]
fn one_triangle_column_is_hit_from_every_height() {
    let scene =
        Scene::from_triangles("one", vec![[Vec3::ZERO, Vec3::new(1.0, 0.0, 0.0), Vec3::new(0.0, 1.0, 0.0)]]).unwrap();
    let mut old_lost = Vec::new();
    for z in [1.0f32, 4.0, 4.5, 5.0, 10.0, 100.0, 1e4, 1e6] {
        let ray = Ray::new(Vec3::new(0.3, 0.2, z), Vec3::new(0.0, 0.0, -1.0), 0.0, f32::INFINITY);
        let (hit, _) = scene.brute_force_counted(&ray);
        assert!(hit.is_hit() && hit.t >= z && hit.t <= z * (1.0 + 1.0 / 65_536.0), "z = {z}: {hit:?}");
        if !scene.brute_force_box(&ray).is_hit() {
            old_lost.push(z);
        }
    }
    assert_eq!(old_lost, [4.5, 5.0, 10.0, 100.0, 1e4, 1e6], "the box rule's losses moved");
}

/// A triangle of zero area (three vertices exactly on one line) is counted as such when the
/// scene loads and never hit: not by a ray aimed at its edge's midpoint, on any conservative
/// layout, while a triangle of area behind it is. A tiny triangle whose fp32 cross product
/// underflows has area: it is not counted, and the exact rule hits it.
#[test]
fn zero_area_triangles_are_counted_exactly_and_never_hit() {
    let line = [Vec3::new(-1.0, 0.0, 0.0), Vec3::new(0.0, 0.0, 0.0), Vec3::new(1.0, 0.0, 0.0)];
    let floor = [Vec3::new(-2.0, -2.0, -1.0), Vec3::new(2.0, -2.0, -1.0), Vec3::new(0.0, 2.0, -1.0)];
    let t = 1e-25f32;
    let tiny = [Vec3::new(0.0, 0.0, -0.5), Vec3::new(t, 0.0, -0.5), Vec3::new(0.0, t, -0.5)];
    assert_eq!((tiny[1] - tiny[0]).cross(tiny[2] - tiny[0]), Vec3::ZERO, "fp32's cross product underflows");
    let scene = Scene::from_triangles("zero", vec![line, floor, tiny]).unwrap();
    assert_eq!(scene.degenerate, 1, "only the collinear triangle has zero area");
    // Aimed at the midpoints of the line's two edges and at another point of it, from above.
    let rays: Vec<Ray> = [-0.5f32, 0.5, 0.75]
        .iter()
        .map(|&x| Ray::new(Vec3::new(x, 0.0, 3.0), Vec3::new(0.0, 0.0, -1.0), 0.0, f32::INFINITY))
        .collect();
    for r in &rays {
        let (hit, _) = scene.brute_force_counted(r);
        assert_eq!(hit.prim, 1, "{r:?}: {hit:?}");
    }
    let bin = halftrace::bvh::build_binary(&scene);
    for layout in LayoutId::all().filter(|l| l.info().conservative) {
        let enc = Encoded::new(&scene, &bin, layout, 4).unwrap();
        for &math in layout.info().maths {
            let (got, _) = enc.reference(&rays, 1, math, FloatControls::On);
            assert!(got.iter().all(|h| h.prim == 1), "{layout} {}: {got:?}", math.name());
        }
    }
    // Through the line's middle vertex (never hit) onto the tiny triangle's vertex (hit).
    let at_tiny = Ray::new(Vec3::new(0.0, 0.0, 3.0), Vec3::new(0.0, 0.0, -1.0), 0.0, f32::INFINITY);
    assert_eq!(scene.brute_force_counted(&at_tiny).0.prim, 2, "the tiny triangle has area and is hit at its vertex");
}
