//! Brute force: every triangle tested. The oracle for the `f32` traversal.

use super::{Closest, RayPre};
use crate::rays::Ray;
use crate::scene::Scene;
use crate::trace::Hit;

pub fn trace(scene: &Scene, ray: &Ray) -> Hit {
    let r = RayPre::new(ray);
    let mut best = Closest::new(ray.tmax);
    for (i, t) in scene.tris.iter().enumerate() {
        let v = [t[0].x, t[0].y, t[0].z, t[1].x, t[1].y, t[1].z, t[2].x, t[2].y, t[2].z];
        best.test(&r, &v, i as i32);
    }
    best.hit()
}
