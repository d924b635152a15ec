//! fp16 box tests against a ray origin that carries an error bound, shared by every layout
//! that stores child boxes as fp16 in a uniformly scaled node frame ([`super::frames`]) —
//! `f16h`, `f16w`, `f16a`, `q8` — and by the poster's `f16h-poster` (its fp16 types, direction
//! and frames, without the bound). The box
//! tests run in IEEE half arithmetic (`half::f16`, one rounding per operation) or in the other
//! math modes, conservative, so a traversal returns exactly the fp32 closest hit.
//! `glsl/half.glsl` does the same operations in the same order; every constant below reaches
//! it through [`glsl_constants`].
//!
//! # The bound relied on
//! A ray origin O in a node's frame stands for the world point P = O_world + tp·D, within e:
//! ‖O − L(P)‖∞ ≤ e, with L the frame's map and d* = D / max|D| (exact). Write a point X of the
//! ray as X = L(P) + s·d* (local units, s = (t_X − tp)·M·K). Since X lies in the node's box
//! (|X| ≤ 16384) and |O| ≤ `OCAP`, |s| ≤ S = 16384 + OCAP + e. The approximate line
//! A(s) = O + s·d16 then satisfies ‖A(s) − X‖∞ ≤ e + S·(2⁻¹² + 2⁻²⁴) (direction rounding).
//! So a child whose true box contains X has A(s) inside its stored box widened by
//! w_req = e + (36864 + e)·(2⁻¹² + 2⁻²⁴). The test widens by w = e·(1 + 2⁻¹¹) + 44 ≥ w_req + 32:
//! the 32 absorb the two fp16 subtractions (lo − O) − w, whose half-ulp errors are ≤ 16 each
//! below 65536 (larger results overflow outward, to ±inf). The products with 1/d16 then carry
//! relative error ≤ 2⁻¹⁰ (rounding of 1/d16 and of the product), which the factors
//! (1 ∓ 2⁻⁸) on the entry/exit cover with room for their own rounding. Hence the computed
//! interval [tn_lb, tf_ub] contains every such s: no false misses.
//! Culling uses s ≤ (t_closest − tp)·M·K (rounded up) and s ≥ −(tp − tlo)·M·K (rounded down),
//! where every point that can still matter has t ≥ tlo.
//!
//! # Without float controls (`Ray16::off`, kernels built with `FC_OFF`)
//! A device without RoundingModeRTE / SignedZeroInfNanPreserve may round each fp16 and fp32
//! operation either way (faithfully: to one of the two neighbours of the exact result, an error
//! up to one ulp instead of half) and may assume no operand is inf or NaN. That build keeps the
//! same nodes and frames and widens every bound by the extra half ulp of every rounding:
//! - Conversions to fp16 are emulated exactly (`fp16::rte16_emulated`, the kernels' `rte16`), so
//!   d16, the anchored origin and the widths are the same values as here; reciprocals come
//!   from an fp32 division (2.5 ulp in Vulkan) rounded to fp16: ≤ 2⁻¹¹ + 2⁻²¹ relative.
//! - Box test: the two fp16 subtractions may each be off by a full ulp (≤ 32 below 65536), so the
//!   widening is e·(1 + 2⁻¹¹) + `W_MARGIN_OFF` (9 direction + 64 + spare). The products
//!   (≤ 2⁻¹⁰ + the reciprocal's 2⁻¹¹ + 2⁻²¹) and the (1 ∓ 2⁻⁸) factors' own rounding (≤ 2⁻¹⁰)
//!   still leave (1 + 1.6·2⁻¹⁰)(1 − 2⁻⁸)(1 + 2⁻¹⁰) < 1: the factors cover them.
//! - No inf: a product is computed in fp32 first (exact: 11 × 11 significant bits); beyond
//!   ±`SAT` it is saturated to ±SAT, which decides exactly as ±inf would, since every relevant
//!   |s| ≤ s_max ≤ 16384 + OCAP + EBIG + 1 = 53249 < SAT·(1 − 2⁻⁸)(1 − 2⁻¹⁰). Unconstrained
//!   intervals start at ±SAT (±`BIG32` in fp32 math).
//! - The anchor's fp32 point: 2⁻²¹·mag·k; a child's entry bound: 2⁻¹⁹.
//!
//! The CPU reference of this build takes the same decisions with IEEE rounding, so on a device
//! that does round to nearest (lavapipe) GPU and CPU agree bit for bit, and elsewhere the hits
//! still equal f32's while counters may differ on rays where an ulp moved a box test.

