// Layout q8 hooks (src/layout/q8): compressed wide nodes after Ylitie, Karras and Laine
// (HPG 2017): child planes quantized to 8 bits relative to the node's fp32 origin p with a
// power-of-two step 2^e per axis, inner children and leaf triangles addressed from two base
// indices and one 16-bit word per child. Read as 32-bit words (no 8- or 16-bit storage).
// The shared anchored hooks (anchored.glsl): fp32 math decodes the planes to world fp32
// ; fp16 math tests them in the node frame (w = p, k = 2^(E_SHIFT - max e)), where
// every grid value q 2^(e_axis + E_SHIFT - max e) is exact in fp16 (the encoder keeps
// e_axis >= max e - 30).
#include "half.glsl"

struct Node {
    float p[3];
    uint exps;          // e_axis + E_BIAS in byte axis
    uint child_base;    // index of the first inner child
    uint tri_base;      // first triangle of the first leaf
    uint q[3 * B / 2];  // bytes: lo[axis * B + slot], then hi[axis * B + slot]
    uint meta[B / 2];   // 16 bits per slot: META_EMPTY, META_INNER | rank, (count-1) << META_COUNT_SHIFT | offset
};
NODE_BUFFER(Node)

uint child_word(uint ni, uint s) {
    uint m = (nodes[ni].meta[s >> 1u] >> ((s & 1u) * 16u)) & 0xffffu;
    if (m == META_EMPTY) return CHILD_EMPTY;
    if ((m & META_INNER) != 0u) return nodes[ni].child_base + (m & ~META_INNER);
    return LEAF_BIT | ((m >> META_COUNT_SHIFT) << LEAF_COUNT_SHIFT) | (nodes[ni].tri_base + (m & META_OFFSET_MASK));
}

uint qbyte(uint ni, uint i) { return (nodes[ni].q[i >> 2u] >> ((i & 3u) * 8u)) & 0xffu; }

// Axis a of the quantized box in grid units.
void grid_planes(uint ni, uint s, int a, out float lo, out float hi) {
    lo = float(qbyte(ni, uint(a) * uint(B) + s));
    hi = float(qbyte(ni, 3u * uint(B) + uint(a) * uint(B) + s));
}

// The quantized box in grid units.
void grid_box(uint ni, uint s, out vec3 lo, out vec3 hi) {
    lo = vec3(0.0);
    hi = vec3(0.0);
    for (int a = 0; a < 3; a++) grid_planes(ni, s, a, lo[a], hi[a]);
}

void child_box(uint ni, uint s, out vec3 lo, out vec3 hi) { grid_box(ni, s, lo, hi); }

// The node's origin and step exponents, read once per visit.
struct NodeFrame { vec3 p; ivec3 e; };
NodeFrame load_frame(uint ni) {
    uint x = nodes[ni].exps;
    ivec3 e = ivec3(int(x & 0xffu), int((x >> 8u) & 0xffu), int((x >> 16u) & 0xffu)) - E_BIAS;
    return NodeFrame(vec3(nodes[ni].p[0], nodes[ni].p[1], nodes[ni].p[2]), e);
}
int frame_emax(NodeFrame f) { return max(max(f.e.x, f.e.y), f.e.z); }
void node_frame(NodeFrame f, out vec3 w, out float k) {
    w = f.p;
    k = pow2(E_SHIFT - frame_emax(f));
}
void local_box(NodeFrame fr, uint ni, uint s, out HVEC3 lo, out HVEC3 hi) {
    lo = HVEC3(0.0);
    hi = HVEC3(0.0);
    vec3 l, u;
    grid_box(ni, s, l, u);
    int em = frame_emax(fr);
    for (int a = 0; a < 3; a++) {
        float f = pow2(fr.e[a] + E_SHIFT - em);
        // q < 2^8 times 2^j, j >= -24: exact in fp32 and in fp16.
        lo[a] = HALF(l[a] * f);
        hi[a] = HALF(u[a] * f);
    }
}
void world_planes(NodeFrame f, uint ni, uint s, int a, out float lo, out float hi);

#include "anchored.glsl"

// Axis a of the fp32 world box (anchored.glsl: world_box; FC_OFF tests a box axis by axis).
void world_planes(NodeFrame fr, uint ni, uint s, int a, out float lo, out float hi) {
    float f = pow2(fr.e[a]);
    // q 2^e is exact in fp32; one rounding in the sum (decode_plane).
    float l, u;
    grid_planes(ni, s, a, l, u);
    lo = decode_plane(fr.p[a], l * f);
    hi = decode_plane(fr.p[a], u * f);
}
