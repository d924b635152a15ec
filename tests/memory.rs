//! The memory side (`halftrace memory`): its exact tiers hold the identities they must, and
//! the cache model agrees with patterns of known answer and with an independent implementation
//! on the same trace.

mod common;
use common::*;
use halftrace::base::Ray;
use halftrace::layout::traverse::Reads;
use halftrace::layout::LayoutId;
use halftrace::memory::cache::{simulate, Cache};
use halftrace::memory::gpus::{gpu, GPUS};
use halftrace::memory::{
    is_write, lines_of, private_offset, requested, wave_lines, waves, Buffers, Enter, Stack, WaveTrace, PRIVATE,
};
use halftrace::precision::{FloatControls, Math};

fn sets() -> (Prepared, Vec<(String, Vec<Ray>)>) {
    let p = prepare(&scene_path("teapot.obj"));
    let s = ray_sets(&p, 48, 256);
    (p, s)
}

/// Requested node bytes per ray = nodes visited × node bytes, vertex bytes = triangle tests ×
/// 36, on every layout and math at B = 4, 8 and P = 1, 8, every ray set; each lane's passes
/// visit what its counters say.
#[test]
fn requested_bytes_are_the_counters_times_the_record_sizes() {
    let (p, sets) = sets();
    for layout in LayoutId::all() {
        for b in [4, 8] {
            let enc = encode(&p, layout, b);
            let buf = Buffers::new([enc.node_size(), enc.nodes.len(), enc.tris.verts.len()]);
            for &math in layout.info().maths {
                for pk in [1, 8] {
                    for (kind, rays) in &sets {
                        let what = format!("{layout} {} B={b} P={pk} {kind}", math.name());
                        let (_, c) = layout.imp().trace(&enc, rays, pk, math, FloatControls::On);
                        let reads = layout.imp().mem_reads(&enc, rays, pk, math, FloatControls::On);
                        let q = requested(&reads, &buf, &Stack { entry: 8, slots: 97, meta: None }, pk);
                        let nodes: u64 = c.iter().map(|c| c.nodes as u64).sum();
                        let tests: u64 = c.iter().map(|c| c.tri_tests as u64).sum();
                        assert_eq!((q.visits, q.tests), (nodes, tests), "{what}: visits and tests");
                        assert_eq!(q.nodes, nodes * enc.node_size() as u64, "{what}: node bytes");
                        assert_eq!(q.verts, 36 * tests, "{what}: vertex bytes");
                        assert!(q.ids <= 4 * tests, "{what}: id bytes");
                    }
                }
            }
        }
    }
}

