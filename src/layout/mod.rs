//! Precision layouts, the unit of extension. A layout is everything that differs between
//! `f32`, `f16h`, …: its node bytes, its encoder, the hooks it plugs into the one traversal
//! skeleton ([`traverse`]: which children a ray enters, in which order, with which per-child
//! state) and what a stack entry carries. Everything else — BVH build, rays, the traversal
//! loop, leaf tests, packets, counters, validation, timing, sweep, report — is shared.
//!
//! A layout is one folder here (`src/layout/<name>/`: node type, encoder, CPU hooks, its
//! [`LayoutInfo`]), one GLSL hooks file (`glsl/layout/<name>.glsl`) and one line in the
//! [`layouts!`] list below (its module and the type implementing [`Layout`]). Code two or more
//! layouts share lives beside them, each file mirrored by a GLSL header of the same name: [`half`] (fp16 box tests with an error bound,
//! `glsl/half.glsl`), [`frames`] (uniformly scaled frames, also in `half.glsl`), [`node16`]
//! (the fp16 node, `glsl/node16.glsl`) and [`anchored`] (origins re-derived per node,
//! `glsl/anchored.glsl`). `docs/architecture.md` walks through adding a layout.

pub mod anchored;
pub mod encoded;
pub mod frames;
pub mod half;
pub mod node16;
pub mod registry;
pub mod traverse;

pub use encoded::{Encoded, NodeArray, TriBuffer};
pub use registry::{DynLayout, LayoutId, UnknownLayout};

/// Declares each layout's module and lists it in [`REGISTRY`], in report order.
macro_rules! layouts {
    ($($module:ident :: $layout:ident),* $(,)?) => {
        $(pub mod $module;)*
        /// Every layout, in report order. The command line, the variant matrix, the sweep, the
        /// report and `shaders --emit` read it; nothing else names a layout.
        pub static REGISTRY: &[&dyn DynLayout] = &[$(&registry::Plug::<$module::$layout>::NEW),*];
    };
}

layouts! {
    f32::F32,
    f16h::F16h,
    f16w::F16w,
    f16a::F16a,
    q8::Q8,
    f16h_poster::F16hPoster,
}

use crate::base::{Counters, RayPre};
use crate::bvh::{ChildRef, WideBvh};
use crate::interface::{inner_word, is_leaf, leaf_parts, leaf_word};
use crate::precision::{FloatControls, Math};
use thiserror::Error;

/// What the harness knows of a layout besides its hooks, in one value (`Layout::INFO`): the
/// command line, the variant matrix, device support, the kernels' generated header and the
/// report all read it through the registry.
#[derive(Clone, Copy)]
pub struct LayoutInfo {
    /// Name in flags, configs, kernel names and reports.
    pub name: &'static str,
    /// One line for `--help`, `halftrace devices` and the docs.
    pub summary: &'static str,
    /// Arithmetic modes of the box tests; the first is the default.
    pub maths: &'static [Math],
    /// The GLSL hooks (`glsl/layout/<name>.glsl`); kernels include them as `layout.glsl`.
    pub glsl: &'static str,
    /// Whether the hooks have a build without float controls (`FC_OFF`) whose hits stay
    /// exact under any faithful rounding and without inf/NaN preservation.
    pub float_controls_off: bool,
    /// Whether the hooks are conservative, so the traversal returns exactly the f32 closest
    /// hit (every layout but the poster's literal algorithm, `f16h-poster`, which is
    /// validated against its own CPU reference and whose disagreements with f32 are reported).
    pub conservative: bool,
    /// What the kernels need from the device in each math mode.
    pub needs: fn(Math) -> Needs,
    /// The stack entry's fields besides the node index, as (name, GLSL type), per math mode:
    /// generated into the kernels' `struct Entry` and counted in the report's stack bytes.
    pub stack_entry: fn(Math) -> &'static [(&'static str, &'static str)],
    /// Whether the kernels derive a child's entry when they enter the child rather
    /// than when they push it (trav.comp, `DEFER_ENTRIES`): the stack then holds one group
    /// per visit (node, entry, hit mask and order of the children left), not an entry per
    /// child — for layouts whose entries are large. The hooks' `ChildHit` and `child_entry`
    /// must then not depend on the closest hit so far; the entries, hits and counters are the
    /// same either way.
    pub defer_entries: bool,
    /// Constants the hooks share with the GLSL side, generated into `interface.glsl` (see
    /// [`crate::interface::glsl_float`]).
    pub glsl_constants: fn() -> String,
}

impl LayoutInfo {
    /// The defaults a layout's `INFO` starts from (`..LayoutInfo::DEFAULT`): one math mode
    /// (fp32), conservative, no build without float controls, no device features, no
    /// constants. `name`, `summary`, `glsl` and `stack_entry` are always given.
    pub const DEFAULT: LayoutInfo = LayoutInfo {
        name: "",
        summary: "",
        maths: &[Math::F32],
        glsl: "",
        float_controls_off: false,
        conservative: true,
        needs: |_| Needs::NONE,
        stack_entry: |_| &[],
        defer_entries: false,
        glsl_constants: String::new,
    };
}

/// Device features a layout's kernels use in one math mode (the shared parts — fp32 leaf
/// tests, fp32 root box — need none of these).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Needs {
    /// 16-bit values in storage buffers (`storageBuffer16BitAccess`). No built-in layout needs
    /// it (on a device without it, fp16 nodes are read from 32-bit words: `HALF_WORDS` in
    /// `glsl/node16.glsl`); a layout added with hooks that declare 16-bit buffers sets it.
    pub storage16: bool,
    /// fp16 arithmetic (`shaderFloat16`); with float controls on, also fp16
    /// round-to-nearest-even and fp16 signed-zero/inf/NaN preservation.
    pub float16: bool,
}

