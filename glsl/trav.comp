#version 460
#extension GL_EXT_control_flow_attributes : require
// The traversal skeleton of every layout and kernel family: single rays (P = 1), packets in
// a subgroup (PACKET_SUBGROUP) and packets in shared memory; STATS adds the counters. It
// mirrors src/layout/traverse.rs step for step.
//
// Defines: B, P, WG, STACK_SIZE, MATH_F16 | MATH_F32 | MATH_MIXED, PACKET_SUBGROUP, STATS,
// HAS_F64, FC_OFF, ADDRESSED. "interface.glsl" is generated from the Rust definitions for this
// variant (child word fields, push constants, Hit, Counters, the layout's stack Entry); "layout.glsl" is the
// variant's layout hooks (glsl/layout/<name>.glsl), which provide:
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
//
// DEFER_ENTRIES (with GROUPS; Variant::defines sets them for layouts whose entries are large):
// a child's entry is derived when the child is entered, not when the visit that hit
// it pushes it. The stack then holds one group per visit that left inner children for later:
// the node, its entry, this ray's hit mask and the children's order — not one entry per child.
// Entering child s of node n under n's entry e calls visit_node(n, e, r, best_t), test_child
// and child_entry with the same node, entry and box as the push would have, so the layout's
// hooks must not let ChildHit or child_entry depend on `best` (only the hit result may, and
// the hit is the one stored at the push): the entry is then the same, bit for bit, and so are
// the hits and counters (but for a ray whose stack overflows: it reports PRIM_OVERFLOW, and
// the encoder's depth check keeps that from happening). Groups
// only ever belong to nodes on the path from the root, and a node with an inner child is at
// most at depth (STACK_SIZE - 1) / (B - 1) - 2: at most GROUPS of them.
#include "interface.glsl"
#include "ray.glsl"
#include "tri.glsl"
#include "box.glsl"
#include "layout.glsl"
#include "packet.glsl"

#ifdef DEFER_ENTRIES
// A group's Meta: this ray's hit mask over the node's children, how many inner children are
// left, and their slots nearest first (SB bits each). One word up to B = 8.
#if B == 2
#define SB 1u
#elif B == 4
#define SB 2u
#else
#define SB 3u
#endif
#if B <= 8
#define Meta uint
#define OFS (uint(B) + SB)
Meta meta_new(uint hit, int left) { return hit | (uint(left) << uint(B)); }
Meta meta_put(Meta m, int k, uint s) { return m | (s << (OFS + SB * uint(k))); }
uint meta_slot(Meta m) { return (m >> OFS) & (uint(B) - 1u); }
uint meta_left(Meta m) { return (m >> uint(B)) & ((1u << SB) - 1u); }
Meta meta_next(Meta m) {
    uint ord = (m >> OFS) >> SB;
    return (m & ((1u << uint(B)) - 1u)) | ((meta_left(m) - 1u) << uint(B)) | (ord << OFS);
}
bool meta_hit(Meta m, uint s) { return (m & (1u << s)) != 0u; }
#else
// B = 16: x = hit mask | left << 16, y and z the slots (4 bits each, y first).
#define Meta uvec3
Meta meta_new(uint hit, int left) { return uvec3(hit | (uint(left) << 16), 0u, 0u); }
Meta meta_put(Meta m, int k, uint s) {
    if (k < 8) m.y |= s << (4 * k);
    else m.z |= s << (4 * (k - 8));
    return m;
}
uint meta_slot(Meta m) { return m.y & 15u; }
uint meta_left(Meta m) { return m.x >> 16; }
Meta meta_next(Meta m) { return uvec3(m.x - 0x10000u, (m.y >> 4) | (m.z << 28), m.z >> 4); }
bool meta_hit(Meta m, uint s) { return (m.x & (1u << s)) != 0u; }
#endif
// One array of groups: compilers keep small private arrays in registers (RADV: up to 256
// bytes), so the node and Meta go beside the entry, in memory, not in 2·GROUPS registers.
struct Group { Entry en; uint node; Meta meta; };
#endif

