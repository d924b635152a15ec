//! halftrace: a harness for reduced-precision BVH traversal, starting from the half-precision
//! hierarchical traversal of Koskela et al. ("Half-Precision Floating-Point Ray Traversal").
//!
//! Layers, bottom up (each module imports only those below it; `docs/architecture.md` has the
//! picture and `tests/architecture.rs` checks it): [`base`] (rays, hits, counters, the fp32
//! tests), [`precision`], [`vendor`] (one file per GPU vendor), [`fp16`], [`fsx`] and [`outdir`] (files and output folders);
//! [`interface`] (what Rust and GLSL share), [`scene`], [`rays`], [`npy`]; [`bvh`]; [`layout`]
//! (one folder per precision layout, the CPU traversal); [`variant`]; [`gpu`] (the Vulkan
//! backend, the only `unsafe`); [`baseline`] (`rq`, `rt`, `embree`); [`report`]; [`runner`]
//! (validate, then time — the one way to a result); [`sweep`], [`bench`], [`conformance`],
//! [`isa`]; [`devreport`]; [`commands`] (one file per subcommand: its arguments and its run).

// The exact arithmetic loops over the three axes index several arrays in step, as the GLSL
// they mirror does; iterators would hide that correspondence.
#![allow(clippy::needless_range_loop)]
// `unsafe` lives in the Vulkan layer alone; anywhere else it is a compile error.
#![deny(unsafe_code)]

pub mod argv;
pub mod base;
pub mod baseline;
pub mod bench;
pub mod bvh;
pub mod commands;
pub mod conformance;
pub mod devreport;
pub mod digest;
pub mod estimate;
pub mod fp16;
pub mod fsx;
#[allow(unsafe_code)]
pub mod gpu;
pub mod images;
pub mod interface;
pub mod isa;
pub mod layout;
pub mod memory;
pub mod npy;
pub mod outdir;
pub mod precision;
pub mod progress;
pub mod rays;
pub mod report;
pub mod runner;
pub mod scene;
pub mod sweep;
pub mod units;
pub mod variant;
pub mod vendor;