impl Needs {
    pub const NONE: Needs = Needs { storage16: false, float16: false };
}

/// Why a BVH does not fit a layout, naming the layout and the node.
#[derive(Debug, Error, PartialEq)]
#[error("{layout}: node {node} {msg}")]
pub struct EncodeError {
    pub layout: &'static str,
    pub node: usize,
    pub msg: String,
}

/// The child word of a wide BVH child ([`crate::interface`] owns the bits).
pub fn encode_child(c: &ChildRef) -> u32 {
    match *c {
        ChildRef::Inner(i) => inner_word(i),
        ChildRef::Leaf { first, count } => leaf_word(first, count),
    }
}

/// Decodes a non-empty child word.
#[inline]
pub fn decode_child(w: u32) -> ChildRef {
    if is_leaf(w) {
        let (first, count) = leaf_parts(w);
        ChildRef::Leaf { first, count }
    } else {
        ChildRef::Inner(w)
    }
}

/// A node of one layout at one branching factor: a `#[repr(C)]` struct without padding whose
/// bytes are exactly what the layout's GLSL `Node` struct reads (a GPU round-trip test proves
/// it for every layout and B).
pub trait Node: Copy + Send + Sync + 'static {
    /// Child reference word of slot `s`.
    fn child(&self, s: usize) -> u32;
    /// The stored box of slot `s` in the layout's own coordinates, widened exactly to f32
    /// (the GLSL hook `child_box` returns the same values).
    fn child_box(&self, s: usize) -> ([f32; 3], [f32; 3]);
    /// Appends the node's bytes in declaration order, as uploaded to the GPU.
    fn write_bytes(&self, out: &mut Vec<u8>);
}

/// What a precision layout plugs into the shared traversal. The CPU skeleton ([`traverse`])
/// and the GLSL skeleton (`glsl/trav.comp`, with the layout's `glsl/layout/<name>.glsl`) call
/// the same hooks in the same order:
///
/// ```text
/// root box hit at `near`     → root_entry
/// pop (node, entry)          → the ray is active when entry_t(entry) ≤ its closest hit
///                              visit (per node and ray)
///   each non-empty slot      → test_child: hit? with a sort key (entry distance)
///   hit slots, by (key, slot): leaves tested; inner children → child_entry, pushed
///                              farthest first
/// ```
///
/// The hooks must be conservative (never reject a box the exact ray reaches inside its
/// interval), so that a traversal returns exactly the fp32 closest hit; the bound each relies
/// on is argued beside its code.
pub trait Layout: Send + Sync + Sized + 'static {
    /// Name, modes, device needs, stack entry, GLSL: everything but the hooks.
    const INFO: LayoutInfo;

    /// The node struct at branching factor `B`.
    type Node<const B: usize>: Node;
    /// Per-BVH data the traversal needs besides the nodes (f16h: the root frame).
    type Root: Copy + Send + Sync + 'static;
    /// Per-ray constants, including the math mode where the hooks need it.
    type Ray: Copy + Send + Sync;
    /// What a stack entry carries for one ray besides the node index.
    type Entry: Copy + Send + Sync;
    /// Per-ray quantities fixed for one visit of one node.
    type Visit: Copy + Send + Sync;
    /// What a hit child's box test hands to [`Layout::child_entry`].
    type ChildHit: Copy + Send + Sync;

    /// A layout that needs its own order of nodes or triangles (e.g. `q8`: each node's inner
    /// children and leaf triangles contiguous) returns the same tree rearranged; it is encoded
    /// from that, and the shared triangle buffer follows its triangle order.
    fn reorder(_w: &WideBvh) -> Option<WideBvh> {
        None
    }
    /// Encodes a wide BVH whose branching factor is `B`.
    fn encode<const B: usize>(w: &WideBvh) -> Result<(Vec<Self::Node<B>>, Self::Root), EncodeError>;
    /// The `root` vec4 of the push constants (what the kernels need from the host).
    fn push_root(root: &Self::Root) -> [f32; 4];

    fn ray(r: &RayPre, math: Math, fc: FloatControls) -> Self::Ray;
    /// The entry of the root node for a ray that enters the root box at `near`.
    fn root_entry(root: &Self::Root, r: &RayPre, lr: &Self::Ray, near: f32) -> Self::Entry;
    /// A lower bound of the world parameter of anything that can still matter under the
    /// entry: the node is skipped for the ray when it exceeds the closest hit.
    fn entry_t(e: &Self::Entry) -> f32;
    /// Per node and active ray, before its box tests (`n` is the node being visited).
    fn visit<const B: usize>(
        n: &Self::Node<B>,
        root: &Self::Root,
        e: &Self::Entry,
        r: &RayPre,
        lr: &Self::Ray,
        best_t: f32,
    ) -> Self::Visit;
    /// The box test of slot `s`: `Some((key, data))` when the ray may touch the child; `key`
    /// orders the children (nearest first).
    fn test_child<const B: usize>(
        n: &Self::Node<B>,
        s: usize,
        e: &Self::Entry,
        v: &Self::Visit,
        r: &RayPre,
        lr: &Self::Ray,
    ) -> Option<(f32, Self::ChildHit)>;
    /// The stack entry of a hit inner child.
    #[allow(clippy::too_many_arguments)]
    fn child_entry<const B: usize>(
        n: &Self::Node<B>,
        s: usize,
        e: &Self::Entry,
        v: &Self::Visit,
        h: &Self::ChildHit,
        r: &RayPre,
        lr: &Self::Ray,
        c: &mut Counters,
    ) -> Self::Entry;
}
