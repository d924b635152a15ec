// Shared by every traversal kernel: workgroup size, the buffers of the interface (declared
// from the generated interface.glsl, which must come first and enables the fp16 types), the
// ray set-up and the hit write. Mirrors src/base/slab.rs (RayPre). The float-control
// execution modes (round-to-nearest-even, signed zero/inf/NaN preserved, per float width the
// kernel computes in) are added to the SPIR-V by the host (gpu::support::float_modes), unless
// the kernel is built without them (FC_OFF).

#ifndef WG
#define WG 64
#endif
layout(local_size_x = WG, local_size_y = 1, local_size_z = 1) in;

#ifdef ADDRESSED
#extension GL_EXT_buffer_reference : require
// The scene's buffers through their device addresses (scenes beyond maxStorageBufferRange):
// a table of three addresses is bound in the nodes' place; `nodes`, `tri_v` and `tri_id`
// read the same bytes as the bound buffers below. A layout declares its node buffer with
// NODE_BUFFER(Node) in either case.
layout(buffer_reference) buffer NodesRef;
layout(buffer_reference, std430, buffer_reference_align = 4) readonly buffer TriVertsRef { float v[]; };
layout(buffer_reference, std430, buffer_reference_align = 4) readonly buffer TriIdsRef { uint v[]; };
layout(std430, set = 0, binding = BINDING_NODES) readonly buffer Addresses { NodesRef nodes_ref; TriVertsRef tri_v_ref; TriIdsRef tri_id_ref; };
#define NODE_BUFFER(T) layout(buffer_reference, std430, buffer_reference_align = 16) readonly buffer NodesRef { T v[]; };
#define nodes nodes_ref.v
#define tri_v tri_v_ref.v
#define tri_id tri_id_ref.v
#else
#define NODE_BUFFER(T) layout(std430, set = 0, binding = BINDING_NODES) readonly buffer Nodes { T nodes[]; };
layout(std430, set = 0, binding = BINDING_TRI_VERTS) readonly buffer TriVerts { float tri_v[]; };   // 9 floats per triangle, leaf order
layout(std430, set = 0, binding = BINDING_TRI_IDS) readonly buffer TriIds { uint tri_id[]; };       // public prim id per triangle
#endif
layout(std430, set = 0, binding = BINDING_RAYS) readonly buffer Rays { float ray_f[]; };            // ox oy oz tmin dx dy dz tmax
#ifdef BRANCH_MARKS
// estimate's marked build (built, never run): the interface's MARK_<NAME>() put an atomic
// operation on the hits buffer at the start of each named side of the triangle test (tri.glsl).
layout(std430, set = 0, binding = BINDING_HITS) buffer Hits { Hit hits[]; };
#else
layout(std430, set = 0, binding = BINDING_HITS) writeonly buffer Hits { Hit hits[]; };
#endif
#ifdef STATS
layout(std430, set = 0, binding = BINDING_COUNTERS) writeonly buffer CounterBuf { Counters counters[]; };
#endif

#ifdef FC_OFF
// Without signed-zero/inf/NaN preservation a driver may assume no operand is infinite, so
// the kernel never computes with inf: "infinity" is FLT_MAX, a ray's infinite tmax is clamped
// to it when loaded (a hit at exactly FLT_MAX, the only case that differs, cannot come from
// finite triangles and rays in practice), and a miss writes inf's bit pattern.
#define INF uintBitsToFloat(0x7f7fffffu)
#else
#define INF uintBitsToFloat(0x7f800000u)
#endif
#define MISS_T uintBitsToFloat(0x7f800000u)
#define FLT_MIN_NORMAL uintBitsToFloat(0x00800000u)
const int NO_PRIM = 0x7fffffff;

// The significand of a non-zero |x| (its bits, sign cleared) normalised to [2^23, 2^24), and
// e with |x| = m * 2^(e - 150), subnormals included.
uint significand(uint x, out int e) {
    e = int(x >> 23);
    uint m = x & 0x7fffffu;
    if (e == 0) {
        int s = 23 - findMSB(m);
        e = 1 - s;
        return m << uint(s);
    }
    return m | 0x800000u;
}

