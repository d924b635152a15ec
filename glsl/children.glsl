// A visit's child tests, in the two ways a layout may offer (TEST_PAIRS: its test_pair tests
// slots s and s + 1 at once, packed fp16 arithmetic; else test_child one by one), with the same
// results and counts either way. Mirrors the child loop of src/layout/traverse.rs (`packet`).

// A layout whose ChildHit is a function of the child's key alone defines HIT_FROM_KEY(k). For
// single rays, whose keys are their own (a packet's are reduced over its rays), a visit then
// keeps no ChildHits: VISIT_HIT(s) derives slot s's from its key (Mali-G610, f16w with fp32
// math at B = 4: 6 spills and fills with them kept, none without).
#if P == 1 && defined(HIT_FROM_KEY)
#ifdef TEST_PAIRS
#error "HIT_FROM_KEY with TEST_PAIRS: the pair test keeps ChildHits (children.glsl)"
#endif
#define KEY_HITS 1
#define VISIT_HIT(s) HIT_FROM_KEY(key[s])
#else
#define VISIT_HIT(s) ch[s]
#endif

// The visit's child words (read once per visit; slots past the first empty one are never
// read) and, where the ray is active, its hit mask over the children with each hit child's
// key and ChildHit (with KEY_HITS no ChildHit: read a hit child's as VISIT_HIT(s), never ch[s]);
// counts the box tests.
uint test_children(uint ni, Entry en, Visit v, RayPre r, bool act, out uint cw[B], out float key[B],
                   out ChildHit ch[B], inout Counts c) {
    uint mask = 0u;
    ChildHit no_hit = {};
    [[unroll]] for (uint s = 0u; s < uint(B); s++) { key[s] = INF; cw[s] = CHILD_EMPTY; ch[s] = no_hit; }
#ifdef TEST_PAIRS
    // A lone last child is tested in a pair with the (in-bounds, ignored) slot after it.
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
            c.box_tests += two ? 2u : 1u;
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
        if (act) {
            c.box_tests++;
            float k;
            ChildHit h;
            if (test_child(ni, s, en, v, r, k, h)) {
                mask |= 1u << s;
                key[s] = k;
#ifndef KEY_HITS
                ch[s] = h;
#endif
            }
        }
    }
#endif
    return mask;
}

// Child s of node ni tested again, as the visit tested it (the same pair where pairs are
// tested): the ChildHit its entry is derived from (stack_groups.glsl).
ChildHit retest_child(uint ni, uint s, Entry en, Visit v, RayPre r) {
#ifdef TEST_PAIRS
    vec2 k;
    ChildHit h0, h1;
    test_pair(ni, s & ~1u, en, v, r, k, h0, h1);
    return (s & 1u) != 0u ? h1 : h0;
#else
    float k;
    ChildHit h;
    test_child(ni, s, en, v, r, k, h);
    return h;
#endif
}
