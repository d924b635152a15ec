// Watertight ray-triangle test (Woop, Benthin, Wald 2013) and the closest-hit rule.
// Mirrors src/base/tri.rs and base::Closest operation for operation (no contraction).

#ifndef HAS_F64
// Without shaderFloat64 the recomputation of an edge function that is zero in fp32 is done
// with integer operations: edge_f64(a, b, c, d) is a*b - c*d computed in f64 (both products
// exact there) and rounded to f32, on 64-bit values held as uvec2(lo, hi). tri.rs,
// edge_f64_emulated, takes the same steps on u64 and is tested against the f64 expression.
uvec2 u64_shl(uvec2 v, uint n) {
    if (n == 0u) return v;
    if (n >= 32u) return uvec2(0u, v.x << (n - 32u));
    return uvec2(v.x << n, (v.y << n) | (v.x >> (32u - n)));
}
uvec2 u64_shr(uvec2 v, uint n) {
    if (n == 0u) return v;
    if (n >= 32u) return uvec2(v.y >> (n - 32u), 0u);
    return uvec2((v.x >> n) | (v.y << (32u - n)), v.y >> n);
}
uvec2 u64_add(uvec2 a, uvec2 b) { uint c; uint lo = uaddCarry(a.x, b.x, c); return uvec2(lo, a.y + b.y + c); }
uvec2 u64_sub(uvec2 a, uvec2 b) { uint br; uint lo = usubBorrow(a.x, b.x, br); return uvec2(lo, a.y - b.y - br); }
bool u64_lt(uvec2 a, uvec2 b) { return a.y < b.y || (a.y == b.y && a.x < b.x); }
int u64_msb(uvec2 v) { return v.y != 0u ? 32 + findMSB(v.y) : findMSB(v.x); }
uvec2 u64_mask(uint n) { return n >= 32u ? uvec2(0xffffffffu, (1u << (n - 32u)) - 1u) : uvec2((1u << n) - 1u, 0u); }

// r rounded to nearest even at bit pos (1..63), shifted down by pos.
uvec2 u64_round_at(uvec2 r, uint pos) {
    uvec2 q = u64_shr(r, pos);
    uvec2 low = r & u64_mask(pos);
    uvec2 halfway = u64_shl(uvec2(1u, 0u), pos - 1u);
    if (u64_lt(halfway, low) || (low == halfway && (q.x & 1u) == 1u)) q = u64_add(q, uvec2(1u, 0u));
    return q;
}

// x*y as sign, m * 2^e with m in [2^62, 2^63) (or m = 0): 48 significant bits, 15 zero bits
// below them and one above.
struct Product { uint sign; int e; uvec2 m; };
Product edge_product(float x, float y, bool negate) {
    uint ux = floatBitsToUint(x);
    uint uy = floatBitsToUint(y);
    uint sign = (ux ^ uy ^ (negate ? 0x80000000u : 0u)) & 0x80000000u;
    ux &= 0x7fffffffu;
    uy &= 0x7fffffffu;
    if (ux == 0u || uy == 0u) return Product(sign, 0, uvec2(0u));
    int ex, ey;
    uint mx = significand(ux, ex);
    uint my = significand(uy, ey);
    uint hi, lo;
    umulExtended(mx, my, hi, lo);
    uvec2 m = uvec2(lo, hi);                            // in [2^46, 2^48)
    uint s = m.y < 0x8000u ? 16u : 15u;
    return Product(sign, ex + ey - 300 - int(s), u64_shl(m, s));
}

float edge_f64(float a, float b, float c, float d) {
    Product p1 = edge_product(a, b, false);
    Product p2 = edge_product(c, d, true);
    bool z1 = p1.m == uvec2(0u);
    bool z2 = p2.m == uvec2(0u);
    if (z1 && z2) return uintBitsToFloat(p1.sign & p2.sign);
    // the larger magnitude first; the smaller aligned to it with a sticky bit
    bool first = z2 || (!z1 && (p1.e > p2.e || (p1.e == p2.e && !u64_lt(p1.m, p2.m))));
    Product pb = first ? p1 : p2;
    Product ps = first ? p2 : p1;
    uint delta = ps.m == uvec2(0u) ? 64u : uint(pb.e - ps.e);
    uvec2 small;
    if (delta >= 64u) small = uvec2(ps.m != uvec2(0u) ? 1u : 0u, 0u);
    else small = u64_shr(ps.m, delta) | uvec2((ps.m & u64_mask(delta)) != uvec2(0u) ? 1u : 0u, 0u);
    uvec2 r = pb.sign == ps.sign ? u64_add(pb.m, small) : u64_sub(pb.m, small);
    int e = pb.e;
    if (r == uvec2(0u)) return 0.0;
    if (r.y >= 0x80000000u) { r = u64_shr(r, 1u) | (r & uvec2(1u, 0u)); e += 1; }
    // to f64's 53 bits (f32 products give no f64 subnormal or overflow)
    int top = u64_msb(r);
    if (top > 52) {
        uint pos = uint(top - 52);
        r = u64_shl(u64_round_at(r, pos), pos);
    }
    // then to f32: 24 bits, or fewer where the result is subnormal
    top = u64_msb(r);
    int pos = max(top - 23, -149 - e);
    uvec2 q;
    if (pos <= 0) q = u64_shl(r, uint(-pos));
    else if (pos > top + 1) q = uvec2(0u);
    else q = u64_round_at(r, uint(pos));
    int ex = e + pos;                                   // the result is q * 2^ex
    if (q.x >= 0x1000000u) { q.x >>= 1; ex += 1; }
    if (q.x >= 0x800000u) {
        int biased = ex + 150;
        if (biased >= 255) return uintBitsToFloat(pb.sign | 0x7f800000u);
        return uintBitsToFloat(pb.sign | (uint(biased) << 23) | (q.x & 0x7fffffu));
    }
    return uintBitsToFloat(pb.sign | q.x);
}
#endif

