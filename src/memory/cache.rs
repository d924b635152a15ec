//! The cache model: set-associative caches with LRU replacement ([`Cache`]), arranged as a
//! GPU's hierarchy ([`Hierarchy`]: an L1 per compute unit, a shared L2, a last-level cache
//! where the GPU has one, then DRAM), fed by the waves the GPU runs at once ([`simulate`]).
//!
//! A model, not the hardware: sets are chosen by the line address modulo the set count (real
//! caches hash it), replacement is true LRU, there is no prefetch, no texture path, no
//! compression, and the L2's slices are one cache. Writes (the stacks' pushes) go to the L1 where
//! the GPU's L1 keeps stores ([`Gpu::l1_write_back`]), else through it (updating a copy it
//! holds) into the L2; a cache takes a write without reading the line from below (it keeps
//! which bytes were written) and writes a dirty line back when it evicts it — L1 to L2, L2 to
//! the last-level cache, else to DRAM; lines still dirty when the run ends are not written.

use super::gpus::Gpu;
use super::{Buffers, WaveTrace};

/// One set-associative cache, LRU, write-back.
#[derive(Clone, Debug)]
pub struct Cache {
    pub line: u64,
    sets: u64,
    ways: usize,
    /// Per set, its ways' line numbers (`u64::MAX`: empty), last-use stamps and dirty bits.
    tags: Vec<u64>,
    stamps: Vec<u64>,
    dirty: Vec<bool>,
    clock: u64,
    pub accesses: u64,
    pub hits: u64,
}

impl Cache {
    /// A cache of `bytes` in lines of `line` bytes, `ways`-way set-associative (at most fully
    /// associative).
    pub fn new(bytes: u64, line: u64, ways: usize) -> Cache {
        let lines = (bytes / line).max(1);
        let ways = (ways as u64).clamp(1, lines);
        let sets = (lines / ways).max(1);
        let n = (sets * ways) as usize;
        Cache {
            line,
            sets,
            ways: ways as usize,
            tags: vec![u64::MAX; n],
            stamps: vec![0; n],
            dirty: vec![false; n],
            clock: 0,
            accesses: 0,
            hits: 0,
        }
    }

    /// Reads line number `l` (byte address ÷ `line`): whether it hit. A miss fills the line,
    /// evicting the set's least recently used.
    pub fn access(&mut self, l: u64) -> bool {
        self.read(l).0
    }

    /// The way holding line `l` in its set, if any.
    fn find(&self, l: u64) -> (usize, Option<usize>) {
        let base = ((l % self.sets) as usize) * self.ways;
        (base, self.tags[base..base + self.ways].iter().position(|&t| t == l).map(|w| base + w))
    }

    /// Puts line `l` in its set in place of the least recently used: the dirty line it evicts,
    /// if any.
    fn fill(&mut self, base: usize, l: u64, dirty: bool) -> Option<u64> {
        let victim =
            (base..base + self.ways).min_by_key(|&i| (self.tags[i] != u64::MAX, self.stamps[i])).expect("a way");
        let evicted = (self.tags[victim] != u64::MAX && self.dirty[victim]).then_some(self.tags[victim]);
        (self.tags[victim], self.stamps[victim], self.dirty[victim]) = (l, self.clock, dirty);
        evicted
    }

    /// [`Cache::access`], with the dirty line the fill evicted (to be written back below).
    pub fn read(&mut self, l: u64) -> (bool, Option<u64>) {
        self.clock += 1;
        self.accesses += 1;
        match self.find(l) {
            (_, Some(i)) => {
                self.stamps[i] = self.clock;
                self.hits += 1;
                (true, None)
            }
            (base, None) => (false, self.fill(base, l, false)),
        }
    }

    /// Writes into line `l`: a hit marks it dirty; a miss puts it in dirty without reading it
    /// from below (GPUs' L2s keep which bytes a store wrote). The model then holds the line as
    /// whole: a later read of bytes the store did not write hits — an undercount where a live
    /// stack line was evicted and another lane's store brought it back (`docs/memory.md`).
    /// Returns whether it hit and the dirty line evicted.
    pub fn write(&mut self, l: u64) -> (bool, Option<u64>) {
        self.clock += 1;
        self.accesses += 1;
        match self.find(l) {
            (_, Some(i)) => {
                (self.stamps[i], self.dirty[i]) = (self.clock, true);
                self.hits += 1;
                (true, None)
            }
            (base, None) => (false, self.fill(base, l, true)),
        }
    }

    /// A write passing through (a write-through cache): a copy of line `l`, if held, is
    /// updated and becomes the most recently used; nothing is counted or filled.
    pub fn write_through(&mut self, l: u64) {
        if let (_, Some(i)) = self.find(l) {
            self.clock += 1;
            self.stamps[i] = self.clock;
        }
    }

