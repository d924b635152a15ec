//! Layout `f16w`: every child box stored as fp16 in one global frame (Koskela et al., CGI 2015,
//! *Using Half-Precision Floating-Point Numbers for Storing Bounding Volume Hierarchies*): the
//! scene is translated to its box centre and scaled by one power of two so its largest half
//! extent lies below 16384, and every box is rounded outward to fp16 there. No hierarchy of
//! frames: it shows what fp16 storage costs where small geometry lies far from the scene
//! centre (the fp16 grid is uniform over the whole scene).
//!
//! Box tests in fp32 (`--math f32`, the paper's: boxes decoded to world fp32)
//! or fp16 (`--math f16`: the origin anchored in the global frame at each node's entry bound,
//! the shared widened fp16 slab test); both argued in [`super::anchored`].
//!
//! Node byte layout for branching B (16·B bytes, the fp16 node [`Node16`]): `lo` f16[3][B] at
//! 0, `hi` f16[3][B] at 6·B, `child` u32[B] at 12·B; 12 bytes of box + 4 of child word per
//! child. The global frame (w.xyz, k) travels in the push constants' `root`. GLSL hooks:
//! `glsl/layout/f16w.glsl`.

use super::anchored::{self, decode_plane, inv_pow2, AnchoredNode};
use super::frames::{fit_frame, Frame};
use super::half::Ray16;
use super::node16::Node16;
use super::{EncodeError, Layout, LayoutInfo, Needs, Node};
use crate::base::{Counters, RayPre};
use crate::bvh::WideBvh;
use crate::precision::Math;
use half::f16;

/// The `f16w` layout.
pub struct F16w;

/// An `f16w` node: the fp16 node, its boxes in the one global frame.
#[repr(transparent)]
#[derive(Clone, Copy, Debug)]
pub struct F16wNode<const B: usize>(pub Node16<B>);

impl<const B: usize> Node for F16wNode<B> {
    #[inline(always)]
    fn child(&self, s: usize) -> u32 {
        self.0.child(s)
    }
    fn child_box(&self, s: usize) -> ([f32; 3], [f32; 3]) {
        self.0.child_box(s)
    }
    fn write_bytes(&self, out: &mut Vec<u8>) {
        self.0.write_bytes(out)
    }
}

impl<const B: usize> AnchoredNode<Frame> for F16wNode<B> {
    /// Every node's frame is the global one (the root).
    fn frame(&self, root: &Frame) -> Frame {
        *root
    }
    fn local_box(&self, s: usize) -> ([f16; 3], [f16; 3]) {
        self.0.slot_box(s)
    }
    /// The stored box of slot `s` decoded to world fp32 (still containing the true box).
    fn world_box(&self, s: usize, f: &Frame) -> ([f32; 3], [f32; 3]) {
        let (lo, hi) = self.0.slot_box(s);
        let ik = inv_pow2(f.k);
        let mut l = [0f32; 3];
        let mut u = [0f32; 3];
        for a in 0..3 {
            // fp16 times a power of two is exact in fp32; the sum rounds once (decode_plane).
            l[a] = decode_plane(f.w[a], lo[a].to_f32() * ik);
            u[a] = decode_plane(f.w[a], hi[a].to_f32() * ik);
        }
        (l, u)
    }
}

impl Layout for F16w {
    const INFO: LayoutInfo = LayoutInfo {
        name: "f16w",
        summary: "fp16 child boxes in one global frame (Koskela et al. 2015)",
        maths: &[Math::F32, Math::F16],
        glsl: include_str!("../../../glsl/layout/f16w.glsl"),
        needs: |math| Needs { storage16: false, float16: math == Math::F16 },
        float_controls_off: true,
        stack_entry: |_| anchored::STACK_ENTRY,
        glsl_constants: super::half::glsl_constants,
        ..LayoutInfo::DEFAULT
    };

    type Node<const B: usize> = F16wNode<B>;
    type Root = Frame;
    type Ray = Ray16;
    /// The node's entry bound (world parameter).
    type Entry = f32;
    type Visit = anchored::Visit;
    /// (entry parameter, its lower bound).
    type ChildHit = (f32, f32);

    fn encode<const B: usize>(w: &WideBvh) -> Result<(Vec<F16wNode<B>>, Frame), EncodeError> {
        let frame = fit_frame(&w.nodes[0].bounds);
        let nodes = w
            .nodes
            .iter()
            .enumerate()
            .map(|(i, n)| anchored::children16::<B>(Self::INFO.name, i, n, &frame).map(F16wNode));
        Ok((nodes.collect::<Result<_, _>>()?, frame))
    }

    fn push_root(root: &Frame) -> [f32; 4] {
        [root.w[0], root.w[1], root.w[2], root.k]
    }

    anchored::anchored_hooks!(F16wNode, Frame);
}
