//! What a traversal returns: the closest hit of each ray ([`Hit`], the closest-hit rule in
//! [`Closest`]), its work counters ([`Counters`]) and how far two results agree
//! ([`agreement`]).
//!
//! Rules shared by every layout and kernel:
//! - Closest-hit ties (bit-identical t) go to the lower `prim`, so results never depend on
//!   traversal order and variants compare ray for ray without tolerance.
//! - Box tests are conservative (never reject a box the exact ray touches), so a traversal
//!   returns exactly the brute-force closest hit.

use super::slab::RayPre;
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
