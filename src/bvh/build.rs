//! Binned SAH construction of a binary BVH in fp32 (Wald 2007, "On fast construction of
//! SAH-based bounding volume hierarchies"), parallel over subtrees and over the binning of
//! large nodes with rayon.

use crate::geom::Aabb;
use crate::scene::Scene;
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

/// Number of SAH bins per axis.
pub const BINS: usize = 16;
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

/// A triangle's box, partitioned in place with its id (`ids`) so every pass over a node's
/// triangles reads memory in order.
type Ref = Bx;

#[derive(Clone, Copy)]
struct Bin {
    bounds: Bx,
    count: u32,
}

const EMPTY_BIN: Bin = Bin { bounds: Bx::EMPTY, count: 0 };

/// Subtrees below this many triangles are built sequentially.
const PAR_SUBTREE: usize = 4096;
/// Nodes above this many triangles are binned, and their bounds gathered, in parallel.
const PAR_BINNING: usize = 1 << 17;
/// Chunk of triangles one parallel binning task takes.
const PAR_CHUNK: usize = 1 << 15;

/// Builds the binary BVH of a scene (a progress line when it takes over a second).
pub fn build_binary(scene: &Scene) -> BinaryBvh {
    crate::progress::step(&format!("building the BVH of {} ({} triangles)", scene.name, scene.tris.len()), || build_binary_quiet(scene))
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
    let mut prims: Vec<u32> = (0..n as u32).collect();
    let (b, cb) = range_bounds(&refs);
    // A subtree over k triangles has at most 2k − 1 nodes: its root, then a region of 2k − 2
    // slots for the rest, which its two children split — both children first (they are
    // adjacent, as `BinaryNode` requires), then each one's own region. Subtrees write disjoint
    // slices, so the parallel build needs no locks and no copies; leaves leave slots unused,
    // which a final pass in depth-first order squeezes out.
    // Zeroed slots come from the OS as zero pages: no pass writes them before the build.
    let mut slots: Vec<BinaryNode> = bytemuck::zeroed_vec((2 * n).saturating_sub(1).max(1));
    let (root, rest) = slots.split_first_mut().expect("at least one slot");
    build_rec(&mut refs, &mut prims, 0, root, rest, 1, b, cb);
    drop(refs);
    BinaryBvh { nodes: compact(&slots), prims }
}

/// The nodes reachable from slot 0, renumbered in depth-first order (children stay adjacent).
fn compact(slots: &[BinaryNode]) -> Vec<BinaryNode> {
    // Reserved in full (untouched capacity costs no memory): no reallocation while filling.
    let mut out = Vec::with_capacity(slots.len());
    out.push(slots[0]);
    // (old index of an inner node's first child, new index of the node)
    let mut stack = Vec::new();
    if !slots[0].is_leaf() {
        stack.push((slots[0].first as usize, 0usize));
    }
    while let Some((old, me)) = stack.pop() {
        let at = out.len();
        out[me].first = at as u32;
        out.push(slots[old]);
        out.push(slots[old + 1]);
        for k in (0..2).rev() {
            if !slots[old + k].is_leaf() {
                stack.push((slots[old + k].first as usize, at + k));
            }
        }
    }
    out
}

fn range_bounds(refs: &[Ref]) -> (Bx, Bx) {
    let f = |(b, mut c): (Bx, Bx), r: &Ref| {
        c.grow(r.min + r.max);
        (b.union(r), c)
    };
    let (b, c2) = if refs.len() >= PAR_BINNING {
        refs.par_chunks(PAR_CHUNK).map(|ch| ch.iter().fold((Bx::EMPTY, Bx::EMPTY), f)).reduce(|| (Bx::EMPTY, Bx::EMPTY), |a, b| (a.0.union(&b.0), a.1.union(&b.1)))
    } else {
        refs.iter().fold((Bx::EMPTY, Bx::EMPTY), f)
    };
    (b, half(c2))
}

