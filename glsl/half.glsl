// The fp16 box test of the layouts that test fp16 boxes in a node frame against an origin with
// an error bound (f16h, f16w, f16a, q8; f16h-poster uses its types, direction and frames
// without the bound), mirroring src/layout/half (the bound is argued there): the anchored
// origin, the per-ray fp16 direction, the widened slab test and the visit bounds. Every
// constant (OCAP, EMAX, …, TWO_M*) comes from the Rust files through the generated
// interface.glsl. Its fp16 types and roundings are fp16.glsl's, the frames frames.glsl's.
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

#ifndef MATH_F32
// fp16 slab test in the node frame: (tn, tn_lb, tf_ub) (half.rs, slab16).
#ifdef FC_OFF
// fp16 product saturated to +-SAT, decided on the exact fp32 product (half.rs, mul_sat).
float16_t mul_sat(float16_t a, float16_t b) {
    precise float p = float(a) * float(b);
    if (p > SAT) return float16_t(SAT);
    if (p < -SAT) return float16_t(-SAT);
    precise float16_t q = a * b;
    return q;
}
#define HMUL(a, b) mul_sat(a, b)
#define UNB16 float16_t(SAT)
#else
#define HMUL(a, b) ((a) * (b))
#define UNB16 HINF
#endif

// The fp16 slab of one box, widened by w when `widen` (a constant at every call, so where it
// is false no 0 is added or subtracted: -0 + 0 is +0): (tn, tf). Unwidened, with float
// controls, the poster's test (f16h-poster's test_child).
void slab16_span(f16vec3 o, bool widen, float16_t w, f16vec3 lo, f16vec3 hi, out float16_t tn, out float16_t tf) {
    tn = -UNB16;
    tf = UNB16;
    for (int a = 0; a < 3; a++) {
        precise float16_t la = widen ? (lo[a] - o[a]) - w : lo[a] - o[a];
        precise float16_t ha = widen ? (hi[a] - o[a]) + w : hi[a] - o[a];
        float16_t t0, t1;
        if (lr_d16[a] == H0) {
            bool inside = la <= H0 && ha >= H0;
            t0 = inside ? -UNB16 : UNB16;
            t1 = inside ? UNB16 : -UNB16;
        } else {
            precise float16_t x = HMUL(la, lr_idir[a]);
            precise float16_t y = HMUL(ha, lr_idir[a]);
            t0 = min(x, y);
            t1 = max(x, y);
        }
        tn = max(tn, t0);
        tf = min(tf, t1);
    }
}

f16vec3 slab16(f16vec3 o, float16_t w, f16vec3 lo, f16vec3 hi) {
    float16_t tn, tf;
    slab16_span(o, true, w, lo, hi, tn, tf);
    const float16_t LO_DOWN = float16_t(1.0 - 1.0 / 256.0);
    const float16_t LO_UP = float16_t(1.0 + 1.0 / 256.0);
    precise float16_t tn_lb = tn * (tn > H0 ? LO_DOWN : LO_UP);
    precise float16_t tf_ub = tf * (tf > H0 ? LO_UP : LO_DOWN);
    return f16vec3(tn, tn_lb, tf_ub);
}
#endif

