//! ACO's own cycle estimate, taken apart per block and per loop.
//!
//! RADV's compiler (ACO, Mesa 25.0 `aco_statistics.cpp`) reports `Latency` ("issue cycles
//! plus stall cycles"): a one-wave, in-order simulation of every basic block of the final
//! program, each block's cycles weighted by how often ACO assumes it runs, and summed. The
//! weights are not printed, and neither are the blocks that late passes emptied. This module
//! rebuilds both from two printouts of one compile:
//!
//! - `ACO_DEBUG=perfinfo`: the final program with every instruction's cycles, `(N clk)` (its
//!   increment of the block's cycle count), and after it the statistics (`latency: …`).
//!   A block's cycles are the sum of its instructions' (`Σ clk`), exactly.
//! - `RADV_DEBUG=preoptir`: the program right after instruction selection ("After
//!   Instruction Selection:"), every block still there. Replaying instruction selection's
//!   order of creating blocks over it gives each block the three depths ACO stamps on it when
//!   it is created — loops, divergent ifs, uniform ifs — and every loop its blocks
//!   (`[header, exit)`; blocks are emptied later, never renumbered).
//!
//! ACO's weight of a block: per enclosing loop, that loop's trips (it assumes 8 for the
//! outermost, 4 for the next level, 2 for every deeper one); ×0.5 per enclosing uniform if;
//! ×0.75 per enclosing divergent if (both sides run when lanes disagree); ×0.25 on the
//! linear-only block a wave runs when it skips a side of a divergent if. With those trips,
//! [`Program::latency`] equals the printed `latency` (the identity the tests check); with
//! other trips, per loop, it is the same model run on them.

use crate::base::tri::Branch;
use std::collections::BTreeMap;

/// One block of a printout.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Block {
    pub index: usize,
    pub logical_preds: Vec<usize>,
    pub linear_preds: Vec<usize>,
    /// ACO's block kinds (`loop-header`, `branch`, `merge`, …).
    pub kind: Vec<String>,
    pub instrs: Vec<String>,
    /// Σ of the instructions' `(N clk)` (perfinfo only).
    pub clk: u64,
}

impl Block {
    fn is(&self, k: &str) -> bool {
        self.kind.iter().any(|x| x == k)
    }

    /// The last instruction, logical markers aside.
    fn terminator(&self) -> &str {
        self.instrs.iter().rev().find(|i| !i.starts_with("p_logical")).map_or("", String::as_str)
    }
}

/// Reads the blocks of one printed program (`BB<n>` lines, each followed by its
/// `/* logical preds: … / linear preds: … / kind: … */` line and its tab-indented
/// instructions); `(N clk)` prefixes are summed into [`Block::clk`].
pub fn parse_blocks(text: &str) -> Result<BTreeMap<usize, Block>, String> {
    let mut blocks = BTreeMap::new();
    let mut cur: Option<Block> = None;
    let ids = |s: &str| -> Result<Vec<usize>, String> {
        s.split(',')
            .map(str::trim)
            .filter(|t| !t.is_empty())
            .map(|t| t.strip_prefix("BB").and_then(|n| n.parse().ok()).ok_or_else(|| format!("bad block name {t:?}")))
            .collect()
    };
    for (no, line) in text.lines().enumerate() {
        let at = |msg: String| format!("line {}: {msg}", no + 1);
        if let Some(n) = line.strip_prefix("BB").and_then(|n| n.parse::<usize>().ok()) {
            if let Some(b) = cur.take() {
                blocks.insert(b.index, b);
            }
            cur = Some(Block { index: n, ..Block::default() });
            continue;
        }
        let Some(b) = cur.as_mut() else { continue };
        if let Some(rest) = line.strip_prefix("/* logical preds: ") {
            let (logical, rest) = rest.split_once("/ linear preds: ").ok_or_else(|| at("no linear preds".into()))?;
            let (linear, kind) = rest.split_once("/ kind: ").ok_or_else(|| at("no block kind".into()))?;
            b.logical_preds = ids(logical).map_err(at)?;
            b.linear_preds = ids(linear).map_err(at)?;
            let kind = kind.trim_end().trim_end_matches("*/");
            b.kind = kind.split(',').map(str::trim).filter(|k| !k.is_empty()).map(String::from).collect();
        } else if let Some(instr) = line.strip_prefix('\t') {
            let instr = instr.trim();
            let instr = match instr.strip_prefix('(').and_then(|r| r.split_once("clk)")) {
                Some((n, rest)) => {
                    b.clk += n.trim().parse::<u64>().map_err(|_| at(format!("bad cycle count {n:?}")))?;
                    rest.trim()
                }
                None => instr,
            };
            b.instrs.push(instr.to_string());
        }
    }
    if let Some(b) = cur {
        blocks.insert(b.index, b);
    }
    Ok(blocks)
}

