//! A BVH encoded in one layout at one branching factor, type-erased ([`Encoded`]): what the
//! CPU reference traverses and what the GPU backend uploads.

use super::{LayoutId, Node};
use crate::base::{Aabb, ClosestTrue, Counters, Hit, Ray};
use crate::bvh::{BinaryBvh, WideBvh};
use crate::precision::{FloatControls, Math};
use crate::scene::Scene;
use std::any::Any;

/// Triangles in leaf order, shared by every layout: 9 floats each (`v0 v1 v2`, xyz), 36 bytes,
/// plus the public `prim` id of each, and the scene's triangle-box padding of the closest-hit
/// rule (`base::hit_pad`; the kernels get it in the push constants).
#[derive(Clone, Debug)]
pub struct TriBuffer {
    pub verts: Vec<[f32; 9]>,
    pub ids: Vec<u32>,
    pub pad: f32,
}

impl TriBuffer {
    pub fn new(scene: &Scene, w: &WideBvh) -> TriBuffer {
        let verts = w
            .prims
            .iter()
            .map(|&p| {
                let t = &scene.tris[p as usize];
                [t[0].x, t[0].y, t[0].z, t[1].x, t[1].y, t[1].z, t[2].x, t[2].y, t[2].z]
            })
            .collect();
        TriBuffer { verts, ids: w.prims.clone(), pad: scene.hit_pad() }
    }

    pub fn bytes(&self) -> usize {
        self.verts.len() * 36 + self.ids.len() * 4
    }

    /// The closest hit of `ray` among every triangle under the closest-hit rule in exact mode
    /// (`base::ClosestTrue::new`): what `Scene::brute_force` gives (ties go to the lower
    /// public prim, so the triangles' order does not matter).
    pub fn brute_force(&self, ray: &Ray) -> Hit {
        ClosestTrue::brute_force(ray, self.verts.iter().zip(&self.ids).map(|(v, &id)| (*v, id as i32))).hit()
    }

    /// Re-traces the rays a traversal flagged (`Hit::is_flagged`) with [`Self::brute_force`],
    /// in place, on every core; returns how many there were.
    pub fn resolve(&self, rays: &[Ray], hits: &mut [Hit]) -> usize {
        crate::base::resolve_flagged(rays, hits, |r| self.brute_force(r))
    }
}

/// A node array of any layout and B, as the type-erased [`Encoded`] holds it.
pub trait NodeArray: Send + Sync {
    fn len(&self) -> usize;
    fn is_empty(&self) -> bool {
        self.len() == 0
    }
    /// Bytes of one node.
    fn node_size(&self) -> usize;
    /// Every node's bytes, exactly as uploaded.
    fn to_bytes(&self) -> Vec<u8> {
        self.bytes_of(0..self.len())
    }
    /// The bytes of nodes `range`, exactly as uploaded.
    fn bytes_of(&self, range: std::ops::Range<usize>) -> Vec<u8>;
    fn child(&self, node: usize, s: usize) -> u32;
    fn child_box(&self, node: usize, s: usize) -> ([f32; 3], [f32; 3]);
    fn as_any(&self) -> &dyn Any;
}

impl<N: Node> NodeArray for Vec<N> {
    fn len(&self) -> usize {
        Vec::len(self)
    }
    fn node_size(&self) -> usize {
        std::mem::size_of::<N>()
    }
    fn bytes_of(&self, range: std::ops::Range<usize>) -> Vec<u8> {
        let mut out = Vec::with_capacity(range.len() * self.node_size());
        for n in &self[range.clone()] {
            n.write_bytes(&mut out);
        }
        assert_eq!(
            out.len(),
            range.len() * self.node_size(),
            "a node wrote other than size_of bytes: its struct has padding"
        );
        out
    }
    fn child(&self, node: usize, s: usize) -> u32 {
        self[node].child(s)
    }
    fn child_box(&self, node: usize, s: usize) -> ([f32; 3], [f32; 3]) {
        self[node].child_box(s)
    }
    fn as_any(&self) -> &dyn Any {
        self
    }
}

