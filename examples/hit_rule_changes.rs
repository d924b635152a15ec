//! Why hits changed under the closest-hit rule (`base::hit`): compares hits traced before it
//! (`old.npy`, e.g. by an older `halftrace trace --backend cpu --rays rays.npy --out old.npy`)
//! with this build's f32 reference on the same rays, and sorts each changed ray by cause.
//!
//! cargo run --release --example hit_rule_changes -- SCENE RAYS.npy OLD_HITS.npy [B]

use halftrace::base::{tri, Hit, RayPre};
use halftrace::layout::{Encoded, LayoutId};

fn main() -> anyhow::Result<()> {
    let args: Vec<String> = std::env::args().collect();
    anyhow::ensure!(args.len() >= 4, "usage: hit_rule_changes SCENE RAYS.npy OLD_HITS.npy [B]");
    let scene = halftrace::scene::load(args[1].as_ref())?;
    let rays = halftrace::npy::read_rays(args[2].as_ref())?;
    let old = halftrace::npy::read_hits(args[3].as_ref())?;
    let b: usize = args.get(4).map_or(Ok(4), |s| s.parse())?;
    anyhow::ensure!(old.len() == rays.len(), "{} hits for {} rays", old.len(), rays.len());
    let bin = halftrace::bvh::build_binary(&scene);
    let new = Encoded::new(&scene, &bin, LayoutId::f32(), b)?.reference_default(&rays).0;
    // The brute force of the old rule: the watertight test's t >= tmin, nearest, ties to the
    // lower prim — no box rule.
    let old_brute = |r: &halftrace::base::Ray| {
        let p = RayPre::new(r);
        let mut best = Hit { t: r.tmax, prim: i32::MAX, u: 0.0, v: 0.0 };
        for (i, t) in scene.tris.iter().enumerate() {
            let v = [t[0].x, t[0].y, t[0].z, t[1].x, t[1].y, t[1].z, t[2].x, t[2].y, t[2].z];
            if let Some((tt, u, vv)) = tri::intersect(&p, &v) {
                if tt >= p.tmin && (tt < best.t || (tt == best.t && (i as i32) < best.prim)) {
                    best = Hit { t: tt, prim: i as i32, u, v: vv };
                }
            }
        }
        if best.prim == i32::MAX {
            Hit::MISS
        } else {
            best
        }
    };
    let (mut culled, mut raised, mut rejected, mut other) = (0, 0, 0, 0);
    let mut changed = 0;
    for i in 0..rays.len() {
        if new[i].same_bits(&old[i]) {
            continue;
        }
        changed += 1;
        let ob = old_brute(&rays[i]);
        let why = if new[i].same_bits(&ob) {
            // The old traversal missed what the old rule's brute force found: a culling the old
            // rule got wrong (tight boxes, near > best), which the padded boxes keep.
            culled += 1;
            "old traversal culled the hit its own brute force finds"
        } else if new[i].prim == ob.prim && new[i].t > ob.t {
            raised += 1;
            "the box rule raises t to the padded box's certified entry"
        } else if ob.is_hit() && new[i].prim != ob.prim {
            rejected += 1;
            "the box rule rejects the old rule's nearest hit"
        } else {
            other += 1;
            "other"
        };
        if changed <= 8 {
            println!(
                "ray {i} {:?}\n  old {:?}\n  new {:?}\n  old brute force {:?}\n  -> {why}",
                rays[i], old[i], new[i], ob
            );
        }
    }
    println!(
        "{}: {} rays, {changed} changed at B = {b}: {culled} old culling wrong, {raised} t raised, {rejected} \
         rejected by the box rule, {other} other",
        scene.name,
        rays.len()
    );
    Ok(())
}