/// The depths ACO stamps on a block when instruction selection creates it.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Depth {
    pub loops: u32,
    pub divergent_ifs: u32,
    pub uniform_ifs: u32,
}

/// A loop of the program: its blocks are `header..exit`.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Loop {
    pub header: usize,
    pub exit: usize,
    /// 1 for an outermost loop.
    pub depth: u32,
    /// The ifs around the loop where it is entered (its header's if depths).
    pub at: Depth,
}

impl Loop {
    pub fn contains(&self, block: usize) -> bool {
        (self.header..self.exit).contains(&block)
    }

    /// The trips ACO assumes for the loop at each entry: 8 outermost, 4 at depth 2, 2 deeper.
    pub fn aco_trips(&self) -> f64 {
        match self.depth {
            1 => 8.0,
            2 => 4.0,
            _ => 2.0,
        }
    }
}

/// Replays instruction selection's order of creating blocks (Mesa 25.0
/// `aco_instruction_selection.cpp`: `begin_loop`/`end_loop`, `emit_loop_jump`,
/// `begin_divergent_if_*`, `begin_uniform_if_*`) over the blocks right after it.
struct Replay<'a> {
    blocks: &'a BTreeMap<usize, Block>,
    depth: Vec<Depth>,
    loops: Vec<Loop>,
    /// The sides open at the block being created, outermost first.
    stack: Vec<Side>,
    /// Per block, the sides around it (parallel to `depth`).
    sides: Vec<Vec<Side>>,
    events: Vec<Event>,
}

/// A side of an if (its then or else blocks): the first block of it, and the weight ACO gives
/// it (0.75 in a divergent if, 0.5 in a uniform one, 1 in an exec skip, which ACO does not
/// weigh).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Side {
    pub first: usize,
    pub weight: f64,
}

/// The program's control flow in the order instruction selection makes it (its shape, for
/// comparing two builds of one kernel: [`branch_sides`]).
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Event {
    /// An if whose sides weigh this much.
    If(f64),
    /// A side of the innermost if, by its first block.
    Side(usize),
    EndSide,
    EndIf,
    Loop,
    EndLoop,
}

impl Replay<'_> {
    fn block(&self, i: usize) -> Result<&Block, String> {
        self.blocks.get(&i).ok_or_else(|| format!("BB{i} is missing after instruction selection"))
    }

    fn create(&mut self, d: Depth, kind: Option<&str>) -> Result<usize, String> {
        let i = self.depth.len();
        let b = self.block(i)?;
        if let Some(k) = kind {
            if !b.is(k) {
                return Err(format!("BB{i}: expected a {k} block, found {:?}", b.kind));
            }
        }
        self.depth.push(d);
        self.sides.push(self.stack.clone());
        Ok(i)
    }

    /// Creates the first block of a side of weight `weight` and opens it.
    fn open_side(&mut self, inner: Depth, weight: f64) -> Result<usize, String> {
        let first = self.depth.len();
        self.events.push(Event::Side(first));
        self.stack.push(Side { first, weight });
        self.create(inner, None)
    }

    fn close_side(&mut self) {
        self.stack.pop();
        self.events.push(Event::EndSide);
    }

    /// One list of control flow whose current block is `cur`: returns the block that ends it.
    fn region(&mut self, mut cur: usize, d: Depth) -> Result<usize, String> {
        loop {
            let b = self.block(cur)?;
            let t = b.terminator().to_string();
            let (jump, uniform) = (b.is("break") || b.is("continue"), b.is("uniform"));
            let (branch, preheader) = (b.is("branch"), b.is("loop-preheader"));
            let cbranch = t.starts_with("p_cbranch");
            if jump && !uniform {
                // A divergent break or continue: a helper block, then the continue block.
                self.create(d, None)?;
                cur = self.create(d, None)?;
            } else if cbranch && branch {
                cur = self.divergent_if(d)?;
            } else if cbranch && t.contains(":exec") {
                // An exec skip: a uniform if that adds no depth.
                cur = self.uniform_if(d, d)?;
            } else if cbranch {
                cur = self.uniform_if(d, Depth { uniform_ifs: d.uniform_ifs + 1, ..d })?;
            } else if t.starts_with("p_branch") && preheader {
                cur = self.nest(d)?;
            } else {
                return Ok(cur);
            }
        }
    }

    fn nest(&mut self, d: Depth) -> Result<usize, String> {
        let inner = Depth { loops: d.loops + 1, ..d };
        self.events.push(Event::Loop);
        let header = self.create(inner, Some("loop-header"))?;
        let last = self.region(header, inner)?;
        if self.block(last)?.is("continue_or_break") {
            self.create(inner, None)?;
            self.create(inner, None)?;
        }
        self.events.push(Event::EndLoop);
        let exit = self.create(d, Some("loop-exit"))?;
        self.loops.push(Loop { header, exit, depth: inner.loops, at: d });
        Ok(exit)
    }

    fn divergent_if(&mut self, d: Depth) -> Result<usize, String> {
        let inner = Depth { divergent_ifs: d.divergent_ifs + 1, ..d };
        self.events.push(Event::If(0.75));
        let then = self.open_side(inner, 0.75)?;
        self.region(then, inner)?;
        self.close_side();
        self.create(d, None)?;
        // ACO 26 leaves out an empty else side (no invert block, no else blocks): the merge
        // follows the then side's linear block.
        if self.block(self.depth.len())?.is("merge") {
            self.events.push(Event::EndIf);
            return self.create(d, Some("merge"));
        }
        self.create(d, Some("invert"))?;
        let els = self.open_side(inner, 0.75)?;
        self.region(els, inner)?;
        self.close_side();
        self.create(d, None)?;
        self.events.push(Event::EndIf);
        self.create(d, Some("merge"))
    }

    fn uniform_if(&mut self, d: Depth, inner: Depth) -> Result<usize, String> {
        let weight = if inner.uniform_ifs > d.uniform_ifs { 0.5 } else { 1.0 };
        self.events.push(Event::If(weight));
        let then = self.open_side(inner, weight)?;
        self.region(then, inner)?;
        self.close_side();
        let els = self.open_side(inner, weight)?;
        self.region(els, inner)?;
        self.close_side();
        self.events.push(Event::EndIf);
        self.create(d, None)
    }
}

