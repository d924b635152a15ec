#version 460
#extension GL_EXT_control_flow_attributes : require
// The traversal skeleton of every layout and kernel family: single rays (P = 1), packets in
// a subgroup (PACKET_SUBGROUP) and packets in shared memory; STATS adds the counters. It
// mirrors src/layout/traverse.rs step for step.
//
// Defines: B, P, WG, STACK_SIZE, MATH_F16 | MATH_F32 | MATH_MIXED, PACKET_SUBGROUP, STATS,
// HAS_F64, FC_OFF, ADDRESSED. "interface.glsl" is generated from the Rust definitions for this
// variant (child word fields, push constants, Hit, Counters, the layout's stack Entry); "layout.glsl" is the
// variant's layout hooks (glsl/layout/<name>.glsl), which provide:
//   Node buffer `nodes[]`, declared with NODE_BUFFER(Node) (bound, or by address: ray.glsl)
//   uint  child_word(uint ni, uint s)
//   void  child_box(uint ni, uint s, out vec3 lo, out vec3 hi)     (stored box, widened)
//   void  layout_ray(RayPre r)                  per-ray constants (private globals)
//   Entry root_entry(RayPre r, float near)      the root's entry for a ray entering at near
//   Entry no_entry(); bool has_entry(Entry e)   the marker of a ray inactive at a level
//   float entry_t(Entry e)                      skip the node when it exceeds the closest hit
//   Visit visit_node(uint ni, Entry e, RayPre r, float best_t)   per node and active ray
//   bool  test_child(uint ni, uint s, Entry e, Visit v, RayPre r, out float key, out ChildHit h)
//   (optional, with TEST_PAIRS defined) bvec2 test_pair(uint ni, uint s, Entry e, Visit v,
//         RayPre r, out vec2 key, out ChildHit h0, out ChildHit h1): slots s and s + 1 at once
//   Entry child_entry(uint ni, uint s, Entry e, Visit v, ChildHit h, RayPre r, inout uint reanchors)
#include "interface.glsl"
#include "ray.glsl"
#include "tri.glsl"
#include "box.glsl"
#include "layout.glsl"
#include "packet.glsl"