    pub fn misses(&self) -> u64 {
        self.accesses - self.hits
    }
}

/// A GPU's caches: one L1 per unit (write-back or write-through as the GPU's: `Gpu::l1_write_back`),
/// the L2 and the last-level cache if any (write-back), and the bytes that crossed to DRAM (all
/// of them, those of the node buffer, those of the waves' private memory).
#[derive(Clone, Debug)]
pub struct Hierarchy {
    pub l1: Vec<Cache>,
    pub l2: Cache,
    pub llc: Option<Cache>,
    /// Bytes read from DRAM and written back to it.
    pub dram_bytes: u64,
    /// Of them, the node buffer's, and the waves' private memory's (their stacks).
    pub dram_node_bytes: u64,
    pub dram_stack_bytes: u64,
    /// Of `dram_bytes`, those written back (dirty lines evicted from the last level).
    pub dram_write_bytes: u64,
    /// [`simulate`]: the wave steps that read (each waits for the deepest level any of its
    /// lines came from, [`Gpu::latency_ns`]).
    pub read_steps: u64,
    /// [`simulate`]: the sum of those steps' latencies over every wave, ns.
    pub wait_ns: f64,
    /// [`simulate`]: the longest wave's sum of its steps' latencies, ns.
    pub longest_wave_ns: f64,
    /// [`simulate`]: the places that ran waves at once (units × resident waves, at most one
    /// per wave that takes a step).
    pub places: usize,
    /// Bytes below this address are the node buffer's.
    nodes_end: u64,
    /// Bytes from this address on are the waves' private memory.
    private_base: u64,
    /// The L1 keeps stores (write-back), else passes them on (write-through).
    l1_write_back: bool,
}

impl Hierarchy {
    pub fn new(g: &Gpu, units: usize, nodes_end: u64, private_base: u64) -> Hierarchy {
        Hierarchy {
            l1: vec![Cache::new(g.l1_kib * 1024, g.l1_line, g.l1_ways); units.max(1)],
            l2: Cache::new(g.l2_kib * 1024, g.l2_line, g.l2_ways),
            llc: (g.llc_kib > 0).then(|| Cache::new(g.llc_kib * 1024, g.llc_line, g.llc_ways)),
            dram_bytes: 0,
            dram_node_bytes: 0,
            dram_stack_bytes: 0,
            dram_write_bytes: 0,
            read_steps: 0,
            wait_ns: 0.0,
            longest_wave_ns: 0.0,
            places: 0,
            nodes_end,
            private_base,
            l1_write_back: g.l1_write_back,
        }
    }

    /// The bytes a write lands on at once: the L1's line where it keeps stores, else the L2's.
    pub fn write_line(&self) -> u64 {
        if self.l1_write_back {
            self.l1[0].line
        } else {
            self.l2.line
        }
    }

    /// Unit `unit` reads the L1 line holding byte `addr`; returns the deepest level its bytes
    /// came from ([`Level`]).
    pub fn read(&mut self, unit: usize, addr: u64) -> Level {
        let l1 = &mut self.l1[unit];
        let span = l1.line;
        let a = addr / span * span;
        let (hit, evicted) = l1.read(a / span);
        if let Some(v) = evicted {
            self.l1_write_back(v * span);
        }
        if hit {
            return Level::L1;
        }
        // The L1 line's bytes in L2 lines (one when the L2's line is the longer).
        let mut deepest = Level::L2;
        let mut b = a / self.l2.line * self.l2.line;
        while b < a + span {
            let (hit, evicted) = self.l2.read(b / self.l2.line);
            if let Some(v) = evicted {
                self.write_back(v * self.l2.line);
            }
            if !hit {
                deepest = deepest.max(self.below_l2(b));
            }
            b += self.l2.line;
        }
        deepest
    }

    /// Unit `unit` writes into the line holding byte `addr` ([`Hierarchy::write_line`]): kept
    /// dirty in its L1 where the L1 is write-back, else through the L1 into the L2.
    pub fn write(&mut self, unit: usize, addr: u64) {
        let l1 = &mut self.l1[unit];
        let span = l1.line;
        if self.l1_write_back {
            if let (_, Some(v)) = l1.write(addr / span) {
                self.l1_write_back(v * span);
            }
            return;
        }
        l1.write_through(addr / span);
        self.l2_write(addr);
    }

    /// The L2 takes a write into the line holding byte `addr`.
    fn l2_write(&mut self, addr: u64) {
        let b = addr / self.l2.line * self.l2.line;
        if let (_, Some(v)) = self.l2.write(b / self.l2.line) {
            self.write_back(v * self.l2.line);
        }
    }

    /// A dirty L1 line at `a` leaves the L1: its bytes into the L2.
    fn l1_write_back(&mut self, a: u64) {
        let span = self.l1[0].line;
        let mut b = a / self.l2.line * self.l2.line;
        while b < a + span {
            self.l2_write(b);
            b += self.l2.line;
        }
    }

