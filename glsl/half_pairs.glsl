// Packed fp16 (f16vec2 lanes) for the builds with float controls in the math modes that
// compute in fp16: the origin move and the slab of two boxes, included by half_f16.glsl and
// half_mixed.glsl after they define SPAN2 and SPAN_UNB (the lanes' min/max type: fp16, or
// fp32 in mixed math); each mode's header then defines slab16x2 on it.
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

