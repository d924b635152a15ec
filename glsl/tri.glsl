// The certified watertight triangle test and the closest-hit rule (src/base/hit.rs, module
// docs; docs/layouts.md, "The closest-hit rule"). Mirrors tri.rs (certify) and ClosestTrue's fast mode
// operation for operation (no contraction): fp32 only, no fp64, no fused multiply-add. What
// fp32 cannot decide may flag the ray (PRIM_FLAGGED); the host re-traces flagged rays exactly.

const int CERT_MISS = 0;
const int CERT_HIT = 1;
const int CERT_UNSURE = 2;
// The unit roundoff 2^-24 and the bounds' slack factors (tri.rs).
const float U24 = 5.9604644775390625e-08;
const float SLACK18 = 1.000003814697265625;   // 1 + 2^-18
const float SLACK16 = 1.0000152587890625;     // 1 + 2^-16
const float ULP22 = 2.384185791015625e-07;    // 2^-22
const float COORD_ERR = (2.0 * U24) * SLACK18; // 2u(1 + 2^-18): exact

// tri.rs, certify (round): the rounding of the edge function x1*y2 - x2*y1's two products and
// difference.
float edge_round(float x1, float y1, float x2, float y2) {
    precise float r = (2.0 * U24) * (abs(x1 * y2) + abs(x2 * y1));
    return r;
}

// tri.rs, certify (edge): the bound of the error of the edge function x1*y2 - x2*y1 of
// sheared coordinates within ex, ey of the exact ones: its rounding (edge_round), its
// operands' errors.
float edge_bound(float x1, float y1, float x2, float y2, float ex, float ey, float round) {
    precise float r = round + ex * (abs(y1) + abs(y2)) + ey * (abs(x1) + abs(x2)) + 2.0 * ex * ey;
    return r * SLACK18;
}

// GLSL's min and max as the selects tri.rs spells (sel_min, sel_max): a NaN comes out alike.
float sel_min(float x, float y) { return y < x ? y : x; }
float sel_max(float x, float y) { return x < y ? y : x; }