/// Entering a child in the kernels that derive its entry then (f16h, f16h-poster:
/// `stack_groups.glsl`'s `enter`) re-reads the parent's child word of that slot — the word of
/// the node the pass visits — and, where the lane hit the child, the child's box: the ranges
/// [`Enter`] names hold exactly those bytes of the uploaded nodes. Every pass but the root's
/// enters a child; single rays enter only children they hit; the requested bytes are the
/// ranges'; the other layouts' kernels re-read nothing.
#[test]
fn entering_a_child_rereads_its_parent_where_the_kernel_does() {
    use halftrace::bvh::ChildRef;
    use halftrace::layout::decode_child;
    let (p, sets) = sets();
    for layout in LayoutId::all() {
        for b in [4, 8] {
            let enc = encode(&p, layout, b);
            let bytes = enc.nodes.to_bytes();
            let ns = enc.node_size() as u64;
            let word = |a: u64| u32::from_le_bytes(bytes[a as usize..a as usize + 4].try_into().unwrap());
            let half = |a: u64| u16::from_le_bytes(bytes[a as usize..a as usize + 2].try_into().unwrap());
            for &math in layout.info().maths {
                let v = halftrace::variant::Variant::new(layout, b, 1).with_math(math);
                let en = Enter::of(&v);
                assert_eq!(en.is_some(), v.defers_entries(), "{layout} {}", math.name());
                // The box is re-read as pair words where the math's box test takes two slots at
                // once (`HALF_PAIRS`: glsl/half_f16.glsl and half_mixed.glsl, with float controls).
                if let Some(en) = en {
                    assert_eq!(en.pairs, math != Math::F32, "{layout} {}: pairs", math.name());
                    assert_eq!(en.bytes(true), if en.pairs { 28 } else { 16 }, "{layout} {}", math.name());
                    if layout.info().float_controls_off {
                        let off = Enter::of(&v.with_fc(FloatControls::Off)).unwrap();
                        assert!(!off.pairs, "{layout} {} without float controls: pairs", math.name());
                    }
                }
                let buf = Buffers::new([enc.node_size(), enc.nodes.len(), enc.tris.verts.len()]).with_enter(en);
                for pk in [1, 8] {
                    for (kind, rays) in sets.iter().take(2) {
                        let what = format!("{layout} {} B={b} P={pk} {kind}", math.name());
                        let reads = layout.imp().mem_reads(&enc, rays, pk, math, FloatControls::On);
                        let (mut entered, mut ranged) = (0u64, 0u64);
                        for (k, packet) in reads.iter().enumerate() {
                            let lanes = pk.min(rays.len() - k * pk);
                            for (i, x) in packet.iter().enumerate() {
                                let Some((pn, ps, hit)) = x.entered else {
                                    assert!(i < lanes, "{what}: packet {k} pass {} entered nothing", i / lanes);
                                    continue;
                                };
                                assert!(i >= lanes, "{what}: the root's pass entered a child");
                                assert!(hit || pk > 1, "{what}: a single ray entered a child it missed");
                                let Some(en) = en else { continue };
                                let mut r = Vec::new();
                                en.ranges(pn as u64 * ns, ps as u64, hit, &mut r);
                                entered += en.bytes(hit);
                                ranged += r.iter().map(|r| r.1 as u64).sum::<u64>();
                                let w = word(r[0].0);
                                assert_eq!(w, enc.nodes.child(pn as usize, ps as usize), "{what}: child word");
                                if let Some(n) = x.node {
                                    assert!(
                                        matches!(decode_child(w), ChildRef::Inner(j) if j == n),
                                        "{what}: entered {n}"
                                    );
                                }
                                if hit {
                                    let (lo, hi) = enc.nodes.child_box(pn as usize, ps as usize);
                                    let want = lo.iter().chain(hi.iter()).map(|&x| half::f16::from_f32(x).to_bits());
                                    for (&(a, n), want) in r[1..].iter().zip(want) {
                                        // A pair's word holds the slot's half at its parity.
                                        let got = if n == 4 { half(a + 2 * (ps as u64 & 1)) } else { half(a) };
                                        assert_eq!(got, want, "{what}: node {pn} slot {ps} box half at {a}");
                                    }
                                    assert_eq!(r.len(), 7, "{what}: the child word and six box values");
                                }
                            }
                        }
                        let q = requested(&reads, &buf, &Stack { entry: 8, slots: 97, meta: None }, pk);
                        assert_eq!((q.enter, entered), (ranged, ranged), "{what}: enter bytes");
                        assert_eq!(q.enter > 0, en.is_some(), "{what}: enter bytes {}", q.enter);
                    }
                }
            }
        }
    }
}

/// The waves carry the entering reads: in a one-lane wave of a group kernel, every pass that
/// entered a child has the parent's ranges ([`Enter::ranges`] at the parent's place, nodes
/// padded or not) as the step just before its node step.
#[test]
fn the_waves_enter_before_they_visit() {
    let (p, sets) = sets();
    let layout = LayoutId::parse("f16h").unwrap();
    for b in [4, 8] {
        let enc = encode(&p, layout, b);
        for math in [Math::F16, Math::F32] {
            let v = halftrace::variant::Variant::new(layout, b, 1).with_math(math);
            let en = Enter::of(&v).unwrap();
            for align in [0, 128] {
                let buf = Buffers::new([enc.node_size(), enc.nodes.len(), enc.tris.verts.len()])
                    .with_node_align(align)
                    .with_enter(Some(en));
                let (kind, rays) = &sets[1];
                let reads = layout.imp().mem_reads(&enc, rays, 1, math, FloatControls::On);
                let ws = waves(&reads, rays.len(), 1, 1, &buf);
                let mut entered = 0;
                for (i, (lane, w)) in reads.iter().zip(&ws).enumerate() {
                    let mut at = 0;
                    for x in lane {
                        let Some((pn, ps, hit)) = x.entered else { continue };
                        let mut want = Vec::new();
                        en.ranges(buf.node(pn).0, ps as u64, hit, &mut want);
                        let j = (at..w.steps.len())
                            .find(|&j| w.steps[j] == want)
                            .unwrap_or_else(|| panic!("{kind} ray {i} B={b} align {align}: no entering step {want:?}"));
                        let node: Vec<_> = x.node.map(|n| buf.node(n)).into_iter().collect();
                        assert_eq!(w.steps.get(j + 1), Some(&node), "{kind} ray {i} B={b}: the node step follows");
                        at = j + 2;
                        entered += 1;
                    }
                }
                assert!(entered > rays.len(), "{kind} B={b}: {entered} entering steps");
            }
        }
    }
}

