//! What the binned SAH build ([`super::build`]) and its node split ([`super::split`]) share:
//! the builder's SIMD box, the SAH's constants and the bounds of a range of references.

use crate::base::Aabb;
use glam::Vec3A;
use rayon::prelude::*;

/// SIMD box used inside the builder.
#[derive(Clone, Copy, Debug)]
pub(super) struct Bx {
    pub(super) min: Vec3A,
    pub(super) max: Vec3A,
}

impl Bx {
    pub(super) const EMPTY: Bx = Bx { min: Vec3A::splat(f32::INFINITY), max: Vec3A::splat(f32::NEG_INFINITY) };
    #[inline(always)]
    pub(super) fn union(&self, o: &Bx) -> Bx {
        Bx { min: self.min.min(o.min), max: self.max.max(o.max) }
    }
    #[inline(always)]
    pub(super) fn grow(&mut self, p: Vec3A) {
        self.min = self.min.min(p);
        self.max = self.max.max(p);
    }
    #[inline(always)]
    pub(super) fn area(&self) -> f32 {
        let d = (self.max - self.min).max(Vec3A::ZERO);
        2.0 * (d.x * d.y + d.y * d.z + d.z * d.x)
    }
    pub(super) fn aabb(&self) -> Aabb {
        Aabb { min: self.min.into(), max: self.max.into() }
    }
}

/// Number of SAH bins per axis (a power of two: `bin_of` masks the bin out of a float's bits).
pub const BINS: usize = 16;
const _: () = assert!(BINS.is_power_of_two() && SMALL <= 16);
/// Largest leaf; also bounded by the 4-bit count in the encoded child references.
pub const MAX_LEAF: usize = 8;
/// SAH cost of one node traversal relative to one triangle test.
pub const C_TRAV: f32 = 1.0;

/// A triangle's box, partitioned in place beside its id (`prims`) so every pass over a node's
/// triangles reads memory in order.
pub(super) type Ref = Bx;

/// Ranges above this many triangles have their bounds gathered in parallel.
pub(super) const PAR_BOUNDS: usize = 1 << 17;

/// Chunk of triangles one parallel bounds task takes.
pub(super) const PAR_CHUNK: usize = 1 << 15;

/// Nodes of at most this many triangles find the binned split by sorting their bin keys
/// (same candidates, same costs, no bin arrays to clear and sweep).
pub(super) const SMALL: usize = 16;

/// Nodes of at least this many triangles choose their split from the bins of an even sample of
/// about `SAMPLES` of them (every (n / SAMPLES)-th in their current order); the partition then
/// gathers both sides' boxes. The top levels bin a few thousand triangles instead of millions.
pub(super) const SAMPLE_FROM: usize = 1 << 16;

pub(super) const SAMPLES: usize = 1 << 13;

pub(super) fn range_bounds(refs: &[Ref]) -> (Bx, Bx) {
    let f = |(b, mut c): (Bx, Bx), r: &Ref| {
        c.grow(r.min + r.max);
        (b.union(r), c)
    };
    let (b, c2) = if refs.len() >= PAR_BOUNDS {
        refs.par_chunks(PAR_CHUNK)
            .map(|ch| ch.iter().fold((Bx::EMPTY, Bx::EMPTY), f))
            .reduce(|| (Bx::EMPTY, Bx::EMPTY), |a, b| (a.0.union(&b.0), a.1.union(&b.1)))
    } else {
        refs.iter().fold((Bx::EMPTY, Bx::EMPTY), f)
    };
    (b, half(c2))
}

/// Centroid bounds are gathered as min + max (twice the centroid); halved once per node.
pub(super) fn half(c2: Bx) -> Bx {
    Bx { min: c2.min * 0.5, max: c2.max * 0.5 }
}