// tri.rs, certify: CERT_MISS, or the interval [lo, hi] that holds the exact crossing's
// parameter (CERT_HIT: the exact ray certainly crosses; CERT_UNSURE: fp32 cannot decide,
// `bounded` false where no interval is known). A hit's barycentrics come as numerators over
// det (closest_test divides).
int tri_certify(RayPre r, uint ti, out float lo, out float hi, out bool bounded, out float nu, out float nv,
                out float det_out) {
    lo = 0.0; hi = 0.0; bounded = false; nu = 0.0; nv = 0.0; det_out = 0.0;
    uint b = 9u * ti;
    precise float A[3];
    precise float Bv[3];
    precise float C[3];
    A[0] = tri_v[b] - r.o.x;       A[1] = tri_v[b + 1u] - r.o.y;  A[2] = tri_v[b + 2u] - r.o.z;
    Bv[0] = tri_v[b + 3u] - r.o.x; Bv[1] = tri_v[b + 4u] - r.o.y; Bv[2] = tri_v[b + 5u] - r.o.z;
    C[0] = tri_v[b + 6u] - r.o.x;  C[1] = tri_v[b + 7u] - r.o.y;  C[2] = tri_v[b + 8u] - r.o.z;
    // Huge coordinates (beyond 2^40 from the ray origin): scaled by a power of two, exactly,
    // so the products cannot overflow; t is scaled back (tri.rs, translated).
    float m = 0.0;
    for (int k = 0; k < 3; k++) m = max(max(m, abs(A[k])), max(abs(Bv[k]), abs(C[k])));
    float back = 1.0;
    if (m > 1099511627776.0) {
        MARK_HUGE();
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
    precise float px0 = r.sx * A[kz], px1 = r.sx * Bv[kz], px2 = r.sx * C[kz];
    precise float py0 = r.sy * A[kz], py1 = r.sy * Bv[kz], py2 = r.sy * C[kz];
    precise float ax = A[kx] - px0, bx = Bv[kx] - px1, cx = C[kx] - px2;
    precise float ay = A[ky] - py0, by = Bv[ky] - py1, cy = C[ky] - py2;
    // the depths now, so that the translated vertices are dead past the bounds below
    precise float az = r.sz * A[kz];
    precise float bz = r.sz * Bv[kz];
    precise float cz = r.sz * C[kz];
    // |x - x*| <= 2u(1 + 2^-18)(|A_x| + 2|p|) (tri.rs, certify)
    precise float mx = max(max(abs(A[kx]) + abs(px0) * 2.0, abs(Bv[kx]) + abs(px1) * 2.0), abs(C[kx]) + abs(px2) * 2.0);
    precise float my = max(max(abs(A[ky]) + abs(py0) * 2.0, abs(Bv[ky]) + abs(py1) * 2.0), abs(C[ky]) + abs(py2) * 2.0);
    precise float ex = COORD_ERR * mx;
    precise float ey = COORD_ERR * my;
    // the exact projected triangle lies on one side of the ray: a certain miss
    if (min(min(ax, bx), cx) > ex || max(max(ax, bx), cx) < -ex || min(min(ay, by), cy) > ey
        || max(max(ay, by), cy) < -ey) return CERT_MISS;
    MARK_EDGES();
    // t's error through the computed vertices' plane (tri.rs): ez + (|Gx| ex + |Gy| ey)/|D|, Gx's
    // bound the least of its three vertex references; here, while the sheared coordinates live
    // (past the edge functions it took turnip 25.0.7's f16h fp32 kernel from 96 to 128 registers)
    precise float wa = abs(by - cy), wb = abs(cy - ay), wc = abs(ay - by);
    precise float va = abs(bx - cx), vb = abs(cx - ax), vc = abs(ax - bx);
    precise float zab = abs(az - bz), zac = abs(az - cz), zbc = abs(bz - cz);
    precise float gx = sel_min(sel_min(zab * wb + zac * wc, zab * wa + zbc * wc), zac * wa + zbc * wb);
    precise float gy = sel_min(sel_min(zab * vb + zac * vc, zab * va + zbc * vc), zac * va + zbc * vb);
    precise float plane = gx * ex + gy * ey;
    precise float uu = cx * by - cy * bx;
    precise float vv = ax * cy - ay * cx;
    precise float ww = bx * ay - by * ax;
    precise float ru = edge_round(cx, cy, bx, by);
    precise float rv = edge_round(ax, ay, cx, cy);
    precise float rw = edge_round(bx, by, ax, ay);
    precise float eu = edge_bound(cx, cy, bx, by, ex, ey, ru);
    precise float ev = edge_bound(ax, ay, cx, cy, ex, ey, rv);
    precise float ew = edge_bound(bx, by, ax, ay, ex, ey, rw);
    bool pos = uu > eu || vv > ev || ww > ew;
    bool neg = uu < -eu || vv < -ev || ww < -ew;
    if (pos && neg) return CERT_MISS;
    MARK_CROSS();
    bool sure = abs(uu) > eu && abs(vv) > ev && abs(ww) > ew;
    precise float det = uu + vv + ww;
    precise float s = abs(uu) + abs(vv) + abs(ww);
    precise float ed = eu + ev + ew + (2.5 * U24) * s;
    precise float zm = max(max(abs(az), abs(bz)), abs(cz));
    // the largest rounding of one edge function's products and difference (t's error)
    precise float er = sel_max(sel_max(ru, rv), rw) * SLACK18;
    precise float ez = (3.5 * U24) * zm;
    precise float t;
    precise float err;
    if (!(abs(det) > 2.0 * ed)) {
        // no usable t: a crossing, if any, lies within the vertices' depths
        MARK_FLAT();
        precise float z0 = min(min(az, bz), cz), z1 = max(max(az, bz), cz);
        t = 0.5 * (z0 + z1);
        err = (0.5 * (z1 - z0) + ez + U24 * abs(t)) * SLACK16;
        sure = false;
    } else {
        MARK_DIVIDE();
        precise float tt = uu * az + vv * bz + ww * cz;
        // what does not need t, before the division (fewer values live across it)
        precise float e0 = plane + (3.5 * U24) * s * zm + U24 * abs(tt);
        t = div_rte(tt, det);
        precise float et = e0 + (2.5 * U24) * abs(t) * s + er * (abs(az - t) + abs(bz - t) + abs(cz - t));
        err = (div_rte(et, abs(det) - ed) + ez) * SLACK16;
        nu = vv; nv = ww; det_out = det;
    }
    // a certified interval stays within 2^-10 of the farthest vertex's depth (tri.rs)
    if (!(err <= zm * (1.0 / 1024.0))) sure = false;
    t *= back;
    err *= back;
    // (finite: err is never negative, so err < +inf tests both; NaN fails)
    if (!(abs(t) <= HIT_CAP && err <= HIT_CAP)) return CERT_UNSURE;
    precise float mm = err * SLACK18 + abs(t) * ULP22;
    lo = t - mm;
    hi = t + mm;
    bounded = true;
    return sure ? CERT_HIT : CERT_UNSURE;
}

// The closest hit so far under the closest-hit rule (hit.rs, ClosestTrue::fast): a hit is kept
// only where its certified interval [lo, t'] lies wholly before the best's (best_lo); (und_t,
// und_prim): the least (lo, prim) of the tests fp32 could not decide (or order) — the ray is
// flagged if it comes before the final best.
float best_t;
float best_lo;
int best_prim;
float best_u;
float best_v;
float und_t;
int und_prim;

bool closer(float t, int prim) { return t < best_t || (t == best_t && prim < best_prim); }

void closest_test(RayPre r, uint ti) {
    float lo, hi, nu, nv, det;
    bool bounded;
    int c = tri_certify(r, ti, lo, hi, bounded, nu, nv, det);
    if (c == CERT_MISS) return;
    int prim = int(tri_id[ti]);
    if (!bounded) lo = -INF;
    if ((bounded && hi < r.tmin) || !closer(lo, prim)) return;
    MARK_CANDIDATE();
    if (c == CERT_HIT && lo >= r.tmin && hi <= r.tmax && hi < best_lo) {
        MARK_BEST();
        best_t = hi; best_lo = lo; best_prim = prim; best_u = div_rte(nu, det); best_v = div_rte(nv, det);
        return;
    }
    if (lo < und_t || (lo == und_t && prim < und_prim)) {
        und_t = lo;
        und_prim = prim;
    }
}

void closest_init(float tmax) {
    best_t = tmax; best_lo = INF; best_prim = NO_PRIM; best_u = 0.0; best_v = 0.0; und_t = INF; und_prim = NO_PRIM;
}

// Writes ray i's closest hit: a miss, the hit, or PRIM_FLAGGED for a ray to re-trace.
void write_closest(uint i) {
    if (closer(und_t, und_prim)) hits[i] = Hit(0.0, PRIM_FLAGGED, 0.0, 0.0);
    else write_hit(i, best_t, best_prim, best_u, best_v);
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
