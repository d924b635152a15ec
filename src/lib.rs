//! halftrace: a harness for reduced-precision BVH traversal, starting from the half-precision
//! hierarchical traversal of Koskela et al. ("Half-Precision Floating-Point Ray Traversal").
//!
//! Data flow: [`scene`] → [`bvh`] (binary SAH, collapsed to B-wide) → [`layout`] (one folder
//! per precision layout, listed in [`layout::REGISTRY`]) → [`trace`] (the one CPU traversal,
//! the oracle) and [`gpu`] (the kernels: one GLSL skeleton, one hooks file per layout, the
//! shared [`interface`]) → [`measure`] (validate, then time) → [`sweep`] (jobs) → [`report`].
//! `docs/architecture.md` has the picture and how to add a layout.

pub mod bench;
pub mod bvh;
pub mod conformance;
pub mod digest;
pub mod embree;
pub mod formats;
pub mod fp16;
pub mod fsx;
pub mod geom;
pub mod gpu;
pub mod images;
pub mod interface;
pub mod layout;
pub mod measure;
pub mod npy;
pub mod progress;
pub mod rays;
pub mod report;
pub mod scene;
pub mod sweep;
pub mod trace;
pub mod variant;
