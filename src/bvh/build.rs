//! Binned SAH construction of a binary BVH in fp32 (Wald 2007, "On fast construction of
//! SAH-based bounding volume hierarchies"), parallel over subtrees with rayon. Nodes of at
//! least 65 536 triangles bin an even sample of them; nodes of at most 16 find the same split as
//! their bins would by sorting.

use super::bx::*;
use super::split::split;
use crate::base::Aabb;
use crate::scene::Scene;
use bytemuck::Zeroable;
use glam::Vec3A;
use rayon::prelude::*;

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

/// Subtrees below this many triangles are built sequentially, each into its own block of slots.
const PAR_SUBTREE: usize = 4096;

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

#[cfg(test)]
mod tests {
    use super::super::split::*;
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
