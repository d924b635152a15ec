#version 460
// Baseline rt's closest hit: t, the primitive (the BLAS holds the triangles in prim order,
// non-indexed, so gl_PrimitiveID is the public prim id, as rq's primitive index is) and the
// barycentrics of vertices 1 and 2, as rq reports them.
#extension GL_EXT_ray_tracing : require
#include "interface.glsl"

layout(location = 0) rayPayloadInEXT Hit hit;
hitAttributeEXT vec2 bary;

void main() {
    hit = Hit(gl_HitTEXT, gl_PrimitiveID, bary.x, bary.y);
}
