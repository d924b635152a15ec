//! Binned SAH construction of a binary BVH in fp32 (Wald 2007, "On fast construction of
//! SAH-based bounding volume hierarchies"), parallel over subtrees with rayon. Nodes of at
//! least 65 536 triangles bin an even sample of them; nodes of at most 16 find the same split as
//! their bins would by sorting.

use crate::base::Aabb;
use crate::scene::Scene;
use bytemuck::Zeroable;
use glam::Vec3A;
use rayon::prelude::*;

/// SIMD box used inside the builder.
#[derive(Clone, Copy, Debug)]
struct Bx {
    min: Vec3A,
    max: Vec3A,
}

impl Bx {
    const EMPTY: Bx = Bx { min: Vec3A::splat(f32::INFINITY), max: Vec3A::splat(f32::NEG_INFINITY) };
    #[inline(always)]
    fn union(&self, o: &Bx) -> Bx {
        Bx { min: self.min.min(o.min), max: self.max.max(o.max) }
    }
    #[inline(always)]
    fn grow(&mut self, p: Vec3A) {
        self.min = self.min.min(p);
        self.max = self.max.max(p);
    }
    #[inline(always)]
    fn area(&self) -> f32 {
        let d = (self.max - self.min).max(Vec3A::ZERO);
        2.0 * (d.x * d.y + d.y * d.z + d.z * d.x)
    }
    fn aabb(&self) -> Aabb {
        Aabb { min: self.min.into(), max: self.max.into() }
    }
}

/// Number of SAH bins per axis (a power of two: `bin_of` masks the bin out of a float's bits).
pub const BINS: usize = 16;
const _: () = assert!(BINS.is_power_of_two() && SMALL <= 16);
/// Largest leaf; also bounded by the 4-bit count in the encoded child references.
pub const MAX_LEAF: usize = 8;
/// SAH cost of one node traversal relative to one triangle test.
pub const C_TRAV: f32 = 1.0;

/// A binary node: `count == 0` means inner with children `first` and `first + 1`;
/// otherwise a leaf holding `prims[first .. first + count]`.
#[derive(Clone, Copy, Debug, bytemuck::Zeroable)]
pub struct BinaryNode {
    pub bounds: Aabb,
    pub first: u32,
    pub count: u32,
}

impl BinaryNode {
    pub fn is_leaf(&self) -> bool {
        self.count > 0
    }
}

/// A binary BVH: `nodes[0]` is the root; `prims` lists triangle ids in leaf order.
#[derive(Clone, Debug)]
pub struct BinaryBvh {
    pub nodes: Vec<BinaryNode>,
    pub prims: Vec<u32>,
}

/// A triangle's box, partitioned in place beside its id (`prims`) so every pass over a node's
/// triangles reads memory in order.
type Ref = Bx;

/// Subtrees below this many triangles are built sequentially, each into its own block of slots.
const PAR_SUBTREE: usize = 4096;
/// Ranges above this many triangles have their bounds gathered in parallel.
const PAR_BOUNDS: usize = 1 << 17;
/// Chunk of triangles one parallel bounds task takes.
const PAR_CHUNK: usize = 1 << 15;
/// Nodes of at most this many triangles find the binned split by sorting their bin keys
/// (same candidates, same costs, no bin arrays to clear and sweep).
const SMALL: usize = 16;
/// Nodes of at least this many triangles choose their split from the bins of an even sample of
/// about `SAMPLES` of them (every (n / SAMPLES)-th in their current order); the partition then
/// gathers both sides' boxes. The top levels bin a few thousand triangles instead of millions.
const SAMPLE_FROM: usize = 1 << 16;
const SAMPLES: usize = 1 << 13;

/// Builds the binary BVH of a scene (a progress line when it takes over a second).
pub fn build_binary(scene: &Scene) -> BinaryBvh {
    crate::progress::step(&format!("building the BVH of {} ({} triangles)", scene.name, scene.tris.len()), || {
        build_binary_quiet(scene)
    })
}

