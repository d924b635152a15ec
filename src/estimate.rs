//! `halftrace estimate`: what a ray costs in cycles on GPUs we do not have, from the
//! compilers' own cost models.
//!
//! This part reads AMD's. ACO estimates each kernel's cycles (`Latency`: one wave, issue
//! plus stall cycles) by weighting every block of the final program with the trips it assumes
//! for the loops around it ([`crate::isa::aco`]). Taken apart, that estimate gives, per loop of
//! the kernel, the cycles of one pass through its own blocks and the share of the estimate it
//! carries; rebuilt from those parts it must equal ACO's figure, which every row checks.
//!
//! Then the rays take the place of ACO's assumed trips ([`ray_rows`]). Three loops of a
//! kernel are named by the program's shape ([`roles`]): the traversal loop (the
//! outermost loop that carries most of the estimate), the triangle loop (the loop inside it
//! with the costliest pass) and, where the compiler kept it a loop, the child-slot loop
//! between them. The CPU reference counts, per wave of the device's wave size in lockstep
//! (single rays, or packets of P rays that step together), how often each runs
//! ([`crate::layout::traverse::LoopWork`]): a pass per node entered, B slot passes per visit,
//! a triangle pass per triangle of the slowest lane of each slot.
//! Every other loop (an exact division's corrections, a per-axis loop the compiler kept)
//! keeps ACO's assumed trips relative to the nearest of those three around it, or runs as
//! ACO assumes when outside them; branches inside a loop keep ACO's weights (0.5 for a
//! uniform if, 0.75 for a divergent one). It is the compiler's model, one wave, issue plus
//! stall cycles, no latency hidden: an estimate, not a measurement.

use crate::base::Status;
use crate::gpu::null;
use crate::isa::{self, aco, Matrix};
use crate::layout::traverse::LoopWork;
use crate::layout::{Encoded, LayoutId};
use crate::precision::{FloatControls, Math};
use crate::rays::RayKind;
pub use crate::report::estimate::{RayRow, Split};
use serde::{Deserialize, Serialize};
use std::collections::HashMap;
use std::path::Path;

/// A loop's part of a kernel's estimate (`header` `None`: the blocks outside every loop).
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct LoopCost {
    /// The loop's header block (`BB<n>`), `None` outside every loop.
    pub header: Option<usize>,
    /// 0 outside every loop, 1 for an outermost loop.
    pub depth: u32,
    /// Cycles of one pass through the loop's own blocks (those of loops inside it apart),
    /// ACO's if factors inside it applied ([`aco::Program::per_pass`]).
    pub cycles_per_trip: f64,
    /// How many passes ACO assumes per run of the kernel (its and its outer loops' trips,
    /// times the weight of the ifs it is entered in).
    pub aco_passes: f64,
    /// `cycles_per_trip × aco_passes` ÷ the kernel's estimate.
    pub share: f64,
}

/// One kernel on one family.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct Row {
    pub family: String,
    pub generation: String,
    pub kernel: String,
    pub layout: String,
    pub math: String,
    pub branching: usize,
    pub packet: usize,
    pub status: Status,
    /// ACO's `Latency` statistic.
    pub aco_latency: Option<f64>,
    /// The same figure rebuilt from the blocks (unrounded; ACO prints it to six decimals).
    pub rebuilt: Option<f64>,
    pub printed: Option<f64>,
    /// Waves per SIMD ACO gives the kernel (`num_waves`).
    pub waves: Option<f64>,
    pub loops: Vec<LoopCost>,
}

/// How far the rebuilt figure may be from the printed one: ACO prints it with `%f`.
pub const TOLERANCE: f64 = 1e-6;

/// A kernel's row from its isa row and ACO's program.
fn row(family: &str, generation: &str, r: &crate::report::isa::IsaRow, p: Result<aco::Program, String>) -> Row {
    let mut row = Row {
        family: family.into(),
        generation: generation.into(),
        kernel: r.kernel.clone(),
        layout: r.layout.clone(),
        math: r.math.clone(),
        branching: r.branching,
        packet: r.packet,
        status: r.status.clone(),
        aco_latency: r.stats.get("Latency").copied(),
        ..Row::default()
    };
    let p = match p {
        Ok(p) => p,
        Err(e) => {
            if row.status.is_ok() {
                row.status = Status::Failed(e);
            }
            return row;
        }
    };
    let total = p.aco_latency();
    row.rebuilt = Some(total);
    row.printed = Some(p.printed_latency);
    row.waves = p.printed.get("num_waves").copied();
    row.loops = std::iter::once(None)
        .chain(p.loops.iter().map(Some))
        .map(|l| {
            let (cycles, passes) = (p.per_pass(l), l.map_or(1.0, |l| p.aco_passes(l)));
            LoopCost {
                header: l.map(|l| l.header),
                depth: l.map_or(0, |l| l.depth),
                cycles_per_trip: cycles,
                aco_passes: passes,
                share: if total > 0.0 { cycles * passes / total } else { 0.0 },
            }
        })
        .collect();
    let parts = p.cycles(|l| p.aco_passes(l));
    if (total - p.printed_latency).abs() > TOLERANCE
        || row.aco_latency != Some(total.round())
        || (parts - total).abs() > TOLERANCE * total.max(1.0)
    {
        row.status = Status::Failed(format!(
            "{family} {}: rebuilt {total:.6} cycles ({parts:.6} from its loops), but ACO printed {:.6} (statistic {:?})",
            r.kernel, p.printed_latency, row.aco_latency
        ));
    }
    row
}