// t is exact (div_rte); the barycentrics come as numerators over det (closest_test divides).
bool tri_intersect(RayPre r, uint ti, out float t, out float nu, out float nv, out float det_out) {
    t = 0.0; nu = 0.0; nv = 0.0; det_out = 0.0;
    uint b = 9u * ti;
    precise float A[3];
    precise float Bv[3];
    precise float C[3];
    A[0] = tri_v[b] - r.o.x;       A[1] = tri_v[b + 1u] - r.o.y;  A[2] = tri_v[b + 2u] - r.o.z;
    Bv[0] = tri_v[b + 3u] - r.o.x; Bv[1] = tri_v[b + 4u] - r.o.y; Bv[2] = tri_v[b + 5u] - r.o.z;
    C[0] = tri_v[b + 6u] - r.o.x;  C[1] = tri_v[b + 7u] - r.o.y;  C[2] = tri_v[b + 8u] - r.o.z;
    // Huge coordinates (beyond 2^40 from the ray origin): scaled by a power of two, exactly,
    // so the products cannot overflow; t is scaled back (tri.rs).
    float m = 0.0;
    for (int k = 0; k < 3; k++) m = max(max(m, abs(A[k])), max(abs(Bv[k]), abs(C[k])));
    float back = 1.0;
    if (m > 1099511627776.0) {
        int shift = int((floatBitsToUint(m) >> 23) & 0xffu) - 127 - 39;
        float down = uintBitsToFloat(uint(127 - shift) << 23);
        back = uintBitsToFloat(uint(127 + shift) << 23);
        for (int k = 0; k < 3; k++) {
            A[k] *= down;
            Bv[k] *= down;
            C[k] *= down;
        }
    }
    int kx = ray_kx(r), ky = ray_ky(r), kz = ray_kz(r);
    precise float ax = A[kx] - r.sx * A[kz];
    precise float ay = A[ky] - r.sy * A[kz];
    precise float bx = Bv[kx] - r.sx * Bv[kz];
    precise float by = Bv[ky] - r.sy * Bv[kz];
    precise float cx = C[kx] - r.sx * C[kz];
    precise float cy = C[ky] - r.sy * C[kz];
    precise float U = cx * by - cy * bx;
    precise float V = ax * cy - ay * cx;
    precise float W = bx * ay - by * ax;
#ifdef HAS_F64
    if (U == 0.0 || V == 0.0 || W == 0.0) {
        precise double dU = double(cx) * double(by) - double(cy) * double(bx);
        precise double dV = double(ax) * double(cy) - double(ay) * double(cx);
        precise double dW = double(bx) * double(ay) - double(by) * double(ax);
        U = float(dU);
        V = float(dV);
        W = float(dW);
    }
#elif defined(FC_OFF)
    // One copy of the emulation, run for each edge in turn: edge k is x.z * y.y - y.z * x.y
    // with x = (ax, bx, cx) and y = (ay, by, cy) rotated k places. On Mali-G610 (the build
    // without float controls) one copy spills less than three (isa, f32 at B = 4: 90 spills
    // and fills against 172); on Adreno a740, which has float controls, three copies need
    // fewer registers (96 against 124), so they stay there.
    if (U == 0.0 || V == 0.0 || W == 0.0) {
        vec3 x = vec3(ax, bx, cx), y = vec3(ay, by, cy), e3 = vec3(0.0);
        [[dont_unroll]] for (int k = 0; k < 3; k++) {
            e3 = vec3(e3.yz, edge_f64(x.z, y.y, y.z, x.y));
            x = x.yzx;
            y = y.yzx;
        }
        U = e3.x;
        V = e3.y;
        W = e3.z;
    }
#else
    if (U == 0.0 || V == 0.0 || W == 0.0) {
        U = edge_f64(cx, by, cy, bx);
        V = edge_f64(ax, cy, ay, cx);
        W = edge_f64(bx, ay, by, ax);
    }
#endif
    if ((U < 0.0 || V < 0.0 || W < 0.0) && (U > 0.0 || V > 0.0 || W > 0.0)) return false;
    precise float det = U + V + W;
    if (det == 0.0) return false;
    precise float az = r.sz * A[kz];
    precise float bz = r.sz * Bv[kz];
    precise float cz = r.sz * C[kz];
    precise float T = U * az + V * bz + W * cz;
    precise float tt = div_rte(T, det) * back;
    t = tt; nu = V; nv = W; det_out = det;
    return true;
}

