// Layout f16a hooks (src/layout/f16a): every inner node stores its own frame (fp32 anchor w,
// power-of-two scale k) and its children as fp16 in that frame; the shared anchored hooks
// (anchored.glsl) re-derive the origin in each node's frame from the fp32 world ray.
#include "half.glsl"

// The node: the frame (w, k), then f16h's fp16 boxes and child words.
#define NODE16_HEAD float w[3]; float k;
#include "node16.glsl"

// The node's frame, read once per visit.
struct NodeFrame { vec3 w; float k; };
NodeFrame load_frame(uint ni) { return NodeFrame(vec3(nodes[ni].w[0], nodes[ni].w[1], nodes[ni].w[2]), nodes[ni].k); }
void node_frame(NodeFrame f, out vec3 w, out float k) {
    w = f.w;
    k = f.k;
}
void local_box(NodeFrame f, uint ni, uint s, out HVEC3 lo, out HVEC3 hi) {
    lo = slot_lo(ni, s);
    hi = slot_hi(ni, s);
}
void world_planes(NodeFrame f, uint ni, uint s, int a, out float lo, out float hi);

#include "anchored.glsl"

// Axis a of the fp32 world box (anchored.glsl: world_box; FC_OFF tests a box axis by axis).
void world_planes(NodeFrame f, uint ni, uint s, int a, out float lo, out float hi) {
    float ik = inv_pow2(f.k);
    uint i = uint(a) * uint(B) + s;
    lo = decode_plane(f.w[a], float(NODE_LO(ni, i)) * ik);
    hi = decode_plane(f.w[a], float(NODE_HI(ni, i)) * ik);
}