/// A block of the final program as the estimate weighs it.
#[derive(Clone, Debug, PartialEq)]
pub struct Weighed {
    pub index: usize,
    /// Σ clk: the block's cycles once through.
    pub clk: u64,
    pub depth: Depth,
    /// The linear-only block a wave runs when it skips a side of a divergent if (×0.25).
    pub skip_side: bool,
    /// The sides of ifs around it, outermost first (their weights make `depth`'s factor).
    pub sides: Vec<Side>,
    /// The named branches whose markers it holds (a marked build's: [`branch_sides`]).
    pub markers: Vec<Branch>,
}

impl Depth {
    /// ACO's weight of the ifs: ×0.5 per uniform if, ×0.75 per divergent one.
    pub fn if_factor(&self) -> f64 {
        0.5f64.powi(self.uniform_ifs as i32) * 0.75f64.powi(self.divergent_ifs as i32)
    }
}

impl Weighed {
    /// The block's weight apart from its loops' trips.
    pub fn if_factor(&self) -> f64 {
        let f = self.depth.if_factor();
        if self.skip_side {
            f * 0.25
        } else {
            f
        }
    }
}

/// One kernel as ACO estimated it.
#[derive(Clone, Debug, PartialEq)]
pub struct Program {
    pub blocks: Vec<Weighed>,
    /// Outer loops before the loops they hold.
    pub loops: Vec<Loop>,
    /// The `latency:` ACO printed (unrounded).
    pub printed_latency: f64,
    /// The other figures printed beside it (`num_waves`, `valu_usage`, …).
    pub printed: BTreeMap<String, f64>,
    /// Its control flow's shape, as instruction selection made it.
    pub events: Vec<Event>,
}

