//! Watertight ray–triangle test (Woop, Benthin, Wald 2013, JCGT 2(1)), fp32 with the paper's
//! fp64 recomputation of the edge functions when one of them is exactly zero.

use super::slab::RayPre;

/// Returns `(t, u, v)` where the ray's line meets the triangle (`t` unchecked against the
/// ray's interval), or `None`. Degenerate triangles (zero determinant) never hit.
#[inline]
pub fn intersect(r: &RayPre, v: &[f32; 9]) -> Option<(f32, f32, f32)> {
    let mut a = [v[0] - r.o.x, v[1] - r.o.y, v[2] - r.o.z];
    let mut b = [v[3] - r.o.x, v[4] - r.o.y, v[5] - r.o.z];
    let mut c = [v[6] - r.o.x, v[7] - r.o.y, v[8] - r.o.z];
    // Huge coordinates (beyond 2^40 from the ray origin): the edge functions (products of two
    // coordinates) and t's numerator (of three) would overflow fp32, so the translated
    // vertices are scaled by a power of two (exact) and t scaled back. Never taken below 2^40,
    // so ordinary scenes compute exactly as without it.
    let m = a.iter().chain(&b).chain(&c).fold(0f32, |m, x| m.max(x.abs()));
    let mut back = 1.0f32;
    if m > BIG_COORD {
        let shift = ((m.to_bits() >> 23) & 0xff) as i32 - 127 - 39;
        let down = f32::from_bits(((127 - shift) as u32) << 23);
        back = f32::from_bits(((127 + shift) as u32) << 23);
        for x in a.iter_mut().chain(b.iter_mut()).chain(c.iter_mut()) {
            *x *= down;
        }
    }
    let (kx, ky, kz) = (r.kx, r.ky, r.kz);
    let ax = a[kx] - r.sx * a[kz];
    let ay = a[ky] - r.sy * a[kz];
    let bx = b[kx] - r.sx * b[kz];
    let by = b[ky] - r.sy * b[kz];
    let cx = c[kx] - r.sx * c[kz];
    let cy = c[ky] - r.sy * c[kz];
    let mut u = cx * by - cy * bx;
    let mut vv = ax * cy - ay * cx;
    let mut w = bx * ay - by * ax;
    if u == 0.0 || vv == 0.0 || w == 0.0 {
        let (ax, ay, bx, by, cx, cy) = (ax as f64, ay as f64, bx as f64, by as f64, cx as f64, cy as f64);
        u = (cx * by - cy * bx) as f32;
        vv = (ax * cy - ay * cx) as f32;
        w = (bx * ay - by * ax) as f32;
    }
    if (u < 0.0 || vv < 0.0 || w < 0.0) && (u > 0.0 || vv > 0.0 || w > 0.0) {
        return None;
    }
    let det = u + vv + w;
    if det == 0.0 {
        return None;
    }
    let az = r.sz * a[kz];
    let bz = r.sz * b[kz];
    let cz = r.sz * c[kz];
    let t = (u * az + vv * bz + w * cz) / det;
    Some((t * back, vv / det, w / det))
}

/// Translated coordinates above this are scaled down before the test (2^40).
pub const BIG_COORD: f32 = 1_099_511_627_776.0;

