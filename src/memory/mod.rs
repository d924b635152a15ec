//! `halftrace memory`: the memory side of a ray — what each kernel reads, from the CPU
//! reference's exact walk (lanes in lockstep), in three tiers:
//!
//! 1. **requested bytes per ray** (exact): nodes (the node record of every node a ray is
//!    active in), triangle vertices (36 bytes per test), triangle ids (4 bytes per test the
//!    certified test does not reject: `closest_test` reads it then), the parent-node bytes
//!    entering a child re-reads in the kernels that derive entries then ([`Enter`]), and the
//!    stack's bytes as the kernel's discipline moves them ([`Stack::ops`]; every modelled
//!    GPU's compiler keeps the single-ray kernels' stack arrays in private memory — scratch,
//!    local memory — as `isa`'s private bytes show);
//! 2. **distinct cache lines** (exact) of 32, 64 and 128 bytes, per ray alone and per wave in
//!    lockstep (at each step the union over the wave's lanes: what coalescing leaves), the
//!    stacks' pops and pushes among them (single rays, in private memory: [`Stack`]);
//! 3. **a cache model** ([`cache`]): each GPU's hierarchy ([`gpus`]) fed by the waves it runs
//!    at once, giving bytes and hit rates at each level and DRAM bytes per ray (a model).
//!
//! Addresses are those of the kernels' buffers: node `i` at `i × node size` in the node
//! buffer, triangle `i`'s vertices at `36 i` in the vertex buffer and its id at `4 i` in the id
//! buffer; the three buffers are placed one after another, each at a 64 KiB boundary (the
//! driver's placement is not known; 64 KiB keeps set indices as a fresh allocation would).

pub mod cache;
pub mod gpus;

use crate::layout::traverse::Reads;

/// A byte range a lane reads: (address, length).
pub type Range = (u64, u32);

/// A wave's reads in lockstep: per step, the ranges its lanes read in it (a traversal pass
/// pops its stack entries, reads the entered nodes, pushes its new entries, then each pass of
/// the triangle loop reads a triangle per lane). A range at [`PRIVATE`] + offset is in the
/// wave's own private memory (its lanes' stacks), placed where the wave runs ([`cache`]).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct WaveTrace {
    pub steps: Vec<Vec<Range>>,
    pub rays: usize,
}

/// Addresses from here on are offsets in a wave's private memory ([`WaveTrace`]).
pub const PRIVATE: u64 = 1 << 62;
/// Set beside [`PRIVATE`] on a range that is written (a stack push), not read.
pub const WRITE: u64 = 1 << 61;

/// The offset in the wave's private memory of an address at [`PRIVATE`], if it is one.
pub fn private_offset(a: u64) -> Option<u64> {
    (a >= PRIVATE).then_some(a & (WRITE - 1))
}

/// Whether an address is a write ([`WRITE`]).
pub fn is_write(a: u64) -> bool {
    a >= PRIVATE && a & WRITE != 0
}

/// Where the scene's buffers lie, and the stacks where the kernel keeps them in private memory.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Buffers {
    pub node_size: u64,
    /// Where node `i` starts: `i × stride` (the node size as the layouts pack them; larger in
    /// `memory --node-align`'s what-if, each node padded to a multiple of its alignment).
    pub stride: u64,
    pub nodes: u64,
    pub tris: u64,
    /// The traversal stack in private memory ([`Stack`]); `None`: left out of the traces.
    pub stack: Option<Stack>,
    /// What entering a child re-reads of its parent node, in kernels that derive entries then
    /// ([`Enter`]); `None` elsewhere.
    pub enter: Option<Enter>,
}

/// The parent-node reads of entering a child, in the kernels that derive a child's entry when
/// they enter it (`stack_groups.glsl`'s `enter`: f16h, f16h-poster): the child word of the
/// slot, and where the lane hit the child its box again (`retest_child`). Their node is
/// `Node16` (`src/layout/node16.rs`: `lo` f16[3][B] at 0, `hi` at 6·B, `child` u32[B] at 12·B);
/// the box is read half by half, or — where the math's box test takes two slots at once
/// (`HALF_PAIRS`: fp16 and mixed math with float controls) — as the 32-bit word of the slot's
/// pair, per axis.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Enter {
    pub branching: u64,
    pub pairs: bool,
}

impl Enter {
    /// A variant's: `None` where its kernels derive entries at the push.
    pub fn of(v: &crate::variant::Variant) -> Option<Enter> {
        use crate::precision::{FloatControls, Math};
        if !v.defers_entries() {
            return None;
        }
        assert!(
            matches!(v.layout.name(), "f16h" | "f16h-poster"),
            "{}: its kernels enter children from the parent's node, whose fields memory::Enter places \
             only for Node16",
            v.layout.name()
        );
        Some(Enter { branching: v.branching as u64, pairs: v.math != Math::F32 && v.fc == FloatControls::On })
    }

    /// The ranges entering slot `s` of the node at `at` reads (`hit`: the lane hit the child).
    pub fn ranges(&self, at: u64, s: u64, hit: bool, out: &mut Vec<Range>) {
        let b = self.branching;
        out.push((at + 12 * b + 4 * s, 4));
        if hit {
            for base in [0, 6 * b] {
                for a in 0..3 {
                    if self.pairs {
                        out.push((at + base + 2 * (a * b + (s & !1)), 4));
                    } else {
                        out.push((at + base + 2 * (a * b + s), 2));
                    }
                }
            }
        }
    }