fn build_binary_quiet(scene: &Scene) -> BinaryBvh {
    let n = scene.tris.len();
    let mut refs: Vec<Ref> = scene
        .tris
        .par_iter()
        .map(|t| {
            let (a, b, c) = (Vec3A::from(t[0]), Vec3A::from(t[1]), Vec3A::from(t[2]));
            Bx { min: a.min(b).min(c), max: a.max(b).max(c) }
        })
        .collect();
    let mut prims: Vec<u32> = (0..n as u32).into_par_iter().collect();
    let (b, cb) = range_bounds(&refs);
    // A subtree over k triangles has at most 2k − 1 nodes: it gets that many slots, its children
    // split them, and a sequential block fills its own slots densely from the front. The slots
    // come from the OS as zero pages, touched only where a node is written, and go back to it
    // in one piece once the blocks are copied out (blocks of their own would stay in the heap).
    let mut slots: Vec<BinaryNode> = bytemuck::zeroed_vec((2 * n).max(2) - 1);
    let top = build_top(&mut refs, &mut prims, 0, &mut slots, b, cb);
    drop(refs);
    let mut bvh = BinaryBvh { nodes: assemble(top), prims };
    refit_padded(scene, &mut bvh);
    bvh
}

/// Refits every node to the padded boxes of its triangles (`base::padded_box` with the scene's
/// `hit_pad`): the closest-hit rule admits a hit only where the exact ray reaches its
/// triangle's padded box, so every box above a triangle must contain that box for a
/// conservative traversal to find it. The tree was chosen with the unpadded boxes, so padding
/// changes no split, only the bounds (by 2⁻¹⁸ of the scene's extent).
fn refit_padded(scene: &Scene, bvh: &mut BinaryBvh) {
    let pad = scene.hit_pad();
    // Parents before children in `order`, so children are refitted first walking it backwards.
    let mut order = Vec::with_capacity(bvh.nodes.len());
    let mut stack = vec![0usize];
    while let Some(i) = stack.pop() {
        order.push(i);
        let n = bvh.nodes[i];
        if !n.is_leaf() {
            stack.push(n.first as usize);
            stack.push(n.first as usize + 1);
        }
    }
    for &i in order.iter().rev() {
        let n = bvh.nodes[i];
        let mut b = Aabb::EMPTY;
        if n.is_leaf() {
            for &p in &bvh.prims[n.first as usize..(n.first + n.count) as usize] {
                let t = &scene.tris[p as usize];
                let v = [t[0].x, t[0].y, t[0].z, t[1].x, t[1].y, t[1].z, t[2].x, t[2].y, t[2].z];
                let (lo, hi) = crate::base::padded_box(&v, pad);
                b = b.union(&Aabb { min: lo.into(), max: hi.into() });
            }
        } else {
            b = bvh.nodes[n.first as usize].bounds.union(&bvh.nodes[n.first as usize + 1].bounds);
        }
        bvh.nodes[i].bounds = b;
    }
}

/// The parallel top of the tree: inner nodes over at least `PAR_SUBTREE` triangles, down to
/// blocks built sequentially.
enum Sub<'a> {
    Inner(Bx, Box<(Sub<'a>, Sub<'a>)>),
    /// A sequentially built subtree: its root first; inner nodes' `first` indexes this block.
    Block(&'a [BinaryNode]),
}

fn build_top<'a>(
    refs: &mut [Ref],
    prims: &mut [u32],
    base: u32,
    slots: &'a mut [BinaryNode],
    bounds: Bx,
    cb: Bx,
) -> Sub<'a> {
    let n = refs.len();
    if n < PAR_SUBTREE {
        let mut used = 1;
        build_seq(refs, prims, base, slots, &mut used, 0, bounds, cb);
        let block: &'a [BinaryNode] = slots;
        return Sub::Block(&block[..used]);
    }
    let sp = split(refs, prims, &bounds, &cb).expect("a node of more than MAX_LEAF triangles always splits");
    let m = sp.mid;
    let (lrefs, rrefs) = refs.split_at_mut(m);
    let (lprims, rprims) = prims.split_at_mut(m);
    let (lslots, rslots) = slots.split_at_mut(2 * m - 1);
    let kids = rayon::join(
        || build_top(lrefs, lprims, base, lslots, sp.lb, sp.lcb),
        || build_top(rrefs, rprims, base + m as u32, rslots, sp.rb, sp.rcb),
    );
    Sub::Inner(bounds, Box::new(kids))
}

