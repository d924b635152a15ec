//! The rays' part of the estimate: the three loops the rays give trips to ([`roles`]), the
//! model's cycles with those trips ([`ray_cycles`]), and each kernel's row per ray set
//! ([`ray_rows`]).

use crate::base::tri::Branch;
use crate::base::Status;
use crate::gpu::null;
use crate::isa::aco;
use crate::layout::traverse::{BranchWork, LoopWork};
use crate::rays::RayKind;
pub use crate::report::estimate::{RayRow, Split};
use crate::runner::rays::RaySpec;
use crate::runner::Runner;
use crate::variant::{Buffers, Variant};
use anyhow::Context as _;
use std::collections::{BTreeMap, HashMap};
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
    roles_at(p, None)
}

/// [`roles`], the triangle loop being the innermost loop around block `test` where it is
/// given (a named side of the triangle test: [`aco::branch_sides`]) and lies inside the
/// traversal loop. By shape alone the costliest pass can be another loop's: ACO 26 keeps f16h
/// fp16's child-slot loop at B = 16, beside the triangle loop and costlier per pass.
pub fn roles_at(p: &impl LoopCosts, test: Option<usize>) -> Result<Roles, String> {
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
    let around = test.and_then(|t| {
        p.loops().iter().filter(|l| **l != traversal && within(&traversal, l) && l.contains(t)).max_by_key(|l| l.depth)
    });
    let triangles = *around
        .or_else(|| {
            p.loops()
                .iter()
                .filter(|l| **l != traversal && within(&traversal, l))
                .max_by(|a, b| p.per_pass(Some(a)).total_cmp(&p.per_pass(Some(b))))
        })
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

/// [`ray_cycles`] with the triangle loop's named branches weighed by the rays too: each block
/// of the triangle loop (and of loops inside it) in a named side runs in as many passes as
/// the side does (`bw`: waves that take it, any lane), times ACO's weights of the ifs inside
/// that side and of the loops inside it; the other blocks keep ACO's weights. `sides`: the
/// named sides of `p` ([`aco::branch_sides`]); with none it is [`ray_cycles`].
pub fn ray_cycles_branches(
    p: &aco::Program,
    roles: &Roles,
    w: &LoopWork,
    bw: &BranchWork,
    b: usize,
    sides: &aco::BranchSides,
) -> Result<Split, String> {
    if bw.tri_passes != w.tri_passes {
        return Err(format!(
            "the branch counts saw {} triangle passes, the loop counts {}",
            bw.tri_passes, w.tri_passes
        ));
    }
    let tri = roles.triangles;
    let inside = |x: usize| (tri.header..tri.exit).contains(&x);
    // Named sides by first block; a side inside a loop within the triangle loop would run
    // more than once per pass, which the counts do not say.
    let named: BTreeMap<usize, Branch> = sides.sides.iter().map(|(&k, &s)| (s, k)).collect();
    for (&s, k) in &named {
        if !inside(s) {
            return Err(format!("the {} side (BB{s}) is outside the triangle loop (BB{})", k.name(), tri.header));
        }
        if p.loops.iter().any(|l| l.header > tri.header && l.contains(s)) {
            return Err(format!("the {} side (BB{s}) is in a loop inside the triangle loop", k.name()));
        }
    }
    let mut split = ray_cycles(p, roles, w, b);
    let mut triangles = 0.0;
    for blk in p.blocks.iter().filter(|x| inside(x.index)) {
        let loops: f64 = p
            .loops
            .iter()
            .filter(|l| l.header > tri.header && l.contains(blk.index))
            .map(aco::Loop::aco_trips)
            .product();
        let around: Vec<&aco::Side> = blk.sides.iter().filter(|s| inside(s.first)).collect();
        let at = around.iter().rposition(|s| named.contains_key(&s.first));
        let (passes, rest) = match at {
            Some(i) => (bw.taken[named[&around[i].first] as usize] as f64, &around[i + 1..]),
            None => (w.tri_passes as f64, &around[..]),
        };
        let weight: f64 = rest.iter().map(|s| s.weight).product::<f64>() * if blk.skip_side { 0.25 } else { 1.0 };
        triangles += blk.clk as f64 * loops * passes * weight;
    }
    split.triangles = triangles;
    Ok(split)
}

/// The named sides a row was weighed with, in words: those weighed by the rays with the share
/// of the waves' triangle passes that run them (`bw`) and, in brackets, of the packets' (or
/// rays') each alone (`alone`), then those left to ACO's weights and why.
fn branches_said(s: &aco::BranchSides, bw: &BranchWork, alone: &BranchWork) -> String {
    let share = |w: &BranchWork, k: Branch| 100.0 * w.taken[k as usize] as f64 / w.tri_passes.max(1) as f64;
    let named: Vec<String> =
        s.sides.keys().map(|&k| format!("{} {:.1}% ({:.1}%)", k.name(), share(bw, k), share(alone, k))).collect();
    let mut out = format!("rays: {}", named.join(", "));
    for (k, why) in &s.left {
        out += &format!("; {}: {why}", k.name());
    }
    out
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

/// One family's kernels: its isa rows beside ACO's programs ([`crate::isa::aco_programs`])
/// and their named branches, from the marked builds ([`aco::branch_sides`]).
pub type Built = [BuiltKernel];

/// One kernel of [`Built`]: its isa row, ACO's program, its named branches (or why not).
pub type BuiltKernel = (crate::report::isa::IsaRow, Result<aco::Program, String>, Result<aco::BranchSides, String>);

/// Each kernel of each family in `built` on each ray set of `rays`: its estimated cycles per
/// ray, with f32's ratio; rows by family, then ray set. Scenes, ray sets and encodings come
/// from the [`Runner`]'s caches (one scene at a time, each ray set and encoding made once);
/// a kernel's loop work is counted once for every family that compiles it with the same
/// wave size.
pub fn ray_rows(built: &[(String, &Built)], rays: &Rays) -> anyhow::Result<Vec<RayRow>> {
    // The loops the rays weigh depend on the program only.
    let named: Vec<Vec<Result<Roles, String>>> = built
        .iter()
        .map(|(_, b)| {
            b.iter()
                .map(|(_, p, sides)| {
                    let test = sides.as_ref().ok().and_then(|s| s.sides.get(&Branch::Edges).copied());
                    p.as_ref().map_err(String::clone).and_then(|p| roles_at(p, test))
                })
                .collect()
        })
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
            let mut branch_work: HashMap<(Variant, usize), (BranchWork, BranchWork)> = HashMap::new();
            for (((family, b), named), out) in built.iter().zip(&named).zip(per_family.iter_mut()) {
                let generation = null::family(family).map_or("", |x| x.generation);
                for ((r, p, sides), roles) in b.iter().zip(named) {
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
                        let aco_split = ray_cycles(p, roles, &lock, r.branching);
                        row.aco_branches = aco_split.total() / rays;
                        row.aco_triangles = aco_split.triangles / rays;
                        // The named branches weighed by the rays where the marked build found them.
                        let mut weighed = |sides: &aco::BranchSides| -> Result<(Split, Split, String), String> {
                            let (bl, ba) = match branch_work.get(&(v, wave)) {
                                Some(w) => *w,
                                None => {
                                    let w = runner.branch_work(&v, set, wave).map_err(|e| format!("{e:#}"))?;
                                    *branch_work.entry((v, wave)).or_insert(w)
                                }
                            };
                            let said = branches_said(sides, &bl, &ba);
                            Ok((
                                ray_cycles_branches(p, roles, &lock, &bl, r.branching, sides)?,
                                ray_cycles_branches(p, roles, &lanes, &ba, r.branching, sides)?,
                                said,
                            ))
                        };
                        let (split, lane_split) = match sides.as_ref().map_err(String::clone).and_then(&mut weighed) {
                            Ok((lock, lanes, said)) => {
                                row.branches = said;
                                (lock, lanes)
                            }
                            Err(why) => {
                                row.branches = format!("ACO's weights: {why}");
                                (aco_split, ray_cycles(p, roles, &lanes, r.branching))
                            }
                        };
                        row.cycles_per_ray = split.total() / rays;
                        row.split = split.scaled(1.0 / rays);
                        // Packets (or single rays) per wave: a lane average is one packet's cost ÷ them.
                        let packets_per_wave = lanes.waves as f64 / lock.waves.max(1) as f64;
                        row.lane_average = lane_split.total() / (rays * packets_per_wave);
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
    use aco::{Depth, Loop, Program, Side, Weighed};

    /// A traversal loop (BB1) around a triangle loop (BB2, in a divergent if) around a helper
    /// loop (BB3), with set-up before them.
    fn program() -> Program {
        let d = |loops, divergent_ifs| Depth { loops, divergent_ifs, uniform_ifs: 0 };
        let b = |index, clk, depth| Weighed { index, clk, depth, skip_side: false, sides: vec![], markers: vec![] };
        Program {
            blocks: vec![b(0, 10, d(0, 0)), b(1, 100, d(1, 0)), b(2, 50, d(2, 1)), b(3, 4, d(3, 1)), b(5, 7, d(0, 0))],
            loops: vec![
                Loop { header: 1, exit: 5, depth: 1, at: d(0, 0) },
                Loop { header: 2, exit: 4, depth: 2, at: d(1, 1) },
                Loop { header: 3, exit: 4, depth: 3, at: d(2, 1) },
            ],
            printed_latency: 0.0,
            printed: Default::default(),
            events: vec![],
        }
    }

    /// A traversal loop (BB1) around a triangle loop (BB2..7) holding a divergent if whose then
    /// side (BB3) holds another (BB4, skipped by BB5).
    fn branchy() -> Program {
        let d = |loops, divergent_ifs| Depth { loops, divergent_ifs, uniform_ifs: 0 };
        let (a, b) = (Side { first: 3, weight: 0.75 }, Side { first: 4, weight: 0.75 });
        let w = |index, clk, depth, sides: Vec<Side>, skip_side| Weighed {
            index,
            clk,
            depth,
            skip_side,
            sides,
            markers: vec![],
        };
        Program {
            blocks: vec![
                w(0, 10, d(0, 0), vec![], false),
                w(1, 100, d(1, 0), vec![], false),
                w(2, 20, d(2, 0), vec![], false),
                w(3, 40, d(2, 1), vec![a], false),
                w(4, 8, d(2, 2), vec![a, b], false),
                w(5, 4, d(2, 1), vec![a], true),
                w(6, 2, d(2, 0), vec![], false),
                w(7, 5, d(1, 0), vec![], false),
                w(8, 7, d(0, 0), vec![], false),
            ],
            loops: vec![
                Loop { header: 1, exit: 8, depth: 1, at: d(0, 0) },
                Loop { header: 2, exit: 7, depth: 2, at: d(1, 0) },
            ],
            printed_latency: 0.0,
            printed: Default::default(),
            events: vec![],
        }
    }

    #[test]
    fn a_named_side_runs_as_often_as_the_rays_take_it() {
        let p = branchy();
        let r = roles(&p).unwrap();
        assert_eq!((r.traversal.header, r.triangles.header), (1, 2));
        let w = LoopWork { waves: 2, rays: 128, steps: 10, visits: 6, tri_passes: 20 };
        let mut bw = BranchWork { tri_passes: 20, ..Default::default() };
        bw.taken[Branch::Edges as usize] = 5;
        // No named side: ACO's weights, as ray_cycles gives them: 20·(20 + 0.75·40 + 0.75²·8 +
        // 0.75·0.25·4 + 2).
        let none = aco::BranchSides::default();
        let aco_split = ray_cycles(&p, &r, &w, 4);
        assert_eq!(aco_split.triangles, 1145.0);
        assert_eq!(ray_cycles_branches(&p, &r, &w, &bw, 4, &none).unwrap(), aco_split);
        // BB3 named: its side runs in 5 passes, the if inside it keeps ACO's 0.75 (0.25 for the
        // skip), the blocks outside it run in every pass: 20·20 + 5·40 + 5·0.75·8 + 5·0.25·4 + 20·2.
        let named = aco::BranchSides { sides: [(Branch::Edges, 3)].into(), left: vec![] };
        let s = ray_cycles_branches(&p, &r, &w, &bw, 4, &named).unwrap();
        assert_eq!(s.triangles, 400.0 + 200.0 + 30.0 + 5.0 + 40.0);
        assert_eq!((s.setup, s.step, s.slots), (aco_split.setup, aco_split.step, aco_split.slots));
        // Counts of other rays, a side outside the triangle loop: refused.
        let other = BranchWork { tri_passes: 21, ..bw };
        assert!(ray_cycles_branches(&p, &r, &w, &other, 4, &named).unwrap_err().contains("21 triangle passes"));
        let outside = aco::BranchSides { sides: [(Branch::Edges, 1)].into(), left: vec![] };
        assert!(ray_cycles_branches(&p, &r, &w, &bw, 4, &outside).unwrap_err().contains("outside the triangle loop"));
    }

    /// A loop beside the triangle loop whose pass costs more is taken for it by shape alone; a
    /// named side of the triangle test names the right one.
    #[test]
    fn a_named_side_names_the_triangle_loop() {
        let mut p = branchy();
        let d = Depth { loops: 2, divergent_ifs: 0, uniform_ifs: 0 };
        p.blocks.push(Weighed { index: 7, clk: 500, depth: d, skip_side: false, sides: vec![], markers: vec![] });
        p.blocks.sort_by_key(|b| b.index);
        p.loops[0].exit = 9;
        p.loops.push(Loop { header: 7, exit: 8, depth: 2, at: Depth { loops: 1, ..Depth::default() } });
        assert_eq!(roles(&p).unwrap().triangles.header, 7, "by shape: the costlier pass");
        assert_eq!(roles_at(&p, Some(3)).unwrap().triangles.header, 2, "by the side in BB3");
        assert_eq!(roles_at(&p, Some(0)).unwrap().triangles.header, 7, "a side outside the traversal: by shape");
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
