// Layout f16h hooks (src/layout/f16h): fp16 child boxes in the parent's frame, frames derived
// from the stored boxes, box tests and origin moves in the variant's math (MATH_F16: the seed,
// MATH_F32, MATH_MIXED) with a carried error bound, re-anchored from the fp32 world ray when
// it grows too large. Mirrors src/layout/f16h/{frame,hooks}.rs operation for operation; the
// bound is argued in hooks.rs. The constants OCAP, EMAX, EBIG, W_MARGIN, D_FLUSH, K_MIN_LOG2
// and K_MAX_LOG2 come from interface.glsl (generated from the Rust ones).
//
// Stack Entry (generated): wk = the node's frame (w.xyz, k), o = the origin in the node's
// frame (OVEC), e = its error bound (-1: inactive), tp = the world parameter o stands for,
// tlo = a lower bound on the world parameter of anything that can still matter.
struct Node {
    float16_t lo[3 * B];   // lo[axis * B + slot], in the node's frame, rounded down
    float16_t hi[3 * B];
    uint child[B];
};
layout(std430, set = 0, binding = BINDING_NODES) readonly buffer Nodes { Node nodes[]; };

uint child_word(uint ni, uint s) { return nodes[ni].child[s]; }

// fp16 values: `float16_t` with fp16 arithmetic (MATH_F16, MATH_MIXED); in MATH_F32 they are
// held exactly in fp32 and the few fp16 roundings are emulated (rte16), so that mode uses 16-bit
// storage only and runs on devices without shaderFloat16. Every value and bound is the same.
#ifdef MATH_F32
#define HALF float
#define HVEC3 vec3
#define LOADH(x) float(x)
#define HINF INF
#define TO_HALF(x) rte16(x)
const float H0 = 0.0;
#else
#define HALF float16_t
#define HVEC3 f16vec3
#define LOADH(x) (x)
#define HINF float16_t(uintBitsToFloat(0x7f800000u))
#define TO_HALF(x) float16_t(x)
const float16_t H0 = float16_t(0.0);
#endif

HVEC3 slot_lo(uint ni, uint s) { return HVEC3(LOADH(nodes[ni].lo[s]), LOADH(nodes[ni].lo[B + s]), LOADH(nodes[ni].lo[2 * B + s])); }
HVEC3 slot_hi(uint ni, uint s) { return HVEC3(LOADH(nodes[ni].hi[s]), LOADH(nodes[ni].hi[B + s]), LOADH(nodes[ni].hi[2 * B + s])); }

void child_box(uint ni, uint s, out vec3 lo, out vec3 hi) {
    lo = vec3(slot_lo(ni, s));
    hi = vec3(slot_hi(ni, s));
}

const float S_BASE = 16384.0 + OCAP;
const float TWO_M10 = 1.0 / 1024.0;
const float TWO_M11 = 1.0 / 2048.0;
const float TWO_M18 = 1.0 / 262144.0;
const float TWO_M21 = 1.0 / 2097152.0;
const float TWO_M22 = 1.0 / 4194304.0;
const float TWO_M23 = 1.0 / 8388608.0;
const float TWO_M24 = 1.0 / 16777216.0;
// Origin type: fp32 in the fp32 math mode, fp16 otherwise (the Entry's `o` has the same type).
#ifdef MATH_F32
#define OVEC vec3
#define OCONV(x) (x)
#else
#define OVEC f16vec3
#define OCONV(x) float16_t(x)
#endif

int frexp_exp(float x) {
    int e = int((floatBitsToUint(x) >> 23) & 0xffu);
    return e == 0 ? -126 : e - 126;
}
float pow2(int e) { return uintBitsToFloat(uint(e + 127) << 23); }

// Round-to-nearest-even of x to fp16, returned exactly in fp32: integer operations on the
// bits and one exact power-of-two product, so it needs no fp16 arithmetic (fp16.rs,
// rte16_emulated, takes the same steps and is tested against the conversion for every fp16
// value, midpoint and neighbour).
float rte16(float x) {
    uint u = floatBitsToUint(x);
    uint sgn = u & 0x80000000u;
    uint a = u & 0x7fffffffu;
    if (a >= 0x7f800000u) return x;                                   // inf, NaN
    if (a >= 0x477ff000u) return uintBitsToFloat(sgn | 0x7f800000u);  // >= 65520 rounds to inf
    int e = int(a >> 23) - 127;
    if (e < -25) return uintBitsToFloat(sgn);                         // below half of 2^-24
    uint m = (a & 0x7fffffu) | 0x800000u;                             // x = m * 2^(e - 23)
    int lsb = max(e - 10, -24);                                       // fp16's last place
    uint sh = uint(lsb - (e - 23));                                   // 13..24
    uint q = m >> sh;
    uint rem = m & ((1u << sh) - 1u);
    uint halfway = 1u << (sh - 1u);
    if (rem > halfway || (rem == halfway && (q & 1u) == 1u)) q++;
    precise float r = float(q) * pow2(lsb);
    return uintBitsToFloat(floatBitsToUint(r) | sgn);
}