/// The lines of a wave of one lane are that ray's own; a wave of every ray twice has the same
/// lines as a wave of the rays once (so half per ray).
#[test]
fn one_lane_waves_and_doubled_rays_keep_their_lines() {
    let (p, sets) = sets();
    let layout = LayoutId::parse("f16h").unwrap();
    let enc = encode(&p, layout, 4);
    let buf = Buffers::new([enc.node_size(), enc.nodes.len(), enc.tris.verts.len()]);
    let math = layout.default_math();
    for (kind, rays) in &sets {
        let reads = layout.imp().mem_reads(&enc, rays, 1, math, FloatControls::On);
        let ones = waves(&reads, rays.len(), 1, 1, &buf);
        for (i, r) in reads.iter().enumerate() {
            // Ray i's own lines, step by step, from its reads directly.
            let mut own = 0;
            for x in r {
                let mut ranges: Vec<_> = x.node.map(|n| buf.node(n)).into_iter().collect();
                let mut v = Vec::new();
                lines_of(&ranges, 64, &mut v);
                own += v.len() as u64 * x.node.is_some() as u64;
                for &(t, id) in &x.tris {
                    ranges = vec![buf.verts(t)];
                    if id {
                        ranges.push(buf.id(t));
                    }
                    v.clear();
                    lines_of(&ranges, 64, &mut v);
                    own += v.len() as u64;
                }
            }
            assert_eq!(wave_lines(&ones[i..i + 1], 64), own, "{kind} ray {i}: a one-lane wave's lines");
        }
        let twice: Vec<Ray> = rays.iter().flat_map(|r| [*r, *r]).collect();
        let reads2 = layout.imp().mem_reads(&enc, &twice, 1, math, FloatControls::On);
        for line in [32, 64, 128] {
            let once = wave_lines(&waves(&reads, rays.len(), 1, 16, &buf), line);
            let doubled = wave_lines(&waves(&reads2, twice.len(), 1, 32, &buf), line);
            assert_eq!(once, doubled, "{kind}: {line}-byte lines of waves of 16 rays and of the same rays twice");
        }
    }
}

/// An LRU cache written another way: per set, a list of (line, dirty), most recent last.
struct Naive {
    sets: Vec<Vec<(u64, bool)>>,
    ways: usize,
    hits: u64,
    accesses: u64,
}

impl Naive {
    fn new(bytes: u64, line: u64, ways: usize) -> Naive {
        let lines = (bytes / line).max(1);
        let ways = (ways as u64).clamp(1, lines) as usize;
        let sets = (lines / ways as u64).max(1) as usize;
        Naive { sets: vec![Vec::new(); sets], ways, hits: 0, accesses: 0 }
    }
    /// A read (`write` false) or a write of line `l`: whether it hit, and the dirty line a miss
    /// pushed out. A write hit or miss leaves the line dirty; a read keeps its dirt.
    fn touch(&mut self, l: u64, write: bool) -> (bool, Option<u64>) {
        self.accesses += 1;
        let n = self.sets.len() as u64;
        let ways = self.ways;
        let set = &mut self.sets[(l % n) as usize];
        let (hit, dirty, out) = match set.iter().position(|x| x.0 == l) {
            Some(i) => (true, set.remove(i).1, None),
            None => {
                let out = if set.len() == ways { Some(set.remove(0)).filter(|x| x.1).map(|x| x.0) } else { None };
                (false, false, out)
            }
        };
        set.push((l, dirty || write));
        self.hits += hit as u64;
        (hit, out)
    }
    /// A write passing by: a held copy becomes the most recent; nothing counted.
    fn pass(&mut self, l: u64) {
        let n = self.sets.len() as u64;
        let set = &mut self.sets[(l % n) as usize];
        if let Some(i) = set.iter().position(|x| x.0 == l) {
            let x = set.remove(i);
            set.push(x);
        }
    }
}

/// The hierarchy of `simulate`, written again with the naive caches and its own schedule
/// loop: (L1 accesses, L1 hits, L2 accesses, L2 hits, LLC accesses, LLC hits, DRAM bytes, of
/// them written back). A
/// wave's private offsets go to its place's region: place `s` at `private + s × region`; a
/// write goes to a write-back L1, else to the L2 (passing a write-through L1); dirty lines go
/// down when pushed out.
/// The counts of [`naive_hierarchy`], then its reading steps, their summed latency (each step as
/// long as its deepest level's latency) and the longest wave's.
type NaiveCounts = ([u64; 8], u64, f64, f64);

