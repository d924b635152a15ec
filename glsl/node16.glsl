// The node of the layouts that store every child box as fp16 in one frame per node or per BVH
// (f16h, f16h-poster, f16w, and f16a after its frame; src/layout/node16.rs, Node16): lo and hi structure of arrays,
// then the child words. Include after half.glsl (HVEC3, LOADH). A layout whose node carries
// more (f16a: its frame) defines NODE16_HEAD as the fields that come first.
struct Node {
#ifdef NODE16_HEAD
    NODE16_HEAD
#endif
    float16_t lo[3 * B];   // lo[axis * B + slot], in the node's frame, rounded down
    float16_t hi[3 * B];
    uint child[B];
};
NODE_BUFFER(Node)

uint child_word(uint ni, uint s) { return nodes[ni].child[s]; }

HVEC3 slot_lo(uint ni, uint s) { return HVEC3(LOADH(nodes[ni].lo[s]), LOADH(nodes[ni].lo[B + s]), LOADH(nodes[ni].lo[2 * B + s])); }
HVEC3 slot_hi(uint ni, uint s) { return HVEC3(LOADH(nodes[ni].hi[s]), LOADH(nodes[ni].hi[B + s]), LOADH(nodes[ni].hi[2 * B + s])); }

void child_box(uint ni, uint s, out vec3 lo, out vec3 hi) {
    lo = vec3(slot_lo(ni, s));
    hi = vec3(slot_hi(ni, s));
}

#ifdef HALF_PAIRS
// Axis a of slots s and s + 1 (s even) as the lanes of one f16vec2: adjacent halves in the
// node, one 32-bit word, no packing.
f16vec2 pair_lo(uint ni, uint s, int a) { return f16vec2(nodes[ni].lo[a * B + s], nodes[ni].lo[a * B + s + 1]); }
f16vec2 pair_hi(uint ni, uint s, int a) { return f16vec2(nodes[ni].hi[a * B + s], nodes[ni].hi[a * B + s + 1]); }
#endif
