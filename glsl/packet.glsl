// Packet reductions over the P rays of a packet (src/layout/traverse.rs has the rule). Per
// visited node the skeleton makes one reduction, packet_reduce: the number of active rays,
// the union of the children they hit and each hit child's smallest key.
// P == 1: single-ray traversal; the reductions are the identity.
// PACKET_SUBGROUP: a packet is a cluster of P invocations of one subgroup (P <= subgroup
// size), reduced with clustered subgroup operations.
// Otherwise a packet is a whole workgroup of P invocations, reduced through shared memory
// (PACKET_HYBRID: after each subgroup has reduced its own rays). Every invocation of a packet
// runs every reduction (uniform control flow), including lanes past the ray count, which
// stay inactive.
#if P == 1
uint packet_lane() { return 0u; }
uint packet_ray_index() { return ray_index(); }
uint packet_or(uint x) { return x; }
uint packet_reduce(bool act, uint mask, inout float key[B], out uint nact) {
    nact = act ? 1u : 0u;
    return mask;
}
#elif defined(PACKET_SUBGROUP)
#extension GL_KHR_shader_subgroup_basic : require
#extension GL_KHR_shader_subgroup_arithmetic : require
#extension GL_KHR_shader_subgroup_clustered : require
uint packet_lane() { return gl_SubgroupInvocationID % uint(P); }
uint packet_ray_index() {
    return (gl_WorkGroupID.y * gl_NumWorkGroups.x + gl_WorkGroupID.x) * uint(WG) + gl_SubgroupID * gl_SubgroupSize + gl_SubgroupInvocationID;
}
uint packet_or(uint x) { return subgroupClusteredOr(x, P); }
uint packet_reduce(bool act, uint mask, inout float key[B], out uint nact) {
    nact = subgroupClusteredAdd(act ? 1u : 0u, P);
    uint any_mask = subgroupClusteredOr(mask, P);
    [[unroll]] for (uint s = 0u; s < uint(B); s++) {
        if ((any_mask & (1u << s)) != 0u) key[s] = subgroupClusteredMin(key[s], P);
    }
    return any_mask;
}
#else
shared uint sh_u[P];
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
// One exchange per visited node, through two alternating buffers so that one barrier per
// node suffices (a buffer is written again only after the next node's barrier, when every
// invocation has read it). PACKET_HYBRID (devices with subgroup arithmetic): each subgroup
// reduces its rays first (active count, hit mask, each slot's smallest key) and one
// invocation per subgroup writes the partial result, so every ray reads a few partials, not
// P; otherwise every ray writes its own and reads all P.
#ifdef PACKET_HYBRID
#extension GL_KHR_shader_subgroup_basic : require
#extension GL_KHR_shader_subgroup_arithmetic : require
#endif
shared uint sh_mask[2 * P];
shared float sh_key[2 * B * P];
uint sh_par = 0u;
uint packet_reduce(bool act, uint mask, inout float key[B], out uint nact) {
    uint base = sh_par * uint(P);
    sh_par ^= 1u;
#ifdef PACKET_HYBRID
    uint a = subgroupAdd(act ? 1u : 0u);
    uint m = subgroupOr(mask);
    float kk[B];
    [[unroll]] for (uint s = 0u; s < uint(B); s++) kk[s] = ((m & (1u << s)) != 0u) ? subgroupMin(key[s]) : INF;
    if (subgroupElect()) {
        sh_mask[base + gl_SubgroupID] = m | (a << 16);
        [[unroll]] for (uint s = 0u; s < uint(B); s++) sh_key[2u * s * uint(P) + base + gl_SubgroupID] = kk[s];
    }
    uint parts = gl_NumSubgroups;
#else
    uint l = gl_LocalInvocationID.x;
    sh_mask[base + l] = mask | (act ? 0x10000u : 0u);
    [[unroll]] for (uint s = 0u; s < uint(B); s++) sh_key[2u * s * uint(P) + base + l] = key[s];
    uint parts = uint(P);
#endif
    barrier();
    uint any_mask = 0u;
    nact = 0u;
    for (uint k = 0u; k < parts; k++) {
        uint w = sh_mask[base + k];
        any_mask |= w & 0xffffu;
        nact += w >> 16;
    }
    [[unroll]] for (uint s = 0u; s < uint(B); s++) {
        if ((any_mask & (1u << s)) != 0u) {
            float mn = INF;
            for (uint k = 0u; k < parts; k++) mn = min(mn, sh_key[2u * s * uint(P) + base + k]);
            key[s] = mn;
        }
    }
    return any_mask;
}
#endif
bool packet_any(bool b) { return packet_or(b ? 1u : 0u) != 0u; }