fn naive_hierarchy(g: &halftrace::memory::gpus::Gpu, ws: &[WaveTrace], private: u64, region: u64) -> NaiveCounts {
    struct Levels {
        l2: Naive,
        llc: Option<Naive>,
        dram: u64,
        written: u64,
        l2_line: u64,
        llc_line: u64,
    }
    impl Levels {
        /// The LLC (or DRAM) takes the dirty L2 line at byte `b`.
        fn l2_out(&mut self, b: u64) {
            match self.llc.as_mut() {
                None => {
                    self.dram += self.l2_line;
                    self.written += self.l2_line;
                }
                Some(c) => {
                    let mut x = b / self.llc_line * self.llc_line;
                    while x < b + self.l2_line {
                        if c.touch(x / self.llc_line, true).1.is_some() {
                            self.dram += self.llc_line;
                            self.written += self.llc_line;
                        }
                        x += self.llc_line;
                    }
                }
            }
        }
        /// The L2 reads (or takes a write of) the line at byte `b`; where a read's bytes came
        /// from: 1 the L2, 2 the LLC, 3 DRAM.
        fn l2(&mut self, b: u64, write: bool) -> usize {
            let (hit, out) = self.l2.touch(b / self.l2_line, write);
            if let Some(o) = out {
                self.l2_out(o * self.l2_line);
            }
            if hit || write {
                return 1;
            }
            match self.llc.as_mut() {
                None => {
                    self.dram += self.l2_line;
                    3
                }
                Some(c) => {
                    let mut from = 2;
                    let mut x = b / self.llc_line * self.llc_line;
                    while x < b + self.l2_line {
                        let (h, o) = c.touch(x / self.llc_line, false);
                        self.dram += self.llc_line * (!h as u64 + o.is_some() as u64);
                        self.written += self.llc_line * o.is_some() as u64;
                        if !h {
                            from = 3;
                        }
                        x += self.llc_line;
                    }
                    from
                }
            }
        }
    }
    let units = g.units as usize;
    let mut l1: Vec<Naive> = (0..units).map(|_| Naive::new(g.l1_kib * 1024, g.l1_line, g.l1_ways)).collect();
    let mut lv = Levels {
        l2: Naive::new(g.l2_kib * 1024, g.l2_line, g.l2_ways),
        llc: (g.llc_kib > 0).then(|| Naive::new(g.llc_kib * 1024, g.llc_line, g.llc_ways)),
        dram: 0,
        written: 0,
        l2_line: g.l2_line,
        llc_line: g.llc_line,
    };
    // The L1 pushes out its dirty line `o`: its bytes into the L2, line by line.
    let l1_out = |lv: &mut Levels, o: u64| {
        let mut b = o * g.l1_line / g.l2_line * g.l2_line;
        while b < (o + 1) * g.l1_line {
            lv.l2(b, true);
            b += g.l2_line;
        }
    };
    let queue: Vec<&WaveTrace> = ws.iter().filter(|w| !w.steps.is_empty()).collect();
    let slots = units * g.resident;
    let mut slot: Vec<Option<(usize, usize)>> = (0..slots).map(|s| queue.get(s).map(|_| (s, 0))).collect();
    let mut next = slots.min(queue.len());
    let (mut read_steps, mut wait) = (0u64, 0f64);
    let mut wave_wait = vec![0f64; queue.len()];
    loop {
        let mut any = false;
        for s in 0..slots {
            let Some((w, i)) = slot[s] else { continue };
            any = true;
            let write = queue[w].steps[i].iter().any(|r| r.0 >= PRIVATE && r.0 & halftrace::memory::WRITE != 0);
            let line = if write && !g.l1_write_back { g.l2_line } else { g.l1_line };
            let mut lines: Vec<u64> = Vec::new();
            for &(a, n) in &queue[w].steps[i] {
                let a =
                    if a >= PRIVATE { (a & (halftrace::memory::WRITE - 1)) + private + s as u64 * region } else { a };
                for l in a / line..=(a + n as u64 - 1) / line {
                    if !lines.contains(&l) {
                        lines.push(l);
                    }
                }
            }
            lines.sort();
            let u = &mut l1[s % units];
            let mut deepest = 0;
            // A step whose lanes read nothing waits for nothing.
            let reads = !write && !lines.is_empty();
            for l in lines {
                if write && !g.l1_write_back {
                    u.pass(l * line / g.l1_line);
                    lv.l2(l * line, true);
                    continue;
                }
                let (hit, out) = u.touch(l, write);
                if let Some(o) = out {
                    l1_out(&mut lv, o);
                }
                if hit || write {
                    continue;
                }
                let (a, end) = (l * g.l1_line, (l + 1) * g.l1_line);
                let mut b = a / g.l2_line * g.l2_line;
                while b < end {
                    deepest = deepest.max(lv.l2(b, false));
                    b += g.l2_line;
                }
            }
            if reads {
                read_steps += 1;
                wait += g.latency_ns[deepest];
                wave_wait[w] += g.latency_ns[deepest];
            }
            slot[s] = if i + 1 < queue[w].steps.len() {
                Some((w, i + 1))
            } else if next < queue.len() {
                next += 1;
                Some((next - 1, 0))
            } else {
                None
            };
        }
        if !any {
            break;
        }
    }
    let (la, lh) = (l1.iter().map(|c| c.accesses).sum(), l1.iter().map(|c| c.hits).sum());
    let (ca, ch) = lv.llc.as_ref().map_or((0, 0), |c| (c.accesses, c.hits));
    let longest = wave_wait.into_iter().fold(0.0, f64::max);
    ([la, lh, lv.l2.accesses, lv.l2.hits, ca, ch, lv.dram, lv.written], read_steps, wait, longest)
}

