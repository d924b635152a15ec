//! Collapse of the binary BVH into B-wide nodes ("MBVH"): each wide node gathers up to B
//! children by repeatedly opening the inner child with the largest surface area (the usual
//! greedy collapse, as in Wald et al. 2008 and tinybvh's `BVH4`/`BVH8` conversions).

use super::build::BinaryBvh;
use super::bx::MAX_LEAF;
use crate::base::Aabb;

/// A child slot of a wide node.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ChildRef {
    /// Index of a wide inner node.
    Inner(u32),
    /// `count` triangles at `prims[first .. first + count]` (1..=MAX_LEAF).
    Leaf { first: u32, count: u32 },
}

/// A wide node: its own box and up to B children, each with its world-space box.
#[derive(Clone, Debug)]
pub struct WideNode {
    pub bounds: Aabb,
    pub children: Vec<(Aabb, ChildRef)>,
}

/// A B-wide BVH over the same triangle order as the binary BVH it came from.
/// `nodes[0]` is the root; nodes lie breadth first — each node's inner children side by side in
/// slot order, level by level — so children always have larger indices than their parent
/// (`breadth_first` says why).
#[derive(Clone, Debug)]
pub struct WideBvh {
    pub branching: usize,
    pub nodes: Vec<WideNode>,
    /// Triangle ids in leaf order (shared with the binary BVH).
    pub prims: Vec<u32>,
}

/// Collapses a binary BVH to branching factor `b` (2, 4, 8 or 16), its nodes breadth first.
pub fn collapse(bin: &BinaryBvh, b: usize) -> WideBvh {
    assert!((2..=16).contains(&b), "branching {b} must be checked by the caller");
    let mut out = WideBvh { branching: b, nodes: Vec::new(), prims: bin.prims.clone() };
    let root = bin.nodes[0];
    if root.is_leaf() {
        out.nodes.push(WideNode {
            bounds: root.bounds,
            children: vec![(root.bounds, ChildRef::Leaf { first: root.first, count: root.count })],
        });
        return out;
    }
    collapse_rec(bin, 0, b, &mut out.nodes);
    out.nodes = breadth_first(std::mem::take(&mut out.nodes));
    out
}

/// The nodes (root at 0) re-indexed breadth first: each node's inner children side by side, in
/// slot order. Every layout stores its nodes so — q8 must (one base index for a node's inner
/// children) — and so the layouts differ only in their records: `memory --node-order` measured
/// siblings side by side against subtrees contiguous (depth first, the collapse's own order)
/// on f32's nodes at 2–3 % fewer DRAM bytes per ray on a 1.1 M-triangle scene and no loss
/// elsewhere (docs/reports/issue-52-memory.md, "Where the nodes lie").
pub fn breadth_first(nodes: Vec<WideNode>) -> Vec<WideNode> {
    let mut order = vec![0usize];
    let mut new_index = vec![u32::MAX; nodes.len()];
    new_index[0] = 0;
    let mut i = 0;
    while i < order.len() {
        for (_, c) in &nodes[order[i]].children {
            if let ChildRef::Inner(j) = *c {
                new_index[j as usize] = order.len() as u32;
                order.push(j as usize);
            }
        }
        i += 1;
    }
    debug_assert_eq!(order.len(), nodes.len(), "every node is reached once from the root");
    let mut slots: Vec<Option<WideNode>> = nodes.into_iter().map(Some).collect();
    order
        .iter()
        .map(|&old| {
            let mut n = slots[old].take().expect("each node once");
            for (_, c) in &mut n.children {
                if let ChildRef::Inner(j) = c {
                    *j = new_index[*j as usize];
                }
            }
            n
        })
        .collect()
}

