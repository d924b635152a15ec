//! Grazing rays: the places where reduced-precision box tests are most fragile.

use crate::base::{validate, Aabb, Ray, Rng};
use crate::scene::Scene;
use glam::Vec3;

/// Rays aimed where reduced-precision box tests are most fragile: axis-parallel rays lying
/// exactly in box face planes, rays through box edges and corners, rays starting inside
/// boxes, rays with one or two zero direction components, rays along triangle edges and
/// through vertices. `boxes` are world-space node boxes (e.g. from the binary BVH).
pub fn grazing(scene: &Scene, boxes: &[Aabb], count: usize, seed: u64) -> Vec<Ray> {
    let mut rng = Rng::new(seed);
    let diag = scene.bounds.diagonal().max(1e-6);
    let far = diag * 2.0;
    let mut out = Vec::with_capacity(count);
    let pick = |rng: &mut Rng, n: usize| (rng.next_u64() % n as u64) as usize;
    let axes = [Vec3::X, Vec3::Y, Vec3::Z];
    while out.len() < count {
        let b = boxes[pick(&mut rng, boxes.len())];
        let corner = |m: u64| {
            Vec3::new(
                if m & 1 != 0 { b.max.x } else { b.min.x },
                if m & 2 != 0 { b.max.y } else { b.min.y },
                if m & 4 != 0 { b.max.z } else { b.min.z },
            )
        };
        let kind = rng.next_u64() % 8;
        let ray = match kind {
            0 => {
                // Axis-parallel ray lying exactly in a face plane, entering from outside.
                let a = pick(&mut rng, 3);
                let c = corner(rng.next_u64());
                let mut o = c;
                let s = if rng.next_u64() & 1 == 0 { 1.0 } else { -1.0 };
                o[a] -= s * far;
                let mut d = Vec3::ZERO;
                d[a] = s;
                Ray::new(o, d, 0.0, f32::INFINITY)
            }
            1 => {
                // Ray through a box corner from a random outside point.
                let c = corner(rng.next_u64());
                let o = c + Vec3::new(rng.next_f32() - 0.5, rng.next_f32() - 0.5, rng.next_f32() - 0.5)
                    .normalize_or_zero()
                    * far;
                Ray::new(o, c - o, 0.0, f32::INFINITY)
            }
            2 => {
                // Ray through the midpoint of a box edge.
                let c0 = corner(rng.next_u64());
                let a = pick(&mut rng, 3);
                let mut c1 = c0;
                c1[a] = if c0[a] == b.min[a] { b.max[a] } else { b.min[a] };
                let m = (c0 + c1) * 0.5;
                let o = m + Vec3::new(rng.next_f32() - 0.5, rng.next_f32() - 0.5, rng.next_f32() - 0.5)
                    .normalize_or_zero()
                    * far;
                Ray::new(o, m - o, 0.0, f32::INFINITY)
            }
            3 => {
                // Ray starting inside a box, random direction.
                let o = b.min + (b.max - b.min) * Vec3::new(rng.next_f32(), rng.next_f32(), rng.next_f32());
                let d = Vec3::new(rng.next_f32() - 0.5, rng.next_f32() - 0.5, rng.next_f32() - 0.5);
                Ray::new(o, if d == Vec3::ZERO { Vec3::X } else { d }, 0.0, f32::INFINITY)
            }
            4 => {
                // One zero direction component, skimming a face plane.
                let a = pick(&mut rng, 3);
                let mut o = corner(rng.next_u64());
                let mut d = Vec3::new(rng.next_f32() - 0.5, rng.next_f32() - 0.5, rng.next_f32() - 0.5);
                d[a] = 0.0;
                if d == Vec3::ZERO {
                    d[(a + 1) % 3] = 1.0;
                }
                o -= d * far;
                Ray::new(o, d, 0.0, f32::INFINITY)
            }
            5 => {
                // Along a triangle edge, starting outside the edge.
                let t = &scene.tris[pick(&mut rng, scene.tris.len())];
                let e = pick(&mut rng, 3);
                let (p, q) = (t[e], t[(e + 1) % 3]);
                let d = q - p;
                if d == Vec3::ZERO {
                    continue;
                }
                Ray::new(p - d * 0.5, d, 0.0, f32::INFINITY)
            }
            6 => {
                // Axis-parallel ray through a triangle vertex.
                let t = &scene.tris[pick(&mut rng, scene.tris.len())];
                let v = t[pick(&mut rng, 3)];
                let a = pick(&mut rng, 3);
                let s = if rng.next_u64() & 1 == 0 { 1.0 } else { -1.0 };
                let mut o = v;
                o[a] -= s * far;
                Ray::new(o, axes[a] * s, 0.0, f32::INFINITY)
            }
            _ => {
                // Tiny box-sized ray from just outside a face, nearly parallel to it.
                let a = pick(&mut rng, 3);
                let mut o = b.center();
                o[a] = b.min[a] - (b.max[a] - b.min[a]) * 1e-3;
                let mut d = Vec3::new(rng.next_f32() - 0.5, rng.next_f32() - 0.5, rng.next_f32() - 0.5);
                d[a] = 1e-6 * d.length().max(1e-3);
                if d == Vec3::ZERO {
                    continue;
                }
                Ray::new(o, d, 0.0, f32::INFINITY)
            }
        };
        if validate(std::slice::from_ref(&ray), "grazing").is_ok() {
            out.push(ray);
        }
    }
    out
}
