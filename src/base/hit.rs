//! What a traversal returns: the closest hit of each ray ([`Hit`], the closest-hit rule in
//! [`Closest`]), its work counters ([`Counters`]) and how far two results agree
//! ([`agreement`]).
//!
//! # The closest-hit rule
//!
//! A triangle's hit is a property of the ray and the triangle alone — never of the boxes a
//! traversal tested, their precision, B or P — so that every conservative layout returns
//! exactly the brute-force closest hit, bit for bit, on every scene:
//!
//! 1. The watertight test ([`tri::intersect`]) gives `t`; it must satisfy `t >= tmin`.
//! 2. **The box rule** ([`admit`]): the exact ray must reach the triangle's *padded box*
//!    (its vertices' box, each bound moved out by the scene's [`hit_pad`]) at some parameter
//!    `s >= tmin`, certified in fp32 with inward rounding; the hit's t becomes
//!    `max(t, enter)`, `enter` being the certified upper bound of where that reach can begin
//!    (so `s <= t`). A hit the rule cannot certify is not a hit.
//! 3. Of the admitted hits the smallest t wins; ties (bit-identical t) go to the lower `prim`,
//!    so results never depend on traversal order.
//!
//! Why (docs/layouts.md, "The closest-hit rule"): the watertight test's t carries an error that
//! grows with the triangle's extent, not with t — a huge ground quad can report a hit in front
//! of a ray whose true crossing is behind it. Before this rule such a hit was found or not
//! depending on whether a tight box culled its leaf, so layouts, B and P disagreed.
//!
//! **The argument.** Let T's admitted hit have t' = max(t, enter). The exact ray meets T's
//! padded box at s = max(tmin, exact entry) with tmin <= s <= t'. Every BVH node above T stores
//! a box containing the padded box (the build refits with padded boxes, `bvh::build`; the
//! encoders round outward), and a conservative box test never rejects a box that the exact ray
//! reaches inside [tmin, best] (every layout's bound is argued beside its test). While a
//! traversal runs, best >= the final t* >= t' for the winning triangle and every triangle tied
//! with it, so every node above them is visited (entry bounds are <= s <= best too) and their
//! tests compute the same t' — the traversal returns the brute-force minimum.
//!
//! **Why padded.** An axis-aligned triangle has a flat box, reached at one exact parameter that
//! no fp32 value equals; with no padding the inward-rounded check would reject every hit on a
//! floor. With padding p the check succeeds for a ray that truly meets the box whenever
//! p >= 1.25·2⁻²⁰·D (D: the ∞-norm distance from the ray origin to the hit), i.e. for origins
//! within 3.2× the scene's extent of the triangle (p = 2⁻¹⁸ of the extent) — the default
//! camera frames a scene from about 2× its extent. Farther origins stay consistent but not
//! true: axis-aligned triangles vanish beyond about 4× the extent, and scenes far from the
//! origin lose every hit (`tests/truth.rs` measures it). [`ClosestTrue`] is the rule that
//! replaces this one (docs/layouts.md, "True hits").

use super::exact;
use super::geom::Aabb;
use super::slab::{lower32, upper32, RayPre};
use super::tri;
use crate::glsl_struct;

glsl_struct! {
    /// One row of `hits.npy` and one record of a kernel's hits buffer: `t` (+inf on a miss),
    /// `prim` (−1 on a miss), barycentrics `u`, `v` of vertices 1 and 2 (hit point =
    /// (1−u−v)·v0 + u·v1 + v·v2). 16 bytes.
    #[derive(Clone, Copy, Debug, PartialEq)]
    pub struct Hit {
        pub t: f32,
        pub prim: i32,
        pub u: f32,
        pub v: f32,
    }
}
const _: () = assert!(std::mem::size_of::<Hit>() == 16);

impl Hit {
    pub const MISS: Hit = Hit { t: f32::INFINITY, prim: -1, u: 0.0, v: 0.0 };
    pub fn is_hit(&self) -> bool {
        self.prim >= 0
    }
    /// Bitwise equality of all four fields.
    pub fn same_bits(&self, o: &Hit) -> bool {
        bytemuck::bytes_of(self) == bytemuck::bytes_of(o)
    }
}

