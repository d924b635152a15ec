//! Hooks shared by the layouts whose child boxes are tested in a per-node (or per-BVH) frame
//! against the ray origin re-derived from the fp32 world ray at every node — `f16w`, `f16a`,
//! `q8` — with `glsl/anchored.glsl` doing the same operations in the same order. A layout
//! supplies its node frame, the child's box in that frame as fp16 (exact or rounded outward),
//! and the child's box decoded to world fp32 ([`decode_plane`]).
//!
//! # fp32 math (`Math::F32`)
//! The stored box is decoded to world fp32 (one rounding, monotone: [`decode_plane`]), which
//! still contains the true box; the robust fp32 slab test of the `f32` layout follows
//! (`base::slab32`), so no ray that reaches the true box within its interval is rejected.
//! Stack entries carry the child's entry distance, as in `f32`.
//!
//! # fp16 math (`Math::F16`)
//! At each visited node the origin is placed at the node's entry bound `t` (the stack entry)
//! in the node's frame, computed in fp32 from the world ray and rounded to fp16, with the
//! error bound of the shared anchor (`half::anchor`: fp32 rounding of the point and the frame
//! map, clamping to ±OCAP, the fp16 rounding). The node's boxes span at most ±16384 in its
//! frame, so the shared box-test argument applies unchanged (`half` module docs: the widening
//! w = e·(1 + 2⁻¹¹) + 44 and the (1 ∓ 2⁻⁸) factors, property-tested there on adversarial
//! boxes and rays); with tp = tlo = t the lower cull keeps exactly the part of the ray from t
//! on, which holds everything that can still matter (t is a lower bound of the node's entry).
//! A hit child's entry bound is its tn_lb mapped back to world units and rounded down
//! (`half::half_child_tlo`). No origin is carried from node to node, so the bound never compounds
//! and nothing is ever re-anchored; the stack entry is one fp32 value.
//!
//! # Without float controls (`FC_OFF`)
//! The build for devices without round-to-nearest-even and inf/NaN preservation keeps every
//! hit under any faithful rounding: fp32 math decodes each plane with `add_rte` (integer
//! operations, `fp16::add_rte_emulated`, equal to IEEE addition), so the decoded box is this
//! reference's bit for bit and still contains the true box; the fp32 slab test is `f32`'s,
//! whose 2⁻²⁰ widening is far beyond what a faithful rounding of its three operations moves.
//! fp16 math takes the shared fp16 machinery's `off` path, whose bounds allow every rounding
//! a full ulp (f16h's argument, `half` and `f16h::hooks`): the anchor's error bound uses 2⁻²¹
//! for 2⁻²³, the fp16 conversions are emulated (`rte16`), products saturate at ±SAT instead of
//! overflowing, the widening and the child's entry bound are those of the `off` build. The
//! frames need nothing: f16w's is the push constants', f16a's and q8's are stored, each scale a
//! power of two whose reciprocal comes from the exponent bits; q8's grid values times powers of
//! two are exact. This reference passes `r16.off` to the same functions.

use super::frames::Frame;
use super::half::{self, HVisit, Ray16};
use crate::base::{slab32, RayPre};
use crate::precision::Math;
use ::half::f16;

/// What one visit of one node fixes for one ray.
#[derive(Clone, Copy, Debug)]
pub struct Visit {
    /// The closest hit so far (fp32 math: the box tests' upper limit).
    pub tmax: f32,
    /// The node's entry bound.
    pub t: f32,
    /// The node's frame.
    pub frame: Frame,
    /// fp16 math: the origin anchored in the node's frame (fp16 values) and the visit bounds.
    pub o: [f32; 3],
    pub h: HVisit,
}

const NO_HALF_VISIT: HVisit = HVisit { mk: 0.0, s_lim: f16::ZERO, lower: f16::ZERO, precise: true, w: f16::ZERO };

/// 1/k for a power of two k, exactly, from the exponent bits (`inv_pow2` in the kernels).
#[inline]
pub fn inv_pow2(k: f32) -> f32 {
    f32::from_bits((254 - (k.to_bits() >> 23)) << 23)
}