/// The loops of a kernel that the rays give trips to.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Roles {
    /// The outermost loop with the largest share of the estimate.
    pub traversal: aco::Loop,
    /// The loop between the traversal and the triangle loop, if the compiler kept the
    /// child-slot loop a loop.
    pub slots: Option<aco::Loop>,
    /// The loop inside the traversal loop with the costliest pass.
    pub triangles: aco::Loop,
}

/// A compiler's cost model in the shape the rays weigh: its loops (outer before inner), the
/// cycles of one pass through a loop's own blocks (or of the blocks outside every loop, once
/// through), and the passes the compiler assumes per run. ACO's ([`aco::Program`]) and Intel's
/// ([`isa::intel::Program`]) have it.
pub trait LoopCosts {
    fn loops(&self) -> &[aco::Loop];
    fn per_pass(&self, l: Option<&aco::Loop>) -> f64;
    fn assumed_passes(&self, l: &aco::Loop) -> f64;
}

impl LoopCosts for aco::Program {
    fn loops(&self) -> &[aco::Loop] {
        &self.loops
    }
    fn per_pass(&self, l: Option<&aco::Loop>) -> f64 {
        aco::Program::per_pass(self, l)
    }
    fn assumed_passes(&self, l: &aco::Loop) -> f64 {
        self.aco_passes(l)
    }
}

/// Names the traversal, slot and triangle loops of `p` by its shape, or says why it cannot.
pub fn roles(p: &impl LoopCosts) -> Result<Roles, String> {
    let within = |outer: &aco::Loop, inner: &aco::Loop| outer.header <= inner.header && inner.exit <= outer.exit;
    let share = |l: &aco::Loop| -> f64 {
        p.loops().iter().filter(|m| within(l, m)).map(|m| p.per_pass(Some(m)) * p.assumed_passes(m)).sum()
    };
    let traversal = *p
        .loops()
        .iter()
        .filter(|l| l.depth == 1)
        .max_by(|a, b| share(a).total_cmp(&share(b)))
        .ok_or("no loop: not a traversal kernel")?;
    let triangles = *p
        .loops()
        .iter()
        .filter(|l| **l != traversal && within(&traversal, l))
        .max_by(|a, b| p.per_pass(Some(a)).total_cmp(&p.per_pass(Some(b))))
        .ok_or("no loop inside the traversal loop (the triangle loop)")?;
    let between: Vec<aco::Loop> = p
        .loops()
        .iter()
        .filter(|l| **l != traversal && **l != triangles && within(&traversal, l) && within(l, &triangles))
        .copied()
        .collect();
    if between.len() > 1 {
        return Err(format!(
            "{} loops between the traversal (BB{}) and triangle (BB{}) loops",
            between.len(),
            traversal.header,
            triangles.header
        ));
    }
    Ok(Roles { traversal, slots: between.first().copied(), triangles })
}

/// The model's cycles for `w` (waves of a ray set, summed) with branching factor `b`: the
/// rays' passes through the three named loops, the compiler's relative trips for every other
/// loop.
pub fn ray_cycles(p: &impl LoopCosts, roles: &Roles, w: &LoopWork, b: usize) -> Split {
    let named: Vec<(aco::Loop, f64, usize)> = [
        Some((roles.traversal, w.steps as f64, 1)),
        roles.slots.map(|l| (l, (w.visits * b as u64) as f64, 2)),
        Some((roles.triangles, w.tri_passes as f64, 3)),
    ]
    .into_iter()
    .flatten()
    .collect();
    let mut parts = [p.per_pass(None) * w.waves as f64, 0.0, 0.0, 0.0];
    for l in p.loops() {
        // The nearest named loop around l (or l itself), else the blocks outside every loop.
        let anchor =
            named.iter().filter(|(n, _, _)| n.header <= l.header && l.exit <= n.exit).max_by_key(|(n, _, _)| n.depth);
        let (passes, part) = match anchor {
            Some((n, passes, part)) => (passes * p.assumed_passes(l) / p.assumed_passes(n), *part),
            None => (w.waves as f64 * p.assumed_passes(l), 0),
        };
        parts[part] += p.per_pass(Some(l)) * passes;
    }
    Split { setup: parts[0], step: parts[1], slots: parts[2], triangles: parts[3] }
}

