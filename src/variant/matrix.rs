//! The kernel matrices, written once: the poster's series ([`series`], which the sweep's
//! configuration and the default matrix both use) and the named sets of kernels every command
//! builds from ([`matrix`]: `isa --quick`, `conformance --quick`, the default matrix of the
//! sweep, `isa` and `spirv/`, and the full cross product).

use super::{KernelId, KernelSpec, PacketImpl, Variant, LAYOUT_BRANCHINGS, PACKETS, SERIES_LAYOUTS};
use crate::bvh::BRANCHINGS;
use crate::layout::LayoutId;
use crate::precision::{FcChoice, Math};

/// Which kernels.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Matrix {
    /// Every layout and math at B = 4, P = 1 (`isa --quick`).
    Layouts,
    /// A set that touches every value of every axis at least once per layout (`conformance
    /// --quick`): every B at P = 1 in the default math, every other math once, every P at
    /// B = 4 (the maths in turn), and the build without float controls in every math at P = 1
    /// and at B = 8, P = 8 where the layout has one.
    Cover,
    /// The default sweep's matrix ([`series`] with every layout in every math).
    Default,
    /// Every layout, math, B and P; float controls on, and off where the layout has such a
    /// build.
    Full,
    /// Every layout and math at every B, P = 1: the single-ray kernels `memory --compilers`
    /// takes each kernel's occupancy from.
    Singles,
}

impl Matrix {
    /// The name `isa-model --matrix` takes.
    pub fn name(self) -> &'static str {
        match self {
            Matrix::Layouts => "layouts",
            Matrix::Cover => "cover",
            Matrix::Default => "default",
            Matrix::Full => "full",
            Matrix::Singles => "singles",
        }
    }

    pub fn parse(s: &str) -> Option<Matrix> {
        [Matrix::Layouts, Matrix::Cover, Matrix::Default, Matrix::Full, Matrix::Singles]
            .into_iter()
            .find(|m| m.name() == s)
    }
}

/// The poster's series over some layouts: every layout × its maths × `layout_branchings` at
/// P = 1, and for the `series` layouts also the B series (`branchings`) at P = 1 and the P
/// series (`packets`) at B = `packet_branching`.
pub struct Series<'a> {
    pub layouts: &'a [LayoutId],
    /// The math modes of a layout.
    pub maths: &'a dyn Fn(LayoutId) -> Vec<Math>,
    pub series: &'a [LayoutId],
    pub branchings: &'a [usize],
    pub layout_branchings: &'a [usize],
    pub packets: &'a [usize],
    pub packet_branching: usize,
}

/// The variants of a [`Series`], sorted (so each layout and B is contiguous), each once.
pub fn series(s: &Series) -> Vec<Variant> {
    let mut v = Vec::new();
    for &layout in s.layouts {
        for math in (s.maths)(layout) {
            for &b in s.layout_branchings {
                v.push(Variant::new(layout, b, 1).with_math(math));
            }
            if s.series.contains(&layout) {
                for &b in s.branchings {
                    v.push(Variant::new(layout, b, 1).with_math(math));
                }
                for &p in s.packets {
                    v.push(Variant::new(layout, s.packet_branching, p).with_math(math));
                }
            }
        }
    }
    v.sort();
    v.dedup();
    v
}

/// The default matrix's variants: the poster's two series — B ∈ {2, 4, 8, 16} at P = 1 and
/// P ∈ {4, 8, 16, 32, 64} at B = 4 — for the [`SERIES_LAYOUTS`], and every layout at
/// [`LAYOUT_BRANCHINGS`] with P = 1; every layout in every math mode.
pub fn default_variants() -> Vec<Variant> {
    let layouts: Vec<LayoutId> = LayoutId::all().collect();
    let series_layouts: Vec<LayoutId> =
        layouts.iter().copied().filter(|l| SERIES_LAYOUTS.contains(&l.name())).collect();
    series(&Series {
        layouts: &layouts,
        maths: &|l| l.info().maths.to_vec(),
        series: &series_layouts,
        branchings: &BRANCHINGS,
        layout_branchings: &LAYOUT_BRANCHINGS,
        packets: &PACKETS,
        packet_branching: 4,
    })
}

