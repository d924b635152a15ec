//! The variant matrix as data: layout × branching × packet size × math. Artifact names spell
//! the values (`trav_f16h_m16_b8_p1`).

use crate::interface;
use crate::layout::LayoutId;
use crate::precision::{FloatControls, Math};

mod kernel;
mod matrix;
pub use kernel::{KernelId, KernelSpec, Source};
pub use matrix::{default_variants, device_impl, every_impl, matrix, series, spirv_kernels, Matrix, Series};

/// Packet sizes the harness supports.
pub const PACKETS: [usize; 6] = [1, 4, 8, 16, 32, 64];

/// The layouts the default sweep runs with the poster's B and P series.
pub const SERIES_LAYOUTS: [&str; 2] = ["f32", "f16h"];
/// The branching factors at which the default sweep compares every layout (P = 1).
pub const LAYOUT_BRANCHINGS: [usize; 2] = [4, 8];

/// One traversal kernel configuration of a BVH layout.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub struct Variant {
    pub layout: LayoutId,
    pub branching: usize,
    /// Rays per packet (1 = single-ray traversal).
    pub packet: usize,
    /// Arithmetic of the box tests (one of the layout's modes).
    pub math: Math,
    /// Whether the kernel declares the float-control execution modes it relies on.
    pub fc: FloatControls,
    /// How the kernel reaches the scene's buffers (set from the uploaded BVH).
    pub buffers: Buffers,
}

/// How a kernel reaches the scene's node, triangle and id buffers.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord, Default)]
pub enum Buffers {
    /// Storage-buffer bindings, each within the device's `maxStorageBufferRange`.
    #[default]
    Bound,
    /// Through 64-bit buffer device addresses, read from a table bound in the nodes' place:
    /// for scenes whose nodes or triangles exceed `maxStorageBufferRange` (needs
    /// `bufferDeviceAddress`). Reads the same bytes, so the hits are the same.
    Addressed,
}

/// How the P rays of a packet cooperate on the GPU.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord, clap::ValueEnum)]
pub enum PacketImpl {
    /// P = 1: classic per-invocation traversal.
    #[value(skip)]
    Single,
    /// Clusters of P invocations of a subgroup (P ≤ subgroup size), clustered subgroup ops.
    Subgroup,
    /// One packet per workgroup of P invocations, reductions through shared memory.
    Shared,
    /// One packet per workgroup of P invocations (P above the subgroup size), each subgroup
    /// reducing its rays with subgroup arithmetic before one shared-memory exchange: the
    /// default for such P on devices with subgroup arithmetic.
    Hybrid,
}

/// GPU stack entries per ray for a branching factor: room for (B−1)·depth + 1 entries with
/// depth ≤ 64, 32, 24, 16 for B = 2, 4, 8, 16.
pub fn stack_entries(b: usize) -> usize {
    match b {
        2 => 65,
        4 => 97,
        8 => 169,
        _ => 241,
    }
}

/// Stack groups per ray of a kernel that defers entries (trav.comp, `DEFER_ENTRIES`): one per
/// node on the path from the root that has an inner child, so depth − 1 with the depth that
/// [`stack_entries`] allows.
pub fn stack_groups(b: usize) -> usize {
    (stack_entries(b) - 1) / (b - 1) - 1
}

/// What is wrong with a variant asked for by parameters: the message starts with the value;
/// a caller puts the parameter ([`VariantError::parameter`]) before it as its input spells it
/// (`--packet 3: …`, `[[kernel]] 'mine': packet 3: …`).
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum VariantError {
    #[error("{0}: use one of 2, 4, 8, 16")]
    Branching(usize),
    #[error("{0}: use one of 1, 4, 8, 16, 32, 64")]
    Packet(usize),
    #[error("{math}: layout {layout} has {has}")]
    Math { math: String, layout: LayoutId, has: String },
}

impl VariantError {
    /// The parameter it is about.
    pub fn parameter(&self) -> &'static str {
        match self {
            VariantError::Branching(_) => "branching",
            VariantError::Packet(_) => "packet",
            VariantError::Math { .. } => "math",
        }
    }
}

impl Variant {
    /// The one checked constructor of a variant from what a user named (`trace`'s flags, a
    /// `[[kernel]]` table): B one of the built ones, P one of [`PACKETS`], the math one the
    /// layout has (its default without one).
    pub fn checked(
        layout: LayoutId,
        branching: usize,
        packet: usize,
        math: Option<Math>,
    ) -> Result<Variant, VariantError> {
        crate::bvh::check_branching(branching).map_err(|_| VariantError::Branching(branching))?;
        if !PACKETS.contains(&packet) {
            return Err(VariantError::Packet(packet));
        }
        let maths = layout.info().maths;
        let math = math.unwrap_or(maths[0]);
        if !maths.contains(&math) {
            let has: Vec<&str> = maths.iter().map(|m| m.name()).collect();
            return Err(VariantError::Math { math: math.name().into(), layout, has: has.join(", ") });
        }
        Ok(Variant::new(layout, branching, packet).with_math(math))
    }