/// A stored plane decoded to world fp32: `w + x`, where `x` (a stored fp16 or 8-bit value times
/// a power of two) is exact in fp32, so the sum is the only rounding. It needs no widening:
/// rounding to nearest is monotone, and the true plane is an fp32 value (a triangle vertex
/// coordinate) on the inner side of the exact stored plane, so the rounded plane stays on the
/// outer side of it — a lower plane v ≤ w + x gives v = fl(v) ≤ fl(w + x), and likewise above.
/// (The kernels compute it with `precise`, so no fused multiply-add changes the rounding;
/// without float controls with `add_rte`, the same sum whatever the device rounds.)
#[inline]
pub fn decode_plane(w: f32, x: f32) -> f32 {
    w + x
}

/// The visit of a node with frame `frame` by a ray whose entry bound there is `t`.
#[inline]
pub fn visit(frame: &Frame, t: f32, r: &RayPre, r16: &Ray16, best_t: f32) -> Visit {
    if r16.math == Math::F32 {
        return Visit { tmax: best_t, t, frame: *frame, o: [0.0; 3], h: NO_HALF_VISIT };
    }
    let (o, e) = half::anchor(r, frame, t, Math::F16, r16.off);
    Visit { tmax: best_t, t, frame: *frame, o, h: half::half_visit(frame.k, e, t, t, r16, best_t) }
}

/// fp32 math: the box test of a child's outward-decoded world box; (key, (near, near)).
#[inline]
pub fn test_world(lo: [f32; 3], hi: [f32; 3], v: &Visit, r: &RayPre) -> Option<(f32, (f32, f32))> {
    let (near, far) = slab32(r, lo, hi, r.tmin, v.tmax);
    (near <= far).then_some((near, (near, near)))
}

/// fp16 math: the widened box test of a child's fp16 box in the node frame; (tn, (tn, tn_lb)).
#[inline]
pub fn test_local(lo: [f16; 3], hi: [f16; 3], v: &Visit, r16: &Ray16) -> Option<(f32, (f32, f32))> {
    half::half_test(&v.o, lo, hi, &v.h, r16).map(|(tn, tn_lb)| (tn, (tn, tn_lb)))
}

/// The stack entry (entry bound) of a hit inner child.
#[inline]
pub fn child_entry(v: &Visit, (tn, tn_lb): (f32, f32), r16: &Ray16) -> f32 {
    if r16.math == Math::F32 {
        tn
    } else {
        half::half_child_tlo(&v.h, v.t, v.t, tn_lb, r16.off)
    }
}

/// A wide node's children as fp16 boxes in frame `f`, rounded outward, with their child words
/// (the fp16 part of the f16w and f16a nodes).
pub fn children16<const B: usize>(
    layout: &'static str,
    i: usize,
    n: &crate::bvh::WideNode,
    f: &Frame,
) -> Result<super::node16::Node16<B>, super::EncodeError> {
    let mut out = super::node16::Node16 {
        lo: [[f16::ZERO; B]; 3],
        hi: [[f16::ZERO; B]; 3],
        child: [crate::interface::CHILD_EMPTY; B],
    };
    for (slot, (b, c)) in n.children.iter().enumerate() {
        let (lo, hi) = super::frames::stored_box(layout, i, slot, f, b)?;
        for a in 0..3 {
            out.lo[a][slot] = lo[a];
            out.hi[a][slot] = hi[a];
        }
        out.child[slot] = super::encode_child(c);
    }
    Ok(out)
}

/// The stack entry fields of these layouts.
pub const STACK_ENTRY: &[(&str, &str)] = &[("t", "float")];

/// What a node of an anchored layout provides; [`anchored_hooks!`] builds the layout's hooks
/// from it (the GLSL side: `NodeFrame` and `load_frame`, read once per visit, then
/// `node_frame`, `local_box`, `world_planes` — `anchored.glsl` builds `world_box` from it).
pub trait AnchoredNode<Root> {
    /// The frame the node's fp16 boxes are stored in.
    fn frame(&self, root: &Root) -> Frame;
    /// Slot `s`'s box in that frame, as fp16 (exact or rounded outward).
    fn local_box(&self, s: usize) -> ([f16; 3], [f16; 3]);
    /// Slot `s`'s box decoded to world fp32 ([`decode_plane`]); `f` is the node's frame.
    fn world_box(&self, s: usize, f: &Frame) -> ([f32; 3], [f32; 3]);
}

