// Layout f16w hooks (src/layout/f16w): every child box stored as fp16 in one global frame
// (push constants' root = w.xyz, k), the nodes of f16h (node16.glsl); the shared anchored hooks
// (anchored.glsl) with that one frame for every node.
#include "half.glsl"
#include "node16.glsl"

// The one frame; 1/k once per visit.
struct NodeFrame { float ik; };
NodeFrame load_frame(uint ni);
void node_frame(NodeFrame f, out vec3 w, out float k) {
    w = pc.root.xyz;
    k = pc.root.w;
}
void local_box(NodeFrame f, uint ni, uint s, out HVEC3 lo, out HVEC3 hi) {
    lo = slot_lo(ni, s);
    hi = slot_hi(ni, s);
}
void world_planes(NodeFrame f, uint ni, uint s, int a, out float lo, out float hi);

#include "anchored.glsl"

NodeFrame load_frame(uint ni) { return NodeFrame(inv_pow2(pc.root.w)); }

// Axis a of the fp32 world box (anchored.glsl: world_box; FC_OFF tests a box axis by axis).
void world_planes(NodeFrame f, uint ni, uint s, int a, out float lo, out float hi) {
    uint i = uint(a) * uint(B) + s;
    // fp16 times a power of two: exact in fp32; one rounding in the sum (decode_plane).
    lo = decode_plane(pc.root[a], float(NODE_LO(ni, i)) * f.ik);
    hi = decode_plane(pc.root[a], float(NODE_HI(ni, i)) * f.ik);
}
