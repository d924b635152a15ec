//! Layout `f32`: world-space fp32 child boxes, structure of arrays per node — the baseline
//! every other layout is compared with. Robust fp32 slab tests (Ize 2013), children visited
//! nearest entry first.
//!
//! Node byte layout for branching B (28·B bytes): `lo` f32[3][B] at 0, `hi` f32[3][B] at
//! 12·B, `child` u32[B] at 24·B. Empty slots have zero boxes and `CHILD_EMPTY`.
//! B=2: 56 bytes, B=4: 112, B=8: 224, B=16: 448. GLSL hooks: `glsl/layout/f32.glsl`.

use super::{encode_child, EncodeError, Layout, LayoutInfo, Node};
use crate::base::{slab32, Counters, RayPre};
use crate::bvh::WideBvh;
use crate::interface::CHILD_EMPTY;
use crate::precision::{FloatControls, Math};

/// The `f32` layout.
pub struct F32;

/// An `f32` node (see the module docs for the byte layout).
#[repr(C)]
#[derive(Clone, Copy, Debug)]
pub struct F32Node<const B: usize> {
    /// Child box minima, structure of arrays: `lo[axis][slot]`.
    pub lo: [[f32; B]; 3],
    /// Child box maxima, `hi[axis][slot]`.
    pub hi: [[f32; B]; 3],
    /// Child reference words.
    pub child: [u32; B],
}
const _: () = {
    assert!(std::mem::size_of::<F32Node<2>>() == 56);
    assert!(std::mem::size_of::<F32Node<4>>() == 112);
    assert!(std::mem::size_of::<F32Node<8>>() == 224);
    assert!(std::mem::size_of::<F32Node<16>>() == 448);
};

impl<const B: usize> Node for F32Node<B> {
    #[inline(always)]
    fn child(&self, s: usize) -> u32 {
        self.child[s]
    }
    #[inline(always)]
    fn child_box(&self, s: usize) -> ([f32; 3], [f32; 3]) {
        ([self.lo[0][s], self.lo[1][s], self.lo[2][s]], [self.hi[0][s], self.hi[1][s], self.hi[2][s]])
    }
    fn write_bytes(&self, out: &mut Vec<u8>) {
        out.extend_from_slice(bytemuck::cast_slice(&self.lo[..]));
        out.extend_from_slice(bytemuck::cast_slice(&self.hi[..]));
        out.extend_from_slice(bytemuck::cast_slice(&self.child[..]));
    }
}

impl Layout for F32 {
    const INFO: LayoutInfo = LayoutInfo {
        name: "f32",
        summary: "world-space fp32 child boxes (the baseline)",
        glsl: include_str!("../../../glsl/layout/f32.glsl"),
        // fp32 everywhere; the slab test never forms a NaN and widens by 2^-20, far more than
        // any faithful rounding of its three operations can move a bound (glsl/box.glsl).
        float_controls_off: true,
        stack_entry: |_| &[("t", "float")],
        ..LayoutInfo::DEFAULT
    };

    type Node<const B: usize> = F32Node<B>;
    type Root = ();
    type Ray = ();
    /// The entry distance of the node's box.
    type Entry = f32;
    /// The ray's closest hit when the node is visited (the box tests' upper limit).
    type Visit = f32;
    /// The child's entry distance.
    type ChildHit = f32;

    fn encode<const B: usize>(w: &WideBvh) -> Result<(Vec<F32Node<B>>, ()), EncodeError> {
        let nodes = w
            .nodes
            .iter()
            .map(|n| {
                let mut out = F32Node { lo: [[0.0; B]; 3], hi: [[0.0; B]; 3], child: [CHILD_EMPTY; B] };
                for (slot, (b, c)) in n.children.iter().enumerate() {
                    for a in 0..3 {
                        out.lo[a][slot] = b.min[a];
                        out.hi[a][slot] = b.max[a];
                    }
                    out.child[slot] = encode_child(c);
                }
                out
            })
            .collect();
        Ok((nodes, ()))
    }

    fn push_root(_: &()) -> [f32; 4] {
        [0.0; 4]
    }

    fn ray(_: &RayPre, _: Math, _: FloatControls) {}

    fn root_entry(_: &(), _: &RayPre, _: &(), near: f32) -> f32 {
        near
    }

    fn entry_t(t: &f32) -> f32 {
        *t
    }

    fn visit<const B: usize>(_: &F32Node<B>, _: &(), _: &f32, _: &RayPre, _: &(), best_t: f32) -> f32 {
        best_t
    }

    #[inline(always)]
    fn test_child<const B: usize>(
        n: &F32Node<B>,
        s: usize,
        _: &f32,
        best_t: &f32,
        r: &RayPre,
        _: &(),
    ) -> Option<(f32, f32)> {
        let (lo, hi) = n.child_box(s);
        let (near, far) = slab32(r, lo, hi, r.tmin, *best_t);
        (near <= far).then_some((near, near))
    }

    fn child_entry<const B: usize>(
        _: &F32Node<B>,
        _: usize,
        _: &f32,
        _: &f32,
        near: &f32,
        _: &RayPre,
        _: &(),
        _: &mut Counters,
    ) -> f32 {
        *near
    }
}
