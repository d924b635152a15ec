// Watertight ray-triangle test (Woop, Benthin, Wald 2013) and the closest-hit rule.
// Mirrors src/base/tri.rs and base::Closest operation for operation (no contraction).

bool tri_intersect(RayPre r, uint ti, out float t, out float u, out float v) {
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
    precise float ax = A[r.kx] - r.sx * A[r.kz];
    precise float ay = A[r.ky] - r.sy * A[r.kz];
    precise float bx = Bv[r.kx] - r.sx * Bv[r.kz];
    precise float by = Bv[r.ky] - r.sy * Bv[r.kz];
    precise float cx = C[r.kx] - r.sx * C[r.kz];
    precise float cy = C[r.ky] - r.sy * C[r.kz];
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
#endif
    if ((U < 0.0 || V < 0.0 || W < 0.0) && (U > 0.0 || V > 0.0 || W > 0.0)) return false;
    precise float det = U + V + W;
    if (det == 0.0) return false;
    precise float az = r.sz * A[r.kz];
    precise float bz = r.sz * Bv[r.kz];
    precise float cz = r.sz * C[r.kz];
    precise float T = U * az + V * bz + W * cz;
    precise float tq = T / det;
    precise float tt = tq * back;
    precise float uu = V / det;
    precise float vv = W / det;
    t = tt; u = uu; v = vv;
    return true;
}

// Closest hit so far; ties (equal t) go to the lower prim.
float best_t;
int best_prim;
float best_u;
float best_v;

void closest_test(RayPre r, uint ti) {
    float t, u, v;
    if (tri_intersect(r, ti, t, u, v)) {
        int prim = int(tri_id[ti]);
        if (t >= r.tmin && (t < best_t || (t == best_t && prim < best_prim))) {
            best_t = t; best_prim = prim; best_u = u; best_v = v;
        }
    }
}

void closest_init(float tmax) {
    best_t = tmax; best_prim = NO_PRIM; best_u = 0.0; best_v = 0.0;
}

bool is_leaf(uint c) { return (c & LEAF_BIT) != 0u; }

// Tests the triangles of leaf child word `c` (the one leaf decode of every kernel).
void test_leaf(RayPre r, uint c, inout uint tri_tests) {
    uint first = c & LEAF_FIRST_MASK;
    uint count = ((c >> LEAF_COUNT_SHIFT) & LEAF_COUNT_MASK) + 1u;
    for (uint t = first; t < first + count; t++) {
        tri_tests++;
        closest_test(r, t);
    }
}
