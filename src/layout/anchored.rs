//! Hooks shared by the layouts whose child boxes are tested in a per-node (or per-BVH) frame
//! against the ray origin re-derived from the fp32 world ray at every node — `f16w`, `f16a`,
//! `q8` — with `glsl/anchored.glsl` doing the same operations in the same order. A layout
//! supplies its node frame, the child's box in that frame as fp16 (exact or rounded outward),
//! and the child's box decoded to world fp32 (rounded outward, [`add_down`] / [`add_up`]).
//!
//! # fp32 math (`Math::F32`)
//! The stored box is decoded to world fp32 and rounded outward; the robust fp32 slab test of
//! the `f32` layout follows. The decoded box contains the stored box (see [`add_down`]), which
//! contains the true box, and the slab test is conservative (`trace::slab32`), so no ray that
//! reaches the true box within its interval is rejected. Stack entries carry the child's
//! entry distance, as in `f32`.
//!
//! # fp16 math (`Math::F16`)
//! At each visited node the origin is placed at the node's entry bound `t` (the stack entry)
//! in the node's frame, computed in fp32 from the world ray and rounded to fp16, with the
//! error bound of `f16h`'s anchor (`hooks::anchor`: fp32 rounding of the point and the frame
//! map, clamping to ±OCAP, the fp16 rounding). The node's boxes span at most ±16384 in its
//! frame, so `f16h`'s box-test argument applies unchanged (`hooks` module docs: the widening
//! w = e·(1 + 2⁻¹¹) + 44 and the (1 ∓ 2⁻⁸) factors, property-tested there on adversarial
//! boxes and rays); with tp = tlo = t the lower cull keeps exactly the part of the ray from t
//! on, which holds everything that can still matter (t is a lower bound of the node's entry).
//! A hit child's entry bound is its tn_lb mapped back to world units and rounded down
//! (`hooks::child_tlo`). No origin is carried from node to node, so the bound never compounds
//! and nothing is ever re-anchored; the stack entry is one fp32 value.

use super::f16h::hooks::{self, Ray16};
use super::f16h::Frame;
use super::Math;
use crate::trace::{slab32, RayPre};
use half::f16;

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
    pub h: hooks::Visit,
}

const NO_HALF_VISIT: hooks::Visit = hooks::Visit { mk: 0.0, s_lim: f16::ZERO, lower: f16::ZERO, precise: true, w: f16::ZERO };

/// 1/k for a power of two k, exactly, from the exponent bits (`inv_pow2` in the kernels).
#[inline]
pub fn inv_pow2(k: f32) -> f32 {
    f32::from_bits((254 - (k.to_bits() >> 23)) << 23)
}

const TWO_M22: f32 = 1.0 / 4_194_304.0;

/// A lower bound of the real w + x. The fp32 sum s is at most |s|·2⁻²⁴ off (exact when
/// subnormal); subtracting d = fl(|s|·2⁻²² + 2⁻¹²⁶) ≥ |s|·2⁻²²·(1 − 2⁻²⁴) and rounding once more
/// (at most (|s| + d)·2⁻²⁴) still lands below w + x, since d·(1 − 2⁻²⁴) > 2·|s|·2⁻²⁴; the 2⁻¹²⁶
/// keeps a zero sum strict.
#[inline]
pub fn add_down(w: f32, x: f32) -> f32 {
    let s = w + x;
    s - (s.abs() * TWO_M22 + f32::MIN_POSITIVE)
}

/// An upper bound of the real w + x (see [`add_down`]).
#[inline]
pub fn add_up(w: f32, x: f32) -> f32 {
    let s = w + x;
    s + (s.abs() * TWO_M22 + f32::MIN_POSITIVE)
}

/// The visit of a node with frame `frame` by a ray whose entry bound there is `t`.
#[inline]
pub fn visit(frame: &Frame, t: f32, r: &RayPre, r16: &Ray16, best_t: f32) -> Visit {
    if r16.math == Math::F32 {
        return Visit { tmax: best_t, t, frame: *frame, o: [0.0; 3], h: NO_HALF_VISIT };
    }
    let (o, e) = hooks::anchor(r, frame, t, Math::F16, false);
    Visit { tmax: best_t, t, frame: *frame, o, h: hooks::visit_parts(frame.k, e, t, t, r16, best_t) }
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
    hooks::test_box(&v.o, lo, hi, &v.h, r16).map(|(tn, tn_lb)| (tn, (tn, tn_lb)))
}

/// The stack entry (entry bound) of a hit inner child.
#[inline]
pub fn child_entry(v: &Visit, (tn, tn_lb): (f32, f32), r16: &Ray16) -> f32 {
    if r16.math == Math::F32 {
        tn
    } else {
        hooks::child_tlo(&v.h, v.t, v.t, tn_lb, false)
    }
}

/// The stack entry fields of these layouts.
pub const STACK_ENTRY: &[(&str, &str)] = &[("t", "float")];

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    /// Operands as the decoders produce them: an fp32 anchor and an fp16 (or 8-bit) value times
    /// a power of two, including values that cancel, tiny and huge ones.
    fn operand() -> impl Strategy<Value = (f32, f32)> {
        let w = prop_oneof![any::<f32>().prop_filter("finite", |x| x.is_finite() && x.abs() < 1e30), -1e4f32..1e4, -1.0f32..1.0];
        let frac = prop_oneof![-16384.0f32..16384.0, 0.0f32..256.0, Just(0.0f32)];
        (w, frac, -60i32..60).prop_map(|(w, f, e)| {
            let x = f16::from_f32(f).to_f32() * 2f32.powi(e);
            // sometimes make the sum cancel almost exactly
            if e == 0 { (w, -w + x * 1e-3) } else { (w, x) }
        })
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(200_000))]
        /// The outward decode holds for every operand pair (exactly, in f64); a plain fp32 sum
        /// (or a move of |s|·2⁻²⁴ only) fails it.
        #[test]
        fn outward_decode_contains_the_exact_sum((w, x) in operand()) {
            let exact = w as f64 + x as f64;
            prop_assume!(exact.abs() < 3e38);
            prop_assert!((add_down(w, x) as f64) <= exact, "add_down({w:e}, {x:e}) = {:e} > {exact:e}", add_down(w, x));
            prop_assert!((add_up(w, x) as f64) >= exact, "add_up({w:e}, {x:e}) = {:e} < {exact:e}", add_up(w, x));
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