/// What [`ray_rows`] computes once for every family: encodings per (ray set, layout, B) and
/// loop work per (ray set, layout, B, P, math, float controls, wave size).
#[derive(Default)]
pub struct WorkCache {
    encoded: HashMap<(usize, String, usize), Result<Encoded, String>>,
    #[allow(clippy::type_complexity)]
    work: HashMap<(usize, String, usize, usize, String, String, usize), (LoopWork, LoopWork)>,
}

/// A ray set for [`ray_rows`]: a scene and its rays.
pub struct RaySet {
    pub scene: String,
    pub kind: String,
    pub scene_data: crate::scene::Scene,
    pub bin: crate::bvh::BinaryBvh,
    pub rays: Vec<crate::base::Ray>,
}

impl RaySet {
    /// `kind` rays at `res`² of the scene at `path`.
    pub fn load(path: &Path, kind: &RayKind, res: u32) -> anyhow::Result<RaySet> {
        let scene = crate::scene::load(path)?;
        let bin = crate::bvh::build_binary(&scene);
        let params = crate::rays::RayParams { width: res, height: res, ..Default::default() };
        let spec = crate::runner::rays::RaySpec { kind: kind.clone(), params };
        let rays = crate::runner::rays::make(&scene, &bin, &spec)?;
        Ok(RaySet { scene: scene.name.clone(), kind: kind.to_string(), scene_data: scene, bin, rays })
    }
}

/// Each kernel of `built` (one family's isa rows and ACO programs) on each ray set:
/// its estimated cycles per ray, with f32's ratio.
pub fn ray_rows(
    family: &str,
    built: &[(crate::report::isa::IsaRow, Result<aco::Program, String>)],
    sets: &[RaySet],
    cache: &mut WorkCache,
) -> Vec<RayRow> {
    let generation = null::family(family).map_or("", |x| x.generation);
    let mut out = Vec::new();
    for (si, set) in sets.iter().enumerate() {
        for (r, p) in built {
            let mut row = RayRow {
                family: family.into(),
                generation: generation.into(),
                kernel: r.kernel.clone(),
                layout: r.layout.clone(),
                math: r.math.clone(),
                branching: r.branching,
                packet: r.packet,
                packet_impl: r.packet_impl.clone(),
                scene: set.scene.clone(),
                rays: set.kind.clone(),
                ray_count: set.rays.len() as u64,
                wave: r.subgroup_size,
                status: r.status.clone(),
                ..RayRow::default()
            };
            let mut run = || -> Result<(), String> {
                let p = p.as_ref().map_err(String::clone)?;
                let roles = roles(p)?;
                let layout = LayoutId::parse(&r.layout).map_err(|e| e.to_string())?;
                let math: Math = r.math.parse()?;
                let fc = if r.float_controls == "off" { FloatControls::Off } else { FloatControls::On };
                let wave = (r.subgroup_size as usize).max(1);
                let key = (si, r.layout.clone(), r.branching, r.packet, r.math.clone(), r.float_controls.clone(), wave);
                if !cache.work.contains_key(&key) {
                    let enc = cache.encoded.entry((si, r.layout.clone(), r.branching)).or_insert_with(|| {
                        Encoded::new(&set.scene_data, &set.bin, layout, r.branching).map_err(|e| format!("{e:#}"))
                    });
                    let enc = enc.as_ref().map_err(String::clone)?;
                    cache.work.insert(key.clone(), layout.imp().loop_work(enc, &set.rays, r.packet, wave, math, fc));
                }
                let (lock, lanes) = cache.work[&key];
                let rays = set.rays.len().max(1) as f64;
                let split = ray_cycles(p, &roles, &lock, r.branching);
                row.cycles_per_ray = split.total() / rays;
                row.split = split.scaled(1.0 / rays);
                // Packets (or single rays) per wave: a lane average is one packet's cost ÷ them.
                let per_wave = lanes.waves as f64 / lock.waves.max(1) as f64;
                row.lane_average = ray_cycles(p, &roles, &lanes, r.branching).total() / (rays * per_wave);
                row.waves = p.printed.get("num_waves").copied().unwrap_or(0.0);
                let per_wave = split.total() / lock.waves.max(1) as f64;
                let w64 = p.printed.get("wave64_per_cycle").copied().unwrap_or(0.0);
                row.rays_per_kclk = 1000.0 * 64.0 * w64 * p.printed_latency / per_wave.max(1.0);
                Ok(())
            };
            if row.status.is_ok() {
                if let Err(e) = run() {
                    row.status = Status::Failed(format!("{family} {} on {} {}: {e}", r.kernel, set.scene, set.kind));
                }
            }
            out.push(row);
        }
    }
    for i in 0..out.len() {
        let f32_row = out.iter().find(|o| {
            o.layout == "f32"
                && o.branching == out[i].branching
                && o.packet == out[i].packet
                && o.scene == out[i].scene
                && o.rays == out[i].rays
                && o.status.is_ok()
        });
        out[i].vs_f32 = f32_row.filter(|_| out[i].status.is_ok()).map(|f| out[i].cycles_per_ray / f.cycles_per_ray);
    }
    out
}