/// An encoded BVH of any layout and branching factor.
pub struct Encoded {
    pub layout: LayoutId,
    pub branching: usize,
    pub nodes: Box<dyn NodeArray>,
    /// The layout's `Root`.
    pub(crate) root: Box<dyn Any + Send + Sync>,
    /// The push constants' `root` vec4.
    pub push_root: [f32; 4],
    /// The root's world box, which every traversal tests first.
    pub root_box: Aabb,
    pub tris: TriBuffer,
    /// Largest traversal stack: (B−1)·depth + 1.
    pub max_stack: usize,
}

impl Encoded {
    /// Collapses `bin` to `b` and encodes it in `layout`.
    pub fn new(scene: &Scene, bin: &BinaryBvh, layout: LayoutId, b: usize) -> anyhow::Result<Encoded> {
        crate::bvh::check_branching(b)?;
        let what = format!("encoding {} as {layout}, B={b}", scene.name);
        crate::progress::step(&what, || {
            let w = crate::bvh::collapse(bin, b);
            layout.imp().encode(scene, &w).map_err(|e| anyhow::anyhow!("{what}: {e}"))
        })
    }

    /// The typed nodes and root of layout `L` at `B` (`None` for another layout or B).
    pub fn typed<L: super::Layout, const B: usize>(&self) -> Option<(&[L::Node<B>], &L::Root)> {
        let n = self.nodes.as_any().downcast_ref::<Vec<L::Node<B>>>()?;
        Some((n, self.root.downcast_ref::<L::Root>()?))
    }

    pub fn node_count(&self) -> usize {
        self.nodes.len()
    }

    /// Bytes of one node.
    pub fn node_size(&self) -> usize {
        self.nodes.node_size()
    }

    /// Bytes of the node array.
    pub fn node_bytes(&self) -> usize {
        self.nodes.len() * self.nodes.node_size()
    }

    /// The CPU reference of this layout: rays in packets of `p` (1: single rays) in math mode
    /// `math`, as the kernel built with float controls `fc` traces them (their bounds differ),
    /// with the rays fp32 could not decide re-traced exactly ([`Self::resolve`]): the hits
    /// every result reports.
    pub fn reference(&self, rays: &[Ray], p: usize, math: Math, fc: FloatControls) -> (Vec<Hit>, Vec<Counters>) {
        let (mut hits, counters) = self.trace_raw(rays, p, math, fc);
        self.resolve(rays, &mut hits);
        (hits, counters)
    }

    /// Single rays in the layout's default math, float controls on.
    pub fn reference_default(&self, rays: &[Ray]) -> (Vec<Hit>, Vec<Counters>) {
        self.reference(rays, 1, self.layout.info().maths[0], FloatControls::On)
    }

    /// [`Self::reference`] before the re-trace: what a kernel writes, bit for bit, flagged
    /// rays (`Hit::is_flagged`) included.
    pub fn trace_raw(&self, rays: &[Ray], p: usize, math: Math, fc: FloatControls) -> (Vec<Hit>, Vec<Counters>) {
        let (hits, counters) = self.layout.imp().trace(self, rays, p, math, fc);
        let label = format!("{} B{} P{p} {} fc-{}", self.layout, self.branching, math.name(), fc.name());
        crate::digest::record("cpu", &label, rays, &hits, Some(&counters));
        (hits, counters)
    }

    /// [`Self::trace_raw`] of single rays in the layout's default math, float controls on.
    pub fn trace_raw_default(&self, rays: &[Ray]) -> Vec<Hit> {
        self.trace_raw(rays, 1, self.layout.info().maths[0], FloatControls::On).0
    }

    /// Re-traces the flagged rays of `hits` exactly, in place ([`TriBuffer::resolve`]);
    /// returns how many there were.
    pub fn resolve(&self, rays: &[Ray], hits: &mut [Hit]) -> usize {
        self.tris.resolve(rays, hits)
    }
}
