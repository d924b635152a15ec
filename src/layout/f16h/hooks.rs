//! The f16h traversal hooks: box tests and origin moves in IEEE half arithmetic (`half::f16`,
//! one rounding per operation) or in the other math modes, conservative, so the traversal
//! returns exactly the fp32 closest hit. `glsl/layout/f16h.glsl` does the same operations in
//! the same order.
//!
//! # State per stack entry (the seed's "extra stack")
//! Besides the node index (which the skeleton keeps): the node's frame (W, K) in fp32; the ray
//! origin O in the node's frame (fp16, or fp32 in the fp32 math mode); `e`, a bound on the
//! origin's error; `tp`, the world parameter of the point P that O stands for; `tlo`, a lower
//! bound on the world parameter of any point of the ray that can still matter in this node.
//!
//! # The bound relied on (invariant)
//! With d* = D / max|D| (exact) and L the node frame's map:
//! (I1) ‖O − L(P)‖∞ ≤ e, where P = O_world + tp·D exactly;
//! (I2) every point X of the ray inside the node's true box with t_X ∈ [tmin, t_closest] has
//!      t_X ≥ tlo.
//! Write X = L(P) + s·d* (local units, s = (t_X − tp)·M·K). Since X lies in the node's box
//! (|X| ≤ 16384) and |O| ≤ `OCAP`, |s| ≤ S = 16384 + OCAP + e. The approximate line
//! A(s) = O + s·d16 then satisfies ‖A(s) − X‖∞ ≤ e + S·(2⁻¹² + 2⁻²⁴) (direction rounding).
//! So a child whose true box contains X has A(s) inside its stored box widened by
//! w_req = e + (36864 + e)·(2⁻¹² + 2⁻²⁴). The test widens by w = e·(1 + 2⁻¹¹) + 44 ≥ w_req + 32:
//! the 32 absorb the two fp16 subtractions (lo − O) − w, whose half-ulp errors are ≤ 16 each
//! below 65536 (larger results overflow outward, to ±inf). The products with 1/d16 then carry
//! relative error ≤ 2⁻¹⁰ (rounding of 1/d16 and of the product), which the factors
//! (1 ∓ 2⁻⁸) on the entry/exit cover with room for their own rounding. Hence the computed
//! interval [tn_lb, tf_ub] contains every such s: no false misses.
//! Culling uses s ≤ (t_closest − tp)·M·K (rounded up) and s ≥ −(tp − tlo)·M·K (rounded down).
//!
//! # Origin move
//! For a hit inner child the new origin is E = O + s_e·d16 with s_e = max(tn, s_lower), then
//! O' = (E − c)·r in the child frame (fp16, r exact). Its error bound e' = r·(e + |s_e|·2⁻¹⁰ +
//! 2⁻¹¹·(|E| + |E − c|) + ε) plus the fp32 rounding of W' and tp'. The bound compounds: each
//! level multiplies by r while P's true position is fixed, so in world units it converges to
//! ≈ the root frame's fp16 grid (root extent / 2048). When e' would exceed `EMAX` (or O'
//! leaves ±`OCAP`, or r > 2¹⁵), the origin is re-anchored: recomputed in fp32 from the world
//! ray at the child's fp32 entry distance (`Counters::reanchors`). Keeping this rare is what
//! makes fp16 origin moves usable; the counter reports how rare.
//!
//! # Without float controls (`Ray16::off`, kernels built with `FC_OFF`)
//! A device without RoundingModeRTE / SignedZeroInfNanPreserve may round each fp16 and fp32
//! operation either way (faithfully: to one of the two neighbours of the exact result, an error
//! up to one ulp instead of half) and may assume no operand is inf or NaN. That build keeps the
//! same nodes and frames and widens every bound by the extra half ulp of every rounding:
//! - Conversions to fp16 are emulated exactly (`fp16::rte16_emulated`, the kernels' `rte16`), so
//!   d16, s_e, the anchored origin and the widths are the same values as here; reciprocals come
//!   from an fp32 division (2.5 ulp in Vulkan) rounded to fp16: ≤ 2⁻¹¹ + 2⁻²¹ relative.
//! - Frames must be the encoder's bit for bit: their fp32 additions use `fp16::add_rte_emulated`
//!   (the kernels' `add_rte`) and every product is by a power of two (exact).
//! - Box test: the two fp16 subtractions may each be off by a full ulp (≤ 32 below 65536), so the
//!   widening is e·(1 + 2⁻¹¹) + `W_MARGIN_OFF` (9 direction + 64 + spare). The products
//!   (≤ 2⁻¹⁰ + the reciprocal's 2⁻¹¹ + 2⁻²¹) and the (1 ∓ 2⁻⁸) factors' own rounding (≤ 2⁻¹⁰)
//!   still leave (1 + 1.6·2⁻¹⁰)(1 − 2⁻⁸)(1 + 2⁻¹⁰) < 1: the factors cover them.
//! - No inf: a product is computed in fp32 first (exact: 11 × 11 significant bits); beyond
//!   ±`SAT` it is saturated to ±SAT, which decides exactly as ±inf would, since every relevant
//!   |s| ≤ s_max ≤ 16384 + OCAP + EBIG + 1 = 53249 < SAT·(1 − 2⁻⁸)(1 − 2⁻¹⁰). Unconstrained
//!   intervals start at ±SAT (±`BIG32` in fp32 math). An origin move whose fp16 values could
//!   overflow (|O| + |s_e| + |c| > 60000, or |E − c|·r > OCAP) re-anchors instead.
//! - Origin-move bound: |s_e|·2⁻⁹ (conversion 2⁻¹¹ + product 2⁻¹⁰), 2⁻¹⁰·(|E| + |E − c|) for
//!   the addition and subtraction, 2⁻²² absolute; the world parameter's division (2.5 ulp) and
//!   addition: 2⁻²⁰·(|tp| + |step|); tlo's margin 2⁻¹⁹; the anchor's fp32 point 2⁻²¹·mag·k.
//! The CPU reference of this build takes the same decisions with IEEE rounding, so on a device
//! that does round to nearest (lavapipe) GPU and CPU agree bit for bit, and elsewhere the hits
//! still equal f32's while counters may differ on rays where an ulp moved a box test.