    /// A variant in its layout's default math.
    pub fn new(layout: LayoutId, branching: usize, packet: usize) -> Variant {
        Variant {
            layout,
            branching,
            packet,
            math: layout.default_math(),
            fc: FloatControls::On,
            buffers: Buffers::Bound,
        }
    }

    /// The same variant with float controls `fc`.
    pub fn with_fc(mut self, fc: FloatControls) -> Variant {
        self.fc = fc;
        self
    }

    /// The same variant reaching the scene's buffers as `buffers` says.
    pub fn with_buffers(mut self, buffers: Buffers) -> Variant {
        self.buffers = buffers;
        self
    }

    /// The same variant in another math mode, when the layout has it (else unchanged).
    pub fn with_math(mut self, math: Math) -> Variant {
        if self.layout.info().maths.contains(&math) {
            self.math = math;
        }
        self
    }

    /// The kernel's name: `trav_{layout}[_{math}]_b{B}_p{P}` (the math tag m16, m32 or mix
    /// for layouts with more than one mode), then `_subgroup` for the subgroup packet
    /// implementation and `_stats` for the counting kernel, after `_fcoff` for a kernel built
    /// without float controls and `_addr` for one that reads the scene by address. Packets of
    /// P > 1 without a suffix use shared memory (portable to any subgroup size).
    pub fn kernel_name(&self, imp: PacketImpl, stats: bool) -> String {
        format!(
            "trav_{}{}_b{}_p{}{}{}{}{}",
            self.layout.name(),
            if self.layout.info().maths.len() > 1 { format!("_{}", self.math.tag()) } else { String::new() },
            self.branching,
            self.packet,
            if self.fc == FloatControls::Off { "_fcoff" } else { "" },
            if self.buffers == Buffers::Addressed { "_addr" } else { "" },
            match imp {
                PacketImpl::Subgroup => "_subgroup",
                PacketImpl::Hybrid => "_hybrid",
                _ => "",
            },
            if stats { "_stats" } else { "" }
        )
    }

    /// The kernel name of the portable implementation.
    pub fn name(&self, stats: bool) -> String {
        self.kernel_name(self.portable_impl(), stats)
    }

    /// Single-ray for P = 1, shared memory otherwise.
    pub fn portable_impl(&self) -> PacketImpl {
        if self.packet == 1 {
            PacketImpl::Single
        } else {
            PacketImpl::Shared
        }
    }

    /// Workgroup size of a kernel.
    pub fn workgroup(&self, imp: PacketImpl) -> u32 {
        match imp {
            PacketImpl::Shared | PacketImpl::Hybrid => self.packet as u32,
            _ => 64,
        }
    }

