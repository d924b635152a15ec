//! A kernel to build, in the one spelling every command uses ([`KernelSpec`]), and the kernel
//! a device builds for it ([`KernelId`]).

use super::{PacketImpl, Variant};
use crate::precision::{FcChoice, FloatControls};
use std::path::{Path, PathBuf};

/// Where a kernel's module comes from.
#[derive(Clone, Debug, PartialEq, Eq, Hash)]
pub enum Source {
    /// Compiled from `glsl/trav.comp` with the variant's layout hooks.
    Builtin,
    /// A user's GLSL compute file, compiled with the built-in kernel's defines and includes.
    Glsl(PathBuf),
    /// A user's SPIR-V module.
    Spirv(PathBuf),
    /// The built-in kernel with a marker at the start of each named side of its triangle test
    /// (`BRANCH_MARKS`: an atomic operation per side, the interface's `MARK_<NAME>()`), so that a
    /// compiler's listing shows which of its blocks run each side — `estimate`'s branch
    /// weights. Built, never run.
    Marked,
    /// The built-in counting kernel with each named side of its triangle test counted per ray
    /// (`BRANCH_COUNTS`: the interface's `MARK_<NAME>()` increments the side's count), written in
    /// place of the work counters but the triangle tests ([`crate::base::tri::Branch::counted`]):
    /// the kernel's own count of what `estimate`'s branch weights take from the CPU reference.
    Counted,
}

impl Source {
    /// A user file: `.spv` is SPIR-V, anything else GLSL.
    pub fn user(path: &Path) -> Source {
        if path.extension().is_some_and(|e| e == "spv") {
            Source::Spirv(path.into())
        } else {
            Source::Glsl(path.into())
        }
    }
}

/// A kernel to build, as a command asks for it: the variant, how its float controls are
/// chosen (auto: on where the device has them, else the layout's build without them), the
/// packet implementation (`None`: the device's choice) and where the module comes from. The
/// sweep's jobs, `trace`, `conformance`, `isa` and `shaders --emit` all ask in this type (the
/// sets of them come from [`super::matrix`]); what a device makes of one is decided once, by
/// `gpu::support::decide`.
#[derive(Clone, Debug, PartialEq, Eq, Hash)]
pub struct KernelSpec {
    pub variant: Variant,
    pub fc: FcChoice,
    pub imp: Option<PacketImpl>,
    pub source: Source,
}

impl KernelSpec {
    /// The built-in kernel of `v`: float controls on where the device has them, the device's
    /// packet implementation.
    pub fn builtin(v: Variant) -> KernelSpec {
        KernelSpec { variant: v, fc: FcChoice::Auto, imp: None, source: Source::Builtin }
    }

    /// The built-in kernel of `v` exactly: its float controls as `v` says, in `imp`.
    pub fn exact(v: Variant, imp: PacketImpl) -> KernelSpec {
        let fc = match v.fc {
            FloatControls::On => FcChoice::On,
            FloatControls::Off => FcChoice::Off,
        };
        KernelSpec { variant: v, fc, imp: Some(imp), source: Source::Builtin }
    }

    /// The same kernel with float controls chosen by `fc`.
    pub fn with_fc(self, fc: FcChoice) -> KernelSpec {
        KernelSpec { fc, ..self }
    }

    /// The same kernel in packet implementation `imp` (`None`: the device's choice).
    pub fn with_imp(self, imp: Option<PacketImpl>) -> KernelSpec {
        KernelSpec { imp, ..self }
    }

    /// The same kernel from `source`.
    pub fn with_source(self, source: Source) -> KernelSpec {
        KernelSpec { source, ..self }
    }
}

/// One kernel: a variant in one packet implementation, timed or counting (`stats`). What the
/// runner keys its pipelines by and what a kernel's name spells.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub struct KernelId {
    pub variant: Variant,
    pub imp: PacketImpl,
    pub stats: bool,
}

impl KernelId {
    pub fn new(variant: Variant, imp: PacketImpl, stats: bool) -> KernelId {
        KernelId { variant, imp, stats }
    }

    /// The same kernel, timed (`false`) or counting (`true`).
    pub fn with_stats(self, stats: bool) -> KernelId {
        KernelId { stats, ..self }
    }

    /// `trav_{layout}[_{math}]_b{B}_p{P}…` ([`Variant::kernel_name`]).
    pub fn name(&self) -> String {
        self.variant.kernel_name(self.imp, self.stats)
    }
}

impl std::fmt::Display for KernelId {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(&self.name())
    }
}