fn collapse_rec(bin: &BinaryBvh, bi: usize, b: usize, nodes: &mut Vec<WideNode>) -> u32 {
    let n = bin.nodes[bi];
    // Gather up to b binary subtrees.
    let mut open: Vec<usize> = vec![n.first as usize, n.first as usize + 1];
    while open.len() < b {
        let best = open
            .iter()
            .enumerate()
            .filter(|(_, &c)| !bin.nodes[c].is_leaf())
            .max_by(|x, y| bin.nodes[*x.1].bounds.area().total_cmp(&bin.nodes[*y.1].bounds.area()));
        let Some((k, &c)) = best else { break };
        let f = bin.nodes[c].first as usize;
        open[k] = f;
        open.insert(k + 1, f + 1);
    }
    let me = nodes.len();
    nodes.push(WideNode { bounds: n.bounds, children: Vec::with_capacity(open.len()) });
    for c in open {
        let cn = bin.nodes[c];
        let r = if cn.is_leaf() {
            debug_assert!(cn.count as usize <= MAX_LEAF);
            ChildRef::Leaf { first: cn.first, count: cn.count }
        } else {
            ChildRef::Inner(collapse_rec(bin, c, b, nodes))
        };
        nodes[me].children.push((cn.bounds, r));
    }
    me as u32
}

impl WideBvh {
    /// Depth in inner nodes (the root alone has depth 1).
    pub fn depth(&self) -> usize {
        fn rec(t: &WideBvh, i: usize) -> usize {
            1 + t.nodes[i]
                .children
                .iter()
                .filter_map(|c| if let ChildRef::Inner(j) = c.1 { Some(rec(t, j as usize)) } else { None })
                .max()
                .unwrap_or(0)
        }
        rec(self, 0)
    }

    pub fn leaf_count(&self) -> usize {
        self.nodes.iter().flat_map(|n| &n.children).filter(|c| matches!(c.1, ChildRef::Leaf { .. })).count()
    }

    /// Largest number of stack entries a depth-first traversal can hold: (B-1) per level + 1.
    pub fn max_stack(&self) -> usize {
        (self.branching - 1) * self.depth() + 1
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::bvh::build_binary;
    use crate::scene::Scene;
    use glam::Vec3;

    #[test]
    fn collapse_keeps_every_prim_and_containment() {
        let mut tris = Vec::new();
        for i in 0..3000 {
            let p = Vec3::new((i % 17) as f32, ((i / 17) % 13) as f32 * 1.5, (i / 221) as f32 * 0.7);
            tris.push([p, p + Vec3::X * 0.4, p + Vec3::Z * 0.3]);
        }
        let s = Scene::from_triangles("t", tris).unwrap();
        let bin = build_binary(&s);
        for b in [2, 4, 8, 16] {
            let w = collapse(&bin, b);
            // Breadth first: the inner children, node after node, are 1, 2, 3, …
            let kids: Vec<u32> = w
                .nodes
                .iter()
                .flat_map(|n| {
                    n.children.iter().filter_map(|c| if let ChildRef::Inner(j) = c.1 { Some(j) } else { None })
                })
                .collect();
            assert_eq!(kids, (1..w.nodes.len() as u32).collect::<Vec<_>>(), "B={b}: nodes breadth first");
            let mut seen = vec![0u32; s.len()];
            for n in &w.nodes {
                assert!(n.children.len() <= b && !n.children.is_empty());
                for (bb, c) in &n.children {
                    assert!(n.bounds.contains(bb));
                    match *c {
                        ChildRef::Inner(j) => {
                            assert_eq!(w.nodes[j as usize].bounds, *bb);
                            assert!(j as usize > 0);
                        }
                        ChildRef::Leaf { first, count } => {
                            for &p in &w.prims[first as usize..(first + count) as usize] {
                                seen[p as usize] += 1;
                                assert!(bb.contains(&Aabb::from_points(&s.tris[p as usize])));
                            }
                        }
                    }
                }
            }
            assert!(seen.iter().all(|&c| c == 1), "B={b}");
        }
    }
}
