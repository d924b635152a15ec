//! Glue shared by the command line and the tests: ray sets by kind, encoding by layout, CPU
//! tracing, the shaded image.

use crate::bvh::{self, BinaryBvh};
use crate::encode::{self, Layout};
use crate::rays::{self, Camera, Ray, RayError};
use crate::scene::Scene;
use crate::trace::{self, Counters, Hit};
use anyhow::Context;
use std::path::{Path, PathBuf};

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
            other => return Err(RayError::Param(format!("--rays '{other}': use primary, ao, diffuse, grazing or a FILE.npy"))),
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
pub fn make_rays(scene: &Scene, bin: &BinaryBvh, kind: &RayKind, p: &RayParams) -> anyhow::Result<Vec<Ray>> {
    let cam = p.camera.unwrap_or_else(|| Camera::framing(&scene.bounds));
    let rays = match kind {
        RayKind::Primary => rays::primary(&cam, p.width, p.height)?,
        RayKind::Ao | RayKind::Diffuse => {
            let prim = rays::primary(&cam, p.width, p.height)?;
            let f = encode::f32::encode(scene, &bvh::collapse(bin, 4));
            let (hits, _) = trace::trace_all(&prim, |r| trace::f32::trace(&f, r));
            let len = if *kind == RayKind::Ao { Some(rays::AO_LENGTH) } else { None };
            rays::secondary(scene, &prim, &hits, p.seed, len)
        }
        RayKind::Grazing => {
            let boxes: Vec<_> = bin.nodes.iter().map(|n| n.bounds).collect();
            rays::grazing(scene, &boxes, p.grazing, p.seed)
        }
        RayKind::File(path) => {
            let r = crate::npy::read_rays(path)?;
            rays::validate(&r, &path.display().to_string())?;
            r
        }
    };
    Ok(rays)
}

/// An encoded BVH of either layout.
pub enum Encoded {
    F32(encode::f32::F32Bvh),
    F16h(encode::f16h::F16hBvh),
}

impl Encoded {
    pub fn new(scene: &Scene, bin: &BinaryBvh, layout: Layout, b: usize) -> anyhow::Result<Encoded> {
        bvh::check_branching(b)?;
        let w = bvh::collapse(bin, b);
        Ok(match layout {
            Layout::F32 => Encoded::F32(encode::f32::encode(scene, &w)),
            Layout::F16h => Encoded::F16h(encode::f16h::encode(scene, &w).with_context(|| format!("encoding {} as f16h, B={b}", scene.name))?),
        })
    }

    /// Node array bytes.
    pub fn node_bytes(&self) -> usize {
        match self {
            Encoded::F32(e) => e.nodes.bytes().len(),
            Encoded::F16h(e) => e.nodes.bytes().len(),
        }
    }

    pub fn layout(&self) -> Layout {
        match self {
            Encoded::F32(_) => Layout::F32,
            Encoded::F16h(_) => Layout::F16h,
        }
    }

    pub fn branching(&self) -> usize {
        match self {
            Encoded::F32(e) => e.branching,
            Encoded::F16h(e) => e.branching,
        }
    }

    /// Largest traversal stack this BVH can need.
    pub fn max_stack(&self) -> usize {
        match self {
            Encoded::F32(e) => e.max_stack,
            Encoded::F16h(e) => e.max_stack,
        }
    }

    pub fn node_count(&self) -> usize {
        match self {
            Encoded::F32(e) => e.nodes.len(),
            Encoded::F16h(e) => e.nodes.len(),
        }
    }

    /// Traces rays in packets of `p` on the CPU reference of this layout (p = 1: single rays),
    /// f16h in its fp16 math mode.
    pub fn trace_packets(&self, rays: &[Ray], p: usize) -> (Vec<Hit>, Vec<Counters>) {
        self.trace_variant(rays, p, trace::f16h::Math::F16)
    }

    /// Traces rays in packets of `p` with an f16h math mode (ignored by f32).
    pub fn trace_variant(&self, rays: &[Ray], p: usize, math: trace::f16h::Math) -> (Vec<Hit>, Vec<Counters>) {
        match (self, p) {
            (Encoded::F32(e), 1) => trace::trace_all(rays, |r| trace::f32::trace(e, r)),
            (Encoded::F16h(e), 1) => trace::trace_all(rays, |r| trace::f16h::trace_math(e, r, math)),
            (Encoded::F32(e), _) => trace::packet::trace_f32(e, rays, p),
            (Encoded::F16h(e), _) => trace::packet::trace_f16h(e, rays, p, math),
        }
    }

    /// Traces all rays on the CPU reference of this layout.
    pub fn trace(&self, rays: &[Ray]) -> (Vec<Hit>, Vec<Counters>) {
        match self {
            Encoded::F32(e) => trace::trace_all(rays, |r| trace::f32::trace(e, r)),
            Encoded::F16h(e) => trace::trace_all(rays, |r| trace::f16h::trace(e, r)),
        }
    }
}

/// Writes a shaded PNG of primary hits: grey by |cos| between ray and geometric normal.
pub fn write_image(path: &Path, scene: &Scene, rays: &[Ray], hits: &[Hit], width: u32, height: u32) -> anyhow::Result<()> {
    anyhow::ensure!(rays.len() == (width * height) as usize, "--image needs primary rays ({}x{} = {} rays, got {})", width, height, width * height, rays.len());
    let mut img = image::RgbImage::new(width, height);
    for (&(x, y), (r, h)) in rays::pixel_order(width, height).iter().zip(rays.iter().zip(hits)) {
        let px = if h.is_hit() {
            let n = scene.normal(h.prim as usize).normalize_or_zero();
            let c = n.dot(r.d().normalize()).abs();
            let g = (40.0 + 215.0 * c) as u8;
            [g, g, (g as f32 * 0.95) as u8]
        } else {
            [22, 26, 38]
        };
        img.put_pixel(x, y, image::Rgb(px));
    }
    img.save(path).with_context(|| format!("writing {}", path.display()))
}

/// Mean counters over a ray set.
pub fn mean_counters(c: &[Counters]) -> [f64; 4] {
    let n = c.len().max(1) as f64;
    let mut s = [0f64; 4];
    for x in c {
        s[0] += x.nodes as f64;
        s[1] += x.box_tests as f64;
        s[2] += x.tri_tests as f64;
        s[3] += x.reanchors as f64;
    }
    s.map(|v| v / n)
}