/// Builds the subtree over `refs`/`prims` (at `base` in the global triangle order) into
/// `block`, its root at `block[me]`; children go to the next free pair (`used`).
#[allow(clippy::too_many_arguments)]
fn build_seq(
    refs: &mut [Ref],
    prims: &mut [u32],
    base: u32,
    block: &mut [BinaryNode],
    used: &mut usize,
    me: usize,
    bounds: Bx,
    cb: Bx,
) {
    let n = refs.len();
    let Some(sp) = split(refs, prims, &bounds, &cb) else {
        block[me] = BinaryNode { bounds: bounds.aabb(), first: base, count: n as u32 };
        return;
    };
    let kid = *used;
    *used += 2;
    block[me] = BinaryNode { bounds: bounds.aabb(), first: kid as u32, count: 0 };
    let m = sp.mid;
    let (lrefs, rrefs) = refs.split_at_mut(m);
    let (lprims, rprims) = prims.split_at_mut(m);
    build_seq(lrefs, lprims, base, block, used, kid, sp.lb, sp.lcb);
    build_seq(rrefs, rprims, base + m as u32, block, used, kid + 1, sp.rb, sp.rcb);
}

/// One node array from the parallel top and its blocks: the top's nodes and the blocks' roots
/// first (depth-first), then each block's other nodes, copied in parallel with their child
/// indices moved to where the block lands.
fn assemble(top: Sub) -> Vec<BinaryNode> {
    fn inner_count(s: &Sub<'_>) -> usize {
        match s {
            Sub::Inner(_, kids) => 1 + inner_count(&kids.0) + inner_count(&kids.1),
            Sub::Block(_) => 0,
        }
    }
    let head_len = 1 + 2 * inner_count(&top);
    let mut head = vec![BinaryNode::zeroed(); head_len];
    // (block, where its nodes after the root land)
    let mut jobs: Vec<(&[BinaryNode], usize)> = Vec::new();
    let (mut pair, mut tail) = (1usize, head_len);
    let mut stack = vec![(&top, 0usize)];
    while let Some((s, at)) = stack.pop() {
        match s {
            Sub::Inner(b, kids) => {
                head[at] = BinaryNode { bounds: b.aabb(), first: pair as u32, count: 0 };
                stack.push((&kids.1, pair + 1));
                stack.push((&kids.0, pair));
                pair += 2;
            }
            Sub::Block(block) => {
                head[at] = moved(block[0], tail);
                jobs.push((&block[1..], tail));
                tail += block.len() - 1;
            }
        }
    }
    let mut out: Vec<BinaryNode> = bytemuck::zeroed_vec(tail);
    let (h, mut rest) = out.split_at_mut(head_len);
    h.copy_from_slice(&head);
    let mut parts = Vec::with_capacity(jobs.len());
    for &(src, at) in &jobs {
        let (dst, r) = std::mem::take(&mut rest).split_at_mut(src.len());
        parts.push((dst, src, at));
        rest = r;
    }
    parts.into_par_iter().for_each(|(dst, src, at)| {
        for (d, s) in dst.iter_mut().zip(src) {
            *d = moved(*s, at);
        }
    });
    out
}

/// A block's node once the block's nodes after its root start at `at`.
#[inline(always)]
fn moved(mut node: BinaryNode, at: usize) -> BinaryNode {
    if !node.is_leaf() {
        node.first += at as u32 - 1;
    }
    node
}

fn range_bounds(refs: &[Ref]) -> (Bx, Bx) {
    let f = |(b, mut c): (Bx, Bx), r: &Ref| {
        c.grow(r.min + r.max);
        (b.union(r), c)
    };
    let (b, c2) = if refs.len() >= PAR_BOUNDS {
        refs.par_chunks(PAR_CHUNK)
            .map(|ch| ch.iter().fold((Bx::EMPTY, Bx::EMPTY), f))
            .reduce(|| (Bx::EMPTY, Bx::EMPTY), |a, b| (a.0.union(&b.0), a.1.union(&b.1)))
    } else {
        refs.iter().fold((Bx::EMPTY, Bx::EMPTY), f)
    };
    (b, half(c2))
}

/// Centroid bounds are gathered as min + max (twice the centroid); halved once per node.
fn half(c2: Bx) -> Bx {
    Bx { min: c2.min * 0.5, max: c2.max * 0.5 }
}

/// 2^23: adding it to a float in [0, 2^22) leaves that float rounded to the nearest integer in
/// the low mantissa bits — a bin index without a (saturating, and slow) float-to-int conversion.
const MAGIC: f32 = 8_388_608.0;

