//! The one list of layouts and baselines. The command line, the variant matrix, the sweep,
//! the report and `shaders --emit` read it; nothing else names a layout. Adding a layout is
//! one line in [`REGISTRY`].

use super::{EncodeError, Encoded, Layout, Math, Needs};
use crate::bvh::WideBvh;
use crate::gpu::kernel::RunOutput;
use crate::gpu::{Gpu, GpuError};
use crate::rays::Ray;
use crate::scene::Scene;
use crate::trace::{Counters, Hit};
use crate::variant::FloatControls;
use std::marker::PhantomData;

/// Every layout and baseline, in report order.
pub static REGISTRY: &[Entry] = &[
    Entry::Layout(&Plug::<super::f32::F32>::NEW),
    Entry::Layout(&Plug::<super::f16h::F16h>::NEW),
    Entry::Layout(&Plug::<super::f16w::F16w>::NEW),
    Entry::Layout(&Plug::<super::f16a::F16a>::NEW),
    Entry::Layout(&Plug::<super::q8::Q8>::NEW),
    Entry::Layout(&Plug::<super::f16h_seed::F16hSeed>::NEW),
    Entry::Baseline(&crate::gpu::rq::Rq),
    Entry::Baseline(&crate::embree::Embree),
];

/// A registered layout (our BVH in one precision layout, traced by our kernels) or baseline
/// (someone else's traversal of the same triangles, e.g. the driver's ray queries).
pub enum Entry {
    Layout(&'static dyn DynLayout),
    Baseline(&'static dyn Baseline),
}

/// What a registry entry supports.
#[derive(Clone, Copy, Debug)]
pub struct Caps {
    /// Branching factor B applies.
    pub branching: bool,
    /// Packet size P applies.
    pub packets: bool,
    /// Work counters (nodes, box and triangle tests) exist.
    pub counters: bool,
    /// Arithmetic modes (empty: not applicable); the first is the default.
    pub maths: &'static [Math],
    /// Results are checked bit for bit against a CPU reference of the same layout (else they
    /// are compared with the f32 reference and reported as agreement).
    pub exact: bool,
}

/// A handle to a registry entry.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub struct LayoutId(u8);

impl LayoutId {
    /// Every entry, in registry order.
    pub fn all() -> impl Iterator<Item = LayoutId> {
        (0..REGISTRY.len()).map(|i| LayoutId(i as u8))
    }

    /// Every BVH layout (no baselines).
    pub fn layouts() -> impl Iterator<Item = LayoutId> {
        Self::all().filter(|l| l.bvh().is_some())
    }

    /// The entry called `name`.
    pub fn parse(name: &str) -> Result<LayoutId, EncodeError> {
        Self::all()
            .find(|l| l.name() == name)
            .ok_or_else(|| EncodeError::UnknownLayout(name.to_string(), Self::names()))
    }

    /// The layout implemented by `L`.
    pub fn of<L: Layout>() -> LayoutId {
        Self::parse(L::NAME).expect("every Layout is registered")
    }

    /// The fp32 baseline layout every other is compared with.
    pub fn f32() -> LayoutId {
        Self::of::<super::f32::F32>()
    }

    /// "f32, f16h or rq".
    pub fn names() -> String {
        let n: Vec<&str> = Self::all().map(|l| l.name()).collect();
        match n.split_last() {
            Some((last, rest)) if !rest.is_empty() => format!("{} or {last}", rest.join(", ")),
            _ => n.join(""),
        }
    }

    pub fn entry(self) -> &'static Entry {
        &REGISTRY[self.0 as usize]
    }

    pub fn name(self) -> &'static str {
        match self.entry() {
            Entry::Layout(l) => l.name(),
            Entry::Baseline(b) => b.name(),
        }
    }

    pub fn summary(self) -> &'static str {
        match self.entry() {
            Entry::Layout(l) => l.summary(),
            Entry::Baseline(b) => b.summary(),
        }
    }

    /// The BVH layout, or `None` for a baseline.
    pub fn bvh(self) -> Option<&'static dyn DynLayout> {
        match self.entry() {
            Entry::Layout(l) => Some(*l),
            Entry::Baseline(_) => None,
        }
    }

    /// The baseline, or `None` for a BVH layout.
    pub fn baseline(self) -> Option<&'static dyn Baseline> {
        match self.entry() {
            Entry::Layout(_) => None,
            Entry::Baseline(b) => Some(*b),
        }
    }

    pub fn caps(self) -> Caps {
        match self.entry() {
            Entry::Layout(l) => Caps { branching: true, packets: true, counters: true, maths: l.maths(), exact: true },
            Entry::Baseline(_) => Caps { branching: false, packets: false, counters: false, maths: &[], exact: false },
        }
    }
}

