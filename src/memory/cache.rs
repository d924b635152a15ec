//! The cache model: set-associative caches with LRU replacement ([`Cache`]), arranged as a
//! GPU's hierarchy ([`Hierarchy`]: an L1 per compute unit, a shared L2, a last-level cache
//! where the GPU has one, then DRAM), fed by the waves the GPU runs at once ([`simulate`]).
//!
//! A model, not the hardware: sets are chosen by the line address modulo the set count (real
//! caches hash it), replacement is true LRU, there is no prefetch, no write traffic (the
//! traversal only reads the scene), no texture path, no compression, and the L2's slices are
//! one cache.

use super::gpus::Gpu;
use super::WaveTrace;

/// One set-associative cache, LRU.
#[derive(Clone, Debug)]
pub struct Cache {
    pub line: u64,
    sets: u64,
    ways: usize,
    /// Per set, its ways' line numbers (`u64::MAX`: empty) and last-use stamps.
    tags: Vec<u64>,
    stamps: Vec<u64>,
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
            clock: 0,
            accesses: 0,
            hits: 0,
        }
    }

    /// Reads line number `l` (byte address ÷ `line`): whether it hit. A miss fills the line,
    /// evicting the set's least recently used.
    pub fn access(&mut self, l: u64) -> bool {
        self.clock += 1;
        self.accesses += 1;
        let base = ((l % self.sets) as usize) * self.ways;
        let set = base..base + self.ways;
        if let Some(w) = self.tags[set.clone()].iter().position(|&t| t == l) {
            self.stamps[base + w] = self.clock;
            self.hits += 1;
            return true;
        }
        let victim = set.min_by_key(|&i| (self.tags[i] != u64::MAX, self.stamps[i])).expect("a way");
        (self.tags[victim], self.stamps[victim]) = (l, self.clock);
        false
    }

    pub fn misses(&self) -> u64 {
        self.accesses - self.hits
    }
}

/// A GPU's caches: one L1 per unit, the L2, the last-level cache if any, and the bytes that
/// reached DRAM (all of them, and those of the node buffer).
#[derive(Clone, Debug)]
pub struct Hierarchy {
    pub l1: Vec<Cache>,
    pub l2: Cache,
    pub llc: Option<Cache>,
    pub dram_bytes: u64,
    pub dram_node_bytes: u64,
    /// Bytes below this address are the node buffer's.
    nodes_end: u64,
}

impl Hierarchy {
    pub fn new(g: &Gpu, units: usize, nodes_end: u64) -> Hierarchy {
        Hierarchy {
            l1: vec![Cache::new(g.l1_kib * 1024, g.l1_line, g.l1_ways); units.max(1)],
            l2: Cache::new(g.l2_kib * 1024, g.l2_line, g.l2_ways),
            llc: (g.llc_kib > 0).then(|| Cache::new(g.llc_kib * 1024, g.llc_line, g.llc_ways)),
            dram_bytes: 0,
            dram_node_bytes: 0,
            nodes_end,
        }
    }

    /// Unit `unit` reads the L1 line holding byte `addr`.
    pub fn read(&mut self, unit: usize, addr: u64) {
        let l1 = &mut self.l1[unit];
        let a = addr / l1.line * l1.line;
        if l1.access(a / l1.line) {
            return;
        }
        let span = l1.line;
        // The L1 line's bytes in L2 lines (one when the L2's line is the longer).
        let mut b = a / self.l2.line * self.l2.line;
        while b < a + span {
            if !self.l2.access(b / self.l2.line) {
                self.below_l2(b);
            }
            b += self.l2.line;
        }
    }

    fn below_l2(&mut self, b: u64) {
        let span = self.l2.line;
        let (line, hit) = match self.llc.as_mut() {
            None => (span, false),
            Some(llc) => {
                let mut c = b / llc.line * llc.line;
                let mut missed = 0;
                while c < b + span {
                    if !llc.access(c / llc.line) {
                        missed += llc.line;
                    }
                    c += llc.line;
                }
                (missed, missed == 0)
            }
        };
        if !hit {
            self.dram_bytes += line;
            if b < self.nodes_end {
                self.dram_node_bytes += line;
            }
        }
    }
}

/// Runs `waves` on `g` as it would run them at once: wave i starts on unit i mod units, each
/// unit holds `resident` waves, and in each round every resident wave makes one lockstep step
/// (units in turn); a finished wave's place goes to the next wave not yet started.
pub fn simulate(g: &Gpu, waves: &[WaveTrace], resident: usize, nodes_end: u64) -> Hierarchy {
    let units = g.units as usize;
    let mut h = Hierarchy::new(g, units, nodes_end);
    // Waves that read nothing (every ray missed the scene's box) take no step.
    let waves: Vec<&WaveTrace> = waves.iter().filter(|w| !w.steps.is_empty()).collect();
    let slots = units * resident.max(1);
    // (wave, next step) per slot; slot s belongs to unit s % units.
    let mut running: Vec<Option<(usize, usize)>> = (0..slots).map(|s| (s < waves.len()).then_some((s, 0))).collect();
    let mut next = slots.min(waves.len());
    let mut lines = Vec::new();
    while running.iter().any(Option::is_some) {
        for (s, r) in running.iter_mut().enumerate() {
            let Some((w, step)) = *r else { continue };
            // The step's lanes coalesce: each distinct L1 line is one request.
            lines.clear();
            super::lines_of(&waves[w].steps[step], g.l1_line, &mut lines);
            for &l in &lines {
                h.read(s % units, l * g.l1_line);
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
}
