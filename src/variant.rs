//! The variant matrix as data: layout × branching × packet size. Artifact names spell the
//! values (`trav_f16h_b8_p1`).

use crate::bvh::BRANCHINGS;
use crate::encode::Layout;
pub use crate::trace::f16h::Math;

/// One traversal kernel configuration.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub struct Variant {
    pub layout: Layout,
    pub branching: usize,
    /// Rays per packet (1 = single-ray traversal).
    pub packet: usize,
    /// f16h arithmetic (the f32 layout always has `Math::F32`).
    pub math: Math,
}

pub use crate::trace::packet::PACKETS;

/// How the P rays of a packet cooperate on the GPU.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum PacketImpl {
    /// P = 1: classic per-invocation traversal.
    Single,
    /// Clusters of P invocations of a subgroup (P ≤ subgroup size), clustered subgroup ops.
    Subgroup,
    /// One packet per workgroup of P invocations, reductions through shared memory.
    Shared,
}

impl PacketImpl {
    /// The implementation used for packet size `p` on a device with `subgroup` lanes.
    pub fn choose(p: usize, subgroup: u32) -> PacketImpl {
        if p == 1 {
            PacketImpl::Single
        } else if p <= subgroup as usize {
            PacketImpl::Subgroup
        } else {
            PacketImpl::Shared
        }
    }
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

impl Variant {
    /// A variant in its layout's default math (f16h: the seed's fp16 math).
    pub fn new(layout: Layout, branching: usize, packet: usize) -> Variant {
        let math = if layout == Layout::F32 { Math::F32 } else { Math::F16 };
        Variant { layout, branching, packet, math }
    }

    /// The same variant with another f16h math mode (no effect on f32).
    pub fn with_math(mut self, math: Math) -> Variant {
        if self.layout == Layout::F16h {
            self.math = math;
        }
        self
    }

    /// The kernel's name: `trav_{layout}[_{math}]_b{B}_p{P}` (math m16, m32 or mix for f16h),
    /// then `_subgroup` for the subgroup packet implementation and `_stats` for the counting
    /// kernel. Packets of P > 1 without a suffix use shared memory (portable to any subgroup
    /// size).
    pub fn kernel_name(&self, imp: PacketImpl, stats: bool) -> String {
        format!(
            "trav_{}{}_b{}_p{}{}{}",
            self.layout.name(),
            if self.layout == Layout::F16h { format!("_{}", self.math.tag()) } else { String::new() },
            self.branching,
            self.packet,
            if imp == PacketImpl::Subgroup { "_subgroup" } else { "" },
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
            PacketImpl::Shared => self.packet as u32,
            _ => 64,
        }
    }

    /// The default matrix (the seed's two series): every layout (f16h in every math mode) with
    /// B ∈ {2, 4, 8, 16} at P = 1, and P ∈ {4, 8, 16, 32, 64} at B = 4.
    pub fn matrix() -> Vec<Variant> {
        let mut v = Vec::new();
        for layout in Layout::ALL {
            let maths: &[Math] = if layout == Layout::F16h { &Math::ALL } else { &[Math::F32] };
            for &math in maths {
                for b in BRANCHINGS {
                    v.push(Variant::new(layout, b, 1).with_math(math));
                }
                for p in PACKETS.into_iter().filter(|&p| p > 1) {
                    v.push(Variant::new(layout, 4, p).with_math(math));
                }
            }
        }
        v
    }

    /// The GLSL entry file of this variant.
    pub fn source_file(&self) -> &'static str {
        match (self.layout, self.packet) {
            (Layout::F32, 1) => "trav_f32.comp",
            (Layout::F16h, 1) => "trav_f16h.comp",
            (Layout::F32, _) => "trav_f32_packet.comp",
            (Layout::F16h, _) => "trav_f16h_packet.comp",
        }
    }

    /// Preprocessor definitions of this variant.
    pub fn defines(&self, imp: PacketImpl, stats: bool, f64_fallback: bool) -> Vec<(String, String)> {
        let mut d = vec![
            ("B".to_string(), self.branching.to_string()),
            ("P".to_string(), self.packet.to_string()),
            ("WG".to_string(), self.workgroup(imp).to_string()),
            ("STACK_SIZE".to_string(), stack_entries(self.branching).to_string()),
        ];
        if imp == PacketImpl::Subgroup {
            d.push(("PACKET_SUBGROUP".into(), "1".into()));
        }
        if self.layout == Layout::F16h {
            match self.math {
                Math::F32 => d.push(("MATH_F32".into(), "1".into())),
                Math::Mixed => d.push(("MATH_MIXED".into(), "1".into())),
                Math::F16 => {}
            }
        }
        if stats {
            d.push(("STATS".into(), "1".into()));
        }
        if f64_fallback {
            d.push(("HAS_F64".into(), "1".into()));
        }
        d
    }
}

impl std::fmt::Display for Variant {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(&self.name(false))
    }
}

/// The kernels kept in `spirv/`: every variant of the default matrix in its portable
/// implementation, plus the subgroup implementation of every packet variant.
pub fn spirv_matrix() -> Vec<(Variant, PacketImpl)> {
    let mut out = Vec::new();
    for v in Variant::matrix() {
        out.push((v, v.portable_impl()));
        if v.packet > 1 {
            out.push((v, PacketImpl::Subgroup));
        }
    }
    out
}
