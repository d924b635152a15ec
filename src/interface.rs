//! The kernel interface: every constant and struct that Rust and the GLSL kernels must agree
//! on, written once here (or, for the hit and counter records, beside their Rust types with
//! [`glsl_struct!`]) and generated into the `interface.glsl` header that every traversal
//! kernel includes ([`glsl_header`]). Nothing in `glsl/` restates these values by hand.
//!
//! Per variant the header also carries the layout's stack entry, declared in Rust by the
//! layout (`Layout::stack_entry`), so the report's stack bytes and the part of the kernel's
//! stack it uses are the same figure (a device's build may allocate more: `STACK_ALLOC`,
//! `GROUPS_ALLOC`).

use crate::base::glsl::GlslStruct;
use crate::base::tri::Branch;
use crate::base::{Counters, Hit};
use crate::glsl_struct;

/// Child reference word, shared by all layouts (4 bytes): [`CHILD_EMPTY`] = empty slot;
/// [`LEAF_BIT`] set = leaf with `count − 1` in the [`LEAF_COUNT_BITS`] bits above the
/// [`LEAF_FIRST_BITS`] bits of its first triangle (in leaf order); otherwise the index of an
/// inner node. The kernels get these values from the generated header.
pub const CHILD_EMPTY: u32 = u32::MAX;
pub const LEAF_BIT: u32 = 1 << 31;
pub const LEAF_FIRST_BITS: u32 = 27;
pub const LEAF_COUNT_BITS: u32 = 4;
/// Most triangles one leaf may hold.
pub const LEAF_MAX: u32 = 1 << LEAF_COUNT_BITS;

/// The child word of inner node `i`.
pub fn inner_word(i: u32) -> u32 {
    assert!(i < LEAF_BIT, "inner node index {i} does not fit a child word");
    i
}

/// The child word of a leaf of `count` triangles from `first` (in leaf order).
pub fn leaf_word(first: u32, count: u32) -> u32 {
    assert!(
        (1..=LEAF_MAX).contains(&count) && first < (1 << LEAF_FIRST_BITS),
        "leaf {first}+{count} does not fit a child word"
    );
    LEAF_BIT | ((count - 1) << LEAF_FIRST_BITS) | first
}

/// Whether a non-empty child word is a leaf.
#[inline]
pub fn is_leaf(w: u32) -> bool {
    w & LEAF_BIT != 0
}

/// A leaf word's first triangle and count.
#[inline]
pub fn leaf_parts(w: u32) -> (u32, u32) {
    (w & ((1 << LEAF_FIRST_BITS) - 1), ((w >> LEAF_FIRST_BITS) & (LEAF_MAX - 1)) + 1)
}

glsl_struct! {
    /// Push constants of every traversal kernel (64 bytes): the ray count, the node count,
    /// the scene's triangle-box padding of the closest-hit rule (`base::hit_pad`), the
    /// layout's root data (`Layout::push_root`: the f16h root frame w.xyz, k; unused by f32)
    /// and the root's world box, which every kernel tests first.
    #[derive(Clone, Copy, Debug, Default, PartialEq)]
    pub struct PushConstants {
        pub ray_count: u32,
        pub node_count: u32,
        pub hit_pad: f32,
        pub pad1: u32,
        pub root: [f32; 4],
        pub box_lo: [f32; 4],
        pub box_hi: [f32; 4],
    }
}
const _: () = assert!(std::mem::size_of::<PushConstants>() == 64);

/// Descriptor bindings of a traversal kernel (set 0), all storage buffers.
pub mod binding {
    /// The layout's node array (declared by its hooks file).
    pub const NODES: u32 = 0;
    /// Triangle vertices in leaf order, 9 floats each.
    pub const TRI_VERTS: u32 = 1;
    /// Public `prim` id of each triangle in leaf order.
    pub const TRI_IDS: u32 = 2;
    /// Rays, [`RAY_FLOATS`](super::RAY_FLOATS) floats each.
    pub const RAYS: u32 = 3;
    /// One `Hit` per ray.
    pub const HITS: u32 = 4;
    /// One `Counters` record per ray (counting kernels only).
    pub const COUNTERS: u32 = 5;
    /// Number of bindings.
    pub const COUNT: u32 = 6;
}

/// Floats per ray in the rays buffer: `ox oy oz tmin dx dy dz tmax` (`base::Ray`).
pub const RAY_FLOATS: u32 = 8;
/// The `prim` a kernel writes for a ray whose traversal stack overflowed.
pub const PRIM_OVERFLOW: i32 = -2;

