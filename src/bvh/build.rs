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
#[derive(Clone, Copy, Debug)]
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

struct Ctx<'a> {
    bounds: &'a [Bx],
    centroids: &'a [Vec3A],
}

#[derive(Clone, Copy)]
struct Bin {
    bounds: Bx,
    count: u32,
}

const EMPTY_BIN: Bin = Bin { bounds: Bx::EMPTY, count: 0 };

/// Subtrees below this many triangles are built sequentially.
const PAR_SUBTREE: usize = 4096;
/// Nodes above this many triangles are binned in parallel.
const PAR_BINNING: usize = 65536;

/// Builds the binary BVH of a scene (a progress line when it takes over a second).
pub fn build_binary(scene: &Scene) -> BinaryBvh {
    crate::progress::step(&format!("building the BVH of {} ({} triangles)", scene.name, scene.tris.len()), || build_binary_quiet(scene))
}

fn build_binary_quiet(scene: &Scene) -> BinaryBvh {
    let n = scene.tris.len();
    let (bounds, centroids): (Vec<Bx>, Vec<Vec3A>) = scene
        .tris
        .par_iter()
        .map(|t| {
            let (a, b, c) = (Vec3A::from(t[0]), Vec3A::from(t[1]), Vec3A::from(t[2]));
            let bx = Bx { min: a.min(b).min(c), max: a.max(b).max(c) };
            (bx, (bx.min + bx.max) * 0.5)
        })
        .unzip();
    let ctx = Ctx { bounds: &bounds, centroids: &centroids };
    let mut prims: Vec<u32> = (0..n as u32).collect();
    let (b, cb) = range_bounds(&ctx, &prims);
    let nodes = build_rec(&ctx, &mut prims, 0, b, cb);
    BinaryBvh { nodes, prims }
}

fn range_bounds(ctx: &Ctx, prims: &[u32]) -> (Bx, Bx) {
    let f = |(mut b, mut c): (Bx, Bx), &p: &u32| {
        b = b.union(&ctx.bounds[p as usize]);
        c.grow(ctx.centroids[p as usize]);
        (b, c)
    };
    if prims.len() >= PAR_BINNING {
        prims
            .par_chunks(8192)
            .map(|ch| ch.iter().fold((Bx::EMPTY, Bx::EMPTY), f))
            .reduce(|| (Bx::EMPTY, Bx::EMPTY), |a, b| (a.0.union(&b.0), a.1.union(&b.1)))
    } else {
        prims.iter().fold((Bx::EMPTY, Bx::EMPTY), f)
    }
}

fn bin_chunk(ctx: &Ctx, prims: &[u32], cb: &Bx, scale: Vec3A) -> [[Bin; BINS]; 3] {
    let mut bins = [[EMPTY_BIN; BINS]; 3];
    let top = glam::UVec3::splat(BINS as u32 - 1);
    for &p in prims {
        let c = ctx.centroids[p as usize];
        let b = &ctx.bounds[p as usize];
        let idx = ((c - cb.min) * scale).as_uvec3().min(top);
        for a in 0..3 {
            let bin = &mut bins[a][idx[a] as usize];
            bin.count += 1;
            bin.bounds = bin.bounds.union(b);
        }
    }
    bins
}

