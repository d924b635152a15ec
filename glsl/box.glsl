// Conservative box tests: fp32 world-space slabs (Ize 2013) and the f16h fp16 slab test.
// Mirror src/trace/mod.rs (slab32) and src/trace/f16h.rs (slab16, up/down rounding).
// No NaN is ever formed: zero direction components get an explicit inside test.

float lower32(float t) {
    precise float r = t * (t > 0.0 ? (1.0 - 1.0 / 1048576.0) : (1.0 + 1.0 / 1048576.0));
    return r;
}
float upper32(float t) {
    precise float r = t * (t > 0.0 ? (1.0 + 1.0 / 1048576.0) : (1.0 - 1.0 / 1048576.0));
    return r;
}

// Returns (near, far); hit when near <= far.
vec2 slab32(RayPre r, vec3 lo, vec3 hi, float t0, float t1) {
    float near_t = t0;
    float far_t = t1;
    for (int a = 0; a < 3; a++) {
        float n, f;
        if (r.d[a] == 0.0) {
            bool inside = r.o[a] >= lo[a] && r.o[a] <= hi[a];
            n = inside ? -INF : INF;
            f = inside ? INF : -INF;
        } else {
            precise float x = (lo[a] - r.o[a]) * r.inv[a];
            precise float y = (hi[a] - r.o[a]) * r.inv[a];
            n = lower32(min(x, y));
            f = upper32(max(x, y));
        }
        near_t = max(near_t, n);
        far_t = min(far_t, f);
    }
    return vec2(near_t, far_t);
}

#ifdef F16H
#define HINF float16_t(uintBitsToFloat(0x7f800000u))
const float16_t H0 = float16_t(0.0);

// An fp16 value >= x with one round-to-nearest conversion (fp16::up_f32).
float16_t up16(float x) {
    precise float y = x + abs(x) * (1.0 / 1024.0) + (1.0 / 16777216.0);
    return y > 65504.0 ? HINF : float16_t(y);
}
float16_t down16(float x) { return -up16(-x); }
float up32(float x) { return isinf(x) ? x : upper32(x); }

// fp16 slab test in the node frame: (tn, tn_lb, tf_ub).
f16vec3 slab16(f16vec3 o, f16vec3 d16, f16vec3 idir, float16_t w, f16vec3 lo, f16vec3 hi) {
    float16_t tn = -HINF;
    float16_t tf = HINF;
    for (int a = 0; a < 3; a++) {
        precise float16_t la = (lo[a] - o[a]) - w;
        precise float16_t ha = (hi[a] - o[a]) + w;
        float16_t t0, t1;
        if (d16[a] == H0) {
            bool inside = la <= H0 && ha >= H0;
            t0 = inside ? -HINF : HINF;
            t1 = inside ? HINF : -HINF;
        } else {
            precise float16_t x = la * idir[a];
            precise float16_t y = ha * idir[a];
            t0 = min(x, y);
            t1 = max(x, y);
        }
        tn = max(tn, t0);
        tf = min(tf, t1);
    }
    const float16_t LO_DOWN = float16_t(1.0 - 1.0 / 256.0);
    const float16_t LO_UP = float16_t(1.0 + 1.0 / 256.0);
    precise float16_t tn_lb = tn * (tn > H0 ? LO_DOWN : LO_UP);
    precise float16_t tf_ub = tf * (tf > H0 ? LO_UP : LO_DOWN);
    return f16vec3(tn, tn_lb, tf_ub);
}

// Origin type: fp32 in the fp32 math mode, fp16 otherwise.
#ifdef MATH_F32
#define OVEC vec3
#define OCONV(x) (x)
#else
#define OVEC f16vec3
#define OCONV(x) float16_t(x)
#endif

// The box test in the variant's math mode, as fp32 (tn, tn_lb, tf_ub) (src/trace/f16h.rs, slab).
vec3 slab_math(OVEC o, f16vec3 d16, f16vec3 idir, vec3 idir32, float16_t w, f16vec3 lo, f16vec3 hi) {
#if !defined(MATH_F32) && !defined(MATH_MIXED)
    return vec3(slab16(o, d16, idir, w, lo, hi));
#else
    float tn = -INF;
    float tf = INF;
    for (int a = 0; a < 3; a++) {
        float t0, t1;
#ifdef MATH_MIXED
        precise float16_t la = (lo[a] - o[a]) - w;
        precise float16_t ha = (hi[a] - o[a]) + w;
        bool inside = la <= H0 && ha >= H0;
        precise float16_t x16 = la * idir[a];
        precise float16_t y16 = ha * idir[a];
        float x = float(x16);
        float y = float(y16);
#else
        float w32 = float(w);
        precise float la = (float(lo[a]) - o[a]) - w32;
        precise float ha = (float(hi[a]) - o[a]) + w32;
        bool inside = la <= 0.0 && ha >= 0.0;
        precise float x = la * idir32[a];
        precise float y = ha * idir32[a];
#endif
        if (d16[a] == H0) {
            t0 = inside ? -INF : INF;
            t1 = inside ? INF : -INF;
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
#endif