/// Centroid bounds are gathered as min + max (twice the centroid); halved once per node.
fn half(c2: Bx) -> Bx {
    Bx { min: c2.min * 0.5, max: c2.max * 0.5 }
}

fn bin_chunk(refs: &[Ref], origin2: Vec3A, scale2: Vec3A) -> [[Bin; BINS]; 3] {
    let mut bins = [[EMPTY_BIN; BINS]; 3];
    let top = glam::UVec3::splat(BINS as u32 - 1);
    for r in refs {
        let idx = ((r.min + r.max - origin2) * scale2).as_uvec3().min(top);
        for (a, axis) in bins.iter_mut().enumerate() {
            let bin = &mut axis[idx[a] as usize];
            bin.count += 1;
            bin.bounds = bin.bounds.union(r);
        }
    }
    bins
}

fn bin_refs(refs: &[Ref], origin2: Vec3A, scale2: Vec3A) -> [[Bin; BINS]; 3] {
    if refs.len() < PAR_BINNING {
        return bin_chunk(refs, origin2, scale2);
    }
    let merge = |mut x: [[Bin; BINS]; 3], y: [[Bin; BINS]; 3]| {
        for a in 0..3 {
            for i in 0..BINS {
                x[a][i].count += y[a][i].count;
                x[a][i].bounds = x[a][i].bounds.union(&y[a][i].bounds);
            }
        }
        x
    };
    refs.par_chunks(PAR_CHUNK).map(|ch| bin_chunk(ch, origin2, scale2)).reduce(|| [[EMPTY_BIN; BINS]; 3], merge)
}

/// Builds the subtree over `refs`/`prims` (partitioned in place, at `base` in the global
/// triangle order): its root goes to `root`, the rest of its nodes into `region`, whose first
/// slot has the global index `at`.
#[allow(clippy::too_many_arguments)]
fn build_rec(refs: &mut [Ref], prims: &mut [u32], base: u32, root: &mut BinaryNode, region: &mut [BinaryNode], at: u32, bounds: Bx, cb: Bx) {
    let n = refs.len();
    let Some(sp) = split(refs, prims, &bounds, &cb) else {
        *root = BinaryNode { bounds: bounds.aabb(), first: base, count: n as u32 };
        return;
    };
    *root = BinaryNode { bounds: bounds.aabb(), first: at, count: 0 };
    let m = sp.mid;
    let (kids, rest) = region.split_at_mut(2);
    let (lk, rk) = kids.split_at_mut(1);
    let (lregion, rregion) = rest.split_at_mut(2 * m - 2);
    let (lrefs, rrefs) = refs.split_at_mut(m);
    let (lprims, rprims) = prims.split_at_mut(m);
    let (lat, rat) = (at + 2, at + 2 * m as u32);
    if n < PAR_SUBTREE {
        build_rec(lrefs, lprims, base, &mut lk[0], lregion, lat, sp.lb, sp.lcb);
        build_rec(rrefs, rprims, base + m as u32, &mut rk[0], rregion, rat, sp.rb, sp.rcb);
    } else {
        rayon::join(
            || build_rec(lrefs, lprims, base, &mut lk[0], lregion, lat, sp.lb, sp.lcb),
            || build_rec(rrefs, rprims, base + m as u32, &mut rk[0], rregion, rat, sp.rb, sp.rcb),
        );
    }
}

/// A chosen split: position in the range and both children's bounds and centroid bounds.
struct Split {
    mid: usize,
    lb: Bx,
    lcb: Bx,
    rb: Bx,
    rcb: Bx,
}

