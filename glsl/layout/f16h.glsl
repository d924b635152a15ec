// Layout f16h hooks (src/layout/f16h): fp16 child boxes in the parent's frame, frames derived
// from the stored boxes, box tests and origin moves in the variant's math (MATH_F16: the poster's,
// MATH_F32, MATH_MIXED) with a carried error bound, re-anchored from the fp32 world ray when
// it grows too large. Mirrors src/layout/f16h/hooks.rs operation for operation (the box test
// and frames: half.glsl); the bound is argued in src/layout/half.rs and hooks.rs. Every
// constant comes from interface.glsl (generated from the Rust ones). FC_OFF: the build for
// devices without float controls (hooks.rs, "Without float controls"; the box test's margins:
// half.rs): conversions to fp16 and the frame's fp32 additions emulated with integer
// operations, products saturated instead of overflowing, no inf or NaN anywhere, every
// rounding allowed a full ulp.
//
// Stack Entry (generated): wk = the node's frame (w.xyz, k), o = the origin in the node's
// frame (OVEC), e = its error bound (-1: inactive), tp = the world parameter o stands for,
// tlo = a lower bound on the world parameter of anything that can still matter.
#include "half.glsl"
#include "node16.glsl"

Entry root_entry(RayPre r, float near_t) {
    OVEC o;
    float e = anchor(r, pc.root.xyz, pc.root.w, near_t, o);
    return Entry(pc.root, o, e, near_t, near_t);
}
Entry no_entry() { return Entry(vec4(0.0), OVEC(0.0), -1.0, 0.0, 0.0); }
bool has_entry(Entry en) { return en.e >= 0.0; }
float entry_t(Entry en) { return en.tlo; }

#define Visit HVisit
Visit visit_node(uint ni, Entry en, RayPre r, float best) { return half_visit(en.wk.w, en.e, en.tp, en.tlo, best); }

// The child's entry parameter and its lower bound in the node's frame, and its box (read
// once: child_entry derives the child's frame from it).
struct ChildHit { float tn; float tn_lb; HVEC3 lo; HVEC3 hi; };

bool test_child(uint ni, uint s, Entry en, Visit v, RayPre r, out float key, out ChildHit h) {
    h.lo = slot_lo(ni, s);
    h.hi = slot_hi(ni, s);
    bool hit = half_test(en.o, v, h.lo, h.hi, h.tn, h.tn_lb);
    key = h.tn;
    return hit;
}

#ifdef HALF_PAIRS
// Children s and s + 1 tested together (half_test2; trav.comp's TEST_PAIRS loop).
#define TEST_PAIRS 1
bvec2 test_pair(uint ni, uint s, Entry en, Visit v, RayPre r, out vec2 key, out ChildHit h0, out ChildHit h1) {
    f16vec2 lo[3], hi[3];
    pair_boxes(ni, s, lo, hi, h0.lo, h0.hi, h1.lo, h1.hi);
    vec2 tn, tn_lb;
    bvec2 hit = half_test2(en.o, v, lo, hi, tn, tn_lb);
    h0.tn = tn.x;
    h0.tn_lb = tn_lb.x;
    h1.tn = tn.y;
    h1.tn_lb = tn_lb.y;
    key = tn;
    return hit;
}
#endif

