//! Primary rays: a pinhole camera ([`Camera`], framing a scene by default) and one ray per
//! pixel centre in tile order ([`pixel_order`]), so packets of neighbouring rays are coherent.

use super::check_image_size;
use crate::base::{Aabb, Ray, RayError};
use glam::Vec3;

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