    /// The bytes of [`Self::ranges`].
    pub fn bytes(&self, hit: bool) -> u64 {
        4 + if hit { 6 * if self.pairs { 4 } else { 2 } } else { 0 }
    }
}

/// A lane's traversal stack in private (scratch) memory, in the kernel's discipline: `slots`
/// entries of `entry` bytes (`stack_entries.glsl`: a visit pushes every inner child it hit but
/// the nearest, which it enters directly; a pass that enters nothing pops one), or — `meta`
/// given — `slots` groups of `entry + meta` bytes (`stack_groups.glsl`: a visit that hit two or
/// more inner children writes one group; a pop reads the top group and writes its order word
/// back while children are left in it). The wave's lanes are interleaved dword by dword (AMD's
/// swizzled scratch, NVIDIA's local memory: dword `k` of lane `l` at `(k × wave + l) × 4` of
/// the wave's region), so a wave's pushes at one depth are contiguous.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Stack {
    pub entry: u64,
    pub slots: u64,
    pub meta: Option<u64>,
}

/// One pass's stack traffic of one lane, in dwords of its own stack (first dword, dwords): the
/// pop before the pass (a read, then — groups — the order word written back) and the pushes
/// after it.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct PassOps {
    pub pop: Option<(u64, u64)>,
    pub pop_write: Option<(u64, u64)>,
    pub push: Vec<(u64, u64)>,
}

impl Stack {
    /// A slot's dwords.
    fn words(&self) -> u64 {
        (self.entry + self.meta.unwrap_or(0)).div_ceil(4)
    }

    /// A lane's stack, dwords.
    pub fn lane_words(&self) -> u64 {
        self.slots * self.words()
    }

    /// The stack traffic of a lane whose passes pushed `pushes` inner children each (the CPU
    /// reference's [`Reads::pushes`]), pass by pass, as the kernel moves it.
    pub fn ops(&self, pushes: impl Iterator<Item = u32>) -> Vec<PassOps> {
        let w = self.words();
        let mut out = Vec::new();
        // Entries (or groups) on the stack; each group's children left; whether the pass ahead
        // pops (the last entered nothing).
        let (mut depth, mut left, mut pop) = (0u64, Vec::<u32>::new(), false);
        for (i, n) in pushes.enumerate() {
            let mut ops = PassOps::default();
            if i > 0 && pop {
                match self.meta {
                    None => {
                        depth -= 1;
                        ops.pop = Some((depth * w, w));
                    }
                    Some(meta) => {
                        let g = left.len() as u64 - 1;
                        ops.pop = Some((g * w, w));
                        let last = left.last_mut().expect("a group to pop");
                        *last -= 1;
                        if *last == 0 {
                            left.pop();
                        } else {
                            let mw = meta.div_ceil(4);
                            ops.pop_write = Some((g * w + w - mw, mw));
                        }
                    }
                }
            }
            match (self.meta, n) {
                (_, 0) => {}
                (None, n) => {
                    for _ in 1..n {
                        ops.push.push((depth * w, w));
                        depth += 1;
                    }
                }
                (Some(_), 1) => {}
                (Some(_), n) => {
                    ops.push.push((left.len() as u64 * w, w));
                    left.push(n - 1);
                }
            }
            pop = n == 0;
            out.push(ops);
        }
        out
    }

    /// A variant's stack: its entry (node index and the layout's fields), in groups where its
    /// kernels defer entries (the order word: 4 bytes, 12 at B = 16).
    pub fn of(v: &crate::variant::Variant) -> Stack {
        let entry = crate::interface::stack_entry_bytes(v.stack_entry()) as u64;
        if v.defers_entries() {
            let meta = if v.branching > 8 { 12 } else { 4 };
            Stack { entry, slots: crate::variant::stack_groups(v.branching) as u64, meta: Some(meta) }
        } else {
            Stack { entry, slots: crate::variant::stack_entries(v.branching) as u64, meta: None }
        }
    }

    /// Bytes a lane's passes move through its stack (reads and writes).
    pub fn bytes(&self, pushes: impl Iterator<Item = u32>) -> u64 {
        self.ops(pushes)
            .iter()
            .map(|o| {
                4 * (o.pop.map_or(0, |r| r.1)
                    + o.pop_write.map_or(0, |r| r.1)
                    + o.push.iter().map(|r| r.1).sum::<u64>())
            })
            .sum()
    }
}

/// Where the nodes lie in `memory --node-order`'s what-if: as each layout stores them, or
/// re-indexed breadth first (every node's inner children side by side, level by level) or depth
/// first (each inner child's subtree before the next child's, in slot order), from the root.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, clap::ValueEnum)]
pub enum NodeOrder {
    #[default]
    Layout,
    Bfs,
    Dfs,
}

impl NodeOrder {
    /// How the nodes lie in this order, in words.
    pub fn what(self) -> &'static str {
        match self {
            NodeOrder::Layout => "as each layout stores them (breadth first, every layout)",
            NodeOrder::Bfs => "breadth first (each node's inner children side by side)",
            NodeOrder::Dfs => "depth first (each subtree contiguous, children in slot order)",
        }
    }

    pub fn name(self) -> &'static str {
        match self {
            NodeOrder::Layout => "layout",
            NodeOrder::Bfs => "bfs",
            NodeOrder::Dfs => "dfs",
        }
    }
}