/// Chooses a SAH split and partitions `refs` and `prims` (centroid bounds of both sides are
/// gathered during the partition, box bounds come from the bins); returns `None` for a leaf.
fn split(refs: &mut [Ref], prims: &mut [u32], bounds: &Bx, cb: &Bx) -> Option<Split> {
    let n = refs.len();
    if n <= 1 {
        return None;
    }
    let ext = cb.max - cb.min;
    // (cost, axis, bin, left box, right box)
    let mut best = (f32::INFINITY, 0usize, 0usize, Bx::EMPTY, Bx::EMPTY);
    if ext.max_element() > 0.0 {
        // Bins over twice the centroid: (min + max − 2·cb.min) · BINS / (2·ext).
        let scale2 = Vec3A::select(ext.cmpgt(Vec3A::ZERO), Vec3A::splat(BINS as f32 * (1.0 - 1e-6) * 0.5) / ext, Vec3A::ZERO);
        let origin2 = cb.min * 2.0;
        if n == 2 {
            // Two triangles (a third of all nodes): on every axis where their centroids differ
            // they fall in bin 0 and bin BINS − 1, so the sweep's only candidate is one triangle
            // a side, at the same cost on each such axis, and the first such axis wins.
            let a = (0..3).find(|&a| ext[a] > 0.0).expect("some axis has extent");
            let (l, r) = if (refs[0].min + refs[0].max)[a] < (refs[1].min + refs[1].max)[a] { (0, 1) } else { (1, 0) };
            let cost = refs[l].area() + refs[r].area();
            if cost < best.0 {
                best = (cost, a, 0, refs[l], refs[r]);
            }
        } else {
            let bins = bin_refs(refs, origin2, scale2);
            for (a, axis) in bins.iter().enumerate() {
                if ext[a] <= 0.0 {
                    continue;
                }
                // Only occupied bins can end a side: an empty bin repeats its neighbour's partition
                // and cost, so sweeping the occupied ones gives the same split (small nodes, the
                // most numerous, occupy few of the bins).
                let mut occ = [0usize; BINS];
                let mut m = 0;
                for (i, bin) in axis.iter().enumerate() {
                    if bin.count > 0 {
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
                    rb = rb.union(&axis[occ[j]].bounds);
                    rc += axis[occ[j]].count;
                    right_box[j] = rb;
                    right_count[j] = rc;
                }
                let (mut lb, mut lc) = (Bx::EMPTY, 0u32);
                for j in 0..m - 1 {
                    lb = lb.union(&axis[occ[j]].bounds);
                    lc += axis[occ[j]].count;
                    let cost = lb.area() * lc as f32 + right_box[j + 1].area() * right_count[j + 1] as f32;
                    if cost < best.0 {
                        best = (cost, a, occ[j], lb, right_box[j + 1]);
                    }
                }
            }
        }
        if best.0.is_finite() {
            let split_cost = C_TRAV + if bounds.area() > 0.0 { best.0 / bounds.area() } else { n as f32 };
            if n <= MAX_LEAF && n as f32 <= split_cost {
                return None;
            }
            let (_, a, i, lb, rb) = best;
            // The binning's test, so both sides match the bins' counts: bin ≤ i, i.e.
            // trunc(x) ≤ i for x ≥ 0, is x < i + 1 (i < BINS − 1, so the clamp never applies).
            let (o, sc, lim) = (origin2[a], scale2[a], (i + 1) as f32);
            let left = |r: &Ref| ((r.min + r.max)[a] - o) * sc < lim;
            let (mut lcb, mut rcb) = (Bx::EMPTY, Bx::EMPTY);
            let (mut lo, mut hi) = (0usize, n);
            while lo < hi {
                if left(&refs[lo]) {
                    lcb.grow(refs[lo].min + refs[lo].max);
                    lo += 1;
                } else {
                    hi -= 1;
                    rcb.grow(refs[lo].min + refs[lo].max);
                    refs.swap(lo, hi);
                    prims.swap(lo, hi);
                }
            }
            if lo > 0 && lo < n {
                return Some(Split { mid: lo, lb, lcb: half(lcb), rb, rcb: half(rcb) });
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
                    assert!(n.bounds.contains(&Aabb::from_points(&scene.tris[p as usize])));
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

    #[test]
    fn coincident_centroids_still_split() {
        let t = [Vec3::ZERO, Vec3::X, Vec3::Y];
        let s = Scene::from_triangles("same", vec![t; 100]).unwrap();
        let b = build_binary(&s);
        assert_consistent(&s, &b);
    }
}
