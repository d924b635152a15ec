// Layout f16a hooks (src/layout/f16a): every inner node stores its own frame (fp32 anchor w,
// power-of-two scale k) and its children as fp16 in that frame; the shared anchored hooks
// (anchored.glsl) re-derive the origin in each node's frame from the fp32 world ray.
#include "half.glsl"

struct Node {
    float w[3];
    float k;
    float16_t lo[3 * B];   // lo[axis * B + slot], in the node's frame, rounded down
    float16_t hi[3 * B];
    uint child[B];
};
layout(std430, set = 0, binding = BINDING_NODES) readonly buffer Nodes { Node nodes[]; };

uint child_word(uint ni, uint s) { return nodes[ni].child[s]; }

HVEC3 slot_lo(uint ni, uint s) { return HVEC3(LOADH(nodes[ni].lo[s]), LOADH(nodes[ni].lo[B + s]), LOADH(nodes[ni].lo[2 * B + s])); }
HVEC3 slot_hi(uint ni, uint s) { return HVEC3(LOADH(nodes[ni].hi[s]), LOADH(nodes[ni].hi[B + s]), LOADH(nodes[ni].hi[2 * B + s])); }

void child_box(uint ni, uint s, out vec3 lo, out vec3 hi) {
    lo = vec3(slot_lo(ni, s));
    hi = vec3(slot_hi(ni, s));
}

void node_frame(uint ni, out vec3 w, out float k) {
    w = vec3(nodes[ni].w[0], nodes[ni].w[1], nodes[ni].w[2]);
    k = nodes[ni].k;
}
void local_box(uint ni, uint s, out HVEC3 lo, out HVEC3 hi) {
    lo = slot_lo(ni, s);
    hi = slot_hi(ni, s);
}
void world_box(uint ni, uint s, out vec3 lo, out vec3 hi);

#include "anchored.glsl"

void world_box(uint ni, uint s, out vec3 lo, out vec3 hi) {
    float ik = inv_pow2(nodes[ni].k);
    vec3 l = vec3(slot_lo(ni, s));
    vec3 u = vec3(slot_hi(ni, s));
    for (int a = 0; a < 3; a++) {
        float w = nodes[ni].w[a];
        lo[a] = decode_plane(w, l[a] * ik);
        hi[a] = decode_plane(w, u[a] * ik);
    }
}