use super::frames::Frame;
use crate::base::{upper32, RayPre};
use crate::fp16::{down_f32, up_f32};
use crate::interface::glsl_float;
use crate::precision::{FloatControls, Math};
use half::f16;

/// Largest |origin coordinate| kept in a frame (node boxes span ±16384).
pub const OCAP: f32 = 20480.0;
/// Largest origin error (local units) an fp16 origin move may leave; beyond it, re-anchor.
pub const EMAX: f32 = 2048.0;
/// Above this origin error the box tests are skipped: every child counts as hit.
pub const EBIG: f32 = 16384.0;
/// Absolute part of the box widening: drift 9 + two half-ulp subtractions 32 + spare.
pub const W_MARGIN: f32 = 44.0;
/// The same without float controls: drift 9 + two full-ulp subtractions 64 + spare.
pub const W_MARGIN_OFF: f32 = 80.0;
/// Saturation of fp16 box-test values without float controls (see the module docs).
pub const SAT: f32 = 60000.0;
/// "Unbounded" in fp32 box tests without float controls.
pub const BIG32: f32 = 1e30;
/// Geometric bound on |s| without the error term: 16384 + OCAP.
pub const S_BASE: f32 = 16384.0 + OCAP;

/// 2⁻²⁰ and 2⁻²² are the frames' (the frame derivation bounds its error with them).
pub use super::frames::{TWO_M20, TWO_M22};
pub const TWO_M9: f32 = 1.0 / 512.0;
pub const TWO_M11: f32 = 1.0 / 2048.0;
pub const TWO_M19: f32 = 1.0 / 524_288.0;
pub const TWO_M10: f32 = 1.0 / 1024.0;
pub const TWO_M18: f32 = 1.0 / 262_144.0;
pub const TWO_M21: f32 = 1.0 / 2_097_152.0;
pub const TWO_M23: f32 = 1.0 / 8_388_608.0;
pub const TWO_M24: f32 = 1.0 / 16_777_216.0;

/// Per-ray fp16 constants: d16 = fp16(D / max|D|), with components below 2⁻¹⁵ in magnitude
/// flushed to +0 (an error ≤ 2⁻¹⁵, inside the 2⁻¹² direction budget), and idir = fp16(1 / d16),
/// finite (|idir| ≤ 32768) for every non-zero component, computed by fp16 division; and the
/// math mode.
#[derive(Clone, Copy, Debug)]
pub struct Ray16 {
    pub m: f32,
    pub d: [f16; 3],
    pub idir: [f16; 3],
    /// 1 / d16 in fp32 (the fp32 math mode's reciprocal).
    pub idir32: [f32; 3],
    pub math: Math,
    /// The build without float controls (module docs).
    pub off: bool,
}

/// Direction components (after normalising the largest to ±1) below this are treated as 0.
pub const D_FLUSH: f32 = 1.0 / 32768.0;

