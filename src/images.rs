//! Images of primary rays (pixel order: `rays::pixel_order`): the shaded render, heat maps
//! of per-pixel work, and masks of differing pixels.

use crate::base::Hit;
use crate::base::Ray;
use crate::rays;
use crate::scene::Scene;
use std::path::Path;

/// Writes a shaded PNG of primary hits: grey by |cos| between ray and geometric normal.
pub fn render(path: &Path, scene: &Scene, rays: &[Ray], hits: &[Hit], width: u32, height: u32) -> anyhow::Result<()> {
    anyhow::ensure!(
        rays.len() as u64 == width as u64 * height as u64,
        "--image needs primary rays ({}x{} = {} rays, got {})",
        width,
        height,
        width as u64 * height as u64,
        rays.len()
    );
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
    crate::fsx::with_temp(path, |t| img.save(t).map_err(anyhow::Error::from))
}

/// Writes a heat map of a per-pixel value (pixel order of primary rays) with a fixed scale.
pub fn heat_map(path: &Path, w: u32, h: u32, values: &[f64], max: f64) -> anyhow::Result<()> {
    let mut img = image::RgbImage::new(w, h);
    for (&(x, y), &v) in rays::pixel_order(w, h).iter().zip(values) {
        let t = if max > 0.0 { (v / max).clamp(0.0, 1.0) } else { 0.0 };
        // black → blue → red → yellow
        let c = if t < 0.33 {
            [0.0, 0.0, t / 0.33]
        } else if t < 0.66 {
            [(t - 0.33) / 0.33, 0.0, 1.0 - (t - 0.33) / 0.33]
        } else {
            [1.0, (t - 0.66) / 0.34, 0.0]
        };
        img.put_pixel(x, y, image::Rgb(c.map(|v| (v * 255.0) as u8)));
    }
    crate::fsx::with_temp(path, |t| img.save(t).map_err(anyhow::Error::from))
}

/// Writes a mask image: white where `mask` is set, black elsewhere.
pub fn mask_image(path: &Path, w: u32, h: u32, mask: &[bool]) -> anyhow::Result<()> {
    let mut img = image::RgbImage::new(w, h);
    for (&(x, y), &m) in rays::pixel_order(w, h).iter().zip(mask) {
        img.put_pixel(x, y, image::Rgb(if m { [255; 3] } else { [0; 3] }));
    }
    crate::fsx::with_temp(path, |t| img.save(t).map_err(anyhow::Error::from))
}