// a / b rounded to nearest even wherever a result must be the CPU's bit for bit (the
// triangle test and its shear constants): Vulkan allows fp32 division an error of 2.5 ulp,
// float controls or not (RADV multiplies by a reciprocal), so the quotient's significand comes
// from integer operations, the native division giving only the first estimate. fp16.rs,
// div_rte_emulated, takes the same steps and is tested against IEEE division with the estimate
// off by up to 100 units either way. b = 0 divides natively.
float div_rte(float a, float b) {
    uint ua = floatBitsToUint(a);
    uint ub = floatBitsToUint(b);
    uint sgn = (ua ^ ub) & 0x80000000u;
    uint xa = ua & 0x7fffffffu;
    uint xb = ub & 0x7fffffffu;
    if (xb == 0u) return a / b;
    if (xa == 0u) return uintBitsToFloat(sgn);
    // significands in [2^23, 2^24): a = ma * 2^(ea - 150), b = mb * 2^(eb - 150)
    int ea, eb;
    uint ma = significand(xa, ea);
    uint mb = significand(xb, eb);
    // g = floor(ma * 2^sh / mb) in [2^23, 2^24); the quotient is (g + rem / mb) * 2^(e - 150)
    uint sh = ma >= mb ? 23u : 24u;
    int e = ea - eb + 127 - int(sh - 23u);
    uint estimate = uint(float(ma) / float(mb) * float(1u << sh));
    uint g = clamp(estimate, 0x800000u, 0xffffffu);
    int rem = int((ma << sh) - g * mb);   // low words only: exact while |estimate - g| < 128
    while (rem < 0) { g--; rem += int(mb); }
    while (rem >= int(mb)) { g++; rem -= int(mb); }
    uint r2 = uint(rem) << 1;
    if (e >= 1) {
        if (r2 > mb || (r2 == mb && (g & 1u) == 1u)) g++;
        if (g == 0x1000000u) { g = 0x800000u; e++; }
        if (e >= 255) return uintBitsToFloat(sgn | 0x7f800000u);
        return uintBitsToFloat(sgn | (uint(e) << 23) | (g & 0x7fffffu));
    }
    // subnormal: the significand keeps g >> s
    uint s = uint(1 - e);
    if (s > 24u) return uintBitsToFloat(sgn);
    uint q = g >> s;
    uint low = g & ((1u << s) - 1u);
    uint halfway = 1u << (s - 1u);
    if (low > halfway || (low == halfway && (rem != 0 || (q & 1u) == 1u))) q++;
    return uintBitsToFloat(sgn | q);
}

// A computed ray parameter moved down (lower32) or up (upper32) by the relative 2^-20 of
// src/base/slab.rs: the slab tests' widening and the closest-hit rule's inward rounding.
float lower32(float t) {
    precise float r = t * (t > 0.0 ? (1.0 - MARGIN32) : (1.0 + MARGIN32));
    return r;
}
float upper32(float t) {
    precise float r = t * (t > 0.0 ? (1.0 + MARGIN32) : (1.0 - MARGIN32));
    return r;
}

uint ray_index() {
    return (gl_WorkGroupID.y * gl_NumWorkGroups.x + gl_WorkGroupID.x) * uint(WG) + gl_LocalInvocationID.x;
}

struct RayPre {
    vec3 o;
    vec3 d;     // subnormal and zero components flushed to +0
    vec3 inv;
    float tmin;
    float tmax;
    // The triangle test's axes kx, ky, kz (2 bits each, from bit 0) and which components of d
    // are zero (bits 6 to 8): one word, so that kernels that need d only for its zeros do not
    // hold it (nor three axis words) across the traversal loop.
    uint axes;
    float sx, sy, sz;
};
int ray_kx(RayPre r) { return int(r.axes & 3u); }
int ray_ky(RayPre r) { return int((r.axes >> 2) & 3u); }
int ray_kz(RayPre r) { return int((r.axes >> 4) & 3u); }
bool ray_d_zero(RayPre r, int a) { return (r.axes & (64u << uint(a))) != 0u; }

RayPre ray_pre(uint i) {
    RayPre r;
    uint b = RAY_FLOATS * i;
    r.o = vec3(ray_f[b], ray_f[b + 1u], ray_f[b + 2u]);
    r.tmin = ray_f[b + 3u];
    vec3 d = vec3(ray_f[b + 4u], ray_f[b + 5u], ray_f[b + 6u]);
    r.tmax = ray_f[b + 7u];
#ifdef FC_OFF
    if ((floatBitsToUint(r.tmax) & 0x7fffffffu) > 0x7f7fffffu) r.tmax = INF;
#endif
    for (int a = 0; a < 3; a++) {
        if (abs(d[a]) < FLT_MIN_NORMAL) d[a] = 0.0;
    }
    r.d = d;
    vec3 ad = abs(d);
    int kz = (ad.x >= ad.y && ad.x >= ad.z) ? 0 : ((ad.y >= ad.z) ? 1 : 2);
    int kx = (kz + 1) % 3;
    int ky = (kx + 1) % 3;
    if (d[kz] < 0.0) { int t = kx; kx = ky; ky = t; }
    r.axes = uint(kx) | (uint(ky) << 2) | (uint(kz) << 4);
    for (int a = 0; a < 3; a++) {
        if (d[a] == 0.0) r.axes |= 64u << uint(a);
    }
    // inv serves only box tests, whose widening allows 2.5 ulp: native division
    precise vec3 inv = vec3(1.0) / d;
    r.inv = inv;
    // the triangle test's shear must be the CPU's bit for bit
    r.sx = div_rte(d[kx], d[kz]);
    r.sy = div_rte(d[ky], d[kz]);
    r.sz = div_rte(1.0, d[kz]);
    return r;
}

void write_hit(uint i, float t, int prim, float u, float v) {
    if (prim == NO_PRIM) hits[i] = Hit(MISS_T, -1, 0.0, 0.0);
    else hits[i] = Hit(t, prim, u, v);
}