// An fp16 value >= x with one round-to-nearest conversion (fp16::up_f32).
HALF up16(float x) {
    precise float y = x + abs(x) * (1.0 / 1024.0) + (1.0 / 16777216.0);
    return y > 65504.0 ? HINF : TO_HALF(y);
}
HALF down16(float x) { return -up16(-x); }
float up32(float x) { return isinf(x) ? x : upper32(x); }

// Child frame from its stored box: centre c (fp16), ratio r, world origin w, scale k
// (frame.rs, derive_child).
void derive_child(vec3 pw, float pk, HVEC3 lo, HVEC3 hi, out HVEC3 c, out float r, out vec3 w, out float k) {
    precise float h = 0.0;
    precise float inv_k = 1.0 / pk;
    float wmax = 0.0;
    for (int a = 0; a < 3; a++) {
        float l = float(lo[a]);
        float u = float(hi[a]);
#ifdef MATH_F32
        // fp16's (lo + hi) * 0.5, each operation rounded to fp16: the fp32 sum of two fp16
        // values is either exact or off by less than fp16's distance to the nearest midpoint
        // (the smaller operand then lies below 2^-12 of the larger), so rounding it to fp16
        // gives the fp16 sum.
        precise float s16 = lo[a] + hi[a];
        precise float hs = rte16(s16) * 0.5;
        float ch = rte16(hs);
#else
        // fp16 arithmetic: compilers may fold an f32->f16->f32 round trip away.
        precise float16_t ch = (lo[a] + hi[a]) * float16_t(0.5);
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
    precise float m = (h + h * (1.0 / 1048576.0)) + (wmax * pk) * (1.0 / 4194304.0);
    int pl = frexp_exp(pk) - 1;
    int j = clamp(14 - frexp_exp(m), K_MIN_LOG2 - pl, K_MAX_LOG2 - pl);
    r = pow2(j);
    precise float kk = pk * r;
    k = kk;
}

// Origin at world parameter t in frame (w, k), fp32 then fp16, clamped to +-OCAP; returns the
// error bound (hooks.rs, anchor).
float anchor(RayPre r, vec3 w, float k, float t, out OVEC o) {
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
    precise float e = (mag * k * TWO_M23 + clampd + lmax * TWO_M11 + TWO_M24) * (1.0 + TWO_M18);
    return e;
}

// Per-ray constants (hooks.rs, Ray16): m = max|D|, d16 = fp16(D / m), its fp16 and fp32
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
#ifndef MATH_F32
        precise float16_t inv = float16_t(1.0) / lr_d16[a];
        lr_idir[a] = lr_d16[a] == H0 ? HINF : inv;
#endif
        precise float inv32 = 1.0 / float(lr_d16[a]);
        lr_idir32[a] = lr_d16[a] == H0 ? INF : inv32;
    }
}

Entry root_entry(RayPre r, float near_t) {
    OVEC o;
    float e = anchor(r, pc.root.xyz, pc.root.w, near_t, o);
    return Entry(pc.root, o, e, near_t, near_t);
}
Entry no_entry() { return Entry(vec4(0.0), OVEC(0.0), -1.0, 0.0, 0.0); }
bool has_entry(Entry en) { return en.e >= 0.0; }
float entry_t(Entry en) { return en.tlo; }

