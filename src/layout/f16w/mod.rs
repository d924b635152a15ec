//! Layout `f16w`: every child box stored as fp16 in one global frame (Koskela et al., CGI 2015,
//! *Using Half-Precision Floating-Point Numbers for Storing Bounding Volume Hierarchies*): the
//! scene is translated to its box centre and scaled by one power of two so its largest half
//! extent lies below 16384, and every box is rounded outward to fp16 there. No hierarchy of
//! frames: it shows what fp16 storage costs where small geometry lies far from the scene
//! centre (the fp16 grid is uniform over the whole scene).
//!
//! Box tests in fp32 (`--math f32`, the paper's: boxes decoded to world fp32)
//! or fp16 (`--math f16`: the origin anchored in the global frame at each node's entry bound,
//! f16h's widened fp16 slab test); both argued in [`super::anchored`].
//!
//! Node byte layout for branching B (16·B bytes, the nodes of `f16h`): `lo` f16[3][B] at 0,
//! `hi` f16[3][B] at 6·B, `child` u32[B] at 12·B; 12 bytes of box + 4 of child word per
//! child. The global frame (w.xyz, k) travels in the push constants' `root`. GLSL hooks:
//! `glsl/layout/f16w.glsl`.

use super::anchored::{self, decode_plane, inv_pow2, AnchoredNode};
use super::f16h::hooks::{slot_box, Ray16};
use super::f16h::{root_frame, F16hNode, Frame};
use super::{EncodeError, Layout, Math, Needs};
use crate::bvh::WideBvh;
use crate::scene::Scene;
use crate::trace::{Counters, RayPre};
use half::f16;

/// The `f16w` layout.
pub struct F16w;

impl<const B: usize> AnchoredNode<Frame> for F16hNode<B> {
    /// Every node's frame is the global one (the root).
    fn frame(&self, root: &Frame) -> Frame {
        *root
    }
    fn local_box(&self, s: usize) -> ([f16; 3], [f16; 3]) {
        slot_box(self, s)
    }
    fn world_box(&self, s: usize, f: &Frame) -> ([f32; 3], [f32; 3]) {
        world_box(self, s, f)
    }
}

/// The stored box of slot `s` decoded to world fp32 (still containing the true box).
#[inline]
pub fn world_box<const B: usize>(n: &F16hNode<B>, s: usize, f: &Frame) -> ([f32; 3], [f32; 3]) {
    let (lo, hi) = slot_box(n, s);
    let ik = inv_pow2(f.k);
    let mut l = [0f32; 3];
    let mut u = [0f32; 3];
    for a in 0..3 {
        // fp16 times a power of two is exact in fp32; the sum rounds once (anchored::decode_plane).
        l[a] = decode_plane(f.w[a], lo[a].to_f32() * ik);
        u[a] = decode_plane(f.w[a], hi[a].to_f32() * ik);
    }
    (l, u)
}

impl Layout for F16w {
    const NAME: &'static str = "f16w";
    const SUMMARY: &'static str = "fp16 child boxes in one global frame (Koskela et al. 2015)";
    const MATHS: &'static [Math] = &[Math::F32, Math::F16];
    const GLSL: &'static str = include_str!("../../../glsl/layout/f16w.glsl");

    fn needs(math: Math) -> Needs {
        Needs { storage16: true, float16: math == Math::F16 }
    }

    type Node<const B: usize> = F16hNode<B>;
    type Root = Frame;
    type Ray = Ray16;
    /// The node's entry bound (world parameter).
    type Entry = f32;
    type Visit = anchored::Visit;
    /// (entry parameter, its lower bound).
    type ChildHit = (f32, f32);

    fn encode<const B: usize>(_scene: &Scene, w: &WideBvh) -> Result<(Vec<F16hNode<B>>, Frame), EncodeError> {
        let frame = root_frame(&w.nodes[0].bounds);
        let mut out = Vec::with_capacity(w.nodes.len());
        for (i, n) in w.nodes.iter().enumerate() {
            let (lo, hi, child) = anchored::children16::<B>(Self::NAME, i, n, &frame)?;
            out.push(F16hNode { lo, hi, child });
        }
        Ok((out, frame))
    }

    fn push_root(root: &Frame) -> [f32; 4] {
        [root.w[0], root.w[1], root.w[2], root.k]
    }

    anchored::anchored_hooks!(F16hNode, Frame);
}
