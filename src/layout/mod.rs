//! Precision layouts, the unit of extension. A layout is everything that differs between
//! `f32`, `f16h`, …: its node bytes, its encoder, the hooks it plugs into the one traversal
//! skeleton (which children a ray enters, in which order, with which per-child state) and what
//! a stack entry carries. Everything else — BVH build, rays, the traversal loop, leaf tests,
//! packets, counters, validation, timing, sweep, report — is shared.
//!
//! A layout is one folder here (`src/layout/<name>/`: node type, encoder, CPU hooks) plus one
//! GLSL hooks file (`glsl/layout/<name>.glsl`) plus one line in [`registry::REGISTRY`]. The
//! [`Layout`] trait says what to implement; `docs/architecture.md` walks through it.

pub mod anchored;
pub mod f16a;
pub mod f16h;
pub mod f16h_seed;
pub mod f16w;
pub mod f32;
pub mod q8;
pub mod registry;

pub use registry::{Baseline, BaselineDevice, BaselineScene, Caps, DynLayout, Entry, LayoutId, REGISTRY};

use crate::bvh::{BinaryBvh, ChildRef, WideBvh};
use crate::geom::Aabb;
use crate::rays::Ray;
use crate::scene::Scene;
use crate::trace::{Counters, Hit, RayPre};
use std::any::Any;
use thiserror::Error;

/// Arithmetic of a layout's box tests (and origin moves), separate from its storage precision.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum Math {
    /// fp16 arithmetic (`float16_t`; the seed's mode for f16h).
    F16,
    /// fp32 arithmetic (reduced-precision values widened on load).
    F32,
    /// fp16 differences and products; fp32 min/max, widening and comparisons.
    Mixed,
}

impl Math {
    pub const ALL: [Math; 3] = [Math::F16, Math::F32, Math::Mixed];
    /// Name in flags, configs and reports: f16, f32, mixed.
    pub fn name(self) -> &'static str {
        match self {
            Math::F16 => "f16",
            Math::F32 => "f32",
            Math::Mixed => "mixed",
        }
    }
    /// Tag in kernel names: m16, m32, mix.
    pub fn tag(self) -> &'static str {
        match self {
            Math::F16 => "m16",
            Math::F32 => "m32",
            Math::Mixed => "mix",
        }
    }
    /// The kernels' define for this mode.
    pub fn define(self) -> &'static str {
        match self {
            Math::F16 => "MATH_F16",
            Math::F32 => "MATH_F32",
            Math::Mixed => "MATH_MIXED",
        }
    }
}

impl std::str::FromStr for Math {
    type Err = String;
    fn from_str(s: &str) -> Result<Math, String> {
        match s {
            "f16" | "m16" => Ok(Math::F16),
            "f32" | "m32" => Ok(Math::F32),
            "mixed" | "mix" => Ok(Math::Mixed),
            o => Err(format!("unknown math mode '{o}' (use f16, f32 or mixed)")),
        }
    }
}

