//! Every ray whose hit changed between two builds, classified by exact geometry
//! (`base::exact`): traced by an older `halftrace trace --backend cpu --layout f32 --save-rays
//! RAYS.npy --out OLD.npy` and by this one on the same rays (`--rays RAYS.npy --out NEW.npy`).
//! Written for issue 50's change from the box rule to the true closest-hit rule; every new hit
//! is also checked to lie on a triangle the exact ray crosses at s ≤ t'.
//!
//! cargo run --release --example rule_change -- SCENE RAYS.npy OLD.npy NEW.npy

use halftrace::base::exact::crossing_in;
use halftrace::base::{Hit, RayPre};
use std::cmp::Ordering;
use std::collections::BTreeMap;

fn main() -> anyhow::Result<()> {
    let args: Vec<String> = std::env::args().collect();
    anyhow::ensure!(args.len() == 5, "usage: rule_change SCENE RAYS.npy OLD.npy NEW.npy");
    let scene = halftrace::scene::load(args[1].as_ref())?;
    let rays = halftrace::npy::read_rays(args[2].as_ref())?;
    let old = halftrace::npy::read_hits(args[3].as_ref())?;
    let new = halftrace::npy::read_hits(args[4].as_ref())?;
    anyhow::ensure!(old.len() == rays.len() && new.len() == rays.len(), "hit files and rays differ in length");
    let mut classes: BTreeMap<&str, usize> = BTreeMap::new();
    let (mut worst_rel, mut examples) = (0f64, Vec::new());
    for i in 0..rays.len() {
        let (o, n) = (&old[i], &new[i]);
        let r = RayPre::new(&rays[i]);
        let crossing = |h: &Hit| crossing_in(&r, &scene.verts(h.prim as usize));
        // The new hit is true: its triangle is crossed at s ≤ t'.
        if n.is_hit() {
            match crossing(n) {
                Some(x) if x.s.cmp_f32(n.t) != Ordering::Greater => {}
                _ => {
                    *classes.entry("WRONG: new hit not on an exact crossing at s <= t'").or_default() += 1;
                    examples.push(format!("ray {i} {:?}: new {n:?}", rays[i]));
                    continue;
                }
            }
        }
        if o.same_bits(n) {
            *classes.entry("unchanged").or_default() += 1;
            continue;
        }
        let class = match (o.is_hit(), n.is_hit()) {
            (false, false) => "miss in both (bits differ)",
            (false, true) => "hit the box rule lost",
            (true, false) => match crossing(o) {
                None => "false hit of the box rule (now a miss)",
                Some(_) => "WRONG: now a miss, but the old triangle is crossed",
            },
            (true, true) if o.prim == n.prim => {
                worst_rel = worst_rel.max((n.t as f64 - o.t as f64).abs() / (o.t as f64).abs().max(1e-30));
                "rounding: same triangle, t' is the certified upper bound"
            }
            (true, true) => match (crossing(o), crossing(n)) {
                (None, _) => "false hit of the box rule (a true hit behind it now)",
                (Some(xo), Some(xn)) => {
                    let c = (&xn.s.n * &xo.s.d).cmp(&(&xo.s.n * &xn.s.d));
                    match c {
                        Ordering::Less => "nearer hit the box rule lost",
                        Ordering::Equal => "tie at one exact crossing (shared edge or vertex): the lower prim wins",
                        Ordering::Greater => "WRONG: a farther triangle won",
                    }
                }
                (Some(_), None) => unreachable!("checked above"),
            },
        };
        if class.starts_with("WRONG") || examples.len() < 3 && !class.starts_with("rounding") {
            examples.push(format!("ray {i} {:?}: old {o:?}, new {n:?}: {class}", rays[i]));
        }
        *classes.entry(class).or_default() += 1;
    }
    println!("{}: {} rays", scene.name, rays.len());
    for (c, k) in &classes {
        println!("  {k:>7}  {c}");
    }
    println!("  largest relative t change on the same triangle: {worst_rel:.2e}");
    for e in examples.iter().take(5) {
        println!("  e.g. {e}");
    }
    Ok(())
}