/// The built-in kernels of matrix `m`, per layout in registry order. `imps(p)`: the packet
/// implementations to build at a packet size p > 1 (`None`: the device's choice); P = 1 is
/// single-ray. Float controls: auto, except the builds the matrix names (`Cover`'s and
/// `Full`'s builds without them, and `Full`'s with them, are asked for exactly).
pub fn matrix(m: Matrix, imps: &dyn Fn(usize) -> Vec<Option<PacketImpl>>) -> Vec<KernelSpec> {
    let mut out = Vec::new();
    let mut add = |v: Variant, fc: FcChoice| {
        let imps = if v.packet == 1 { vec![None] } else { imps(v.packet) };
        out.extend(imps.into_iter().map(|imp| KernelSpec::builtin(v).with_fc(fc).with_imp(imp)));
    };
    match m {
        Matrix::Layouts => {
            for l in LayoutId::all() {
                for &math in l.info().maths {
                    add(Variant::new(l, 4, 1).with_math(math), FcChoice::Auto);
                }
            }
        }
        Matrix::Cover => {
            for l in LayoutId::all() {
                let maths = l.info().maths;
                for b in BRANCHINGS {
                    add(Variant::new(l, b, 1), FcChoice::Auto);
                }
                for (i, &m) in maths.iter().enumerate().skip(1) {
                    add(Variant::new(l, BRANCHINGS[i % BRANCHINGS.len()], 1).with_math(m), FcChoice::Auto);
                }
                for (j, p) in PACKETS.into_iter().filter(|&p| p > 1).enumerate() {
                    add(Variant::new(l, 4, p).with_math(maths[j % maths.len()]), FcChoice::Auto);
                }
                if l.info().float_controls_off {
                    for (i, &m) in maths.iter().enumerate() {
                        add(Variant::new(l, BRANCHINGS[(i + 1) % BRANCHINGS.len()], 1).with_math(m), FcChoice::Off);
                    }
                    add(Variant::new(l, 8, 8).with_math(maths[maths.len() - 1]), FcChoice::Off);
                }
            }
        }
        Matrix::Default => {
            for v in default_variants() {
                add(v, FcChoice::Auto);
            }
        }
        Matrix::Singles => {
            for l in LayoutId::all() {
                for &math in l.info().maths {
                    for b in BRANCHINGS {
                        add(Variant::new(l, b, 1).with_math(math), FcChoice::Auto);
                    }
                }
            }
        }
        Matrix::Full => {
            for l in LayoutId::all() {
                let fcs: &[FcChoice] =
                    if l.info().float_controls_off { &[FcChoice::On, FcChoice::Off] } else { &[FcChoice::On] };
                for &math in l.info().maths {
                    for b in BRANCHINGS {
                        for p in PACKETS {
                            for &fc in fcs {
                                add(Variant::new(l, b, p).with_math(math), fc);
                            }
                        }
                    }
                }
            }
        }
    }
    out
}

/// Every implementation of a packet: shared memory, a subgroup's clusters, the hybrid.
pub fn every_impl(_p: usize) -> Vec<Option<PacketImpl>> {
    vec![Some(PacketImpl::Subgroup), Some(PacketImpl::Shared), Some(PacketImpl::Hybrid)]
}

/// The device's choice at every packet size.
pub fn device_impl(_p: usize) -> Vec<Option<PacketImpl>> {
    vec![None]
}

/// The kernels kept in `spirv/` (timed; each also has its counting build): every kernel of
/// the default matrix with float controls, in its portable implementation, plus the subgroup
/// and hybrid implementations of every packet variant. Decided without a device: these are
/// the builds of a Vulkan 1.2 device with everything (`DeviceBuild::FULL`).
pub fn spirv_kernels() -> Vec<KernelId> {
    let portable = |_p: usize| vec![Some(PacketImpl::Shared), Some(PacketImpl::Subgroup), Some(PacketImpl::Hybrid)];
    matrix(Matrix::Default, &portable)
        .into_iter()
        .map(|k| KernelId::new(k.variant, k.imp.unwrap_or(PacketImpl::Single), false))
        .collect()
}
