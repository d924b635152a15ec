//! The one CPU traversal, generic over the layout ([`Layout`]) and the packet width. P = 1 is
//! a packet of one ray. It is the bit-exact oracle of every kernel — hits and counters — and
//! follows the GLSL skeleton (`glsl/trav.comp`) step for step.
//!
//! Packet rule (identical in the kernels):
//! - A ray is *active* for a popped node when it hit that node's box and its closest hit so
//!   far is not nearer than its entry bound (`Layout::entry_t`). The node is visited when any
//!   ray is active; otherwise it is skipped. Each active ray counts the visit and its box
//!   tests.
//! - A child is visited when any active ray hits it. Children are ordered once per packet by
//!   the smallest key (entry distance) among the rays that hit them, ties by slot
//!   ([`order_children`]). Leaves are tested, in that order, by the rays that hit them (the
//!   kernels test them after the push, in slot order, one loop over the triangles of all the
//!   visit's leaves: the closest hit and the counters do not depend on the order, ties going to
//!   the lower prim); inner children are pushed farthest first.
//! - Each ray keeps its own closest hit and its own stack entry per level (inactive rays carry
//!   none).
//!
//! Packets are P consecutive rays; the last may be partial. Packet counters (nodes the packet
//! visited, active rays summed over them) are stored in its first ray.
//!
//! Kernels built with `DEFER_ENTRIES` (f16h, f16h-poster) derive each child's entry
//! when they enter the child instead of when it is pushed, from the same arguments: the
//! entries here are theirs (docs/architecture.md, "Deferred entries").

use super::{decode_child, Encoded, Layout, Node, TriBuffer};
use crate::base::tri::Branch;
use crate::base::Ray;
use crate::base::{slab32, ClosestTrue, Counters, Hit, RayPre};
use crate::bvh::ChildRef;
use crate::interface::CHILD_EMPTY;
use crate::precision::{FloatControls, Math};
use rayon::prelude::*;

/// Orders hit children by (key, slot) ascending: an insertion sort over slots given in
/// increasing order. The kernels reach the same order without sorting (trav.comp places each
/// inner child on the stack at its rank by (key, slot)). Keys are never NaN; −0 and +0
/// compare equal.
#[inline]
pub fn order_children(v: &mut [(f32, usize)]) {
    for i in 1..v.len() {
        let x = v[i];
        let mut j = i;
        while j > 0 && v[j - 1].0 > x.0 {
            v[j] = v[j - 1];
            j -= 1;
        }
        v[j] = x;
    }
}

/// One ray of a packet: its fp32 constants, the layout's constants, its closest hit, its
/// counters.
struct Lane<L: Layout> {
    r: RayPre,
    lr: L::Ray,
    best: ClosestTrue,
    c: Counters,
}

impl<L: Layout> Lane<L> {
    fn test_leaf(&mut self, tris: &TriBuffer, first: u32, count: u32) {
        for i in first..first + count {
            self.c.tri_tests += 1;
            self.best.test(&self.r, &tris.verts[i as usize], tris.ids[i as usize] as i32);
        }
    }
}

/// Buffers reused from packet to packet (one per worker thread).
struct Scratch<L: Layout> {
    lanes: Vec<Lane<L>>,
    /// Per stack level: the node, its parent and its slot there (the root: [`ROOT_PARENT`]).
    stack: Vec<(u32, u32, u32)>,
    /// P entries per stack level (`None`: the ray is inactive there).
    entries: Vec<Option<L::Entry>>,
    cur: Vec<Option<L::Entry>>,
    visits: Vec<Option<L::Visit>>,
    /// B × P box test results of the current node.
    res: Vec<Option<(f32, L::ChildHit)>>,
    order: Vec<(f32, usize)>,
    /// The visit's inner children to push, nearest first: node and slot.
    pend: Vec<(u32, u32)>,
    pend_entries: Vec<Option<L::Entry>>,
    /// Each lane's `tri_tests` when the current visit began (only while recording steps).
    lane_tris: Vec<u32>,
    /// Each lane's leaves hit in the current visit, (slot, first, count) (only while recording
    /// reads).
    lane_leaves: Vec<Vec<(usize, u32, u32)>>,
}

