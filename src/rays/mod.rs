//! Ray sets by kind: primary ([`camera`]: a pinhole camera, tiled pixel order), ao and diffuse
//! ([`secondary`]: cosine-weighted from the primary hits, which the caller traces), grazing
//! ([`grazing`]: aimed where fp16 rounding bites) or a user's `.npy` file. Every generator is
//! deterministic for a given seed and takes what it needs as arguments.

pub mod camera;
pub mod grazing;
pub mod secondary;

pub use camera::{pixel_order, primary, Camera};
pub use grazing::grazing;
pub use secondary::{secondary, AO_LENGTH, SURFACE_OFFSET};

use crate::base::RayError;
use std::path::PathBuf;

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
#[derive(Clone, Debug, PartialEq)]
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