impl Program {
    /// Reads one kernel's compile from its driver printout (`RADV_DEBUG=preoptir` and
    /// `ACO_DEBUG=perfinfo` of one pipeline): the first program after instruction selection,
    /// the final program after it and the statistics after that.
    pub fn from_printout(text: &str) -> Result<Program, String> {
        let isel_at = text
            .find("After Instruction Selection:")
            .ok_or("no \"After Instruction Selection:\" (RADV_DEBUG=preoptir)")?;
        let fin_rel = text[isel_at..]
            .find("After lowering to hw instructions:")
            .ok_or("no \"After lowering to hw instructions:\" (ACO_DEBUG=perfinfo)")?;
        let fin_at = isel_at + fin_rel;
        let mut printed = BTreeMap::new();
        let mut stats_at = None;
        let mut pos = fin_at;
        for line in text[fin_at..].lines() {
            if stats_at.is_none() && line.starts_with("num_waves: ") {
                stats_at = Some(pos);
            }
            if stats_at.is_some() {
                let Some((k, v)) = line.split_once(": ") else { break };
                let Ok(v) = v.trim().parse::<f64>() else { break };
                printed.insert(k.to_string(), v);
                if k == "wave64_per_cycle" {
                    break;
                }
            }
            pos += line.len() + 1;
        }
        let stats_at = stats_at.ok_or("no statistics (num_waves: …) after the final program")?;
        let printed_latency = *printed.get("latency").ok_or("no \"latency:\" among the statistics")?;
        let isel = parse_blocks(&text[isel_at..fin_at]).map_err(|e| format!("after instruction selection, {e}"))?;
        let fin = parse_blocks(&text[fin_at..stats_at]).map_err(|e| format!("final program, {e}"))?;
        Self::new(&isel, &fin, printed_latency, printed)
    }

    /// Weighs the final program's blocks (`fin`) with the depths the replay over `isel` gives.
    pub fn new(
        isel: &BTreeMap<usize, Block>,
        fin: &BTreeMap<usize, Block>,
        printed_latency: f64,
        printed: BTreeMap<String, f64>,
    ) -> Result<Program, String> {
        let mut r = Replay {
            blocks: isel,
            depth: Vec::new(),
            loops: Vec::new(),
            stack: Vec::new(),
            sides: Vec::new(),
            events: Vec::new(),
        };
        let first = r.create(Depth::default(), None)?;
        r.region(first, Depth::default())?;
        if r.depth.len() != isel.len() {
            return Err(format!("the replay placed {} of {} blocks", r.depth.len(), isel.len()));
        }
        let mut succs: BTreeMap<usize, usize> = BTreeMap::new();
        for b in fin.values() {
            for &p in &b.linear_preds {
                *succs.entry(p).or_default() += 1;
            }
        }
        let blocks = fin
            .values()
            .map(|b| {
                // Blocks appended after instruction selection are at depth 0.
                let depth = r.depth.get(b.index).copied().unwrap_or_default();
                let skip_side = b.logical_preds.is_empty()
                    && b.linear_preds.len() == 1
                    && succs.get(&b.index) == Some(&1)
                    && fin.get(&b.linear_preds[0]).is_some_and(|p| p.is("branch") || p.is("invert"));
                let sides = r.sides.get(b.index).cloned().unwrap_or_default();
                Weighed { index: b.index, clk: b.clk, depth, skip_side, sides, markers: markers(b) }
            })
            .collect();
        let mut loops = r.loops;
        loops.sort_by_key(|l| l.header);
        Ok(Program { blocks, loops, printed_latency, printed, events: r.events })
    }

    /// The loops holding block `i`, outermost first.
    pub fn loops_of(&self, i: usize) -> impl Iterator<Item = &Loop> {
        self.loops.iter().filter(move |l| l.contains(i))
    }

    /// ACO's latency model with `trips(loop)` per entry of each loop: Σ blocks of cycles ×
    /// the product of their loops' trips × their if factor.
    pub fn latency(&self, trips: impl Fn(&Loop) -> f64) -> f64 {
        self.blocks
            .iter()
            .map(|b| b.clk as f64 * self.loops_of(b.index).map(&trips).product::<f64>() * b.if_factor())
            .sum()
    }

    /// [`Self::latency`] with ACO's own trips: its `Latency` statistic.
    pub fn aco_latency(&self) -> f64 {
        self.latency(Loop::aco_trips)
    }

    /// The innermost loop holding block `i`.
    pub fn inner_loop(&self, i: usize) -> Option<&Loop> {
        self.loops_of(i).last()
    }

    /// How many passes ACO assumes through `l`'s own blocks per run: the trips of it and of
    /// its outer loops, times the weight of the ifs it is entered in.
    pub fn aco_passes(&self, l: &Loop) -> f64 {
        self.loops_of(l.header).map(Loop::aco_trips).product::<f64>() * l.at.if_factor()
    }

    /// The cycles of one pass through a loop's own blocks (not those of loops inside it; the
    /// ifs inside it weighted as ACO weighs them), or of the blocks outside every loop
    /// (`None`) once through.
    pub fn per_pass(&self, l: Option<&Loop>) -> f64 {
        let entry = l.map_or(1.0, |l| l.at.if_factor());
        self.blocks.iter().filter(|b| self.inner_loop(b.index) == l).map(|b| b.clk as f64 * b.if_factor() / entry).sum()
    }