impl std::fmt::Display for LayoutId {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

impl std::str::FromStr for LayoutId {
    type Err = EncodeError;
    fn from_str(s: &str) -> Result<LayoutId, EncodeError> {
        LayoutId::parse(s)
    }
}

/// The object-safe face of a [`Layout`], implemented once for all of them by [`Plug`].
pub trait DynLayout: Send + Sync {
    fn name(&self) -> &'static str;
    fn summary(&self) -> &'static str;
    fn maths(&self) -> &'static [Math];
    /// The GLSL hooks source.
    fn glsl(&self) -> &'static str;
    fn stack_entry(&self, math: Math) -> &'static [(&'static str, &'static str)];
    fn needs(&self, math: Math) -> Needs;
    fn float_controls_off(&self) -> bool;
    fn conservative(&self) -> bool;
    fn glsl_constants(&self) -> String;
    fn encode(&self, scene: &Scene, w: &WideBvh) -> Result<Encoded, EncodeError>;
    /// The CPU reference: rays in packets of `p` (1: single rays) in math mode `math`.
    fn trace(&self, enc: &Encoded, rays: &[Ray], p: usize, math: Math, fc: FloatControls) -> (Vec<Hit>, Vec<Counters>);
}

/// Registers a [`Layout`]: `Entry::Layout(&Plug::<MyLayout>::NEW)`.
pub struct Plug<L>(PhantomData<fn() -> L>);

impl<L: Layout> Plug<L> {
    pub const NEW: Plug<L> = Plug(PhantomData);
}

/// Calls `$f::<B>` for the runtime branching factor `$b` — the one place where B becomes a
/// type-level constant.
macro_rules! with_branching {
    ($b:expr, $f:ident $(, $arg:expr)*) => {
        match $b {
            2 => $f::<L, 2>($($arg),*),
            4 => $f::<L, 4>($($arg),*),
            8 => $f::<L, 8>($($arg),*),
            16 => $f::<L, 16>($($arg),*),
            b => unreachable!("branching {b} is checked before encoding"),
        }
    };
}

fn encode_b<L: Layout, const B: usize>(scene: &Scene, w: &WideBvh) -> Result<Encoded, EncodeError> {
    let reordered = L::reorder(w);
    let w = reordered.as_ref().unwrap_or(w);
    let (nodes, root) = L::encode::<B>(scene, w)?;
    let rb = w.nodes[0].bounds;
    Ok(Encoded {
        layout: LayoutId::of::<L>(),
        branching: B,
        nodes: Box::new(nodes),
        push_root: L::push_root(&root),
        root: Box::new(root),
        root_box: rb,
        tris: super::TriBuffer::new(scene, w),
        max_stack: w.max_stack(),
    })
}

fn trace_b<L: Layout, const B: usize>(
    enc: &Encoded,
    rays: &[Ray],
    p: usize,
    math: Math,
    fc: FloatControls,
) -> (Vec<Hit>, Vec<Counters>) {
    let (nodes, root) = enc.typed::<L, B>().expect("Encoded of another layout or B");
    crate::trace::traverse::trace_all::<L, B>(nodes, root, enc, rays, p, math, fc)
}

impl<L: Layout> DynLayout for Plug<L> {
    fn name(&self) -> &'static str {
        L::NAME
    }
    fn summary(&self) -> &'static str {
        L::SUMMARY
    }
    fn maths(&self) -> &'static [Math] {
        L::MATHS
    }
    fn glsl(&self) -> &'static str {
        L::GLSL
    }
    fn stack_entry(&self, math: Math) -> &'static [(&'static str, &'static str)] {
        L::stack_entry(math)
    }
    fn needs(&self, math: Math) -> Needs {
        L::needs(math)
    }
    fn float_controls_off(&self) -> bool {
        L::FLOAT_CONTROLS_OFF
    }
    fn conservative(&self) -> bool {
        L::CONSERVATIVE
    }
    fn glsl_constants(&self) -> String {
        L::glsl_constants()
    }
    fn encode(&self, scene: &Scene, w: &WideBvh) -> Result<Encoded, EncodeError> {
        with_branching!(w.branching, encode_b, scene, w)
    }
    fn trace(&self, enc: &Encoded, rays: &[Ray], p: usize, math: Math, fc: FloatControls) -> (Vec<Hit>, Vec<Counters>) {
        assert!(L::MATHS.contains(&math), "{}: math {} is not one of its modes", L::NAME, math.name());
        with_branching!(enc.branching, trace_b, enc, rays, p, math, fc)
    }
}

/// A traversal that is not ours, run on the same rays as the baseline a user would otherwise
/// pick (`rq`: the driver's ray queries). Its results are compared with the f32 reference and
/// reported as agreement; it has no B, P or work counters.
pub trait Baseline: Send + Sync {
    fn name(&self) -> &'static str;
    fn summary(&self) -> &'static str;
    /// The `kernel` column of its rows.
    fn kernel(&self) -> &'static str;
    /// Why a device cannot run it (one line for the report and `devices`), or `None`.
    fn unavailable(&self, info: &crate::gpu::DeviceInfo) -> Option<String>;
    /// What it needs once per device (pipelines).
    fn prepare<'g>(&self, gpu: &'g Gpu) -> Result<Box<dyn BaselineDevice + 'g>, GpuError>;
}

/// A baseline prepared on one device.
pub trait BaselineDevice {
    /// Builds its structures over a scene's triangles (in `prim` order).
    fn scene<'s>(&'s self, scene: &Scene) -> Result<Box<dyn BaselineScene + 's>, GpuError>;
}

/// A baseline's structures over one scene.
pub trait BaselineScene {
    /// Bytes of its acceleration structures.
    fn bytes(&self) -> u64;
    /// Build time, ms.
    fn build_ms(&self) -> f64;
    /// `warmup` untimed then `repeat` timed traversals of `rays` (at least one in all).
    fn run(&self, rays: &[Ray], warmup: usize, repeat: usize) -> Result<RunOutput, GpuError>;
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn names_are_unique_and_parse_back() {
        for l in LayoutId::all() {
            assert_eq!(LayoutId::parse(l.name()), Ok(l));
            assert_eq!(LayoutId::all().filter(|m| m.name() == l.name()).count(), 1);
        }
        assert_eq!(LayoutId::f32().name(), "f32");
        let e = LayoutId::parse("f8").unwrap_err().to_string();
        assert!(e.contains("unknown layout 'f8'") && e.contains("f32, f16h"), "{e}");
    }
}
