//! The fp32 ray set-up and the conservative fp32 slab test (Ize 2013) every layout's root
//! box and the `f32` layout's child boxes use; the kernels' `ray.glsl` and `box.glsl` mirror it.

use super::ray::Ray;
use glam::Vec3;

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
        let kz = super::geom::max_abs_axis(d);
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

/// The relative widening of the fp32 slab test's entry and exit (2⁻²⁰; `glsl/box.glsl` gets it
/// from the generated header).
pub const MARGIN32: f32 = 1.0 / 1_048_576.0;

/// Multiplies a computed ray parameter so it becomes a lower bound of the exact one
/// (relative error allowance 2⁻²⁰ ≫ the 2γ₃ of Ize 2013). NaN stays NaN.
#[inline]
pub fn lower32(t: f32) -> f32 {
    t * if t > 0.0 { 1.0 - MARGIN32 } else { 1.0 + MARGIN32 }
}

/// Upper-bound counterpart of [`lower32`].
#[inline]
pub fn upper32(t: f32) -> f32 {
    t * if t > 0.0 { 1.0 + MARGIN32 } else { 1.0 - MARGIN32 }
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

/// Exits beyond this parameter count as this (2¹²⁷): a computed exit that overflowed to +inf
/// then still bounds the exact one from below.
pub const HIT_CAP: f32 = f32::from_bits(0x7f00_0000);

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
