//! Exact geometry on fp32 inputs: where the *exact* ray `o + s·d` (its fp32 origin and
//! direction taken as exact numbers) meets a closed triangle given by its fp32 vertices,
//! decided and placed with integer arithmetic — no rounding anywhere. The oracle of "true"
//! hits (docs/layouts.md, "The closest-hit rule") and the rare path of the certified triangle test
//! ([`super::tri::certify`]), which defers to it whenever fp32 cannot decide.
//!
//! Every fp32 value is an integer multiple of 2⁻¹⁴⁹, so each is held as that integer
//! ([`big`]); differences, the three edge determinants and the crossing's parameter are then
//! exact integers and one exact ratio.

use super::slab::RayPre;
use num_bigint::{BigInt, Sign};
use std::cmp::Ordering;

/// `x · 2¹⁴⁹` as an exact integer (x finite).
pub fn big(x: f32) -> BigInt {
    let b = x.to_bits();
    let exp = ((b >> 23) & 0xff) as i32;
    let frac = (b & 0x7f_ffff) as u64;
    let (m, e) = if exp == 0 { (frac, 0) } else { (frac | 0x80_0000, exp - 1) };
    let v = BigInt::from(m) << e as usize;
    if b >> 31 == 1 {
        -v
    } else {
        v
    }
}

/// An exact non-negative-denominator ratio `n / d` (d > 0).
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Ratio {
    pub n: BigInt,
    pub d: BigInt,
}

impl Ratio {
    fn new(n: BigInt, d: BigInt) -> Ratio {
        if d.sign() == Sign::Minus {
            Ratio { n: -n, d: -d }
        } else {
            Ratio { n, d }
        }
    }
    /// The order of this ratio against the fp32 value `x` (finite or ±inf).
    pub fn cmp_f32(&self, x: f32) -> Ordering {
        if x == f32::INFINITY {
            return Ordering::Less;
        }
        if x == f32::NEG_INFINITY {
            return Ordering::Greater;
        }
        // n/d vs x = big(x)/2^149  ⇔  n·2^149 vs big(x)·d
        (&self.n << 149usize).cmp(&(big(x) * &self.d))
    }
    /// An approximation in f64 (exact numerators and denominators of any size, scaled first).
    pub fn to_f64(&self) -> f64 {
        let shift = self.n.bits().max(self.d.bits()).saturating_sub(1000);
        let (n, d) = (&self.n >> shift as usize, &self.d >> shift as usize);
        use num_traits::ToPrimitive;
        n.to_f64().unwrap_or(f64::NAN) / d.to_f64().unwrap_or(f64::NAN)
    }
    /// The smallest f32 not below this ratio (+inf beyond f32's range).
    pub fn round_up(&self) -> f32 {
        let mut c = self.to_f64() as f32;
        if c.is_nan() {
            c = 0.0;
        }
        while self.cmp_f32(c) == Ordering::Greater {
            c = next_up(c);
        }
        loop {
            let down = next_down(c);
            if down == c || self.cmp_f32(down) == Ordering::Greater {
                return c;
            }
            c = down;
        }
    }
    /// The f32 nearest this ratio, through f64 (within one f32 ulp).
    /// The order of two exact values.
    pub fn cmp_ratio(&self, o: &Ratio) -> Ordering {
        (&self.n * &o.d).cmp(&(&o.n * &self.d))
    }

    pub fn approx_f32(&self) -> f32 {
        self.to_f64() as f32
    }
}

/// The next f32 up (`f32::next_up`, spelled for the crate's minimum Rust).
pub fn next_up(x: f32) -> f32 {
    if x.is_nan() || x == f32::INFINITY {
        return x;
    }
    if x == 0.0 {
        return f32::from_bits(1);
    }
    let b = x.to_bits();
    f32::from_bits(if x > 0.0 { b + 1 } else { b - 1 })
}

/// The next f32 down.
pub fn next_down(x: f32) -> f32 {
    -next_up(-x)
}

