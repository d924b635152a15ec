//! Per-BVH statistics: node and leaf counts, depth, SAH cost, bytes per layout.

use super::wide::{ChildRef, WideBvh};

/// SAH cost constants: one unit per inner node visit, one per triangle test.
pub const SAH_NODE: f64 = 1.0;
pub const SAH_TRI: f64 = 1.0;

#[derive(Clone, Debug, PartialEq)]
pub struct BvhStats {
    pub branching: usize,
    pub inner_nodes: usize,
    pub leaves: usize,
    pub depth: usize,
    /// Expected cost of a random ray (surface-area heuristic), relative to the root.
    pub sah_cost: f64,
    /// Mean number of occupied child slots per inner node.
    pub fill: f64,
}

pub fn stats(w: &WideBvh) -> BvhStats {
    let root_area = w.nodes[0].bounds.area() as f64;
    let mut cost = 0.0;
    let mut slots = 0usize;
    for n in &w.nodes {
        cost += SAH_NODE * n.bounds.area() as f64;
        slots += n.children.len();
        for (b, c) in &n.children {
            if let ChildRef::Leaf { count, .. } = c {
                cost += SAH_TRI * b.area() as f64 * *count as f64;
            }
        }
    }
    BvhStats {
        branching: w.branching,
        inner_nodes: w.nodes.len(),
        leaves: w.leaf_count(),
        depth: w.depth(),
        sah_cost: if root_area > 0.0 { cost / root_area } else { cost },
        fill: slots as f64 / w.nodes.len() as f64,
    }
}
