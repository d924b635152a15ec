// Chained frames, mirroring src/layout/frames.rs: a child's uniformly scaled frame derived from
// its stored fp16 box, bit for bit as the encoder derived it (f16h, f16h-poster). Its
// constants (K_MIN_LOG2, K_MAX_LOG2, TWO_M20, TWO_M22) come from interface.glsl.

// Child frame from its stored box: centre c (fp16), ratio r, world origin w, scale k
// (frame.rs, derive_child).
void derive_child(vec3 pw, float pk, HVEC3 lo, HVEC3 hi, out HVEC3 c, out float r, out vec3 w, out float k) {
    c = HVEC3(0.0);
    w = vec3(0.0);
    precise float h = 0.0;
#ifdef FC_OFF
    // pk is a power of two: its reciprocal from the exponent bits, exactly.
    float inv_k = pow2(1 - frexp_exp(pk));
#else
    precise float inv_k = 1.0 / pk;
#endif
    float wmax = 0.0;
#if !defined(FC_OFF) && !defined(MATH_F32)
    // The centre's fp16 (lo + hi) * 0.5: x and y on f16vec2 lanes (packed), z alone.
    precise f16vec2 cxy = (lo.xy + hi.xy) * f16vec2(0.5);
    precise float16_t cz = (lo.z + hi.z) * float16_t(0.5);
    f16vec3 c3 = f16vec3(cxy, cz);
#endif
    for (int a = 0; a < 3; a++) {
        float l = float(lo[a]);
        float u = float(hi[a]);
#ifdef FC_OFF
        // The same roundings as the fp16 (lo + hi) * 0.5, emulated (see the MATH_F32 case);
        // products by powers of two are exact on any device.
        float ch = rte16(rte16(add_rte(l, u)) * 0.5);
        c[a] = HALF(ch);
        float cf = ch;
        h = max(max(h, add_rte(u, -cf)), add_rte(cf, -l));
        float wa = add_rte(pw[a], cf * inv_k);
        w[a] = wa;
        wmax = max(wmax, abs(wa));
    }
    float m = add_rte(add_rte(h, h * TWO_M20), (wmax * pk) * TWO_M22);
#else
#ifdef MATH_F32
        // fp16's (lo + hi) * 0.5, each operation rounded to fp16: the fp32 sum of two fp16
        // values is either exact or off by less than fp16's distance to the nearest midpoint
        // (the smaller operand then lies below 2^-12 of the larger), so rounding it to fp16
        // gives the fp16 sum.
        precise float s16 = lo[a] + hi[a];
        precise float hs = rte16(s16) * 0.5;
        float ch = rte16(hs);
#else
        // fp16 arithmetic (c3): compilers may fold an f32->f16->f32 round trip away.
        float16_t ch = c3[a];
#endif
        c[a] = ch;
        float cf = float(ch);
        precise float du = u - cf;
        precise float dl = cf - l;
        h = max(max(h, du), dl);
        precise float wa = pw[a] + cf * inv_k;
        w[a] = wa;
        wmax = max(wmax, abs(wa));
    }
    precise float m = (h + h * TWO_M20) + (wmax * pk) * TWO_M22;
#endif
    int pl = frexp_exp(pk) - 1;
    int j = clamp(14 - frexp_exp(m), K_MIN_LOG2 - pl, K_MAX_LOG2 - pl);
    r = pow2(j);
    precise float kk = pk * r;
    k = kk;
}
