//! What a result row measured, typed: [`What`] holds a kernel's identity as the input side's
//! own types ([`KernelId`]: layout, math, B, P, float controls, packet implementation), a
//! user's kernel or a baseline as their own cases, and a row this version cannot name as
//! it was read. Every row type ([`super::Row`], [`super::isa::IsaRow`],
//! [`super::estimate::RayRow`], `estimate::Row`) carries one, set where the row is made from
//! the kernel it measured, or parsed once where a file is read ([`What::read`]); and one
//! function answers which row is f32's peer ([`f32_peer`]).

use crate::baseline::BaselineId;
use crate::layout::LayoutId;
use crate::precision::{FloatControls, Math};
use crate::variant::{Buffers, KernelId, PacketImpl, Variant};

/// What one row measured.
#[derive(Clone, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum What {
    /// A built-in kernel.
    Builtin(KernelId),
    /// A user's kernel (`[[kernel]]`, `--kernel-file`) standing in for a built-in one: its
    /// name as given.
    User(String, KernelId),
    /// Someone else's traversal.
    Baseline(BaselineId),
    /// A row of another version: a layout or math this one does not know, kept as read.
    Unknown(Unknown),
}

/// The identity columns of a row this version cannot type.
#[derive(Clone, Debug, Default, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub struct Unknown {
    pub layout: String,
    pub math: String,
    pub branching: usize,
    pub packet: usize,
    pub float_controls: String,
    pub kernel: String,
}

impl Default for What {
    fn default() -> What {
        What::Unknown(Unknown::default())
    }
}

/// The identity columns as a file spells them.
#[derive(Clone, Copy, Debug)]
pub struct Columns<'a> {
    pub layout: &'a str,
    pub math: &'a str,
    pub branching: usize,
    pub packet: usize,
    /// `on`, `off`, `n/a` or empty (a file without the column).
    pub float_controls: &'a str,
    pub kernel: &'a str,
    /// `single`, `subgroup`, `shared`, `hybrid`, or `None` where the file has no such column
    /// (then the kernel's name says it).
    pub packet_impl: Option<&'a str>,
}

impl What {
    /// The one parser of a row's identity columns: a known layout in one of its math modes
    /// with a B and P it has is a kernel — built-in when `kernel` is the name the built-in
    /// kernel of those values has in some packet implementation, else a user's; a baseline's
    /// name is the baseline; anything else is [`What::Unknown`], kept as read.
    pub fn read(c: Columns) -> What {
        let unknown = || {
            What::Unknown(Unknown {
                layout: c.layout.into(),
                math: c.math.into(),
                branching: c.branching,
                packet: c.packet,
                float_controls: c.float_controls.into(),
                kernel: c.kernel.into(),
            })
        };
        if let Some(b) = BaselineId::parse(c.layout) {
            return What::Baseline(b);
        }
        let Ok(layout) = LayoutId::parse(c.layout) else { return unknown() };
        let math = match c.math.parse::<Math>() {
            Ok(m) if layout.info().maths.contains(&m) => m,
            _ => return unknown(),
        };
        if !crate::bvh::BRANCHINGS.contains(&c.branching) || !crate::variant::PACKETS.contains(&c.packet) {
            return unknown();
        }
        // `n/a`: a kernel the device could not build, named as its portable build; empty: a
        // file without the column (the kernel's name says it).
        let fcs: &[FloatControls] = match c.float_controls {
            "off" => &[FloatControls::Off],
            "on" => &[FloatControls::On],
            _ => &[FloatControls::On, FloatControls::Off],
        };
        let buffers = [Buffers::Bound, Buffers::Addressed];
        // Single rays have one implementation; a packet's name without a suffix is shared memory.
        let imps: &[PacketImpl] = if c.packet == 1 {
            &[PacketImpl::Single]
        } else {
            &[PacketImpl::Shared, PacketImpl::Subgroup, PacketImpl::Hybrid]
        };
        for &fc in fcs {
            for b in buffers {
                let v = Variant::new(layout, c.branching, c.packet).with_math(math).with_fc(fc).with_buffers(b);
                if let Some(id) = imps.iter().map(|&i| KernelId::new(v, i, false)).find(|id| id.name() == c.kernel) {
                    return What::Builtin(id);
                }
            }
        }
        let v = Variant::new(layout, c.branching, c.packet).with_math(math).with_fc(fcs[0]);
        let imp = match c.packet_impl.map(impl_of) {
            Some(Some(imp)) => imp,
            _ => v.portable_impl(),
        };
        What::User(c.kernel.into(), KernelId::new(v, imp, false))
    }

