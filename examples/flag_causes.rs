//! Why the closest-hit rule's fast path flags a ray (docs/layouts.md, "The closest-hit rule";
//! the rates: `examples/flag_rates.rs`): per scene and ray set, the rays the f32 B = 4
//! traversal flags, each classified by the undecided test that comes first — a triangle fp32
//! cannot decide (an edge function or the determinant within its bound, or an interval wider
//! than 2⁻¹⁰ of the vertices' depth), or a certified hit whose interval straddles tmin or tmax,
//! or overlaps the best hit's — and, for the certified ones, how loose the interval is: its
//! half-width ÷ the distance of t from the exact crossing (exact arithmetic, `base::exact`).
//!
//! cargo run --release --example flag_causes -- SCENE...

use halftrace::base::{exact, tri, ClosestTrue, RayPre};
use halftrace::layout::{Encoded, LayoutId};
use halftrace::precision::{FloatControls, Math};
use halftrace::rays::{RayKind, RayParams};
use halftrace::runner::rays::{make, RaySpec};
use std::collections::BTreeMap;

fn median(v: &mut [f64]) -> f64 {
    v.sort_by(f64::total_cmp);
    if v.is_empty() {
        f64::NAN
    } else {
        v[v.len() / 2]
    }
}

fn main() -> anyhow::Result<()> {
    let paths: Vec<String> = std::env::args().skip(1).collect();
    anyhow::ensure!(!paths.is_empty(), "usage: flag_causes SCENE...");
    println!("| scene | rays | count | flagged | undecided triangle | straddles tmin | straddles tmax | overlaps the best | certified: err ÷ error, median (min) |");
    println!("|---|---|---:|---:|---:|---:|---:|---:|---|");
    for path in &paths {
        let scene = halftrace::scene::load(path.as_ref())?;
        let bin = halftrace::bvh::build_binary(&scene);
        let enc = Encoded::new(&scene, &bin, LayoutId::parse("f32")?, 4)?;
        let verts: Vec<[f32; 9]> = (0..scene.tris.len()).map(|p| scene.verts(p)).collect();
        for kind in [RayKind::Primary, RayKind::Ao, RayKind::Diffuse, RayKind::Grazing] {
            let rays = make(&scene, &bin, &RaySpec::new(kind.clone(), RayParams::default()))?;
            let (hits, _) = enc.trace_raw(&rays, 1, Math::F32, FloatControls::On);
            let mut class: BTreeMap<&str, usize> = BTreeMap::new();
            let mut loose = Vec::new();
            let mut flagged = 0;
            for (ray, _) in rays.iter().zip(&hits).filter(|(_, h)| h.is_flagged()) {
                flagged += 1;
                let r = RayPre::new(ray);
                let mut best = ClosestTrue::fast(ray.tmax);
                for (p, v) in verts.iter().enumerate() {
                    best.test(&r, v, p as i32);
                }
                anyhow::ensure!(
                    best.flagged(),
                    "{}: a ray the traversal flags and the brute force does not",
                    scene.name
                );
                let v = &verts[best.undecided.1 as usize];
                let c = tri::certify(&r, v);
                let (lo, hi) = c.bounds();
                let what = match c {
                    tri::Cert::Hit { t, err, .. } => {
                        if let Some(x) = exact::crossing(&r, v) {
                            loose.push(err as f64 / (x.s.to_f64() - t as f64).abs().max(f64::MIN_POSITIVE));
                        }
                        if lo < ray.tmin {
                            "straddles tmin"
                        } else if hi > ray.tmax {
                            "straddles tmax"
                        } else {
                            "overlaps the best"
                        }
                    }
                    _ => "undecided triangle",
                };
                *class.entry(what).or_default() += 1;
            }
            let n = |k: &str| class.get(k).copied().unwrap_or(0);
            let min = loose.iter().copied().fold(f64::INFINITY, f64::min);
            let l = if loose.is_empty() { "–".into() } else { format!("{:.0} ({:.0})", median(&mut loose), min) };
            println!(
                "| {} | {kind} | {} | {flagged} | {} | {} | {} | {} | {l} |",
                scene.name,
                rays.len(),
                n("undecided triangle"),
                n("straddles tmin"),
                n("straddles tmax"),
                n("overlaps the best")
            );
        }
    }
    Ok(())
}
