//! Layout `f16a` (anchored): every inner node stores its own frame — an fp32 anchor `w` (the
//! centre of its box) and a power-of-two scale `k` (its largest half extent below 16384) — and
//! its children as fp16 in that frame, rounded outward. At each node the ray origin is moved
//! into the node's frame from the fp32 world ray: no chain of moved origins, no re-anchoring,
//! a stack entry of one fp32 value. The lean alternative to the poster's chained frames.
//!
//! Box tests in fp16 (`--math f16`, the default: origin anchored at the node's entry bound,
//! the shared widened fp16 slab test) or fp32 (`--math f32`: boxes decoded to world fp32); both
//! argued in [`super::anchored`].
//!
//! Node byte layout for branching B (16 + 16·B bytes): `w` f32[3] at 0, `k` f32 at 12, `lo`
//! f16[3][B] at 16, `hi` f16[3][B] at 16 + 6·B, `child` u32[B] at 16 + 12·B: 16 bytes per
//! child plus 16 per node. B=2: 48 bytes, B=4: 80, B=8: 144, B=16: 272. GLSL hooks:
//! `glsl/layout/f16a.glsl`.

use super::anchored::{self, decode_plane, inv_pow2, AnchoredNode};
use super::frames::{fit_frame, Frame};
use super::half::Ray16;
use super::{EncodeError, Layout, LayoutInfo, Needs, Node};
use crate::base::{Counters, RayPre};
use crate::bvh::WideBvh;
use crate::precision::Math;
use half::f16;

/// The `f16a` layout.
pub struct F16a;

/// An `f16a` node (see the module docs for the byte layout).
#[repr(C)]
#[derive(Clone, Copy, Debug)]
pub struct F16aNode<const B: usize> {
    /// The frame's anchor (world).
    pub w: [f32; 3],
    /// The frame's scale, a power of two: x_local = (x − w)·k.
    pub k: f32,
    /// Child box minima in the node's frame, rounded down: `lo[axis][slot]`.
    pub lo: [[f16; B]; 3],
    /// Child box maxima, rounded up.
    pub hi: [[f16; B]; 3],
    pub child: [u32; B],
}
const _: () = {
    assert!(std::mem::size_of::<F16aNode<2>>() == 48);
    assert!(std::mem::size_of::<F16aNode<4>>() == 80);
    assert!(std::mem::size_of::<F16aNode<8>>() == 144);
    assert!(std::mem::size_of::<F16aNode<16>>() == 272);
};

impl<const B: usize> F16aNode<B> {
    #[inline(always)]
    fn slot(&self, s: usize) -> ([f16; 3], [f16; 3]) {
        ([self.lo[0][s], self.lo[1][s], self.lo[2][s]], [self.hi[0][s], self.hi[1][s], self.hi[2][s]])
    }

    /// The stored box of slot `s` decoded to world fp32 (still containing the true box).
    #[inline]
    pub fn world_box(&self, s: usize) -> ([f32; 3], [f32; 3]) {
        let (lo, hi) = self.slot(s);
        let ik = inv_pow2(self.k);
        let mut l = [0f32; 3];
        let mut u = [0f32; 3];
        for a in 0..3 {
            l[a] = decode_plane(self.w[a], lo[a].to_f32() * ik);
            u[a] = decode_plane(self.w[a], hi[a].to_f32() * ik);
        }
        (l, u)
    }
}

impl<const B: usize> AnchoredNode<()> for F16aNode<B> {
    fn frame(&self, _: &()) -> Frame {
        Frame { w: self.w, k: self.k }
    }
    fn local_box(&self, s: usize) -> ([f16; 3], [f16; 3]) {
        self.slot(s)
    }
    fn world_box(&self, s: usize, _: &Frame) -> ([f32; 3], [f32; 3]) {
        F16aNode::world_box(self, s)
    }
}

impl<const B: usize> Node for F16aNode<B> {
    #[inline(always)]
    fn child(&self, s: usize) -> u32 {
        self.child[s]
    }
    fn child_box(&self, s: usize) -> ([f32; 3], [f32; 3]) {
        let (lo, hi) = self.slot(s);
        (lo.map(f16::to_f32), hi.map(f16::to_f32))
    }
    fn write_bytes(&self, out: &mut Vec<u8>) {
        out.extend_from_slice(bytemuck::cast_slice(&self.w[..]));
        out.extend_from_slice(&self.k.to_le_bytes());
        out.extend_from_slice(bytemuck::cast_slice(&self.lo[..]));
        out.extend_from_slice(bytemuck::cast_slice(&self.hi[..]));
        out.extend_from_slice(bytemuck::cast_slice(&self.child[..]));
    }
}

impl Layout for F16a {
    const INFO: LayoutInfo = LayoutInfo {
        name: "f16a",
        summary: "fp16 child boxes in a per-node fp32 anchored frame, origin re-derived per node",
        maths: &[Math::F16, Math::F32],
        glsl: include_str!("../../../glsl/layout/f16a.glsl"),
        needs: |math| Needs { storage16: false, float16: math == Math::F16 },
        float_controls_off: true,
        stack_entry: |_| anchored::STACK_ENTRY,
        glsl_constants: super::half::glsl_constants,
        ..LayoutInfo::DEFAULT
    };

    type Node<const B: usize> = F16aNode<B>;
    type Root = ();
    type Ray = Ray16;
    /// The node's entry bound (world parameter).
    type Entry = f32;
    type Visit = anchored::Visit;
    /// (entry parameter, its lower bound).
    type ChildHit = (f32, f32);

    fn encode<const B: usize>(w: &WideBvh) -> Result<(Vec<F16aNode<B>>, ()), EncodeError> {
        let mut out = Vec::with_capacity(w.nodes.len());
        for (i, n) in w.nodes.iter().enumerate() {
            let mut bounds = crate::base::Aabb::EMPTY;
            for (b, _) in &n.children {
                bounds.grow(b.min);
                bounds.grow(b.max);
            }
            let f = fit_frame(&bounds);
            let c = anchored::children16::<B>(Self::INFO.name, i, n, &f)?;
            out.push(F16aNode { w: f.w, k: f.k, lo: c.lo, hi: c.hi, child: c.child });
        }
        Ok((out, ()))
    }

    fn push_root(_: &()) -> [f32; 4] {
        [0.0; 4]
    }

    anchored::anchored_hooks!(F16aNode, ());
}