impl Ray16 {
    pub fn new(r: &RayPre, math: Math, fc: FloatControls) -> Ray16 {
        let off = fc == FloatControls::Off;
        let m = r.d.abs().max_element();
        let mut d = [f16::ZERO; 3];
        let mut idir = [f16::ZERO; 3];
        let mut idir32 = [0f32; 3];
        for a in 0..3 {
            let x = r.d[a] / m;
            d[a] = if x.abs() < D_FLUSH { f16::ZERO } else { f16::from_f32(x) };
            // fp16 division (correctly rounded), not an f32 round trip a compiler may fold.
            // (Without float controls: an fp32 reciprocal rounded to fp16 — the same value
            // here, as f32 carries enough bits for the double rounding to be exact.)
            let zero = d[a] == f16::ZERO;
            idir[a] = match (zero, off) {
                (true, false) => f16::INFINITY,
                (true, true) => f16::ZERO,
                (false, false) => f16::ONE / d[a],
                (false, true) => f16::from_f32(1.0 / d[a].to_f32()),
            };
            idir32[a] = match (zero, off) {
                (true, false) => f32::INFINITY,
                (true, true) => 0.0,
                (false, _) => 1.0 / d[a].to_f32(),
            };
        }
        Ray16 { m, d, idir, idir32, math, off }
    }
}

/// Places the origin at world parameter `t` in frame `f`, computed in fp32 and rounded to
/// fp16, clamped to ±OCAP; returns it with its error bound (fp32 rounding of the point and the
/// frame map, the clamp distance, the fp16 rounding).
pub fn anchor(r: &RayPre, f: &Frame, t: f32, math: Math, off: bool) -> ([f32; 3], f32) {
    let mut o = [0f32; 3];
    let mut mag = 0f32;
    let mut clampd = 0f32;
    let mut lmax = 0f32;
    for a in 0..3 {
        let td = t * r.d[a];
        let x = r.o[a] + td;
        let l = (x - f.w[a]) * f.k;
        mag = mag.max(r.o[a].abs() + td.abs() + x.abs() + f.w[a].abs());
        let lc = l.clamp(-OCAP, OCAP);
        clampd = clampd.max((l - lc).abs());
        lmax = lmax.max(lc.abs());
        // fp32 math keeps the fp32 origin; the bound below covers the fp16 rounding anyway.
        o[a] = if math == Math::F32 { lc } else { f16::from_f32(lc).to_f32() };
    }
    let fp32_err = if off { TWO_M21 } else { TWO_M23 };
    let e = (mag * f.k * fp32_err + clampd + lmax * TWO_M11 + TWO_M24) * (1.0 + TWO_M18);
    (o, e)
}

/// The fp16 slab test of one child box: returns (tn, tn_lb, tf_ub) in the node's local
/// parameter s. An axis with d16 = 0 constrains nothing when O lies in the widened slab and
/// rejects the box otherwise; no NaN is ever formed. Without float controls (`r16.off`),
/// unbounded is ±SAT and products saturate there ([`mul_sat`]).
#[inline]
pub fn slab16(o: &[f16; 3], r16: &Ray16, w: f16, lo: [f16; 3], hi: [f16; 3]) -> (f16, f16, f16) {
    let unb = if r16.off { f16::from_f32_const(SAT) } else { f16::INFINITY };
    let mul = |a: f16, b: f16| if r16.off { mul_sat(a, b) } else { a * b };
    let mut tn = -unb;
    let mut tf = unb;
    for a in 0..3 {
        let la = (lo[a] - o[a]) - w;
        let ha = (hi[a] - o[a]) + w;
        let (t0, t1) = if r16.d[a] == f16::ZERO {
            if la <= f16::ZERO && ha >= f16::ZERO {
                (-unb, unb)
            } else {
                (unb, -unb)
            }
        } else {
            let x = mul(la, r16.idir[a]);
            let y = mul(ha, r16.idir[a]);
            (x.min(y), x.max(y))
        };
        tn = tn.max(t0);
        tf = tf.min(t1);
    }
    const LO_DOWN: f16 = f16::from_f32_const(1.0 - 1.0 / 256.0);
    const LO_UP: f16 = f16::from_f32_const(1.0 + 1.0 / 256.0);
    let tn_lb = tn * if tn > f16::ZERO { LO_DOWN } else { LO_UP };
    let tf_ub = tf * if tf > f16::ZERO { LO_UP } else { LO_DOWN };
    (tn, tn_lb, tf_ub)
}

