//! One ray, as every layer and file holds it, and the checks every ray set passes.

use glam::Vec3;
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
