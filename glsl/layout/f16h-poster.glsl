// Layout f16h-poster hooks (src/layout/f16h_poster): the poster's algorithm as written, on the
// nodes and frames of f16h (node16.glsl, derive_child): the origin moved to the hit child's
// entry point and converted to the child frame in fp16, box tests in fp16 without widening,
// no error bound, no re-anchoring. Not conservative: its own CPU reference is its oracle and
// its disagreements with f32 are reported. A moved origin that overflows fp16 is clamped to
// +-65504 (NaN to 0), which the poster does not specify, so that no NaN enters a box test.
//
// Stack Entry (generated): wk = the node's frame (w.xyz, k; k = 0: inactive), o = the origin
// in the node's frame (fp16), tp = the world parameter o stands for.
#include "half.glsl"
#include "node16.glsl"

Entry root_entry(RayPre r, float near_t) {
    OVEC o;
    anchor(r, pc.root.xyz, pc.root.w, near_t, o);
    return Entry(pc.root, o, near_t);
}
Entry no_entry() { return Entry(vec4(0.0), f16vec3(0.0), 0.0); }
bool has_entry(Entry en) { return en.wk.w > 0.0; }
float entry_t(Entry en) { return en.tp; }

struct Visit { float mk; float16_t s_lim; };

Visit visit_node(uint ni, Entry en, RayPre r, float best) {
    precise float mk = lr_m * en.wk.w;
    precise float lim = (best - en.tp) * mk;
    return Visit(mk, float16_t(lim));
}

// The child's entry parameter, and its box (read once: child_entry derives the frame from it).
struct ChildHit { float16_t tn; f16vec3 lo; f16vec3 hi; };

bool test_child(uint ni, uint s, Entry en, Visit v, RayPre r, out float key, out ChildHit h) {
    f16vec3 lo = slot_lo(ni, s);
    f16vec3 hi = slot_hi(ni, s);
    // Not widened, with float controls (HMUL a plain product, UNB16 inf): the poster's test.
    float16_t tn, tf;
    slab16_span(en.o, false, H0, lo, hi, tn, tf);
    key = float(tn);
    h = ChildHit(tn, lo, hi);
    return tn <= tf && tf >= H0 && tn <= v.s_lim;
}

// Children s and s + 1 tested together on f16vec2 lanes (packed fp16; trav.comp's TEST_PAIRS
// loop): lane by lane the operations of test_child, so the same results bit for bit.
#define TEST_PAIRS 1
bvec2 test_pair(uint ni, uint s, Entry en, Visit v, RayPre r, out vec2 key, out ChildHit h0, out ChildHit h1) {
    f16vec2 lo[3], hi[3];
    pair_boxes(ni, s, lo, hi, h0.lo, h0.hi, h1.lo, h1.hi);
    // Not widened: the poster's test.
    f16vec2 tn, tf;
    slab16x2_span(en.o, false, f16vec2(H0), lo, hi, tn, tf);
    key = vec2(tn);
    h0.tn = tn.x;
    h1.tn = tn.y;
    // tn <= tf && tf >= 0 && tn <= s_lim, two comparisons a lane (max is exact).
    bvec2 a = lessThanEqual(max(tn, f16vec2(H0)), tf);
    bvec2 b = lessThanEqual(tn, f16vec2(v.s_lim));
    return bvec2(a.x && b.x, a.y && b.y);
}

float16_t finite16(float16_t x) { return isnan(x) ? H0 : clamp(x, float16_t(-F16_MAX), float16_t(F16_MAX)); }

Entry child_entry(uint ni, uint s, Entry en, Visit v, ChildHit h, RayPre r, inout uint reanchors) {
    HVEC3 cc; float cr; vec3 cw; float ck;
    derive_child(en.wk.xyz, en.wk.w, h.lo, h.hi, cc, cr, cw, ck);
    float16_t se = max(h.tn, H0);
    float16_t r16 = float16_t(cr);
    f16vec3 ea, ec;
    f16vec3 oa = move16(en.o, se, cc, r16, ea, ec);
    // finite16 of x and y on lanes: the clamp packed, NaN (compared a lane) to 0.
    f16vec2 cxy = clamp(oa.xy, f16vec2(-F16_MAX), f16vec2(F16_MAX));
    f16vec3 o2 = f16vec3(mix(cxy, f16vec2(H0), isnan(oa.xy)), finite16(oa.z));
    precise float step_t = float(se) / v.mk;
    precise float tp = en.tp + step_t;
    return Entry(vec4(cw, ck), o2, tp);
}
