// f16h frames: child-frame derivation and origin anchoring.
// Mirrors src/encode/f16h.rs (derive_child) and src/trace/f16h.rs (anchor) exactly.

const float OCAP = 20480.0;
const float EMAX = 2048.0;
const float EBIG = 16384.0;
const float W_MARGIN = 44.0;
const float S_BASE = 16384.0 + OCAP;
const float TWO_M10 = 1.0 / 1024.0;
const float TWO_M11 = 1.0 / 2048.0;
const float TWO_M18 = 1.0 / 262144.0;
const float TWO_M21 = 1.0 / 2097152.0;
const float TWO_M22 = 1.0 / 4194304.0;
const float TWO_M23 = 1.0 / 8388608.0;
const float TWO_M24 = 1.0 / 16777216.0;
const int K_MIN_LOG2 = -60;
const int K_MAX_LOG2 = 60;

int frexp_exp(float x) {
    int e = int((floatBitsToUint(x) >> 23) & 0xffu);
    return e == 0 ? -126 : e - 126;
}
float pow2(int e) { return uintBitsToFloat(uint(e + 127) << 23); }

// Child frame from its stored box: centre c (fp16), ratio r, world origin w, scale k.
void derive_child(vec3 pw, float pk, f16vec3 lo, f16vec3 hi, out f16vec3 c, out float r, out vec3 w, out float k) {
    precise float h = 0.0;
    precise float inv_k = 1.0 / pk;
    float wmax = 0.0;
    for (int a = 0; a < 3; a++) {
        float l = float(lo[a]);
        float u = float(hi[a]);
        // fp16 arithmetic: compilers may fold an f32->f16->f32 round trip away.
        precise float16_t ch = (lo[a] + hi[a]) * float16_t(0.5);
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

// Origin at world parameter t in frame (w, k), fp32 then fp16, clamped to +-OCAP; returns the error bound.
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

// The stack entry of a hit inner child (mirrors f16h::child_entry): its frame, and the origin
// moved into it in fp16, or re-anchored from the fp32 world ray when the bound grows too large
// (counted in `reanchors`).
void child_entry(RayPre r, float m, f16vec3 d16, vec3 fw, float fk, OVEC o, float e, float tp, float tlo,
                 float mk, float lower, bool prec, f16vec3 lo, f16vec3 hi, float tn, float tn_lb,
                 inout uint reanchors, out vec4 wk, out OVEC o2, out float e2, out float tp2, out float tlo_c) {
    f16vec3 cc; float cr; vec3 cw; float ck;
    derive_child(fw, fk, lo, hi, cc, cr, cw, ck);
    wk = vec4(cw, ck);
    float s_lo = max(tn_lb, lower);
    precise float q = s_lo / mk;
    precise float tlo_c0 = (tp + q) - (abs(tp) + abs(q)) * TWO_M21;
    tlo_c = max(tlo_c0, tlo);
    float se = max(tn, lower);
    if (prec && cr <= 32768.0) {
        float emag = 0.0, ecmag = 0.0, omag = 0.0;
        bool finite = true;
        for (int a = 0; a < 3; a++) {
#ifdef MATH_F32
            precise float ea = o[a] + se * float(d16[a]);
            precise float ec = ea - float(cc[a]);
            precise float oa = ec * cr;
#else
            float16_t s_e = float16_t(se);
            float16_t r16c = float16_t(cr);
            precise float16_t ea = o[a] + s_e * d16[a];
            precise float16_t ec = ea - cc[a];
            precise float16_t oa = ec * r16c;
#endif
            o2[a] = oa;
            emag = max(emag, abs(float(ea)));
            ecmag = max(ecmag, abs(float(ec)));
            omag = max(omag, abs(float(oa)));
            finite = finite && !isinf(oa) && !isnan(oa);
        }
        precise float step_t = se / mk;
        precise float tpn = tp + step_t;
        float wmax = max(max(max(0.0, abs(cw.x)), abs(cw.y)), abs(cw.z));
        precise float mk2 = m * ck;
        precise float ee = (cr * (e + abs(se) * TWO_M10 + TWO_M11 * (emag + ecmag) + TWO_M23)
            + wmax * TWO_M24 * ck
            + (abs(tp) + abs(step_t)) * TWO_M22 * mk2)
            * (1.0 + TWO_M18);
        if (finite && omag <= OCAP && ee <= EMAX) {
            e2 = ee;
            tp2 = tpn;
            return;
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
    tp2 = max(min(io.x, io.y), tlo_c);
    e2 = anchor(r, cw, ck, tp2, o2);
}
