//! Secondary rays from primary hits: ambient occlusion (short) and diffuse (unbounded),
//! cosine-weighted over the hemisphere of each hit's surface.

use crate::base::{Hit, Ray, Rng};
use crate::scene::Scene;
use glam::Vec3;

/// Default ao ray length as a fraction of the scene diagonal.
pub const AO_LENGTH: f32 = 0.1;
/// Offset of secondary ray origins along the surface normal, as a fraction of the diagonal.
pub const SURFACE_OFFSET: f32 = 1e-5;

/// Cosine-weighted hemisphere rays from the primary hits (one per hit, in primary-ray order, so
/// neighbouring rays come from neighbouring pixels), on the
/// side of the surface the primary ray came from. `length`: `Some(fraction of the scene
/// diagonal)` for ao, `None` (unbounded) for diffuse.
pub fn secondary(scene: &Scene, primary: &[Ray], hits: &[Hit], seed: u64, length: Option<f32>) -> Vec<Ray> {
    let diag = scene.bounds.diagonal();
    let tmax = length.map_or(f32::INFINITY, |f| f * diag);
    let mut out = Vec::new();
    for (i, (r, h)) in primary.iter().zip(hits).enumerate() {
        if h.prim < 0 {
            continue;
        }
        // The hit point from its barycentrics, on the triangle: the hit's t' is an upper bound
        // of the crossing (docs/layouts.md, "The closest-hit rule"), so o + t'·d may lie behind
        // the surface by more than the offset below.
        let tri = &scene.tris[h.prim as usize];
        let p = tri[0] * (1.0 - h.u - h.v) + tri[1] * h.u + tri[2] * h.v;
        let mut n = scene.normal(h.prim as usize).normalize_or_zero();
        if n == Vec3::ZERO {
            continue;
        }
        if n.dot(r.d()) > 0.0 {
            n = -n;
        }
        let mut rng = Rng::new(seed.wrapping_mul(0x10_0000_01B3).wrapping_add(i as u64));
        let (r1, r2) = (rng.next_f32(), rng.next_f32());
        let phi = 2.0 * std::f32::consts::PI * r1;
        let rad = r2.sqrt();
        let local = Vec3::new(rad * phi.cos(), rad * phi.sin(), (1.0 - r2).max(0.0).sqrt());
        let (t, b) = n.any_orthonormal_pair();
        let d = (t * local.x + b * local.y + n * local.z).normalize();
        out.push(Ray::new(p + n * (SURFACE_OFFSET * diag), d, 0.0, tmax));
    }
    out
}