/// Equal hit and miss counts at every level, and equal DRAM bytes, on a real trace, for every
/// modelled GPU (their line sizes, associativities and last-level caches differ), with the
/// stacks in private memory and without them.
#[test]
fn the_cache_model_agrees_with_an_independent_implementation() {
    let (p, sets) = sets();
    let layout = LayoutId::parse("q8").unwrap();
    let enc = encode(&p, layout, 4);
    let scene = Buffers::new([enc.node_size(), enc.nodes.len(), enc.tris.verts.len()]);
    let (kind, rays) = &sets[2];
    let reads: Vec<Vec<Reads>> = layout.imp().mem_reads(&enc, rays, 1, layout.default_math(), FloatControls::On);
    // Dirty lines written back to DRAM somewhere: the write path is exercised.
    let mut written_back = 0;
    for buf in [
        scene,
        scene.with_stack(Stack { entry: 8, slots: 97, meta: None }),
        scene.with_stack(Stack { entry: 20, slots: 31, meta: Some(4) }),
    ] {
        for g in GPUS {
            // A small GPU of the same caches, so that waves queue and caches fill; a latency
            // per level that names the level in the sum.
            let small = halftrace::memory::gpus::Gpu {
                units: 2,
                resident: 2,
                l2_kib: 64,
                llc_kib: g.llc_kib.min(128),
                latency_ns: [1.0, 1e3, 1e6, 1e9],
                ..g.clone()
            };
            // Both ways an L1 can take the stacks' stores; with the GPU's lines, and (write-through)
            // with L2 lines half and twice the L1's, so that an L1 miss spans several L2 lines and
            // an L2 line several L1 lines.
            let (l1, l2) = (g.l1_line, g.l2_line);
            for (wb, l1_line, l2_line) in [(false, l1, l2), (true, l1, l2), (false, l1, l1 / 2), (false, l1 / 2, l1)] {
                let small = halftrace::memory::gpus::Gpu { l1_write_back: wb, l1_line, l2_line, ..small.clone() };
                let ws = waves(&reads, rays.len(), 1, g.wave, &buf);
                let h = simulate(&small, &ws, small.resident, &buf);
                let got = [
                    h.l1.iter().map(|c| c.accesses).sum(),
                    h.l1.iter().map(|c| c.hits).sum(),
                    h.l2.accesses,
                    h.l2.hits,
                    h.llc.as_ref().map_or(0, |c| c.accesses),
                    h.llc.as_ref().map_or(0, |c| c.hits),
                    h.dram_bytes,
                    h.dram_write_bytes,
                ];
                let region = buf.private_region(g.wave);
                let stack = buf.stack.is_some();
                let naive = naive_hierarchy(&small, &ws, buf.private_base(), region);
                assert_eq!(
                    (got, h.read_steps, h.wait_ns, h.longest_wave_ns),
                    naive,
                    "{} on {kind} rays, L1 write-back {wb}, lines {l1_line}/{l2_line}",
                    g.id
                );
                assert!(got[1] < got[0] && got[6] > 0, "{}: a trace that both hits and misses", g.id);
                assert!(h.dram_stack_bytes == 0 || stack, "{}: stack bytes from DRAM only with the stacks", g.id);
                assert!(h.dram_write_bytes <= h.dram_stack_bytes, "{}: only the stacks are written", g.id);
                written_back += h.dram_write_bytes;
            }
        }
    }
    assert!(written_back > 0, "no dirty line reached DRAM in any run");
    assert!(gpu("navi31").is_some() && gpu("nope").is_none());
}