/// The `Layout` hooks every anchored layout shares, inside its `impl Layout` block, for node
/// type `$node` (implementing [`AnchoredNode`]) and root type `$root`. Its `INFO` takes
/// [`STACK_ENTRY`] and `half::glsl_constants`.
macro_rules! anchored_hooks {
    ($node:ident, $root:ty) => {
        fn ray(r: &RayPre, math: Math, fc: crate::precision::FloatControls) -> Ray16 {
            Ray16::new(r, math, fc)
        }

        fn root_entry(_: &$root, _: &RayPre, _: &Ray16, near: f32) -> f32 {
            near
        }

        fn entry_t(t: &f32) -> f32 {
            *t
        }

        fn visit<const B: usize>(
            n: &$node<B>,
            root: &$root,
            t: &f32,
            r: &RayPre,
            lr: &Ray16,
            best_t: f32,
        ) -> anchored::Visit {
            anchored::visit(&anchored::AnchoredNode::frame(n, root), *t, r, lr, best_t)
        }

        #[inline]
        fn test_child<const B: usize>(
            n: &$node<B>,
            s: usize,
            _: &f32,
            v: &anchored::Visit,
            r: &RayPre,
            lr: &Ray16,
        ) -> Option<(f32, (f32, f32))> {
            if lr.math == Math::F32 {
                let (lo, hi) = anchored::AnchoredNode::world_box(n, s, &v.frame);
                anchored::test_world(lo, hi, v, r)
            } else {
                let (lo, hi) = anchored::AnchoredNode::local_box(n, s);
                anchored::test_local(lo, hi, v, lr)
            }
        }

        fn child_entry<const B: usize>(
            _: &$node<B>,
            _: usize,
            _: &f32,
            v: &anchored::Visit,
            h: &(f32, f32),
            _: &RayPre,
            lr: &Ray16,
            _: &mut Counters,
        ) -> f32 {
            anchored::child_entry(v, *h, lr)
        }
    };
}
pub(crate) use anchored_hooks;

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    /// A true plane v (an fp32 value), a stored value x outward of it on the decoder's grid
    /// (fp16 or 8-bit times a power of two, as the encoders round), and the anchor w: the
    /// decoded plane is never on the inner side of v — including sums that cancel, tiny and
    /// huge values. (A decode whose product is off by 2⁻²⁰ fails it.)
    fn case() -> impl Strategy<Value = (f32, f32, f32, bool)> {
        let w = prop_oneof![
            any::<f32>().prop_filter("finite", |x| x.is_finite() && x.abs() < 1e30),
            -1e4f32..1e4,
            -1.0f32..1.0
        ];
        (w, -16384.0f64..16384.0, -60i32..60, any::<bool>(), prop_oneof![Just(0.0f64), 0.0f64..1.0]).prop_map(
            |(w, local, e, lower, frac)| {
                let k = 2f64.powi(e);
                // the true plane: an fp32 value near w + local / k
                let v = (w as f64 + local / k) as f32;
                // the stored value: the true plane mapped to local units, rounded outward to fp16
                let l = (v as f64 - w as f64) * k;
                let l16 = if lower { crate::fp16::down_f64(l) } else { crate::fp16::up_f64(l) };
                let _ = frac;
                (w, v, l16.to_f32() * (1.0 / k as f32), lower)
            },
        )
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(200_000))]
        #[test]
        fn decoded_planes_stay_outward_of_the_true_planes((w, v, x, lower) in case()) {
            prop_assume!(x.is_finite() && (w as f64 + x as f64).abs() < 3e38);
            let d = decode_plane(w, x);
            if lower {
                prop_assert!(d <= v, "lower plane {v:e} decoded as {d:e} (w {w:e}, x {x:e})");
            } else {
                prop_assert!(d >= v, "upper plane {v:e} decoded as {d:e} (w {w:e}, x {x:e})");
            }
        }
    }

    #[test]
    fn inv_pow2_is_exact() {
        for j in -126..=126 {
            let k = 2f32.powi(j);
            assert_eq!(inv_pow2(k), 1.0 / k, "2^{j}");
        }
    }
}
