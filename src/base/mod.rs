//! The bottom layer, importing nothing of halftrace's: rays ([`Ray`]), boxes ([`Aabb`]), the
//! fp32 ray set-up and slab test ([`RayPre`], [`slab32`]), the watertight triangle test
//! ([`tri`]), hits and counters with the closest-hit rule ([`Hit`], [`Counters`],
//! [`ClosestTrue`]), agreement between results, how a measurement ended ([`Status`]), the random generator ([`Rng`]) and the Rust↔GLSL
//! struct mechanism ([`glsl`]). Every other module builds on these.

pub mod agreement;
pub mod exact;
pub mod geom;
pub mod glsl;
pub mod hit;
pub mod ray;
pub mod rng;
pub mod slab;
pub mod status;
pub mod tri;

pub use agreement::{agreement, mean_counters, simd_utilisation, Agreement, RunOutput};
pub use geom::{max_abs_axis, Aabb};
pub use hit::{admit, hit_pad, padded_box, resolve_flagged, ClosestBox, ClosestTrue, Counters, Hit, PRIM_FLAGGED};
pub use ray::{validate, Ray, RayError, DIR_MAX, DIR_MIN};
pub use rng::Rng;
pub use slab::{lower32, slab32, upper32, RayPre, HIT_CAP};
pub use status::Status;
