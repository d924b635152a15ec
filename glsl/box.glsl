// The conservative fp32 slab test (Ize 2013), shared by every layout's root box test.
// Mirrors src/base/slab.rs (slab32; lower32 and upper32 are in ray.glsl). No NaN is ever
// formed: zero direction components get an explicit inside test.

// Returns (near, far); hit when near <= far.
vec2 slab32(RayPre r, vec3 lo, vec3 hi, float t0, float t1) {
    float near_t = t0;
    float far_t = t1;
    for (int a = 0; a < 3; a++) {
        float n, f;
        if (ray_d_zero(r, a)) {
            bool inside = r.o[a] >= lo[a] && r.o[a] <= hi[a];
            n = inside ? -INF : INF;
            f = inside ? INF : -INF;
        } else {
            precise float x = (lo[a] - r.o[a]) * r.inv[a];
            precise float y = (hi[a] - r.o[a]) * r.inv[a];
            n = lower32(min(x, y));
            f = upper32(max(x, y));
        }
        near_t = max(near_t, n);
        far_t = min(far_t, f);
    }
    return vec2(near_t, far_t);
}
