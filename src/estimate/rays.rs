//! The rays' part of the estimate: the three loops the rays give trips to ([`roles`]), the
//! model's cycles with those trips ([`ray_cycles`]), and each kernel's row per ray set
//! ([`ray_rows`]).

use crate::base::Status;
use crate::gpu::null;
use crate::isa::aco;
use crate::layout::traverse::LoopWork;
use crate::rays::RayKind;
pub use crate::report::estimate::{RayRow, Split};
use crate::runner::rays::RaySpec;
use crate::runner::Runner;
use crate::variant::{Buffers, Variant};
use anyhow::Context as _;
use std::collections::HashMap;
use std::path::PathBuf;

/// The loops of a kernel that the rays give trips to.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Roles {
    /// The outermost loop with the largest share of the estimate.
    pub traversal: aco::Loop,
    /// The loop between the traversal and the triangle loop, if a compiler kept a child-slot
    /// loop around the triangle loop (none does since the kernels test a visit's leaves after
    /// their unrolled slot loops).
    pub slots: Option<aco::Loop>,
    /// The loop inside the traversal loop with the costliest pass.
    pub triangles: aco::Loop,
}

/// A compiler's cost model in the shape the rays weigh: its loops (outer before inner), the
/// cycles of one pass through a loop's own blocks (or of the blocks outside every loop, once
/// through), and the passes the compiler assumes per run. ACO's ([`aco::Program`]) has it;
/// another compiler's per-block model (Intel's, once its printed blocks add up) would.
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

/// The rays the kernels are weighed with: each scene's ray kinds, primary rays at `res`².
pub struct Rays {
    pub scenes: Vec<PathBuf>,
    pub kinds: Vec<RayKind>,
    pub res: u32,
}

impl Rays {
    /// How many ray sets: scenes × kinds.
    pub fn sets(&self) -> usize {
        self.scenes.len() * self.kinds.len()
    }
}

/// One family's kernels: its isa rows beside ACO's programs ([`crate::isa::aco_programs`]).
pub type Built = [(crate::report::isa::IsaRow, Result<aco::Program, String>)];

/// Each kernel of each family in `built` on each ray set of `rays`: its estimated cycles per
/// ray, with f32's ratio; rows by family, then ray set. Scenes, ray sets and encodings come
/// from the [`Runner`]'s caches (one scene at a time, each ray set and encoding made once);
/// a kernel's loop work is counted once for every family that compiles it with the same
/// wave size.
pub fn ray_rows(built: &[(String, &Built)], rays: &Rays) -> anyhow::Result<Vec<RayRow>> {
    // The loops the rays weigh depend on the program only.
    let named: Vec<Vec<Result<Roles, String>>> = built
        .iter()
        .map(|(_, b)| b.iter().map(|(_, p)| p.as_ref().map_err(String::clone).and_then(roles)).collect())
        .collect();
    let mut per_family: Vec<Vec<RayRow>> = vec![Vec::new(); built.len()];
    let mut runner = Runner::new(None, &[], Default::default())?;
    for path in &rays.scenes {
        let scene = runner.scene(path).with_context(|| path.display().to_string())?.0.name.clone();
        for kind in &rays.kinds {
            let params = crate::rays::RayParams { width: rays.res, height: rays.res, ..Default::default() };
            let set = runner
                .ray_set(&RaySpec { kind: kind.clone(), params })
                .with_context(|| format!("{} {kind} rays", path.display()))?;
            let ray_count = runner.rays(set).rays.len();
            if ray_count == 0 {
                eprintln!("estimate: {scene} {kind}: the ray set has no rays; its rows are skipped");
            }
            let mut work: HashMap<(Variant, usize), (LoopWork, LoopWork)> = HashMap::new();
            for (((family, b), named), out) in built.iter().zip(&named).zip(per_family.iter_mut()) {
                let generation = null::family(family).map_or("", |x| x.generation);
                for ((r, p), roles) in b.iter().zip(named) {
                    let mut row = RayRow {
                        family: family.clone(),
                        generation: generation.into(),
                        driver: r.driver.clone(),
                        kernel: r.kernel.clone(),
                        layout: r.layout.clone(),
                        math: r.math.clone(),
                        branching: r.branching,
                        packet: r.packet,
                        packet_impl: r.packet_impl.clone(),
                        scene: scene.clone(),
                        rays: kind.to_string(),
                        ray_count: ray_count as u64,
                        wave: r.subgroup_size,
                        status: r.status.clone(),
                        what: r.what.clone(),
                        ..RayRow::default()
                    };
                    let mut weigh = || -> Result<(), String> {
                        let (p, roles) = (p.as_ref().map_err(String::clone)?, roles.as_ref().map_err(String::clone)?);
                        let k = r.what.kernel().ok_or_else(|| format!("{}: not a kernel of a layout", r.kernel))?;
                        let v = k.variant.with_buffers(Buffers::Bound);
                        let wave = (r.subgroup_size as usize).max(1);
                        let (lock, lanes) = match work.get(&(v, wave)) {
                            Some(w) => *w,
                            None => {
                                let w = runner.loop_work(&v, set, wave).map_err(|e| format!("{e:#}"))?;
                                *work.entry((v, wave)).or_insert(w)
                            }
                        };
                        let rays = ray_count.max(1) as f64;
                        let split = ray_cycles(p, roles, &lock, r.branching);
                        row.cycles_per_ray = split.total() / rays;
                        row.split = split.scaled(1.0 / rays);
                        // Packets (or single rays) per wave: a lane average is one packet's cost ÷ them.
                        let packets_per_wave = lanes.waves as f64 / lock.waves.max(1) as f64;
                        row.lane_average =
                            ray_cycles(p, roles, &lanes, r.branching).total() / (rays * packets_per_wave);
                        row.waves = p.printed.get("num_waves").copied().unwrap_or(0.0);
                        let cycles_per_wave = split.total() / lock.waves.max(1) as f64;
                        let w64 = p.printed.get("wave64_per_cycle").copied().unwrap_or(0.0);
                        row.rays_per_kclk = 1000.0 * 64.0 * w64 * p.printed_latency / cycles_per_wave.max(1.0);
                        Ok(())
                    };
                    if row.status.is_ok() && ray_count == 0 {
                        row.status = Status::Skipped(format!("{scene} {kind}: the ray set has no rays"));
                    }
                    if row.status.is_ok() {
                        if let Err(e) = weigh() {
                            row.status = Status::Failed(format!("{family} {} on {scene} {kind}: {e}", r.kernel));
                        }
                    }
                    out.push(row);
                }
            }
        }
    }
    let mut out: Vec<RayRow> = per_family.into_iter().flatten().collect();
    crate::report::estimate::set_ratios(&mut out);
    Ok(out)
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