    /// The kernel, when the row measured one of a layout (built-in or a user's).
    pub fn kernel(&self) -> Option<&KernelId> {
        match self {
            What::Builtin(k) | What::User(_, k) => Some(k),
            _ => None,
        }
    }

    /// The built-in kernel, when the row measured one.
    pub fn builtin(&self) -> Option<&KernelId> {
        match self {
            What::Builtin(k) => Some(k),
            _ => None,
        }
    }

    /// The layout of a kernel's row.
    pub fn layout(&self) -> Option<LayoutId> {
        self.kernel().map(|k| k.variant.layout)
    }

    /// Whether the row measured f32's built-in kernel (the layout every other is compared with).
    pub fn is_f32(&self) -> bool {
        self.builtin().is_some_and(|k| k.variant.layout == LayoutId::f32())
    }

    /// Whether the row measured a built-in kernel of the poster's layout in its poster math
    /// ([`LayoutId::poster`]): the headline's numerator.
    pub fn is_poster(&self) -> bool {
        self.builtin().is_some_and(|k| (k.variant.layout, k.variant.math) == LayoutId::poster())
    }

    /// f32's built-in kernels this row compares with, in order of preference: the same B, P,
    /// packet implementation and float controls, then the other float controls (an fp16
    /// layout may build without them where f32 builds with them, or the other way round).
    /// None for a baseline or an unknown row.
    pub fn f32_peers(&self) -> Option<[What; 2]> {
        let k = self.kernel()?;
        let at = |fc: FloatControls| {
            let v = Variant::new(LayoutId::f32(), k.variant.branching, k.variant.packet)
                .with_fc(fc)
                .with_buffers(k.variant.buffers);
            What::Builtin(KernelId::new(v, k.imp, false))
        };
        let other = match k.variant.fc {
            FloatControls::On => FloatControls::Off,
            FloatControls::Off => FloatControls::On,
        };
        Some([at(k.variant.fc), at(other)])
    }
}

/// A packet implementation's name as files spell it.
pub fn impl_name(imp: PacketImpl) -> &'static str {
    match imp {
        PacketImpl::Single => "single",
        PacketImpl::Subgroup => "subgroup",
        PacketImpl::Shared => "shared",
        PacketImpl::Hybrid => "hybrid",
    }
}

fn impl_of(s: &str) -> Option<PacketImpl> {
    [PacketImpl::Single, PacketImpl::Subgroup, PacketImpl::Shared, PacketImpl::Hybrid]
        .into_iter()
        .find(|&i| impl_name(i) == s)
}

/// A result row of any kind, as [`f32_peer`] sees it.
/// Makes a result row type keyed: [`Keyed`] (its `what`, its place, its `status`) and
/// `typed()`, which parses `what` once from the row's identity columns (`layout`, `math`,
/// `branching`, `packet`, `kernel`) where rows are read. `$r` names the row in the expressions
/// for its place, its float-controls column and its packet implementation.
macro_rules! keyed_row {
    ($t:ident, |$r:ident| place: $place:expr, float_controls: $fc:expr, packet_impl: $imp:expr $(,)?) => {
        impl $crate::report::key::Keyed for $t {
            fn what(&self) -> &$crate::report::key::What {
                &self.what
            }
            fn place(&self) -> [&str; 4] {
                let $r = self;
                $place
            }
            fn ok(&self) -> bool {
                self.status.is_ok()
            }
        }

        impl $t {
            /// The row with its `what` parsed from its identity columns
            /// ([`What::read`](crate::report::key::What::read)).
            pub fn typed(mut self) -> $t {
                let $r = &self;
                let what = $crate::report::key::What::read($crate::report::key::Columns {
                    layout: &$r.layout,
                    math: &$r.math,
                    branching: $r.branching,
                    packet: $r.packet,
                    float_controls: $fc,
                    kernel: &$r.kernel,
                    packet_impl: $imp,
                });
                self.what = what;
                self
            }
        }
    };
}
pub(crate) use keyed_row;