    /// DRAM moves `bytes` at `addr`.
    fn dram(&mut self, addr: u64, bytes: u64) {
        self.dram_bytes += bytes;
        if addr < self.nodes_end {
            self.dram_node_bytes += bytes;
        } else if addr >= self.private_base {
            self.dram_stack_bytes += bytes;
        }
    }

    /// A dirty L2 line at `b` leaves the L2: into the last-level cache, else to DRAM.
    fn write_back(&mut self, b: u64) {
        let span = self.l2.line;
        let Some(llc) = self.llc.as_mut() else {
            self.dram_write_bytes += span;
            return self.dram(b, span);
        };
        let mut out = Vec::new();
        let mut c = b / llc.line * llc.line;
        while c < b + span {
            if let (_, Some(v)) = llc.write(c / llc.line) {
                out.push(v * llc.line);
            }
            c += llc.line;
        }
        let line = llc.line;
        for v in out {
            self.dram_write_bytes += line;
            self.dram(v, line);
        }
    }

    /// An L2 miss at `b`: its bytes from the last-level cache, else from DRAM; returns where
    /// they came from (DRAM where any part of them did).
    fn below_l2(&mut self, b: u64) -> Level {
        let span = self.l2.line;
        let Some(llc) = self.llc.as_mut() else {
            self.dram(b, span);
            return Level::Dram;
        };
        let (mut missed, mut out) = (Vec::new(), Vec::new());
        let mut c = b / llc.line * llc.line;
        while c < b + span {
            let (hit, evicted) = llc.read(c / llc.line);
            if !hit {
                missed.push(c);
            }
            out.extend(evicted.map(|v| v * llc.line));
            c += llc.line;
        }
        let line = llc.line;
        for v in out {
            self.dram_write_bytes += line;
            self.dram(v, line);
        }
        let level = if missed.is_empty() { Level::Llc } else { Level::Dram };
        for c in missed {
            self.dram(c, line);
        }
        level
    }
}

/// Where a read's bytes came from, nearest first (an index into [`Gpu::latency_ns`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord)]
pub enum Level {
    L1,
    L2,
    Llc,
    Dram,
}

