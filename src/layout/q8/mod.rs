//! Layout `q8`: compressed wide nodes after Ylitie, Karras and Laine (HPG 2017, *Efficient
//! Incoherent Ray Traversal on GPUs Through Compressed Wide BVHs*), for every B. Each node
//! stores an fp32 origin p (the minimum corner of its box) and per axis a power-of-two step
//! 2^e, the smallest with 255·2^e ≥ the box's extent; each child's planes are 8-bit grid
//! values, the lower rounded down (floor((lo − p)/2^e)) and the upper up (ceil), computed
//! exactly, so the stored box contains the true one — the paper's conservative quantization.
//! As in the paper, a node's inner children are stored consecutively (one base index) and so
//! are its leaves' triangles (one base index): [`Layout::reorder`] lays the tree out breadth
//! first and the triangles leaf by leaf; a 16-bit word per child says empty, inner (its rank
//! among the inner children) or leaf (triangle count − 1 and offset from the base).
//!
//! Box tests in fp32 (`--math f32`, the paper's: planes decoded to world fp32, p + q·2^e with
//! one rounding) or fp16 (`--math f16`: the node frame w = p, k = 2^(6 − max e), in which
//! every grid value is q·2^(e_axis + 6 − max e) ≤ 16320, exact in fp16 because the encoder keeps
//! e_axis ≥ max e − 30; then the anchored origin and f16h's widened fp16 test); both argued in
//! [`super::anchored`]. Steps are kept in 2^[−54, 66] so that every scale and product stays a
//! normal fp32 number (coarser steps for tinier nodes; larger extents are an encoding error).
//!
//! Node byte layout for branching B (24 + 8·B bytes): `p` f32[3] at 0, `exps` u32 at 12 (e + 128
//! per axis in bytes 0–2), `child_base` u32 at 16, `tri_base` u32 at 20, `q` u8[2][3][B] at 24
//! (lo then hi, axis-major), `meta` u16[B] at 24 + 6·B: 8 bytes per child plus 24 per node.
//! B=2: 40 bytes, B=4: 56, B=8: 88 (CWBVH: 80), B=16: 152. The kernels read it as 32-bit words,
//! so it needs no 8- or 16-bit storage. GLSL hooks: `glsl/layout/q8.glsl`.

use super::anchored::{self, decode_plane, AnchoredNode};
use super::frames::Frame;
use super::half::Ray16;
use super::{EncodeError, Layout, LayoutInfo, Needs, Node};
use crate::base::Aabb;
use crate::base::{Counters, RayPre};
use crate::bvh::{ChildRef, WideBvh, WideNode};
use crate::interface::{glsl_int, glsl_uint, CHILD_EMPTY, LEAF_BIT, LEAF_FIRST_BITS};
use crate::precision::Math;
use half::f16;

/// The `q8` layout.
pub struct Q8;

/// Range of the per-axis step exponents.
pub const E_MIN: i32 = -54;
pub const E_MAX: i32 = 66;
/// The fp16 frame's scale is 2^(E_SHIFT − max e): the largest grid value 255 maps to 16320.
pub const E_SHIFT: i32 = 6;
/// Step exponents are stored as e + E_BIAS, one byte per axis.
pub const E_BIAS: i32 = 128;

/// A child's 16-bit meta word: `META_EMPTY`, `META_INNER | rank` (among the node's inner
/// children), or `(count − 1) << META_COUNT_SHIFT | offset` for a leaf (triangles from
/// `tri_base + offset`).
pub const META_EMPTY: u16 = 0xffff;
pub const META_INNER: u16 = 0x8000;
pub const META_COUNT_SHIFT: u32 = 8;
pub const META_OFFSET_MASK: u16 = 0xff;

/// The constants `glsl/layout/q8.glsl` shares with this module, besides `half`'s.
fn glsl_constants() -> String {
    super::half::glsl_constants()
        + &glsl_uint("META_EMPTY", META_EMPTY as u32)
        + &glsl_uint("META_INNER", META_INNER as u32)
        + &glsl_uint("META_COUNT_SHIFT", META_COUNT_SHIFT)
        + &glsl_uint("META_OFFSET_MASK", META_OFFSET_MASK as u32)
        + &glsl_int("E_SHIFT", E_SHIFT)
        + &glsl_int("E_BIAS", E_BIAS)
}

/// A `q8` node (see the module docs for the byte layout).
#[repr(C)]
#[derive(Clone, Copy, Debug)]
pub struct Q8Node<const B: usize> {
    pub p: [f32; 3],
    /// e + 128 per axis, bytes 0, 1, 2.
    pub exps: u32,
    pub child_base: u32,
    pub tri_base: u32,
    /// Grid values: `q[0][axis][slot]` lower planes, `q[1][axis][slot]` upper planes.
    pub q: [[[u8; B]; 3]; 2],
    pub meta: [u16; B],
}
const _: () = {
    assert!(std::mem::size_of::<Q8Node<2>>() == 40);
    assert!(std::mem::size_of::<Q8Node<4>>() == 56);
    assert!(std::mem::size_of::<Q8Node<8>>() == 88);
    assert!(std::mem::size_of::<Q8Node<16>>() == 152);
};