/// Builds `matrix` (for `layouts`; empty: all) on each AMD family, one child process each,
/// as many at once as there are cores, takes each kernel's estimate apart and weighs its
/// loops with the rays of `sets`; rows in family order.
pub fn run(
    exe: &Path,
    families: &[String],
    matrix: Matrix,
    layouts: &[LayoutId],
    sets: &[RaySet],
) -> anyhow::Result<(Vec<Row>, Vec<RayRow>)> {
    use rayon::prelude::*;
    let built: Vec<anyhow::Result<_>> =
        families.par_iter().map(|f| isa::aco_programs(exe, f, matrix, layouts)).collect();
    let (mut rows, mut ray_out, mut cache) = (Vec::new(), Vec::new(), WorkCache::default());
    for (f, b) in families.iter().zip(built) {
        let b = b?;
        let generation = null::family(f).map_or("", |x| x.generation);
        ray_out.extend(ray_rows(f, &b, sets, &mut cache));
        rows.extend(b.into_iter().map(|(r, p)| row(f, generation, &r, p)));
    }
    Ok((rows, ray_out))
}

/// The loops of a row, largest share first (the blocks outside every loop last).
fn by_share(r: &Row) -> Vec<&LoopCost> {
    let mut ls: Vec<&LoopCost> = r.loops.iter().filter(|l| l.header.is_some()).collect();
    ls.sort_by(|a, b| b.share.total_cmp(&a.share));
    ls
}

/// estimate.md: per family, each kernel's ACO estimate, rebuilt, and its three costliest
/// loops.
pub fn markdown(rows: &[Row]) -> String {
    let mut md = String::from("# Estimated cycles: ACO's model taken apart per loop\n\n");
    md += "ACO's `Latency` (one wave, issue plus stall cycles) for each kernel, rebuilt from the final program's \
           blocks with the weights ACO gives them, and the loops that carry it: the cycles of one pass through a \
           loop's own blocks and its share of the estimate under ACO's assumed trips (8 for an outermost loop, 4 at \
           the second level, 2 deeper). **It is the compiler's model, not a measurement**, and its trips are \
           assumptions; `BB<n>` is the loop's header block in the `--disasm` listings.\n\n";
    let mut families: Vec<&str> = rows.iter().map(|r| r.family.as_str()).collect();
    families.dedup();
    for f in families {
        let fr: Vec<&Row> = rows.iter().filter(|r| r.family == f).collect();
        md += &format!("## {f} ({})\n\n", fr[0].generation);
        md += "| kernel | layout | math | B | P | ACO Latency | rebuilt | waves | loops | costliest loops (depth: cycles per pass × passes = share) | outside loops | status |\n";
        md += "|---|---|---|---:|---:|---:|---:|---:|---:|---|---:|---|\n";
        for r in fr {
            let num = |x: Option<f64>, d: usize| x.map_or("–".to_string(), |v| format!("{v:.d$}"));
            let top: Vec<String> = by_share(r)
                .iter()
                .take(3)
                .map(|l| {
                    format!(
                        "BB{} ({}: {:.1} × {} = {:.1}%)",
                        l.header.unwrap_or(0),
                        l.depth,
                        l.cycles_per_trip,
                        l.aco_passes,
                        100.0 * l.share
                    )
                })
                .collect();
            let outside = r.loops.iter().find(|l| l.header.is_none()).map_or(0.0, |l| l.share);
            md += &format!(
                "| {} | {} | {} | {} | {} | {} | {} | {} | {} | {} | {:.1}% | {} |\n",
                r.kernel,
                r.layout,
                r.math,
                r.branching,
                r.packet,
                num(r.aco_latency, 0),
                num(r.rebuilt, 3),
                num(r.waves, 0),
                r.loops.len().saturating_sub(1),
                top.join("; "),
                100.0 * outside,
                r.status
            );
        }
        md += "\n";
    }
    md
}

