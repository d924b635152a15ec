//! Layout `f32`: world-space fp32 child boxes, structure of arrays per node.
//!
//! Node byte layout for branching B (28·B bytes): `lo` f32[3][B] at 0, `hi` f32[3][B] at
//! 12·B, `child` u32[B] at 24·B. Empty slots have zero boxes and `CHILD_EMPTY`.
//! B=2: 56 bytes, B=4: 112, B=8: 224, B=16: 448.

use super::{encode_child, node_types, TriBuffer};
use crate::bvh::WideBvh;
use crate::scene::Scene;

/// Accessors shared by the f32 node structs.
pub trait NodeF32: bytemuck::Pod {
    const B: usize;
    fn lo(&self, axis: usize, slot: usize) -> f32;
    fn hi(&self, axis: usize, slot: usize) -> f32;
    fn child(&self, slot: usize) -> u32;
    fn empty() -> Self;
    fn set(&mut self, slot: usize, lo: [f32; 3], hi: [f32; 3], child: u32);
}

node_types!(F32Nodes, NodeF32, f32, [(F32Node2, 2, B2), (F32Node4, 4, B4), (F32Node8, 8, B8), (F32Node16, 16, B16)]);

/// An encoded `f32` BVH: nodes (root at 0), the root's world box and the triangles.
#[derive(Clone, Debug)]
pub struct F32Bvh {
    pub branching: usize,
    pub nodes: F32Nodes,
    pub root_lo: [f32; 3],
    pub root_hi: [f32; 3],
    pub tris: TriBuffer,
    /// Largest traversal stack: (B−1)·depth + 1.
    pub max_stack: usize,
}

fn encode_nodes<N: NodeF32>(w: &WideBvh) -> Vec<N> {
    w.nodes
        .iter()
        .map(|n| {
            let mut out = N::empty();
            for (slot, (b, c)) in n.children.iter().enumerate() {
                out.set(slot, b.min.into(), b.max.into(), encode_child(c));
            }
            out
        })
        .collect()
}

pub fn encode(scene: &Scene, w: &WideBvh) -> F32Bvh {
    let nodes = match w.branching {
        2 => F32Nodes::B2(encode_nodes(w)),
        4 => F32Nodes::B4(encode_nodes(w)),
        8 => F32Nodes::B8(encode_nodes(w)),
        16 => F32Nodes::B16(encode_nodes(w)),
        b => panic!("unsupported branching {b}"),
    };
    let rb = w.nodes[0].bounds;
    F32Bvh { branching: w.branching, nodes, root_lo: rb.min.into(), root_hi: rb.max.into(), tris: TriBuffer::new(scene, w), max_stack: w.max_stack() }
}
