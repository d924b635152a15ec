#version 460
// The traversal skeleton of every layout and kernel family: single rays (P = 1), packets in
// a subgroup (PACKET_SUBGROUP) and packets in shared memory; STATS adds the counters. It
// mirrors src/trace/traverse.rs step for step.
//
// Defines: B, P, WG, STACK_SIZE, MATH_F16 | MATH_F32 | MATH_MIXED, PACKET_SUBGROUP, STATS,
// HAS_F64. "interface.glsl" is generated from the Rust definitions for this variant (child
// word fields, push constants, Hit, Counters, the layout's stack Entry); "layout.glsl" is the
// variant's layout hooks (glsl/layout/<name>.glsl), which provide:
//   Node buffer `nodes[]` at BINDING_NODES
//   uint  child_word(uint ni, uint s)
//   void  child_box(uint ni, uint s, out vec3 lo, out vec3 hi)     (stored box, widened)
//   void  layout_ray(RayPre r)                  per-ray constants (private globals)
//   Entry root_entry(RayPre r, float near)      the root's entry for a ray entering at near
//   Entry no_entry(); bool has_entry(Entry e)   the marker of a ray inactive at a level
//   float entry_t(Entry e)                      skip the node when it exceeds the closest hit
//   Visit visit_node(uint ni, Entry e, RayPre r, float best_t)   per node and active ray
//   bool  test_child(uint ni, uint s, Entry e, Visit v, RayPre r, out float key, out ChildHit h)
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
    uint st_node[STACK_SIZE];
    Entry st[STACK_SIZE];
    int sp = 0;
    bool overflow = false;
    if (packet_any(root_hit)) {
        st_node[0] = 0u;
        st[0] = root_hit ? root_entry(r, root.x) : no_entry();
        sp = 1;
    }
    while (sp > 0) {
        sp--;
        uint ni = st_node[sp];
        Entry en = st[sp];
        bool act = has_entry(en) && entry_t(en) <= best_t;
        uint nact = packet_add(act ? 1u : 0u);
        if (nact == 0u) continue;
        pnodes++;
        asum += nact;
        if (act) cnt.x++;
        Visit v = visit_node(ni, en, r, best_t);
        uint mask = 0u;
        float key[B];
        ChildHit ch[B];
        for (uint s = 0u; s < uint(B); s++) {
            key[s] = INF;
            if (child_word(ni, s) == CHILD_EMPTY) break;
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
        uint any_mask = packet_or(mask);
        for (uint s = 0u; s < uint(B); s++) {
            if ((any_mask & (1u << s)) != 0u) key[s] = packet_min(key[s]);
        }
        uint order[B];
        int n = order_children(any_mask, key, order);
        uint p_node[B];
        Entry p_e[B];
        int np = 0;
        for (int k = 0; k < n; k++) {
            uint s = order[k];
            uint c = child_word(ni, s);
            bool mine = (mask & (1u << s)) != 0u;
            if (is_leaf(c)) {
                if (mine) test_leaf(r, c, cnt.z);
                continue;
            }
            p_node[np] = c;
            p_e[np] = mine ? child_entry(ni, s, en, v, ch[s], r, cnt.w) : no_entry();
            np++;
        }
        for (int k = np - 1; k >= 0; k--) {
            if (sp >= STACK_SIZE) { overflow = true; break; }
            st_node[sp] = p_node[k];
            st[sp] = p_e[k];
            sp++;
        }
        if (overflow) break;
    }
    if (!valid) return;
    if (overflow) hits[i] = Hit(0.0, PRIM_OVERFLOW, 0.0, 0.0);
    else write_hit(i, best_t, best_prim, best_u, best_v);
#ifdef STATS
    bool first = packet_lane() == 0u;
    counters[i] = Counters(cnt.x, cnt.y, cnt.z, cnt.w, first ? pnodes : 0u, first ? asum : 0u);
#endif
}
