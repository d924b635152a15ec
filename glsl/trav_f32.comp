#version 460
// Single-ray traversal of the f32 layout (B-wide, world-space fp32 child boxes).
// Mirrors src/trace/f32.rs: closest-first order, leaves tested when their box is hit.
// Defines: B (branching), P (packet size, 1), STACK_SIZE, STATS (counting variant), HAS_F64.
#include "ray.glsl"
#include "tri.glsl"
#include "box.glsl"

#include "node.glsl"

void main() {
    uint i = ray_index();
    if (i >= pc.ray_count) return;
    RayPre r = ray_pre(i);
    uvec4 cnt = uvec4(0u, 1u, 0u, 0u);
    best_t = r.tmax; best_prim = NO_PRIM; best_u = 0.0; best_v = 0.0;
    vec2 root = slab32(r, pc.box_lo.xyz, pc.box_hi.xyz, r.tmin, r.tmax);
    bool overflow = false;
    if (root.x <= root.y) {
        uint st_node[STACK_SIZE];
        float st_t[STACK_SIZE];
        int sp = 1;
        st_node[0] = 0u;
        st_t[0] = root.x;
        while (sp > 0) {
            sp--;
            uint ni = st_node[sp];
            if (st_t[sp] > best_t) continue;
            cnt.x++;
            float hit_t[B];
            uint hit_s[B];
            int nh = 0;
            for (uint s = 0u; s < uint(B); s++) {
                if (nodes[ni].child[s] == CHILD_EMPTY) break;
                cnt.y++;
                vec3 lo = vec3(nodes[ni].lo[s], nodes[ni].lo[B + s], nodes[ni].lo[2 * B + s]);
                vec3 hi = vec3(nodes[ni].hi[s], nodes[ni].hi[B + s], nodes[ni].hi[2 * B + s]);
                vec2 q = slab32(r, lo, hi, r.tmin, best_t);
                if (q.x <= q.y) {
                    // insertion by (t, slot): slots arrive in increasing order
                    int j = nh;
                    while (j > 0 && hit_t[j - 1] > q.x) { hit_t[j] = hit_t[j - 1]; hit_s[j] = hit_s[j - 1]; j--; }
                    hit_t[j] = q.x; hit_s[j] = s;
                    nh++;
                }
            }
            uint inner[B];
            float inner_t[B];
            int ni_count = 0;
            for (int k = 0; k < nh; k++) {
                uint c = nodes[ni].child[hit_s[k]];
                if ((c & LEAF_BIT) != 0u) {
                    uint first = c & 0x7ffffffu;
                    uint count = ((c >> 27) & 15u) + 1u;
                    for (uint t = first; t < first + count; t++) {
                        cnt.z++;
                        closest_test(r, t);
                    }
                } else {
                    inner[ni_count] = c;
                    inner_t[ni_count] = hit_t[k];
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
    }
    if (overflow) hits[i] = Hit(0.0, -2, 0.0, 0.0);
    else write_hit(i, best_t, best_prim, best_u, best_v);
#ifdef STATS
    counters[2u * i] = cnt;
    counters[2u * i + 1u] = uvec4(cnt.x, cnt.x, 0u, 0u);
#endif
}
