//! halftrace: a harness for half-precision hierarchical BVH traversal (Koskela et al.,
//! "Half-Precision Floating-Point Ray Traversal").
//!
//! Data flow: [`scene`] → [`bvh`] (binary SAH, collapsed to B-wide) → [`encode`] (one module
//! per layout) → [`trace`] (CPU reference per layout) and, later, the GPU.

pub mod bvh;
pub mod encode;
pub mod fp16;
pub mod geom;
pub mod gpu;
pub mod npy;
pub mod pipeline;
pub mod rays;
pub mod report;
pub mod scene;
pub mod sweep;
pub mod trace;
pub mod variant;

