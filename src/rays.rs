//! Ray sets: primary (pinhole camera), ao and diffuse (cosine-weighted from primary hits),
//! a grazing set that aims at the places where fp16 rounding bites, and validation.
//! Every generator is deterministic for a given seed.

use crate::geom::Aabb;
use crate::scene::Scene;
use crate::trace::Hit;
use glam::Vec3;
use std::path::PathBuf;
use thiserror::Error;

/// One ray, laid out as a row of the rays `.npy` file: `ox oy oz tmin dx dy dz tmax`
/// (32 bytes). Directions need not be normalised: `t` is measured in units of the
/// direction's length (as in Embree). `tmax` may be +inf.
#[repr(C)]
#[derive(Clone, Copy, Debug, PartialEq, bytemuck::Pod, bytemuck::Zeroable)]
pub struct Ray {
    pub origin: [f32; 3],
    pub tmin: f32,
    pub dir: [f32; 3],
    pub tmax: f32,
}
const _: () = assert!(std::mem::size_of::<Ray>() == 32);

impl Ray {
    pub fn new(o: Vec3, d: Vec3, tmin: f32, tmax: f32) -> Ray {
        Ray { origin: o.into(), tmin, dir: d.into(), tmax }
    }
    pub fn o(&self) -> Vec3 {
        Vec3::from(self.origin)
    }
    pub fn d(&self) -> Vec3 {
        Vec3::from(self.dir)
    }
}

/// Smallest and largest supported direction magnitude (largest component), so that the
/// traversal's scale products stay finite in fp32.
pub const DIR_MIN: f32 = 1e-18;
pub const DIR_MAX: f32 = 1e18;

#[derive(Debug, Error, PartialEq)]
pub enum RayError {
    #[error("{source_name}: ray {index}: {msg}")]
    Invalid { source_name: String, index: usize, msg: String },
    #[error("{0}")]
    Param(String),
}

/// Checks every ray: finite origin and direction, a non-zero direction within
/// [`DIR_MIN`, `DIR_MAX`], `0 <= tmin <= tmax`, `tmax` not NaN (+inf allowed).
pub fn validate(rays: &[Ray], source_name: &str) -> Result<(), RayError> {
    for (i, r) in rays.iter().enumerate() {
        let bad = |msg: String| Err(RayError::Invalid { source_name: source_name.into(), index: i, msg });
        if !r.o().is_finite() {
            return bad(format!("origin {:?} is not finite", r.origin));
        }
        if !r.d().is_finite() {
            return bad(format!("direction {:?} is not finite", r.dir));
        }
        let m = r.d().abs().max_element();
        if m == 0.0 {
            return bad("direction is zero".into());
        }
        if !(DIR_MIN..=DIR_MAX).contains(&m) {
            return bad(format!("direction magnitude {m:e} is outside the supported range [{DIR_MIN:e}, {DIR_MAX:e}]"));
        }
        if !(r.tmin.is_finite() && r.tmin >= 0.0) {
            return bad(format!("tmin {} must be finite and >= 0", r.tmin));
        }
        if r.tmax.is_nan() || r.tmax < r.tmin {
            return bad(format!("tmax {} must be >= tmin {}", r.tmax, r.tmin));
        }
    }
    Ok(())
}

/// A pinhole camera: eye, target, vertical field of view in degrees.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Camera {
    pub eye: Vec3,
    pub target: Vec3,
    pub fov_deg: f32,
}

/// Default view direction (from the target towards the eye) used to frame a scene.
pub const DEFAULT_VIEW_DIR: Vec3 = Vec3::new(0.55, 0.45, 0.70);
/// Default vertical field of view in degrees.
pub const DEFAULT_FOV: f32 = 45.0;

impl Camera {
    /// Frames the scene's bounding box: looks at its centre from [`DEFAULT_VIEW_DIR`], far
    /// enough that the bounding sphere fits the vertical field of view [`DEFAULT_FOV`].
    pub fn framing(bounds: &Aabb) -> Camera {
        let c = bounds.center();
        let radius = (0.5 * bounds.diagonal()).max(1e-6);
        let dist = radius / (0.5 * DEFAULT_FOV.to_radians()).sin() * 1.02;
        Camera { eye: c + DEFAULT_VIEW_DIR.normalize() * dist, target: c, fov_deg: DEFAULT_FOV }
    }

    /// Parses `ex,ey,ez,tx,ty,tz,fov`.
    pub fn parse(s: &str) -> Result<Camera, RayError> {
        let v: Result<Vec<f32>, _> = s.split(',').map(|x| x.trim().parse::<f32>()).collect();
        let v = v.map_err(|_| {
            RayError::Param(format!(
                "--camera '{s}': expected 7 numbers eye_x,eye_y,eye_z,target_x,target_y,target_z,fov"
            ))
        })?;
        if v.len() != 7 || v.iter().any(|x| !x.is_finite()) {
            return Err(RayError::Param(format!(
                "--camera '{s}': expected 7 finite numbers eye_x,eye_y,eye_z,target_x,target_y,target_z,fov"
            )));
        }
        let cam = Camera { eye: Vec3::new(v[0], v[1], v[2]), target: Vec3::new(v[3], v[4], v[5]), fov_deg: v[6] };
        if cam.eye == cam.target {
            return Err(RayError::Param(format!("--camera '{s}': eye and target coincide")));
        }
        if !(cam.fov_deg > 0.0 && cam.fov_deg < 180.0) {
            return Err(RayError::Param(format!("--camera '{s}': fov must be in (0, 180) degrees")));
        }
        Ok(cam)
    }
}

