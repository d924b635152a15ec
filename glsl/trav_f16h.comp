#version 460
// Single-ray traversal of the f16h layout: fp16 box tests and fp16 origin moves with a
// carried error bound, re-anchored from the fp32 world ray when the bound grows too large.
// Mirrors src/trace/f16h.rs operation for operation; see the bound argued there.
// Defines: B, P (1), STACK_SIZE, STATS, HAS_F64.
#define F16H 1
#include "ray.glsl"
#include "tri.glsl"
#include "box.glsl"
#include "frame.glsl"

#include "node.glsl"

// The "extra stack": node, frame (w, k), origin in the node frame, its error bound,
// the world parameter it stands for, and a lower bound on what can still matter.
uint st_node[STACK_SIZE];
vec4 st_wk[STACK_SIZE];
OVEC st_o[STACK_SIZE];
float st_e[STACK_SIZE];
float st_tp[STACK_SIZE];
float st_tlo[STACK_SIZE];

void main() {
    uint i = ray_index();
    if (i >= pc.ray_count) return;
    RayPre r = ray_pre(i);
    // Ray16
    float m = max(max(abs(r.d.x), abs(r.d.y)), abs(r.d.z));
    f16vec3 d16, idir;
    vec3 idir32;
    for (int a = 0; a < 3; a++) {
        precise float x = r.d[a] / m;
        d16[a] = abs(x) < (1.0 / 32768.0) ? H0 : float16_t(x);
        precise float16_t inv = float16_t(1.0) / d16[a];
        idir[a] = d16[a] == H0 ? HINF : inv;
        precise float inv32 = 1.0 / float(d16[a]);
        idir32[a] = d16[a] == H0 ? INF : inv32;
    }
    uvec4 cnt = uvec4(0u, 1u, 0u, 0u);
    best_t = r.tmax; best_prim = NO_PRIM; best_u = 0.0; best_v = 0.0;
    vec2 root = slab32(r, pc.box_lo.xyz, pc.box_hi.xyz, r.tmin, r.tmax);
    bool overflow = false;
    if (root.x <= root.y) {
        int sp = 1;
        OVEC o0;
        float e0 = anchor(r, pc.root_wk.xyz, pc.root_wk.w, root.x, o0);
        st_node[0] = 0u; st_wk[0] = pc.root_wk; st_o[0] = o0; st_e[0] = e0; st_tp[0] = root.x; st_tlo[0] = root.x;
        while (sp > 0) {
            sp--;
            uint ni = st_node[sp];
            vec3 fw = st_wk[sp].xyz;
            float fk = st_wk[sp].w;
            OVEC o = st_o[sp];
            float e = st_e[sp];
            float tp = st_tp[sp];
            float tlo = st_tlo[sp];
            if (tlo > best_t) continue;
            cnt.x++;
            precise float mk = m * fk;
            precise float s_max = S_BASE + e + 1.0;
            precise float lim = (best_t - tp) * mk;
            float16_t s_lim = up16(min(up32(lim), s_max));
            precise float sg = (tp - tlo) * mk;
            float sigma = up32(sg);
            float16_t lower = down16(max(-sigma, -s_max));
            bool prec = e <= EBIG;
            precise float we = e + e * TWO_M11 + W_MARGIN;
            float16_t w = up16(we);
            float h_tn[B];
            float h_lb[B];
            uint h_s[B];
            int nh = 0;
            for (uint s = 0u; s < uint(B); s++) {
                if (nodes[ni].child[s] == CHILD_EMPTY) break;
                cnt.y++;
                float tn, tn_lb;
                bool hit;
                if (prec) {
                    f16vec3 lo = f16vec3(nodes[ni].lo[s], nodes[ni].lo[B + s], nodes[ni].lo[2 * B + s]);
                    f16vec3 hi = f16vec3(nodes[ni].hi[s], nodes[ni].hi[B + s], nodes[ni].hi[2 * B + s]);
                    vec3 q = slab_math(o, d16, idir, idir32, w, lo, hi);
                    tn = q.x; tn_lb = q.y;
                    hit = q.y <= q.z && q.z >= float(lower) && q.y <= float(s_lim);
                } else {
                    tn = float(lower); tn_lb = float(lower); hit = true;
                }
                if (hit) {
                    int j = nh;
                    while (j > 0 && h_tn[j - 1] > tn) { h_tn[j] = h_tn[j - 1]; h_lb[j] = h_lb[j - 1]; h_s[j] = h_s[j - 1]; j--; }
                    h_tn[j] = tn; h_lb[j] = tn_lb; h_s[j] = s;
                    nh++;
                }
            }
            // children to push, in hit order
            uint p_node[B];
            vec4 p_wk[B];
            OVEC p_o[B];
            float p_e[B];
            float p_tp[B];
            float p_tlo[B];
            int np = 0;
            for (int k = 0; k < nh; k++) {
                uint s = h_s[k];
                uint c = nodes[ni].child[s];
                if ((c & LEAF_BIT) != 0u) {
                    uint first = c & 0x7ffffffu;
                    uint count = ((c >> 27) & 15u) + 1u;
                    for (uint t = first; t < first + count; t++) {
                        cnt.z++;
                        closest_test(r, t);
                    }
                    continue;
                }
                f16vec3 lo = f16vec3(nodes[ni].lo[s], nodes[ni].lo[B + s], nodes[ni].lo[2 * B + s]);
                f16vec3 hi = f16vec3(nodes[ni].hi[s], nodes[ni].hi[B + s], nodes[ni].hi[2 * B + s]);
                child_entry(r, m, d16, fw, fk, o, e, tp, tlo, mk, float(lower), prec, lo, hi, h_tn[k], h_lb[k],
                            cnt.w, p_wk[np], p_o[np], p_e[np], p_tp[np], p_tlo[np]);
                p_node[np] = c;
                np++;
            }
            for (int k = np - 1; k >= 0; k--) {
                if (sp >= STACK_SIZE) { overflow = true; break; }
                st_node[sp] = p_node[k]; st_wk[sp] = p_wk[k]; st_o[sp] = p_o[k];
                st_e[sp] = p_e[k]; st_tp[sp] = p_tp[k]; st_tlo[sp] = p_tlo[k];
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
