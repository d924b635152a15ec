// Layout f32 hooks (src/layout/f32): world-space fp32 child boxes, structure of arrays per
// node, robust fp32 slab tests. The stack Entry (generated) holds the node's entry distance t.
struct Node {
    float lo[3 * B];   // lo[axis * B + slot]
    float hi[3 * B];
    uint child[B];
};
NODE_BUFFER(Node)

uint child_word(uint ni, uint s) { return nodes[ni].child[s]; }

void child_box(uint ni, uint s, out vec3 lo, out vec3 hi) {
    lo = vec3(nodes[ni].lo[s], nodes[ni].lo[B + s], nodes[ni].lo[2 * B + s]);
    hi = vec3(nodes[ni].hi[s], nodes[ni].hi[B + s], nodes[ni].hi[2 * B + s]);
}

void layout_ray(RayPre r) {}

Entry root_entry(RayPre r, float near_t) { return Entry(near_t); }
// Entry distances are >= tmin >= 0, so a negative one marks an inactive ray.
Entry no_entry() { return Entry(-1.0); }
bool has_entry(Entry e) { return e.t >= 0.0; }
float entry_t(Entry e) { return e.t; }

// The ray's closest hit when the node is visited: the box tests' upper limit.
struct Visit { float tmax; };
Visit visit_node(uint ni, Entry e, RayPre r, float best) { return Visit(best); }

struct ChildHit { float t; };
#define HIT_FROM_KEY(k) ChildHit(k)   // test_child's h is ChildHit(key)

bool test_child(uint ni, uint s, Entry e, Visit v, RayPre r, out float key, out ChildHit h) {
    vec3 lo, hi;
    child_box(ni, s, lo, hi);
    vec2 q = slab32(r, lo, hi, r.tmin, v.tmax);
    key = q.x;
    h = ChildHit(q.x);
    return q.x <= q.y;
}

Entry child_entry(uint ni, uint s, Entry e, Visit v, ChildHit h, RayPre r, inout uint reanchors) {
    return Entry(h.t);
}