/// The new index of every node of `nodes` (B slots each, the root at 0) in `order`, or `None`
/// for [`NodeOrder::Layout`]. An error where the child words do not form one tree over every
/// node (a layout whose child words are not node indices).
pub fn node_permutation(
    nodes: &dyn crate::layout::encoded::NodeArray,
    branching: usize,
    order: NodeOrder,
) -> anyhow::Result<Option<Vec<u32>>> {
    use crate::interface::LEAF_BIT;
    let n = nodes.len();
    let inner = |i: usize| (0..branching).map(move |s| nodes.child(i, s)).filter(|c| c & LEAF_BIT == 0);
    let mut seq: Vec<usize> = Vec::with_capacity(n);
    match order {
        NodeOrder::Layout => return Ok(None),
        NodeOrder::Bfs => {
            seq.push(0);
            let mut i = 0;
            while i < seq.len() && seq.len() <= n {
                seq.extend(inner(seq[i]).map(|c| c as usize));
                i += 1;
            }
        }
        NodeOrder::Dfs => {
            let mut todo = vec![0usize];
            while let Some(i) = todo.pop() {
                seq.push(i);
                if seq.len() > n {
                    break;
                }
                let kids: Vec<usize> = inner(i).map(|c| c as usize).collect();
                todo.extend(kids.into_iter().rev());
            }
        }
    }
    let mut perm = vec![u32::MAX; n];
    for (k, &old) in seq.iter().enumerate() {
        anyhow::ensure!(
            old < n && perm[old] == u32::MAX,
            "--node-order {}: node {old} reached twice or out of range ({n} nodes)",
            order.name()
        );
        perm[old] = k as u32;
    }
    anyhow::ensure!(seq.len() == n, "--node-order {}: {} of {n} nodes reached from the root", order.name(), seq.len());
    Ok(Some(perm))
}

/// The reads with every node index (visited and entered parents) moved by `perm`
/// ([`node_permutation`]).
pub fn permute_nodes(reads: &mut [Vec<Reads>], perm: &[u32]) {
    let at = |i: u32| perm.get(i as usize).copied().unwrap_or(i);
    for r in reads.iter_mut().flatten() {
        r.node = r.node.map(at);
        r.entered = r.entered.map(|(p, s, hit)| (at(p), s, hit));
    }
}

const ALIGN: u64 = 64 * 1024;

impl Buffers {
    pub fn new([node_size, nodes, tris]: [usize; 3]) -> Buffers {
        Buffers {
            node_size: node_size as u64,
            stride: node_size as u64,
            nodes: nodes as u64,
            tris: tris as u64,
            stack: None,
            enter: None,
        }
    }
    /// The same buffers, entering a child re-reading its parent as `enter` says ([`Enter`]).
    pub fn with_enter(self, enter: Option<Enter>) -> Buffers {
        Buffers { enter, ..self }
    }
    /// The same buffers, each node padded to a multiple of `align` bytes (a what-if: no layout
    /// places its nodes so; 0 or 1 leaves them packed).
    pub fn with_node_align(self, align: u64) -> Buffers {
        Buffers { stride: self.node_size.div_ceil(align.max(1)) * align.max(1), ..self }
    }
    /// The same buffers, the stacks in private memory.
    pub fn with_stack(self, stack: Stack) -> Buffers {
        Buffers { stack: Some(stack), ..self }
    }
    /// Where the waves' private memory starts: after the id buffer, aligned.
    pub fn private_base(&self) -> u64 {
        (self.ids_base() + 4 * self.tris).div_ceil(ALIGN) * ALIGN
    }
    /// A wave's private region of `wave` lanes, bytes (0 without the stack).
    pub fn private_region(&self, wave: usize) -> u64 {
        self.stack.map_or(0, |s| (s.lane_words() * 4 * wave as u64).div_ceil(256) * 256)
    }
    /// Where the node buffer ends (its bytes are the nodes').
    pub fn nodes_end(&self) -> u64 {
        self.nodes * self.stride
    }
    fn verts_base(&self) -> u64 {
        self.nodes_end().div_ceil(ALIGN) * ALIGN
    }
    fn ids_base(&self) -> u64 {
        (self.verts_base() + 36 * self.tris).div_ceil(ALIGN) * ALIGN
    }
    pub fn node(&self, i: u32) -> Range {
        (i as u64 * self.stride, self.node_size as u32)
    }
    pub fn verts(&self, i: u32) -> Range {
        (self.verts_base() + 36 * i as u64, 36)
    }
    pub fn id(&self, i: u32) -> Range {
        (self.ids_base() + 4 * i as u64, 4)
    }
}

/// The dwords `(first, count)` of lane `lane`'s stack in a wave of `wave` lanes, as ranges at
/// [`PRIVATE`] offsets, [`WRITE`] where `write`.
fn lane_words((first, count): (u64, u64), lane: usize, wave: usize, write: bool, out: &mut Vec<Range>) {
    let at = PRIVATE | if write { WRITE } else { 0 };
    for k in first..first + count {
        out.push((at + (k * wave as u64 + lane as u64) * 4, 4));
    }
}

/// The distinct lines of `line` bytes that `ranges` touch, appended to `out` (sorted).
pub fn lines_of(ranges: &[Range], line: u64, out: &mut Vec<u64>) {
    let start = out.len();
    for &(a, n) in ranges {
        out.extend(a / line..=(a + n.max(1) as u64 - 1) / line);
    }
    out[start..].sort_unstable();
    let mut v = out.split_off(start);
    v.dedup();
    out.extend(v);
}

