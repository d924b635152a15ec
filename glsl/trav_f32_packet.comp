#version 460
// Packet traversal of the f32 layout: P rays, one shared node sequence (packet.glsl).
// Mirrors src/trace/f32.rs (trace_packet). Defines: B, P, WG, STACK_SIZE, STATS, HAS_F64,
// PACKET_SUBGROUP.
#include "ray.glsl"
#include "tri.glsl"
#include "box.glsl"
#include "node.glsl"
#include "packet.glsl"

void main() {
    uint i = packet_ray_index();
    bool valid = i < pc.ray_count;
    RayPre r = ray_pre(valid ? i : 0u);
    uvec4 cnt = uvec4(0u, 1u, 0u, 0u);
    uint pnodes = 0u, asum = 0u;
    best_t = r.tmax; best_prim = NO_PRIM; best_u = 0.0; best_v = 0.0;
    vec2 root = slab32(r, pc.box_lo.xyz, pc.box_hi.xyz, r.tmin, r.tmax);
    bool root_hit = valid && root.x <= root.y;
    // per lane: entry distance of the node, or -1 when inactive for it
    uint st_node[STACK_SIZE];
    float st_t[STACK_SIZE];
    int sp = 0;
    bool overflow = false;
    if (packet_any(root_hit)) {
        st_node[0] = 0u;
        st_t[0] = root_hit ? root.x : -1.0;
        sp = 1;
    }
    while (sp > 0) {
        sp--;
        uint ni = st_node[sp];
        float tn0 = st_t[sp];
        bool act = tn0 >= 0.0 && tn0 <= best_t;
        uint nact = packet_add(act ? 1u : 0u);
        if (nact == 0u) continue;
        pnodes++;
        asum += nact;
        if (act) cnt.x++;
        uint mask = 0u;
        float lt[B];
        for (uint s = 0u; s < uint(B); s++) {
            lt[s] = INF;
            if (nodes[ni].child[s] == CHILD_EMPTY) break;
            if (act) {
                cnt.y++;
                vec3 lo = vec3(nodes[ni].lo[s], nodes[ni].lo[B + s], nodes[ni].lo[2 * B + s]);
                vec3 hi = vec3(nodes[ni].hi[s], nodes[ni].hi[B + s], nodes[ni].hi[2 * B + s]);
                vec2 q = slab32(r, lo, hi, r.tmin, best_t);
                if (q.x <= q.y) { mask |= 1u << s; lt[s] = q.x; }
            }
        }
        uint any_mask = packet_or(mask);
        float key[B];
        for (uint s = 0u; s < uint(B); s++) {
            key[s] = INF;
            if ((any_mask & (1u << s)) != 0u) key[s] = packet_min(lt[s]);
        }
        uint order[B];
        int n = packet_order(any_mask, key, order);
        uint inner[B];
        float inner_t[B];
        int ni_count = 0;
        for (int k = 0; k < n; k++) {
            uint s = order[k];
            uint c = nodes[ni].child[s];
            bool mine = (mask & (1u << s)) != 0u;
            if ((c & LEAF_BIT) != 0u) {
                if (mine) {
                    uint first = c & 0x7ffffffu;
                    uint count = ((c >> 27) & 15u) + 1u;
                    for (uint t = first; t < first + count; t++) {
                        cnt.z++;
                        closest_test(r, t);
                    }
                }
            } else {
                inner[ni_count] = c;
                inner_t[ni_count] = mine ? lt[s] : -1.0;
                ni_count++;
            }
        }
        for (int k = ni_count - 1; k >= 0; k--) {
            if (sp >= STACK_SIZE) { overflow = true; break; }
            st_node[sp] = inner[k];
            st_t[sp] = inner_t[k];
            sp++;
        }
        if (overflow) break;
    }
    if (!valid) return;
    if (overflow) hits[i] = Hit(0.0, -2, 0.0, 0.0);
    else write_hit(i, best_t, best_prim, best_u, best_v);
#ifdef STATS
    counters[2u * i] = cnt;
    counters[2u * i + 1u] = packet_lane() == 0u ? uvec4(pnodes, asum, 0u, 0u) : uvec4(0u);
#endif
}
