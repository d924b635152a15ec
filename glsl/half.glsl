// The fp16 box test of the layouts that test fp16 boxes in a node frame against an origin with
// an error bound (f16h, f16w, f16a, q8; f16h-poster uses its types, direction and frames
// without the bound), mirroring src/layout/half (the bound is argued there): the anchored
// origin, the per-ray fp16 direction, the widened slab test and the visit bounds. Every
// constant (OCAP, EMAX, …, TWO_M*) comes from the Rust files through the generated
// interface.glsl. Its fp16 types and roundings are fp16.glsl's, the frames frames.glsl's; the
// box test of each math mode is half_f16.glsl's, half_mixed.glsl's or half_f32.glsl's.
#include "fp16.glsl"

#ifdef FC_OFF
float up32(float x) { return upper32(x); }
#else
float up32(float x) { return isinf(x) ? x : upper32(x); }
#endif

// Origin at world parameter t in frame (w, k), fp32 then fp16, clamped to +-OCAP; returns the
// error bound (half.rs, anchor).
float anchor(RayPre r, vec3 w, float k, float t, out OVEC o) {
    o = OVEC(0.0);
    float mag = 0.0;
    float clampd = 0.0;
    float lmax = 0.0;
    for (int a = 0; a < 3; a++) {
        precise float td = t * r.d[a];
        precise float x = r.o[a] + td;
        precise float l = (x - w[a]) * k;
        precise float s = abs(r.o[a]) + abs(td) + abs(x) + abs(w[a]);
        mag = max(mag, s);
        float lc = clamp(l, -OCAP, OCAP);
        precise float cd = abs(l - lc);
        clampd = max(clampd, cd);
        lmax = max(lmax, abs(lc));
        o[a] = OCONV(lc);
    }
#ifdef FC_OFF
    precise float e = (mag * k * TWO_M21 + clampd + lmax * TWO_M11 + TWO_M24) * (1.0 + TWO_M18);
#else
    precise float e = (mag * k * TWO_M23 + clampd + lmax * TWO_M11 + TWO_M24) * (1.0 + TWO_M18);
#endif
    return e;
}

// Per-ray constants (half.rs, Ray16): m = max|D|, d16 = fp16(D / m), its fp16 and fp32
// reciprocals.
float lr_m;
HVEC3 lr_d16;
#ifndef MATH_F32
f16vec3 lr_idir;
#endif
vec3 lr_idir32;

void layout_ray(RayPre r) {
    lr_m = max(max(abs(r.d.x), abs(r.d.y)), abs(r.d.z));
    for (int a = 0; a < 3; a++) {
        precise float x = r.d[a] / lr_m;
        lr_d16[a] = abs(x) < D_FLUSH ? H0 : TO_HALF(x);
#ifdef FC_OFF
        // An fp32 reciprocal rounded to fp16 (no inf: a zero component's is never used).
        precise float inv32 = 1.0 / float(lr_d16[a]);
        lr_idir32[a] = lr_d16[a] == H0 ? 0.0 : inv32;
#ifndef MATH_F32
        lr_idir[a] = lr_d16[a] == H0 ? H0 : float16_t(rte16(inv32));
#endif
#else
#ifndef MATH_F32
        precise float16_t inv = float16_t(1.0) / lr_d16[a];
        lr_idir[a] = lr_d16[a] == H0 ? HINF : inv;
#endif
        precise float inv32 = 1.0 / float(lr_d16[a]);
        lr_idir32[a] = lr_d16[a] == H0 ? INF : inv32;
#endif
    }
}

// The math mode's box test, one header each.
#if defined(MATH_F32)
#include "half_f32.glsl"
#elif defined(MATH_MIXED)
#include "half_mixed.glsl"
#else
#include "half_f16.glsl"
#endif

// Quantities fixed for one visit of one node by one ray (half.rs, half_visit): node frame scale k,
// origin error e, the world parameter tp the origin stands for, the entry bound tlo.
struct HVisit {
    float mk;
    HALF s_lim;
    HALF lower;
    bool prec;
    HALF w;
};

HVisit half_visit(float k, float e, float tp, float tlo, float best) {
    HVisit v;
    precise float mk = lr_m * k;
    precise float s_max = S_BASE + e + 1.0;
    precise float lim = (best - tp) * mk;
#ifdef FC_OFF
    // No inf: a limit that overflows (or comes from a clamped infinite tmax) becomes s_max,
    // which the min below would pick anyway; tested on the bits.
    if ((floatBitsToUint(lim) & 0x7fffffffu) >= floatBitsToUint(BIG32)) lim = s_max;
#endif
    v.s_lim = up16(min(up32(lim), s_max));
    precise float sg = (tp - tlo) * mk;
    float sigma = up32(sg);
    v.lower = down16(max(-sigma, -s_max));
    v.prec = e <= EBIG;
#ifdef FC_OFF
    precise float we = e + e * TWO_M11 + W_MARGIN_OFF;
#else
    precise float we = e + e * TWO_M11 + W_MARGIN;
#endif
    v.w = up16(we);
    v.mk = mk;
    return v;
}

// The box test of one stored fp16 box under a visit: hit, with (tn, tn_lb) (half.rs, half_test).
bool half_test(OVEC o, HVisit v, HVEC3 lo, HVEC3 hi, out float tn, out float tn_lb) {
    if (!v.prec) {
        tn = float(v.lower);
        tn_lb = tn;
        return true;
    }
    vec3 q = slab_math(o, v.w, lo, hi);
    tn = q.x;
    tn_lb = q.y;
    return q.y <= q.z && q.z >= float(v.lower) && q.y <= float(v.s_lim);
}

#ifdef HALF_PAIRS
// Two box tests under one visit, as two half_test calls would give them (slab16x2; lo[a], hi[a]:
// axis a of both boxes).
bvec2 half_test2(OVEC o, HVisit v, f16vec2 lo[3], f16vec2 hi[3], out vec2 tn, out vec2 tn_lb) {
    if (!v.prec) {
        tn = vec2(float(v.lower));
        tn_lb = tn;
        return bvec2(true);
    }
    vec2 ub;
    slab16x2(o, v.w, lo, hi, tn, tn_lb, ub);
    // tn_lb <= ub && ub >= lower && tn_lb <= s_lim, two comparisons a lane (max is exact).
    bvec2 a = lessThanEqual(max(tn_lb, vec2(float(v.lower))), ub);
    bvec2 b = lessThanEqual(tn_lb, vec2(float(v.s_lim)));
    return bvec2(a.x && b.x, a.y && b.y);
}
#endif

// A lower bound of the world parameter of anything that matters in a hit child (half.rs,
// half_child_tlo).
float half_child_tlo(HVisit v, float tp, float tlo, float tn_lb) {
    float s_lo = max(tn_lb, float(v.lower));
    precise float q = s_lo / v.mk;
#ifdef FC_OFF
    // A node visited without box tests keeps its parent's tlo (half.rs).
    precise float t0 = (tp + q) - (abs(tp) + abs(q)) * TWO_M19;
    return v.prec ? max(t0, tlo) : tlo;
#else
    precise float t0 = (tp + q) - (abs(tp) + abs(q)) * TWO_M21;
    return max(t0, tlo);
#endif
}

#include "frames.glsl"