/// fp16 product saturated to ±SAT (the build without float controls; module docs): decided
/// on the exact fp32 product, so no fp16 operation overflows.
#[inline]
fn mul_sat(a: f16, b: f16) -> f16 {
    let p = a.to_f32() * b.to_f32();
    if p > SAT {
        f16::from_f32_const(SAT)
    } else if p < -SAT {
        f16::from_f32_const(-SAT)
    } else {
        a * b
    }
}

/// The box test of one child in the ray's math mode, as fp32 values (exact conversions of the
/// fp16 results in the fp16 mode, so comparisons are unchanged): (tn, tn_lb, tf_ub).
#[inline]
pub fn slab(o: &[f32; 3], r16: &Ray16, w: f16, lo: [f16; 3], hi: [f16; 3]) -> (f32, f32, f32) {
    let math = r16.math;
    // Unbounded: ±inf, or without float controls ±SAT (fp16 products) / ±BIG32 (fp32).
    let unb = match (r16.off, math) {
        (false, _) => f32::INFINITY,
        (true, Math::Mixed) => SAT,
        (true, _) => BIG32,
    };
    match math {
        Math::F16 => {
            let (a, b, c) = slab16(&o.map(f16::from_f32), r16, w, lo, hi);
            (a.to_f32(), b.to_f32(), c.to_f32())
        }
        Math::Mixed | Math::F32 => {
            let mut tn = -unb;
            let mut tf = unb;
            let w32 = w.to_f32();
            for a in 0..3 {
                let (t0, t1) = if math == Math::Mixed {
                    let o16 = f16::from_f32(o[a]);
                    let la = (lo[a] - o16) - w;
                    let ha = (hi[a] - o16) + w;
                    if r16.d[a] == f16::ZERO {
                        parallel(la <= f16::ZERO && ha >= f16::ZERO, unb)
                    } else {
                        let mul = |v: f16| if r16.off { mul_sat(v, r16.idir[a]) } else { v * r16.idir[a] };
                        let (x, y) = (mul(la).to_f32(), mul(ha).to_f32());
                        (x.min(y), x.max(y))
                    }
                } else {
                    let la = (lo[a].to_f32() - o[a]) - w32;
                    let ha = (hi[a].to_f32() - o[a]) + w32;
                    if r16.d[a] == f16::ZERO {
                        parallel(la <= 0.0 && ha >= 0.0, unb)
                    } else {
                        let (x, y) = (la * r16.idir32[a], ha * r16.idir32[a]);
                        (x.min(y), x.max(y))
                    }
                };
                tn = tn.max(t0);
                tf = tf.min(t1);
            }
            const DOWN: f32 = 1.0 - 1.0 / 256.0;
            const UP: f32 = 1.0 + 1.0 / 256.0;
            let tn_lb = tn * if tn > 0.0 { DOWN } else { UP };
            let tf_ub = tf * if tf > 0.0 { UP } else { DOWN };
            (tn, tn_lb, tf_ub)
        }
    }
}

#[inline]
fn parallel(inside: bool, unb: f32) -> (f32, f32) {
    if inside {
        (-unb, unb)
    } else {
        (unb, -unb)
    }
}

/// Rounds an fp32 value computed with a few roundings up to a safe upper bound.
#[inline]
fn up32(x: f32) -> f32 {
    if x.is_infinite() {
        x
    } else {
        upper32(x)
    }
}

/// The box-test quantities fixed for one visit of one node by one ray.
#[derive(Clone, Copy, Debug)]
pub struct HVisit {
    pub mk: f32,
    pub s_lim: f16,
    pub lower: f16,
    pub precise: bool,
    pub w: f16,
}