#[inline]
fn pow2(e: i32) -> f32 {
    f32::from_bits(((e + 127) as u32) << 23)
}

impl<const B: usize> Q8Node<B> {
    #[inline(always)]
    pub fn exp(&self, a: usize) -> i32 {
        ((self.exps >> (8 * a)) & 0xff) as i32 - E_BIAS
    }

    #[inline(always)]
    fn exp_max(&self) -> i32 {
        self.exp(0).max(self.exp(1)).max(self.exp(2))
    }

    /// The fp16-math frame: w = p, k = 2^(6 − max e).
    pub fn frame(&self) -> Frame {
        Frame { w: self.p, k: pow2(E_SHIFT - self.exp_max()) }
    }

    /// Grid values of slot `s` as f32.
    #[inline(always)]
    fn grid(&self, s: usize) -> ([f32; 3], [f32; 3]) {
        ([0, 1, 2].map(|a| self.q[0][a][s] as f32), [0, 1, 2].map(|a| self.q[1][a][s] as f32))
    }

    /// The box of slot `s` in the fp16 frame (exact).
    #[inline]
    pub fn local_box(&self, s: usize) -> ([f16; 3], [f16; 3]) {
        let (l, u) = self.grid(s);
        let em = self.exp_max();
        let f = [0, 1, 2].map(|a| pow2(self.exp(a) + E_SHIFT - em));
        ([0, 1, 2].map(|a| f16::from_f32(l[a] * f[a])), [0, 1, 2].map(|a| f16::from_f32(u[a] * f[a])))
    }

    /// The box of slot `s` decoded to world fp32 (still containing the true box).
    #[inline]
    pub fn world_box(&self, s: usize) -> ([f32; 3], [f32; 3]) {
        let (l, u) = self.grid(s);
        let mut lo = [0f32; 3];
        let mut hi = [0f32; 3];
        for a in 0..3 {
            let f = pow2(self.exp(a));
            lo[a] = decode_plane(self.p[a], l[a] * f);
            hi[a] = decode_plane(self.p[a], u[a] * f);
        }
        (lo, hi)
    }
}

impl<const B: usize> AnchoredNode<()> for Q8Node<B> {
    fn frame(&self, _: &()) -> Frame {
        Q8Node::frame(self)
    }
    fn local_box(&self, s: usize) -> ([f16; 3], [f16; 3]) {
        Q8Node::local_box(self, s)
    }
    fn world_box(&self, s: usize, _: &Frame) -> ([f32; 3], [f32; 3]) {
        Q8Node::world_box(self, s)
    }
}

impl<const B: usize> Node for Q8Node<B> {
    #[inline(always)]
    fn child(&self, s: usize) -> u32 {
        let m = self.meta[s];
        if m == META_EMPTY {
            CHILD_EMPTY
        } else if m & META_INNER != 0 {
            self.child_base + (m & !META_INNER) as u32
        } else {
            LEAF_BIT
                | (((m >> META_COUNT_SHIFT) as u32) << LEAF_FIRST_BITS)
                | (self.tri_base + (m & META_OFFSET_MASK) as u32)
        }
    }
    /// The grid values (the kernels' `child_box` returns the same).
    fn child_box(&self, s: usize) -> ([f32; 3], [f32; 3]) {
        self.grid(s)
    }
    fn write_bytes(&self, out: &mut Vec<u8>) {
        out.extend_from_slice(bytemuck::cast_slice(&self.p[..]));
        for w in [self.exps, self.child_base, self.tri_base] {
            out.extend_from_slice(&w.to_le_bytes());
        }
        for h in &self.q {
            for a in h {
                out.extend_from_slice(a);
            }
        }
        out.extend_from_slice(bytemuck::cast_slice(&self.meta[..]));
    }
}

/// The smallest step exponent e in [E_MIN, E_MAX] with 255·2^e ≥ `ext`, if any.
fn step_exp(ext: f64) -> Option<i32> {
    (E_MIN..=E_MAX).find(|&e| 255.0 * 2f64.powi(e) >= ext)
}

