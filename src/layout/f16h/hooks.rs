//! The f16h traversal hooks: the chained frames' stack entry and the origin move, in IEEE
//! half arithmetic (`half::f16`, one rounding per operation) or in the other math modes,
//! conservative, so the traversal returns exactly the fp32 closest hit. The box test itself
//! and its bound are shared ([`crate::layout::half`]). `glsl/layout/f16h.glsl` does the same
//! operations in the same order.
//!
//! # State per stack entry (the poster's "extra stack")
//! Besides the node index (which the skeleton keeps): the node's frame (W, K) in fp32; the ray
//! origin O in the node's frame (fp16, or fp32 in the fp32 math mode); `e`, a bound on the
//! origin's error; `tp`, the world parameter of the point P that O stands for; `tlo`, a lower
//! bound on the world parameter of any point of the ray that can still matter in this node.
//!
//! # The invariant
//! With d* = D / max|D| (exact) and L the node frame's map:
//! (I1) ‖O − L(P)‖∞ ≤ e, where P = O_world + tp·D exactly;
//! (I2) every point X of the ray inside the node's true box with t_X ∈ [tmin, t_closest] has
//!      t_X ≥ tlo.
//! Under it the widened box test of [`crate::layout::half`] never rejects a child the ray
//! reaches; each hook below keeps it for the child's entry.
//!
//! # Origin move
//! For a hit inner child the new origin is E = O + s_e·d16 with s_e = max(tn, s_lower), then
//! O' = (E − c)·r in the child frame (fp16, r exact). Its error bound e' = r·(e + |s_e|·2⁻¹⁰ +
//! 2⁻¹¹·(|E| + |E − c|) + ε) plus the fp32 rounding of W' and tp'. The bound compounds: each
//! level multiplies by r while P's true position is fixed, so in world units it converges to
//! ≈ the root frame's fp16 grid (root extent / 2048). When e' would exceed `EMAX` (or O'
//! leaves ±`OCAP`, or r > [`R_MAX`]), the origin is re-anchored: recomputed in fp32 from the
//! world ray at the child's fp32 entry distance (`Counters::reanchors`). Keeping this rare is
//! what makes fp16 origin moves usable; the counter reports how rare.
//!
//! # Without float controls (`Ray16::off`, kernels built with `FC_OFF`)
//! Besides the box test's margins (`half`):
//! - Frames must be the encoder's bit for bit: their fp32 additions use `fp16::add_rte_emulated`
//!   (the kernels' `add_rte`) and every product is by a power of two (exact); s_e is converted
//!   to fp16 with the emulated rounding.
//! - An origin move whose fp16 values could overflow (|O| + |s_e| + |c| > [`MOVE_LIMIT`], or
//!   |E − c|·r > OCAP) re-anchors instead.
//! - Origin-move bound: |s_e|·2⁻⁹ (conversion 2⁻¹¹ + product 2⁻¹⁰), 2⁻¹⁰·(|E| + |E − c|) for
//!   the addition and subtraction, 2⁻²² absolute; the world parameter's division (2.5 ulp) and
//!   addition: 2⁻²⁰·(|tp| + |step|); tlo's margin 2⁻¹⁹.

use crate::base::{slab32, Counters, RayPre};
use crate::interface::glsl_float;
use crate::layout::frames::{derive_child, Frame};
use crate::layout::half::*;
use crate::layout::node16::Node16;
use crate::precision::Math;
use half::f16;

/// Largest |O| + |s_e| + |c| of an fp16 origin move without float controls (below fp16's
/// 65504, so nothing overflows); larger moves re-anchor.
pub const MOVE_LIMIT: f32 = 60000.0;
/// Largest frame-scale ratio r an origin is moved across; a larger one re-anchors.
pub const R_MAX: f32 = 32768.0;

/// The constants `glsl/layout/f16h.glsl` shares with this module, besides `half`'s.
pub fn glsl_constants() -> String {
    glsl_float("MOVE_LIMIT", MOVE_LIMIT) + &glsl_float("R_MAX", R_MAX)
}

/// One stack entry besides the node index (see the module docs). The origin is held in fp32;
/// in the fp16 modes its values are fp16 numbers (exactly representable).
#[derive(Clone, Copy, Debug)]
pub struct Entry {
    pub frame: Frame,
    pub o: [f32; 3],
    pub e: f32,
    pub tp: f32,
    pub tlo: f32,
}

/// The root entry of a ray entering the root box at `near`.
pub fn root_entry(root: &Frame, r: &RayPre, r16: &Ray16, near: f32) -> Entry {
    let (o, e) = anchor(r, root, near, r16.math, r16.off);
    Entry { frame: *root, o, e, tp: near, tlo: near }
}