/// The waves of `reads` (each packet's passes × lanes, [`crate::layout::traverse::mem_reads`],
/// of `rays` rays in packets of `p`: the last may hold fewer) in waves of `wave` lanes:
/// ⌊wave ÷ p⌋ packets in lockstep per wave (at least one), pass by pass, each pass its pops,
/// its entering reads ([`Enter`], where `b` has them), its node step, its pushes and its
/// triangle steps (the kernels push a visit's children before testing its leaves). The stack's
/// steps ([`Stack::ops`]) are there where `b` has it and for single rays (P = 1: a packet's
/// stack is the packet's, in shared memory or registers).
pub fn waves(reads: &[Vec<Reads>], rays: usize, p: usize, wave: usize, b: &Buffers) -> Vec<WaveTrace> {
    let p = p.max(1);
    let per_wave = (wave / p).max(1);
    let lanes = |k: usize| p.min(rays - k * p);
    let stack = b.stack.is_some() && p == 1;
    let mut out = Vec::new();
    for (w, packets) in reads.chunks(per_wave).enumerate() {
        let first = w * per_wave;
        let pass = |k: usize, i: usize| {
            let n = lanes(first + k);
            packets[k].get(i * n..(i + 1) * n)
        };
        let passes = (0..packets.len()).map(|k| packets[k].len() / lanes(first + k)).max().unwrap_or(0);
        // Each lane's stack traffic pass by pass (single rays: a packet is one lane).
        let ops: Vec<Vec<PassOps>> = match b.stack.filter(|_| stack) {
            Some(st) => packets.iter().map(|k| st.ops(k.iter().map(|x| x.pushes))).collect(),
            None => Vec::new(),
        };
        let mut steps = Vec::new();
        for i in 0..passes {
            let at = |k: usize| ops.get(k).and_then(|o| o.get(i));
            let (mut pops, mut back) = (Vec::new(), Vec::new());
            for k in 0..packets.len() {
                if let Some(o) = at(k) {
                    if let Some(r) = o.pop {
                        lane_words(r, k, wave, false, &mut pops);
                    }
                    if let Some(r) = o.pop_write {
                        lane_words(r, k, wave, true, &mut back);
                    }
                }
            }
            steps.extend([pops, back].into_iter().filter(|s| !s.is_empty()));
            // Entering the pass's node: a kernel that derives entries then re-reads its parent.
            if let Some(en) = b.enter {
                let mut reads = Vec::new();
                for x in (0..packets.len()).filter_map(|k| pass(k, i)).flatten() {
                    if let Some((pn, ps, hit)) = x.entered {
                        en.ranges(b.node(pn).0, ps as u64, hit, &mut reads);
                    }
                }
                if !reads.is_empty() {
                    steps.push(reads);
                }
            }
            let mut node = Vec::new();
            let mut most = 0;
            for x in (0..packets.len()).filter_map(|k| pass(k, i)).flatten() {
                node.extend(x.node.map(|n| b.node(n)));
                most = most.max(x.tris.len());
            }
            steps.push(node);
            // The visit pushes its inner children before it tests its leaves' triangles
            // (trav.comp: push_children, then test_leaves).
            let mut pushes = Vec::new();
            for k in 0..packets.len() {
                for &r in at(k).map_or(&[][..], |o| &o.push[..]) {
                    lane_words(r, k, wave, true, &mut pushes);
                }
            }
            if !pushes.is_empty() {
                steps.push(pushes);
            }
            for j in 0..most {
                let mut t = Vec::new();
                for x in (0..packets.len()).filter_map(|k| pass(k, i)).flatten() {
                    if let Some(&(i, id)) = x.tris.get(j) {
                        t.push(b.verts(i));
                        if id {
                            t.push(b.id(i));
                        }
                    }
                }
                steps.push(t);
            }
        }
        out.push(WaveTrace { steps, rays: (0..packets.len()).map(|k| lanes(first + k)).sum() });
    }
    out
}

/// Requested bytes, summed over rays: nodes, triangle vertices, triangle ids, stack, and the
/// parent-node re-reads of entering children ([`Enter`]).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Requested {
    pub nodes: u64,
    pub enter: u64,
    pub verts: u64,
    pub ids: u64,
    pub stack: u64,
    /// Node visits and triangle tests, summed over rays (the counters' `nodes`, `tri_tests`).
    pub visits: u64,
    pub tests: u64,
}

/// The bytes every lane of `reads` (packets of `p` rays) requests. The stack's: single rays'
/// as the kernel moves it ([`Stack::ops`]); a packet's (P > 1, in shared memory or registers)
/// two entries' bytes per child pushed, what it would move in memory.
pub fn requested(reads: &[Vec<Reads>], b: &Buffers, stack: &Stack, p: usize) -> Requested {
    let mut q = Requested::default();
    for x in reads.iter().flatten() {
        q.visits += x.node.is_some() as u64;
        q.tests += x.tris.len() as u64;
        q.ids += 4 * x.tris.iter().filter(|t| t.1).count() as u64;
        if let (Some(en), Some((_, _, hit))) = (b.enter, x.entered) {
            q.enter += en.bytes(hit);
        }
        if p > 1 {
            q.stack += 2 * stack.entry * x.pushes as u64;
        }
    }
    if p <= 1 {
        q.stack = reads.iter().map(|lane| stack.bytes(lane.iter().map(|x| x.pushes))).sum();
    }
    q.nodes = q.visits * b.node_size;
    q.verts = 36 * q.tests;
    q
}

