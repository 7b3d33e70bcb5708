// Shared by the resolve passes: read one pixel's crossing list (recorded by crossing.glsl in
// RESOLVE mode), sort it along the ray, and sweep it with the ownership rule. The lists stay in
// place; the host empties them when the last resolve pass of a view is done.

layout(local_size_x = 8, local_size_y = 8) in;
layout(std430, binding = BINDING_HEADS) readonly buffer Heads { uint heads[]; };
layout(std430, binding = BINDING_NODES) readonly buffer Nodes { uvec4 nodes[]; };  // t bits, object*2 + exit, next, -
layout(std430, binding = BINDING_COUNTERS) buffer Counters { uint overflow_pixels; uint max_depth; };

const uint END = 0xFFFFFFFFu;
float ts[MAX_CROSSINGS];
uint metas[MAX_CROSSINGS];
float listed_ts[MAX_CROSSINGS];  // in list order, before sorting
uint listed_metas[MAX_CROSSINGS];
uint active_rank[MAX_CROSSINGS];
int active_count[MAX_CROSSINGS];
int n_active = 0;

// The list of `pixel` into ts/metas, sorted by t; returns how many crossings it holds, or -1
// after counting an overflow when it holds more than MAX_CROSSINGS (the host then reruns the
// pass with room for max_depth).
int load_sorted(int pixel) {
    uint node = heads[pixel];
    int n = 0;
    int depth = 0;
    while (node != END) {
        uvec4 e = nodes[node];
        if (n < MAX_CROSSINGS) {
            listed_ts[n] = uintBitsToFloat(e.x);
            listed_metas[n] = e.y;
            n++;
        }
        node = e.z;
        depth++;
    }
    if (depth > MAX_CROSSINGS) {
        atomicAdd(overflow_pixels, 1u);
        atomicMax(max_depth, uint(depth));
        return -1;
    }
    // Sorted by rank: each crossing's place is the number of crossings before it (ties in list
    // order). Its inner loop reads every lane's j-th element at once, where an insertion sort's
    // shifts stop at a different place in each SIMD lane: on llvmpipe the overlap pass took 2-9 %
    // less time (BENCHMARKS.md).
    for (int i = 0; i < n; i++) {
        float t = listed_ts[i];
        int place = 0;
        for (int j = 0; j < n; j++) {
            float u = listed_ts[j];
            place += (u < t || (u == t && j < i)) ? 1 : 0;
        }
        ts[place] = t;
        metas[place] = listed_metas[i];
    }
    return n;
}

// Crossing i enters (+1) or leaves (-1) its object; given the owner before it, returns the rank
// of the object that owns the space after it: the highest-ranked (priority, then insertion order)
// object the ray is inside, or -1 for none. The active list holds only the objects the ray is
// inside (an object whose count returns to 0 leaves it), so it stays as short as the nesting is
// deep however many objects the ray crosses: keeping every object once met made each crossing
// cost O(objects met). Only the owner's own exit needs the list searched for the next owner.
int sweep(int i, int owner) {
    uint rank = metas[i] >> 1;  // object index = rank order
    int step = (metas[i] & 1u) == 1u ? -1 : 1;  // exit leaves, entry enters
    int j = 0;
    while (j < n_active && active_rank[j] != rank) j++;
    if (j == n_active) { active_rank[j] = rank; active_count[j] = 0; n_active++; }
    int count = active_count[j] + step;
    active_count[j] = count;
    if (count == 0) {
        n_active--;
        active_rank[j] = active_rank[n_active];
        active_count[j] = active_count[n_active];
    }
    if (count > 0) return max(owner, int(rank));
    if (int(rank) != owner) return owner;
    owner = -1;
    for (int q = 0; q < n_active; q++)
        if (active_count[q] > 0 && int(active_rank[q]) > owner) owner = int(active_rank[q]);
    return owner;
}