/// Where the exact ray meets a triangle, exactly.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Crossing {
    /// The parameter s of the crossing point `o + s·d`.
    pub s: Ratio,
    /// The barycentrics of vertices 1 and 2 at that point.
    pub u: Ratio,
    pub v: Ratio,
}

/// `det[p, q, d]` of three exact vectors.
fn det3(p: &[BigInt; 3], q: &[BigInt; 3], d: &[BigInt; 3]) -> BigInt {
    &p[0] * (&q[1] * &d[2] - &q[2] * &d[1]) - &p[1] * (&q[0] * &d[2] - &q[2] * &d[0])
        + &p[2] * (&q[0] * &d[1] - &q[1] * &d[0])
}

/// Whether a triangle's three vertices lie exactly on one line (or coincide): zero area, the
/// case [`crossing`] never crosses (its determinant is zero for every ray), so no ray hits it.
/// Decided in f64 where its cross product is clearly not zero, else exactly.
pub fn collinear(v: &[f32; 9]) -> bool {
    let p = |k: usize| [0, 1, 2].map(|a| v[3 * k + a] as f64);
    let (a, b, c) = (p(0), p(1), p(2));
    let (e, f) = ([0, 1, 2].map(|i| b[i] - a[i]), [0, 1, 2].map(|i| c[i] - a[i]));
    let n = [e[1] * f[2] - e[2] * f[1], e[2] * f[0] - e[0] * f[2], e[0] * f[1] - e[1] * f[0]];
    let size = |x: [f64; 3]| x.iter().map(|y| y.abs()).fold(0.0, f64::max);
    // f64's differences and products are within 2^-50 of the exact ones relative to this.
    let scale = size(e) * size(f);
    if n.iter().any(|x| x.abs() > scale * 1e-12) {
        return false;
    }
    let q = |k: usize| [0, 1, 2].map(|i| big(v[3 * k + i]));
    let (a, b, c) = (q(0), q(1), q(2));
    let (e, f) = ([0, 1, 2].map(|i| &b[i] - &a[i]), [0, 1, 2].map(|i| &c[i] - &a[i]));
    [(1, 2), (2, 0), (0, 1)].iter().all(|&(i, j)| &e[i] * &f[j] == &e[j] * &f[i])
}

/// The crossing of the exact ray line (`r.o`, `r.d`: the direction as the test uses it, with
/// zero and subnormal components flushed to +0) with the closed triangle `v` (edges and
/// vertices included), or `None` where it does not meet it or meets it only edge-on (the line
/// parallel to the triangle's plane, or a triangle of zero area). The signs of the three edge
/// functions are those of the watertight test's `U`, `V`, `W` computed without rounding
/// (`det[C, B, d]`, `det[A, C, d]`, `det[B, A, d]` with `A = v0 − o`, …, a positive multiple of
/// the sheared 2×2 determinants), so this is the watertight test in exact arithmetic.
pub fn crossing(r: &RayPre, v: &[f32; 9]) -> Option<Crossing> {
    let o = [big(r.o.x), big(r.o.y), big(r.o.z)];
    let vert = |k: usize| -> [BigInt; 3] { [0, 1, 2].map(|a| big(v[3 * k + a]) - &o[a]) };
    let (a, b, c) = (vert(0), vert(1), vert(2));
    let d = [big(r.d.x), big(r.d.y), big(r.d.z)];
    let eu = det3(&c, &b, &d);
    let ev = det3(&a, &c, &d);
    let ew = det3(&b, &a, &d);
    let neg = [&eu, &ev, &ew].iter().any(|x| x.sign() == Sign::Minus);
    let pos = [&eu, &ev, &ew].iter().any(|x| x.sign() == Sign::Plus);
    if neg && pos {
        return None;
    }
    let det = &eu + &ev + &ew;
    if det.sign() == Sign::NoSign {
        return None;
    }
    // The crossing point is (U·A + V·B + W·C)/det relative to o; its coordinate on the
    // direction's largest axis over that axis's d gives s.
    let kz = r.kz;
    let num = &eu * &a[kz] + &ev * &b[kz] + &ew * &c[kz];
    let s = Ratio::new(num, &d[kz] * &det);
    Some(Crossing { s, u: Ratio::new(ev, det.clone()), v: Ratio::new(ew, det) })
}

