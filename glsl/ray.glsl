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
layout(std430, set = 0, binding = BINDING_HITS) writeonly buffer Hits { Hit hits[]; };
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

uint ray_index() {
    return (gl_WorkGroupID.y * gl_NumWorkGroups.x + gl_WorkGroupID.x) * uint(WG) + gl_LocalInvocationID.x;
}

struct RayPre {
    vec3 o;
    vec3 d;     // subnormal and zero components flushed to +0
    vec3 inv;
    float tmin;
    float tmax;
    int kx, ky, kz;
    float sx, sy, sz;
};

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
    r.kx = kx; r.ky = ky; r.kz = kz;
    precise vec3 inv = vec3(1.0) / d;
    r.inv = inv;
    precise float sx = d[kx] / d[kz];
    precise float sy = d[ky] / d[kz];
    precise float sz = 1.0 / d[kz];
    r.sx = sx; r.sy = sy; r.sz = sz;
    return r;
}

void write_hit(uint i, float t, int prim, float u, float v) {
    if (prim == NO_PRIM) hits[i] = Hit(MISS_T, -1, 0.0, 0.0);
    else hits[i] = Hit(t, prim, u, v);
}