impl<L: Layout> Scratch<L> {
    fn new() -> Scratch<L> {
        Scratch {
            lanes: Vec::new(),
            stack: Vec::new(),
            entries: Vec::new(),
            cur: Vec::new(),
            visits: Vec::new(),
            res: Vec::new(),
            order: Vec::new(),
            pend: Vec::new(),
            pend_entries: Vec::new(),
            lane_tris: Vec::new(),
            lane_leaves: Vec::new(),
        }
    }
}

/// Traces `rays` in packets of `p` consecutive rays (in parallel), keeping input order.
pub fn trace_all<L: Layout, const B: usize>(
    nodes: &[L::Node<B>],
    root: &L::Root,
    enc: &Encoded,
    rays: &[Ray],
    p: usize,
    math: Math,
    fc: FloatControls,
) -> (Vec<Hit>, Vec<Counters>) {
    let p = p.max(1);
    let mut hits = vec![Hit::MISS; rays.len()];
    let mut counters = vec![Counters::default(); rays.len()];
    rays.par_chunks(p)
        .zip(hits.par_chunks_mut(p))
        .zip(counters.par_chunks_mut(p))
        .for_each_init(Scratch::<L>::new, |s, ((rays, hits), counters)| {
            packet::<L, B>(nodes, root, enc, rays, math, fc, s, hits, counters, None, None)
        });
    (hits, counters)
}

/// One pass of a packet's traversal loop (a single ray is a packet of one): one node entered, as
/// the kernel enters it (the root, then one per pop). `visited`: a ray was active there;
/// `tris`: the passes of the visit's triangle loop, which runs each lane through the triangles
/// of every leaf it hit (trav.comp, `test_leaves`): the most any lane of the packet tests. The
/// loop's last check, which finds no leaf left, is not counted as a pass.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Step {
    pub visited: bool,
    pub tris: u32,
}

/// One lane's reads of the scene's buffers in one pass of the traversal loop (recorded for
/// the memory model, [`mem_reads`]): the node it entered (when it was active there: the kernel
/// reads the node for its box tests), the triangles its visit tested in the kernel's order
/// (leaves in slot order, each leaf's triangles in order, `test_leaves`) with whether the test
/// read the triangle's id (`closest_test` reads it unless the certified test is a miss), and
/// the stack entries it pushed.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct Reads {
    pub node: Option<u32>,
    pub tris: Vec<(u32, bool)>,
    pub pushes: u32,
    /// The child this pass entered — its parent node, its slot there, and whether this lane hit
    /// it — for every pass but the root's (a kernel that derives entries when it enters a child,
    /// `stack_groups.glsl`'s `enter`, re-reads the parent's child word, and the child's box
    /// where the lane hit it).
    pub entered: Option<(u32, u32, bool)>,
}

/// The parent the root's stack level names: it has none.
const ROOT_PARENT: u32 = u32::MAX;

/// How often a kernel's loops run for a set of single rays: the traversal loop's passes
/// (`steps`), the passes in which a node is visited (`visits`; a visit runs the child-slot loop
/// once over every slot) and the triangle loop's passes (`tri_passes`).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct LoopWork {
    /// Waves (lanes in lockstep), each running the passes outside the loops once.
    pub waves: u64,
    pub rays: u64,
    pub steps: u64,
    pub visits: u64,
    pub tri_passes: u64,
}

impl std::ops::AddAssign for LoopWork {
    fn add_assign(&mut self, o: LoopWork) {
        self.waves += o.waves;
        self.rays += o.rays;
        self.steps += o.steps;
        self.visits += o.visits;
        self.tri_passes += o.tri_passes;
    }
}

impl LoopWork {
    /// One wave running `lanes` (each packet's or single ray's steps) in lockstep: the wave
    /// makes a pass while any lane does, visits when any lane visits, and runs a visit's
    /// triangle loop as long as its busiest lane.
    pub fn lockstep(lanes: &[Vec<Step>]) -> LoopWork {
        let k = lanes.iter().map(Vec::len).max().unwrap_or(0);
        let mut w = LoopWork { waves: 1, rays: lanes.len() as u64, steps: k as u64, ..Default::default() };
        for i in 0..k {
            let at = || lanes.iter().filter_map(move |l| l.get(i));
            w.visits += at().any(|s| s.visited) as u64;
            w.tri_passes += at().map(|x| x.tris as u64).max().unwrap_or(0);
        }
        w
    }