/// The bin of a position already mapped to [0, BINS − 1] and offset by `MAGIC`; binning and
/// partition both go through this, so both sides of a split match the bins' counts.
#[inline(always)]
fn bin_of(t: f32) -> usize {
    (t.to_bits() & (BINS as u32 - 1)) as usize
}

/// Per axis, per bin: box and count (structure of arrays: one min and one max per update).
struct Bins {
    lo: [[Vec3A; BINS]; 3],
    hi: [[Vec3A; BINS]; 3],
    count: [[u32; BINS]; 3],
}

impl Bins {
    fn new() -> Bins {
        Bins { lo: [[Vec3A::INFINITY; BINS]; 3], hi: [[Vec3A::NEG_INFINITY; BINS]; 3], count: [[0; BINS]; 3] }
    }
}

/// Twice the centroid, mapped so `bin_of` of each lane gives that axis's bin.
#[inline(always)]
fn bin_pos(r: &Ref, origin2: Vec3A, scale2: Vec3A) -> [f32; 3] {
    ((r.min + r.max - origin2) * scale2 + Vec3A::splat(MAGIC)).to_array()
}

fn bin_chunk<'a>(refs: impl IntoIterator<Item = &'a Ref>, origin2: Vec3A, scale2: Vec3A) -> Bins {
    let mut bins = Bins::new();
    for r in refs {
        for (a, &t) in bin_pos(r, origin2, scale2).iter().enumerate() {
            let i = bin_of(t);
            bins.lo[a][i] = bins.lo[a][i].min(r.min);
            bins.hi[a][i] = bins.hi[a][i].max(r.max);
            bins.count[a][i] += 1;
        }
    }
    bins
}

/// A chosen split: position in the range and both children's bounds and centroid bounds.
struct Split {
    mid: usize,
    lb: Bx,
    lcb: Bx,
    rb: Bx,
    rcb: Bx,
}

/// The cheapest split so far: (cost, axis, last bin of the left side, left box, right box).
type Best = (f32, usize, usize, Bx, Bx);

/// The binned SAH over the bins of nodes above `SMALL` triangles: only occupied bins can end
/// a side (an empty bin repeats its neighbour's partition and cost).
fn sweep_bins(bins: &Bins, ext: Vec3A, best: &mut Best) {
    for a in 0..3 {
        if ext[a] <= 0.0 {
            continue;
        }
        let mut occ = [0usize; BINS];
        let mut m = 0;
        for (i, &c) in bins.count[a].iter().enumerate() {
            if c > 0 {
                occ[m] = i;
                m += 1;
            }
        }
        if m < 2 {
            continue;
        }
        let mut right_box = [Bx::EMPTY; BINS];
        let mut right_count = [0u32; BINS];
        let (mut rb, mut rc) = (Bx::EMPTY, 0u32);
        for j in (1..m).rev() {
            let i = occ[j];
            rb = rb.union(&Bx { min: bins.lo[a][i], max: bins.hi[a][i] });
            rc += bins.count[a][i];
            right_box[j] = rb;
            right_count[j] = rc;
        }
        let (mut lb, mut lc) = (Bx::EMPTY, 0u32);
        for j in 0..m - 1 {
            let i = occ[j];
            lb = lb.union(&Bx { min: bins.lo[a][i], max: bins.hi[a][i] });
            lc += bins.count[a][i];
            let cost = lb.area() * lc as f32 + right_box[j + 1].area() * right_count[j + 1] as f32;
            if cost < best.0 {
                *best = (cost, a, i, lb, right_box[j + 1]);
            }
        }
    }
}