#[derive(Debug, Error, PartialEq)]
pub enum EncodeError {
    #[error("unknown layout '{0}' (use {1})")]
    UnknownLayout(String, String),
    #[error("{layout}: node {node} child {child}: coordinate {value:e} lies outside [-16384, 16384] in its frame (frame scales stop at 2^-60, so boxes wider than about 1.9e22 do not fit this layout)")]
    OutOfRange { layout: &'static str, node: usize, child: usize, value: f64 },
    #[error("{layout}: node {node} spans {value:e}, more than the {limit:e} its quantization can step over")]
    Extent { layout: &'static str, node: usize, value: f64, limit: f64 },
}

/// Device features a layout's kernels use in one math mode (the shared parts — fp32 leaf tests,
/// fp32 root box — need none of these).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Needs {
    /// 16-bit values in storage buffers (`storageBuffer16BitAccess`).
    pub storage16: bool,
    /// fp16 arithmetic (`shaderFloat16`); with float controls on, also fp16 round-to-nearest-even
    /// and fp16 signed-zero/inf/NaN preservation.
    pub float16: bool,
}

/// Child reference word, shared by all layouts (4 bytes): [`CHILD_EMPTY`] = empty slot;
/// [`LEAF_BIT`] set = leaf with `count − 1` in the [`LEAF_COUNT_BITS`] bits above the
/// [`LEAF_FIRST_BITS`] bits of its first triangle (in leaf order); otherwise the index of an
/// inner node. The kernels get these values from the generated `interface.glsl`.
pub const CHILD_EMPTY: u32 = u32::MAX;
pub const LEAF_BIT: u32 = 1 << 31;
pub const LEAF_FIRST_BITS: u32 = 27;
pub const LEAF_COUNT_BITS: u32 = 4;

pub fn encode_child(c: &ChildRef) -> u32 {
    match *c {
        ChildRef::Inner(i) => {
            assert!(i < LEAF_BIT);
            i
        }
        ChildRef::Leaf { first, count } => {
            assert!((1..=1 << LEAF_COUNT_BITS).contains(&count) && first < (1 << LEAF_FIRST_BITS));
            LEAF_BIT | ((count - 1) << LEAF_FIRST_BITS) | first
        }
    }
}

/// Decodes a non-empty child word.
#[inline]
pub fn decode_child(w: u32) -> ChildRef {
    if w & LEAF_BIT != 0 {
        ChildRef::Leaf {
            first: w & ((1 << LEAF_FIRST_BITS) - 1),
            count: ((w >> LEAF_FIRST_BITS) & ((1 << LEAF_COUNT_BITS) - 1)) + 1,
        }
    } else {
        ChildRef::Inner(w)
    }
}

/// Triangles in leaf order, shared by every layout: 9 floats each (`v0 v1 v2`, xyz), 36 bytes,
/// plus the public `prim` id of each.
#[derive(Clone, Debug)]
pub struct TriBuffer {
    pub verts: Vec<[f32; 9]>,
    pub ids: Vec<u32>,
}

impl TriBuffer {
    pub fn new(scene: &Scene, w: &WideBvh) -> TriBuffer {
        let verts = w
            .prims
            .iter()
            .map(|&p| {
                let t = &scene.tris[p as usize];
                [t[0].x, t[0].y, t[0].z, t[1].x, t[1].y, t[1].z, t[2].x, t[2].y, t[2].z]
            })
            .collect();
        TriBuffer { verts, ids: w.prims.clone() }
    }

