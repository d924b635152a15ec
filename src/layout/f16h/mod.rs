//! Layout `f16h`: the hierarchical half-precision encoding of Koskela et al. (*Half-Precision
//! Floating-Point Ray Traversal*): every child box stored as fp16 in its parent's uniformly
//! scaled frame ([`frame`]: frames, encoder), box tests and origin moves in fp16 arithmetic
//! (or fp32, or mixed) with a carried error bound ([`hooks`]: the bound and its argument).
//!
//! Node byte layout for branching B (16·B bytes): `lo` f16[3][B] at 0, `hi` f16[3][B] at
//! 6·B, `child` u32[B] at 12·B. B=2: 32 bytes, B=4: 64, B=8: 128, B=16: 256. The root frame
//! (w.xyz, k) travels in the push constants' `root`. GLSL hooks: `glsl/layout/f16h.glsl`.

pub mod frame;
pub mod hooks;

pub use frame::{derive_child, encode_with_frames, root_frame, to_local, ChildFrame, Frame, COORD_LIMIT};
pub use hooks::{Entry, Ray16, Visit};

use super::{EncodeError, Layout, Math, Needs, Node};
use crate::bvh::WideBvh;
use crate::scene::Scene;
use crate::trace::{Counters, RayPre};
use half::f16;

/// The `f16h` layout.
pub struct F16h;

/// An `f16h` node (see the module docs for the byte layout).
#[repr(C)]
#[derive(Clone, Copy, Debug)]
pub struct F16hNode<const B: usize> {
    /// Child box minima in the node's frame, rounded down: `lo[axis][slot]`.
    pub lo: [[f16; B]; 3],
    /// Child box maxima, rounded up.
    pub hi: [[f16; B]; 3],
    /// Child reference words.
    pub child: [u32; B],
}
const _: () = {
    assert!(std::mem::size_of::<F16hNode<2>>() == 32);
    assert!(std::mem::size_of::<F16hNode<4>>() == 64);
    assert!(std::mem::size_of::<F16hNode<8>>() == 128);
    assert!(std::mem::size_of::<F16hNode<16>>() == 256);
};

impl<const B: usize> Node for F16hNode<B> {
    #[inline(always)]
    fn child(&self, s: usize) -> u32 {
        self.child[s]
    }
    fn child_box(&self, s: usize) -> ([f32; 3], [f32; 3]) {
        let (lo, hi) = hooks::slot_box(self, s);
        (lo.map(f16::to_f32), hi.map(f16::to_f32))
    }
    fn write_bytes(&self, out: &mut Vec<u8>) {
        out.extend_from_slice(bytemuck::cast_slice(&self.lo[..]));
        out.extend_from_slice(bytemuck::cast_slice(&self.hi[..]));
        out.extend_from_slice(bytemuck::cast_slice(&self.child[..]));
    }
}

impl Layout for F16h {
    const NAME: &'static str = "f16h";
    const SUMMARY: &'static str =
        "fp16 child boxes in the parent's frame, frames chained (Koskela et al.), made conservative";
    const MATHS: &'static [Math] = &[Math::F16, Math::F32, Math::Mixed];
    const GLSL: &'static str = include_str!("../../../glsl/layout/f16h.glsl");

    /// fp16 storage always; fp16 arithmetic in the f16 and mixed modes only: the f32 mode
    /// emulates its few fp16 roundings (frame centres, bounds) with fp32 and integer
    /// operations (glsl/layout/f16h.glsl, `rte16`), so it runs without `shaderFloat16`.
    const FLOAT_CONTROLS_OFF: bool = true;

    fn needs(math: Math) -> Needs {
        Needs { storage16: true, float16: math != Math::F32 }
    }

    type Node<const B: usize> = F16hNode<B>;
    type Root = Frame;
    type Ray = Ray16;
    type Entry = Entry;
    type Visit = Visit;
    /// (tn, tn_lb): the entry parameter and its lower bound in the node's frame.
    type ChildHit = (f32, f32);

    fn encode<const B: usize>(_scene: &Scene, w: &WideBvh) -> Result<(Vec<F16hNode<B>>, Frame), EncodeError> {
        encode_with_frames::<B>(w).map(|(nodes, root, _)| (nodes, root))
    }

    fn push_root(root: &Frame) -> [f32; 4] {
        [root.w[0], root.w[1], root.w[2], root.k]
    }

    fn stack_entry(math: Math) -> &'static [(&'static str, &'static str)] {
        // frame (w.xyz, k), origin in the node's frame, its error bound, tp, tlo.
        match math {
            Math::F32 => &[("wk", "vec4"), ("o", "vec3"), ("e", "float"), ("tp", "float"), ("tlo", "float")],
            Math::F16 | Math::Mixed => {
                &[("wk", "vec4"), ("o", "f16vec3"), ("e", "float"), ("tp", "float"), ("tlo", "float")]
            }
        }
    }

    fn glsl_constants() -> String {
        use crate::interface::{glsl_float, glsl_int};
        [
            glsl_float("OCAP", hooks::OCAP),
            glsl_float("EMAX", hooks::EMAX),
            glsl_float("EBIG", hooks::EBIG),
            glsl_float("W_MARGIN", hooks::W_MARGIN),
            glsl_float("W_MARGIN_OFF", hooks::W_MARGIN_OFF),
            glsl_float("SAT", hooks::SAT),
            glsl_float("BIG32", hooks::BIG32),
            glsl_float("D_FLUSH", hooks::D_FLUSH),
            glsl_int("K_MIN_LOG2", frame::K_MIN_LOG2),
            glsl_int("K_MAX_LOG2", frame::K_MAX_LOG2),
        ]
        .concat()
    }

    fn ray(r: &RayPre, math: Math, fc: crate::variant::FloatControls) -> Ray16 {
        Ray16::new(r, math, fc)
    }

    fn root_entry(root: &Frame, r: &RayPre, lr: &Ray16, near: f32) -> Entry {
        hooks::root_entry(root, r, lr, near)
    }

    fn entry_t(e: &Entry) -> f32 {
        e.tlo
    }

    fn visit<const B: usize>(_: &F16hNode<B>, _: &Frame, e: &Entry, _: &RayPre, lr: &Ray16, best_t: f32) -> Visit {
        hooks::visit(e, lr, best_t)
    }

    #[inline]
    fn test_child<const B: usize>(
        n: &F16hNode<B>,
        s: usize,
        e: &Entry,
        v: &Visit,
        _: &RayPre,
        lr: &Ray16,
    ) -> Option<(f32, (f32, f32))> {
        hooks::test_child(n, s, e, v, lr)
    }

    fn child_entry<const B: usize>(
        n: &F16hNode<B>,
        s: usize,
        e: &Entry,
        v: &Visit,
        h: &(f32, f32),
        r: &RayPre,
        lr: &Ray16,
        c: &mut Counters,
    ) -> Entry {
        hooks::child_entry(n, s, e, v, *h, r, lr, c)
    }
}