/// The same binned SAH for nodes of at most `SMALL` triangles, without bins: per axis the
/// triangles sorted by (bin, position), and a side ends wherever the bin changes — the same
/// candidates in the same order, with the same boxes (unions are exact) and counts, so the
/// same costs and the same choice. One instance per node size: every loop has a fixed length
/// (unrolled, no mispredicted loop exits) and the choice is kept without branches.
fn sweep_small<const N: usize>(refs: &[Ref], origin2: Vec3A, scale2: Vec3A, ext: Vec3A, best: &mut Best) {
    let refs: &[Ref; N] = refs.try_into().expect("node of N triangles");
    let pos: [[f32; 3]; N] = std::array::from_fn(|j| bin_pos(&refs[j], origin2, scale2));
    // The cheapest candidate as one integer to minimise without branches: costs are finite and
    // non-negative, so their bits order as they do; then axis, then position (the first of
    // equal costs wins, as in the bins' sweep).
    let mut key = u64::MAX;
    let mut sorted = [[0u8; N]; 3];
    for a in 0..3 {
        if ext[a] <= 0.0 {
            continue;
        }
        // Counting sort by bin (stable): `order` lists the triangles' indices by bin.
        let bin: [u8; N] = std::array::from_fn(|j| bin_of(pos[j][a]) as u8);
        let mut start = [0u8; BINS];
        for &b in &bin {
            start[b as usize] += 1;
        }
        let mut acc = 0u8;
        for s in start.iter_mut() {
            let c = *s;
            *s = acc;
            acc += c;
        }
        let order = &mut sorted[a];
        for (j, &b) in bin.iter().enumerate() {
            order[index::<N>(start[b as usize])] = j as u8;
            start[b as usize] += 1;
        }
        let at = |k: usize| index::<N>(order[k]);
        let mut right_area = [0f32; N];
        let mut rb = Bx::EMPTY;
        for k in (1..N).rev() {
            rb = rb.union(&refs[at(k)]);
            right_area[k] = rb.area();
        }
        let mut lb = Bx::EMPTY;
        for k in 0..N - 1 {
            lb = lb.union(&refs[at(k)]);
            let c = lb.area() * (k + 1) as f32 + right_area[k + 1] * (N - k - 1) as f32;
            let here = (c.to_bits() as u64) << 32 | (a as u64) << 8 | k as u64;
            key = key.min(if bin[at(k)] != bin[at(k + 1)] { here } else { u64::MAX });
        }
    }
    let cost = f32::from_bits((key >> 32) as u32);
    if cost < best.0 {
        let (axis, last) = ((key >> 8 & 3) as usize, (key & 0xff) as usize);
        let order = &sorted[axis];
        let (mut lb, mut rb) = (Bx::EMPTY, Bx::EMPTY);
        for (k, &j) in order.iter().enumerate() {
            if k <= last {
                lb = lb.union(&refs[index::<N>(j)]);
            } else {
                rb = rb.union(&refs[index::<N>(j)]);
            }
        }
        *best = (cost, axis, bin_of(pos[index::<N>(order[last])][axis]), lb, rb);
    }
}

/// A position in a node of N triangles, kept below N so indexing needs no bounds check.
#[inline(always)]
fn index<const N: usize>(j: u8) -> usize {
    (j as usize).min(N - 1)
}

/// `sweep_small` for a node of 3 to `SMALL` triangles.
fn sweep_small_any(refs: &[Ref], origin2: Vec3A, scale2: Vec3A, ext: Vec3A, best: &mut Best) {
    macro_rules! by_size {
        ($($n:literal)*) => {
            match refs.len() {
                $($n => sweep_small::<$n>(refs, origin2, scale2, ext, best),)*
                n => unreachable!("sweep_small_any called for a node of {n} triangles"),
            }
        };
    }
    by_size!(3 4 5 6 7 8 9 10 11 12 13 14 15 16)
}

/// Splits `refs`/`prims` in place into the triangles `left` accepts and the rest; returns the
/// split position and the left and right boxes (gathered only if `BOXES`) and centroid
/// bounds.
fn partition<const BOXES: bool>(
    refs: &mut [Ref],
    prims: &mut [u32],
    left: impl Fn(&Ref) -> bool,
) -> (usize, Bx, Bx, Bx, Bx) {
    let (mut lb, mut lcb, mut rb, mut rcb) = (Bx::EMPTY, Bx::EMPTY, Bx::EMPTY, Bx::EMPTY);
    let (mut lo, mut hi) = (0usize, refs.len());
    while lo < hi {
        let r = refs[lo];
        if left(&r) {
            lcb.grow(r.min + r.max);
            if BOXES {
                lb = lb.union(&r);
            }
            lo += 1;
        } else {
            hi -= 1;
            rcb.grow(r.min + r.max);
            if BOXES {
                rb = rb.union(&r);
            }
            refs.swap(lo, hi);
            prims.swap(lo, hi);
        }
    }
    (lo, lb, half(lcb), rb, half(rcb))
}