    /// Preprocessor definitions of this variant's kernel on a device offering `dev` — every
    /// define a kernel is built with, listed here once (`glsl/trav.comp` points here):
    ///
    /// - `B`, `P`: branching factor and packet size; `WG`: the workgroup size;
    ///   `STACK_SIZE`: the stack's entries ([`stack_entries`]).
    /// - `MATH_F16`, `MATH_F32` or `MATH_MIXED`: the math mode of the box tests.
    /// - `DEFER_ENTRIES` with `GROUPS` ([`stack_groups`]): the stack of one group per visit
    ///   (`glsl/stack_groups.glsl`) instead of an entry per child (`stack_entries.glsl`), and
    ///   `GROUPS_ALLOC`, the groups it is allocated ([`Variant::groups_alloc`]), and
    ///   `PENDING_SHARED` where the device's build keeps the entry of the child to enter next
    ///   in shared memory ([`DeviceBuild::pending_shared`]); else `STACK_ALLOC`, the entries the
    ///   entry stack is allocated ([`Variant::stack_alloc`]).
    /// - `PACKET_SUBGROUP` or `PACKET_HYBRID`: a packet's reductions in a subgroup, or a
    ///   subgroup then shared memory; neither: shared memory (`glsl/packet.glsl`).
    /// - `STATS`: the kernel writes the work counters.
    /// - `HALF_WORDS`: no 16-bit storage; fp16 values are read from 32-bit words.
    /// - `FC_OFF`: the build without float controls (exact without RTE and inf/NaN
    ///   preservation).
    /// - `ADDRESSED`: buffers by device address instead of bindings.
    ///
    /// A layout's hooks may add their own (`TEST_PAIRS`: `glsl/children.glsl` tests two
    /// children at once); the generated `interface.glsl` spells the Rust constants.
    pub fn defines(&self, imp: PacketImpl, stats: bool, dev: DeviceBuild) -> Vec<(String, String)> {
        let mut d = vec![
            ("B".to_string(), self.branching.to_string()),
            ("P".to_string(), self.packet.to_string()),
            ("WG".to_string(), self.workgroup(imp).to_string()),
            ("STACK_SIZE".to_string(), stack_entries(self.branching).to_string()),
            (self.math.define().to_string(), "1".to_string()),
        ];
        if self.defers_entries() {
            d.push(("DEFER_ENTRIES".into(), "1".into()));
            d.push(("GROUPS".into(), stack_groups(self.branching).to_string()));
            d.push(("GROUPS_ALLOC".into(), self.groups_alloc(dev).to_string()));
            if dev.pending_shared {
                d.push(("PENDING_SHARED".into(), "1".into()));
            }
        } else {
            d.push(("STACK_ALLOC".into(), self.stack_alloc(dev).to_string()));
        }
        match imp {
            PacketImpl::Subgroup => d.push(("PACKET_SUBGROUP".into(), "1".into())),
            PacketImpl::Hybrid => d.push(("PACKET_HYBRID".into(), "1".into())),
            _ => {}
        }
        if stats {
            d.push(("STATS".into(), "1".into()));
        }
        if !dev.storage16 {
            d.push(("HALF_WORDS".into(), "1".into()));
        }
        if self.fc == FloatControls::Off {
            d.push(("FC_OFF".into(), "1".into()));
        }
        if self.buffers == Buffers::Addressed {
            d.push(("ADDRESSED".into(), "1".into()));
        }
        d
    }

    /// The groups the group stack is allocated (`GROUPS_ALLOC`): [`stack_groups`], or where the
    /// device's compiler keeps private arrays of up to `dev.register_array_bytes` in registers,
    /// enough that the array of the group's smallest field (an entry field, or the 4-byte node
    /// and meta) is larger.
    pub fn groups_alloc(&self, dev: DeviceBuild) -> usize {
        self.past_register_arrays(stack_groups(self.branching), dev)
    }

    /// The entries the entry stack is allocated (`STACK_ALLOC`): [`stack_entries`], or where the
    /// device's compiler keeps private arrays of up to `dev.register_array_bytes` in registers,
    /// enough that the array of the entry's smallest field (or the 4-byte node) is larger.
    pub fn stack_alloc(&self, dev: DeviceBuild) -> usize {
        self.past_register_arrays(stack_entries(self.branching), dev)
    }

    /// A stack of `used` records allocated, where `dev`'s compiler keeps private arrays of up
    /// to `dev.register_array_bytes` in registers, long enough that the array of its smallest
    /// field (an entry field, or a 4-byte node) is larger; elsewhere `used`.
    fn past_register_arrays(&self, used: usize, dev: DeviceBuild) -> usize {
        if dev.register_array_bytes == 0 {
            return used;
        }
        let smallest = self.stack_entry().iter().map(|(_, t)| crate::interface::glsl_size(t)).fold(4, usize::min);
        used.max(dev.register_array_bytes as usize / smallest + 1)
    }

    /// The layout's stack entry fields in this variant's math.
    pub fn stack_entry(&self) -> &'static [(&'static str, &'static str)] {
        (self.layout.info().stack_entry)(self.math)
    }

    /// Whether this variant's kernels derive entries when entering children (the layout's
    /// [`LayoutInfo::defer_entries`](crate::layout::LayoutInfo), at every B: even at B = 2,
    /// where a group holds one child and takes a few bytes more than its entry, a visit that
    /// derives no entries needs fewer registers — RDNA3 f16h 96 → 84 VGPRs).
    pub fn defers_entries(&self) -> bool {
        self.layout.info().defer_entries
    }

    /// Stack bytes per ray that the traversal can use: entries × entry bytes (node index and
    /// the layout's fields, from the same definition the kernel's `struct Entry` is generated
    /// from); for a kernel that defers entries, groups × (node index, the layout's fields and
    /// the group's order word: 4 bytes, 12 at B = 16). On a device whose compiler keeps small
    /// arrays in registers the allocation may be larger ([`Variant::groups_alloc`]).
    pub fn stack_bytes(&self) -> u64 {
        let entry = interface::stack_entry_bytes(self.stack_entry());
        if self.defers_entries() {
            let meta = if self.branching > 8 { 12 } else { 4 };
            (stack_groups(self.branching) * (entry + meta)) as u64
        } else {
            (stack_entries(self.branching) * entry) as u64
        }
    }

    /// The generated `interface.glsl` of this variant's kernels.
    pub fn interface_glsl(&self) -> String {
        interface::glsl_header(Some((self.stack_entry(), &(self.layout.info().glsl_constants)())))
    }
}

