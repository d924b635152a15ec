// The stack of one group per visit (DEFER_ENTRIES, with GROUPS; Variant::defines sets them for
// layouts whose entries are large): a child's entry is derived when the child is entered, not
// when the visit that hit it pushes it. The stack holds one group per visit that left inner
// children for later: the node, its entry, this ray's hit mask and the children's order — not
// one entry per child. Entering child s of node n under n's entry e calls visit_node(n, e, r,
// best_t), the child test and child_entry with the same node, entry and box as the push would
// have, so the layout's hooks must not let ChildHit or child_entry depend on `best` (only the
// hit result may, and the hit is the one stored at the push): the entry is then the same, bit
// for bit, and so are the hits and counters (but for a ray whose stack overflows: it reports
// PRIM_OVERFLOW, and the encoder's depth check keeps that from happening). Groups only ever
// belong to nodes on the path from the root, and a node with an inner child is at most at depth
// (STACK_SIZE - 1) / (B - 1) - 2: at most GROUPS of them. The interface is stack_entries.glsl's.

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
// GROUPS_ALLOC >= GROUPS: where a compiler keeps each field's array on its own in registers
// up to a size (turnip: 256 bytes), the array is allocated long enough that none fits there
// (Variant::groups_alloc); only the first GROUPS are ever used.
struct Group { Entry en; uint node; Meta meta; };

Group gs[GROUPS_ALLOC];
int gp;
// Children left in the groups.
int sp;
// The child to enter: slot ps of node pn, under pn's entry pe; phit: this ray hit it. With
// PENDING_SHARED pe is kept in shared memory, one per invocation: it is written by the push or
// the pop and read when the child is entered, so it is not held in registers across the
// visit's triangle tests, where the register peak is (isa, B = 4: RDNA3 84 -> 72 VGPRs,
// Mali-G610 646 -> 357 spills and fills; Variant::defines says where it is not set).
uint pn, ps;
#ifdef PENDING_SHARED
shared Entry sh_pe[WG];
#define pe sh_pe[gl_LocalInvocationID.x]
#else
Entry pe;
#endif
bool phit;

void stack_init() {
    gp = 0;
    sp = 0;
    pn = 0u;
    ps = 0u;
    pe = no_entry();
    phit = false;
}

// Whether the visit's inner children fit: their entries, and a group where more than one.
bool stack_fits(uint inner) {
    int n = bitCount(inner);
    return sp + n <= STACK_SIZE && (n <= 1 || gp < GROUPS);
}

// Inner children `inner` of node ni (this ray hit those in `mask`), nearest first by (key,
// slot): the nearest is entered next (enter), the others wait in one group.
void push_children(inout uint ni, inout Entry en, Visit v, RayPre r, uint mask, uint inner, uint cw[B],
                   float key[B], ChildHit ch[B], inout Counts c, inout bool descend) {
    int n = bitCount(inner);
    uint s0 = 0u;
    Meta gm = meta_new(mask, n - 1);
    [[unroll]] for (uint s = 0u; s < uint(B); s++) {
        if ((inner & (1u << s)) != 0u) {
            int rank = 0;
            [[unroll]] for (uint t = 0u; t < uint(B); t++) {
                // (key, slot) order with one comparison: t < s is known when unrolled.
                bool before = t < s ? key[t] <= key[s] : key[t] < key[s];
                if ((inner & (1u << t)) != 0u && before) rank++;
            }
            if (rank == 0) s0 = s;
            else gm = meta_put(gm, rank - 1, s);
        }
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
}

// The nearest child left in the top group; the group goes when it is empty.
bool pop_next(inout uint ni, inout Entry en) {
    if (sp == 0) return false;
    sp--;
    int g = gp - 1;
    Meta m = gs[g].meta;
    pn = gs[g].node;
    pe = gs[g].en;
    ps = meta_slot(m);
    phit = meta_hit(m, ps);
    m = meta_next(m);
    if (meta_left(m) == 0u) gp = g;
    else gs[g].meta = m;
    return true;
}

// Enter the child: its entry from its parent's, as the push would have derived it.
void enter(inout uint ni, inout Entry en, RayPre r, inout Counts c) {
    ni = child_word(pn, ps);
    en = no_entry();
    if (phit) {
        Visit pv = visit_node(pn, pe, r, best_t);
        ChildHit h = retest_child(pn, ps, pe, pv, r);
        en = child_entry(pn, ps, pe, pv, h, r, c.reanchors);
    }
}
