//! The Vulkan backend on the default device (lavapipe in CI), with the Khronos validation
//! layer on: every variant of every registered layout equals the CPU reference of its layout
//! ray for ray (hits bitwise, counters exactly), the shader reads every node layout as Rust
//! writes it, user kernels are checked, validated and timed, no validation message, no leaked
//! allocation, and bad input gets a clear error. One test binary, a module per concern.

mod baselines;
#[path = "../common/mod.rs"]
mod common;
mod conformance;
mod devices;
mod isa;
mod kernels;
mod user;

pub use common::*;
pub use halftrace::base::Ray;
pub use halftrace::bvh::BRANCHINGS;
pub use halftrace::gpu::{ContextOptions, Gpu, GpuBvh, GpuError, Kernel};
pub use halftrace::layout::LayoutId;
pub use halftrace::precision::Math;
pub use halftrace::variant::{KernelId, PacketImpl, Source, Variant, PACKETS};
pub use std::path::PathBuf;
pub use std::process::Command;

/// Opens the default device with validation. A machine without Vulkan fails here, loudly:
/// CI always has lavapipe (scripts/install-deps.sh).
pub fn gpu() -> Gpu {
    let g = Gpu::new(&ContextOptions { validation: true, ..Default::default() }).unwrap_or_else(|e| {
        panic!("GPU TESTS CANNOT RUN: no usable Vulkan device ({e}). Run scripts/install-deps.sh (Mesa lavapipe).")
    });
    assert!(
        g.validation_enabled,
        "VK_LAYER_KHRONOS_validation is not installed (package vulkan-validationlayers); GPU tests require it"
    );
    g
}

pub fn clean(g: &Gpu) {
    let msgs = g.validation_messages();
    assert!(msgs.is_empty(), "validation messages:\n{}", msgs.join("\n"));
    assert_eq!(g.allocated_bytes(), 0, "allocations leaked");
}

pub fn builtin<'g>(g: &'g Gpu, v: &Variant, imp: PacketImpl, stats: bool) -> Kernel<'g> {
    builtin_as(g, v, imp, stats, |_| {})
}

/// The built-in kernel as the device admits it, its decision changed by `edit` first (e.g. the
/// build of a device without fp64).
pub fn builtin_as<'g>(
    g: &'g Gpu,
    v: &Variant,
    imp: PacketImpl,
    stats: bool,
    edit: impl FnOnce(&mut halftrace::gpu::support::Decision),
) -> Kernel<'g> {
    built_from(g, v, imp, stats, &Source::Builtin, edit)
}

/// [`builtin_as`] built from `source` (the built-in kernel's marked or counted builds).
pub fn built_from<'g>(
    g: &'g Gpu,
    v: &Variant,
    imp: PacketImpl,
    stats: bool,
    source: &Source,
    edit: impl FnOnce(&mut halftrace::gpu::support::Decision),
) -> Kernel<'g> {
    let k = KernelId::new(*v, imp, stats);
    let mut d = halftrace::gpu::support::admit(&g.info, &k).unwrap_or_else(|e| panic!("{k}: {e}"));
    edit(&mut d);
    Kernel::build(g, &d.with_stats(stats), source).unwrap_or_else(|e| panic!("{k}: {e}"))
}

pub fn tmp(name: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("halftrace-gpu-{}", std::process::id()));
    std::fs::create_dir_all(&d).unwrap();
    d.join(name)
}

pub fn cli(args: &[&str]) -> (bool, String, String) {
    cli_env(&[], args)
}

/// [`cli`] with environment variables set.
pub fn cli_env(env: &[(&str, &str)], args: &[&str]) -> (bool, String, String) {
    let o = Command::new(env!("CARGO_BIN_EXE_halftrace")).envs(env.iter().copied()).args(args).output().unwrap();
    (o.status.success(), String::from_utf8_lossy(&o.stdout).to_string(), String::from_utf8_lossy(&o.stderr).to_string())
}

pub fn repo(path: &str) -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join(path)
}