impl std::fmt::Display for Variant {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(&self.name(false))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The one checked constructor names what is wrong, value first, for trace and
    /// `[[kernel]]` alike.
    #[test]
    fn a_checked_variant_names_the_bad_parameter() {
        let f16h = LayoutId::parse("f16h").unwrap();
        let f32 = LayoutId::f32();
        let v = Variant::checked(f16h, 8, 4, Some(Math::F32)).unwrap();
        assert_eq!((v.branching, v.packet, v.math), (8, 4, Math::F32));
        assert_eq!(Variant::checked(f16h, 4, 1, None).unwrap().math, f16h.default_math());
        let e = Variant::checked(f16h, 3, 1, None).unwrap_err();
        assert_eq!((e.parameter(), e.to_string()), ("branching", "3: use one of 2, 4, 8, 16".to_string()));
        let e = Variant::checked(f16h, 4, 2, None).unwrap_err();
        assert_eq!((e.parameter(), e.to_string()), ("packet", "2: use one of 1, 4, 8, 16, 32, 64".to_string()));
        let e = Variant::checked(f32, 4, 1, Some(Math::F16)).unwrap_err();
        assert_eq!((e.parameter(), e.to_string()), ("math", "f16: layout f32 has f32".to_string()));
    }

    #[test]
    fn stack_bytes_follow_the_layout_and_math() {
        let f32 = LayoutId::f32();
        let f16h = LayoutId::parse("f16h").unwrap();
        assert_eq!(Variant::new(f32, 4, 1).stack_bytes(), 97 * 8);
        // f16h's entry: node 4 + frame 16 + origin (fp16 6 or fp32 12) + e, tp, tlo 12 = 38 or
        // 44 bytes. Groups: depth - 1 of them (63 at B = 2, 31 at B = 4, 23 at B = 8, 15 at
        // B = 16), each an entry and its order word (4 bytes, 12 at B = 16).
        assert_eq!(Variant::new(f16h, 2, 1).with_math(Math::F16).stack_bytes(), 63 * 42);
        assert_eq!(Variant::new(f16h, 2, 1).with_math(Math::F32).stack_bytes(), 63 * 48);
        assert_eq!(Variant::new(f16h, 4, 1).with_math(Math::F16).stack_bytes(), 31 * 42);
        assert_eq!(Variant::new(f16h, 4, 1).with_math(Math::Mixed).stack_bytes(), 31 * 42);
        assert_eq!(Variant::new(f16h, 4, 1).with_math(Math::F32).stack_bytes(), 31 * 48);
        assert_eq!(Variant::new(f16h, 8, 1).with_math(Math::F16).stack_bytes(), 23 * 42);
        assert_eq!(Variant::new(f16h, 16, 1).with_math(Math::F32).stack_bytes(), 15 * 56);
        assert!(Variant::new(f16h, 2, 1).defers_entries() && Variant::new(f16h, 4, 1).defers_entries());
        assert!(!Variant::new(f32, 8, 1).defers_entries());
    }

    #[test]
    fn the_entry_stack_is_allocated_past_what_registers_hold() {
        let turnip = DeviceBuild { register_array_bytes: 768, ..DeviceBuild::FULL };
        for l in LayoutId::all().filter(|l| !l.info().defer_entries) {
            for &m in l.info().maths {
                for b in [2, 4, 8, 16] {
                    let v = Variant::new(l, b, 1).with_math(m);
                    assert_eq!(v.stack_alloc(DeviceBuild::FULL), stack_entries(b), "{}", v.name(false));
                    let smallest =
                        v.stack_entry().iter().map(|(_, t)| crate::interface::glsl_size(t)).fold(4, usize::min);
                    let n = v.stack_alloc(turnip);
                    assert!(n >= stack_entries(b) && n * smallest > 768, "{}: {n}", v.name(false));
                    assert!(n == stack_entries(b) || (n - 1) * smallest <= 768, "{}: {n}", v.name(false));
                    let defines = v.defines(PacketImpl::Subgroup, false, turnip);
                    assert!(defines.contains(&("STACK_ALLOC".into(), n.to_string())), "{}", v.name(false));
                }
            }
        }
    }