use super::frame::{derive_child, Frame};
use super::F16hNode;
use crate::fp16::{down_f32, up_f32};
use crate::layout::Math;
use crate::trace::{slab32, upper32, Counters, RayPre};
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
const S_BASE: f32 = 16384.0 + OCAP;

const TWO_M9: f32 = 1.0 / 512.0;
const TWO_M11: f32 = 1.0 / 2048.0;
const TWO_M19: f32 = 1.0 / 524_288.0;
const TWO_M20: f32 = 1.0 / 1_048_576.0;
const TWO_M10: f32 = 1.0 / 1024.0;
const TWO_M18: f32 = 1.0 / 262_144.0;
const TWO_M21: f32 = 1.0 / 2_097_152.0;
const TWO_M22: f32 = 1.0 / 4_194_304.0;
const TWO_M23: f32 = 1.0 / 8_388_608.0;
const TWO_M24: f32 = 1.0 / 16_777_216.0;

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
    pub fn new(r: &RayPre, math: Math, fc: crate::variant::FloatControls) -> Ray16 {
        let off = fc == crate::variant::FloatControls::Off;
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

/// The root entry of a ray entering the root box at `near`.
pub fn root_entry(root: &Frame, r: &RayPre, r16: &Ray16, near: f32) -> Entry {
    let (o, e) = anchor(r, root, near, r16.math, r16.off);
    Entry { frame: *root, o, e, tp: near, tlo: near }
}

/// Quantities fixed for one visit of one node by one ray.
#[derive(Clone, Copy, Debug)]
pub struct Visit {
    pub mk: f32,
    pub s_lim: f16,
    pub lower: f16,
    pub precise: bool,
    pub w: f16,
}

pub fn visit(en: &Entry, r16: &Ray16, best_t: f32) -> Visit {
    visit_parts(en.frame.k, en.e, en.tp, en.tlo, r16, best_t)
}

/// The visit bounds of a node whose frame has scale `k`, for an origin with error bound `e`
/// standing for world parameter `tp`, under the entry bound `tlo` (shared with the other
/// layouts that test fp16 boxes in a node frame: f16w, f16a, q8).
pub fn visit_parts(k: f32, e: f32, tp: f32, tlo: f32, r16: &Ray16, best_t: f32) -> Visit {
    let mk = r16.m * k;
    let s_max = S_BASE + e + 1.0;
    let lim = (best_t - tp) * mk;
    // Without float controls no value may be inf: a limit that overflows (or comes from a
    // clamped infinite tmax) is replaced by s_max, which the min below would pick anyway.
    let lim = if r16.off && !(lim.abs() < BIG32) { s_max } else { lim };
    let s_lim = up_f32(up32(lim).min(s_max));
    let sigma = up32((tp - tlo) * mk);
    let lower = down_f32((-sigma).max(-s_max));
    let w_margin = if r16.off { W_MARGIN_OFF } else { W_MARGIN };
    Visit { mk, s_lim, lower, precise: e <= EBIG, w: up_f32(e + e * TWO_M11 + w_margin) }
}

/// The box test of one stored fp16 box against origin `o` (its error bound is in `v`):
/// `Some((tn, tn_lb))` when the ray may touch it.
#[inline]
pub fn test_box(o: &[f32; 3], lo: [f16; 3], hi: [f16; 3], v: &Visit, r16: &Ray16) -> Option<(f32, f32)> {
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
pub fn child_tlo(v: &Visit, tp: f32, tlo: f32, tn_lb: f32, off: bool) -> f32 {
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

/// The stored fp16 box of slot `s`.
#[inline(always)]
pub fn slot_box<const B: usize>(n: &F16hNode<B>, s: usize) -> ([f16; 3], [f16; 3]) {
    ([n.lo[0][s], n.lo[1][s], n.lo[2][s]], [n.hi[0][s], n.hi[1][s], n.hi[2][s]])
}

/// The box test of one child: `Some((tn, (tn, tn_lb)))` when the ray may touch it.
#[inline]
pub fn test_child<const B: usize>(
    n: &F16hNode<B>,
    s: usize,
    en: &Entry,
    v: &Visit,
    r16: &Ray16,
) -> Option<(f32, (f32, f32))> {
    let (lo, hi) = slot_box(n, s);
    test_box(&en.o, lo, hi, v, r16).map(|(tn, tn_lb)| (tn, (tn, tn_lb)))
}

/// The stack entry of a hit inner child: its frame, and the origin moved into it in fp16
/// (or re-anchored from the fp32 world ray when the bound grows too large).
#[allow(clippy::too_many_arguments)]
pub fn child_entry<const B: usize>(
    n: &F16hNode<B>,
    s: usize,
    en: &Entry,
    v: &Visit,
    (tn, tn_lb): (f32, f32),
    r: &RayPre,
    r16: &Ray16,
    c: &mut Counters,
) -> Entry {
    let (lo, hi) = slot_box(n, s);
    let (mk, math) = (v.mk, r16.math);
    let cf = derive_child(&en.frame, lo, hi);
    let lower = v.lower.to_f32();
    let off = r16.off;
    let tlo = child_tlo(v, en.tp, en.tlo, tn_lb, off);
    let se = tn.max(lower);
    // Without float controls the fp16 origin move must not overflow (module docs).
    let fits = !off || math == Math::F32 || {
        let om = en.o.iter().fold(0f32, |m, x| m.max(x.abs()));
        let cm = cf.c.iter().fold(0f32, |m, x| m.max(x.to_f32().abs()));
        om + se.abs() + cm <= 60000.0
    };
    if v.precise && cf.r <= 32768.0 && fits {
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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::fp16;
    use crate::rays::Ray;
    use proptest::prelude::*;

    /// One fp16 operation rounded faithfully: the exact result (`x`, exact in f64 for these
    /// operands) rounded to nearest, or — when `flip` — to its other fp16 neighbour, as a device
    /// without float controls may.
    fn faithful(x: f64, flip: bool) -> f16 {
        let r = f16::from_f64(x);
        if !flip || r.to_f64() == x || r.is_infinite() {
            return r;
        }
        if r.to_f64() < x {
            fp16::next_up(r)
        } else {
            fp16::next_down(r)
        }
    }

    /// [`slab16`] without float controls, with every fp16 operation (and the reciprocal) rounded either way.
    fn slab16_faithful(o: &[f16; 3], d: &[f16; 3], w: f16, lo: [f16; 3], hi: [f16; 3], bits: &mut u64) -> (f64, f64) {
        let mut flip = || {
            *bits = bits.rotate_left(1);
            *bits & 1 == 1
        };
        let sat = f16::from_f32(SAT);
        let (mut tn, mut tf) = (-sat, sat);
        for a in 0..3 {
            let la = faithful(faithful(lo[a].to_f64() - o[a].to_f64(), flip()).to_f64() - w.to_f64(), flip());
            let ha = faithful(faithful(hi[a].to_f64() - o[a].to_f64(), flip()).to_f64() + w.to_f64(), flip());
            let (t0, t1) = if d[a] == f16::ZERO {
                if la <= f16::ZERO && ha >= f16::ZERO {
                    (-sat, sat)
                } else {
                    (sat, -sat)
                }
            } else {
                let idir = faithful(1.0 / d[a].to_f64(), flip());
                let mul = |v: f16, f: bool| {
                    let p = v.to_f64() * idir.to_f64();
                    if p > SAT as f64 {
                        sat
                    } else if p < -(SAT as f64) {
                        -sat
                    } else {
                        faithful(p, f)
                    }
                };
                let (x, y) = (mul(la, flip()), mul(ha, flip()));
                (x.min(y), x.max(y))
            };
            tn = tn.max(t0);
            tf = tf.min(t1);
        }
        let down = f16::from_f32(1.0 - 1.0 / 256.0);
        let up = f16::from_f32(1.0 + 1.0 / 256.0);
        let tn_lb = faithful(tn.to_f64() * if tn > f16::ZERO { down } else { up }.to_f64(), flip());
        let tf_ub = faithful(tf.to_f64() * if tf > f16::ZERO { up } else { down }.to_f64(), flip());
        (tn_lb.to_f64(), tf_ub.to_f64())
    }

    /// Rays and boxes of the slab property tests: a point X of the box at parameter s on the
    /// exact line through P = X − s·d (|P| ≤ 20000), and an fp16 origin O within e of P.
    #[allow(clippy::type_complexity)]
    fn slab_case(
        x: [f64; 3],
        off: [f64; 3],
        e_scale: f64,
        d: [f64; 3],
        s_frac: f64,
        ext: [f64; 3],
    ) -> ([f16; 3], f32, f64, [f16; 3], [f16; 3]) {
        let mut s = s_frac * (16384.0 + 20000.0);
        for a in 0..3 {
            if d[a] != 0.0 {
                s = s.signum() * s.abs().min((20000.0 - x[a].abs()) / d[a].abs());
            }
        }
        let p = [0, 1, 2].map(|a| x[a] - s * d[a]);
        let o: [f16; 3] = [0, 1, 2].map(|a| f16::from_f64((p[a] + off[a] * e_scale).clamp(-OCAP as f64, OCAP as f64)));
        let e_true = (0..3).fold(0f64, |m, a| m.max((o[a].to_f64() - p[a]).abs()));
        let e = (e_true as f32) * (1.0 + 1e-6) + 1e-6;
        let lo = [0, 1, 2].map(|a| fp16::down_f64((x[a] - ext[a]).max(-16384.0)));
        let hi = [0, 1, 2].map(|a| fp16::up_f64((x[a] + ext[a]).min(16384.0)));
        (o, e, s, lo, hi)
    }

    /// Without float controls: whichever way each fp16 operation (and the reciprocal) rounds —
    /// to nearest, always the other way, or mixed — the widened test (`W_MARGIN_OFF`) reports an
    /// interval containing s. (Sampling finds no case that needs more than the e·2⁻¹¹ term even
    /// without the absolute margin: a subtraction can only err by 16–32 where the operands are
    /// large, and there the relative 2⁻⁸ or the outward rounding of w covers it; the margin keeps
    /// the argued full-ulp budget rather than relying on that.)
    #[test]
    fn slab16_off_holds_under_any_faithful_rounding() {
        use proptest::test_runner::{Config, TestRunner};
        let mut runner = TestRunner::new(Config { cases: 20000, ..Config::default() });
        let strat = (
            prop::array::uniform3(-16384.0f64..16384.0),
            prop::array::uniform3(-1.0f64..1.0),
            prop_oneof![Just(0.0f64), 0.0f64..1.0, 0.0f64..64.0, 1000.0f64..16000.0],
            prop::array::uniform3(-1.0f64..1.0),
            0usize..4,
            prop_oneof![-1.0f64..1.0, -1e-3f64..1e-3],
            prop::array::uniform3(prop_oneof![Just(0.0f64), 0.0f64..0.01, 0.0f64..50.0]),
            any::<u64>(),
        );
        runner
            .run(&strat, |(x, off, e_scale, dv, zero_axis, s_frac, ext, seed)| {
                let mut dv = dv;
                if zero_axis < 3 {
                    dv[zero_axis] = 0.0;
                }
                let Some(d) = dir(dv) else { return Ok(()) };
                let (o, e, s, lo, hi) = slab_case(x, off, e_scale, d, s_frac, ext);
                prop_assume!(e <= EBIG);
                let pre = RayPre::new(&Ray::new(
                    glam::Vec3::ZERO,
                    glam::Vec3::new(d[0] as f32, d[1] as f32, d[2] as f32),
                    0.0,
                    f32::INFINITY,
                ));
                let r16 = Ray16::new(&pre, Math::F16, crate::variant::FloatControls::Off);
                for flips in [seed, !seed, u64::MAX, 0] {
                    let mut bits = flips;
                    let w = up_f32(e + e * TWO_M11 + W_MARGIN_OFF);
                    let (tn_lb, tf_ub) = slab16_faithful(&o, &r16.d, w, lo, hi, &mut bits);
                    prop_assert!(
                        tn_lb <= s && s <= tf_ub,
                        "s={} not in [{}, {}] (o={:?} e={} d={:?} box {:?}..{:?})",
                        s,
                        tn_lb,
                        tf_ub,
                        o,
                        e,
                        d,
                        lo,
                        hi
                    );
                }
                Ok(())
            })
            .unwrap();
    }

    /// A unit-max-norm direction from three random components.
    fn dir(v: [f64; 3]) -> Option<[f64; 3]> {
        let m = v.iter().fold(0f64, |m, x| m.max(x.abs()));
        (m > 1e-9).then(|| {
            let d = v.map(|x| ((x / m) as f32) as f64);
            // make the dominant component exactly ±1
            let k = (0..3).max_by(|&a, &b| d[a].abs().total_cmp(&d[b].abs())).unwrap();
            let mut d = d;
            d[k] = d[k].signum();
            d
        })
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(20000))]

        /// The invariant the traversal relies on: if the true line through P (within e of
        /// O) reaches a point X of a box at parameter s, the widened fp16 slab test of the
        /// stored box reports an interval containing s.
        #[test]
        fn slab16_never_misses_a_point_the_true_ray_reaches(
            x in prop::array::uniform3(-16384.0f64..16384.0),
            off in prop::array::uniform3(-1.0f64..1.0),
            e_scale in prop_oneof![Just(0.0f64), 0.0f64..1.0, 0.0f64..64.0, 0.0f64..2048.0],
            dv in prop::array::uniform3(-1.0f64..1.0),
            zero_axis in 0usize..4,
            s_frac in -1.0f64..1.0,
            ext in prop::array::uniform3(prop_oneof![Just(0.0f64), 0.0f64..0.01, 0.0f64..50.0, 0.0f64..5000.0]),
        ) {
            let mut dv = dv;
            if zero_axis < 3 { dv[zero_axis] = 0.0; }
            let Some(d) = dir(dv) else { return Ok(()) };
            let (o, e, s, lo, hi) = slab_case(x, off, e_scale, d, s_frac, ext);
            let pre = RayPre::new(&Ray::new(glam::Vec3::ZERO, glam::Vec3::new(d[0] as f32, d[1] as f32, d[2] as f32), 0.0, f32::INFINITY));
            let r16 = Ray16::new(&pre, Math::F16, crate::variant::FloatControls::On);
            prop_assert_eq!(r16.m, 1.0);
            let w = up_f32(e + e * TWO_M11 + W_MARGIN);
            let (_tn, tn_lb, tf_ub) = slab16(&o, &r16, w, lo, hi);
            prop_assert!(tn_lb.to_f64() <= s && s <= tf_ub.to_f64(),
                "s={} not in [{}, {}] (o={:?} e={} d={:?} box {:?}..{:?})", s, tn_lb, tf_ub, o, e, d, lo, hi);
        }

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
            let mut b = crate::geom::Aabb::EMPTY;
            for corner in 0..8 {
                let p: [f32; 3] = [0, 1, 2].map(|a| {
                    let h = half[a].min(16384.0 - c[a].abs());
                    to_world(if corner >> a & 1 == 1 { c[a] + h } else { c[a] - h }, a)
                });
                b.grow(glam::Vec3::from(p));
            }
            let (lo, hi, exact) = super::super::frame::to_local(&parent, &b);
            prop_assume!(exact.iter().all(|v| v.abs() <= 16384.0));
            for a in 0..3 {
                prop_assert!(lo[a].to_f64() <= exact[a] && hi[a].to_f64() >= exact[3 + a]);
            }
            let cf = super::super::frame::derive_child(&parent, lo, hi);
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
