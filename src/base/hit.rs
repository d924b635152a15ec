//! What a traversal returns: the closest hit of each ray ([`Hit`], the closest-hit rule in
//! [`ClosestTrue`]), its work counters ([`Counters`]) and how far two results agree
//! ([`agreement`]).
//!
//! # The closest-hit rule (the true rule)
//!
//! A triangle is hit where the *exact* ray — its fp32 origin and direction taken as exact
//! numbers — crosses it, closed (edges and vertices included), at an exact parameter s in
//! `[tmin, tmax]`. The hit is kept with a t' that is a function of the ray and the triangle
//! alone, with s ≤ t' (docs/layouts.md, "The closest-hit rule"):
//!
//! - `t' = hi`, the upper end of the interval [`tri::certify`] certifies to hold s, where fp32
//!   decides the crossing and its interval lies in `[tmin, tmax]`;
//! - else `t' =` s rounded up to f32, decided and placed exactly ([`exact::crossing`]).
//!
//! The nearest exact crossing wins (the smallest s; equal s go to the lower `prim`), reported
//! with its t', so results never depend on traversal order. Every BVH node above a hit triangle contains the
//! exact crossing point, which the exact ray reaches at s ≤ t' ≤ best, and a conservative box
//! test never rejects a box the exact ray reaches inside `[tmin, best]` (every layout's bound is
//! argued beside its test): every conservative traversal visits the winning triangle and
//! returns the brute-force minimum — consistent and true, at any distance and scene offset.
//!
//! **Fast and exact.** A traversal ([`ClosestTrue::fast`], what the kernels and the CPU
//! references run) never takes the exact path: it keeps what fp32 certifies and notes the
//! least possible start `lo` of the crossings it could not decide; if one of those might come
//! before the final best, the ray is *flagged* ([`PRIM_FLAGGED`]) and re-traced with the exact
//! path ([`ClosestTrue::new`]; [`resolve_flagged`]). A ray that is not flagged had no
//! undecided triangle that could beat its hit, so its hit is the exact rule's.
//!
//! [`ClosestBox`] is the rule this one replaced (the box rule), kept to show what it loses.