pub trait Keyed {
    /// What the row measured.
    fn what(&self) -> &What;
    /// Where: the device (or family), its driver, the scene and the ray set — all of which
    /// a peer shares (empty where a row type has no such column).
    fn place(&self) -> [&str; 4];
    /// Whether the row holds a result.
    fn ok(&self) -> bool;
}

/// The row of `rows` that is `row`'s f32 peer: an ok row in the same place measuring f32's
/// built-in kernel at the same B, P, packet implementation and float controls (else the other
/// float controls) — the one answer the tables, `isa`, `estimate` and the memory results use.
/// `row` itself when it is f32's kernel; None for a baseline, an unknown row, or where f32 has
/// no ok row. `rows`: a slice's `iter()`, or references already filtered.
pub fn f32_peer<'a, R: Keyed + 'a>(row: &R, rows: impl IntoIterator<Item = &'a R> + Clone) -> Option<&'a R> {
    let peers = row.what().f32_peers()?;
    let place = row.place();
    peers.iter().find_map(|p| rows.clone().into_iter().find(|r| r.ok() && r.place() == place && r.what() == p))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn cols<'a>(layout: &'a str, math: &'a str, b: usize, p: usize, fc: &'a str, kernel: &'a str) -> Columns<'a> {
        Columns { layout, math, branching: b, packet: p, float_controls: fc, kernel, packet_impl: None }
    }

    /// Every built-in kernel of the full matrix reads back as itself from its columns.
    #[test]
    fn every_builtin_kernel_reads_back_from_its_columns() {
        let imps = |_p: usize| vec![Some(PacketImpl::Subgroup), Some(PacketImpl::Shared), Some(PacketImpl::Hybrid)];
        for spec in crate::variant::matrix(crate::variant::Matrix::Full, &imps) {
            let v = spec.variant.with_fc(match spec.fc {
                crate::precision::FcChoice::Off => FloatControls::Off,
                _ => FloatControls::On,
            });
            let id = KernelId::new(v, spec.imp.filter(|_| v.packet > 1).unwrap_or(PacketImpl::Single), false);
            let name = id.name();
            let got = What::read(cols(v.layout.name(), v.math.name(), v.branching, v.packet, v.fc.name(), &name));
            assert_eq!(got, What::Builtin(id), "{name}");
        }
    }

    #[test]
    fn users_baselines_and_unknown_names_keep_their_cases() {
        let f16h = LayoutId::parse("f16h").unwrap();
        let mine = What::read(cols("f16h", "f16", 4, 1, "on", "mine"));
        assert_eq!(mine, What::User("mine".into(), KernelId::new(Variant::new(f16h, 4, 1), PacketImpl::Single, false)));
        assert!(matches!(What::read(cols("rq", "n/a", 0, 0, "n/a", "trav_rq")), What::Baseline(_)));
        for c in [
            cols("f99", "f16", 4, 1, "on", "trav_f99_b4_p1"),
            cols("f16h", "f64", 4, 1, "on", "x"),
            cols("f16h", "f16", 3, 1, "on", "x"),
        ] {
            assert!(matches!(What::read(c), What::Unknown(_)), "{c:?}");
        }
    }

    #[test]
    fn the_peer_is_f32_at_the_same_b_p_implementation_and_float_controls() {
        let q8 = What::read(cols("q8", "f32", 8, 8, "off", "trav_q8_m32_b8_p8_fcoff_subgroup"));
        let [same, other] = q8.f32_peers().unwrap();
        assert_eq!(same.builtin().unwrap().name(), "trav_f32_b8_p8_fcoff_subgroup");
        assert_eq!(other.builtin().unwrap().name(), "trav_f32_b8_p8_subgroup");
        assert!(What::read(cols("embree", "n/a", 0, 0, "n/a", "x")).f32_peers().is_none());
    }
}
