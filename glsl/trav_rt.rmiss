#version 460
// Baseline rt's miss: the miss record of every kernel (t = +inf, prim -1).
#extension GL_EXT_ray_tracing : require
#include "interface.glsl"

layout(location = 0) rayPayloadInEXT Hit hit;

void main() {
    hit = Hit(uintBitsToFloat(0x7f800000u), -1, 0.0, 0.0);
}