/// Runs `waves` (of the buffers `b`) on `g` as it would run them at once: wave i starts on unit
/// i mod units, each unit holds `resident` waves, and in each round every resident wave makes
/// one lockstep step (units in turn); a finished wave's place goes to the next wave not yet
/// started. A wave's private memory (its [`super::PRIVATE`] ranges) is its place's: place `s`
/// has the `s`-th region after [`Buffers::private_base`], as a driver gives each resident wave
/// its scratch. Each step that reads waits for the slowest of its lines: the latency of the
/// deepest level any of them came from, summed in [`Hierarchy::wait_ns`] (no latency is hidden
/// within a wave: a step's loads depend on the step before).
pub fn simulate(g: &Gpu, waves: &[WaveTrace], resident: usize, b: &Buffers) -> Hierarchy {
    let units = g.units as usize;
    let mut h = Hierarchy::new(g, units, b.nodes_end(), b.private_base());
    let region = b.private_region(g.wave);
    let mut ranges: Vec<super::Range> = Vec::new();
    // Waves that read nothing (every ray missed the scene's box) take no step.
    let waves: Vec<&WaveTrace> = waves.iter().filter(|w| !w.steps.is_empty()).collect();
    let slots = units * resident.max(1);
    // (wave, next step) per slot; slot s belongs to unit s % units.
    let mut running: Vec<Option<(usize, usize)>> = (0..slots).map(|s| (s < waves.len()).then_some((s, 0))).collect();
    let mut next = slots.min(waves.len());
    h.places = next;
    let mut lines = Vec::new();
    let mut wave_ns = vec![0f64; waves.len()];
    while running.iter().any(Option::is_some) {
        for (s, r) in running.iter_mut().enumerate() {
            let Some((w, step)) = *r else { continue };
            // The step's lanes coalesce: each distinct L1 line is one request.
            lines.clear();
            ranges.clear();
            let steps = &waves[w].steps[step];
            // A step's lanes all read, or all write (a stack's pushes).
            let write = steps.first().is_some_and(|r| super::is_write(r.0));
            ranges.extend(steps.iter().map(|&(a, n)| match super::private_offset(a) {
                Some(off) => (b.private_base() + s as u64 * region + off, n),
                None => (a, n),
            }));
            if write {
                // The lanes' writes coalesce per line of the level that takes them.
                let line = h.write_line();
                super::lines_of(&ranges, line, &mut lines);
                for &l in &lines {
                    h.write(s % units, l * line);
                }
            } else {
                // The wave waits for the slowest of its lines (a store does not wait).
                super::lines_of(&ranges, g.l1_line, &mut lines);
                let deepest = lines.iter().map(|&l| h.read(s % units, l * g.l1_line)).max();
                if let Some(d) = deepest {
                    h.read_steps += 1;
                    h.wait_ns += g.latency_ns[d as usize];
                    wave_ns[w] += g.latency_ns[d as usize];
                }
            }
            *r = if step + 1 < waves[w].steps.len() {
                Some((w, step + 1))
            } else if next < waves.len() {
                next += 1;
                Some((next - 1, 0))
            } else {
                None
            };
        }
    }
    h.longest_wave_ns = wave_ns.into_iter().fold(0.0, f64::max);
    h
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A stream larger than the cache, read twice: every access misses.
    #[test]
    fn a_stream_larger_than_the_cache_always_misses() {
        let mut c = Cache::new(4096, 64, 4);
        for _ in 0..2 {
            for l in 0..200 {
                c.access(l);
            }
        }
        assert_eq!((c.accesses, c.hits), (400, 0));
    }

    /// A working set that fits: only compulsory misses.
    #[test]
    fn a_working_set_that_fits_misses_once_per_line() {
        let mut c = Cache::new(4096, 64, 4);
        for _ in 0..5 {
            for l in 0..64 {
                c.access(l);
            }
        }
        assert_eq!(c.misses(), 64);
    }

    /// Ways + 1 lines of one set, in turn: LRU evicts each before its reuse.
    #[test]
    fn a_conflict_pattern_on_one_set_thrashes() {
        let mut c = Cache::new(4096, 64, 4); // 16 sets
        for _ in 0..3 {
            for k in 0..5 {
                c.access(k * 16);
            }
        }
        assert_eq!(c.hits, 0);
        let mut c = Cache::new(4096, 64, 4);
        for _ in 0..3 {
            for k in 0..4 {
                c.access(k * 16);
            }
        }
        assert_eq!(c.misses(), 4);
    }

    /// Each reading step waits for the deepest level its lines came from: DRAM, L1, L2 and
    /// the last-level cache in turn on a one-unit GPU with direct-mapped L1 and L2, one step
    /// reading two lines (one in L1, one from DRAM) waiting for DRAM.
    #[test]
    fn a_step_waits_for_its_slowest_line() {
        let mut g = crate::memory::gpus::gpu("navi31").expect("navi31").clone();
        (g.units, g.l1_kib, g.l1_line, g.l1_ways) = (1, 1, 64, 1); // 16 sets
        (g.l2_kib, g.l2_line, g.l2_ways) = (2, 64, 1); // 32 sets
        (g.llc_kib, g.llc_line, g.llc_ways) = (64, 64, 16);
        g.latency_ns = [1.0, 10.0, 100.0, 1000.0];
        let line = |l: u64| (l * 64, 4);
        // 0 from DRAM, 0 in L1, 16 from DRAM (0 leaves the L1, stays in the L2), 0 from the L2,
        // 32 from DRAM (0 leaves the L1 and the L2, stays in the LLC), 0 from the LLC, then
        // 0 (L1) with 48 (DRAM) in one step.
        let steps = [0, 0, 16, 0, 32, 0].iter().map(|&l| vec![line(l)]).chain([vec![line(0), line(48)]]).collect();
        let waves = [WaveTrace { steps, rays: 32 }];
        let b = Buffers::new([56, 1000, 10]);
        let h = simulate(&g, &waves, 1, &b);
        assert_eq!(h.read_steps, 7);
        assert_eq!(h.wait_ns, 1000.0 + 1.0 + 1000.0 + 10.0 + 1000.0 + 100.0 + 1000.0);
        // One place (one unit, one wave): 32 rays in 4111 ns; more resident waves than waves
        // running add no place.
        assert_eq!((h.longest_wave_ns, h.places), (h.wait_ns, 1));
        let (step, bound) = crate::memory::latency(&h, 32);
        assert_eq!(step, 4111.0 / 7.0);
        assert!((bound - 32.0 / 4111.0 * 1e3).abs() < 1e-9, "{bound}");
        let h8 = simulate(&g, &waves, 8, &b);
        assert_eq!((h8.places, crate::memory::latency(&h8, 32).1), (1, bound));
        // Two waves on two places: no faster than the longer one, whatever the mean.
        let short = WaveTrace { steps: vec![vec![line(0)]], rays: 32 };
        let two = [waves[0].clone(), short];
        g.units = 2;
        let h = simulate(&g, &two, 1, &b);
        // (The short wave's line comes from the L2: the first wave brought it there.)
        assert_eq!((h.wait_ns, h.longest_wave_ns), (4111.0 + 10.0, 4111.0));
        let (_, bound) = crate::memory::latency(&h, 64);
        assert!((bound - 64.0 / 4111.0 * 1e3).abs() < 1e-9, "{bound}");
    }
}