/// `a·b − c·d` computed in f64 (both products exact there) and rounded to f32 — the test's
/// recomputation of the edge functions when one is zero in fp32 — with 32/64-bit integer
/// operations only: a device without `shaderFloat64` computes it this way (`glsl/tri.glsl`,
/// `edge_f64`, the same steps on pairs of 32-bit words), so its hits are an fp64 device's.
/// Equal to `(a as f64 * b as f64 - c as f64 * d as f64) as f32` for finite inputs (tested).
pub fn edge_f64_emulated(a: f32, b: f32, c: f32, d: f32) -> f32 {
    // Each product as sign, m·2^e with m in [2^62, 2^63) (or m = 0): 48 significant bits, 15
    // zero bits below them (room for an aligned operand) and one above (for a carry).
    let product = |x: f32, y: f32, negate: bool| -> (u32, i32, u64) {
        let sign = (x.to_bits() ^ y.to_bits() ^ if negate { 0x8000_0000 } else { 0 }) & 0x8000_0000;
        let (xx, xy) = (x.to_bits() & 0x7fff_ffff, y.to_bits() & 0x7fff_ffff);
        if xx == 0 || xy == 0 {
            return (sign, 0, 0);
        }
        // Significands in [2^23, 2^24) (fp16::significand's steps; base may not import fp16).
        let normalise = |u: u32| -> (u64, i32) {
            let (e, m) = ((u >> 23) as i32, u & 0x7f_ffff);
            if e == 0 {
                let s = m.leading_zeros() as i32 - 8;
                ((m << s) as u64, 1 - s)
            } else {
                ((m | 0x80_0000) as u64, e)
            }
        };
        let ((mx, ex), (my, ey)) = (normalise(xx), normalise(xy));
        let m = mx * my; // in [2^46, 2^48): x·y = m·2^(ex + ey − 300)
        let s = if m < 1 << 47 { 16 } else { 15 };
        (sign, ex + ey - 300 - s, m << s)
    };
    let (s1, e1, m1) = product(a, b, false);
    let (s2, e2, m2) = product(c, d, true);
    if m1 == 0 && m2 == 0 {
        return f32::from_bits(s1 & s2); // −0 only as −0 + −0
    }
    // The larger magnitude first; the smaller aligned to it with a sticky bit (bit 0 lies two
    // places or more below the round bit of every result that has dropped bits).
    let ((sb, eb, mb), (ss, es, ms)) = if m2 == 0 || (m1 != 0 && (e1, m1) >= (e2, m2)) {
        ((s1, e1, m1), (s2, e2, m2))
    } else {
        ((s2, e2, m2), (s1, e1, m1))
    };
    let delta = if ms == 0 { 64 } else { (eb - es) as u32 };
    let small =
        if delta >= 64 { u64::from(ms != 0) } else { (ms >> delta) | u64::from(ms & ((1u64 << delta) - 1) != 0) };
    let mut r = if sb == ss { mb + small } else { mb - small };
    let mut e = eb;
    if r == 0 {
        return 0.0;
    }
    if r >= 1 << 63 {
        r = (r >> 1) | (r & 1);
        e += 1;
    }
    // Round to f64's 53 bits (no f64 subnormal or overflow can come from f32 products).
    let round_at = |r: u64, pos: u32| -> u64 {
        let q = r >> pos;
        let low = r & ((1u64 << pos) - 1);
        let half = 1u64 << (pos - 1);
        if low > half || (low == half && q & 1 == 1) {
            q + 1
        } else {
            q
        }
    };
    let top = 63 - r.leading_zeros() as i32;
    if top > 52 {
        let pos = (top - 52) as u32;
        r = round_at(r, pos) << pos; // a carry to 2^(top + 1) stays below 2^64
    }
    // Then to f32: 24 bits, or fewer where the result is subnormal.
    let top = 63 - r.leading_zeros() as i32;
    let pos = (top - 23).max(-149 - e);
    let mut q = if pos <= 0 {
        r << -pos
    } else if pos > top + 1 {
        0
    } else {
        round_at(r, pos as u32)
    };
    let mut ex = e + pos; // the result is q·2^ex
    if q >= 1 << 24 {
        q >>= 1;
        ex += 1;
    }
    if q >= 1 << 23 {
        let biased = ex + 150;
        if biased >= 255 {
            return f32::from_bits(sb | 0x7f80_0000);
        }
        return f32::from_bits(sb | ((biased as u32) << 23) | (q as u32 & 0x7f_ffff));
    }
    f32::from_bits(sb | q as u32)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::base::Ray;
    use glam::Vec3;

    #[test]
    fn hits_centre_and_reports_barycentrics() {
        let tri = [0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0, 0.0];
        let r = RayPre::new(&Ray::new(Vec3::new(0.25, 0.5, 1.0), Vec3::new(0.0, 0.0, -2.0), 0.0, f32::INFINITY));
        let (t, u, v) = intersect(&r, &tri).unwrap();
        assert_eq!((t, u, v), (0.5, 0.25, 0.5));
    }

    #[test]
    fn shared_edge_is_watertight() {
        // Two triangles sharing the diagonal of a square: rays through the diagonal hit at
        // least one of them.
        let t0 = [0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 1.0, 1.0, 0.0];
        let t1 = [0.0, 0.0, 0.0, 1.0, 1.0, 0.0, 0.0, 1.0, 0.0];
        for i in 1..1000 {
            let x = i as f32 / 1000.0;
            for d in [Vec3::new(0.0, 0.0, -1.0), Vec3::new(-0.3, -0.3, -1.0), Vec3::new(0.37, -0.21, -1.0)] {
                let r = RayPre::new(&Ray::new(Vec3::new(x, x, 0.0) - d, d, 0.0, f32::INFINITY));
                assert!(intersect(&r, &t0).is_some() || intersect(&r, &t1).is_some(), "gap at {x} dir {d}");
            }
        }
    }

    #[test]
    fn degenerate_never_hits() {
        let tri = [0.0, 0.0, 0.0, 1.0, 1.0, 1.0, 2.0, 2.0, 2.0];
        let r = RayPre::new(&Ray::new(Vec3::new(1.0, 1.0, 5.0), Vec3::new(0.0, 0.0, -1.0), 0.0, f32::INFINITY));
        assert!(intersect(&r, &tri).is_none());
    }

    #[test]
    fn emulated_f64_edge_function_equals_the_native_one() {
        let mut x: u64 = 0x853c_49e6_748f_ea9b;
        let mut next = || {
            x ^= x << 13;
            x ^= x >> 7;
            x ^= x << 17;
            x
        };
        let check = |a: f32, b: f32, c: f32, d: f32| {
            let want = (a as f64 * b as f64 - c as f64 * d as f64) as f32;
            let got = edge_f64_emulated(a, b, c, d);
            assert_eq!(got.to_bits(), want.to_bits(), "{a:e}·{b:e} − {c:e}·{d:e}: {got:e} vs {want:e}");
        };
        let near = |v: f32, r: u64| f32::from_bits(v.to_bits().wrapping_add((r % 5) as u32).wrapping_sub(2));
        for i in 0..2_000_000u64 {
            let r = next();
            let (a, b) = (f32::from_bits(r as u32), f32::from_bits((r >> 32) as u32));
            let r2 = next();
            let (c, d) = (f32::from_bits(r2 as u32), f32::from_bits((r2 >> 32) as u32));
            if ![a, b, c, d].iter().all(|v| v.is_finite()) {
                continue;
            }
            // Arbitrary operands (products far apart: sticky bits, double rounding); products
            // that nearly cancel (the case the test recomputes); exponents spread over the
            // subnormal and overflow edges of the f32 result.
            check(a, b, c, d);
            check(a, b, near(a, r2), near(b, r2 >> 8));
            check(a, b, near(b, r2), near(a, r2 >> 8));
            let scale = |v: f32, k: u64| f32::from_bits((v.to_bits() & 0x807f_ffff) | (((k % 254) as u32 + 1) << 23));
            let (sa, sb) = (scale(a, r2 >> 16), scale(b, r2 >> 24));
            check(sa, sb, scale(c, r2 >> 32), scale(d, r2 >> 40));
            check(sa, sb, near(sa, i), near(sb, i >> 3));
            // Exact f32 midpoints less a tiny product: rounds differently in one step.
            check(3.0, 1.0 + f32::EPSILON, near(c, r) * 1e-20, d * 1e-20);
        }
        for (a, b, c, d) in [
            (0.0f32, 1.0f32, 0.0f32, 1.0f32),
            (-0.0, 1.0, 0.0, 1.0),
            (0.0, -1.0, -0.0, -1.0),
            (-0.0, 1.0, -0.0, -1.0),
            (1.0, 1.0, 1.0, 1.0),
            (f32::MAX, f32::MAX, 1.0, 1.0),
            (1e-45, 1e-45, 0.0, 0.0),
            (f32::MIN_POSITIVE, 0.5, 0.0, 7.0),
            (f32::MIN_POSITIVE, 0.5, 1e-45, 1e-45),
            (3.0, 1.0 + f32::EPSILON, 1e-30, 1e-30),
            (3.0, 1.0 + f32::EPSILON, -1e-30, 1e-30),
            (1.0 + f32::EPSILON, 1.0 - f32::EPSILON / 2.0, 1.0, 1.0),
        ] {
            check(a, b, c, d);
            check(c, d, a, b);
        }
    }
}
