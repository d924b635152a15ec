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
}