glsl_struct! {
    /// Work counters of one ray, as the CPU reference counts them and a counting kernel writes
    /// them (one record per ray, 24 bytes).
    #[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
    pub struct Counters {
        /// Inner nodes popped and visited.
        pub nodes: u32,
        /// Ray–box tests (child boxes of visited nodes, plus the root's own box).
        pub box_tests: u32,
        /// Ray–triangle tests.
        pub tri_tests: u32,
        /// f16h only: child origins recomputed from the fp32 world ray because the fp16 origin
        /// move's error bound grew too large.
        pub reanchors: u32,
        /// Packet counters, stored in the first ray of each packet (0 in the others): nodes the
        /// packet visited, and the sum over those visits of the rays active for them.
        /// Single-ray traversal: both equal `nodes`.
        pub packet_nodes: u32,
        pub active_lanes: u32,
    }
}

impl std::ops::AddAssign for Counters {
    fn add_assign(&mut self, o: Counters) {
        self.nodes += o.nodes;
        self.box_tests += o.box_tests;
        self.tri_tests += o.tri_tests;
        self.reanchors += o.reanchors;
        self.packet_nodes += o.packet_nodes;
        self.active_lanes += o.active_lanes;
    }
}

/// The padding of every triangle's box in the closest-hit rule, as a share of the scene's
/// largest extent (2⁻¹⁸; see the module docs for why this size).
pub const HIT_PAD_SHARE: f32 = 1.0 / 262_144.0;

/// Exits beyond this parameter count as this (2¹²⁷): a computed exit that overflowed to +inf
/// then still bounds the exact one from below.
pub const HIT_CAP: f32 = f32::from_bits(0x7f00_0000);

/// The padding of a scene whose vertices span `bounds` ([`HIT_PAD_SHARE`] of its largest
/// extent, halved before subtracting so that no extent overflows fp32).
pub fn hit_pad(bounds: &Aabb) -> f32 {
    let h = (bounds.max * 0.5 - bounds.min * 0.5).max_element().max(0.0);
    h * (2.0 * HIT_PAD_SHARE)
}

/// A triangle's padded box: its vertices' box, each bound moved out by `pad` (one rounding;
/// what the BVH is refitted with and what the rule tests — `glsl/tri.glsl` computes the same).
#[inline]
pub fn padded_box(v: &[f32; 9], pad: f32) -> ([f32; 3], [f32; 3]) {
    let mut lo = [0f32; 3];
    let mut hi = [0f32; 3];
    for a in 0..3 {
        let (x, y, z) = (v[a], v[3 + a], v[6 + a]);
        lo[a] = sel_min(sel_min(x, y), z) - pad;
        hi[a] = sel_max(sel_max(x, y), z) + pad;
    }
    (lo, hi)
}

/// GLSL's `min` and `max` (`y < x ? y : x`, `x < y ? y : x`), spelled out so that a signed
/// zero comes out as the kernels give it.
#[inline]
fn sel_min(x: f32, y: f32) -> f32 {
    if y < x {
        y
    } else {
        x
    }
}
#[inline]
fn sel_max(x: f32, y: f32) -> f32 {
    if x < y {
        y
    } else {
        x
    }
}

/// The box rule of the closest-hit rule (module docs): for a hit of triangle `v` at `t >=
/// r.tmin`, the t it is kept with, or `None` when the exact ray's reach of the padded box at
/// or after `tmin` cannot be certified.
///
/// Each plane parameter `(bound − o)·inv` is the exact one times (1 + η), |η| < 3.0001·2⁻²⁴
/// (three roundings), so [`upper32`]/[`lower32`] (2⁻²⁰ ≫ 4·2⁻²⁴) bound the exact entry from
/// above and the exact exit from below; both are monotone, so they commute with the slab's
/// min and max. An axis the ray does not move along is tested exactly. Plane parameters that
/// underflow fp32's normal range (below 2⁻¹²⁶ in magnitude) are outside this argument.
#[inline]
pub fn admit(r: &RayPre, v: &[f32; 9], pad: f32, t: f32) -> Option<f32> {
    let (lo, hi) = padded_box(v, pad);
    let mut enter = r.tmin;
    let mut exit = HIT_CAP;
    for a in 0..3 {
        if r.d[a] == 0.0 {
            if !(r.o[a] >= lo[a] && r.o[a] <= hi[a]) {
                return None;
            }
        } else {
            let x = (lo[a] - r.o[a]) * r.inv[a];
            let y = (hi[a] - r.o[a]) * r.inv[a];
            enter = sel_max(enter, upper32(sel_min(x, y)));
            exit = sel_min(exit, lower32(sel_max(x, y)));
        }
    }
    (enter <= exit).then(|| sel_max(t, enter))
}