    /// The model with `passes(l)` passes per run through each loop's own blocks (the blocks
    /// outside every loop run once): Σ over loops of [`Self::per_pass`] × passes. With
    /// [`Self::aco_passes`] it is [`Self::aco_latency`], up to rounding.
    pub fn cycles(&self, passes: impl Fn(&Loop) -> f64) -> f64 {
        self.per_pass(None) + self.loops.iter().map(|l| self.per_pass(Some(l)) * passes(l)).sum::<f64>()
    }
}

/// The named branches whose markers (atomic operations, [`Branch::marker`]) block `b` holds.
fn markers(b: &Block) -> Vec<Branch> {
    b.instrs
        .iter()
        .filter_map(|i| {
            let op = i.split_whitespace().find_map(|w| w.split_once("atomic_").map(|(_, op)| op))?;
            Branch::of_marker(op.split('_').next().unwrap_or(op))
        })
        .collect()
}

/// What a marked build says of the real build's branches: for each named branch whose
/// marker the marked build holds, the side of the real program that runs it (its first
/// block), or why none does.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct BranchSides {
    pub sides: BTreeMap<Branch, usize>,
    /// Branches not found as a side of the real program, with why: flattened there (its if was
    /// made selects, so ACO weighs no block of it), or not in a side of its own.
    pub left: Vec<(Branch, String)>,
}

