// The stack of one entry per child: a visit derives every inner child's entry and pushes all
// but the nearest, which it enters directly. The stack interface (stack_groups.glsl has the
// other discipline, DEFER_ENTRIES):
//   void stack_init()
//   bool stack_fits(uint inner)    whether the visit's inner children fit (else the ray overflows)
//   void push_children(...)        the visit's inner children, nearest first
//   bool pop_next(inout uint ni, inout Entry en)    false when the stack is empty
//   void enter(inout uint ni, inout Entry en, RayPre r, inout Counts c)   after a pop
// Its state is private globals (inlined into main, they are main's locals).

// STACK_ALLOC >= STACK_SIZE: where a compiler keeps private arrays in registers up to a size,
// the arrays are allocated long enough that neither fits there (Variant::stack_alloc); only the
// first STACK_SIZE are ever used.
uint st_node[STACK_ALLOC];
Entry st[STACK_ALLOC];
// Entries on the stack.
int sp;

void stack_init() { sp = 0; }

// The same bound as pushing all of a visit's inner children (traverse.rs); the encoder checks
// that a BVH never needs more (GpuBvh::upload).
bool stack_fits(uint inner) { return sp + bitCount(inner) <= STACK_SIZE; }

// Inner children `inner` of node ni visited under entry en (this ray hit those in `mask`):
// each one's place is its rank by (key, slot), so nothing is sorted or copied through arrays
// indexed at run time (traverse.rs, order_children); rank 0 becomes (ni, en), the others are
// pushed with the nearer ones on top. `descend`: there was one.
void push_children(inout uint ni, inout Entry en, Visit v, RayPre r, uint mask, uint inner, uint cw[B],
                   float key[B], ChildHit ch[B], inout Counts c, inout bool descend) {
    int n = bitCount(inner);
    uint next_node = 0u;
    Entry next_entry = no_entry();
    [[unroll]] for (uint s = 0u; s < uint(B); s++) {
        if ((inner & (1u << s)) != 0u) {
            int rank = 0;
            [[unroll]] for (uint t = 0u; t < uint(B); t++) {
                bool before = key[t] < key[s] || (key[t] == key[s] && t < s);
                if ((inner & (1u << t)) != 0u && before) rank++;
            }
            Entry e = (mask & (1u << s)) != 0u ? child_entry(ni, s, en, v, VISIT_HIT(s), r, c.reanchors) : no_entry();
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
    }
    if (n > 0) {
        sp += n - 1;
        ni = next_node;
        en = next_entry;
        descend = true;
    }
}

bool pop_next(inout uint ni, inout Entry en) {
    if (sp == 0) return false;
    sp--;
    ni = st_node[sp];
    en = st[sp];
    return true;
}

// The popped entry is whole already.
void enter(inout uint ni, inout Entry en, RayPre r, inout Counts c) {}