    /// The same lanes each on its own (the sum over lanes of one-lane waves; `waves` counts
    /// them).
    pub fn lanes(lanes: &[Vec<Step>]) -> LoopWork {
        let mut w = LoopWork::default();
        for l in lanes {
            w += LoopWork::lockstep(std::slice::from_ref(l));
        }
        w
    }
}

/// [`LoopWork`] of `rays` traced in packets of `p` consecutive rays (1: single rays), in waves
/// of `wave` consecutive rays (the last may be partial), a wave's packets in lockstep: summed
/// over the waves, and summed over the packets each on its own.
#[allow(clippy::too_many_arguments)]
pub fn loop_work<L: Layout, const B: usize>(
    nodes: &[L::Node<B>],
    root: &L::Root,
    enc: &Encoded,
    rays: &[Ray],
    p: usize,
    wave: usize,
    math: Math,
    fc: FloatControls,
) -> (LoopWork, LoopWork) {
    let p = p.max(1);
    rays.par_chunks(wave.max(p))
        .map_init(Scratch::<L>::new, |s, rays| {
            let lanes: Vec<Vec<Step>> = rays
                .chunks(p)
                .map(|rays| {
                    let n = rays.len();
                    let (mut hit, mut c, mut steps) = (vec![Hit::MISS; n], vec![Counters::default(); n], Vec::new());
                    packet::<L, B>(nodes, root, enc, rays, math, fc, s, &mut hit, &mut c, Some(&mut steps), None);
                    steps
                })
                .collect();
            (LoopWork::lockstep(&lanes), LoopWork::lanes(&lanes))
        })
        .reduce(Default::default, |mut a, b| {
            a.0 += b.0;
            a.1 += b.1;
            a
        })
}

/// How often a kernel's named branches run for a set of rays: the triangle loop's passes and,
/// per side of the triangle test ([`Branch`], `Branch as usize`), the passes in which it runs
/// — in lockstep, a wave runs a side in a pass when any of its lanes takes it there.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct BranchWork {
    pub tri_passes: u64,
    pub taken: [u64; Branch::ALL.len()],
}

impl std::ops::AddAssign for BranchWork {
    fn add_assign(&mut self, o: BranchWork) {
        self.tri_passes += o.tri_passes;
        for (a, b) in self.taken.iter_mut().zip(o.taken) {
            *a += b;
        }
    }
}

impl BranchWork {
    /// One wave running `lanes` (each lane's passes, each pass the sides its triangle tests
    /// took, in the kernel's order) in lockstep: a pass of the visit's triangle loop while any
    /// lane has a triangle left, a side run in it when any lane takes it.
    pub fn lockstep(lanes: &[Vec<Vec<u8>>]) -> BranchWork {
        let mut w = BranchWork::default();
        let passes = lanes.iter().map(Vec::len).max().unwrap_or(0);
        for i in 0..passes {
            let at = || lanes.iter().filter_map(move |l| l.get(i));
            let tris = at().map(Vec::len).max().unwrap_or(0);
            w.tri_passes += tris as u64;
            for j in 0..tris {
                let any = at().filter_map(|t| t.get(j)).fold(0u8, |a, &b| a | b);
                for b in Branch::ALL {
                    w.taken[b as usize] += (any & b.bit() != 0) as u64;
                }
            }
        }
        w
    }
}