/// Quantizes one node; `bfs` indices of its inner children must be consecutive.
fn encode_node<const B: usize>(i: usize, n: &WideNode) -> Result<Q8Node<B>, EncodeError> {
    let mut bounds = Aabb::EMPTY;
    for (b, _) in &n.children {
        bounds.grow(b.min);
        bounds.grow(b.max);
    }
    let p: [f32; 3] = bounds.min.into();
    let mut e = [0i32; 3];
    for a in 0..3 {
        let ext = bounds.max[a] as f64 - bounds.min[a] as f64;
        let limit = 255.0 * 2f64.powi(E_MAX);
        let msg = || format!("spans {ext:e}, more than the {limit:e} its quantization can step over");
        e[a] = step_exp(ext).ok_or_else(|| EncodeError { layout: "q8", node: i, msg: msg() })?;
    }
    let em = e[0].max(e[1]).max(e[2]);
    for x in &mut e {
        // Keeps q·2^(e + 6 − max e) exact in fp16 (a coarser grid on flat axes).
        *x = (*x).max(em - 30);
    }
    let mut node = Q8Node { p, exps: 0, child_base: 0, tri_base: 0, q: [[[0u8; B]; 3]; 2], meta: [META_EMPTY; B] };
    for a in 0..3 {
        node.exps |= ((e[a] + E_BIAS) as u32) << (8 * a);
    }
    let first_inner = n.children.iter().find_map(|(_, c)| if let ChildRef::Inner(j) = c { Some(*j) } else { None });
    let first_leaf =
        n.children.iter().find_map(|(_, c)| if let ChildRef::Leaf { first, .. } = c { Some(*first) } else { None });
    node.child_base = first_inner.unwrap_or(0);
    node.tri_base = first_leaf.unwrap_or(0);
    let mut rank = 0u16;
    for (slot, (b, c)) in n.children.iter().enumerate() {
        for a in 0..3 {
            let step = 2f64.powi(e[a]);
            let lo = ((b.min[a] as f64 - p[a] as f64) / step).floor();
            let hi = ((b.max[a] as f64 - p[a] as f64) / step).ceil();
            assert!(
                (0.0..=255.0).contains(&lo) && (0.0..=255.0).contains(&hi),
                "q8: node {i} slot {slot} axis {a}: grid {lo}..{hi}"
            );
            node.q[0][a][slot] = lo as u8;
            node.q[1][a][slot] = hi as u8;
        }
        node.meta[slot] = match *c {
            ChildRef::Inner(j) => {
                assert_eq!(
                    j,
                    node.child_base + rank as u32,
                    "q8: inner children of node {i} are not consecutive (reorder first)"
                );
                rank += 1;
                META_INNER | (rank - 1)
            }
            ChildRef::Leaf { first, count } => {
                let off = first - node.tri_base;
                assert!(off < 256 && (1..=16).contains(&count), "q8: leaf of node {i} at offset {off} (reorder first)");
                (((count - 1) as u16) << META_COUNT_SHIFT) | off as u16
            }
        };
    }
    Ok(node)
}

impl Layout for Q8 {
    const INFO: LayoutInfo = LayoutInfo {
        name: "q8",
        summary: "8-bit quantized child planes per node, compressed wide nodes (Ylitie et al. 2017)",
        maths: &[Math::F32, Math::F16],
        glsl: include_str!("../../../glsl/layout/q8.glsl"),
        needs: |math| Needs { storage16: false, float16: math == Math::F16 },
        float_controls_off: true,
        stack_entry: |_| anchored::STACK_ENTRY,
        glsl_constants,
        ..LayoutInfo::DEFAULT
    };

    type Node<const B: usize> = Q8Node<B>;
    type Root = ();
    type Ray = Ray16;
    /// The node's entry bound (world parameter).
    type Entry = f32;
    type Visit = anchored::Visit;
    /// (entry parameter, its lower bound).
    type ChildHit = (f32, f32);

    /// Breadth first (`bvh::breadth_first`, as `collapse` lays every tree out), so each node's
    /// inner children are consecutive; triangles leaf by leaf in that node order, so each
    /// node's leaves are consecutive (offsets < 16·16).
    fn reorder(w: &WideBvh) -> Option<WideBvh> {
        let mut nodes = crate::bvh::breadth_first(w.nodes.clone());
        let mut prims = Vec::with_capacity(w.prims.len());
        for n in &mut nodes {
            for (_, c) in &mut n.children {
                if let ChildRef::Leaf { first, count } = *c {
                    let f = prims.len() as u32;
                    prims.extend_from_slice(&w.prims[first as usize..(first + count) as usize]);
                    *c = ChildRef::Leaf { first: f, count };
                }
            }
        }
        Some(WideBvh { branching: w.branching, nodes, prims })
    }

    fn encode<const B: usize>(w: &WideBvh) -> Result<(Vec<Q8Node<B>>, ()), EncodeError> {
        w.nodes.iter().enumerate().map(|(i, n)| encode_node::<B>(i, n)).collect::<Result<Vec<_>, _>>().map(|v| (v, ()))
    }

    fn push_root(_: &()) -> [f32; 4] {
        [0.0; 4]
    }

    anchored::anchored_hooks!(Q8Node, ());
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn step_exponents_cover_the_extent_minimally() {
        for ext in [0.0, 1e-30, 1.0, 255.0, 255.5, 1e6, 3.4e38 * 0.0 + 1e20] {
            let e = step_exp(ext).unwrap();
            assert!(255.0 * 2f64.powi(e) >= ext);
            assert!(e == E_MIN || 255.0 * 2f64.powi(e - 1) < ext, "{ext}: {e}");
        }
        assert!(step_exp(1e30).is_none());
    }
}