/// The stacks in the traces, in both of the kernels' disciplines. An entry per child
/// (`stack_entries.glsl`): a visit writes every inner child it hit but the nearest, a pass
/// that entered nothing pops one — 2 × entry × Σ max(n − 1, 0) bytes per ray, counted here from
/// the reads, equal to what the traces move at every wave width. A group per visit
/// (`stack_groups.glsl`): a visit with two or more inner children writes one group, a pop reads
/// the top group and writes its order word back while children are left. Either way a pop
/// reads what its own lane wrote and offsets stay in the lane's region; entries are never
/// pushed over a live one and all are popped by the end; lanes pushing at one depth share lines; without
/// the stack, or at P > 1, the traces hold none.
#[test]
fn the_stacks_move_what_the_rays_push_and_pop() {
    let (p, sets) = sets();
    let layout = LayoutId::parse("f16w").unwrap();
    let enc = encode(&p, layout, 4);
    let scene = Buffers::new([enc.node_size(), enc.nodes.len(), enc.tris.verts.len()]);
    let entries = Stack { entry: 12, slots: 97, meta: None };
    let groups = Stack { entry: 20, slots: 31, meta: Some(4) };
    for (kind, rays) in &sets {
        let reads = layout.imp().mem_reads(&enc, rays, 1, layout.default_math(), FloatControls::On);
        // The entry discipline's bytes from the reads alone.
        let expect: u64 = reads.iter().flatten().map(|x| 2 * 12 * (x.pushes.max(1) as u64 - 1)).sum();
        assert!(expect > 0, "{kind}: some pushes");
        assert_eq!(requested(&reads, &scene, &entries, 1).stack, expect, "{kind}: requested stack bytes");
        for st in [entries, groups] {
            let buf = scene.with_stack(st);
            let q = requested(&reads, &buf, &st, 1);
            for wave in [1, 32, 64] {
                let ws = waves(&reads, rays.len(), 1, wave, &buf);
                let mut moved = 0;
                for w in &ws {
                    // Live dwords (by lane offset) and the step kinds, replayed in order.
                    let mut live = std::collections::HashSet::new();
                    for step in &w.steps {
                        let private: Vec<_> = step.iter().filter(|r| r.0 >= PRIVATE).collect();
                        if private.is_empty() {
                            continue;
                        }
                        assert_eq!(private.len(), step.len(), "{kind}: a step of stack and scene");
                        let write = is_write(step[0].0);
                        assert!(step.iter().all(|r| is_write(r.0) == write), "{kind}: reads and writes in a step");
                        for &&(a, n) in &private {
                            moved += n as u64;
                            let off = private_offset(a).unwrap();
                            assert!((off / 4) % (wave as u64) < w.rays as u64, "{kind} wave {wave}: no lane's offset");
                            assert!(off < buf.private_region(wave), "{kind} wave {wave}: offset {off} past the region");
                        }
                        let offs: Vec<u64> = step.iter().map(|r| private_offset(r.0).unwrap()).collect();
                        if !write {
                            assert!(
                                offs.iter().all(|o| live.contains(o)),
                                "{kind} {st:?}: a pop of what no push wrote"
                            );
                            if st.meta.is_none() {
                                offs.iter().for_each(|o| {
                                    live.remove(o);
                                });
                            }
                        } else if st.meta.is_none() {
                            assert!(offs.iter().all(|o| live.insert(*o)), "{kind}: a push over a live entry");
                        } else {
                            // Groups: a pop reads dwords a push of its lane wrote (a discarded
                            // group's slot is written again by the next group there).
                            live.extend(offs);
                        }
                    }
                    if st.meta.is_none() {
                        assert!(live.is_empty(), "{kind}: entries pushed and never popped");
                    }
                }
                assert_eq!(moved, q.stack, "{kind} {st:?}, waves of {wave}: stack bytes moved");
            }
        }
        let none = waves(&reads, rays.len(), 1, 32, &scene);
        assert!(none.iter().flat_map(|w| &w.steps).flatten().all(|r| r.0 < PRIVATE), "{kind}: no stack without it");
        let packets = layout.imp().mem_reads(&enc, rays, 8, layout.default_math(), FloatControls::On);
        let p8 = waves(&packets, rays.len(), 8, 32, &scene.with_stack(entries));
        assert!(p8.iter().flat_map(|w| &w.steps).flatten().all(|r| r.0 < PRIVATE), "{kind}: no stack at P = 8");
    }
    // 32 lanes each visiting a node with two inner children (one written, the nearest entered),
    // a leaf-less child (nothing), then popping the written one: 3 dwords a lane, the lanes'
    // dword k side by side — 384 contiguous bytes, 6 lines of 64 bytes, each way.
    let buf = scene.with_stack(entries);
    let visit = |pushes: u32| Reads { node: Some(0), tris: vec![], pushes, entered: None };
    let ws = waves(&vec![vec![visit(2), visit(0), visit(0)]; 32], 32, 1, 32, &buf);
    let stack_steps: Vec<&Vec<_>> = ws[0].steps.iter().filter(|s| s[0].0 >= PRIVATE).collect();
    assert_eq!(stack_steps.len(), 2, "one push step, one pop step");
    for s in stack_steps {
        let mut v = Vec::new();
        lines_of(s, 64, &mut v);
        let first = s.iter().map(|r| private_offset(r.0).unwrap()).min();
        assert_eq!((s.len(), v.len(), first), (96, 6, Some(0)));
    }
}

/// The known answers, through the hierarchy: a stream of distinct lines longer than every level
/// misses everywhere; the same small set of lines read again and again misses once per line.
#[test]
fn the_hierarchy_has_the_known_answers() {
    let g = halftrace::memory::gpus::Gpu { units: 1, resident: 1, ..gpu("navi31").unwrap().clone() };
    let line = g.l1_line;
    let far = (g.llc_kib * 1024 * 4) / line;
    let stream = WaveTrace { steps: (0..far).map(|i| vec![(i * line, line as u32)]).collect(), rays: 1 };
    let none = Buffers::new([0, 0, 0]);
    let h = simulate(&g, std::slice::from_ref(&stream), 1, &none);
    assert_eq!(h.l1[0].hits + h.l2.hits + h.llc.as_ref().unwrap().hits, 0);
    assert_eq!(h.dram_bytes, far * line);
    let small = WaveTrace { steps: (0..1000).map(|i| vec![((i % 10) * line, line as u32)]).collect(), rays: 1 };
    let h = simulate(&g, std::slice::from_ref(&small), 1, &none);
    assert_eq!((h.l1[0].accesses - h.l1[0].hits, h.dram_bytes), (10, 10 * line));
    let _ = Cache::new(1024, 64, 4);
}