/// The visit bounds of a node whose frame has scale `k`, for an origin with error bound `e`
/// standing for world parameter `tp`, under the entry bound `tlo` (every layout that tests fp16 boxes in a node frame).
pub fn half_visit(k: f32, e: f32, tp: f32, tlo: f32, r16: &Ray16, best_t: f32) -> HVisit {
    let mk = r16.m * k;
    let s_max = S_BASE + e + 1.0;
    let lim = (best_t - tp) * mk;
    // Without float controls no value may be inf: a limit that overflows (or comes from a
    // clamped infinite tmax) is replaced by s_max, which the min below would pick anyway.
    #[allow(clippy::neg_cmp_op_on_partial_ord)] // NaN counts as unbounded too
    let lim = if r16.off && !(lim.abs() < BIG32) { s_max } else { lim };
    let s_lim = up_f32(up32(lim).min(s_max));
    let sigma = up32((tp - tlo) * mk);
    let lower = down_f32((-sigma).max(-s_max));
    let w_margin = if r16.off { W_MARGIN_OFF } else { W_MARGIN };
    HVisit { mk, s_lim, lower, precise: e <= EBIG, w: up_f32(e + e * TWO_M11 + w_margin) }
}

/// The box test of one stored fp16 box against origin `o` (its error bound is in `v`):
/// `Some((tn, tn_lb))` when the ray may touch it.
#[inline]
pub fn half_test(o: &[f32; 3], lo: [f16; 3], hi: [f16; 3], v: &HVisit, r16: &Ray16) -> Option<(f32, f32)> {
    let lower = v.lower.to_f32();
    if !v.precise {
        return Some((lower, lower));
    }
    let (tn, tn_lb, tf_ub) = slab(o, r16, v.w, lo, hi);
    (tn_lb <= tf_ub && tf_ub >= lower && tn_lb <= v.s_lim.to_f32()).then_some((tn, tn_lb))
}

/// A lower bound of the world parameter of anything that matters in a hit child: its entry
/// bound `tn_lb` (local) mapped back to world units from `tp`, rounded down (2⁻²¹ covers the
/// division and the addition; 2⁻¹⁹ without float controls), never below the parent's `tlo`.
#[inline]
pub fn half_child_tlo(v: &HVisit, tp: f32, tlo: f32, tn_lb: f32, off: bool) -> f32 {
    let s_lo = tn_lb.max(v.lower.to_f32());
    let q = s_lo / v.mk;
    // Without float controls a node visited without box tests keeps its parent's tlo (its
    // `lower` may have saturated; the parent's bound is valid for every child).
    if off && !v.precise {
        tlo
    } else {
        ((tp + q) - (tp.abs() + q.abs()) * if off { TWO_M19 } else { TWO_M21 }).max(tlo)
    }
}

/// The constants `glsl/half.glsl` shares with this module, for `interface.glsl`.
pub fn glsl_constants() -> String {
    let f = [
        ("OCAP", OCAP),
        ("EMAX", EMAX),
        ("EBIG", EBIG),
        ("W_MARGIN", W_MARGIN),
        ("W_MARGIN_OFF", W_MARGIN_OFF),
        ("SAT", SAT),
        ("BIG32", BIG32),
        ("D_FLUSH", D_FLUSH),
        ("S_BASE", S_BASE),
        ("TWO_M9", TWO_M9),
        ("TWO_M10", TWO_M10),
        ("TWO_M11", TWO_M11),
        ("TWO_M18", TWO_M18),
        ("TWO_M19", TWO_M19),
        ("TWO_M20", TWO_M20),
        ("TWO_M21", TWO_M21),
        ("TWO_M22", TWO_M22),
        ("TWO_M23", TWO_M23),
        ("TWO_M24", TWO_M24),
        ("F16_MAX", crate::fp16::F16_MAX),
        ("NUDGE_REL", crate::fp16::NUDGE_REL),
        ("NUDGE_ABS", crate::fp16::NUDGE_ABS),
    ];
    let mut s: String = f.iter().map(|(n, x)| glsl_float(n, *x)).collect();
    s += &super::frames::glsl_constants();
    s
}

#[cfg(test)]
mod tests;
