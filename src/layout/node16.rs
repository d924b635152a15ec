//! The fp16 node: every child box as fp16 in one frame, structure of arrays, then the child
//! words — the node of `f16h` and `f16h-poster` (chained frames) and, wrapped, of `f16w`.
//! `glsl/node16.glsl` declares the same struct; `f16a`'s GLSL node is it with the frame in
//! front (`NODE16_HEAD`), its Rust node (`F16aNode`) spells the same fields out.
//!
//! Byte layout for branching B (16·B bytes): `lo` f16[3][B] at 0, `hi` f16[3][B] at 6·B,
//! `child` u32[B] at 12·B. B=2: 32 bytes, B=4: 64, B=8: 128, B=16: 256.

use super::Node;
use half::f16;

/// An fp16 node (see the module docs for the byte layout).
#[repr(C)]
#[derive(Clone, Copy, Debug)]
pub struct Node16<const B: usize> {
    /// Child box minima in the node's frame, rounded down: `lo[axis][slot]`.
    pub lo: [[f16; B]; 3],
    /// Child box maxima, rounded up.
    pub hi: [[f16; B]; 3],
    /// Child reference words.
    pub child: [u32; B],
}
const _: () = {
    assert!(std::mem::size_of::<Node16<2>>() == 32);
    assert!(std::mem::size_of::<Node16<4>>() == 64);
    assert!(std::mem::size_of::<Node16<8>>() == 128);
    assert!(std::mem::size_of::<Node16<16>>() == 256);
};

impl<const B: usize> Node16<B> {
    /// The stored fp16 box of slot `s`.
    #[inline(always)]
    pub fn slot_box(&self, s: usize) -> ([f16; 3], [f16; 3]) {
        ([self.lo[0][s], self.lo[1][s], self.lo[2][s]], [self.hi[0][s], self.hi[1][s], self.hi[2][s]])
    }
}

impl<const B: usize> Node for Node16<B> {
    #[inline(always)]
    fn child(&self, s: usize) -> u32 {
        self.child[s]
    }
    fn child_box(&self, s: usize) -> ([f32; 3], [f32; 3]) {
        let (lo, hi) = self.slot_box(s);
        (lo.map(f16::to_f32), hi.map(f16::to_f32))
    }
    fn write_bytes(&self, out: &mut Vec<u8>) {
        out.extend_from_slice(bytemuck::cast_slice(&self.lo[..]));
        out.extend_from_slice(bytemuck::cast_slice(&self.hi[..]));
        out.extend_from_slice(bytemuck::cast_slice(&self.child[..]));
    }
}