    #[test]
    fn the_group_stack_is_allocated_past_what_registers_hold() {
        let f16h = LayoutId::parse("f16h").unwrap();
        let poster = LayoutId::parse("f16h-poster").unwrap();
        let turnip = DeviceBuild { register_array_bytes: 256, ..DeviceBuild::FULL };
        for b in [2, 4, 8, 16] {
            for v in [Variant::new(f16h, b, 1), Variant::new(poster, b, 1)] {
                // Elsewhere the array is what the stack uses; on turnip every field's array
                // (the smallest field: 4 bytes, or 2 for a float16_t) exceeds 256 bytes.
                assert_eq!(v.groups_alloc(DeviceBuild::FULL), stack_groups(b), "{}", v.name(false));
                let smallest = v.stack_entry().iter().map(|(_, t)| crate::interface::glsl_size(t)).fold(4, usize::min);
                let n = v.groups_alloc(turnip);
                assert!(
                    n >= stack_groups(b) && n * smallest > 256 && (n - 1) * smallest <= 256,
                    "{}: {n}",
                    v.name(false)
                );
            }
        }
    }

    #[test]
    fn only_deferring_kernels_keep_the_next_entry_in_shared_memory() {
        let f16h = LayoutId::parse("f16h").unwrap();
        let has = |v: Variant, dev: DeviceBuild| {
            v.defines(PacketImpl::Subgroup, false, dev).iter().any(|(k, _)| k == "PENDING_SHARED")
        };
        let registers = DeviceBuild { pending_shared: false, ..DeviceBuild::FULL };
        for b in [2, 4, 8, 16] {
            assert!(has(Variant::new(f16h, b, 1), DeviceBuild::FULL), "f16h B = {b}");
            assert!(!has(Variant::new(f16h, b, 1), registers), "f16h B = {b}, registers");
            assert!(!has(Variant::new(LayoutId::f32(), b, 1), DeviceBuild::FULL), "f32 B = {b}");
        }
    }

    #[test]
    fn kernel_names_spell_the_variant() {
        let f16h = LayoutId::parse("f16h").unwrap();
        assert_eq!(Variant::new(LayoutId::f32(), 8, 1).name(false), "trav_f32_b8_p1");
        assert_eq!(
            Variant::new(f16h, 4, 16).with_math(Math::F32).kernel_name(PacketImpl::Subgroup, true),
            "trav_f16h_m32_b4_p16_subgroup_stats"
        );
        assert_eq!(
            Variant::new(LayoutId::f32(), 4, 64).kernel_name(PacketImpl::Hybrid, false),
            "trav_f32_b4_p64_hybrid"
        );
        assert_eq!(Variant::new(LayoutId::f32(), 4, 1).with_math(Math::F16).math, Math::F32, "f32 has one math mode");
    }
}

/// What a kernel's build takes from the device beyond its variant. None changes a value, so
/// none is in the kernel's name: `storage16`, fp16 nodes are read as `float16_t`, else as
/// pairs of halves in 32-bit words (`HALF_WORDS`, `glsl/node16.glsl`: the same bytes; a word
/// costs a shift or a conversion per half, so it is used only where 16-bit storage is missing).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct DeviceBuild {
    pub storage16: bool,
    /// The SPIR-V version the module is built for, 1.x: 5 (Vulkan 1.2 and later), 3 (1.1), 0
    /// (1.0). The same kernel either way; an older device is handed the version it accepts.
    pub spirv_minor: u8,
    /// The largest private array the compiler keeps in registers (bytes; 0: none known,
    /// [`crate::gpu::DeviceInfo::register_array_bytes`]): the stack is then allocated long
    /// enough that each of its fields' arrays is larger (`GROUPS_ALLOC`, `STACK_ALLOC`), so that
    /// it is kept in memory, as on other devices. Only its length changes.
    pub register_array_bytes: u32,
    /// A kernel that defers entries keeps the entry of the child it enters next in shared
    /// memory, one per invocation (`PENDING_SHARED`, `glsl/stack_groups.glsl`), not in
    /// registers across the visit's triangle tests ([`crate::gpu::DeviceInfo::pending_shared`]).
    /// Only where the entry is held changes.
    pub pending_shared: bool,
}

impl DeviceBuild {
    /// A Vulkan 1.2 GPU with 16-bit storage, whose compiler keeps no private array in
    /// registers, the next entry in shared memory (the SPIR-V in `spirv/`, `halftrace shaders`).
    pub const FULL: DeviceBuild =
        DeviceBuild { storage16: true, spirv_minor: 5, register_array_bytes: 0, pending_shared: true };
}