void main() {
    uint i = packet_ray_index();
    bool valid = i < pc.ray_count;
#if P == 1
    if (!valid) return;
#endif
    RayPre r = ray_pre(valid ? i : 0u);
    layout_ray(r);
    uvec4 cnt = uvec4(0u, 1u, 0u, 0u);   // nodes, box tests (the root's first), triangle tests, re-anchors
    uint pnodes = 0u, asum = 0u;
    closest_init(r.tmax);
    vec2 root = slab32(r, pc.box_lo.xyz, pc.box_hi.xyz, r.tmin, r.tmax);
    bool root_hit = valid && root.x <= root.y;
    // The stack holds the nodes still to visit; the node being visited (ni, en) is kept out of
    // it: a visit goes on with its nearest inner child directly and pushes only the others, so
    // the nodes are visited in exactly the order of pushing all and popping the top.
    uint st_node[STACK_SIZE];
    Entry st[STACK_SIZE];
    int sp = 0;
    bool overflow = false;
    bool more = packet_any(root_hit);
    uint ni = 0u;
    Entry en = root_hit ? root_entry(r, root.x) : no_entry();
    while (more) {
        bool act = has_entry(en) && entry_t(en) <= best_t;
        bool descend = false;
#if P == 1
        if (act) {
#endif
        Visit v = visit_node(ni, en, r, best_t);
        // The child words are read once per visit; slots past the first empty one are never read.
        uint mask = 0u;
        uint cw[B];
        float key[B];
        ChildHit ch[B];
        [[unroll]] for (uint s = 0u; s < uint(B); s++) key[s] = INF;
#ifdef TEST_PAIRS
        // Two children per test (the layout's test_pair: packed fp16 arithmetic), the same
        // results and counts as testing them one by one; a lone last child is tested in a
        // pair with the (in-bounds, ignored) slot after it.
        uint nc = uint(B);
        [[unroll]] for (uint s = 0u; s < uint(B); s++) {
            cw[s] = child_word(ni, s);
            if (cw[s] == CHILD_EMPTY) {
                nc = s;
                break;
            }
        }
        if (act) {
            [[unroll]] for (uint s = 0u; s < uint(B); s += 2u) {
                if (s >= nc) break;
                bool two = s + 1u < nc;
                cnt.y += two ? 2u : 1u;
                vec2 k;
                ChildHit h0, h1;
                bvec2 hit = test_pair(ni, s, en, v, r, k, h0, h1);
                if (hit.x) {
                    mask |= 1u << s;
                    key[s] = k.x;
                    ch[s] = h0;
                }
                if (two && hit.y) {
                    mask |= 2u << s;
                    key[s + 1u] = k.y;
                    ch[s + 1u] = h1;
                }
            }
        }
#else
        [[unroll]] for (uint s = 0u; s < uint(B); s++) {
            cw[s] = child_word(ni, s);
            if (cw[s] == CHILD_EMPTY) break;
            if (!act) continue;
            cnt.y++;
            float k;
            ChildHit h;
            if (test_child(ni, s, en, v, r, k, h)) {
                mask |= 1u << s;
                key[s] = k;
                ch[s] = h;
            }
        }
#endif
        // One reduction over the packet: active rays, the union of hit children, each hit
        // child's smallest key. A node no ray is active for is skipped (nothing was tested).
        uint nact;
        uint any_mask = packet_reduce(act, mask, key, nact);
        if (nact != 0u) {
            pnodes++;
            asum += nact;
            if (act) cnt.x++;
            // Leaves first, in slot order, by the rays that hit them: any order gives the same
            // closest hit (ties go to the lower prim) and the same counters. Inner children go
            // nearest first: each one's place is its rank by (key, slot), so nothing is sorted
            // or copied through arrays indexed at run time (traverse.rs, order_children); rank
            // 0 is visited next, the others are pushed with the nearer ones on top.
            uint inner = 0u;
            [[unroll]] for (uint s = 0u; s < uint(B); s++) {
                if ((any_mask & (1u << s)) == 0u) continue;
                uint c = cw[s];
                if (!is_leaf(c)) inner |= 1u << s;
                else if ((mask & (1u << s)) != 0u) test_leaf(r, c, cnt.z);
            }
            int n = bitCount(inner);
            uint next_node = 0u;
            Entry next_entry = no_entry();
            [[unroll]] for (uint s = 0u; s < uint(B); s++) {
                if ((inner & (1u << s)) == 0u) continue;
                int rank = 0;
                [[unroll]] for (uint t = 0u; t < uint(B); t++) {
                    bool before = key[t] < key[s] || (key[t] == key[s] && t < s);
                    if ((inner & (1u << t)) != 0u && before) rank++;
                }
                Entry e = (mask & (1u << s)) != 0u ? child_entry(ni, s, en, v, ch[s], r, cnt.w) : no_entry();
                if (rank == 0) {
                    next_node = cw[s];
                    next_entry = e;
                } else {
                    int pos = sp + n - 1 - rank;
                    if (pos < STACK_SIZE) {
                        st_node[pos] = cw[s];
                        st[pos] = e;
                    }
                }
            }
            // The same bound as pushing all n (traverse.rs): the encoder checks that a BVH
            // never needs more (GpuBvh::upload).
            if (sp + n > STACK_SIZE) {
                overflow = true;
                break;
            }
            if (n > 0) {
                sp += n - 1;
                ni = next_node;
                en = next_entry;
                descend = true;
            }
        }
#if P == 1
        }
#endif
        if (!descend) {
            if (sp == 0) {
                more = false;
            } else {
                sp--;
                ni = st_node[sp];
                en = st[sp];
            }
        }
    }
    if (!valid) return;
    if (overflow) hits[i] = Hit(0.0, PRIM_OVERFLOW, 0.0, 0.0);
    else write_hit(i, best_t, best_prim, best_u, best_v);
#ifdef STATS
    bool first = packet_lane() == 0u;
    counters[i] = Counters(cnt.x, cnt.y, cnt.z, cnt.w, first ? pnodes : 0u, first ? asum : 0u);
#endif
}