/// Chooses a SAH split and partitions `refs` and `prims` (centroid bounds of both sides are
/// gathered during the partition; box bounds come from the bins, or from the partition where
/// the bins held a sample); returns `None` for a leaf.
fn split(refs: &mut [Ref], prims: &mut [u32], bounds: &Bx, cb: &Bx) -> Option<Split> {
    let n = refs.len();
    if n <= 1 {
        return None;
    }
    let ext = cb.max - cb.min;
    let mut best: Best = (f32::INFINITY, 0usize, 0usize, Bx::EMPTY, Bx::EMPTY);
    let sampled = n >= SAMPLE_FROM;
    if ext.max_element() > 0.0 {
        // Bins over twice the centroid: (min + max − 2·cb.min) · (BINS − 1) / (2·ext), rounded
        // to the nearest bin (the end bins are half as wide as the others).
        let scale2 = Vec3A::select(ext.cmpgt(Vec3A::ZERO), Vec3A::splat((BINS - 1) as f32 * 0.5) / ext, Vec3A::ZERO);
        let origin2 = cb.min * 2.0;
        if n == 2 {
            // Two triangles (a third of all nodes): on every axis where their centroids differ
            // they fall in bin 0 and bin BINS − 1, so the sweep's only candidate is one triangle
            // a side, at the same cost on each such axis, and the first such axis wins.
            let a = (0..3).find(|&a| ext[a] > 0.0).expect("some axis has extent");
            let (l, r) = if (refs[0].min + refs[0].max)[a] < (refs[1].min + refs[1].max)[a] { (0, 1) } else { (1, 0) };
            best = (refs[l].area() + refs[r].area(), a, 0, refs[l], refs[r]);
        } else if n <= SMALL {
            sweep_small_any(refs, origin2, scale2, ext, &mut best);
        } else if sampled {
            sweep_bins(&bin_chunk(refs.iter().step_by(n / SAMPLES), origin2, scale2), ext, &mut best);
        } else {
            sweep_bins(&bin_chunk(refs.iter(), origin2, scale2), ext, &mut best);
        }
        if best.0.is_finite() {
            let split_cost = C_TRAV + if bounds.area() > 0.0 { best.0 / bounds.area() } else { n as f32 };
            if n <= MAX_LEAF && n as f32 <= split_cost {
                return None;
            }
            let (_, a, i, lb, rb) = best;
            let (o, sc) = (origin2[a], scale2[a]);
            let left = |r: &Ref| bin_of(((r.min + r.max)[a] - o) * sc + MAGIC) <= i;
            let (lo, lb, lcb, rb, rcb) = if sampled {
                partition::<true>(refs, prims, left)
            } else {
                let (lo, _, lcb, _, rcb) = partition::<false>(refs, prims, left);
                (lo, lb, lcb, rb, rcb)
            };
            if lo > 0 && lo < n {
                return Some(Split { mid: lo, lb, lcb, rb, rcb });
            }
        }
    }
    if n <= MAX_LEAF {
        return None;
    }
    // All centroids coincide (or binning failed): split in the middle of the range.
    let mid = n / 2;
    let (lb, lcb) = range_bounds(&refs[..mid]);
    let (rb, rcb) = range_bounds(&refs[mid..]);
    Some(Split { mid, lb, lcb, rb, rcb })
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::Vec3;

    fn grid_scene(n: usize) -> Scene {
        let mut tris = Vec::new();
        for i in 0..n {
            let p = Vec3::new((i % 37) as f32, ((i / 37) % 29) as f32, (i / (37 * 29)) as f32);
            tris.push([p, p + Vec3::X * 0.5, p + Vec3::Y * 0.5]);
        }
        Scene::from_triangles("grid", tris).unwrap()
    }

    /// svenstaro/bvh-style consistency: every prim exactly once, children inside parents,
    /// leaves bound their triangles, leaf sizes within limits.
    pub(crate) fn assert_consistent(scene: &Scene, bvh: &BinaryBvh) {
        let mut seen = vec![false; scene.len()];
        let mut stack = vec![0usize];
        while let Some(i) = stack.pop() {
            let n = bvh.nodes[i];
            if n.is_leaf() {
                assert!(n.count as usize <= MAX_LEAF, "leaf of {} prims", n.count);
                for &p in &bvh.prims[n.first as usize..(n.first + n.count) as usize] {
                    assert!(!seen[p as usize]);
                    seen[p as usize] = true;
                    let t = &scene.tris[p as usize];
                    let v = [t[0].x, t[0].y, t[0].z, t[1].x, t[1].y, t[1].z, t[2].x, t[2].y, t[2].z];
                    let (lo, hi) = crate::base::padded_box(&v, scene.hit_pad());
                    assert!(n.bounds.contains(&Aabb { min: lo.into(), max: hi.into() }));
                }
            } else {
                for c in [n.first as usize, n.first as usize + 1] {
                    assert!(n.bounds.contains(&bvh.nodes[c].bounds));
                    stack.push(c);
                }
            }
        }
        assert!(seen.iter().all(|&s| s));
    }

    #[test]
    fn consistent_small_and_parallel() {
        for n in [1, 2, 7, 9, 100, 5000, 20000] {
            let s = grid_scene(n);
            let b = build_binary(&s);
            assert_consistent(&s, &b);
        }
    }

    /// The sort-based sweep of small nodes chooses what the bins' sweep chooses: same cost,
    /// axis, bin and both boxes, on random nodes of every small size (with repeated centroids).
    #[test]
    fn small_sweep_matches_the_bins() {
        let mut seed = 0x2545_f491_4f6c_dd1du64;
        let mut rnd = move || {
            seed ^= seed << 13;
            seed ^= seed >> 7;
            seed ^= seed << 17;
            (seed >> 40) as f32 / (1u64 << 24) as f32
        };
        for trial in 0..3000 {
            let n = 3 + trial % (SMALL - 2);
            let refs: Vec<Ref> = (0..n)
                .map(|_| {
                    // Coarse positions so some centroids coincide or share a bin.
                    let c = Vec3A::new((rnd() * 8.0).floor(), (rnd() * 8.0).floor(), rnd());
                    let h = Vec3A::new(rnd(), rnd(), rnd()) * 0.5;
                    Bx { min: c - h, max: c + h }
                })
                .collect();
            let (_, cb) = range_bounds(&refs);
            let ext = cb.max - cb.min;
            let scale2 =
                Vec3A::select(ext.cmpgt(Vec3A::ZERO), Vec3A::splat((BINS - 1) as f32 * 0.5) / ext, Vec3A::ZERO);
            let origin2 = cb.min * 2.0;
            let empty: Best = (f32::INFINITY, 0, 0, Bx::EMPTY, Bx::EMPTY);
            let (mut small, mut binned) = (empty, empty);
            sweep_small_any(&refs, origin2, scale2, ext, &mut small);
            sweep_bins(&bin_chunk(refs.iter(), origin2, scale2), ext, &mut binned);
            let key = |b: &Best| {
                (
                    b.0.to_bits(),
                    b.1,
                    b.2,
                    (b.3.min + 0.0).to_array(),
                    (b.3.max + 0.0).to_array(),
                    (b.4.min + 0.0).to_array(),
                    (b.4.max + 0.0).to_array(),
                )
            };
            assert_eq!(key(&small), key(&binned), "trial {trial}, {n} triangles");
        }
    }

    /// Above `SAMPLE_FROM` triangles the split comes from a sample: still every triangle once,
    /// every box tight around its children.
    #[test]
    fn sampled_top_levels_are_consistent() {
        let s = grid_scene(SAMPLE_FROM + 4321);
        let b = build_binary(&s);
        assert_consistent(&s, &b);
        let mut stack = vec![0usize];
        while let Some(i) = stack.pop() {
            let n = b.nodes[i];
            if !n.is_leaf() {
                let (l, r) = (b.nodes[n.first as usize].bounds, b.nodes[n.first as usize + 1].bounds);
                assert_eq!(n.bounds, Aabb { min: l.min.min(r.min), max: l.max.max(r.max) }, "node {i} is not tight");
                stack.extend([n.first as usize, n.first as usize + 1]);
            }
        }
    }

    #[test]
    fn coincident_centroids_still_split() {
        let t = [Vec3::ZERO, Vec3::X, Vec3::Y];
        let s = Scene::from_triangles("same", vec![t; 100]).unwrap();
        let b = build_binary(&s);
        assert_consistent(&s, &b);
    }
}
