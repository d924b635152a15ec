// Hooks shared by the layouts whose child boxes are tested in a per-node (or per-BVH) frame
// against the origin re-derived from the fp32 world ray at every node (f16w, f16a, q8;
// src/layout/anchored.rs has the argument). Include after half.glsl, and after the layout's
//   struct NodeFrame                                  what a node's boxes are decoded with
//   NodeFrame load_frame(uint ni)                     read once per visit (may be declared only)
//   void node_frame(NodeFrame f, out vec3 w, out float k)             x_local = (x - w) * k
//   void local_box(NodeFrame f, uint ni, uint s, out HVEC3 lo, out HVEC3 hi)   fp16 box in it
//   void world_planes(NodeFrame f, uint ni, uint s, int a, out float lo, out float hi)
//                     axis a of the fp32 world box (decode_plane; may be declared only)
// MATH_F32: the stored box decoded to world fp32 (still containing the true box), then the
// robust fp32 slab test (FC_OFF: one axis at a time).
// Otherwise: the origin anchored in the node frame at the node's entry bound (fp32, rounded to
// fp16, with its error bound), then the widened fp16 slab test of f16h.
// Stack Entry (generated): t = a lower bound of the world parameter of anything that can still
// matter in the node (-1: inactive).

// 1/k for a power of two k, exactly, from the exponent bits.
float inv_pow2(float k) { return uintBitsToFloat((254u - (floatBitsToUint(k) >> 23)) << 23); }

// A stored plane decoded to world fp32: w + x with x exact (fp16 or 8-bit times a power of
// two), one rounding; monotone rounding keeps it outward of the true (fp32) plane
// (anchored.rs, decode_plane). precise: no fused multiply-add. Without float controls the
// sum is add_rte's, IEEE's on any device.
float decode_plane(float w, float x) {
#ifdef FC_OFF
    return add_rte(w, x);
#else
    precise float s = w + x;
    return s;
#endif
}

Entry root_entry(RayPre r, float near_t) { return Entry(near_t); }
Entry no_entry() { return Entry(-1.0); }
bool has_entry(Entry e) { return e.t >= 0.0; }
float entry_t(Entry e) { return e.t; }

struct Visit {
    float tmax;
    float t;
    NodeFrame f;
#ifndef MATH_F32
    OVEC o;
    HVisit h;
#endif
};

Visit visit_node(uint ni, Entry en, RayPre r, float best) {
    Visit v;
    v.tmax = best;
    v.t = en.t;
    v.f = load_frame(ni);
#ifndef MATH_F32
    vec3 w;
    float k;
    node_frame(v.f, w, k);
    float e = anchor(r, w, k, en.t, v.o);
    v.h = half_visit(k, e, en.t, en.t, best);
#endif
    return v;
}

// The fp32 world box of slot s, axis by axis.
void world_box(NodeFrame f, uint ni, uint s, out vec3 lo, out vec3 hi) {
    lo = vec3(0.0);
    hi = vec3(0.0);
    for (int a = 0; a < 3; a++) world_planes(f, ni, s, a, lo[a], hi[a]);
}

// (entry parameter, its lower bound): world t in fp32 math, the node frame's s otherwise.
struct ChildHit { float tn; float tn_lb; };
#ifdef MATH_F32
#define HIT_FROM_KEY(k) ChildHit(k, k)   // test_child's h in fp32 math
#endif

bool test_child(uint ni, uint s, Entry en, Visit v, RayPre r, out float key, out ChildHit h) {
#ifdef MATH_F32
#ifdef FC_OFF
    vec2 q = vec2(r.tmin, v.tmax);
    // Without float controls decode_plane is an integer emulation: each axis's planes are
    // decoded and tested in turn (slab32's steps), so that no decoded box is held whole
    // (Mali-G610, f16w at B = 4: 63 spills and fills with the whole box, 6 this way).
    for (int a = 0; a < 3; a++) {
        float lo, hi;
        world_planes(v.f, ni, s, a, lo, hi);
        slab32_axis(r, a, lo, hi, q.x, q.y);
    }
#else
    // The whole box first, its loads together (RDNA3: the axis-by-axis order costs f16w and
    // f16a 50 % more per traversal step in ACO's model, teapot primary rays at B = 4: 123 → 184
    // of 375 → 437 cycles per ray).
    vec3 lo, hi;
    world_box(v.f, ni, s, lo, hi);
    vec2 q = slab32(r, lo, hi, r.tmin, v.tmax);
#endif
    key = q.x;
    h = ChildHit(q.x, q.x);
    return q.x <= q.y;
#else
    HVEC3 lo, hi;
    local_box(v.f, ni, s, lo, hi);
    bool hit = half_test(v.o, v.h, lo, hi, h.tn, h.tn_lb);
    key = h.tn;
    return hit;
#endif
}

#ifdef HALF_PAIRS
// Children s and s + 1 tested together (half_test2; trav.comp's TEST_PAIRS loop).
#define TEST_PAIRS 1
bvec2 test_pair(uint ni, uint s, Entry en, Visit v, RayPre r, out vec2 key, out ChildHit h0, out ChildHit h1) {
    HVEC3 lo0, hi0, lo1, hi1;
    local_box(v.f, ni, s, lo0, hi0);
    local_box(v.f, ni, s + 1u, lo1, hi1);
    f16vec2 lo[3], hi[3];
    for (int a = 0; a < 3; a++) {
        lo[a] = f16vec2(lo0[a], lo1[a]);
        hi[a] = f16vec2(hi0[a], hi1[a]);
    }
    vec2 tn, tn_lb;
    bvec2 hit = half_test2(v.o, v.h, lo, hi, tn, tn_lb);
    h0 = ChildHit(tn.x, tn_lb.x);
    h1 = ChildHit(tn.y, tn_lb.y);
    key = tn;
    return hit;
}
#endif

Entry child_entry(uint ni, uint s, Entry en, Visit v, ChildHit h, RayPre r, inout uint reanchors) {
#ifdef MATH_F32
    return Entry(h.tn);
#else
    return Entry(half_child_tlo(v.h, v.t, v.t, h.tn_lb));
#endif
}
