//! The CPU reference: one traversal skeleton generic over the layout and the packet width
//! ([`traverse`]), plus brute force. These are the oracles every GPU variant is compared with.
//!
//! Rules shared by every layout (and by the kernels):
//! - Triangle tests are fp32 world space, watertight (Woop, Benthin, Wald 2013, with the
//!   paper's fp64 fallback when an edge function is exactly zero), accepting
//!   `tmin <= t <= t_closest`.
//! - Closest-hit ties (bit-identical t) go to the lower `prim`, so results never depend on
//!   traversal order and variants compare ray for ray without tolerance.
//! - Box tests are conservative (never reject a box the exact ray touches), so a traversal
//!   returns exactly the brute-force closest hit.

pub mod brute;
pub mod traverse;
pub mod tri;

use crate::glsl_struct;
use crate::rays::Ray;
use glam::Vec3;

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

/// Per-ray constants shared by the fp32 box and triangle tests.
#[derive(Clone, Copy, Debug)]
pub struct RayPre {
    pub o: Vec3,
    /// Direction with zero and subnormal components replaced by +0.
    pub d: Vec3,
    pub inv: Vec3,
    pub tmin: f32,
    pub tmax: f32,
    pub kx: usize,
    pub ky: usize,
    pub kz: usize,
    pub sx: f32,
    pub sy: f32,
    pub sz: f32,
}

impl RayPre {
    pub fn new(r: &Ray) -> RayPre {
        // Subnormal components are flushed to +0 so 1/d is finite or +inf.
        let d = Vec3::from(r.dir.map(|c| if c.abs() < f32::MIN_POSITIVE { 0.0 } else { c }));
        let kz = crate::geom::max_abs_axis(d);
        let mut kx = (kz + 1) % 3;
        let mut ky = (kx + 1) % 3;
        if d[kz] < 0.0 {
            std::mem::swap(&mut kx, &mut ky);
        }
        RayPre {
            o: r.o(),
            d,
            inv: Vec3::ONE / d,
            tmin: r.tmin,
            tmax: r.tmax,
            kx,
            ky,
            kz,
            sx: d[kx] / d[kz],
            sy: d[ky] / d[kz],
            sz: 1.0 / d[kz],
        }
    }
}

/// The closest hit so far. `prim == i32::MAX` until something is hit, so a hit exactly at
/// `tmax` is accepted like any other (`t <= tmax`).
#[derive(Clone, Copy, Debug)]
pub struct Closest {
    pub t: f32,
    pub prim: i32,
    pub u: f32,
    pub v: f32,
}

impl Closest {
    pub fn new(tmax: f32) -> Closest {
        Closest { t: tmax, prim: i32::MAX, u: 0.0, v: 0.0 }
    }
    /// Tests triangle `verts` with public id `prim` and keeps it if closer (ties: lower prim).
    #[inline]
    pub fn test(&mut self, r: &RayPre, verts: &[f32; 9], prim: i32) {
        if let Some((t, u, v)) = tri::intersect(r, verts) {
            if t >= r.tmin && (t < self.t || (t == self.t && prim < self.prim)) {
                *self = Closest { t, prim, u, v };
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

/// Multiplies a computed ray parameter so it becomes a lower bound of the exact one
/// (relative error allowance 2⁻²⁰ ≫ the 2γ₃ of Ize 2013). NaN stays NaN.
#[inline]
pub fn lower32(t: f32) -> f32 {
    t * if t > 0.0 { 1.0 - 1.0 / 1_048_576.0 } else { 1.0 + 1.0 / 1_048_576.0 }
}

/// Upper-bound counterpart of [`lower32`].
#[inline]
pub fn upper32(t: f32) -> f32 {
    t * if t > 0.0 { 1.0 + 1.0 / 1_048_576.0 } else { 1.0 - 1.0 / 1_048_576.0 }
}

/// Conservative fp32 slab test of the ray line against a world box over `[t0, t1]`.
/// An axis with a zero direction component constrains nothing when the origin lies in the
/// slab (faces included) and rejects the box otherwise; no NaN is ever formed, so the shader's
/// min/max and comparisons cannot disagree with this code.
/// Returns the (lowered) entry and (raised) exit; the box is hit when `near <= far`.
#[inline]
pub fn slab32(r: &RayPre, lo: [f32; 3], hi: [f32; 3], t0: f32, t1: f32) -> (f32, f32) {
    let mut near = t0;
    let mut far = t1;
    for a in 0..3 {
        let (n, f) = if r.d[a] == 0.0 {
            if r.o[a] >= lo[a] && r.o[a] <= hi[a] {
                (f32::NEG_INFINITY, f32::INFINITY)
            } else {
                (f32::INFINITY, f32::NEG_INFINITY)
            }
        } else {
            let x = (lo[a] - r.o[a]) * r.inv[a];
            let y = (hi[a] - r.o[a]) * r.inv[a];
            (lower32(x.min(y)), upper32(x.max(y)))
        };
        near = near.max(n);
        far = far.min(f);
    }
    (near, far)
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

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(20000))]

        /// The fp32 slab test never rejects a box that the exact (f64) ray reaches at a
        /// parameter inside the interval.
        #[test]
        fn slab32_never_misses(
            o in prop::array::uniform3(-100.0f32..100.0),
            d in prop::array::uniform3(prop_oneof![Just(0.0f32), -1.0f32..1.0, -1e-6f32..1e-6]),
            s in 0.0f64..300.0,
            ext in prop::array::uniform3(prop_oneof![Just(0.0f32), 0.0f32..1e-4, 0.0f32..10.0]),
        ) {
            prop_assume!(d.iter().any(|&x| x != 0.0));
            let x = [0, 1, 2].map(|a| o[a] as f64 + s * d[a] as f64);
            // The box contains the exact point in f32 (round outward).
            let lo = [0, 1, 2].map(|a| { let v = (x[a] - ext[a] as f64) as f32; if v as f64 > x[a] - ext[a] as f64 { v.next_down() } else { v } });
            let hi = [0, 1, 2].map(|a| { let v = (x[a] + ext[a] as f64) as f32; if (v as f64) < x[a] + ext[a] as f64 { v.next_up() } else { v } });
            let r = RayPre::new(&Ray::new(Vec3::from(o), Vec3::from(d), 0.0, f32::INFINITY));
            let (near, far) = slab32(&r, lo, hi, 0.0, f32::INFINITY);
            prop_assert!(near as f64 <= s && s <= far as f64, "s={} not in [{}, {}]", s, near, far);
        }
    }
}