#ifndef MATH_F32
// fp16 slab test in the node frame: (tn, tn_lb, tf_ub) (hooks.rs, slab16).
f16vec3 slab16(f16vec3 o, float16_t w, f16vec3 lo, f16vec3 hi) {
    float16_t tn = -HINF;
    float16_t tf = HINF;
    for (int a = 0; a < 3; a++) {
        precise float16_t la = (lo[a] - o[a]) - w;
        precise float16_t ha = (hi[a] - o[a]) + w;
        float16_t t0, t1;
        if (lr_d16[a] == H0) {
            bool inside = la <= H0 && ha >= H0;
            t0 = inside ? -HINF : HINF;
            t1 = inside ? HINF : -HINF;
        } else {
            precise float16_t x = la * lr_idir[a];
            precise float16_t y = ha * lr_idir[a];
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
#endif

// The box test in the variant's math mode, as fp32 (tn, tn_lb, tf_ub) (hooks.rs, slab).
vec3 slab_math(OVEC o, HALF w, HVEC3 lo, HVEC3 hi) {
#if !defined(MATH_F32) && !defined(MATH_MIXED)
    return vec3(slab16(o, w, lo, hi));
#else
    float tn = -INF;
    float tf = INF;
    for (int a = 0; a < 3; a++) {
        float t0, t1;
#ifdef MATH_MIXED
        precise float16_t la = (lo[a] - o[a]) - w;
        precise float16_t ha = (hi[a] - o[a]) + w;
        bool inside = la <= H0 && ha >= H0;
        precise float16_t x16 = la * lr_idir[a];
        precise float16_t y16 = ha * lr_idir[a];
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

// Quantities fixed for one visit of one node by one ray (hooks.rs, visit).
struct Visit {
    float mk;
    HALF s_lim;
    HALF lower;
    bool prec;
    HALF w;
};

Visit visit_node(Entry en, float best) {
    Visit v;
    precise float mk = lr_m * en.wk.w;
    precise float s_max = S_BASE + en.e + 1.0;
    precise float lim = (best - en.tp) * mk;
    v.s_lim = up16(min(up32(lim), s_max));
    precise float sg = (en.tp - en.tlo) * mk;
    float sigma = up32(sg);
    v.lower = down16(max(-sigma, -s_max));
    v.prec = en.e <= EBIG;
    precise float we = en.e + en.e * TWO_M11 + W_MARGIN;
    v.w = up16(we);
    v.mk = mk;
    return v;
}

// The child's entry parameter and its lower bound in the node's frame.
struct ChildHit { float tn; float tn_lb; };

bool test_child(uint ni, uint s, Entry en, Visit v, RayPre r, out float key, out ChildHit h) {
    if (!v.prec) {
        key = float(v.lower);
        h = ChildHit(float(v.lower), float(v.lower));
        return true;
    }
    vec3 q = slab_math(en.o, v.w, slot_lo(ni, s), slot_hi(ni, s));
    key = q.x;
    h = ChildHit(q.x, q.y);
    return q.y <= q.z && q.z >= float(v.lower) && q.y <= float(v.s_lim);
}

// The stack entry of a hit inner child (hooks.rs, child_entry): its frame, and the origin
// moved into it in fp16, or re-anchored from the fp32 world ray when the bound grows too large
// (counted in `reanchors`).
Entry child_entry(uint ni, uint s, Entry en, Visit v, ChildHit h, RayPre r, inout uint reanchors) {
    HVEC3 lo = slot_lo(ni, s);
    HVEC3 hi = slot_hi(ni, s);
    vec3 fw = en.wk.xyz;
    float fk = en.wk.w;
    HVEC3 cc; float cr; vec3 cw; float ck;
    derive_child(fw, fk, lo, hi, cc, cr, cw, ck);
    float lower = float(v.lower);
    float s_lo = max(h.tn_lb, lower);
    precise float q = s_lo / v.mk;
    precise float tlo_c0 = (en.tp + q) - (abs(en.tp) + abs(q)) * TWO_M21;
    float tlo_c = max(tlo_c0, en.tlo);
    float se = max(h.tn, lower);
    OVEC o2;
    if (v.prec && cr <= 32768.0) {
        float emag = 0.0, ecmag = 0.0, omag = 0.0;
        bool finite = true;
        for (int a = 0; a < 3; a++) {
#ifdef MATH_F32
            precise float ea = en.o[a] + se * float(lr_d16[a]);
            precise float ec = ea - float(cc[a]);
            precise float oa = ec * cr;
#else
            float16_t s_e = float16_t(se);
            float16_t r16c = float16_t(cr);
            precise float16_t ea = en.o[a] + s_e * lr_d16[a];
            precise float16_t ec = ea - cc[a];
            precise float16_t oa = ec * r16c;
#endif
            o2[a] = oa;
            emag = max(emag, abs(float(ea)));
            ecmag = max(ecmag, abs(float(ec)));
            omag = max(omag, abs(float(oa)));
            finite = finite && !isinf(oa) && !isnan(oa);
        }
        precise float step_t = se / v.mk;
        precise float tpn = en.tp + step_t;
        float wmax = max(max(max(0.0, abs(cw.x)), abs(cw.y)), abs(cw.z));
        precise float mk2 = lr_m * ck;
        precise float ee = (cr * (en.e + abs(se) * TWO_M10 + TWO_M11 * (emag + ecmag) + TWO_M23)
            + wmax * TWO_M24 * ck
            + (abs(en.tp) + abs(step_t)) * TWO_M22 * mk2)
            * (1.0 + TWO_M18);
        if (finite && omag <= OCAP && ee <= EMAX) {
            return Entry(vec4(cw, ck), o2, ee, tpn, tlo_c);
        }
    }
    reanchors++;
    precise float inv_k = 1.0 / fk;
    vec3 blo, bhi;
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
