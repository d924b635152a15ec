#version 460
// A minimal traversal kernel that works with any layout's hooks: depth first, children in
// slot order (no sorting), one ray per invocation, no counters. Run it in place of a
// variant's built-in kernel; it is validated against that layout's CPU reference first:
//
//   halftrace trace --scene scenes/teapot.obj --layout f16h --branching 4 \
//       --kernel docs/examples/unordered.comp
//
// Its hits equal the built-in kernel's bit for bit (the closest hit does not depend on the
// visiting order: ties go to the lower prim); its work and speed do not.
#include "interface.glsl"   // generated: push constants, Hit, child-word fields, the layout's Entry
#include "ray.glsl"         // bindings, workgroup size, RayPre, ray_pre, write_hit
#include "tri.glsl"         // watertight triangle test, closest hit, is_leaf, test_leaf
#include "box.glsl"         // slab32 (the root box test)
#include "layout.glsl"      // the variant's layout hooks (glsl/layout/<name>.glsl)

void main() {
    uint i = ray_index();
    if (i >= pc.ray_count) return;
    RayPre r = ray_pre(i);
    layout_ray(r);
    closest_init(r.tmax);
    bool overflow = false;
    vec2 root = slab32(r, pc.box_lo.xyz, pc.box_hi.xyz, r.tmin, r.tmax);
    if (root.x <= root.y) {
        uint st_node[STACK_SIZE];
        Entry st[STACK_SIZE];
        st_node[0] = 0u;
        st[0] = root_entry(r, root.x);
        int sp = 1;
        uint uncounted = 0u;
        while (sp > 0 && !overflow) {
            sp--;
            uint ni = st_node[sp];
            Entry en = st[sp];
            if (entry_t(en) > best_t) continue;
            Visit v = visit_node(ni, en, r, best_t);
            for (uint s = 0u; s < uint(B); s++) {
                uint c = child_word(ni, s);
                if (c == CHILD_EMPTY) break;
                float key;
                ChildHit h;
                if (!test_child(ni, s, en, v, r, key, h)) continue;
                if (is_leaf(c)) {
                    test_leaf(r, c, uncounted);
                } else if (sp < STACK_SIZE) {
                    st_node[sp] = c;
                    st[sp] = child_entry(ni, s, en, v, h, r, uncounted);
                    sp++;
                } else {
                    overflow = true;
                }
            }
        }
    }
    if (overflow) hits[i] = Hit(0.0, PRIM_OVERFLOW, 0.0, 0.0);
    else write_closest(i);
}
