#version 460
#extension GL_EXT_control_flow_attributes : require
#extension GL_EXT_null_initializer : require
// The traversal skeleton of every layout and kernel family: single rays (P = 1) and packets of
// P rays (packet.glsl: in a subgroup, a subgroup then shared memory, or shared memory), with
// counters where STATS is defined. It mirrors src/layout/traverse.rs step for step.
//
// Every define a kernel is built with is listed once, in the documentation of
// `Variant::defines` (src/variant/mod.rs). "interface.glsl" is generated from the Rust definitions
// for this variant (child word fields, push constants, Hit, Counters, the layout's stack
// Entry); "layout.glsl" is the variant's layout hooks (glsl/layout/<name>.glsl), which provide:
//   Node buffer `nodes[]`, declared with NODE_BUFFER(Node) (bound, or by address: ray.glsl)
//   uint  child_word(uint ni, uint s)
//   void  child_box(uint ni, uint s, out vec3 lo, out vec3 hi)     (stored box, widened)
//   void  layout_ray(RayPre r)                  per-ray constants (private globals)
//   Entry root_entry(RayPre r, float near)      the root's entry for a ray entering at near
//   Entry no_entry(); bool has_entry(Entry e)   the marker of a ray inactive at a level
//   float entry_t(Entry e)                      skip the node when it exceeds the closest hit
//   Visit visit_node(uint ni, Entry e, RayPre r, float best_t)   per node and active ray
//   bool  test_child(uint ni, uint s, Entry e, Visit v, RayPre r, out float key, out ChildHit h)
//   (optional, with TEST_PAIRS defined) bvec2 test_pair(uint ni, uint s, Entry e, Visit v,
//         RayPre r, out vec2 key, out ChildHit h0, out ChildHit h1): slots s and s + 1 at once
//   Entry child_entry(uint ni, uint s, Entry e, Visit v, ChildHit h, RayPre r, inout uint reanchors)
//   (optional) #define HIT_FROM_KEY(k): the ChildHit test_child returns with key k, where it
//         depends on nothing else (children.glsl: single rays then keep no ChildHits; not
//         with TEST_PAIRS)
//
//
// The pieces: children.glsl (a visit's child tests, singles or pairs), and one of two stack
// disciplines behind one interface — stack_entries.glsl (an entry per child) or, with
// DEFER_ENTRIES, stack_groups.glsl (one group per visit, entries derived on entering).
#include "interface.glsl"
#include "ray.glsl"
#include "tri.glsl"
#include "box.glsl"
#include "layout.glsl"
#include "packet.glsl"

// What a ray's traversal counts (the Counters it writes, with the packet's two). `visits`, not
// `nodes`: with ADDRESSED, ray.glsl defines `nodes` as a macro.
struct Counts { uint visits; uint box_tests; uint tri_tests; uint reanchors; };

#include "children.glsl"
#ifdef DEFER_ENTRIES
#include "stack_groups.glsl"
#else
#include "stack_entries.glsl"
#endif

// The ray's counters (STATS only): the packet's visits and active rays on its first lane.
void write_counters(uint i, Counts c, uint pnodes, uint asum) {
#if defined(STATS) && defined(BRANCH_COUNTS)
    // The branch-counting build: the ray's count of each named side of its triangle tests, the
    // sides two by two in 16-bit halves (Branch::counted), its triangle tests where they are.
    counters[i] = Counters(branch_pair(0u, 1u), branch_pair(2u, 3u), c.tri_tests, branch_pair(4u, 5u), branch_pair(6u, 7u), 0u);
#elif defined(STATS)
    bool first = packet_lane() == 0u;
    counters[i] = Counters(c.visits, c.box_tests, c.tri_tests, c.reanchors, first ? pnodes : 0u, first ? asum : 0u);
#endif
}

void main() {
    uint i = packet_ray_index();
    bool valid = i < pc.ray_count;
    if (P == 1 && !valid) return;
    RayPre r = ray_pre(valid ? i : 0u);
    layout_ray(r);
    Counts c = Counts(0u, 1u, 0u, 0u);   // the root's box test counts
    uint pnodes = 0u, asum = 0u;         // the packet's visits and active rays over them
    closest_init(r.tmax);
    vec2 root = slab32(r, pc.box_lo.xyz, pc.box_hi.xyz, r.tmin, r.tmax);
    bool root_hit = valid && root.x <= root.y;
    // The stack holds the nodes still to visit; the node being visited (ni, en) is kept out of
    // it: a visit goes on with its nearest inner child directly and pushes only the others, so
    // the nodes are visited in exactly the order of pushing all and popping the top.
    stack_init();
    bool overflow = false;
    bool more = packet_any(root_hit);
    uint ni = 0u;
    Entry en = root_hit ? root_entry(r, root.x) : no_entry();
    while (more) {
        bool act = has_entry(en) && entry_t(en) <= best_t;
        bool descend = false;
        // Single rays skip an inactive visit; a packet's lanes all take part in its reductions.
        if (P > 1 || act) {
            Visit v = visit_node(ni, en, r, best_t);
            uint cw[B];
            float key[B];
            ChildHit ch[B];
            uint mask = test_children(ni, en, v, r, act, cw, key, ch, c);
            // One reduction over the packet: active rays, the union of hit children, each hit
            // child's smallest key. A node no ray is active for is skipped (nothing was tested).
            uint nact;
            uint any_mask = packet_reduce(act, mask, key, nact);
            if (nact != 0u) {
                pnodes++;
                asum += nact;
                if (act) c.visits++;
                // Inner children nearest first, through the stack; then the leaves this ray
                // hit, in slot order, in one loop (any order gives the same closest hit, ties
                // going to the lower prim, and the same counters; nothing in the push depends
                // on best_t), so that the visit's keys and child data are not held across the
                // triangle tests.
                uint inner = 0u, leaves = 0u;
                [[unroll]] for (uint s = 0u; s < uint(B); s++) {
                    if ((any_mask & (1u << s)) != 0u) {
                        if (!is_leaf(cw[s])) inner |= 1u << s;
                        else leaves |= mask & (1u << s);
                    }
                }
                if (!stack_fits(inner)) {
                    overflow = true;
                    break;
                }
                push_children(ni, en, v, r, mask, inner, cw, key, ch, c, descend);
                test_leaves(r, leaves, cw, c.tri_tests);
            }
        }
        if (!descend) more = pop_next(ni, en);
        if (more) enter(ni, en, r, c);
    }
    if (!valid) return;
    if (overflow) hits[i] = Hit(0.0, PRIM_OVERFLOW, 0.0, 0.0);
    else write_closest(i);
    write_counters(i, c, pnodes, asum);
}
