// Node layouts, exactly as src/encode/{f32,f16h}.rs write them (structure of arrays):
// lo[axis * B + slot], hi[axis * B + slot], child[slot]. 28·B bytes (f32), 16·B bytes (f16h).
#ifdef F16H
#define COORD float16_t
#else
#define COORD float
#endif
struct Node {
    COORD lo[3 * B];
    COORD hi[3 * B];
    uint child[B];
};
layout(std430, set = 0, binding = 0) readonly buffer Nodes { Node nodes[]; };
