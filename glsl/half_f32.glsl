// fp32 math (MATH_F32): fp16 boxes and directions, fp32 differences, products and bounds. The
// box test of this math mode (slab_math), chosen by half.glsl's one #if.

// The box test in the variant's math mode, as fp32 (tn, tn_lb, tf_ub) (half.rs, slab).
vec3 slab_math(OVEC o, HALF w, HVEC3 lo, HVEC3 hi) {
    // Unbounded: inf, or without float controls BIG32 (fp32 products).
#ifdef FC_OFF
    const float UNB = BIG32;
#else
    const float UNB = INF;
#endif
    float tn = -UNB;
    float tf = UNB;
    for (int a = 0; a < 3; a++) {
        float t0, t1;
        float w32 = float(w);
        precise float la = (float(lo[a]) - o[a]) - w32;
        precise float ha = (float(hi[a]) - o[a]) + w32;
        bool inside = la <= 0.0 && ha >= 0.0;
        precise float x = la * lr_idir32[a];
        precise float y = ha * lr_idir32[a];
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

