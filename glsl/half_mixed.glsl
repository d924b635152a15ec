// Mixed math (MATH_MIXED): fp16 differences and products, fp32 min, max and bounds. The box
// test of this math mode (slab_math) and, with float controls, two boxes at once on packed
// lanes (slab16x2), chosen by half.glsl's one #if.
#include "half16.glsl"

// The box test in the variant's math mode, as fp32 (tn, tn_lb, tf_ub) (half.rs, slab).
vec3 slab_math(OVEC o, HALF w, HVEC3 lo, HVEC3 hi) {
    // Unbounded: inf, or without float controls SAT (fp16 products).
#ifdef FC_OFF
    const float UNB = SAT;
#else
    const float UNB = INF;
#endif
    float tn = -UNB;
    float tf = UNB;
    for (int a = 0; a < 3; a++) {
        float t0, t1;
        precise float16_t la = (lo[a] - o[a]) - w;
        precise float16_t ha = (hi[a] - o[a]) + w;
        bool inside = la <= H0 && ha >= H0;
        precise float16_t x16 = HMUL(la, lr_idir[a]);
        precise float16_t y16 = HMUL(ha, lr_idir[a]);
        float x = float(x16);
        float y = float(y16);
        if (lr_d16[a] == H0) {
            t0 = inside ? -UNB : UNB;
            t1 = inside ? UNB : -UNB;
        } else {
            t0 = min(x, y);
            t1 = max(x, y);
        }
        tn = max(tn, t0);
        tf = min(tf, t1);
    }
    precise float tn_lb = tn * (tn > 0.0 ? (1.0 - 1.0 / 256.0) : (1.0 + 1.0 / 256.0));
    precise float tf_ub = tf * (tf > 0.0 ? (1.0 + 1.0 / 256.0) : (1.0 - 1.0 / 256.0));
    return vec3(tn, tn_lb, tf_ub);
}

#ifndef FC_OFF
#define HALF_PAIRS 1
#define SPAN2 vec2
#define SPAN_UNB INF
#include "half_pairs.glsl"

// Two box tests at once (two children of a node), on f16vec2 lanes: the operations of
// slab_math (fp16 differences and products, fp32 min/max), each lane rounded exactly as the scalar test rounds it, so a GPU compiler can pack the fp16 ones
// two to a register (v_pk_* on AMD, HFMA2/HMNMX2 on NVIDIA) and both results equal two scalar
// tests bit for bit (min and max are exact). Returns (tn, tn_lb, tf_ub) per lane as fp32.
// lo[a], hi[a]: axis a of both boxes (box 0 in x, box 1 in y).
void slab16x2(OVEC o, HALF w, f16vec2 lo[3], f16vec2 hi[3], out vec2 tn, out vec2 tn_lb, out vec2 tf_ub) {
    SPAN2 tn2, tf2;
    slab16x2_span(o, true, f16vec2(w), lo, hi, tn2, tf2);
    // fp32 bounds (slab_math's mixed path).
    tn = tn2;
    precise vec2 lb = tn2 * mix(vec2(1.0 + 1.0 / 256.0), vec2(1.0 - 1.0 / 256.0), greaterThan(tn2, vec2(0.0)));
    precise vec2 ub = tf2 * mix(vec2(1.0 - 1.0 / 256.0), vec2(1.0 + 1.0 / 256.0), greaterThan(tf2, vec2(0.0)));
    tn_lb = lb;
    tf_ub = ub;
}
#endif