// Closest hit so far under the closest-hit rule (src/base/hit.rs, module docs): t >= tmin,
// the box rule (admit), then the smallest t, ties (equal t) to the lower prim. The
// barycentrics are divided only for a hit that becomes the closest.
float best_t;
int best_prim;
float best_u;
float best_v;

// GLSL's min and max, spelled as hit.rs spells them (sel_min, sel_max).
float sel_min(float x, float y) { return y < x ? y : x; }
float sel_max(float x, float y) { return x < y ? y : x; }

// The box rule (hit.rs, admit): the exact ray must reach triangle ti's box, padded by the
// scene's pc.hit_pad, at a parameter >= tmin, certified with inward rounding; the hit keeps
// t' = max(t, enter). Its argument is in hit.rs.
bool admit(RayPre r, uint ti, float t, out float t_kept) {
    uint b = 9u * ti;
    t_kept = t;
    float enter = r.tmin;
    float exit_t = HIT_CAP;
    for (int a = 0; a < 3; a++) {
        float x0 = tri_v[b + uint(a)];
        float x1 = tri_v[b + 3u + uint(a)];
        float x2 = tri_v[b + 6u + uint(a)];
        precise float lo = sel_min(sel_min(x0, x1), x2) - pc.hit_pad;
        precise float hi = sel_max(sel_max(x0, x1), x2) + pc.hit_pad;
        if (ray_d_zero(r, a)) {
            if (!(r.o[a] >= lo && r.o[a] <= hi)) return false;
        } else {
            precise float x = (lo - r.o[a]) * r.inv[a];
            precise float y = (hi - r.o[a]) * r.inv[a];
            enter = sel_max(enter, upper32(sel_min(x, y)));
            exit_t = sel_min(exit_t, lower32(sel_max(x, y)));
        }
    }
    t_kept = sel_max(t, enter);
    return enter <= exit_t;
}

bool closer(float t, int prim) { return t < best_t || (t == best_t && prim < best_prim); }

void closest_test(RayPre r, uint ti) {
    float t, nu, nv, det;
    if (tri_intersect(r, ti, t, nu, nv, det)) {
        int prim = int(tri_id[ti]);
        // The box rule only raises t: it runs only for a hit that would be kept (the
        // barycentrics first, so that fewer values are held across it).
        if (t >= r.tmin && closer(t, prim)) {
            float u = div_rte(nu, det);
            float v = div_rte(nv, det);
            float tk;
            if (admit(r, ti, t, tk) && closer(tk, prim)) {
                best_t = tk; best_prim = prim; best_u = u; best_v = v;
            }
        }
    }
}

void closest_init(float tmax) {
    best_t = tmax; best_prim = NO_PRIM; best_u = 0.0; best_v = 0.0;
}

bool is_leaf(uint c) { return (c & LEAF_BIT) != 0u; }

// The triangles [first, end) of leaf child word `c` (the one leaf decode).
uint leaf_first(uint c) { return c & LEAF_FIRST_MASK; }
uint leaf_end(uint c) { return leaf_first(c) + ((c >> LEAF_COUNT_SHIFT) & LEAF_COUNT_MASK) + 1u; }

// Tests the triangles of leaf child word `c` (the leaf decode of user kernels, e.g.
// docs/examples/unordered.comp; the skeleton tests a visit's leaves with test_leaves).
void test_leaf(RayPre r, uint c, inout uint tri_tests) {
    for (uint t = leaf_first(c); t < leaf_end(c); t++) {
        tri_tests++;
        closest_test(r, t);
    }
}

// Tests the triangles of the leaves `leaves` (slots of child words cw) in one loop, slot by
// slot: one pass per triangle, so a wave runs the loop as long as its busiest lane's triangles
// of the visit (not each leaf's as long as its slowest lane), and no leaf's loop is nested in
// the child-slot loop.
void test_leaves(RayPre r, uint leaves, uint cw[B], inout uint tri_tests) {
    uint t = 0u, end = 0u;
    while (true) {
        if (t == end) {
            if (leaves == 0u) break;
            uint s = uint(findLSB(leaves));
            leaves &= leaves - 1u;
            uint c = cw[0];
            [[unroll]] for (uint k = 1u; k < uint(B); k++) {
                if (s == k) c = cw[k];
            }
            t = leaf_first(c);
            end = leaf_end(c);
        }
        tri_tests++;
        closest_test(r, t);
        t++;
    }
}