// The box test in the variant's math mode, as fp32 (tn, tn_lb, tf_ub) (half.rs, slab).
vec3 slab_math(OVEC o, HALF w, HVEC3 lo, HVEC3 hi) {
#if !defined(MATH_F32) && !defined(MATH_MIXED)
    return vec3(slab16(o, w, lo, hi));
#else
    // Unbounded: inf, or without float controls SAT (fp16 products) / BIG32 (fp32).
#if !defined(FC_OFF)
    const float UNB = INF;
#elif defined(MATH_MIXED)
    const float UNB = SAT;
#else
    const float UNB = BIG32;
#endif
    float tn = -UNB;
    float tf = UNB;
    for (int a = 0; a < 3; a++) {
        float t0, t1;
#ifdef MATH_MIXED
        precise float16_t la = (lo[a] - o[a]) - w;
        precise float16_t ha = (hi[a] - o[a]) + w;
        bool inside = la <= H0 && ha >= H0;
        precise float16_t x16 = HMUL(la, lr_idir[a]);
        precise float16_t y16 = HMUL(ha, lr_idir[a]);
        float x = float(x16);
        float y = float(y16);
#else
        float w32 = float(w);
        precise float la = (float(lo[a]) - o[a]) - w32;
        precise float ha = (float(hi[a]) - o[a]) + w32;
        bool inside = la <= 0.0 && ha >= 0.0;
        precise float x = la * lr_idir32[a];
        precise float y = ha * lr_idir32[a];
#endif
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
#endif
}

#if !defined(MATH_F32) && !defined(FC_OFF)
// Packed fp16 (f16vec2 lanes) for the builds with float controls and fp16 storage math.
#define HALF_PAIRS 1
// The fp16 origin move of f16h and f16h-poster: ea = o + s * d, ec = ea - c, the result ec * r,
// x and y on f16vec2 lanes (packed), z alone; per axis the scalar operations, rounded the same.
f16vec3 move16(f16vec3 o, float16_t s, f16vec3 c, float16_t r, out f16vec3 ea, out f16vec3 ec) {
    precise f16vec2 eaxy = o.xy + f16vec2(s) * lr_d16.xy;
    precise float16_t eaz = o.z + s * lr_d16.z;
    precise f16vec2 ecxy = eaxy - c.xy;
    precise float16_t ecz = eaz - c.z;
    precise f16vec2 oaxy = ecxy * f16vec2(r);
    precise float16_t oaz = ecz * r;
    ea = f16vec3(eaxy, eaz);
    ec = f16vec3(ecxy, ecz);
    return f16vec3(oaxy, oaz);
}

// The slab of two boxes on lanes (slab16_span's loop; lo[a], hi[a]: axis a of both boxes, box 0
// in x, box 1 in y), each widened by w2 when `widen` (as slab16_span): (tn, tf) per lane. The
// differences and products are fp16; min and max are SPAN2's: fp16, or fp32 in MATH_MIXED
// (slab_math's mixed path: its products converted, exactly, and its unbounded inf).
#ifdef MATH_MIXED
#define SPAN2 vec2
#define SPAN_UNB INF
#else
#define SPAN2 f16vec2
#define SPAN_UNB UNB16
#endif
void slab16x2_span(f16vec3 o, bool widen, f16vec2 w2, f16vec2 lo[3], f16vec2 hi[3], out SPAN2 tn, out SPAN2 tf) {
    tn = SPAN2(-SPAN_UNB);
    tf = SPAN2(SPAN_UNB);
    for (int a = 0; a < 3; a++) {
        f16vec2 o2 = f16vec2(o[a]);
        precise f16vec2 la = widen ? (lo[a] - o2) - w2 : lo[a] - o2;
        precise f16vec2 ha = widen ? (hi[a] - o2) + w2 : hi[a] - o2;
        SPAN2 t0, t1;
        if (lr_d16[a] == H0) {
            // la <= 0 && ha >= 0, one comparison a lane: max(la, -ha) <= 0 (exact).
            bvec2 inside = lessThanEqual(max(la, -ha), f16vec2(H0));
            t0 = mix(SPAN2(SPAN_UNB), SPAN2(-SPAN_UNB), inside);
            t1 = -t0;
        } else {
            f16vec2 id = f16vec2(lr_idir[a]);
            precise f16vec2 x16 = la * id;
            precise f16vec2 y16 = ha * id;
            SPAN2 x = SPAN2(x16);
            SPAN2 y = SPAN2(y16);
            t0 = min(x, y);
            t1 = max(x, y);
        }
        tn = max(tn, t0);
        tf = min(tf, t1);
    }
}

// Two box tests at once (two children of a node), on f16vec2 lanes: the operations of slab16
// (MATH_F16) or of slab_math's mixed path (fp16 differences and products, fp32 min/max), each
// lane rounded exactly as the scalar test rounds it, so a GPU compiler can pack the fp16 ones
// two to a register (v_pk_* on AMD, HFMA2/HMNMX2 on NVIDIA) and both results equal two scalar
// tests bit for bit (min and max are exact). Returns (tn, tn_lb, tf_ub) per lane as fp32.
// lo[a], hi[a]: axis a of both boxes (box 0 in x, box 1 in y).
void slab16x2(OVEC o, HALF w, f16vec2 lo[3], f16vec2 hi[3], out vec2 tn, out vec2 tn_lb, out vec2 tf_ub) {
    SPAN2 tn2, tf2;
    slab16x2_span(o, true, f16vec2(w), lo, hi, tn2, tf2);
#ifdef MATH_MIXED
    // fp32 bounds (slab_math's mixed path).
    tn = tn2;
    precise vec2 lb = tn2 * mix(vec2(1.0 + 1.0 / 256.0), vec2(1.0 - 1.0 / 256.0), greaterThan(tn2, vec2(0.0)));
    precise vec2 ub = tf2 * mix(vec2(1.0 - 1.0 / 256.0), vec2(1.0 + 1.0 / 256.0), greaterThan(tf2, vec2(0.0)));
    tn_lb = lb;
    tf_ub = ub;
#else
    // x * (x > 0 ? down : up) with the factor chosen by x's sign bit, both lanes in one 32-bit
    // integer operation: the same product, as a zero's factor does not matter (±0 either way)
    // and no NaN occurs (half.rs, slab16).
    const uint DOWN2 = 0x3bf83bf8u;                 // fp16(1 - 1/256) in both halves
    const uint FLIP2 = 0x3bf83bf8u ^ 0x3c043c04u; // to fp16(1 + 1/256)
    uint sn = (packFloat2x16(tn2) >> 15) & 0x00010001u;
    uint sf = (packFloat2x16(tf2) >> 15) & 0x00010001u;
    precise f16vec2 lb = tn2 * unpackFloat2x16(DOWN2 ^ (sn * 0xffffu & FLIP2));
    precise f16vec2 ub = tf2 * unpackFloat2x16(DOWN2 ^ ((sf ^ 0x00010001u) * 0xffffu & FLIP2));
    tn = vec2(tn2);
    tn_lb = vec2(lb);
    tf_ub = vec2(ub);
#endif
}
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