/// The visit of a node: the box-test bounds of its entry's origin.
pub fn visit(en: &Entry, r16: &Ray16, best_t: f32) -> HVisit {
    half_visit(en.frame.k, en.e, en.tp, en.tlo, r16, best_t)
}

/// The box test of one child: `Some((tn, (tn, tn_lb)))` when the ray may touch it.
#[inline]
pub fn test_child<const B: usize>(
    n: &Node16<B>,
    s: usize,
    en: &Entry,
    v: &HVisit,
    r16: &Ray16,
) -> Option<(f32, (f32, f32))> {
    let (lo, hi) = n.slot_box(s);
    half_test(&en.o, lo, hi, v, r16).map(|(tn, tn_lb)| (tn, (tn, tn_lb)))
}

/// The stack entry of a hit inner child: its frame, and the origin moved into it in fp16
/// (or re-anchored from the fp32 world ray when the bound grows too large).
#[allow(clippy::too_many_arguments)]
pub fn child_entry<const B: usize>(
    n: &Node16<B>,
    s: usize,
    en: &Entry,
    v: &HVisit,
    (tn, tn_lb): (f32, f32),
    r: &RayPre,
    r16: &Ray16,
    c: &mut Counters,
) -> Entry {
    let (lo, hi) = n.slot_box(s);
    let (mk, math) = (v.mk, r16.math);
    let cf = derive_child(&en.frame, lo, hi);
    let lower = v.lower.to_f32();
    let off = r16.off;
    let tlo = half_child_tlo(v, en.tp, en.tlo, tn_lb, off);
    let se = tn.max(lower);
    // Without float controls the fp16 origin move must not overflow (module docs).
    let fits = !off || math == Math::F32 || {
        let om = en.o.iter().fold(0f32, |m, x| m.max(x.abs()));
        let cm = cf.c.iter().fold(0f32, |m, x| m.max(x.to_f32().abs()));
        om + se.abs() + cm <= MOVE_LIMIT
    };
    if v.precise && cf.r <= R_MAX && fits {
        let mut o2 = [0f32; 3];
        let (mut emag, mut ecmag, mut omag) = (0f32, 0f32, 0f32);
        let mut finite = true;
        for a in 0..3 {
            let (ea, ec, oa) = if math == Math::F32 {
                let ea = en.o[a] + se * r16.d[a].to_f32();
                let ec = ea - cf.c[a].to_f32();
                (ea, ec, ec * cf.r)
            } else {
                let s_e = f16::from_f32(se);
                let ea = f16::from_f32(en.o[a]) + s_e * r16.d[a];
                let ec = ea - cf.c[a];
                if off && ec.to_f32().abs() * cf.r > OCAP {
                    // Would leave ±OCAP (or overflow): re-anchor, as the check below would.
                    finite = false;
                    (ea.to_f32(), ec.to_f32(), 0.0)
                } else {
                    (ea.to_f32(), ec.to_f32(), (ec * f16::from_f32(cf.r)).to_f32())
                }
            };
            o2[a] = oa;
            emag = emag.max(ea.abs());
            ecmag = ecmag.max(ec.abs());
            omag = omag.max(oa.abs());
            finite &= oa.is_finite();
        }
        let step = se / mk;
        let tp = en.tp + step;
        let wmax = cf.frame.w.iter().fold(0f32, |m, x| m.max(x.abs()));
        let mk2 = r16.m * cf.frame.k;
        let e2 = if off {
            (cf.r * (en.e + se.abs() * TWO_M9 + TWO_M10 * (emag + ecmag) + TWO_M22)
                + wmax * TWO_M24 * cf.frame.k
                + (en.tp.abs() + step.abs()) * TWO_M20 * mk2)
                * (1.0 + TWO_M18)
        } else {
            (cf.r * (en.e + se.abs() * TWO_M10 + TWO_M11 * (emag + ecmag) + TWO_M23)
                + wmax * TWO_M24 * cf.frame.k
                + (en.tp.abs() + step.abs()) * TWO_M22 * mk2)
                * (1.0 + TWO_M18)
        };
        if finite && omag <= OCAP && e2 <= EMAX {
            return Entry { frame: cf.frame, o: o2, e: e2, tp, tlo };
        }
    }
    c.reanchors += 1;
    let inv_k = 1.0 / en.frame.k;
    let mut blo = [0f32; 3];
    let mut bhi = [0f32; 3];
    for a in 0..3 {
        blo[a] = en.frame.w[a] + lo[a].to_f32() * inv_k;
        bhi[a] = en.frame.w[a] + hi[a].to_f32() * inv_k;
    }
    let (tin, tout) = slab32(r, blo, bhi, f32::NEG_INFINITY, f32::INFINITY);
    let tp = tin.min(tout).max(tlo);
    let (o, e) = anchor(r, &cf.frame, tp, math, off);
    Entry { frame: cf.frame, o, e, tp, tlo }
}
