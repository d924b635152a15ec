// Packet reductions over the P rays of a packet (src/trace/traverse.rs has the rule) and the
// one child ordering of every kernel.
// P == 1: single-ray traversal; the reductions are the identity.
// PACKET_SUBGROUP: a packet is a cluster of P invocations of one subgroup (P <= subgroup
// size), reduced with clustered subgroup operations.
// Otherwise a packet is a whole workgroup of P invocations, reduced through shared memory
// with barriers. Every invocation of a packet runs every reduction (uniform control flow),
// including lanes past the ray count, which stay inactive.
#if P == 1
uint packet_lane() { return 0u; }
uint packet_ray_index() { return ray_index(); }
uint packet_or(uint x) { return x; }
uint packet_add(uint x) { return x; }
float packet_min(float x) { return x; }
#elif defined(PACKET_SUBGROUP)
#extension GL_KHR_shader_subgroup_basic : require
#extension GL_KHR_shader_subgroup_arithmetic : require
#extension GL_KHR_shader_subgroup_clustered : require
uint packet_lane() { return gl_SubgroupInvocationID % uint(P); }
uint packet_ray_index() {
    return (gl_WorkGroupID.y * gl_NumWorkGroups.x + gl_WorkGroupID.x) * uint(WG) + gl_SubgroupID * gl_SubgroupSize + gl_SubgroupInvocationID;
}
uint packet_or(uint x) { return subgroupClusteredOr(x, P); }
uint packet_add(uint x) { return subgroupClusteredAdd(x, P); }
float packet_min(float x) { return subgroupClusteredMin(x, P); }
#else
shared uint sh_u[P];
shared float sh_f[P];
uint packet_lane() { return gl_LocalInvocationID.x; }
uint packet_ray_index() { return ray_index(); }
uint packet_or(uint x) {
    barrier();
    sh_u[gl_LocalInvocationID.x] = x;
    barrier();
    uint r = 0u;
    for (uint k = 0u; k < uint(P); k++) r |= sh_u[k];
    return r;
}
uint packet_add(uint x) {
    barrier();
    sh_u[gl_LocalInvocationID.x] = x;
    barrier();
    uint r = 0u;
    for (uint k = 0u; k < uint(P); k++) r += sh_u[k];
    return r;
}
float packet_min(float x) {
    barrier();
    sh_f[gl_LocalInvocationID.x] = x;
    barrier();
    float r = INF;
    for (uint k = 0u; k < uint(P); k++) r = min(r, sh_f[k]);
    return r;
}
#endif
bool packet_any(bool b) { return packet_or(b ? 1u : 0u) != 0u; }

// Orders the slots in `mask` by (key, slot) ascending into `order`; returns their count
// (src/trace/traverse.rs, order_children).
int order_children(uint mask, float key[B], out uint order[B]) {
    int n = 0;
    for (uint s = 0u; s < uint(B); s++) {
        if ((mask & (1u << s)) == 0u) continue;
        int j = n;
        while (j > 0 && key[order[j - 1]] > key[s]) { order[j] = order[j - 1]; j--; }
        order[j] = s;
        n++;
    }
    return n;
}
