//! Uniformly scaled frames, and the chained encoder of `f16h` and `f16h-poster`.
//!
//! A frame maps world points to local units, `x_local = (x_world − W) · K`, with one
//! power-of-two scale for all three axes ("rays don't bend"). Every fp16 layout stores its
//! child boxes in such frames: one for the whole BVH (`f16w`), one per node stored beside it
//! (`f16a`, and `q8`'s grid), or chained ([`encode_chained`]: `f16h`, `f16h-poster`). In a
//! chain only the root frame is stored (fp32); every child box is stored in fp16 in its
//! parent's frame, rounded outward, so it contains the true box. A child's frame is derived
//! from its stored fp16 box alone by [`derive_child`], which the traversal (CPU reference and
//! `glsl/half.glsl`) runs identically:
//!
//! ```text
//! c   = (lo + hi) · 0.5 in fp16 arithmetic          centre, per axis, in the parent frame
//! h   = max over axes of max(hi − c, c − lo)      half extent (fp32)
//! W_i = W_n + c / K_n                              fp32, one rounding per axis
//! m   = h + h·2⁻²⁰ + max|W_i|·K_n·2⁻²²             covers fp32 rounding of h and of W_i
//! r   = 2^(14 − e) where m = f·2^e, f ∈ [0.5, 1)  so m·r < 16384
//! K_i = K_n · r                                     (r capped so K stays in [2⁻⁶⁰, 2⁶⁰])
//! ```
//!
//! Consequently every coordinate a node stores lies in [−16384, 16384], a quarter of fp16's
//! finite range, leaving room for the slab test's differences and products.

use super::node16::Node16;
use super::{encode_child, EncodeError};
use crate::base::Aabb;
use crate::bvh::{ChildRef, WideBvh};
use crate::fp16;
use crate::interface::{glsl_int, CHILD_EMPTY};
use half::f16;

/// 2⁻²⁰ and 2⁻²²: the relative error terms of a derived frame's bound (and of the box tests in
/// [`super::half`], which uses them too).
pub const TWO_M20: f32 = 1.0 / 1_048_576.0;
pub const TWO_M22: f32 = 1.0 / 4_194_304.0;

/// Largest magnitude of any stored coordinate.
pub const COORD_LIMIT: f32 = 16384.0;
/// Bounds on the frame scale K.
pub const K_MIN_LOG2: i32 = -60;
pub const K_MAX_LOG2: i32 = 60;

/// A frame: `x_local = (x_world − w) · k`, `k` a power of two. A chain's root frame (or
/// `f16w`'s one frame) is the layout's `Root`, in the push constants' `root` = w.xyz, k.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Frame {
    pub w: [f32; 3],
    pub k: f32,
}

/// A child's frame as derived from its stored box: centre `c` (parent frame, fp16), scale
/// ratio `r` (power of two), and the resulting world frame.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ChildFrame {
    pub c: [f16; 3],
    pub r: f32,
    pub frame: Frame,
}

/// Binary exponent e of x = f·2^e with f ∈ [0.5, 1) (x > 0, normal); −126 for 0 and subnormals.
#[inline]
pub fn frexp_exp(x: f32) -> i32 {
    let e = ((x.to_bits() >> 23) & 0xff) as i32;
    if e == 0 {
        -126
    } else {
        e - 126
    }
}

#[inline]
fn pow2(e: i32) -> f32 {
    f32::from_bits(((e + 127) as u32) << 23)
}

/// Scale exponent for a half extent `m` under a parent scale exponent `parent_log2`
/// (0 for the root): the largest power of two keeping m·r < 16384, clamped so K stays bounded.
#[inline]
fn ratio_log2(m: f32, parent_log2: i32) -> i32 {
    let j = 14 - frexp_exp(m);
    j.clamp(K_MIN_LOG2 - parent_log2, K_MAX_LOG2 - parent_log2)
}

/// Derives a child's frame from its stored fp16 box in the parent frame. Runs identically in
/// the encoder, the CPU reference and the shader (fp32 round-to-nearest, no fused ops).
#[inline]
pub fn derive_child(parent: &Frame, lo: [f16; 3], hi: [f16; 3]) -> ChildFrame {
    let mut c = [f16::ZERO; 3];
    let mut h = 0f32;
    let inv_k = 1.0 / parent.k;
    let mut w = [0f32; 3];
    let mut wmax = 0f32;
    for a in 0..3 {
        let (l, u) = (lo[a].to_f32(), hi[a].to_f32());
        // In fp16 arithmetic: shader compilers may fold an f32→f16→f32 round trip away.
        c[a] = (lo[a] + hi[a]) * f16::from_f32_const(0.5);
        let cf = c[a].to_f32();
        h = h.max(u - cf).max(cf - l);
        w[a] = parent.w[a] + cf * inv_k;
        wmax = wmax.max(w[a].abs());
    }
    let m = h + h * TWO_M20 + wmax * parent.k * TWO_M22;
    let j = ratio_log2(m, frexp_exp(parent.k) - 1);
    let r = pow2(j);
    ChildFrame { c, r, frame: Frame { w, k: parent.k * r } }
}

/// The frame fitting a box: centred on it, its largest half extent below 16384 local units
/// (the root of a chain, `f16w`'s one frame, `f16a`'s per node).
pub fn fit_frame(b: &Aabb) -> Frame {
    let w = b.center();
    let mut m = 0f64;
    for a in 0..3 {
        m = m.max(b.max[a] as f64 - w[a] as f64).max(w[a] as f64 - b.min[a] as f64);
    }
    let m = (m * (1.0 + 1e-6)) as f32;
    Frame { w: w.into(), k: pow2(ratio_log2(m, 0)) }
}