/// Lines of `line` bytes summed over the waves' steps (each step its distinct lines).
pub fn wave_lines(waves: &[WaveTrace], line: u64) -> u64 {
    let mut v = Vec::new();
    let mut n = 0;
    for w in waves {
        for s in &w.steps {
            v.clear();
            lines_of(s, line, &mut v);
            n += v.len() as u64;
        }
    }
    n
}

/// What `memory` runs.
pub struct Config {
    pub scenes: Vec<std::path::PathBuf>,
    pub kinds: Vec<crate::rays::RayKind>,
    /// Side of the primary rays' image.
    pub res: u32,
    pub gpus: Vec<&'static gpus::Gpu>,
    pub variants: Vec<crate::variant::Variant>,
    /// `estimate`'s rows (`estimate-rays.json`): where one names a GPU's family, scene, ray
    /// set and kernel, its issue cycles bound the rays/s beside DRAM's.
    pub estimates: Vec<crate::report::estimate::RayRow>,
    /// The stacks in the traces and the cache model (single rays; [`Stack`]); `false` leaves
    /// them out (`memory --no-stack`).
    pub stack: bool,
    /// Nodes padded to a multiple of this many bytes (`memory --node-align`, a what-if; 0: as
    /// the layouts pack them).
    pub node_align: u64,
    /// Nodes re-indexed in this order (`memory --node-order`, a what-if; `Layout`: as stored).
    pub node_order: NodeOrder,
    /// `isa`'s rows of the single-ray kernels on one compilers release (`memory --compilers`):
    /// where a GPU's compiler ([`gpus::Gpu::compiler`]) built a kernel and gave its occupancy,
    /// that sets the kernel's resident waves per unit ([`resident`]); empty: every GPU's
    /// assumed figure.
    pub isa_rows: Vec<crate::report::isa::IsaRow>,
}

/// How many waves share a unit's L1 in the cache model, and where the figure comes from.
#[derive(Clone, Debug, PartialEq)]
pub struct Resident {
    pub waves: usize,
    /// `assumed` (with why, where a compiler's was sought), or the compiler's occupancy it was
    /// made from: `radv Mesa 26.2.6-1: 24 waves/SIMD × 2 SIMDs`.
    pub from: String,
}

/// The resident waves per unit of variant `v` on GPU `g`: the occupancy `g`'s compiler gave
/// the kernel in `rows` (`isa`'s, [`Config::isa_rows`]) in waves per unit — AMD's waves per
/// SIMD × the CU's SIMDs ([`gpus::Gpu::simds`]), Adreno's waves per core, NVIDIA's warps per SM,
/// Mali's thread class (2: the core's [`gpus::VALHALL_WARPS_PER_CORE`], 1: half of them), and
/// for Hopper the warps GA102's build's registers allow with Hopper's limits — where it built it
/// and gave one; else the model's assumed figure ([`gpus::Gpu::resident`]),
/// saying why where `rows` were given.
pub fn resident(g: &gpus::Gpu, v: &crate::variant::Variant, rows: &[crate::report::isa::IsaRow]) -> Resident {
    let assumed = |why: &str| Resident { waves: g.resident, from: format!("assumed{why}") };
    if rows.is_empty() {
        return assumed("");
    }
    let Some(target) = g.compiler else {
        return assumed(" (no compiler here reports its wave count)");
    };
    let row = rows.iter().find(|r| {
        r.family == target
            && r.layout == v.layout.name()
            && r.math == v.math.name()
            && r.branching == v.branching
            && r.packet == v.packet
    });
    let Some(r) = row else { return assumed(&format!(" ({target}: not built)")) };
    if !r.status.is_ok() {
        return assumed(&format!(" ({target}: {})", r.status));
    }
    let Some(o) = r.occupancy.filter(|&o| o >= 1.0) else {
        return assumed(&format!(" ({target}: no occupancy reported)"));
    };
    let n = o.round() as usize;
    let (waves, how) = match r.occupancy_unit.as_str() {
        "waves/SIMD" if g.simds > 0 => (n * g.simds as usize, format!(" × {} SIMDs", g.simds)),
        "waves/core" | "warps/SM" if target == g.id => (n, String::new()),
        // Hopper on GA102's build: the same 64 K registers per SM, up to 64 warps (GA102: 48).
        "warps/SM" => match r.registers {
            Some(gprs) => {
                let cap = crate::vendor::nvidia::HOPPER_MAX_WARPS;
                let w = crate::vendor::nvidia::warps(gprs, cap) as usize;
                (w, format!(" on {target}; {gprs} registers: {w} warps/SM with {}'s {cap}-warp limit", g.id))
            }
            None => return assumed(&format!(" ({target}'s build gave no registers)")),
        },
        // Mali's shaderdb thread class (2: at most 32 registers, full occupancy; 1: half).
        "threads" if g.id == "g610" && n <= 2 => {
            (n * gpus::VALHALL_WARPS_PER_CORE / 2, format!(" (of 2: {} warps/core at 2)", gpus::VALHALL_WARPS_PER_CORE))
        }
        u => return assumed(&format!(" ({target}: occupancy in {u}, not waves per {})", g.unit)),
    };
    // A device without float controls builds the kernel without them (`_fcoff`): its
    // occupancy stands for the variant's, said.
    let build = if r.float_controls != v.fc.name() { format!(" ({})", r.kernel) } else { String::new() };
    Resident { waves, from: format!("{}: {o} {}{how}{build}", r.driver, r.occupancy_unit) }
}