/// Side of the square screen tiles primary rays are ordered in.
pub const TILE: u32 = 8;

/// Pixel order of primary rays: 8×8 tiles in row-major order, pixels inside a tile in Morton
/// (Z) order, pixels outside the image skipped. Any aligned run of P = 4, 8, 16, 32, 64 rays
/// inside a full tile is then a compact block (2×2, 4×2, 4×4, 8×4, 8×8), so packets of
/// neighbouring rays are coherent for every packet size at once.
pub fn pixel_order(width: u32, height: u32) -> Vec<(u32, u32)> {
    let mut v = Vec::with_capacity(width as usize * height as usize);
    for ty in (0..height).step_by(TILE as usize) {
        for tx in (0..width).step_by(TILE as usize) {
            for m in 0..TILE * TILE {
                // de-interleave the Morton index: even bits x, odd bits y
                let (mut x, mut y) = (0, 0);
                for b in 0..3 {
                    x |= ((m >> (2 * b)) & 1) << b;
                    y |= ((m >> (2 * b + 1)) & 1) << b;
                }
                let (px, py) = (tx + x, ty + y);
                if px < width && py < height {
                    v.push((px, py));
                }
            }
        }
    }
    v
}

/// Most rays one image may have (2^26: 6.4 GiB of rays, hits and counters on the device).
pub const MAX_IMAGE_RAYS: u64 = 1 << 26;

/// Refuses an image whose ray count exceeds [`MAX_IMAGE_RAYS`] (computed without overflow).
pub fn check_image_size(width: u32, height: u32) -> Result<(), String> {
    let n = width as u64 * height as u64;
    if n > MAX_IMAGE_RAYS {
        return Err(format!(
            "image size {width}x{height} = {n} rays: more than the {MAX_IMAGE_RAYS} (2^26) one ray set may have"
        ));
    }
    Ok(())
}

/// One normalised primary ray per pixel centre, in [`pixel_order`], `tmin = 0`, `tmax = +inf`.
pub fn primary(cam: &Camera, width: u32, height: u32) -> Result<Vec<Ray>, RayError> {
    if width == 0 || height == 0 {
        return Err(RayError::Param(format!("image size {width}x{height}: width and height must be positive")));
    }
    check_image_size(width, height).map_err(RayError::Param)?;
    let finite = |v: Vec3| v.is_finite();
    if !(finite(cam.eye) && finite(cam.target) && cam.fov_deg.is_finite() && cam.fov_deg > 0.0 && cam.fov_deg < 180.0)
        || cam.eye == cam.target
    {
        return Err(RayError::Param(format!(
            "camera eye {} target {} fov {}: eye and target must be finite and distinct, fov in (0, 180) degrees",
            cam.eye, cam.target, cam.fov_deg
        )));
    }
    // Normalised in f64: the squared distance of an eye 1e20 away overflows fp32.
    let fwd = (cam.target.as_dvec3() - cam.eye.as_dvec3()).normalize().as_vec3();
    let up0 = if fwd.cross(Vec3::Y).length() < 1e-4 { Vec3::Z } else { Vec3::Y };
    let right = fwd.cross(up0).normalize();
    let up = right.cross(fwd);
    let h = (0.5 * cam.fov_deg.to_radians()).tan();
    let aspect = width as f32 / height as f32;
    Ok(pixel_order(width, height)
        .into_iter()
        .map(|(x, y)| {
            let px = ((x as f32 + 0.5) / width as f32 * 2.0 - 1.0) * h * aspect;
            let py = (1.0 - (y as f32 + 0.5) / height as f32 * 2.0) * h;
            Ray::new(cam.eye, (fwd + right * px + up * py).normalize(), 0.0, f32::INFINITY)
        })
        .collect::<Vec<Ray>>())
    .and_then(|rays| match rays.iter().find(|r| !(r.d().is_finite() && r.d().length() > 0.0)) {
        // e.g. an eye 1e20 from the target: its squared distance overflows fp32.
        Some(r) => Err(RayError::Param(format!(
            "camera eye {} target {}: the primary ray directions are not finite ({:?}); the distance is beyond what fp32 can normalise — move the camera closer or scale the scene",
            cam.eye,
            cam.target,
            r.d()
        ))),
        None => Ok(rays),
    })
}

/// SplitMix64: a tiny, stable, seedable generator (its stream never changes across versions).
#[derive(Clone, Debug)]
pub struct Rng(u64);

