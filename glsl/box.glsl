// The conservative fp32 slab test (Ize 2013), shared by every layout's root box test.
// Mirrors src/base/slab.rs (slab32; lower32 and upper32 are in ray.glsl). No NaN is ever
// formed: zero direction components get an explicit inside test.

// Axis a of the slab test: (near_t, far_t) narrowed by the planes lo, hi.
void slab32_axis(RayPre r, int a, float lo, float hi, inout float near_t, inout float far_t) {
    float n, f;
    if (ray_d_zero(r, a)) {
        bool inside = r.o[a] >= lo && r.o[a] <= hi;
        n = inside ? -INF : INF;
        f = inside ? INF : -INF;
    } else {
        precise float x = (lo - r.o[a]) * r.inv[a];
        precise float y = (hi - r.o[a]) * r.inv[a];
        n = lower32(min(x, y));
        f = upper32(max(x, y));
    }
    near_t = max(near_t, n);
    far_t = min(far_t, f);
}

// Returns (near, far); hit when near <= far.
vec2 slab32(RayPre r, vec3 lo, vec3 hi, float t0, float t1) {
    float near_t = t0;
    float far_t = t1;
    for (int a = 0; a < 3; a++) slab32_axis(r, a, lo[a], hi[a], near_t, far_t);
    return vec2(near_t, far_t);
}