/// Every variant of `cfg` on every scene and ray set, each on every GPU model: its rows, with
/// their ratios to f32.
pub fn run(cfg: &Config, mut progress: impl FnMut(&str)) -> anyhow::Result<Vec<crate::report::memory::MemRow>> {
    use crate::report::memory::MemRow;
    use crate::report::What;
    use crate::runner::{rays::RaySpec, Runner};
    use crate::variant::KernelId;
    use anyhow::Context as _;
    use rayon::prelude::*;
    let mut rows = Vec::new();
    let mut runner = Runner::new(None, &[], Default::default())?;
    for path in &cfg.scenes {
        let (scene, triangles) = {
            let s = runner.scene(path).with_context(|| path.display().to_string())?.0;
            (s.name.clone(), s.len())
        };
        for kind in &cfg.kinds {
            let params = crate::rays::RayParams { width: cfg.res, height: cfg.res, ..Default::default() };
            let set = runner
                .ray_set(&RaySpec { kind: kind.clone(), params })
                .with_context(|| format!("{} {kind} rays", path.display()))?;
            let n = runner.rays(set).rays.len();
            for v in &cfg.variants {
                let id = KernelId::new(*v, v.portable_impl(), false);
                progress(&format!("{scene} {kind} {}", id.name()));
                let (mut reads, sizes) = runner.mem_reads(v, set)?;
                // The layout's own order (the default) needs neither the encoding nor a permutation.
                if cfg.node_order != NodeOrder::Layout {
                    let enc = runner.encoding(v.layout, v.branching)?;
                    let perm = node_permutation(enc.nodes.as_ref(), v.branching, cfg.node_order)
                        .with_context(|| format!("{} B={}", v.layout, v.branching))?;
                    if let Some(perm) = perm {
                        permute_nodes(&mut reads, &perm);
                    }
                }
                let stack = Stack::of(v);
                let b = Buffers::new(sizes).with_node_align(cfg.node_align);
                let b = if cfg.stack { b.with_stack(stack) } else { b };
                let b = b.with_enter(Enter::of(v));
                let q = requested(&reads, &b, &stack, v.packet);
                let per = |x: u64| x as f64 / n.max(1) as f64;
                let alone = waves(&reads, n, v.packet, v.packet, &b);
                let alone_lines = [32, 64, 128].map(|l| per(wave_lines(&alone, l)));
                // Each wave width's waves and lines once (several GPUs share a width).
                let mut widths: Vec<usize> = cfg.gpus.iter().map(|g| g.wave).collect();
                widths.sort_unstable();
                widths.dedup();
                let by_width: Vec<(usize, Vec<WaveTrace>, [f64; 3])> = widths
                    .into_iter()
                    .map(|w| {
                        let ws = waves(&reads, n, v.packet, w, &b);
                        let lines = [32, 64, 128].map(|l| per(wave_lines(&ws, l)));
                        (w, ws, lines)
                    })
                    .collect();
                let per_gpu = cfg.gpus.par_iter().map(|g| {
                    let (_, ws, lines) = by_width.iter().find(|x| x.0 == g.wave).expect("every width made");
                    let (ws, lines) = (ws.as_slice(), *lines);
                    let res = resident(g, v, &cfg.isa_rows);
                    let h = cache::simulate(g, ws, res.waves, &b);
                    let l1_acc: u64 = h.l1.iter().map(|c| c.accesses).sum();
                    let l1_hits: u64 = h.l1.iter().map(|c| c.hits).sum();
                    let rate = |hits: u64, acc: u64| if acc > 0 { hits as f64 / acc as f64 } else { 0.0 };
                    let llc = h.llc.as_ref();
                    let dram = per(h.dram_bytes);
                    let l2_bytes = per(h.l2.accesses * g.l2_line);
                    // Millions of rays per second `gbs` GB/s allows at `bytes` per ray.
                    let bound =
                        |gbs: f64, bytes: f64| if bytes > 0.0 { gbs * 1e9 / bytes / 1e6 } else { f64::INFINITY };
                    let (step_ns, latency_bound) = latency(&h, n);
                    MemRow {
                        gpu: g.id.into(),
                        scene: scene.clone(),
                        triangles,
                        rays: kind.to_string(),
                        ray_count: n,
                        kernel: id.name(),
                        layout: v.layout.name().into(),
                        math: v.math.name().into(),
                        branching: v.branching,
                        packet: v.packet,
                        wave: g.wave,
                        resident: res.waves,
                        resident_from: res.from,
                        status: Default::default(),
                        node_bytes: per(q.nodes),
                        vert_bytes: per(q.verts),
                        id_bytes: per(q.ids),
                        enter_bytes: per(q.enter),
                        stack_bytes: per(q.stack),
                        lines32_alone: alone_lines[0],
                        lines64_alone: alone_lines[1],
                        lines128_alone: alone_lines[2],
                        lines32: lines[0],
                        lines64: lines[1],
                        lines128: lines[2],
                        l1_bytes: per(l1_acc * g.l1_line),
                        l1_hit: rate(l1_hits, l1_acc),
                        l2_bytes,
                        l2_hit: rate(h.l2.hits, h.l2.accesses),
                        llc_bytes: llc.map_or(0.0, |c| per(c.accesses * c.line)),
                        llc_hit: llc.map_or(0.0, |c| rate(c.hits, c.accesses)),
                        dram_bytes: dram,
                        dram_node_bytes: per(h.dram_node_bytes),
                        dram_stack_bytes: per(h.dram_stack_bytes),
                        dram_nj: dram * 8.0 * g.pj_per_bit / 1000.0,
                        dram_bound_mrays: bound(g.dram_gbs, dram),
                        l2_bound_mrays: Some(bound(g.l2_gbs, l2_bytes)),
                        step_ns,
                        latency_bound_mrays: Some(latency_bound),
                        issue_bound_mrays: cfg
                            .estimates
                            .iter()
                            .find(|e| {
                                e.family == g.id
                                    && e.scene == scene
                                    && e.rays == kind.to_string()
                                    && e.kernel == id.name()
                                    && e.status.is_ok()
                            })
                            .filter(|_| g.simds > 0)
                            .map(|e| e.rays_per_kclk / 1000.0 * g.clock_mhz as f64 * (g.units * g.simds) as f64),
                        what: What::Builtin(id),
                        ..MemRow::default()
                    }
                });
                rows.extend(per_gpu.collect::<Vec<_>>());
            }
        }
    }
    // By GPU, then as run: scene, ray set, variant.
    rows.sort_by_key(|r| cfg.gpus.iter().position(|g| g.id == r.gpu));
    crate::report::memory::set_ratios(&mut rows);
    Ok(rows)
}