fn bin_prims(ctx: &Ctx, prims: &[u32], cb: &Bx, scale: Vec3A) -> [[Bin; BINS]; 3] {
    if prims.len() < PAR_BINNING {
        return bin_chunk(ctx, prims, cb, scale);
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
    prims.par_chunks(8192).map(|ch| bin_chunk(ctx, ch, cb, scale)).reduce(|| [[EMPTY_BIN; BINS]; 3], merge)
}

/// Builds the subtree over `prims` (in place partition); returns its nodes with the root first
/// and child indices local to the returned vector. `base` is the offset of `prims` in the
/// global primitive array.
fn build_rec(ctx: &Ctx, prims: &mut [u32], base: u32, bounds: Bx, cb: Bx) -> Vec<BinaryNode> {
    let mut nodes = Vec::with_capacity(2 * prims.len() / 3 + 1);
    if prims.len() < PAR_SUBTREE {
        nodes.push(BinaryNode { bounds: Aabb::EMPTY, first: 0, count: 0 });
        build_seq_at(ctx, prims, base, &mut nodes, 0, bounds, cb);
        return nodes;
    }
    let Some(sp) = split(ctx, prims, &bounds, &cb) else {
        nodes.push(BinaryNode { bounds: bounds.aabb(), first: base, count: prims.len() as u32 });
        return nodes;
    };
    let mid = sp.mid;
    let (l, r) = prims.split_at_mut(mid);
    let (ln, rn) = rayon::join(|| build_rec(ctx, l, base, sp.lb, sp.lcb), || build_rec(ctx, r, base + mid as u32, sp.rb, sp.rcb));
    nodes.push(BinaryNode { bounds: bounds.aabb(), first: 1, count: 0 });
    nodes.push(ln[0]);
    nodes.push(rn[0]);
    // Children of the root are at 1 and 2; the rest of each subtree follows.
    let l_off = 3 - 1; // local index i>0 of the left subtree moves to i + 2
    let r_off = 3 + (ln.len() - 1) - 1; // local index i>0 of the right subtree moves to i + r_off
    let fix = |n: &BinaryNode, off: usize| {
        let mut n = *n;
        if !n.is_leaf() {
            n.first = (n.first as usize + off) as u32;
        }
        n
    };
    nodes[1] = fix(&ln[0], l_off);
    nodes[2] = fix(&rn[0], r_off);
    nodes.extend(ln[1..].iter().map(|n| fix(n, l_off)));
    nodes.extend(rn[1..].iter().map(|n| fix(n, r_off)));
    nodes
}

/// Builds the subtree over `prims` with its root written to `nodes[slot]`.
fn build_seq_at(ctx: &Ctx, prims: &mut [u32], base: u32, nodes: &mut Vec<BinaryNode>, slot: usize, bounds: Bx, cb: Bx) {
    let Some(sp) = split(ctx, prims, &bounds, &cb) else {
        nodes[slot] = BinaryNode { bounds: bounds.aabb(), first: base, count: prims.len() as u32 };
        return;
    };
    let first = nodes.len();
    nodes[slot] = BinaryNode { bounds: bounds.aabb(), first: first as u32, count: 0 };
    nodes.push(BinaryNode { bounds: Aabb::EMPTY, first: 0, count: 0 });
    nodes.push(BinaryNode { bounds: Aabb::EMPTY, first: 0, count: 0 });
    let (l, r) = prims.split_at_mut(sp.mid);
    build_seq_at(ctx, l, base, nodes, first, sp.lb, sp.lcb);
    build_seq_at(ctx, r, base + sp.mid as u32, nodes, first + 1, sp.rb, sp.rcb);
}

/// A chosen split: position in the range and both children's bounds and centroid bounds.
struct Split {
    mid: usize,
    lb: Bx,
    lcb: Bx,
    rb: Bx,
    rcb: Bx,
}

/// Chooses a SAH split and partitions `prims` (centroid bounds of both sides are gathered
/// during the partition, box bounds come from the bins); returns `None` for a leaf.
fn split(ctx: &Ctx, prims: &mut [u32], bounds: &Bx, cb: &Bx) -> Option<Split> {
    let n = prims.len();
    if n <= 1 {
        return None;
    }
    let ext = cb.max - cb.min;
    // (cost, axis, bin, left box, right box)
    let mut best = (f32::INFINITY, 0usize, 0usize, Bx::EMPTY, Bx::EMPTY);
    if ext.max_element() > 0.0 {
        let scale = Vec3A::select(ext.cmpgt(Vec3A::ZERO), Vec3A::splat(BINS as f32 * (1.0 - 1e-6)) / ext, Vec3A::ZERO);
        let bins = bin_prims(ctx, prims, cb, scale);
        for a in 0..3 {
            if ext[a] <= 0.0 {
                continue;
            }
            let mut right_box = [Bx::EMPTY; BINS];
            let mut right_count = [0u32; BINS];
            let (mut rb, mut rc) = (Bx::EMPTY, 0u32);
            for i in (1..BINS).rev() {
                rb = rb.union(&bins[a][i].bounds);
                rc += bins[a][i].count;
                right_box[i] = rb;
                right_count[i] = rc;
            }
            let (mut lb, mut lc) = (Bx::EMPTY, 0u32);
            for i in 0..BINS - 1 {
                lb = lb.union(&bins[a][i].bounds);
                lc += bins[a][i].count;
                let rc = right_count[i + 1];
                if lc == 0 || rc == 0 {
                    continue;
                }
                let cost = lb.area() * lc as f32 + right_box[i + 1].area() * rc as f32;
                if cost < best.0 {
                    best = (cost, a, i, lb, right_box[i + 1]);
                }
            }
        }
        if best.0.is_finite() {
            let split_cost = C_TRAV + if bounds.area() > 0.0 { best.0 / bounds.area() } else { n as f32 };
            if n <= MAX_LEAF && n as f32 <= split_cost {
                return None;
            }
            let (_, a, i, lb, rb) = best;
            let (mut lcb, mut rcb) = (Bx::EMPTY, Bx::EMPTY);
            let mut m = 0;
            for j in 0..n {
                let p = prims[j];
                let c = ctx.centroids[p as usize];
                if (((c[a] - cb.min[a]) * scale[a]) as usize).min(BINS - 1) <= i {
                    lcb.grow(c);
                    prims.swap(m, j);
                    m += 1;
                } else {
                    rcb.grow(c);
                }
            }
            if m > 0 && m < n {
                return Some(Split { mid: m, lb, lcb, rb, rcb });
            }
        }
    }
    if n <= MAX_LEAF {
        return None;
    }
    // All centroids coincide (or binning failed): split in the middle of the index range.
    let mid = n / 2;
    let (lb, lcb) = range_bounds(ctx, &prims[..mid]);
    let (rb, rcb) = range_bounds(ctx, &prims[mid..]);
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