/// Maps a world box into a frame and rounds it outward to fp16 (exact: fp32 inputs, f64
/// arithmetic with power-of-two k). Also returns the exact local coordinates (lo xyz, hi xyz).
pub fn to_local(f: &Frame, b: &Aabb) -> ([f16; 3], [f16; 3], [f64; 6]) {
    let mut lo = [f16::ZERO; 3];
    let mut hi = [f16::ZERO; 3];
    let mut exact = [0f64; 6];
    for a in 0..3 {
        let l = (b.min[a] as f64 - f.w[a] as f64) * f.k as f64;
        let u = (b.max[a] as f64 - f.w[a] as f64) * f.k as f64;
        exact[a] = l;
        exact[3 + a] = u;
        lo[a] = fp16::down_f64(l);
        hi[a] = fp16::up_f64(u);
    }
    (lo, hi, exact)
}

/// Child box `b` (of slot `slot` of node `node`) in frame `f` as stored: rounded outward to
/// fp16, every coordinate within ±[`COORD_LIMIT`] (else an error naming the layout, node and
/// child).
pub fn stored_box(
    layout: &'static str,
    node: usize,
    slot: usize,
    f: &Frame,
    b: &Aabb,
) -> Result<([f16; 3], [f16; 3]), EncodeError> {
    let (lo, hi, exact) = to_local(f, b);
    for (k, v) in lo.iter().chain(&hi).enumerate() {
        #[allow(clippy::neg_cmp_op_on_partial_ord)] // NaN is out of range too
        if !(v.to_f32().abs() <= COORD_LIMIT) {
            let msg = format!(
                "child {slot}: coordinate {:e} lies outside [-16384, 16384] in its frame (frame scales stop at 2^-60, so boxes wider than about 1.9e22 do not fit this layout)",
                exact[k]
            );
            return Err(EncodeError { layout, node, msg });
        }
    }
    Ok((lo, hi))
}

/// The constants `glsl/half.glsl`'s frame code shares with this module.
pub fn glsl_constants() -> String {
    glsl_int("K_MIN_LOG2", K_MIN_LOG2) + &glsl_int("K_MAX_LOG2", K_MAX_LOG2)
}

/// Encodes a wide BVH in chained frames (`layout` names it in errors); returns the nodes (root
/// at 0), the root frame and, for tests and statistics, the frame of every node.
pub fn encode_chained<const B: usize>(
    layout: &'static str,
    w: &WideBvh,
) -> Result<(Vec<Node16<B>>, Frame, Vec<Frame>), EncodeError> {
    let root = fit_frame(&w.nodes[0].bounds);
    let mut frames: Vec<Option<Frame>> = vec![None; w.nodes.len()];
    frames[0] = Some(root);
    let mut out = Vec::with_capacity(w.nodes.len());
    for (i, n) in w.nodes.iter().enumerate() {
        // Children always follow their parent, so the frame is known by now.
        let f = frames[i].expect("wide BVH nodes are in depth-first order");
        let mut node = Node16 { lo: [[f16::ZERO; B]; 3], hi: [[f16::ZERO; B]; 3], child: [CHILD_EMPTY; B] };
        for (slot, (b, c)) in n.children.iter().enumerate() {
            let (lo, hi) = stored_box(layout, i, slot, &f, b)?;
            for a in 0..3 {
                node.lo[a][slot] = lo[a];
                node.hi[a][slot] = hi[a];
            }
            node.child[slot] = encode_child(c);
            if let ChildRef::Inner(j) = c {
                frames[*j as usize] = Some(derive_child(&f, lo, hi).frame);
            }
        }
        out.push(node);
    }
    Ok((out, root, frames.into_iter().map(|f| f.expect("every node is reached")).collect()))
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(20000))]

        /// Encoder and frame derivation: a random box inside a random parent frame is stored
        /// conservatively, and its own children map into [-16384, 16384] in the derived frame.
        #[test]
        fn derived_frames_keep_children_in_range(
            w in prop::array::uniform3(-1.0e4f32..1.0e4),
            k_log2 in -20i32..20,
            c in prop::array::uniform3(-16000.0f64..16000.0),
            half in prop::array::uniform3(prop_oneof![0.0f64..1e-3, 0.0f64..1.0, 0.0f64..300.0]),
            inner in prop::array::uniform3(0.0f64..1.0),
        ) {
            let parent = Frame { w, k: 2f32.powi(k_log2) };
            // A world box whose local image is centred at c with the given half extents.
            let to_world = |l: f64, a: usize| (l / parent.k as f64 + w[a] as f64) as f32;
            let mut b = crate::base::Aabb::EMPTY;
            for corner in 0..8 {
                let p: [f32; 3] = [0, 1, 2].map(|a| {
                    let h = half[a].min(16384.0 - c[a].abs());
                    to_world(if corner >> a & 1 == 1 { c[a] + h } else { c[a] - h }, a)
                });
                b.grow(glam::Vec3::from(p));
            }
            let (lo, hi, exact) = super::to_local(&parent, &b);
            prop_assume!(exact.iter().all(|v| v.abs() <= 16384.0));
            for a in 0..3 {
                prop_assert!(lo[a].to_f64() <= exact[a] && hi[a].to_f64() >= exact[3 + a]);
            }
            let cf = super::derive_child(&parent, lo, hi);
            // A grandchild anywhere inside the true child box maps within range.
            let g: [f32; 3] = [0, 1, 2].map(|a| b.min[a] + (b.max[a] - b.min[a]) * inner[a] as f32);
            for a in 0..3 {
                for v in [b.min[a], b.max[a], g[a]] {
                    let l = (v as f64 - cf.frame.w[a] as f64) * cf.frame.k as f64;
                    prop_assert!(l.abs() < 16384.0, "axis {} value {} maps to {}", a, v, l);
                }
            }
        }
    }
}
