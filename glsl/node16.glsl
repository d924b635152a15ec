// The node of the layouts that store every child box as fp16 in one frame per node or per BVH
// (f16h, f16h-poster, f16w, and f16a after its frame; src/layout/node16.rs, Node16): lo and hi structure of arrays,
// then the child words (HALF_WORDS: in 32-bit words, for devices without 16-bit storage).
// Include after half.glsl (HVEC3, LOADH). A layout whose node carries
// more (f16a: its frame) defines NODE16_HEAD as the fields that come first.
struct Node {
#ifdef NODE16_HEAD
    NODE16_HEAD
#endif
#ifdef HALF_WORDS
    // Without 16-bit storage: fp16 pairs in 32-bit words, the same bytes; half i of lo is the
    // low (i even) or the high half of lo[i / 2]
    uint lo[3 * B / 2];
    uint hi[3 * B / 2];
#else
    float16_t lo[3 * B];   // lo[axis * B + slot], in the node's frame, rounded down
    float16_t hi[3 * B];
#endif
    uint child[B];
};
NODE_BUFFER(Node)

uint child_word(uint ni, uint s) { return nodes[ni].child[s]; }

#ifdef HALF_WORDS
// Half i of a word array, exactly: a bit cast with fp16 arithmetic, a conversion without.
#ifdef MATH_F32
float half_of(uint word, uint i) { return unpackHalf2x16(word >> ((i & 1u) << 4)).x; }
#else
float16_t half_of(uint word, uint i) { return unpackFloat2x16(word >> ((i & 1u) << 4)).x; }
#endif
#define NODE_LO(ni, i) half_of(nodes[ni].lo[(i) >> 1], (i))
#define NODE_HI(ni, i) half_of(nodes[ni].hi[(i) >> 1], (i))
#else
#define NODE_LO(ni, i) LOADH(nodes[ni].lo[i])
#define NODE_HI(ni, i) LOADH(nodes[ni].hi[i])
#endif

HVEC3 slot_lo(uint ni, uint s) { return HVEC3(NODE_LO(ni, s), NODE_LO(ni, B + s), NODE_LO(ni, 2 * B + s)); }
HVEC3 slot_hi(uint ni, uint s) { return HVEC3(NODE_HI(ni, s), NODE_HI(ni, B + s), NODE_HI(ni, 2 * B + s)); }

void child_box(uint ni, uint s, out vec3 lo, out vec3 hi) {
    lo = vec3(slot_lo(ni, s));
    hi = vec3(slot_hi(ni, s));
}

#ifdef HALF_PAIRS
// Axis a of slots s and s + 1 (s even) as the lanes of one f16vec2: adjacent halves in the
// node, one 32-bit word, no packing.
#ifdef HALF_WORDS
f16vec2 pair_lo(uint ni, uint s, int a) { return unpackFloat2x16(nodes[ni].lo[(uint(a) * B + s) >> 1]); }
f16vec2 pair_hi(uint ni, uint s, int a) { return unpackFloat2x16(nodes[ni].hi[(uint(a) * B + s) >> 1]); }
#else
f16vec2 pair_lo(uint ni, uint s, int a) { return f16vec2(nodes[ni].lo[a * B + s], nodes[ni].lo[a * B + s + 1]); }
f16vec2 pair_hi(uint ni, uint s, int a) { return f16vec2(nodes[ni].hi[a * B + s], nodes[ni].hi[a * B + s + 1]); }
#endif

// The boxes of slots s and s + 1 (s even) for a pair test: axis a of both as lo[a], hi[a] (slot s
// in x, s + 1 in y), and each as a box (lo0, hi0: slot s; lo1, hi1: slot s + 1).
void pair_boxes(uint ni, uint s, out f16vec2 lo[3], out f16vec2 hi[3], out f16vec3 lo0, out f16vec3 hi0,
                out f16vec3 lo1, out f16vec3 hi1) {
    for (int a = 0; a < 3; a++) {
        lo[a] = pair_lo(ni, s, a);
        hi[a] = pair_hi(ni, s, a);
    }
    lo0 = f16vec3(lo[0].x, lo[1].x, lo[2].x);
    hi0 = f16vec3(hi[0].x, hi[1].x, hi[2].x);
    lo1 = f16vec3(lo[0].y, lo[1].y, lo[2].y);
    hi1 = f16vec3(hi[0].y, hi[1].y, hi[2].y);
}
#endif
