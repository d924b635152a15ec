// The fp16 slab test in the node frame of the math modes that compute in fp16 (f16 and mixed:
// half_f16.glsl, half_mixed.glsl include it), mirroring src/layout/half: the saturated product
// without float controls, the slab of one box and its widened bounds.
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