void main() {
    uint i = packet_ray_index();
    bool valid = i < pc.ray_count;
#if P == 1
    if (!valid) return;
#endif
    RayPre r = ray_pre(valid ? i : 0u);
    layout_ray(r);
    uvec4 cnt = uvec4(0u, 1u, 0u, 0u);   // nodes, box tests (the root's first), triangle tests, re-anchors
    uint pnodes = 0u, asum = 0u;
    closest_init(r.tmax);
    vec2 root = slab32(r, pc.box_lo.xyz, pc.box_hi.xyz, r.tmin, r.tmax);
    bool root_hit = valid && root.x <= root.y;
    // The stack holds the nodes still to visit; the node being visited (ni, en) is kept out of
    // it: a visit goes on with its nearest inner child directly and pushes only the others, so
    // the nodes are visited in exactly the order of pushing all and popping the top.
#ifdef DEFER_ENTRIES
    Group gs[GROUPS];
    int gp = 0;
    // The child to enter: slot ps of node pn, under pn's entry pe; phit: this ray hit it.
    uint pn = 0u, ps = 0u;
    Entry pe = no_entry();
    bool phit = false;
#else
    uint st_node[STACK_SIZE];
    Entry st[STACK_SIZE];
#endif
    // Entries on the stack (with DEFER_ENTRIES: children left in its groups).
    int sp = 0;
    bool overflow = false;
    bool more = packet_any(root_hit);
    uint ni = 0u;
    Entry en = root_hit ? root_entry(r, root.x) : no_entry();
    while (more) {
        bool act = has_entry(en) && entry_t(en) <= best_t;
        bool descend = false;
#if P == 1
        if (act) {
#endif
        Visit v = visit_node(ni, en, r, best_t);
        // The child words are read once per visit; slots past the first empty one are never read.
        uint mask = 0u;
        uint cw[B];
        float key[B];
        ChildHit ch[B];
        [[unroll]] for (uint s = 0u; s < uint(B); s++) key[s] = INF;
#ifdef TEST_PAIRS
        // Two children per test (the layout's test_pair: packed fp16 arithmetic), the same
        // results and counts as testing them one by one; a lone last child is tested in a
        // pair with the (in-bounds, ignored) slot after it.
        uint nc = uint(B);
        [[unroll]] for (uint s = 0u; s < uint(B); s++) {
            cw[s] = child_word(ni, s);
            if (cw[s] == CHILD_EMPTY) {
                nc = s;
                break;
            }
        }
        if (act) {
            [[unroll]] for (uint s = 0u; s < uint(B); s += 2u) {
                if (s >= nc) break;
                bool two = s + 1u < nc;
                cnt.y += two ? 2u : 1u;
                vec2 k;
                ChildHit h0, h1;
                bvec2 hit = test_pair(ni, s, en, v, r, k, h0, h1);
                if (hit.x) {
                    mask |= 1u << s;
                    key[s] = k.x;
                    ch[s] = h0;
                }
                if (two && hit.y) {
                    mask |= 2u << s;
                    key[s + 1u] = k.y;
                    ch[s + 1u] = h1;
                }
            }
        }
#else
        [[unroll]] for (uint s = 0u; s < uint(B); s++) {
            cw[s] = child_word(ni, s);
            if (cw[s] == CHILD_EMPTY) break;
            if (!act) continue;
            cnt.y++;
            float k;
            ChildHit h;
            if (test_child(ni, s, en, v, r, k, h)) {
                mask |= 1u << s;
                key[s] = k;
                ch[s] = h;
            }
        }
#endif
        // One reduction over the packet: active rays, the union of hit children, each hit
        // child's smallest key. A node no ray is active for is skipped (nothing was tested).
        uint nact;
        uint any_mask = packet_reduce(act, mask, key, nact);
        if (nact != 0u) {
            pnodes++;
            asum += nact;
            if (act) cnt.x++;
            // Leaves first (with DEFER_ENTRIES after the push), in slot order, by the rays that
            // hit them: any order gives the same closest hit (ties go to the lower prim) and the
            // same counters. Inner children go nearest first: each one's place is its rank by
            // (key, slot), so nothing is sorted or copied through arrays indexed at run time
            // (traverse.rs, order_children); rank 0 is visited next, the others are pushed with
            // the nearer ones on top.
            uint inner = 0u;
            [[unroll]] for (uint s = 0u; s < uint(B); s++) {
                if ((any_mask & (1u << s)) == 0u) continue;
                uint c = cw[s];
                if (!is_leaf(c)) inner |= 1u << s;
#ifndef DEFER_ENTRIES
                else if ((mask & (1u << s)) != 0u) test_leaf(r, c, cnt.z);
#endif
            }
            int n = bitCount(inner);
#ifdef DEFER_ENTRIES
            uint s0 = 0u;
            Meta gm = meta_new(mask, n - 1);
            [[unroll]] for (uint s = 0u; s < uint(B); s++) {
                if ((inner & (1u << s)) == 0u) continue;
                int rank = 0;
                [[unroll]] for (uint t = 0u; t < uint(B); t++) {
                    // (key, slot) order with one comparison: t < s is known when unrolled.
                    bool before = t < s ? key[t] <= key[s] : key[t] < key[s];
                    if ((inner & (1u << t)) != 0u && before) rank++;
                }
                if (rank == 0) s0 = s;
                else gm = meta_put(gm, rank - 1, s);
            }
            if (sp + n > STACK_SIZE || (n > 1 && gp >= GROUPS)) {
                overflow = true;
                break;
            }
            if (n > 0) {
                if (n > 1) {
                    gs[gp] = Group(en, ni, gm);
                    gp++;
                }
                sp += n - 1;
                pn = ni;
                pe = en;
                ps = s0;
                phit = (mask & (1u << s0)) != 0u;
                descend = true;
            }
            // The leaves after the push, so that the visit's keys and entry are not held
            // across the triangle tests (the same tests: nothing above depends on best_t).
            [[unroll]] for (uint s = 0u; s < uint(B); s++) {
                if ((mask & ~inner & (1u << s)) != 0u) test_leaf(r, cw[s], cnt.z);
            }
#else
            uint next_node = 0u;
            Entry next_entry = no_entry();
            [[unroll]] for (uint s = 0u; s < uint(B); s++) {
                if ((inner & (1u << s)) == 0u) continue;
                int rank = 0;
                [[unroll]] for (uint t = 0u; t < uint(B); t++) {
                    bool before = key[t] < key[s] || (key[t] == key[s] && t < s);
                    if ((inner & (1u << t)) != 0u && before) rank++;
                }
                Entry e = (mask & (1u << s)) != 0u ? child_entry(ni, s, en, v, ch[s], r, cnt.w) : no_entry();
                if (rank == 0) {
                    next_node = cw[s];
                    next_entry = e;
                } else {
                    int pos = sp + n - 1 - rank;
                    if (pos < STACK_SIZE) {
                        st_node[pos] = cw[s];
                        st[pos] = e;
                    }
                }
            }
            // The same bound as pushing all n (traverse.rs): the encoder checks that a BVH
            // never needs more (GpuBvh::upload).
            if (sp + n > STACK_SIZE) {
                overflow = true;
                break;
            }
            if (n > 0) {
                sp += n - 1;
                ni = next_node;
                en = next_entry;
                descend = true;
            }
#endif
        }
#if P == 1
        }
#endif
        if (!descend) {
            if (sp == 0) {
                more = false;
            } else {
                sp--;
#ifdef DEFER_ENTRIES
                // The nearest child left in the top group; the group goes when it is empty.
                int g = gp - 1;
                Meta m = gs[g].meta;
                pn = gs[g].node;
                pe = gs[g].en;
                ps = meta_slot(m);
                phit = meta_hit(m, ps);
                m = meta_next(m);
                if (meta_left(m) == 0u) gp = g;
                else gs[g].meta = m;
#else
                ni = st_node[sp];
                en = st[sp];
#endif
            }
        }
#ifdef DEFER_ENTRIES
        // Enter the child: its entry from its parent's, as the push would have derived it.
        if (more) {
            ni = child_word(pn, ps);
            en = no_entry();
            if (phit) {
                Visit pv = visit_node(pn, pe, r, best_t);
                ChildHit h;
#ifdef TEST_PAIRS
                // The pair the child was tested in (the same results: packed, as the visit).
                vec2 k;
                ChildHit h0, h1;
                test_pair(pn, ps & ~1u, pe, pv, r, k, h0, h1);
                h = (ps & 1u) != 0u ? h1 : h0;
#else
                float k;
                test_child(pn, ps, pe, pv, r, k, h);
#endif
                en = child_entry(pn, ps, pe, pv, h, r, cnt.w);
            }
        }
#endif
    }
    if (!valid) return;
    if (overflow) hits[i] = Hit(0.0, PRIM_OVERFLOW, 0.0, 0.0);
    else write_hit(i, best_t, best_prim, best_u, best_v);
#ifdef STATS
    bool first = packet_lane() == 0u;
    counters[i] = Counters(cnt.x, cnt.y, cnt.z, cnt.w, first ? pnodes : 0u, first ? asum : 0u);
#endif
}