/// [`BranchWork`] of `rays` from their packets' reads (`reads`, [`mem_reads`] of the same rays
/// in packets of `p`): each lane's triangle tests replayed in the kernel's order with the
/// closest-hit state the kernel keeps (`closest_test` of glsl/tri.glsl), in waves of `wave`
/// consecutive rays, the wave's lanes in lockstep — summed over the waves, and over the
/// packets each on its own.
pub fn branch_work(
    reads: &[Vec<Reads>],
    rays: &[Ray],
    tris: &TriBuffer,
    p: usize,
    wave: usize,
) -> (BranchWork, BranchWork) {
    let p = p.max(1);
    let per_wave = (wave.max(p) / p).max(1);
    reads
        .par_chunks(per_wave)
        .zip(rays.par_chunks(per_wave * p))
        .map(|(packets, rays)| {
            let mut lanes: Vec<Vec<Vec<u8>>> = Vec::new();
            let mut alone = BranchWork::default();
            for (packet, rays) in packets.iter().zip(rays.chunks(p)) {
                let n = rays.len();
                // Lane l's passes are reads l, l + n, … of its packet.
                let mine: Vec<Vec<Vec<u8>>> = rays
                    .iter()
                    .enumerate()
                    .map(|(l, ray)| {
                        let (r, mut best) = (RayPre::new(ray), ClosestTrue::fast(ray.tmax));
                        let test = |i: u32, best: &mut ClosestTrue| {
                            best.test_traced(&r, &tris.verts[i as usize], tris.ids[i as usize] as i32)
                        };
                        packet
                            .iter()
                            .skip(l)
                            .step_by(n)
                            .map(|pass| pass.tris.iter().map(|&(i, _)| test(i, &mut best)).collect())
                            .collect()
                    })
                    .collect();
                alone += BranchWork::lockstep(&mine);
                lanes.extend(mine);
            }
            (BranchWork::lockstep(&lanes), alone)
        })
        .reduce(Default::default, |mut a, b| {
            a.0 += b.0;
            a.1 += b.1;
            a
        })
}

/// Every packet's reads, pass by pass: for packets of `p` consecutive rays (1: single rays),
/// per packet its passes × its lanes (pass-major), as the kernel makes them. Hits and counters
/// are those of [`trace_all`] (not returned).
#[allow(clippy::too_many_arguments)]
pub fn mem_reads<L: Layout, const B: usize>(
    nodes: &[L::Node<B>],
    root: &L::Root,
    enc: &Encoded,
    rays: &[Ray],
    p: usize,
    math: Math,
    fc: FloatControls,
) -> Vec<Vec<Reads>> {
    let p = p.max(1);
    rays.par_chunks(p)
        .map_init(Scratch::<L>::new, |s, rays| {
            let n = rays.len();
            let (mut hit, mut c, mut reads) = (vec![Hit::MISS; n], vec![Counters::default(); n], Vec::new());
            packet::<L, B>(nodes, root, enc, rays, math, fc, s, &mut hit, &mut c, None, Some(&mut reads));
            reads
        })
        .collect()
}