use super::exact;
use super::geom::Aabb;
use super::ray::Ray;
use super::slab::{lower32, upper32, RayPre, HIT_CAP};
use super::tri::{self, sel_max, sel_min};
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
    /// A ray the fast rule could not decide, still to be re-traced ([`PRIM_FLAGGED`]).
    pub fn is_flagged(&self) -> bool {
        self.prim == PRIM_FLAGGED
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

/// The padding of every triangle's box in the box rule ([`ClosestBox`]) and of the BVH's
/// refit (`bvh::build`), as a share of the scene's largest extent (2⁻¹⁸).
pub const HIT_PAD_SHARE: f32 = 1.0 / 262_144.0;

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

/// The box rule ([`ClosestBox`]): for a hit of triangle `v` at `t >=
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

/// The closest hit so far under the **box rule**, the rule [`ClosestTrue`] replaced, kept to
/// measure what it loses (`tests/truth.rs`) and to classify changed rays: the watertight
/// test's t ≥ tmin, admitted only where fp32, rounding inward, certifies that the exact ray
/// reaches the triangle's box padded by [`hit_pad`] ([`admit`]), t raised to that entry.
/// Consistent across layouts but not true: hits vanish from farther than about 4× the scene's
/// extent and in scenes far from the origin (docs/layouts.md). `prim == i32::MAX` until
/// something is hit.
#[derive(Clone, Copy, Debug)]
pub struct ClosestBox {
    pub t: f32,
    pub prim: i32,
    pub u: f32,
    pub v: f32,
    /// The scene's triangle-box padding ([`hit_pad`]).
    pub pad: f32,
}

impl ClosestBox {
    pub fn new(tmax: f32, pad: f32) -> ClosestBox {
        ClosestBox { t: tmax, prim: i32::MAX, u: 0.0, v: 0.0, pad }
    }
    /// Tests triangle `verts` with public id `prim` and keeps it if closer (ties: lower prim).
    /// The box rule only ever raises t, so it is applied only to a hit that would be kept.
    #[inline]
    pub fn test(&mut self, r: &RayPre, verts: &[f32; 9], prim: i32) {
        if let Some((t, u, v)) = tri::intersect(r, verts) {
            if t >= r.tmin && self.closer(t, prim) {
                if let Some(t) = admit(r, verts, self.pad, t).filter(|&t| self.closer(t, prim)) {
                    *self = ClosestBox { t, prim, u, v, pad: self.pad };
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

/// The `prim` of a ray that fp32 could not decide ([`ClosestTrue::fast`]): its hit is found
/// by the exact re-trace (module docs). A kernel writes it with t = 0, u = v = 0.
pub const PRIM_FLAGGED: i32 = -3;

/// The closest hit so far under the closest-hit rule (module docs). `prim == i32::MAX` until
/// something is hit, so a hit exactly at `tmax` is accepted like any other (`t' <= tmax`).
#[derive(Clone, Debug)]
pub struct ClosestTrue {
    /// The best hit's t' (the culling bound: at least its exact crossing).
    pub t: f32,
    pub prim: i32,
    pub u: f32,
    pub v: f32,
    /// A lower bound of the best hit's exact crossing (`+inf` before any hit).
    pub lo: f32,
    /// Triangle tests that fp32 could not decide (in exact mode, the exact path ran).
    pub rare: u32,
    /// Fast mode ([`Self::fast`]): a test fp32 cannot decide is noted in `undecided`.
    pub fast: bool,
    /// Fast mode: the least `(lo, prim)` of the undecided tests (`lo`: where the crossing, if
    /// any, can begin; `−inf` when unknown).
    pub undecided: (f32, i32),
    /// Exact mode: the best triangle's vertices, for an exact comparison of crossings.
    best_verts: [f32; 9],
}

/// What fp32 decides of one triangle for the closest-hit rule.
enum Decision {
    /// Not hit, or certainly not before the best so far.
    No,
    /// Hit, certainly before the best so far: kept with t' = `hi`, `lo` ≤ s, barycentrics.
    Kept { lo: f32, hi: f32, u: f32, v: f32 },
    /// fp32 cannot decide whether it is hit before the best; a crossing, if any, lies at or
    /// after `lo`.
    Undecided(f32),
}

impl ClosestTrue {
    /// Exact mode: every test decided, by exact arithmetic where fp32 cannot.
    pub fn new(tmax: f32) -> ClosestTrue {
        ClosestTrue {
            t: tmax,
            prim: i32::MAX,
            u: 0.0,
            v: 0.0,
            lo: f32::INFINITY,
            rare: 0,
            fast: false,
            undecided: (f32::INFINITY, i32::MAX),
            best_verts: [0.0; 9],
        }
    }

    /// Exact mode over every triangle of `tris` (vertices and public prim, in any order: ties go
    /// to the lower prim): the brute force every conservative traversal is held to.
    pub fn brute_force(ray: &Ray, tris: impl IntoIterator<Item = ([f32; 9], i32)>) -> ClosestTrue {
        let r = RayPre::new(ray);
        let mut best = ClosestTrue::new(ray.tmax);
        for (v, prim) in tris {
            best.test(&r, &v, prim);
        }
        best
    }

    /// Fast mode, what traversals run (and `glsl/tri.glsl` mirrors operation for operation):
    /// fp32 alone. The ray is flagged ([`Self::hit`] is [`PRIM_FLAGGED`]) when a test fp32
    /// could not decide might come before the final best — decided at the end, so it does not
    /// depend on the order of the triangle tests (a kernel tests a visit's leaves in slot
    /// order, the CPU reference in key order).
    pub fn fast(tmax: f32) -> ClosestTrue {
        ClosestTrue { fast: true, ..ClosestTrue::new(tmax) }
    }

    /// fp32's decision on triangle `verts` against the best so far: kept only where its
    /// certified interval lies wholly before the best's (`hi < lo_best`), so that the kept
    /// hit is the nearest exact crossing, not only the smallest upper bound.
    /// The sides of the kernel's test it takes go to `path` ([`tri::Branch`] bits).
    #[inline]
    fn decide(&self, r: &RayPre, verts: &[f32; 9], prim: i32, path: &mut u8) -> Decision {
        let c = tri::certify_traced(r, verts, path);
        if c == tri::Cert::Miss {
            return Decision::No;
        }
        let (lo, hi) = c.bounds();
        if hi < r.tmin || !closer(lo, prim, (self.t, self.prim)) {
            return Decision::No;
        }
        *path |= tri::Branch::Candidate.bit();
        if let tri::Cert::Hit { u, v, .. } = c {
            if lo >= r.tmin && hi <= r.tmax && hi < self.lo {
                *path |= tri::Branch::Best.bit();
                return Decision::Kept { lo, hi, u, v };
            }
        }
        Decision::Undecided(lo)
    }

    /// Tests triangle `verts` with public id `prim` and keeps it if nearer.
    #[inline]
    pub fn test(&mut self, r: &RayPre, verts: &[f32; 9], prim: i32) {
        self.test_traced(r, verts, prim);
    }

    /// [`Self::test`], returning the sides of the kernel's `tri_certify` and `closest_test`
    /// it took ([`tri::Branch`] bits; fast mode is what the kernels run).
    #[inline]
    pub fn test_traced(&mut self, r: &RayPre, verts: &[f32; 9], prim: i32) -> u8 {
        let mut path = 0;
        match self.decide(r, verts, prim, &mut path) {
            Decision::No => {}
            Decision::Kept { lo, hi, u, v } => self.keep(verts, prim, lo, hi, u, v),
            Decision::Undecided(lo) => {
                self.rare += 1;
                if self.fast {
                    if closer(lo, prim, self.undecided) {
                        self.undecided = (lo, prim);
                        path |= tri::Branch::Note.bit();
                    }
                } else {
                    self.decide_exactly(r, verts, prim);
                }
            }
        }
        path
    }

    fn keep(&mut self, verts: &[f32; 9], prim: i32, lo: f32, hi: f32, u: f32, v: f32) {
        (self.t, self.lo, self.prim, self.u, self.v) = (hi, lo, prim, u, v);
        self.best_verts = *verts;
    }

    /// Exact mode: the triangle's exact crossing in `[tmin, tmax]`, against the best's; kept
    /// if nearer (equal: lower prim), with t' = the certified upper bound where fp32 certifies
    /// its crossing in range, else s rounded up.
    fn decide_exactly(&mut self, r: &RayPre, verts: &[f32; 9], prim: i32) {
        let Some(x) = exact::crossing_in(r, verts) else { return };
        if self.prim != i32::MAX {
            let best = exact::crossing_in(r, &self.best_verts).expect("the best hit is crossed");
            match x.s.cmp_ratio(&best.s) {
                std::cmp::Ordering::Less => {}
                std::cmp::Ordering::Equal if prim < self.prim => {}
                _ => return,
            }
        }
        let c = tri::certify(r, verts);
        let (lo, hi) = c.bounds();
        match c {
            tri::Cert::Hit { u, v, .. } if lo >= r.tmin && hi <= r.tmax => self.keep(verts, prim, lo, hi, u, v),
            _ => {
                let t = x.s.round_up();
                let lo = super::exact::next_down(t);
                self.keep(verts, prim, lo, t, x.u.approx_f32(), x.v.approx_f32());
            }
        }
    }

    /// Fast mode: an undecided test might come before the best (the ray is to be re-traced).
    pub fn flagged(&self) -> bool {
        self.fast && closer(self.undecided.0, self.undecided.1, (self.t, self.prim))
    }

    /// The ray's hit: [`PRIM_FLAGGED`] for a flagged ray.
    pub fn hit(&self) -> Hit {
        if self.flagged() {
            Hit { t: 0.0, prim: PRIM_FLAGGED, u: 0.0, v: 0.0 }
        } else if self.prim == i32::MAX {
            Hit::MISS
        } else {
            Hit { t: self.t, prim: self.prim, u: self.u, v: self.v }
        }
    }
}

/// Replaces each flagged hit of `hits` (`Hit::is_flagged`) by `exact` of its ray, on every
/// core; returns how many there were.
pub fn resolve_flagged(rays: &[Ray], hits: &mut [Hit], exact: impl Fn(&Ray) -> Hit + Sync) -> usize {
    use rayon::prelude::*;
    let flagged: Vec<usize> = (0..hits.len()).filter(|&i| hits[i].is_flagged()).collect();
    let fixed: Vec<Hit> = flagged.par_iter().map(|&i| exact(&rays[i])).collect();
    for (&i, h) in flagged.iter().zip(fixed) {
        hits[i] = h;
    }
    flagged.len()
}

/// `(t, prim)` comes before `best` in the closest-hit order (smaller t; equal t, lower prim).
fn closer(t: f32, prim: i32, best: (f32, i32)) -> bool {
    t < best.0 || (t == best.0 && prim < best.1)
}