/// Finds the named branches of `real` from `marked`, the same kernel built with a marker at
/// the start of each named side (`BRANCH_MARKS`). The two programs' control flow must be the
/// same but for ifs the markers kept that the real build flattened (an if with no if or loop
/// inside, holding a marker): those branches are left out, said. Where two alignments of the
/// shapes fit, the branches in the ifs they disagree on are left out too. Any other difference
/// is an error: the marked build changed the program's shape.
pub fn branch_sides(marked: &Program, real: &Program) -> Result<BranchSides, String> {
    let (a, b) = (&marked.events, &real.events);
    let (n, m) = (a.len(), b.len());
    // The side each marker is in (the innermost side of its block).
    let mut side_of: BTreeMap<Branch, Option<usize>> = BTreeMap::new();
    for blk in &marked.blocks {
        for &k in &blk.markers {
            if side_of.insert(k, blk.sides.last().map(|s| s.first)).is_some() {
                return Err(format!("the {} marker appears twice in the marked build", k.name()));
            }
        }
    }
    let marked_sides: Vec<usize> = side_of.values().flatten().copied().collect();
    // Where an if starting at event i ends (the event after its EndIf), when it holds no if or
    // loop and one of its sides holds a marker: the marked build may have kept it alone.
    let skip: Vec<Option<usize>> = (0..n)
        .map(|i| {
            if !matches!(a[i], Event::If(_)) {
                return None;
            }
            let mut marker = false;
            for (j, e) in a.iter().enumerate().skip(i + 1) {
                match e {
                    Event::Side(f) => marker |= marked_sides.contains(f),
                    Event::EndSide => {}
                    Event::EndIf => return marker.then_some(j + 1),
                    _ => return None,
                }
            }
            None
        })
        .collect();
    let same = |x: &Event, y: &Event| match (x, y) {
        (Event::Side(_), Event::Side(_)) => true,
        _ => x == y,
    };
    // ok[i][j]: a[i..] aligns with b[j..].
    let mut ok = vec![vec![false; m + 1]; n + 1];
    ok[n][m] = true;
    for i in (0..n).rev() {
        for j in (0..=m).rev() {
            let matched = j < m && same(&a[i], &b[j]) && ok[i + 1][j + 1];
            let skipped = skip[i].is_some_and(|e| ok[e][j]);
            ok[i][j] = matched || skipped;
        }
    }
    if !ok[0][0] {
        return Err(format!(
            "the marked build's control flow ({} ifs, {} loops) is not the real build's ({} ifs, {} loops) with marked ifs added",
            a.iter().filter(|e| matches!(e, Event::If(_))).count(),
            a.iter().filter(|e| **e == Event::Loop).count(),
            b.iter().filter(|e| matches!(e, Event::If(_))).count(),
            b.iter().filter(|e| **e == Event::Loop).count()
        ));
    }
    let (mut i, mut j) = (0, 0);
    let mut map: BTreeMap<usize, usize> = BTreeMap::new();
    let mut dropped: Vec<(usize, &str)> = Vec::new();
    while i < n {
        let matched = j < m && same(&a[i], &b[j]) && ok[i + 1][j + 1];
        let skipped = skip[i].filter(|&e| ok[e][j]);
        match (matched, skipped) {
            (true, skip) => {
                if let (Event::Side(x), Event::Side(y)) = (a[i], b[j]) {
                    map.insert(x, y);
                }
                if let Some(e) = skip {
                    for ev in &a[i..e] {
                        if let Event::Side(x) = ev {
                            dropped.push((
                                *x,
                                "its if matches the real build's in one alignment and is missing in another",
                            ));
                        }
                    }
                }
                (i, j) = (i + 1, j + 1);
            }
            (false, Some(e)) => {
                for ev in &a[i..e] {
                    if let Event::Side(x) = ev {
                        dropped.push((*x, "flattened in the real build (its if became selects: no block to weigh)"));
                    }
                }
                i = e;
            }
            (false, None) => unreachable!("ok[i][j] holds on the path taken"),
        }
    }
    let mut out = BranchSides::default();
    for k in Branch::ALL.into_iter().filter(|k| k.marker().is_some() && !side_of.contains_key(k)) {
        out.left.push((k, "no marker in the marked build (its compiler removed or changed it)".into()));
    }
    for (k, side) in side_of {
        let Some(side) = side else {
            out.left.push((k, "its marker is in no side of an if".into()));
            continue;
        };
        if let Some((_, why)) = dropped.iter().find(|(x, _)| *x == side) {
            out.left.push((k, (*why).into()));
        } else if let Some(&y) = map.get(&side) {
            out.sides.insert(k, y);
        } else {
            out.left.push((k, "its side has no counterpart in the real build".into()));
        }
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// One block of a printout: its line, its preds-and-kind line, its instructions.
    fn block(i: usize, lp: &str, linp: &str, kind: &str, instrs: &[&str]) -> String {
        let mut s = format!("BB{i}\n/* logical preds: {lp}/ linear preds: {linp}/ kind: {kind}*/\n");
        for x in instrs {
            s += &format!("\t{x}\n");
        }
        s
    }

    /// A compile's printout: the blocks after instruction selection, the final ones, and the
    /// statistics (`latency` is not read: the test rebuilds it).
    fn compile(isel: &[String], fin: &[String]) -> String {
        format!(
            "After Instruction Selection:\n{}After lowering to hw instructions:\n{}num_waves: 16\nlatency: 0\nwave64_per_cycle: 1\n",
            isel.concat(),
            fin.concat()
        )
    }

    /// A kernel's printout cut to a loop around a divergent if: block 0 runs once; 1..6 are
    /// a loop (header 1, exit 6) holding a divergent if (2 then, 3 then-linear, 4 invert, 5
    /// else, … merge). Hand-built to the shapes `aco_instruction_selection.cpp` makes.
    fn printout() -> String {
        let isel = [
            block(0, "", "", "top-level, loop-preheader, ", &["p_logical_start", "p_logical_end", "p_branch BB1"]),
            block(1, "BB0, BB9, ", "BB0, BB9, ", "loop-header, branch, ", &["p_cbranch_z %1"]),
            block(2, "BB1, ", "BB1, ", "uniform, ", &["s_nop", "p_branch BB4"]),
            block(3, "", "BB1, ", "uniform, ", &["p_branch BB4"]),
            block(4, "", "BB2, BB3, ", "invert, ", &["p_cbranch_z %2"]),
            block(5, "BB1, ", "BB4, ", "uniform, ", &["v_nop", "p_branch BB7"]),
            block(6, "", "BB4, ", "uniform, ", &["p_branch BB7"]),
            block(7, "BB2, BB5, ", "BB5, BB6, ", "merge, ", &["p_logical_start", "p_logical_end", "p_branch BB8"]),
            block(8, "BB7, ", "BB7, ", "loop-exit, ", &["s_endpgm"]),
        ];
        let fin = [
            block(0, "", "", "top-level, loop-preheader, ", &["(  3 clk)   s_mov_b32"]),
            block(1, "BB0, BB7, ", "BB0, BB7, ", "loop-header, branch, ", &["( 10 clk)   s_cbranch_execz"]),
            block(2, "BB1, ", "BB1, ", "uniform, ", &["(  4 clk)   v_add"]),
            block(3, "", "BB1, ", "uniform, ", &["(  8 clk)   s_branch"]),
            block(4, "", "BB2, BB3, ", "invert, ", &["(  2 clk)   s_not"]),
            block(5, "BB1, ", "BB4, ", "uniform, ", &["(  6 clk)   v_mul"]),
            block(7, "BB2, BB5, ", "BB5, BB4, ", "merge, ", &["(  1 clk)   s_cbranch_scc1"]),
            block(8, "BB7, ", "BB7, ", "loop-exit, ", &["(  5 clk)   s_endpgm"]),
        ];
        compile(&isel, &fin)
    }

    #[test]
    fn blocks_weigh_as_aco_weighs_them() {
        let p = Program::from_printout(&printout()).unwrap();
        assert_eq!(p.loops, vec![Loop { header: 1, exit: 8, depth: 1, at: Depth::default() }]);
        let d = |i: usize| p.blocks.iter().find(|b| b.index == i).unwrap();
        assert_eq!(d(2).depth, Depth { loops: 1, divergent_ifs: 1, uniform_ifs: 0 });
        assert!(d(3).skip_side, "BB3 runs when the wave skips the then side");
        assert!(!d(2).skip_side && !d(5).skip_side);
        // 3 + 8·(10 + 0.75·4 + 0.25·8 + 2 + 0.75·6 + 1) + 5, by hand.
        let want = 3.0 + 8.0 * (10.0 + 0.75 * 4.0 + 0.25 * 8.0 + 2.0 + 0.75 * 6.0 + 1.0) + 5.0;
        assert_eq!(p.aco_latency(), want);
        // Other trips move only the loop's blocks.
        assert_eq!(p.latency(|_| 1.0), 8.0 + (want - 8.0) / 8.0);
        assert_eq!(p.per_pass(None), 8.0);
        assert_eq!(p.per_pass(Some(&p.loops[0])), 22.5);
        assert_eq!(p.cycles(|l| p.aco_passes(l)), want);
        assert_eq!(p.cycles(|_| 3.0), 8.0 + 3.0 * 22.5);
        // The if's two sides, by their first blocks, and the shape of the control flow.
        let (then, els) = (Side { first: 2, weight: 0.75 }, Side { first: 5, weight: 0.75 });
        assert_eq!((d(2).sides.clone(), d(5).sides.clone(), d(3).sides.clone()), (vec![then], vec![els], vec![]));
        use Event as E;
        let shape = [E::Loop, E::If(0.75), E::Side(2), E::EndSide, E::Side(5), E::EndSide, E::EndIf, E::EndLoop];
        assert_eq!(p.events, shape);
        // The product of a block's sides' weights is ACO's if factor.
        for b in &p.blocks {
            assert_eq!(b.sides.iter().map(|s| s.weight).product::<f64>(), b.depth.if_factor(), "BB{}", b.index);
        }
    }

    #[test]
    fn markers_are_read_from_their_atomic_operations() {
        let b = |instrs: &[&str]| Block { instrs: instrs.iter().map(|s| s.to_string()).collect(), ..Block::default() };
        assert_eq!(
            markers(&b(&["(  4 clk)   buffer_atomic_add %1, %2, 0 offset:4", "v_mov_b32 v0, 1"])),
            vec![Branch::Edges]
        );
        assert_eq!(
            markers(&b(&["global_atomic_cmpswap v[0:1], v2", "buffer_atomic_smin v1"])),
            vec![Branch::Best, Branch::Huge]
        );
        assert_eq!(markers(&b(&["buffer_atomic_swap v1", "buffer_store_dword v1"])), vec![]);
    }

    /// A program of events `ev` whose blocks `marked` hold markers, each in the side `first`.
    fn shaped(ev: Vec<Event>, marked: &[(usize, Branch)]) -> Program {
        Program {
            blocks: marked
                .iter()
                .map(|&(first, k)| Weighed {
                    index: first,
                    clk: 0,
                    depth: Depth::default(),
                    skip_side: false,
                    sides: vec![Side { first, weight: 0.75 }],
                    markers: vec![k],
                })
                .collect(),
            loops: vec![],
            printed_latency: 0.0,
            printed: Default::default(),
            events: ev,
        }
    }

    #[test]
    fn a_marked_build_names_the_real_builds_sides() {
        use Event::*;
        // Real: a loop holding an if (sides 3, 9) with an if inside its then side (5).
        let real = shaped(
            vec![Loop, If(0.75), Side(3), If(0.75), Side(5), EndSide, EndIf, EndSide, Side(9), EndSide, EndIf, EndLoop],
            &[],
        );
        // Marked: the same, the markers moving the blocks' numbers, and one marked (uniform) if
        // more (side 8: flattened in the real build).
        let with = |flat: f64| {
            vec![
                Loop,
                If(0.75),
                Side(4),
                If(0.75),
                Side(6),
                EndSide,
                EndIf,
                If(flat),
                Side(8),
                EndSide,
                EndIf,
                EndSide,
                Side(12),
                EndSide,
                EndIf,
                EndLoop,
            ]
        };
        let marks = [(4, Branch::Edges), (6, Branch::Cross), (8, Branch::Best), (12, Branch::Flat)];
        let marked = shaped(with(0.5), &marks);
        let s = branch_sides(&marked, &real).unwrap();
        assert_eq!(s.sides, [(Branch::Edges, 3), (Branch::Cross, 5), (Branch::Flat, 9)].into());
        let left: Vec<Branch> = s.left.iter().map(|x| x.0).collect();
        assert_eq!(left, vec![Branch::Huge, Branch::Divide, Branch::Candidate, Branch::Best]);
        assert!(s.left.iter().any(|(k, why)| *k == Branch::Best && why.contains("flattened")), "{:?}", s.left);
        // Two marked divergent ifs in a row where the real build has one: either could be it,
        // so neither is named.
        let s = branch_sides(&shaped(with(0.75), &marks), &real).unwrap();
        assert_eq!(s.sides, [(Branch::Edges, 3), (Branch::Flat, 9)].into());
        assert!(s.left.iter().any(|(k, why)| *k == Branch::Cross && why.contains("another")), "{:?}", s.left);
        // An if the real build lacks that holds no marker, or a loop more: not the same program.
        let unmarked = shaped(marked.events.clone(), &[(4, Branch::Edges)]);
        assert!(branch_sides(&unmarked, &real).unwrap_err().contains("not the real build's"));
        let mut looped = marked.clone();
        looped.events.splice(0..0, [Loop, EndLoop]);
        assert!(branch_sides(&looped, &real).is_err());
        // A marker twice is refused.
        let twice = shaped(marked.events.clone(), &[(4, Branch::Edges), (6, Branch::Edges)]);
        assert!(branch_sides(&twice, &real).unwrap_err().contains("twice"));
    }

    /// ACO 26 leaves an empty else side out: the merge follows the then side's linear block,
    /// with no invert block and no else blocks.
    #[test]
    fn a_divergent_if_without_an_else_side_is_read() {
        let isel = [
            block(0, "", "", "top-level, loop-preheader, ", &["p_logical_start", "p_logical_end", "p_branch BB1"]),
            block(1, "BB0, BB4, ", "BB0, BB4, ", "loop-header, branch, ", &["p_cbranch_z %1"]),
            block(2, "BB1, ", "BB1, ", "uniform, ", &["s_nop", "p_branch BB4"]),
            block(3, "", "BB1, ", "uniform, ", &["p_branch BB4"]),
            block(4, "BB1, ", "BB2, BB3, ", "uniform, merge, ", &["p_logical_start", "p_logical_end", "p_branch BB5"]),
            block(5, "BB4, ", "BB4, ", "loop-exit, ", &["s_endpgm"]),
        ];
        let fin = [
            block(0, "", "", "top-level, loop-preheader, ", &["(  3 clk)   s_mov_b32"]),
            block(1, "BB0, BB4, ", "BB0, BB4, ", "loop-header, branch, ", &["( 10 clk)   s_cbranch_execz"]),
            block(2, "BB1, ", "BB1, ", "uniform, ", &["(  4 clk)   v_add"]),
            block(3, "", "BB1, ", "uniform, ", &["(  8 clk)   s_branch"]),
            block(4, "BB1, ", "BB2, BB3, ", "uniform, merge, ", &["(  1 clk)   s_cbranch_scc1"]),
            block(5, "BB4, ", "BB4, ", "loop-exit, ", &["(  5 clk)   s_endpgm"]),
        ];
        let p = Program::from_printout(&compile(&isel, &fin)).unwrap();
        assert_eq!(p.loops, vec![Loop { header: 1, exit: 5, depth: 1, at: Depth::default() }]);
        let d = |i: usize| p.blocks.iter().find(|b| b.index == i).unwrap();
        assert_eq!(d(2).depth.divergent_ifs, 1);
        assert!(d(3).skip_side && d(4).depth.divergent_ifs == 0);
        // 3 + 8·(10 + 0.75·4 + 0.25·8 + 1) + 5, by hand.
        assert_eq!(p.aco_latency(), 3.0 + 8.0 * (10.0 + 0.75 * 4.0 + 0.25 * 8.0 + 1.0) + 5.0);
    }

    #[test]
    fn a_printout_without_its_parts_is_refused() {
        let e = Program::from_printout("After lowering to hw instructions:\nBB0\n").unwrap_err();
        assert!(e.contains("preoptir"), "{e}");
        let no_stats = printout().replace("latency: 0\n", "").replace("num_waves: 16\n", "");
        assert!(Program::from_printout(&no_stats).unwrap_err().contains("statistics"));
    }
}