/// Traces one packet of the encoded scene `enc` (`nodes` and `root` are its, typed).
#[allow(clippy::too_many_arguments)]
fn packet<L: Layout, const B: usize>(
    nodes: &[L::Node<B>],
    root: &L::Root,
    enc: &Encoded,
    rays: &[Ray],
    math: Math,
    fc: FloatControls,
    s: &mut Scratch<L>,
    hits: &mut [Hit],
    counters: &mut [Counters],
    mut steps: Option<&mut Vec<Step>>,
    mut reads: Option<&mut Vec<Reads>>,
) {
    let p = rays.len();
    let tris = &enc.tris;
    let (box_lo, box_hi): ([f32; 3], [f32; 3]) = (enc.root_box.min.into(), enc.root_box.max.into());
    let Scratch { lanes, stack, entries, cur, visits, res, order, pend, pend_entries, lane_tris, lane_leaves } = s;
    if reads.is_some() {
        lane_leaves.resize(p, Vec::new());
    }
    lanes.clear();
    stack.clear();
    entries.clear();
    let mut any_root = false;
    for ray in rays {
        let r = RayPre::new(ray);
        let lr = L::ray(&r, math, fc);
        let (near, far) = slab32(&r, box_lo, box_hi, r.tmin, r.tmax);
        let e = (near <= far).then(|| L::root_entry(root, &r, &lr, near));
        any_root |= e.is_some();
        entries.push(e);
        lanes.push(Lane {
            r,
            lr,
            best: ClosestTrue::fast(ray.tmax),
            c: Counters { box_tests: 1, ..Default::default() },
        });
    }
    if any_root {
        stack.push((0, ROOT_PARENT, 0));
    } else {
        entries.clear();
    }
    let (mut packet_nodes, mut active_lanes) = (0u32, 0u32);
    while let Some((ni, parent, slot)) = stack.pop() {
        if let Some(st) = steps.as_mut() {
            st.push(Step::default());
        }
        cur.clear();
        cur.extend(entries.drain(entries.len() - p..));
        if let Some(rd) = reads.as_mut() {
            rd.extend(cur.iter().map(|e| Reads {
                entered: (parent != ROOT_PARENT).then_some((parent, slot, e.is_some())),
                ..Reads::default()
            }));
        }
        visits.clear();
        let n = &nodes[ni as usize];
        let mut active = 0;
        for (lane, e) in lanes.iter().zip(cur.iter()) {
            let v = e
                .as_ref()
                .filter(|e| L::entry_t(e) <= lane.best.t)
                .map(|e| L::visit::<B>(n, root, e, &lane.r, &lane.lr, lane.best.t));
            active += v.is_some() as u32;
            visits.push(v);
        }
        if active == 0 {
            continue;
        }
        if let Some(st) = steps.as_mut().and_then(|st| st.last_mut()) {
            st.visited = true;
            lane_tris.clear();
            lane_tris.extend(lanes.iter().map(|l| l.c.tri_tests));
        }
        packet_nodes += 1;
        active_lanes += active;
        res.clear();
        order.clear();
        for slot in 0..B {
            if n.child(slot) == CHILD_EMPTY {
                break;
            }
            let mut key = f32::INFINITY;
            let mut hit = false;
            for l in 0..p {
                let t = match (&cur[l], &visits[l]) {
                    (Some(e), Some(v)) => {
                        let lane = &mut lanes[l];
                        lane.c.box_tests += 1;
                        L::test_child::<B>(n, slot, e, v, &lane.r, &lane.lr)
                    }
                    _ => None,
                };
                if let Some((k, _)) = t {
                    key = key.min(k);
                    hit = true;
                }
                res.push(t);
            }
            if hit {
                order.push((key, slot));
            }
        }
        order_children(order);
        pend.clear();
        pend_entries.clear();
        for &(_, slot) in order.iter() {
            let tests = &res[slot * p..slot * p + p];
            match decode_child(n.child(slot)) {
                ChildRef::Leaf { first, count } => {
                    for (l, (lane, t)) in lanes.iter_mut().zip(tests).enumerate() {
                        if t.is_some() {
                            lane.test_leaf(tris, first, count);
                            if reads.is_some() {
                                lane_leaves[l].push((slot, first, count));
                            }
                        }
                    }
                }
                ChildRef::Inner(j) => {
                    pend.push((j, slot as u32));
                    for l in 0..p {
                        let lane = &mut lanes[l];
                        let e = match (&tests[l], &cur[l], &visits[l]) {
                            (Some((_, h)), Some(e), Some(v)) => {
                                Some(L::child_entry::<B>(n, slot, e, v, h, &lane.r, &lane.lr, &mut lane.c))
                            }
                            _ => None,
                        };
                        pend_entries.push(e);
                    }
                }
            }
        }
        for (lane, v) in lanes.iter_mut().zip(visits.iter()) {
            if v.is_some() {
                lane.c.nodes += 1;
            }
        }
        // A packet's lanes run the visit's triangle loop together while any of them has a
        // triangle left.
        if let Some(st) = steps.as_mut().and_then(|st| st.last_mut()) {
            st.tris = lanes.iter().zip(lane_tris.iter()).map(|(l, &t0)| l.c.tri_tests - t0).max().unwrap_or(0);
        }
        if let Some(rd) = reads.as_mut() {
            let at = rd.len() - p;
            for (l, lane) in lanes.iter().enumerate() {
                let r = &mut rd[at + l];
                r.node = visits[l].is_some().then_some(ni);
                r.pushes = (0..pend.len()).filter(|k| pend_entries[k * p + l].is_some()).count() as u32;
                let leaves = &mut lane_leaves[l];
                leaves.sort_by_key(|x| x.0);
                for &(_, first, count) in leaves.iter() {
                    for i in first..first + count {
                        let miss = matches!(
                            crate::base::tri::certify(&lane.r, &tris.verts[i as usize]),
                            crate::base::tri::Cert::Miss
                        );
                        r.tris.push((i, !miss));
                    }
                }
                leaves.clear();
            }
        }
        for k in (0..pend.len()).rev() {
            stack.push((pend[k].0, ni, pend[k].1));
            entries.extend_from_slice(&pend_entries[k * p..k * p + p]);
        }
    }
    for ((lane, h), c) in lanes.iter().zip(hits.iter_mut()).zip(counters.iter_mut()) {
        *h = lane.best.hit();
        *c = lane.c;
    }
    counters[0].packet_nodes = packet_nodes;
    counters[0].active_lanes = active_lanes;
}
