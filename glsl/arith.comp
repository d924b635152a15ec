#version 460
// Raw arithmetic throughput of the slab test's operations (OP: 0 sub, 1 mul, 2 min, 3 max,
// 4 compare + select) in float16_t (F16) or float: 4 independent vec4 chains, loop-carried, so every
// iteration does 16 operations the compiler cannot drop. The result is written to keep it live.
#extension GL_EXT_shader_explicit_arithmetic_types_float16 : require
#extension GL_EXT_shader_16bit_storage : require
layout(local_size_x = 64) in;
layout(push_constant) uniform Push { uint iters; float start; } pc;
layout(std430, set = 0, binding = 0) writeonly buffer Out { float outv[]; };
#ifdef F16
#define T float16_t
#define V f16vec4
#else
#define T float
#define V vec4
#endif

void main() {
    uint i = gl_GlobalInvocationID.x;
    float s = pc.start + float(i & 15u) * 0.0625;
    V y0 = V(T(s), T(s + 0.25), T(s + 0.5), T(s + 0.75));
    V y1 = V(T(0.999), T(1.001), T(0.998), T(1.002));
    V x0 = y0, x1 = y0 + y1, x2 = y0 - y1, x3 = y0 * y1;
    for (uint k = 0u; k < pc.iters; k++) {
#if OP == 0
        x0 = x0 - y1; x1 = x1 - y1; x2 = x2 - y1; x3 = x3 - y1;
#elif OP == 1
        x0 = x0 * y1; x1 = x1 * y1; x2 = x2 * y1; x3 = x3 * y1;
#elif OP == 2
        x0 = min(x0, x1); x1 = min(x1, x2); x2 = min(x2, x3); x3 = min(x3, x0 + y1);
#elif OP == 3
        x0 = max(x0, x1); x1 = max(x1, x2); x2 = max(x2, x3); x3 = max(x3, x0 - y1);
#else
        x0 = mix(x0, x1, lessThan(x0, y0)); x1 = mix(x1, x2, lessThan(x1, y0));
        x2 = mix(x2, x3, lessThan(x2, y0)); x3 = mix(x3, x0, lessThan(x3, y1));
#endif
    }
    V r = x0 + x1 + x2 + x3;
    outv[i] = float(r.x + r.y + r.z + r.w);
}