/// The closest hit so far under the closest-hit rule (module docs). `prim == i32::MAX` until
/// something is hit, so a hit exactly at `tmax` is accepted like any other (`t <= tmax`).
#[derive(Clone, Copy, Debug)]
pub struct Closest {
    pub t: f32,
    pub prim: i32,
    pub u: f32,
    pub v: f32,
    /// The scene's triangle-box padding ([`hit_pad`]).
    pub pad: f32,
}

impl Closest {
    pub fn new(tmax: f32, pad: f32) -> Closest {
        Closest { t: tmax, prim: i32::MAX, u: 0.0, v: 0.0, pad }
    }
    /// Tests triangle `verts` with public id `prim` and keeps it if closer (ties: lower prim).
    /// The box rule only ever raises t, so it is applied only to a hit that would be kept.
    #[inline]
    pub fn test(&mut self, r: &RayPre, verts: &[f32; 9], prim: i32) {
        if let Some((t, u, v)) = tri::intersect(r, verts) {
            if t >= r.tmin && self.closer(t, prim) {
                if let Some(t) = admit(r, verts, self.pad, t).filter(|&t| self.closer(t, prim)) {
                    *self = Closest { t, prim, u, v, pad: self.pad };
                }
            }
        }
    }
    #[inline]
    fn closer(&self, t: f32, prim: i32) -> bool {
        closer(t, prim, (self.t, self.prim))
    }
    pub fn hit(&self) -> Hit {
        if self.prim == i32::MAX {
            Hit::MISS
        } else {
            Hit { t: self.t, prim: self.prim, u: self.u, v: self.v }
        }
    }
}

/// The closest hit under the **true rule** (docs/layouts.md, "True hits"), the rule that is to
/// replace [`Closest`]'s box rule: a triangle is hit where the *exact* ray (its fp32 origin and
/// direction as exact numbers) crosses it, closed (edges and vertices included), at an exact
/// parameter s in `[tmin, tmax]`; the hit is kept with
///
/// - `t' = hi`, the upper end of [`tri::certify`]'s interval, where fp32 certifies the crossing
///   and its interval lies in `[tmin, tmax]`;
/// - else `t' = ` s rounded up to f32, decided and placed exactly ([`exact::crossing`]: the rare
///   path, counted in `rare`).
///
/// `t'` is a function of the ray and the triangle alone, with `s ≤ t'`: every BVH node above a
/// hit triangle contains the exact crossing point, which the exact ray reaches at `s ≤ t' ≤
/// best`, so every conservative traversal visits it — consistent, with no padding, at any
/// distance and offset. Ties go to the lower prim, as in [`Closest`].
#[derive(Clone, Copy, Debug)]
pub struct ClosestTrue {
    pub t: f32,
    pub prim: i32,
    pub u: f32,
    pub v: f32,
    /// Triangle tests that fp32 could not decide (the exact path ran).
    pub rare: u32,
}

impl ClosestTrue {
    pub fn new(tmax: f32) -> ClosestTrue {
        ClosestTrue { t: tmax, prim: i32::MAX, u: 0.0, v: 0.0, rare: 0 }
    }

