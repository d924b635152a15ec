#version 460
// Baseline rq: the driver's acceleration structure, traced with a ray query (closest hit,
// opaque triangles, no culling). Same interface as the other kernels: binding 0 is the TLAS.
#extension GL_EXT_ray_query : require
#include "interface.glsl"
#include "ray.glsl"

layout(set = 0, binding = BINDING_NODES) uniform accelerationStructureEXT tlas;

void main() {
    uint i = ray_index();
    if (i >= pc.ray_count) return;
    uint b = RAY_FLOATS * i;
    vec3 o = vec3(ray_f[b], ray_f[b + 1u], ray_f[b + 2u]);
    vec3 d = vec3(ray_f[b + 4u], ray_f[b + 5u], ray_f[b + 6u]);
    rayQueryEXT q;
    rayQueryInitializeEXT(q, tlas, gl_RayFlagsOpaqueEXT, 0xFFu, o, ray_f[b + 3u], d, ray_f[b + 7u]);
    while (rayQueryProceedEXT(q)) {}
    if (rayQueryGetIntersectionTypeEXT(q, true) == gl_RayQueryCommittedIntersectionTriangleEXT) {
        vec2 uv = rayQueryGetIntersectionBarycentricsEXT(q, true);
        hits[i] = Hit(rayQueryGetIntersectionTEXT(q, true), rayQueryGetIntersectionPrimitiveIndexEXT(q, true), uv.x, uv.y);
    } else {
        hits[i] = Hit(INF, -1, 0.0, 0.0);
    }
}