/// estimate.csv: one line per kernel and loop (`outside` for the blocks outside every loop).
pub fn csv(rows: &[Row]) -> anyhow::Result<Vec<u8>> {
    let mut w = csv::Writer::from_writer(Vec::new());
    w.write_record([
        "family",
        "generation",
        "kernel",
        "layout",
        "math",
        "B",
        "P",
        "status",
        "aco_latency",
        "rebuilt",
        "waves",
        "loop",
        "depth",
        "cycles_per_pass",
        "aco_passes",
        "share",
    ])?;
    let num = |x: Option<f64>| x.map(|v| v.to_string()).unwrap_or_default();
    for r in rows {
        let empty = [LoopCost::default()];
        let loops: &[LoopCost] = if r.loops.is_empty() { &empty } else { &r.loops };
        for l in loops {
            let name = match l.header {
                Some(h) => format!("BB{h}"),
                None if r.loops.is_empty() => String::new(),
                None => "outside".into(),
            };
            w.write_record([
                r.family.clone(),
                r.generation.clone(),
                r.kernel.clone(),
                r.layout.clone(),
                r.math.clone(),
                r.branching.to_string(),
                r.packet.to_string(),
                r.status.to_string(),
                num(r.aco_latency),
                num(r.rebuilt),
                num(r.waves),
                name,
                l.depth.to_string(),
                l.cycles_per_trip.to_string(),
                l.aco_passes.to_string(),
                l.share.to_string(),
            ])?;
        }
    }
    Ok(w.into_inner()?)
}

#[cfg(test)]
mod tests {
    use super::*;
    use aco::{Depth, Loop, Program, Weighed};

    /// A traversal loop (BB1) around a triangle loop (BB2, in a divergent if) around a helper
    /// loop (BB3), with set-up before them.
    fn program() -> Program {
        let d = |loops, divergent_ifs| Depth { loops, divergent_ifs, uniform_ifs: 0 };
        let b = |index, clk, depth| Weighed { index, clk, depth, skip_side: false };
        Program {
            blocks: vec![b(0, 10, d(0, 0)), b(1, 100, d(1, 0)), b(2, 50, d(2, 1)), b(3, 4, d(3, 1)), b(5, 7, d(0, 0))],
            loops: vec![
                Loop { header: 1, exit: 5, depth: 1, at: d(0, 0) },
                Loop { header: 2, exit: 4, depth: 2, at: d(1, 1) },
                Loop { header: 3, exit: 4, depth: 3, at: d(2, 1) },
            ],
            printed_latency: 0.0,
            printed: Default::default(),
        }
    }

    #[test]
    fn the_rays_trips_replace_acos_in_the_named_loops_only() {
        let p = program();
        let r = roles(&p).unwrap();
        assert_eq!((r.traversal.header, r.slots, r.triangles.header), (1, None, 2));
        // ACO's own passes rebuild its latency: 17 + 8·100 + 8·4·0.75·50 + 8·4·2·0.75·4.
        let aco = 17.0 + 800.0 + 1200.0 + 192.0;
        assert_eq!(p.cycles(|l| p.aco_passes(l)), aco);
        assert_eq!(p.aco_latency(), aco);
        let w = LoopWork { waves: 2, rays: 128, steps: 10, visits: 6, tri_passes: 20 };
        let s = ray_cycles(&p, &r, &w, 4);
        // The helper keeps ACO's 2 passes per triangle pass.
        assert_eq!(s, Split { setup: 2.0 * 17.0, step: 1000.0, slots: 0.0, triangles: 20.0 * 50.0 + 40.0 * 4.0 });
        // Twice the work in the loops: twice their cycles, the set-up unchanged.
        let w2 = LoopWork { steps: 20, visits: 12, tri_passes: 40, ..w };
        let s2 = ray_cycles(&p, &r, &w2, 4);
        assert_eq!((s2.setup, s2.step, s2.triangles), (s.setup, 2.0 * s.step, 2.0 * s.triangles));
    }

    #[test]
    fn a_program_without_a_loop_inside_the_traversal_is_named_as_such() {
        let mut p = program();
        p.loops.truncate(1);
        assert!(roles(&p).unwrap_err().contains("triangle loop"));
        p.loops.clear();
        assert!(roles(&p).unwrap_err().contains("no loop"));
    }
}