    /// The kept t' of triangle `verts` (`None`: not hit), and its barycentrics; `rare` is
    /// raised when the exact path decides. Skips the exact path for a triangle whose crossing
    /// cannot be closer than `(best_t, best_prim)`.
    pub fn kept(r: &RayPre, verts: &[f32; 9], prim: i32, best: (f32, i32), rare: &mut u32) -> Option<(f32, f32, f32)> {
        let c = tri::certify(r, verts);
        let (lo, hi) = c.bounds();
        if hi < r.tmin || !closer(lo, prim, best) {
            return None;
        }
        if let tri::Cert::Hit { u, v, .. } = c {
            if lo >= r.tmin && hi <= r.tmax {
                return Some((hi, u, v));
            }
        }
        *rare += 1;
        exact::crossing_in(r, verts).map(|x| (x.s.round_up(), x.u.approx_f32(), x.v.approx_f32()))
    }

    /// Tests triangle `verts` with public id `prim` and keeps it if closer.
    pub fn test(&mut self, r: &RayPre, verts: &[f32; 9], prim: i32) {
        if let Some((t, u, v)) = Self::kept(r, verts, prim, (self.t, self.prim), &mut self.rare) {
            if closer(t, prim, (self.t, self.prim)) {
                *self = ClosestTrue { t, prim, u, v, rare: self.rare };
            }
        }
    }

    pub fn hit(&self) -> Hit {
        if self.prim == i32::MAX {
            Hit::MISS
        } else {
            Hit { t: self.t, prim: self.prim, u: self.u, v: self.v }
        }
    }
}

/// `(t, prim)` comes before `best` in the closest-hit order (smaller t; equal t, lower prim).
fn closer(t: f32, prim: i32, best: (f32, i32)) -> bool {
    t < best.0 || (t == best.0 && prim < best.1)
}

/// How many rays of one result agree with a reference: same hit/miss, and the same `prim` or,
/// where triangles tie or share edges, `t` within 1e-5 relative. This is the one definition of
/// "differs from f32" in reports ([`Agreement::differs`]); the exact layouts are held to more —
/// bitwise equality with their CPU reference — by validation.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Agreement {
    pub agree: usize,
    pub total: usize,
    pub false_misses: usize,
    pub max_abs_dt: f64,
}

impl Agreement {
    /// Rays that disagree.
    pub fn differs(&self) -> usize {
        self.total - self.agree
    }

    pub fn rate(&self) -> f64 {
        if self.total == 0 {
            1.0
        } else {
            self.agree as f64 / self.total as f64
        }
    }
}

pub fn agreement(got: &[Hit], reference: &[Hit]) -> Agreement {
    let mut a = Agreement { agree: 0, total: got.len(), false_misses: 0, max_abs_dt: 0.0 };
    for (g, r) in got.iter().zip(reference) {
        let ok = match (g.is_hit(), r.is_hit()) {
            (false, false) => true,
            (true, true) => {
                let dt = (g.t as f64 - r.t as f64).abs();
                a.max_abs_dt = a.max_abs_dt.max(dt);
                g.prim == r.prim || dt <= 1e-5 * (r.t as f64).abs().max(f64::MIN_POSITIVE)
            }
            (false, true) => {
                a.false_misses += 1;
                false
            }
            (true, false) => false,
        };
        a.agree += ok as usize;
    }
    a
}

/// Share of active rays per visited packet node: Σ active / (Σ packet visits · P).
pub fn simd_utilisation(c: &[Counters], p: usize) -> f64 {
    let visits: u64 = c.iter().map(|x| x.packet_nodes as u64).sum();
    let active: u64 = c.iter().map(|x| x.active_lanes as u64).sum();
    if visits == 0 {
        1.0
    } else {
        active as f64 / (visits as f64 * p as f64)
    }
}

/// Mean counters over a ray set: nodes, box tests, triangle tests, re-anchors per ray.
pub fn mean_counters(c: &[Counters]) -> [f64; 4] {
    let n = c.len().max(1) as f64;
    let mut s = [0f64; 4];
    for x in c {
        s[0] += x.nodes as f64;
        s[1] += x.box_tests as f64;
        s[2] += x.tri_tests as f64;
        s[3] += x.reanchors as f64;
    }
    s.map(|v| v / n)
}

/// Hits (and counters, for a counting kernel) and the time of each timed run, ms.
pub struct RunOutput {
    pub hits: Vec<Hit>,
    pub counters: Option<Vec<Counters>>,
    pub times_ms: Vec<f64>,
}