impl Rng {
    pub fn new(seed: u64) -> Rng {
        Rng(seed ^ 0x9E37_79B9_7F4A_7C15)
    }
    pub fn next_u64(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^ (z >> 31)
    }
    /// Uniform in [0, 1).
    pub fn next_f32(&mut self) -> f32 {
        (self.next_u64() >> 40) as f32 / (1u64 << 24) as f32
    }
}

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
        let p = r.o() + r.d() * h.t;
        let mut n = scene.normal(h.prim as usize).normalize_or_zero();
        if n == Vec3::ZERO {
            continue;
        }
        if n.dot(r.d()) > 0.0 {
            n = -n;
        }
        let mut rng = Rng::new(seed.wrapping_mul(0x1000_0001_B3).wrapping_add(i as u64));
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

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn pixel_order_covers_the_image_once_and_packets_are_tiles() {
        for (w, h) in [(8, 8), (16, 8), (13, 7), (64, 48)] {
            let o = pixel_order(w, h);
            let mut seen = vec![false; (w * h) as usize];
            for &(x, y) in &o {
                assert!(!seen[(y * w + x) as usize]);
                seen[(y * w + x) as usize] = true;
            }
            assert!(seen.iter().all(|&s| s));
        }
        let o = pixel_order(64, 64);
        for (p, (bw, bh)) in [(4, (2, 2)), (8, (4, 2)), (16, (4, 4)), (32, (8, 4)), (64, (8, 8))] {
            for chunk in o.chunks(p) {
                let (x0, x1) = (chunk.iter().map(|c| c.0).min().unwrap(), chunk.iter().map(|c| c.0).max().unwrap());
                let (y0, y1) = (chunk.iter().map(|c| c.1).min().unwrap(), chunk.iter().map(|c| c.1).max().unwrap());
                assert_eq!((x1 - x0 + 1, y1 - y0 + 1), (bw, bh), "P={p}");
            }
        }
    }
}

// Ray sets by kind, as the command line and the sweep name them.

/// Which rays to trace.
#[derive(Clone, Debug, PartialEq)]
pub enum RayKind {
    Primary,
    Ao,
    Diffuse,
    Grazing,
    File(PathBuf),
}

impl std::str::FromStr for RayKind {
    type Err = RayError;
    fn from_str(s: &str) -> Result<RayKind, RayError> {
        Ok(match s {
            "primary" => RayKind::Primary,
            "ao" => RayKind::Ao,
            "diffuse" => RayKind::Diffuse,
            "grazing" => RayKind::Grazing,
            f if f.ends_with(".npy") => RayKind::File(PathBuf::from(f)),
            other => {
                return Err(RayError::Param(format!(
                    "--rays '{other}': use primary, ao, diffuse, grazing or a FILE.npy"
                )))
            }
        })
    }
}

impl std::fmt::Display for RayKind {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            RayKind::Primary => f.write_str("primary"),
            RayKind::Ao => f.write_str("ao"),
            RayKind::Diffuse => f.write_str("diffuse"),
            RayKind::Grazing => f.write_str("grazing"),
            RayKind::File(p) => write!(f, "{}", p.display()),
        }
    }
}

/// Parameters of generated ray sets.
#[derive(Clone, Debug)]
pub struct RayParams {
    pub width: u32,
    pub height: u32,
    pub camera: Option<Camera>,
    pub seed: u64,
    /// Number of grazing rays.
    pub grazing: usize,
}

impl Default for RayParams {
    fn default() -> Self {
        RayParams { width: 256, height: 256, camera: None, seed: 1, grazing: 4096 }
    }
}

/// Builds or reads the ray set. ao and diffuse trace the primary rays first (f32, B = 4).
pub fn make_rays(
    scene: &Scene,
    bin: &crate::bvh::BinaryBvh,
    kind: &RayKind,
    p: &RayParams,
) -> anyhow::Result<Vec<Ray>> {
    let cam = p.camera.unwrap_or_else(|| Camera::framing(&scene.bounds));
    let rays = match kind {
        RayKind::Primary => primary(&cam, p.width, p.height)?,
        RayKind::Ao | RayKind::Diffuse => {
            let prim = primary(&cam, p.width, p.height)?;
            let f = crate::layout::Encoded::new(scene, bin, crate::layout::LayoutId::f32(), 4)?;
            let (hits, _) = f.trace_default(&prim);
            let len = if *kind == RayKind::Ao { Some(AO_LENGTH) } else { None };
            secondary(scene, &prim, &hits, p.seed, len)
        }
        RayKind::Grazing => {
            let boxes: Vec<_> = bin.nodes.iter().map(|n| n.bounds).collect();
            grazing(scene, &boxes, p.grazing, p.seed)
        }
        RayKind::File(path) => {
            let r = crate::npy::read_rays(path)?;
            validate(&r, &path.display().to_string())?;
            r
        }
    };
    Ok(rays)
}