/// The latency side of the roofline, from a run of the cache model (`h`, [`cache::simulate`]):
/// the mean latency of a reading step (ns), and the millions of rays per second (of `rays` in
/// all) the latency allows — every place on the GPU (units × resident waves, at most one per
/// wave: [`cache::Hierarchy::places`]) runs its waves one after another, a wave as long as the
/// sum of its steps' latencies, so the waves need at least their summed latencies ÷ the places
/// (Little's law: what is in flight ÷ how long each takes), and at least the longest wave's.
pub fn latency(h: &cache::Hierarchy, rays: usize) -> (f64, f64) {
    let step = if h.read_steps > 0 { h.wait_ns / h.read_steps as f64 } else { 0.0 };
    let ns = if h.places > 0 { (h.wait_ns / h.places as f64).max(h.longest_wave_ns) } else { 0.0 };
    let bound = if ns > 0.0 { rays as f64 / ns * 1e3 } else { f64::INFINITY };
    (step, bound)
}

/// The default variants: every layout in every math at each of `branchings` and `packets`
/// (1: single rays), f32 always among them (every ratio's peer at the same B and P).
pub fn default_variants(
    branchings: &[usize],
    packets: &[usize],
    layouts: &[crate::layout::LayoutId],
) -> Vec<crate::variant::Variant> {
    use crate::layout::LayoutId;
    let mut v = Vec::new();
    for l in LayoutId::all().filter(|l| layouts.is_empty() || layouts.contains(l) || *l == LayoutId::f32()) {
        for &m in l.info().maths {
            for &p in packets {
                for &b in branchings {
                    v.push(crate::variant::Variant::new(l, b, p).with_math(m));
                }
            }
        }
    }
    v
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The what-if of padded nodes: node i starts at i × the padded stride, keeps its own
    /// bytes, and the buffers after the nodes move past the padded ones.
    #[test]
    fn padded_nodes_start_on_their_stride() {
        let b = Buffers::new([56, 1000, 10]);
        let p = b.with_node_align(64);
        assert_eq!((b.node(3), p.node(3)), ((168, 56), (192, 56)));
        assert_eq!((b.nodes_end(), p.nodes_end()), (56_000, 64_000));
        assert!(p.verts(0).0 >= p.nodes_end());
        // 56-byte nodes packed: node 1 straddles two 64-byte lines; padded: one each.
        let lines = |b: &Buffers| {
            let mut v = Vec::new();
            lines_of(&[b.node(1)], 64, &mut v);
            v.len()
        };
        assert_eq!((lines(&b), lines(&p)), (2, 1));
        assert_eq!(Buffers::new([112, 4, 4]).with_node_align(0).node(1), (112, 112));
    }

    /// The two disciplines on one lane's passes: a visit with three inner children, then three
    /// passes that enter nothing (the nearest child entered directly, the other two popped).
    #[test]
    fn each_discipline_moves_what_its_kernel_moves() {
        let pushes = [3u32, 0, 0, 0];
        let entries = Stack { entry: 12, slots: 97, meta: None };
        let ops = entries.ops(pushes.into_iter());
        // Two entries written (the nearest entered), popped at passes 2 and 3, top first.
        assert_eq!(ops[0].push, vec![(0, 3), (3, 3)]);
        assert_eq!((ops[1].pop, ops[2].pop, ops[3].pop), (None, Some((3, 3)), Some((0, 3))));
        assert_eq!(entries.bytes(pushes.into_iter()), 4 * 12);
        let groups = Stack { entry: 20, slots: 31, meta: Some(4) };
        let ops = groups.ops(pushes.into_iter());
        // One group of six dwords; the first pop writes its order word back, the last frees it.
        assert_eq!(ops[0].push, vec![(0, 6)]);
        assert_eq!((ops[2].pop, ops[2].pop_write), (Some((0, 6)), Some((5, 1))));
        assert_eq!((ops[3].pop, ops[3].pop_write), (Some((0, 6)), None));
        assert_eq!(groups.bytes(pushes.into_iter()), 4 * (6 + 6 + 1 + 6));
        // One inner child: entered directly, nothing on either stack.
        assert_eq!((entries.bytes([1u32, 0].into_iter()), groups.bytes([1u32, 0].into_iter())), (0, 0));
    }

    /// The resident waves: the compiler's occupancy in waves per unit where the GPU's compiler
    /// built the kernel and gave one (AMD: waves per SIMD × SIMDs per CU), else the assumed
    /// figure, saying why once rows were given.
    #[test]
    fn resident_waves_come_from_the_compilers_occupancy() {
        use crate::report::isa::{test_row, IsaRow};
        let gpu = |id: &str| gpus::gpu(id).unwrap();
        let v = crate::variant::Variant::new(crate::layout::LayoutId::parse("f16h").unwrap(), 4, 1);
        let row = |family: &str, occupancy: Option<f64>, unit: &str| IsaRow {
            occupancy,
            occupancy_unit: unit.into(),
            ..test_row("f16h", ("dev", family, "gen", "drv Mesa 26.2.6-1"))
        };
        // No rows: the assumed figure, said plainly.
        assert_eq!(resident(gpu("navi31"), &v, &[]), Resident { waves: 8, from: "assumed".into() });
        let release = crate::report::memory::resident_release;
        assert_eq!(release("assumed (a740: not built)"), None);
        // Another math of the same layout and B, built with another occupancy: not this one's.
        let m32 = crate::variant::Variant { math: crate::precision::Math::F32, ..v };
        let other_math = IsaRow { math: "f32".into(), ..row("navi31", Some(24.0), "waves/SIMD") };
        let rows = [
            other_math,
            row("navi31", Some(18.0), "waves/SIMD"),
            row("vega10", Some(3.0), "waves/SIMD"),
            row("a740", Some(6.0), "waves/core"),
            row("ga102", Some(16.0), "warps/SM"),
        ];
        let r = resident(gpu("navi31"), &v, &rows);
        assert_eq!(r, Resident { waves: 36, from: "drv Mesa 26.2.6-1: 18 waves/SIMD × 2 SIMDs".into() });
        assert_eq!(release(&r.from).as_deref(), Some("Mesa 26.2.6"));
        assert_eq!(resident(gpu("navi31"), &m32, &rows).waves, 48);
        // GCN: four SIMD16 per CU; Adreno and NVIDIA count per core and per SM already.
        assert_eq!(resident(gpu("vega10"), &v, &rows).waves, 12);
        assert_eq!(resident(gpu("a740"), &v, &rows).waves, 6);
        assert_eq!(resident(gpu("ga102"), &v, &rows).waves, 16);
        // Mali: the thread class, 1 (more than 32 registers) half the core's 64 warps, 2 all.
        let mali = |c: f64| resident(gpu("g610"), &v, &[row("g610", Some(c), "threads")]);
        assert_eq!((mali(1.0).waves, mali(2.0).waves), (32, 64));
        assert_eq!(mali(1.0).from, "drv Mesa 26.2.6-1: 1 threads (of 2: 64 warps/core at 2)");
        assert!(mali(3.0).from.starts_with("assumed (g610: occupancy in threads"));
        // Hopper on GA102's build: its registers by CUDA's rule, up to 64 warps (GA102's 48); GA102
        // itself takes its own row's occupancy.
        let nv = |gprs: f64| IsaRow { registers: Some(gprs), ..row("ga102", Some(20.0), "warps/SM") };
        assert_eq!(resident(gpu("ga102"), &v, &[nv(128.0)]).waves, 20);
        assert_eq!(resident(gpu("h100"), &v, &[nv(128.0)]).waves, 16);
        assert_eq!(resident(gpu("h200"), &v, &[nv(40.0)]).waves, 51);
        assert_eq!(
            resident(gpu("h100"), &v, &[nv(107.0)]).from,
            "drv Mesa 26.2.6-1: 20 warps/SM on ga102; 107 registers: 18 warps/SM with h100's 64-warp limit"
        );
        assert!(resident(gpu("h100"), &v, &rows).from.starts_with("assumed (ga102's build gave no registers"));
        // Another kernel (B = 8) was not built; Intel has no compiler here that counts; a failed
        // build, a missing occupancy or one in another unit falls back too.
        let b8 = crate::variant::Variant { branching: 8, ..v };
        assert_eq!(resident(gpu("a740"), &b8, &rows).from, "assumed (a740: not built)");
        assert_eq!(resident(gpu("g610"), &v, &rows).from, "assumed (g610: not built)");
        assert!(resident(gpu("lnl"), &v, &rows).from.starts_with("assumed (no compiler"));
        let failed = IsaRow { status: crate::base::Status::Failed("no".into()), ..rows[3].clone() };
        assert!(resident(gpu("a740"), &v, &[failed]).from.starts_with("assumed (a740: "));
        assert_eq!(resident(gpu("a740"), &v, &[row("a740", None, "")]).from, "assumed (a740: no occupancy reported)");
        let threads = row("a740", Some(512.0), "threads");
        assert_eq!(
            resident(gpu("a740"), &v, &[threads]).from,
            "assumed (a740: occupancy in threads, not waves per SP)"
        );
        // A build without float controls stands for the variant's, named.
        let fcoff =
            IsaRow { float_controls: "off".into(), kernel: "trav_f16h_m16_b4_p1_fcoff".into(), ..rows[3].clone() };
        assert!(resident(gpu("a740"), &v, &[fcoff]).from.ends_with("6 waves/core (trav_f16h_m16_b4_p1_fcoff)"));
    }
}