/// The crossing if it lies in the ray's interval `[tmin, tmax]`.
pub fn crossing_in(r: &RayPre, v: &[f32; 9]) -> Option<Crossing> {
    crossing(r, v).filter(|c| c.s.cmp_f32(r.tmin) != Ordering::Less && c.s.cmp_f32(r.tmax) != Ordering::Greater)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::base::Ray;
    use glam::Vec3;

    #[test]
    fn collinear_is_exact() {
        assert!(collinear(&[0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 2.0, 0.0, 0.0]));
        assert!(collinear(&[0.1, 0.2, 0.3, 0.1, 0.2, 0.3, 5.0, 6.0, 7.0]), "two vertices the same");
        assert!(!collinear(&[0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0, 0.0]));
        // fp32's cross product underflows to zero; the triangle has area and can be hit.
        let t = 1e-25f32;
        assert!(!collinear(&[0.0, 0.0, 0.0, t, 0.0, 0.0, 0.0, t, 0.0]));
        // One ulp off the line.
        let y = f32::from_bits(1);
        assert!(!collinear(&[0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 2.0, y, 0.0]));
    }

    #[test]
    fn big_is_exact() {
        assert_eq!(big(1.0), BigInt::from(1) << 149usize);
        assert_eq!(big(-0.5), -(BigInt::from(1) << 148usize));
        assert_eq!(big(f32::from_bits(1)), BigInt::from(1));
        assert_eq!(big(0.0), BigInt::from(0));
    }

    #[test]
    fn crossing_of_a_plain_ray() {
        let tri = [0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0, 0.0];
        let r = RayPre::new(&Ray::new(Vec3::new(0.25, 0.5, 1.0), Vec3::new(0.0, 0.0, -2.0), 0.0, f32::INFINITY));
        let c = crossing(&r, &tri).unwrap();
        assert_eq!(c.s.round_up(), 0.5);
        assert_eq!((c.u.approx_f32(), c.v.approx_f32()), (0.25, 0.5));
        // through a vertex and an edge: closed triangle
        let r = RayPre::new(&Ray::new(Vec3::new(1.0, 0.0, 3.0), Vec3::new(0.0, 0.0, -1.0), 0.0, f32::INFINITY));
        assert_eq!(crossing(&r, &tri).unwrap().s.round_up(), 3.0);
        let r = RayPre::new(&Ray::new(Vec3::new(0.5, 0.5, 3.0), Vec3::new(0.0, 0.0, -1.0), 0.0, f32::INFINITY));
        assert!(crossing(&r, &tri).is_some());
        let r = RayPre::new(&Ray::new(Vec3::new(0.5, 0.500001, 3.0), Vec3::new(0.0, 0.0, -1.0), 0.0, f32::INFINITY));
        assert!(crossing(&r, &tri).is_none());
        // zero area never crosses
        let flat = [0.0, 0.0, 0.0, 1.0, 1.0, 0.0, 2.0, 2.0, 0.0];
        let r = RayPre::new(&Ray::new(Vec3::new(1.0, 1.0, 3.0), Vec3::new(0.0, 0.0, -1.0), 0.0, f32::INFINITY));
        assert!(crossing(&r, &flat).is_none());
    }

    #[test]
    fn round_up_is_the_smallest_f32_not_below() {
        for (n, d) in [(1i64, 3i64), (-1, 3), (2, 1), (0, 5), (7, 1 << 40)] {
            let r = Ratio::new(BigInt::from(n), BigInt::from(d));
            let x = r.round_up();
            assert_ne!(r.cmp_f32(x), Ordering::Greater, "{n}/{d}");
            assert_eq!(r.cmp_f32(next_down(x)), Ordering::Greater, "{n}/{d}");
        }
    }
}
