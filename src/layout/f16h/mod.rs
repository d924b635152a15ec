//! Layout `f16h`: the hierarchical half-precision encoding of Koskela et al. (*Half-Precision
//! Floating-Point Ray Traversal*): every child box stored as fp16 in its parent's uniformly
//! scaled frame (chained frames, [`crate::layout::frames`]), box tests and origin moves in
//! fp16 arithmetic (or fp32, or mixed) with a carried error bound ([`hooks`]: the origin move
//! and its argument; [`crate::layout::half`]: the box test).
//!
//! Nodes: [`Node16`] (16·B bytes). The root frame (w.xyz, k) travels in the push constants'
//! `root`. GLSL hooks: `glsl/layout/f16h.glsl`.

pub mod hooks;

pub use hooks::Entry;

use super::frames::{encode_chained, Frame};
use super::half::{HVisit, Ray16};
use super::node16::Node16;
use super::{EncodeError, Layout, LayoutInfo, Needs};
use crate::base::{Counters, RayPre};
use crate::bvh::WideBvh;
use crate::precision::{FloatControls, Math};

/// The `f16h` layout.
pub struct F16h;

impl Layout for F16h {
    const INFO: LayoutInfo = LayoutInfo {
        name: "f16h",
        summary: "fp16 child boxes in the parent's frame, frames chained (Koskela et al.), made conservative",
        maths: &[Math::F16, Math::F32, Math::Mixed],
        glsl: include_str!("../../../glsl/layout/f16h.glsl"),
        // fp16 storage always; fp16 arithmetic in the f16 and mixed modes only: the f32 mode
        // emulates its few fp16 roundings (frame centres, bounds) with fp32 and integer
        // operations (glsl/half.glsl, `rte16`), so it runs without `shaderFloat16`.
        float_controls_off: true,
        needs: |math| Needs { storage16: false, float16: math != Math::F32 },
        // frame (w.xyz, k), origin in the node's frame, its error bound, tp, tlo.
        stack_entry: |math| match math {
            Math::F32 => &[("wk", "vec4"), ("o", "vec3"), ("e", "float"), ("tp", "float"), ("tlo", "float")],
            Math::F16 | Math::Mixed => {
                &[("wk", "vec4"), ("o", "f16vec3"), ("e", "float"), ("tp", "float"), ("tlo", "float")]
            }
        },
        defer_entries: true,
        glsl_constants: || super::half::glsl_constants() + &hooks::glsl_constants(),
        ..LayoutInfo::DEFAULT
    };

    type Node<const B: usize> = Node16<B>;
    type Root = Frame;
    type Ray = Ray16;
    type Entry = Entry;
    type Visit = HVisit;
    /// (tn, tn_lb): the entry parameter and its lower bound in the node's frame.
    type ChildHit = (f32, f32);

    fn encode<const B: usize>(w: &WideBvh) -> Result<(Vec<Node16<B>>, Frame), EncodeError> {
        encode_chained::<B>(Self::INFO.name, w).map(|(nodes, root, _)| (nodes, root))
    }

    fn push_root(root: &Frame) -> [f32; 4] {
        [root.w[0], root.w[1], root.w[2], root.k]
    }

    fn ray(r: &RayPre, math: Math, fc: FloatControls) -> Ray16 {
        Ray16::new(r, math, fc)
    }

    fn root_entry(root: &Frame, r: &RayPre, lr: &Ray16, near: f32) -> Entry {
        hooks::root_entry(root, r, lr, near)
    }

    fn entry_t(e: &Entry) -> f32 {
        e.tlo
    }

    fn visit<const B: usize>(_: &Node16<B>, _: &Frame, e: &Entry, _: &RayPre, lr: &Ray16, best_t: f32) -> HVisit {
        hooks::visit(e, lr, best_t)
    }

    #[inline]
    fn test_child<const B: usize>(
        n: &Node16<B>,
        s: usize,
        e: &Entry,
        v: &HVisit,
        _: &RayPre,
        lr: &Ray16,
    ) -> Option<(f32, (f32, f32))> {
        hooks::test_child(n, s, e, v, lr)
    }

    fn child_entry<const B: usize>(
        n: &Node16<B>,
        s: usize,
        e: &Entry,
        v: &HVisit,
        h: &(f32, f32),
        r: &RayPre,
        lr: &Ray16,
        c: &mut Counters,
    ) -> Entry {
        hooks::child_entry(n, s, e, v, *h, r, lr, c)
    }
}
