//! GPU node layouts, one module per layout, all converted from the same [`WideBvh`]
//! ("build once, convert many"). Every node struct is `#[repr(C)]` + `bytemuck::Pod` with a
//! compile-time size assert; the byte layout is documented on the struct.

pub mod f16h;
pub mod f32;

use crate::bvh::{ChildRef, WideBvh};
use thiserror::Error;

/// A precision layout.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum Layout {
    /// World-space fp32 child boxes (the baseline).
    F32,
    /// Hierarchical half precision (Koskela et al.): fp16 child boxes in the parent's frame.
    F16h,
}

impl Layout {
    pub const ALL: [Layout; 2] = [Layout::F32, Layout::F16h];
    pub fn name(self) -> &'static str {
        match self {
            Layout::F32 => "f32",
            Layout::F16h => "f16h",
        }
    }
}

impl std::fmt::Display for Layout {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

impl std::str::FromStr for Layout {
    type Err = EncodeError;
    fn from_str(s: &str) -> Result<Layout, EncodeError> {
        match s {
            "f32" => Ok(Layout::F32),
            "f16h" => Ok(Layout::F16h),
            _ => Err(EncodeError::UnknownLayout(s.to_string())),
        }
    }
}

#[derive(Debug, Error, PartialEq)]
pub enum EncodeError {
    #[error("unknown layout '{0}' (use f32 or f16h)")]
    UnknownLayout(String),
    #[error("f16h: node {node} child {child}: coordinate {value} lies outside [-16384, 16384] in the parent frame")]
    OutOfRange { node: usize, child: usize, value: f64 },
}

/// Child reference word, shared by all layouts (4 bytes):
/// `0xFFFF_FFFF` = empty slot; bit 31 set = leaf with `count - 1` in bits 27..=30 and the
/// first triangle (in leaf order) in bits 0..=26; otherwise the index of an inner node.
pub const CHILD_EMPTY: u32 = u32::MAX;
pub const LEAF_BIT: u32 = 1 << 31;

pub fn encode_child(c: &ChildRef) -> u32 {
    match *c {
        ChildRef::Inner(i) => {
            assert!(i < LEAF_BIT);
            i
        }
        ChildRef::Leaf { first, count } => {
            assert!((1..=16).contains(&count) && first < (1 << 27));
            LEAF_BIT | ((count - 1) << 27) | first
        }
    }
}

/// Decodes a non-empty child word.
#[inline]
pub fn decode_child(w: u32) -> ChildRef {
    if w & LEAF_BIT != 0 {
        ChildRef::Leaf { first: w & ((1 << 27) - 1), count: ((w >> 27) & 15) + 1 }
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
    pub fn new(scene: &crate::scene::Scene, w: &WideBvh) -> TriBuffer {
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

/// Generates a node struct per branching factor and the enum holding a node vector of any B.
macro_rules! node_types {
    ($enum:ident, $trait:ident, $coord:ty, [$(($name:ident, $b:literal, $variant:ident)),*]) => {
        $(
            #[repr(C)]
            #[derive(Clone, Copy, Debug, bytemuck::Pod, bytemuck::Zeroable)]
            pub struct $name {
                /// Child box minima, structure of arrays: `lo[axis][slot]`.
                pub lo: [[$coord; $b]; 3],
                /// Child box maxima, `hi[axis][slot]`.
                pub hi: [[$coord; $b]; 3],
                /// Child reference words (see `encode::CHILD_EMPTY`, `encode::LEAF_BIT`).
                pub child: [u32; $b],
            }
            const _: () = assert!(std::mem::size_of::<$name>() == (6 * std::mem::size_of::<$coord>() + 4) * $b);
            impl $trait for $name {
                const B: usize = $b;
                #[inline(always)]
                fn lo(&self, axis: usize, slot: usize) -> $coord { self.lo[axis][slot] }
                #[inline(always)]
                fn hi(&self, axis: usize, slot: usize) -> $coord { self.hi[axis][slot] }
                #[inline(always)]
                fn child(&self, slot: usize) -> u32 { self.child[slot] }
                fn empty() -> Self {
                    let mut n: Self = bytemuck::Zeroable::zeroed();
                    n.child = [crate::encode::CHILD_EMPTY; $b];
                    n
                }
                fn set(&mut self, slot: usize, lo: [$coord; 3], hi: [$coord; 3], child: u32) {
                    for a in 0..3 { self.lo[a][slot] = lo[a]; self.hi[a][slot] = hi[a]; }
                    self.child[slot] = child;
                }
            }
        )*
        /// Nodes of one branching factor.
        #[derive(Clone, Debug)]
        pub enum $enum { $($variant(Vec<$name>)),* }
        impl $enum {
            pub fn len(&self) -> usize { match self { $(Self::$variant(v) => v.len()),* } }
            pub fn is_empty(&self) -> bool { self.len() == 0 }
            /// The node array as bytes, exactly as uploaded to the GPU.
            pub fn bytes(&self) -> &[u8] { match self { $(Self::$variant(v) => bytemuck::cast_slice(v)),* } }
            pub fn node_size(&self) -> usize { match self { $(Self::$variant(_) => std::mem::size_of::<$name>()),* } }
        }
    };
}
pub(crate) use node_types;