/// The command: a bad GPU or branching is refused naming the flag; a small run writes its
/// three files, one verdict per GPU and coherence, every layout's rows with f32's ratio 1, and
/// its CSV reads back with the columns it names.
#[test]
fn the_command_writes_its_files_and_refuses_bad_flags() {
    use std::process::Command;
    let bin = env!("CARGO_BIN_EXE_halftrace");
    let dir = std::env::temp_dir().join(format!("halftrace-memory-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    let run = |args: &[&str]| Command::new(bin).arg("memory").args(args).output().unwrap();
    // A bad flag fails, its message naming it.
    for (flag, value, says) in [
        ("--gpu", "nope", "--gpu 'nope'"),
        ("--branchings", "3", "--branchings"),
        ("--node-align", "48", "--node-align 48"),
        ("--packets", "3", "--packets 3"),
    ] {
        let out = run(&[flag, value, "--out", dir.to_str().unwrap()]);
        let err = String::from_utf8_lossy(&out.stderr);
        assert!(!out.status.success() && err.contains(says), "{flag} {value}: {err}");
    }
    let teapot = scene_path("teapot.obj");
    // Packets: every row at the P asked, each layout's ratio to f32's at the same P.
    let pdir = dir.with_extension("packets");
    let out = run(&[
        "--gpu",
        "navi31",
        "--res",
        "24",
        "--rays",
        "primary",
        "--branchings",
        "4",
        "--packets",
        "4",
        "--layouts",
        "q8",
        "--scene",
        teapot.to_str().unwrap(),
        "--out",
        pdir.to_str().unwrap(),
    ]);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let rows = halftrace::report::memory::read(&pdir).unwrap().expect("memory.json");
    assert_eq!(rows.len(), 1 + LayoutId::parse("q8").unwrap().info().maths.len(), "f32 and q8's maths");
    for r in &rows {
        assert_eq!((r.packet, r.branching), (4, 4), "{}", r.kernel);
        assert!(r.node_bytes > 0.0 && r.dram_vs_f32.is_some(), "{}", r.kernel);
        if r.layout == "f32" {
            assert_eq!(r.dram_vs_f32, Some(1.0), "{}", r.kernel);
        }
    }
    std::fs::remove_dir_all(&pdir).unwrap();
    let out = run(&[
        "--gpu",
        "navi31,g610",
        "--res",
        "24",
        "--scene",
        teapot.to_str().unwrap(),
        "--out",
        dir.to_str().unwrap(),
    ]);
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(out.status.success(), "{text} {}", String::from_utf8_lossy(&out.stderr));
    assert_eq!(text.lines().filter(|l| l.contains("rays: **")).count(), 4, "{text}");
    let md = std::fs::read_to_string(dir.join("memory.md")).unwrap();
    assert!(md.starts_with("# The memory side of a ray\n\n## Verdict per GPU"), "{md}");
    let mut r = csv::Reader::from_path(dir.join("memory.csv")).unwrap();
    let h = r.headers().unwrap().clone();
    let col = |name: &str| h.iter().position(|c| c == name).unwrap_or_else(|| panic!("no column {name}"));
    let (layout, ratio) = (col("layout"), col("dram_vs_f32"));
    let rows: Vec<csv::StringRecord> = r.records().map(Result::unwrap).collect();
    // 2 GPUs × 3 ray kinds × every layout's maths × B 4, 8.
    let kernels: usize = LayoutId::all().map(|l| l.info().maths.len() * 2).sum();
    assert_eq!(rows.len(), 2 * 3 * kernels);
    for row in rows.iter().filter(|r| &r[layout] == "f32") {
        assert_eq!(&row[ratio], "1", "f32's own ratio");
    }
    // The roofline: the L2 bound is the GPU's L2 bandwidth over the bytes per ray requested from
    // the L2, a step's mean latency lies between the L1's and DRAM's, and the bound is the
    // lowest of the bounds, named by `binds`.
    let rows = halftrace::report::memory::read(&dir).unwrap().expect("memory.json");
    assert_eq!(rows.len(), 2 * 3 * kernels);
    for r in &rows {
        let g = gpu(&r.gpu).unwrap();
        let l2 = r.l2_bound_mrays.expect("an L2 bound");
        assert!(r.l2_bytes > 0.0 && (l2 * r.l2_bytes / (g.l2_gbs * 1e3) - 1.0).abs() < 1e-9, "{} {}", r.gpu, r.kernel);
        let lat = r.latency_bound_mrays.expect("a latency bound");
        assert!(lat > 0.0 && lat.is_finite(), "{} {}: latency bound {lat}", r.gpu, r.kernel);
        let (l1, dram) = (g.latency_ns[0], g.latency_ns[3]);
        assert!(r.step_ns >= l1 && r.step_ns <= dram, "{} {}: step {} ns", r.gpu, r.kernel, r.step_ns);
        let bounds = [
            (r.issue_bound_mrays, "issue"),
            (Some(lat), "latency"),
            (Some(l2), "L2"),
            (Some(r.dram_bound_mrays), "DRAM"),
        ];
        let lowest = bounds.iter().filter_map(|b| b.0).fold(f64::INFINITY, f64::min);
        assert_eq!(r.bound_mrays, lowest, "{} {}", r.gpu, r.kernel);
        assert!(
            bounds.iter().any(|b| b.0 == Some(lowest) && b.1 == r.binds),
            "{} {}: binds {}",
            r.gpu,
            r.kernel,
            r.binds
        );
    }
    std::fs::remove_dir_all(&dir).unwrap();
}

/// `memory --node-order`: every layout stores its nodes breadth first (the permutation to
/// breadth first is the identity); depth first is a permutation in which each subtree is
/// contiguous after its root; re-indexing the reads moves only addresses — the requested bytes
/// and the steps stay, and a one-lane wave's node steps are the permuted nodes' places.
#[test]
fn node_orders_move_addresses_only() {
    use halftrace::memory::{node_permutation, permute_nodes, NodeOrder};
    let (p, sets) = sets();
    let (kind, rays) = &sets[0];
    for layout in LayoutId::all() {
        for b in [4, 8] {
            let enc = encode(&p, layout, b);
            let n = enc.nodes.len();
            assert!(node_permutation(enc.nodes.as_ref(), b, NodeOrder::Layout).unwrap().is_none());
            let bfs = node_permutation(enc.nodes.as_ref(), b, NodeOrder::Bfs).unwrap().unwrap();
            assert_eq!(bfs, (0..n as u32).collect::<Vec<_>>(), "{layout} B={b}: stored breadth first");
            let dfs = node_permutation(enc.nodes.as_ref(), b, NodeOrder::Dfs).unwrap().unwrap();
            let mut seen = dfs.clone();
            seen.sort_unstable();
            assert_eq!(seen, (0..n as u32).collect::<Vec<_>>(), "{layout} B={b}: a permutation");
            assert_ne!(dfs, bfs, "{layout} B={b}: depth first differs on the teapot");
            // Depth first: a subtree of s nodes takes the s places after its root's.
            fn size(enc: &halftrace::layout::encoded::Encoded, b: usize, i: usize) -> usize {
                1 + (0..b)
                    .map(|s| enc.nodes.child(i, s))
                    .filter(|c| c & halftrace::interface::LEAF_BIT == 0)
                    .map(|c| size(enc, b, c as usize))
                    .sum::<usize>()
            }
            for i in 0..n.min(50) {
                let mut at = dfs[i] + 1;
                for c in (0..b).map(|s| enc.nodes.child(i, s)).filter(|c| c & halftrace::interface::LEAF_BIT == 0) {
                    assert_eq!(dfs[c as usize], at, "{layout} B={b}: node {i}'s child {c}");
                    at += size(&enc, b, c as usize) as u32;
                }
            }
            let buf = Buffers::new([enc.node_size(), n, enc.tris.verts.len()]);
            let stack = Stack { entry: 8, slots: 97, meta: None };
            let reads = layout.imp().mem_reads(&enc, rays, 1, Math::F32, FloatControls::On);
            let mut moved = reads.clone();
            permute_nodes(&mut moved, &dfs);
            let what = format!("{layout} B={b} {kind}");
            assert_eq!(requested(&reads, &buf, &stack, 1), requested(&moved, &buf, &stack, 1), "{what}");
            let (a, m) = (waves(&reads, rays.len(), 1, 1, &buf), waves(&moved, rays.len(), 1, 1, &buf));
            for (lane, (wa, wm)) in reads.iter().zip(a.iter().zip(&m)) {
                assert_eq!(wa.steps.len(), wm.steps.len(), "{what}: steps");
                let nodes: Vec<_> = lane.iter().filter_map(|x| x.node).map(|i| buf.node(dfs[i as usize])).collect();
                let steps: Vec<_> =
                    wm.steps.iter().filter(|s| s.len() == 1 && s[0].0 < buf.nodes_end()).map(|s| s[0]).collect();
                assert_eq!(steps, nodes, "{what}: the node steps at the permuted places");
            }
        }
    }
}
