//! Layout `f16h-poster`: the poster's algorithm as written (Koskela et al., *Half-Precision
//! Floating-Point Ray Traversal*), on the nodes and frames of `f16h` (same encoder, same bytes):
//! at a hit inner child the origin is moved to the child's entry point, O + max(tn, 0)·d16, and
//! converted to the child frame, (· − c)·r, all in fp16; box tests in fp16 with no widening; no
//! error bound and no re-anchoring. It is not conservative — rounding of the moved origins and
//! of the box tests can reject a box the ray touches — so it is checked bit for bit against
//! its own CPU reference (this module), and its false misses and other disagreements with
//! `f32` are reported, never hidden. A moved origin that overflows fp16 is clamped to ±65504
//! (NaN to 0), which the poster does not specify, so that no NaN enters a box test (and CPU and
//! GPU agree). Only fp16 math. GLSL hooks: `glsl/layout/f16h-poster.glsl`.

use super::frames::{derive_child, encode_chained, Frame};
use super::half::{anchor, Ray16};
use super::node16::Node16;
use super::{EncodeError, Layout, LayoutInfo, Needs};
use crate::base::{Counters, RayPre};
use crate::bvh::WideBvh;
use crate::precision::{FloatControls, Math};
use half::f16;

/// The `f16h-poster` layout.
pub struct F16hPoster;

/// A stack entry: the node's frame, the origin in it (fp16) and the world parameter it stands
/// for.
#[derive(Clone, Copy, Debug)]
pub struct Entry {
    pub frame: Frame,
    pub o: [f16; 3],
    pub tp: f32,
}

/// Per visit: m·k (local units per world unit) and the closest hit in local units (fp16).
#[derive(Clone, Copy, Debug)]
pub struct Visit {
    pub mk: f32,
    pub s_lim: f16,
}

fn finite16(x: f16) -> f16 {
    if x.is_nan() {
        f16::ZERO
    } else {
        x.clamp(f16::MIN, f16::MAX)
    }
}

impl Layout for F16hPoster {
    const INFO: LayoutInfo = LayoutInfo {
        name: "f16h-poster",
        summary: "the poster's f16h as written: fp16 origin moves, no error bound (not conservative)",
        maths: &[Math::F16],
        glsl: include_str!("../../../glsl/layout/f16h-poster.glsl"),
        conservative: false,
        needs: |_| Needs { storage16: false, float16: true },
        stack_entry: |_| &[("wk", "vec4"), ("o", "f16vec3"), ("tp", "float")],
        defer_entries: true,
        glsl_constants: super::half::glsl_constants,
        ..LayoutInfo::DEFAULT
    };

    type Node<const B: usize> = Node16<B>;
    type Root = Frame;
    type Ray = Ray16;
    type Entry = Entry;
    type Visit = Visit;
    /// The child's entry parameter in the node's frame.
    type ChildHit = f16;

    fn encode<const B: usize>(w: &WideBvh) -> Result<(Vec<Node16<B>>, Frame), EncodeError> {
        encode_chained::<B>(Self::INFO.name, w).map(|(nodes, root, _)| (nodes, root))
    }

    fn push_root(root: &Frame) -> [f32; 4] {
        [root.w[0], root.w[1], root.w[2], root.k]
    }

    fn ray(r: &RayPre, math: Math, fc: FloatControls) -> Ray16 {
        Ray16::new(r, math, fc)
    }

    fn root_entry(root: &Frame, r: &RayPre, _: &Ray16, near: f32) -> Entry {
        let (o, _) = anchor(r, root, near, Math::F16, false);
        Entry { frame: *root, o: o.map(f16::from_f32), tp: near }
    }

    fn entry_t(e: &Entry) -> f32 {
        e.tp
    }

    fn visit<const B: usize>(_: &Node16<B>, _: &Frame, e: &Entry, _: &RayPre, lr: &Ray16, best_t: f32) -> Visit {
        let mk = lr.m * e.frame.k;
        Visit { mk, s_lim: f16::from_f32((best_t - e.tp) * mk) }
    }

    fn test_child<const B: usize>(
        n: &Node16<B>,
        s: usize,
        e: &Entry,
        v: &Visit,
        _: &RayPre,
        lr: &Ray16,
    ) -> Option<(f32, f16)> {
        let (lo, hi) = n.slot_box(s);
        let (mut tn, mut tf) = (f16::NEG_INFINITY, f16::INFINITY);
        for a in 0..3 {
            let la = lo[a] - e.o[a];
            let ha = hi[a] - e.o[a];
            let (t0, t1) = if lr.d[a] == f16::ZERO {
                if la <= f16::ZERO && ha >= f16::ZERO {
                    (f16::NEG_INFINITY, f16::INFINITY)
                } else {
                    (f16::INFINITY, f16::NEG_INFINITY)
                }
            } else {
                let (x, y) = (la * lr.idir[a], ha * lr.idir[a]);
                (x.min(y), x.max(y))
            };
            tn = tn.max(t0);
            tf = tf.min(t1);
        }
        (tn <= tf && tf >= f16::ZERO && tn <= v.s_lim).then_some((tn.to_f32(), tn))
    }

    fn child_entry<const B: usize>(
        n: &Node16<B>,
        s: usize,
        e: &Entry,
        v: &Visit,
        tn: &f16,
        _: &RayPre,
        lr: &Ray16,
        _: &mut Counters,
    ) -> Entry {
        let (lo, hi) = n.slot_box(s);
        let cf = derive_child(&e.frame, lo, hi);
        let se = tn.max(f16::ZERO);
        let r16 = f16::from_f32(cf.r);
        let o = [0, 1, 2].map(|a| finite16(((e.o[a] + se * lr.d[a]) - cf.c[a]) * r16));
        Entry { frame: cf.frame, o, tp: e.tp + se.to_f32() / v.mk }
    }
}