    pub fn bytes(&self) -> usize {
        self.verts.len() * 36 + self.ids.len() * 4
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

/// What a precision layout plugs into the shared traversal. The CPU skeleton
/// ([`crate::trace::traverse`]) and the GLSL skeleton (`glsl/trav.comp`, with the layout's
/// `glsl/layout/<name>.glsl`) call the same hooks in the same order:
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
    /// Name in flags, configs, kernel names and reports.
    const NAME: &'static str;
    /// One line for `--help`, `halftrace devices` and the docs.
    const SUMMARY: &'static str;
    /// Arithmetic modes of the box tests; the first is the default.
    const MATHS: &'static [Math];
    /// The GLSL hooks (`glsl/layout/<name>.glsl`); kernels include them as `layout.glsl`.
    const GLSL: &'static str;
    /// Whether the hooks have a build without float controls (`FC_OFF`) whose hits stay
    /// exact under any faithful rounding and without inf/NaN preservation.
    const FLOAT_CONTROLS_OFF: bool = false;
    /// Whether the hooks are conservative, so the traversal returns exactly the f32 closest
    /// hit (every layout but the seed's literal algorithm, `f16h-seed`, which is validated
    /// against its own CPU reference and whose disagreements with f32 are reported).
    const CONSERVATIVE: bool = true;

    /// What the kernels need from the device in math mode `math`.
    fn needs(_math: Math) -> Needs {
        Needs::default()
    }

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
    fn encode<const B: usize>(scene: &Scene, w: &WideBvh) -> Result<(Vec<Self::Node<B>>, Self::Root), EncodeError>;
    /// The `root` vec4 of the push constants (what the kernels need from the host).
    fn push_root(root: &Self::Root) -> [f32; 4];
    /// The stack entry's fields besides the node index, as (name, GLSL type): generated into
    /// the kernels' `struct Entry` and counted in the report's stack bytes.
    fn stack_entry(math: Math) -> &'static [(&'static str, &'static str)];
    /// Constants the hooks share with the GLSL side, generated into `interface.glsl` (see
    /// [`crate::interface::glsl_float`]); none by default.
    fn glsl_constants() -> String {
        String::new()
    }

    fn ray(r: &RayPre, math: Math, fc: crate::variant::FloatControls) -> Self::Ray;
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
    #[allow(clippy::too_many_arguments)]
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

/// A node array of any layout and B, as the type-erased [`Encoded`] holds it.
pub trait NodeArray: Send + Sync {
    fn len(&self) -> usize;
    fn is_empty(&self) -> bool {
        self.len() == 0
    }
    /// Bytes of one node.
    fn node_size(&self) -> usize;
    /// Every node's bytes, exactly as uploaded.
    fn to_bytes(&self) -> Vec<u8> {
        self.bytes_of(0..self.len())
    }
    /// The bytes of nodes `range`, exactly as uploaded.
    fn bytes_of(&self, range: std::ops::Range<usize>) -> Vec<u8>;
    fn child(&self, node: usize, s: usize) -> u32;
    fn child_box(&self, node: usize, s: usize) -> ([f32; 3], [f32; 3]);
    fn as_any(&self) -> &dyn Any;
}

impl<N: Node> NodeArray for Vec<N> {
    fn len(&self) -> usize {
        Vec::len(self)
    }
    fn node_size(&self) -> usize {
        std::mem::size_of::<N>()
    }
    fn bytes_of(&self, range: std::ops::Range<usize>) -> Vec<u8> {
        let mut out = Vec::with_capacity(range.len() * self.node_size());
        for n in &self[range.clone()] {
            n.write_bytes(&mut out);
        }
        assert_eq!(
            out.len(),
            range.len() * self.node_size(),
            "a node wrote other than size_of bytes: its struct has padding"
        );
        out
    }
    fn child(&self, node: usize, s: usize) -> u32 {
        self[node].child(s)
    }
    fn child_box(&self, node: usize, s: usize) -> ([f32; 3], [f32; 3]) {
        self[node].child_box(s)
    }
    fn as_any(&self) -> &dyn Any {
        self
    }
}

/// An encoded BVH of any layout and branching factor.
pub struct Encoded {
    pub layout: LayoutId,
    pub branching: usize,
    pub nodes: Box<dyn NodeArray>,
    /// The layout's `Root`.
    pub(crate) root: Box<dyn Any + Send + Sync>,
    /// The push constants' `root` vec4.
    pub push_root: [f32; 4],
    /// The root's world box, which every traversal tests first.
    pub root_box: Aabb,
    pub tris: TriBuffer,
    /// Largest traversal stack: (B−1)·depth + 1.
    pub max_stack: usize,
}

impl Encoded {
    /// Collapses `bin` to `b` and encodes it in `layout`.
    pub fn new(scene: &Scene, bin: &BinaryBvh, layout: LayoutId, b: usize) -> anyhow::Result<Encoded> {
        crate::bvh::check_branching(b)?;
        let l = layout.bvh().ok_or_else(|| anyhow::anyhow!("{layout} is a baseline, not a BVH layout"))?;
        let what = format!("encoding {} as {layout}, B={b}", scene.name);
        crate::progress::step(&what, || {
            let w = crate::bvh::collapse(bin, b);
            l.encode(scene, &w).map_err(|e| anyhow::anyhow!("{what}: {e}"))
        })
    }

    /// The typed nodes and root of layout `L` at `B` (`None` for another layout or B).
    pub fn typed<L: Layout, const B: usize>(&self) -> Option<(&[L::Node<B>], &L::Root)> {
        let n = self.nodes.as_any().downcast_ref::<Vec<L::Node<B>>>()?;
        Some((n, self.root.downcast_ref::<L::Root>()?))
    }

    pub fn node_count(&self) -> usize {
        self.nodes.len()
    }

    /// Bytes of one node.
    pub fn node_size(&self) -> usize {
        self.nodes.node_size()
    }

    /// Bytes of the node array.
    pub fn node_bytes(&self) -> usize {
        self.nodes.len() * self.nodes.node_size()
    }

    /// Traces rays in packets of `p` (1: single rays) on the CPU reference of this layout.
    pub fn trace(&self, rays: &[Ray], p: usize, math: Math) -> (Vec<Hit>, Vec<Counters>) {
        self.trace_fc(rays, p, math, crate::variant::FloatControls::On)
    }

    /// The CPU reference of the kernel built with float controls `fc` (their bounds differ).
    pub fn trace_fc(
        &self,
        rays: &[Ray],
        p: usize,
        math: Math,
        fc: crate::variant::FloatControls,
    ) -> (Vec<Hit>, Vec<Counters>) {
        let (hits, counters) = self.layout.bvh().expect("Encoded holds a BVH layout").trace(self, rays, p, math, fc);
        crate::digest::record(
            "cpu",
            &format!("{} B{} P{p} {} fc-{}", self.layout, self.branching, math.name(), fc.name()),
            rays,
            &hits,
            Some(&counters),
        );
        (hits, counters)
    }

    /// Single rays in the layout's default math.
    pub fn trace_default(&self, rays: &[Ray]) -> (Vec<Hit>, Vec<Counters>) {
        self.trace(rays, 1, self.layout.caps().maths[0])
    }
}
