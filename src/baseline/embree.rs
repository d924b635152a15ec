//! The `embree` baseline: Intel Embree 3 (Debian's libembree, through the `embree` crate) on
//! the host CPU, over the same triangles and rays as every other row. It answers "is this
//! faster than the CPU next to the device": on lavapipe it is the same silicon, on a GPU the
//! host beside it. Its BVH is Embree's own (built with its default, high-quality settings on
//! all host threads), traced with `rtcIntersect1` over every host core (rayon); its hits are
//! compared with the f32 reference like `rq`'s (Embree's watertight triangle test is not
//! ours, so a few t may differ in the last bits) and it is timed as host wall time over the
//! same rays with the same warm-up and repeats.

use super::{Baseline, BaselineDevice, BaselineError, BaselineScene};
use crate::base::{Hit, Ray, RunOutput};
use crate::gpu::{DeviceInfo, Gpu};
use crate::scene::Scene;
use cgmath::{Vector3, Vector4};
use embree::{CommittedScene, Device, Geometry, IntersectContext, RayHit, Scene as EScene, TriangleMesh};
use rayon::prelude::*;
use std::time::Instant;

/// The registry entry `embree`.
pub struct Embree;

/// Rays per rayon task: enough that scheduling is amortised, small enough that 2..64 cores
/// stay balanced on incoherent rays.
const CHUNK: usize = 256;

impl Baseline for Embree {
    fn name(&self) -> &'static str {
        "embree"
    }
    fn summary(&self) -> &'static str {
        "Intel Embree 3 on the host CPU (all cores, rtcIntersect1), the CPU next to the device"
    }
    fn kernel(&self) -> &'static str {
        "embree3_intersect1_host"
    }
    fn unavailable(&self, _info: &DeviceInfo) -> Option<String> {
        None
    }
    fn prepare<'g>(&self, _gpu: &'g Gpu) -> Result<Box<dyn BaselineDevice<'g> + 'g>, BaselineError> {
        Ok(Box::new(host()))
    }
}

/// Embree on the host, without a Vulkan device (it needs none).
pub fn host() -> EmbreeDevice {
    // One Embree device for the process, never released: scenes built on it outlive any one
    // caller (Embree's scenes borrow their device).
    static DEVICE: std::sync::OnceLock<&'static Device> = std::sync::OnceLock::new();
    EmbreeDevice { device: DEVICE.get_or_init(|| Box::leak(Box::new(Device::new()))) }
}

/// Embree on the host, ready to build scenes.
pub struct EmbreeDevice {
    device: &'static Device,
}

struct EmbreeScene {
    scene: EScene<'static>,
    bytes: u64,
    build_ms: f64,
}

impl<'g> BaselineDevice<'g> for EmbreeDevice {
    fn scene(&self, scene: &Scene) -> Result<Box<dyn BaselineScene + 'g>, BaselineError> {
        let n = scene.tris.len();
        let mut mesh = TriangleMesh::unanimated(self.device, n, 3 * n);
        {
            let mut v = mesh.vertex_buffer.map();
            for (i, t) in scene.tris.iter().enumerate() {
                for (k, p) in t.iter().enumerate() {
                    v[3 * i + k] = Vector4::new(p.x, p.y, p.z, 0.0);
                }
            }
        }
        {
            let mut ix = mesh.index_buffer.map();
            for i in 0..n {
                let b = 3 * i as u32;
                ix[i] = Vector3::new(b, b + 1, b + 2);
            }
        }
        let mut geom = Geometry::Triangle(mesh);
        geom.commit();
        let mut es = EScene::new(self.device);
        es.attach_geometry(geom);
        let t0 = Instant::now();
        let _ = es.commit();
        let build_ms = t0.elapsed().as_secs_f64() * 1e3;
        // Embree does not report its BVH's size; this is the triangle data handed to it
        // (16-byte vertices, 12-byte index triples), a lower bound.
        let bytes = (n * (3 * 16 + 12)) as u64;
        Ok(Box::new(EmbreeScene { scene: es, bytes, build_ms }))
    }
}

/// Traces `rays` into `out` on every host core.
fn trace(committed: &CommittedScene, rays: &[Ray], out: &mut [Hit]) {
    rays.par_chunks(CHUNK).zip(out.par_chunks_mut(CHUNK)).for_each(|(rs, hs)| {
        let mut ctx = IntersectContext::incoherent();
        for (r, h) in rs.iter().zip(hs.iter_mut()) {
            let ray = embree::Ray::segment(Vector3::from(r.origin), Vector3::from(r.dir), r.tmin, r.tmax);
            let mut rh = RayHit::new(ray);
            committed.intersect(&mut ctx, &mut rh);
            *h = if rh.hit.hit() {
                Hit { t: rh.ray.tfar, prim: rh.hit.primID as i32, u: rh.hit.u, v: rh.hit.v }
            } else {
                Hit::MISS
            };
        }
    });
}

impl BaselineScene for EmbreeScene {
    fn bytes(&self) -> u64 {
        self.bytes
    }
    fn build_ms(&self) -> f64 {
        self.build_ms
    }
    fn run(&self, rays: &[Ray], warmup: usize, repeat: usize) -> Result<RunOutput, BaselineError> {
        let mut hits = vec![Hit::MISS; rays.len()];
        let mut times_ms = Vec::with_capacity(repeat);
        // Committed once, outside the timed loop (the scene is already built: `scene`).
        let committed = self.scene.commit();
        for i in 0..warmup + repeat.max(1) {
            let t0 = Instant::now();
            trace(&committed, rays, &mut hits);
            if i >= warmup {
                times_ms.push(t0.elapsed().as_secs_f64() * 1e3);
            }
        }
        crate::digest::record("baseline", "embree3_intersect1_host", rays, &hits, None);
        Ok(RunOutput { hits, counters: None, times_ms, flagged: 0 })
    }
}
