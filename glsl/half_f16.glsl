// fp16 math (the default): everything in fp16. The box test of this math mode (slab_math) and,
// with float controls, two boxes at once on packed lanes (slab16x2), chosen by half.glsl's one
// #if.
#include "half16.glsl"

// The box test in the variant's math mode, as fp32 (tn, tn_lb, tf_ub) (half.rs, slab).
vec3 slab_math(OVEC o, HALF w, HVEC3 lo, HVEC3 hi) {
    return vec3(slab16(o, w, lo, hi));
}

#ifndef FC_OFF
#define HALF_PAIRS 1
#define SPAN2 f16vec2
#define SPAN_UNB UNB16
#include "half_pairs.glsl"

// Two box tests at once (two children of a node), on f16vec2 lanes: the operations of slab16,
// each lane rounded exactly as the scalar test rounds it, so a GPU compiler can pack the fp16 ones
// two to a register (v_pk_* on AMD, HFMA2/HMNMX2 on NVIDIA) and both results equal two scalar
// tests bit for bit (min and max are exact). Returns (tn, tn_lb, tf_ub) per lane as fp32.
// lo[a], hi[a]: axis a of both boxes (box 0 in x, box 1 in y).
void slab16x2(OVEC o, HALF w, f16vec2 lo[3], f16vec2 hi[3], out vec2 tn, out vec2 tn_lb, out vec2 tf_ub) {
    SPAN2 tn2, tf2;
    slab16x2_span(o, true, f16vec2(w), lo, hi, tn2, tf2);
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
}
#endif