/// A GLSL `const float` declaration of `x`, exactly (the f32 value's shortest f64 spelling).
pub fn glsl_float(name: &str, x: f32) -> String {
    format!("const float {name} = {:?};\n", x as f64)
}

/// A GLSL `const uint` declaration.
pub fn glsl_uint(name: &str, x: u32) -> String {
    format!("const uint {name} = {x:#x}u;\n")
}

/// A GLSL `const int` declaration.
pub fn glsl_int(name: &str, x: i32) -> String {
    format!("const int {name} = {x};\n")
}

/// Bytes of one value of a GLSL type used in stack entries.
pub fn glsl_size(ty: &str) -> usize {
    match ty {
        "float" | "uint" | "int" | "f16vec2" => 4,
        "float16_t" => 2,
        "f16vec3" => 6,
        "f16vec4" | "vec2" | "uvec2" => 8,
        "vec3" | "uvec3" => 12,
        "vec4" | "uvec4" => 16,
        other => panic!("glsl_size: no size for GLSL type {other}"),
    }
}

/// Bytes of a stack entry: the node index (4) plus the layout's per-ray fields.
pub fn stack_entry_bytes(fields: &[(&str, &str)]) -> usize {
    4 + fields.iter().map(|(_, t)| glsl_size(t)).sum::<usize>()
}

fn glsl_fields(fields: &[(&str, &str)]) -> String {
    fields.iter().map(|(n, t)| format!(" {t} {n};")).collect()
}

/// `MARK_<NAME>()` for each named side of the triangle test ([`Branch`]): in `estimate`'s
/// marked build (`BRANCH_MARKS`; glsl/ray.glsl then declares the hits buffer read-write) an
/// atomic operation on the ray's hit, a different one per side, so that a compiler's listing
/// shows which blocks run it; in the branch-counting build (`BRANCH_COUNTS`, with `STATS`) an
/// increment of the ray's count of that side, which `branch_pair` packs into its counters
/// ([`Branch::counted`]); in every other build nothing.
fn branch_markers() -> String {
    let (mut on, mut count, mut off) = (String::new(), String::new(), String::new());
    for (k, b) in Branch::ALL.into_iter().enumerate() {
        let name = b.name().to_uppercase();
        if let Some((f, args, _)) = b.marker_op() {
            on += &format!("#define MARK_{name}() {f}(hits[gl_GlobalInvocationID.x].prim, {args})\n");
            count += &format!("#define MARK_{name}() branch_taken[{k}]++\n");
            off += &format!("#define MARK_{name}()\n");
        }
    }
    let n = Branch::ALL.len();
    let zeros = vec!["0u"; n].join(", ");
    count += &format!(
        "uint branch_taken[{n}] = uint[{n}]({zeros});\n\
         // Sides a and b of the ray's counts in one word, 16 bits each (saturating).\n\
         uint branch_pair(uint a, uint b) {{ return min(branch_taken[a], 0xffffu) | (min(branch_taken[b], 0xffffu) << 16u); }}\n"
    );
    format!("#ifdef BRANCH_MARKS\n{on}#elif defined(BRANCH_COUNTS)\n{count}#else\n{off}#endif\n")
}