// The stack entry of a hit inner child (hooks.rs, child_entry): its frame, and the origin
// moved into it in fp16, or re-anchored from the fp32 world ray when the bound grows too large
// (counted in `reanchors`).
Entry child_entry(uint ni, uint s, Entry en, Visit v, ChildHit h, RayPre r, inout uint reanchors) {
    HVEC3 lo = h.lo;
    HVEC3 hi = h.hi;
    vec3 fw = en.wk.xyz;
    float fk = en.wk.w;
    HVEC3 cc; float cr; vec3 cw; float ck;
    derive_child(fw, fk, lo, hi, cc, cr, cw, ck);
    float lower = float(v.lower);
    float tlo_c = half_child_tlo(v, en.tp, en.tlo, h.tn_lb);
    float se = max(h.tn, lower);
    OVEC o2 = OVEC(0.0);
    bool fits = true;
#if defined(FC_OFF) && !defined(MATH_F32)
    // The fp16 origin move must not overflow (hooks.rs): else re-anchor.
    float om = max(max(abs(float(en.o.x)), abs(float(en.o.y))), abs(float(en.o.z)));
    float cm = max(max(abs(float(cc.x)), abs(float(cc.y))), abs(float(cc.z)));
    fits = om + abs(se) + cm <= MOVE_LIMIT;
#endif
    if (v.prec && cr <= R_MAX && fits) {
        // in_cap: every |o2| <= OCAP, so finite (ordered comparisons are false for NaN): the
        // same as hooks.rs's `finite && omag <= OCAP`, one comparison an axis.
        float emag = 0.0, ecmag = 0.0;
        bool in_cap = true;
#if !defined(MATH_F32) && !defined(FC_OFF)
        // The move (half.glsl, move16): per axis the operations of the loop below.
        f16vec3 ea3, ec3;
        o2 = move16(en.o, TO_HALF(se), cc, float16_t(cr), ea3, ec3);
        for (int a = 0; a < 3; a++) {
            emag = max(emag, abs(float(ea3[a])));
            ecmag = max(ecmag, abs(float(ec3[a])));
            in_cap = in_cap && abs(float(o2[a])) <= OCAP;
        }
#else
        for (int a = 0; a < 3; a++) {
#ifdef MATH_F32
            precise float ea = en.o[a] + se * float(lr_d16[a]);
            precise float ec = ea - float(cc[a]);
            precise float oa = ec * cr;
#else
            float16_t s_e = TO_HALF(se);
            float16_t r16c = float16_t(cr);
            precise float16_t ea = en.o[a] + s_e * lr_d16[a];
            precise float16_t ec = ea - cc[a];
#ifdef FC_OFF
            precise float ecr = abs(float(ec)) * cr;
            bool big = ecr > OCAP;
            float16_t oa = H0;
            if (!big) {
                precise float16_t op = ec * r16c;
                oa = op;
            }
            in_cap = in_cap && !big;
#else
            precise float16_t oa = ec * r16c;
#endif
#endif
            o2[a] = oa;
            emag = max(emag, abs(float(ea)));
            ecmag = max(ecmag, abs(float(ec)));
            in_cap = in_cap && abs(float(oa)) <= OCAP;
        }
#endif
        precise float step_t = se / v.mk;
        precise float tpn = en.tp + step_t;
        float wmax = max(max(max(0.0, abs(cw.x)), abs(cw.y)), abs(cw.z));
        precise float mk2 = lr_m * ck;
#ifdef FC_OFF
        precise float ee = (cr * (en.e + abs(se) * TWO_M9 + TWO_M10 * (emag + ecmag) + TWO_M22)
            + wmax * TWO_M24 * ck
            + (abs(en.tp) + abs(step_t)) * TWO_M20 * mk2)
            * (1.0 + TWO_M18);
#else
        precise float ee = (cr * (en.e + abs(se) * TWO_M10 + TWO_M11 * (emag + ecmag) + TWO_M23)
            + wmax * TWO_M24 * ck
            + (abs(en.tp) + abs(step_t)) * TWO_M22 * mk2)
            * (1.0 + TWO_M18);
#endif
        if (in_cap && ee <= EMAX) {
            return Entry(vec4(cw, ck), o2, ee, tpn, tlo_c);
        }
    }
    reanchors++;
#ifdef FC_OFF
    float inv_k = pow2(1 - frexp_exp(fk));
#else
    precise float inv_k = 1.0 / fk;
#endif
    vec3 blo = vec3(0.0), bhi = vec3(0.0);
    for (int a = 0; a < 3; a++) {
        precise float bl = fw[a] + float(lo[a]) * inv_k;
        precise float bh = fw[a] + float(hi[a]) * inv_k;
        blo[a] = bl; bhi[a] = bh;
    }
    vec2 io = slab32(r, blo, bhi, -INF, INF);
    float tp2 = max(min(io.x, io.y), tlo_c);
    float e2 = anchor(r, cw, ck, tp2, o2);
    return Entry(vec4(cw, ck), o2, e2, tp2, tlo_c);
}
