//! The exact re-trace of the rays a fast traversal flagged (`base::hit`, "Fast and exact"):
//! the closest-hit rule in exact mode over the binary BVH — every triangle fp32 cannot decide
//! decided in exact arithmetic — so that a flagged ray costs a traversal, not a brute force.

use super::build::BinaryBvh;
use crate::base::{resolve_flagged, slab32, ClosestTrue, Hit, Ray, RayPre};
use crate::scene::Scene;

impl BinaryBvh {
    /// The closest hit of `ray` under the closest-hit rule in exact mode: what
    /// `Scene::brute_force` gives. Every node box contains its triangles (the build's refit),
    /// the fp32 slab test never rejects a box the exact ray reaches inside `[tmin, best]`, and
    /// the rule's kept t' is at least the exact crossing, so no winning triangle is culled.
    pub fn trace_exact(&self, scene: &Scene, ray: &Ray) -> Hit {
        let r = RayPre::new(ray);
        let mut best = ClosestTrue::new(ray.tmax);
        let mut stack = vec![0usize];
        while let Some(i) = stack.pop() {
            let n = &self.nodes[i];
            let (near, far) = slab32(&r, n.bounds.min.into(), n.bounds.max.into(), r.tmin, best.t);
            if near > far {
                continue;
            }
            if n.is_leaf() {
                for &p in &self.prims[n.first as usize..(n.first + n.count) as usize] {
                    best.test(&r, &scene.verts(p as usize), p as i32);
                }
            } else {
                stack.extend([n.first as usize + 1, n.first as usize]);
            }
        }
        best.hit()
    }

    /// Re-traces the flagged rays of `hits` with [`Self::trace_exact`], in place, on every
    /// core; returns how many there were.
    pub fn resolve(&self, scene: &Scene, rays: &[Ray], hits: &mut [Hit]) -> usize {
        if self.nodes.is_empty() {
            return resolve_flagged(rays, hits, |_| Hit::MISS);
        }
        resolve_flagged(rays, hits, |r| self.trace_exact(scene, r))
    }
}

/// Re-traces the flagged rays of `hits` exactly: through `bin` where there is one, else by
/// the scene's brute force (the same hits either way); returns how many there were.
pub fn resolve(scene: &Scene, bin: Option<&BinaryBvh>, rays: &[Ray], hits: &mut [Hit]) -> usize {
    match bin {
        Some(b) => b.resolve(scene, rays, hits),
        None => scene.resolve(rays, hits),
    }
}

#[cfg(test)]
mod tests {
    use crate::base::{Ray, Rng};
    use crate::scene::Scene;
    use glam::Vec3;

    /// The exact re-trace through the BVH gives the brute force's hits, bit for bit, on rays
    /// aimed at random triangles' vertices, edge midpoints and faces from near and far.
    #[test]
    fn exact_retrace_equals_the_brute_force() {
        let mut rng = Rng::new(0xe4ac7);
        let mut v = || Vec3::new(rng.next_f32(), rng.next_f32(), rng.next_f32()) * 2.0 - 1.0;
        let tris: Vec<[Vec3; 3]> = (0..400)
            .map(|_| {
                let c = v() * 10.0;
                [c + v(), c + v(), c + v()]
            })
            .collect();
        let scene = Scene::from_triangles("random", tris.clone()).unwrap();
        let bin = crate::bvh::build_binary(&scene);
        let mut hits = 0;
        for (i, t) in tris.iter().enumerate() {
            let aim = [t[0], (t[0] + t[1]) * 0.5, (t[0] + t[1] + t[2]) / 3.0][i % 3];
            let o = aim + v() * [1.0f32, 30.0, 1000.0][i % 3];
            let ray = Ray::new(o, aim - o, 0.0, f32::INFINITY);
            let (a, b) = (bin.trace_exact(&scene, &ray), scene.brute_force(&ray));
            assert!(a.same_bits(&b), "ray {ray:?}: BVH {a:?}, brute force {b:?}");
            hits += a.is_hit() as usize;
        }
        assert!(hits > 300, "only {hits} hits: the test checks too little");
    }
}