/// The `interface.glsl` header of a kernel. `layout`: the layout's stack entry fields and its
/// constants (`None` for kernels without a layout, such as the ray-query baseline).
pub fn glsl_header(layout: Option<(&[(&str, &str)], &str)>) -> String {
    let mut s = String::from("// interface.glsl: generated by halftrace from src/interface.rs and the layout's\n// Rust definitions for this variant. Do not edit; do not copy these values by hand.\n");
    // Stack entries may hold fp16 values; every kernel stores fp16 in buffers.
    s += "#extension GL_EXT_shader_explicit_arithmetic_types_float16 : require\n#extension GL_EXT_shader_16bit_storage : require\n";
    // The shared includes hint loops ([[unroll]], [[dont_unroll]]: tri.glsl), user kernels too.
    s += "#extension GL_EXT_control_flow_attributes : require\n";
    s += &format!("const uint CHILD_EMPTY = {CHILD_EMPTY:#010x}u;\nconst uint LEAF_BIT = {LEAF_BIT:#010x}u;\n");
    s += &format!("const uint LEAF_FIRST_MASK = {:#010x}u;\nconst uint LEAF_COUNT_SHIFT = {LEAF_FIRST_BITS}u;\nconst uint LEAF_COUNT_MASK = {:#x}u;\n", (1u32 << LEAF_FIRST_BITS) - 1, (1u32 << LEAF_COUNT_BITS) - 1);
    s += &format!(
        "const uint RAY_FLOATS = {RAY_FLOATS}u;\nconst int PRIM_OVERFLOW = {PRIM_OVERFLOW};\nconst int PRIM_FLAGGED = {};\n",
        crate::base::PRIM_FLAGGED
    );
    s += &glsl_float("MARGIN32", crate::base::slab::MARGIN32);
    s += &glsl_float("HIT_CAP", crate::base::HIT_CAP);
    for (name, value) in [
        ("NODES", binding::NODES),
        ("TRI_VERTS", binding::TRI_VERTS),
        ("TRI_IDS", binding::TRI_IDS),
        ("RAYS", binding::RAYS),
        ("HITS", binding::HITS),
        ("COUNTERS", binding::COUNTERS),
    ] {
        s += &format!("#define BINDING_{name} {value}\n");
    }
    s += &format!("layout(push_constant) uniform Push {{{} }} pc;\n", glsl_fields(PushConstants::FIELDS));
    s += &format!("struct Hit {{{} }};\n", glsl_fields(Hit::FIELDS));
    s += &format!("struct Counters {{{} }};\n", glsl_fields(Counters::FIELDS));
    s += &branch_markers();
    if let Some((entry, constants)) = layout {
        s += &format!(
            "// The layout's stack entry besides the node index ({} bytes with it) and its constants.\n",
            stack_entry_bytes(entry)
        );
        s += &format!(
            "struct Entry {{{} }};\n#define STACK_ENTRY_BYTES {}\n",
            glsl_fields(entry),
            stack_entry_bytes(entry)
        );
        s += constants;
    }
    s
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn header_spells_the_rust_values() {
        let h = glsl_header(Some((&[("t", "float")], &glsl_float("D", 1.0 / 32768.0))));
        assert!(h.contains("const float D = 3.0517578125e-5;"), "{h}");
        assert!(h.contains("const uint LEAF_BIT = 0x80000000u;"), "{h}");
        assert!(h.contains("const uint LEAF_FIRST_MASK = 0x07ffffffu;"), "{h}");
        assert!(h.contains("const uint LEAF_COUNT_SHIFT = 27u;"), "{h}");
        assert!(h.contains("layout(push_constant) uniform Push { uint ray_count; uint node_count; float hit_pad; uint pad1; vec4 root; vec4 box_lo; vec4 box_hi; } pc;"), "{h}");
        assert!(h.contains("struct Hit { float t; int prim; float u; float v; };"), "{h}");
        assert!(h.contains("struct Entry { float t; };") && h.contains("#define STACK_ENTRY_BYTES 8"), "{h}");
        // The branch markers: an atomic in the marked build, nothing in any other.
        assert!(
            h.contains("#ifdef BRANCH_MARKS\n#define MARK_HUGE() atomicMin(hits[gl_GlobalInvocationID.x].prim, 1)\n"),
            "{h}"
        );
        assert!(
            h.contains("#define MARK_BEST() atomicCompSwap(hits[gl_GlobalInvocationID.x].prim, 0, 1)\n#elif defined(BRANCH_COUNTS)\n#define MARK_HUGE() branch_taken[0]++\n"),
            "{h}"
        );
        // The counting build: Branch::ALL's order, two sides a word.
        assert!(h.contains("#define MARK_BEST() branch_taken[6]++\nuint branch_taken[8] = uint[8](0u, 0u, 0u, 0u, 0u, 0u, 0u, 0u);\n"), "{h}");
        assert!(h.contains("uint branch_pair(uint a, uint b)") && h.contains("#endif\n"), "{h}");
        assert!(h.contains("#define MARK_EDGES()\n") && !h.contains("MARK_NOTE"), "{h}");
    }

    #[test]
    fn generated_struct_sizes_match_rust() {
        let size = |f: &[(&str, &str)]| f.iter().map(|(_, t)| if *t == "vec4" { 16 } else { 4 }).sum::<usize>();
        assert_eq!(size(PushConstants::FIELDS), std::mem::size_of::<PushConstants>());
        assert_eq!(size(Hit::FIELDS), std::mem::size_of::<Hit>());
        assert_eq!(size(Counters::FIELDS), std::mem::size_of::<Counters>());
    }
}
